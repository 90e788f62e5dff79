"""Scene load and upload time per backend, then one rendered frame (not a test).

    .venv/bin/python benchmarks/bench_scene_load.py [--scenes courtyard,stress,city]
        [--backends vk,wgpu] [--repeats 3] [--no-before] [--before-repeats 1]
        [--render flat] [--render-size 320x180] [--scene-dir .scenes]
        [--out out/bench_scene_load.json]

Each case (scene, backend, allocator) runs in a fresh process, which makes one device and
then, ``--repeats`` times: reads or generates the scene (``load``: ``rfw.scene.load_scene``,
as ``rfw run --scene`` does), picks its drawable instances and camera (``prepare``), and
uploads it through the backend plug-in (``upload``: ``Backend.scene``, waiting until the
device has finished the copies), then destroys it. A small stress scene goes first, untimed,
so imports and first-use costs stay out; the table prints medians, and min..max.

Then the case renders the loaded scene once through ``rfw.render.render`` with the
``--render`` config (default ``flat``: one draw per instance, nothing else) at
``--render-size``: ``render ms`` is that call's wall time (upload, pipelines, recording every
draw, one warm-up and one timed frame, readback), ``frame gpu ms`` the timed frame's GPU
time, and ``covered`` the share of pixels off the background colour, so a frame that drew
nothing shows. ``--render none`` skips it (an older commit without ``rfw.render`` skips it
by itself).

``--before`` repeats the vk cases with ``vkext.blocks.BlockAllocator.default_strategy =
"first-fit"``, the scan the block allocator used before it binned its free ranges (quadratic
in the buffers of a block), in the same run. Only the search differs (freeing is O(1) in
both), and since VkScene packs every mesh into a few buffers the scene upload barely feels
it now; the whole change is measured at two commits instead, the script being standalone:

    git archive 8a4ce6b | tar -x -C /tmp/old && cp benchmarks/bench_scene_load.py /tmp/old/benchmarks/
    PYTHONPATH=/tmp/old .venv/bin/python /tmp/old/benchmarks/bench_scene_load.py \
        --scenes courtyard,city --scene-dir .scenes --out out/bench_scene_load_old.json

Scenes: ``courtyard`` (built in), ``stress`` (100,000 cubes; ``stress:COUNT`` for another
count), and ``city`` (Sionna RT's Munich, 2,367 meshes) or any other name: ``<name>.glb`` in
a ``--scene-dir`` (default ``.scenes``), else ``<name>.npz`` there (the compact form
``bench_meshlets.py --export-scenes`` writes, read by its ``load_npz``: no uvs, int8
normals, tangents recomputed, so its ``load`` differs from the GLB's while everything after
is the same), else the fetch cache's GLB (``rfw scenes fetch city``). The ``source`` column
says which. A missing scene is reported and skipped; any other path names a file. A case
that crashes or fails is reported with its exit status and the last line it printed, and
the others still run.

On the GPU machine (no network), ``.scenes`` travels with ``city.npz`` and ``dragon.npz``
(``benchmarks/device_prepare.sh``); from the repository root there:

    source benchmarks/device_env.sh && python3 benchmarks/bench_scene_load.py \\
        --scenes courtyard,stress,city --out $OUT/bench_scene_load.json
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))  # bench_meshlets.load_npz

SCENES = ("courtyard", "stress", "city")
BACKENDS = ("vk", "wgpu")
PHASES = ("load", "prepare", "upload")


def scene_source(name: str, scene_dirs: list[Path]) -> str | None:
    """What the worker loads for ``name``: a built-in name, a file given by path, or
    ``<name>.glb`` then ``<name>.npz`` in ``scene_dirs``, then the fetch cache's GLB (None
    when it is nowhere here)."""
    if name in ("courtyard", "stress") or name.startswith("stress:"):
        return name
    if Path(name).suffix in (".glb", ".gltf", ".npz", ".obj", ".ply"):
        return name if Path(name).is_file() else None
    from rfw.scene.fetch import default_cache

    for path in [*(d / f"{name}{ext}" for d in scene_dirs for ext in (".glb", ".npz")),
                 default_cache() / f"{name}.glb"]:
        if path.is_file():
            return str(path)
    return None


def _load(source: str):
    # the courtyard by its function: older commits know no scene names
    from rfw.scene import default_scene, load_scene

    if source == "courtyard":
        return default_scene()
    if source.endswith(".npz"):
        from bench_meshlets import load_npz

        return load_npz(Path(source))
    return load_scene(source)


# ---------------------------------------------------------------------------------------------
# one case, in its own process


def _wait(backend: str, device) -> None:
    # the upload counts until the device has made the copies
    if backend == "wgpu":
        import wgpu

        # a read waits for every write queued before it (work-done callbacks do not work
        # in every wgpu-py release)
        buf = device.device.create_buffer(size=4, usage=wgpu.BufferUsage.COPY_SRC
                                          | wgpu.BufferUsage.COPY_DST)
        device.device.queue.write_buffer(buf, 0, b"\0\0\0\0")
        device.device.queue.read_buffer(buf)
        buf.destroy()
    else:
        device.wait_idle()


def _triangle():
    import numpy as np

    from rfw.scene import Instance, Mesh, Scene

    tri = Mesh("tri", np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32),
               np.array([[0, 0, 1]] * 3, np.float32), np.zeros((3, 2), np.float32),
               np.array([[1, 0, 0, 1]] * 3, np.float32), np.arange(3, dtype=np.uint32))
    return Scene("triangle", [tri], instances=[Instance(0, np.identity(4, np.float32))])


def _allocator_stats(backend: str, gpu_scene) -> dict:
    # getattr: the same script times older commits too (git archive), whose allocator
    # counted nothing
    if backend != "vk":
        return {}
    a = gpu_scene.allocator
    return {**a.stats(), "visits": getattr(a, "visits", None),
            "strategy": getattr(a, "strategy", "first-fit")}


def _render(config: str, size: str, scene, backend: str, device) -> dict:
    """One ``rfw.render.render`` of ``scene`` (a warm-up frame and a timed one): its wall
    time, the timed frame's GPU and record times, and the share of pixels drawn."""
    import numpy as np

    try:
        from rfw.config import apply_overrides, load_config
        from rfw.render import render
    except ImportError:  # an older commit
        return {"render_error": "this commit has no rfw.render"}
    path = ROOT / "configs" / f"{config}.toml"
    cfg = apply_overrides(load_config(path), [f"size={size}"])
    t = time.perf_counter()
    result = render(cfg, scene=scene, device=device, backend=backend, frames=1)
    wall = (time.perf_counter() - t) * 1e3
    image = np.asarray(next(iter(result.images.values())))
    rgb = image.reshape(-1, image.shape[-1])[:, :3].astype(np.int64)
    background = rgb[0]  # the top-left corner: sky in every built-in camera
    passes = result.timings.get("passes", [])
    return {"render_ms": wall, "render_config": config, "render_size": size,
            "frame_gpu_ms": sum(p.get("gpu_ms") or 0.0 for p in passes),
            "frame_cpu_ms": sum(p.get("cpu_ms") or 0.0 for p in passes),
            "covered": float((np.abs(rgb - background).sum(axis=1) > 24).mean())}


def run_case(source: str, backend_name: str, strategy: str, repeats: int,
             render_config: str = "none", render_size: str = "320x180") -> dict:
    from rfw.backend import get_backend

    if backend_name == "vk":
        from vkext.blocks import BlockAllocator

        BlockAllocator.default_strategy = strategy
    backend = get_backend(backend_name)
    device = backend.make_device(label="bench_scene_load")
    times: dict[str, list[float]] = {p: [] for p in PHASES}
    out: dict = {"device": backend.describe(device)}
    try:
        # warm-up on one triangle: imports and first-use costs stay out of every repeat
        warm = _triangle()
        backend.scene(device, warm, warm.default_camera(), (64, 64)).destroy()
        for _ in range(repeats):
            t0 = time.perf_counter()
            scene = _load(source)
            t1 = time.perf_counter()
            drawable = scene.drawable()
            camera = drawable.default_camera()
            t2 = time.perf_counter()
            gpu_scene = backend.scene(device, drawable, camera, (1280, 720))
            _wait(backend_name, device)
            t3 = time.perf_counter()
            out["blocks"] = _allocator_stats(backend_name, gpu_scene)
            gpu_scene.destroy()
            for p, (a, b) in zip(PHASES, ((t0, t1), (t1, t2), (t2, t3)), strict=True):
                times[p].append((b - a) * 1e3)
        out.update(meshes=len(scene.meshes), instances=len(scene.instances),
                   triangles=scene.triangle_count, ms=times)
        if render_config != "none":
            out.update(_render(render_config, render_size, drawable, backend_name, device))
    finally:
        backend.destroy_device(device)
    return out


# ---------------------------------------------------------------------------------------------
# the driver


def _exit_text(rc: int) -> str:
    if rc < 0:
        try:
            return f"killed by {signal.Signals(-rc).name}"
        except ValueError:
            return f"killed by signal {-rc}"
    return f"exit status {rc}"


def spawn(source: str, backend: str, strategy: str, repeats: int, timeout: float,
          render: tuple[str, str] = ("none", "")) -> dict:
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", source, backend, strategy,
           str(repeats), *render]
    t = time.perf_counter()
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, check=False)
    except subprocess.TimeoutExpired:
        return {"error": f"over the {timeout:.0f} s limit"}
    wall = time.perf_counter() - t
    lines = [ln for ln in done.stdout.splitlines() if ln.startswith("{")]
    if done.returncode or not lines:
        last = (done.stderr.strip().splitlines() or ["(nothing printed)"])[-1]
        return {"error": f"{_exit_text(done.returncode)}: {last[:200]}", "wall_s": wall}
    return {**json.loads(lines[-1]), "wall_s": wall}


def _median(xs: list[float]) -> float:
    return statistics.median(xs) if xs else float("nan")


def summarize(row: dict) -> dict:
    """Median and range of each phase, and of their sum per repeat."""
    ms = row.get("ms")
    if not ms:
        return {}
    totals = [sum(v) for v in zip(*(ms[p] for p in PHASES), strict=True)]
    out = {f"{p}_ms": _median(ms[p]) for p in PHASES}
    out.update(total_ms=_median(totals), total_min_ms=min(totals), total_max_ms=max(totals))
    return out


def table(rows: list[dict]) -> str:
    head = (f"{'scene':<14}{'source':<8}{'backend':<8}{'allocator':<11}{'buffers':>8}"
            f"{'load ms':>10}{'prepare':>10}{'upload ms':>11}{'total ms':>11}  {'range':<13}"
            f"{'render ms':>10}{'frame gpu ms':>13}{'covered':>8}")
    lines = [head, "-" * len(head)]
    for r in rows:
        key = f"{r['scene']:<14}{_kind(r.get('source', '')):<8}{r['backend']:<8}" \
              f"{r['allocator']:<11}"
        if "error" in r:
            lines.append(f"{key}{'':>8}  FAILED: {r['error']}")
            continue
        s = r["summary"]
        bufs = r.get("blocks", {}).get("allocations", "")
        spread = f"{s['total_min_ms']:.0f}..{s['total_max_ms']:.0f}"
        line = (f"{key}{bufs!s:>8}{s['load_ms']:>10.1f}{s['prepare_ms']:>10.1f}"
                f"{s['upload_ms']:>11.1f}{s['total_ms']:>11.1f}  {spread:<13}")
        if "render_ms" in r:
            line += f"{r['render_ms']:>10.1f}{r['frame_gpu_ms']:>13.2f}{r['covered']:>8.2f}"
        elif "render_error" in r:
            line += f"  render: {r['render_error']}"
        lines.append(line.rstrip())
    return "\n".join(lines)


def _kind(source: str) -> str:
    # where a scene came from: built in, a GLB, or the compact .npz
    suffix = Path(source).suffix
    return suffix[1:] if suffix else "builtin"


def ratios(rows: list[dict]) -> dict[str, float]:
    """Per scene on vk: first-fit upload ms over good-fit upload ms (same run)."""
    out = {}
    by = {(r["scene"], r["backend"], r["allocator"]): r for r in rows if "summary" in r}
    for (scene, backend, alloc), r in by.items():
        old = by.get((scene, backend, "first-fit"))
        if alloc == "good-fit" and old:
            out[scene] = old["summary"]["upload_ms"] / r["summary"]["upload_ms"]
    return out


def _commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                              capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--backends", default=",".join(BACKENDS))
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--before", action=argparse.BooleanOptionalAction, default=False,
                    help="also time the vk cases with the old first-fit allocator")
    ap.add_argument("--before-repeats", type=int, default=1,
                    help="repeats of the first-fit cases (the city takes a minute each on "
                         "lavapipe)")
    ap.add_argument("--scene-dir", action="append", default=[],
                    help="folders searched for <scene>.glb, then <scene>.npz (default: "
                         ".scenes)")
    ap.add_argument("--render", default="flat",
                    help="config (configs/NAME.toml) rendered once per case after the "
                         "uploads, or none")
    ap.add_argument("--render-size", default="320x180")
    ap.add_argument("--timeout", type=float, default=900.0, help="seconds per case")
    ap.add_argument("--out", default=str(ROOT / "out" / "bench_scene_load.json"))
    ap.add_argument("--worker", nargs="+", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:  # SOURCE BACKEND ALLOCATOR REPEATS [RENDER SIZE]
        source, backend, strategy, repeats, *render = args.worker
        print(json.dumps(run_case(source, backend, strategy, int(repeats), *render)))
        return 0

    scene_dirs = [Path(d) for d in args.scene_dir] or [ROOT / ".scenes"]
    rows, skipped = [], []
    for name in args.scenes.split(","):
        source = scene_source(name, scene_dirs)
        if source is None:
            skipped.append(f"{name}: no {name}.glb or {name}.npz in "
                           f"{', '.join(map(str, scene_dirs))}, nor in the fetch cache (rfw "
                           f"scenes fetch {name}; bench_meshlets.py --export-scenes .scenes "
                           f"to carry it)")
            continue
        for backend in args.backends.split(","):
            strategies = ["good-fit", *(["first-fit"] if args.before else [])] \
                if backend == "vk" else ["-"]  # the block allocator is vk's
            for strategy in strategies:
                n = args.before_repeats if strategy == "first-fit" else args.repeats
                # the frame is rendered once per scene and backend, not per allocator
                render = (args.render, args.render_size) if strategy != "first-fit" \
                    else ("none", "")
                row = {"scene": name, "source": source, "backend": backend,
                       "allocator": strategy, "repeats": n,
                       **spawn(source, backend, strategy, n, args.timeout, render)}
                # what the allocator says it was (an older commit's knows first fit only)
                row["allocator"] = row.get("blocks", {}).get("strategy", strategy)
                if "ms" in row:
                    row["summary"] = summarize(row)
                rows.append(row)
                print(table([row]).splitlines()[-1], flush=True)
    doc = {"bench": "scene_load", "commit": os.environ.get("RFW_COMMIT") or _commit(),
           "machine": {"cpu": platform.processor() or platform.machine(),
                       "cores": os.cpu_count(), "python": platform.python_version()},
           "rows": rows, "first_fit_over_good_fit_upload": ratios(rows), "skipped": skipped}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(doc, indent=1) + "\n")
    print()
    print(table(rows))
    for r in {(r["backend"], json.dumps(r.get("device", {}))) for r in rows if "device" in r}:
        print(f"{r[0]}: {r[1]}")
    for scene, x in doc["first_fit_over_good_fit_upload"].items():
        print(f"{scene}: vk upload with the first-fit allocator takes {x:.1f}x as long")
    for s in skipped:
        print(f"skipped {s}")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
