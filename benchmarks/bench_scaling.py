"""GPU ms of each raster pass against resolution, instance count, triangles per instance and
textures, beside a depth-only floor drawing the same geometry (issue 13, item 2).

One graph (written to ``OUT/scaling.toml``) holds every pass measured, so all see the same
frame, scene and camera: ``shadow`` (``shadow_map``, its own 2048² target whatever the
resolution), ``floor`` (``depth_prepass``: one pipeline, a vertex shader, no fragment shader, no
textures, depth only), ``gbuffer`` and ``forward`` (its shadow lookups on). ``floor`` pays
rfw's per-draw and per-instance costs, so ``gbuffer / floor`` is what the G-buffer's
attachments, fragment shading and texturing add to drawing the geometry.

Below that, two raw-Vulkan floors outside the frame graph (``raw_floor.py``, on a Vulkan
device of their own after the rfw frames): the same geometry, camera and size, depth only,
with a command buffer recorded once: ``raw_draws`` (a ``vkCmdDrawIndexed`` per instance, no
descriptor sets) and ``raw_instanced`` (one instanced draw). ``floor / raw_instanced`` is what
rfw's way of drawing costs the GPU over the least any renderer could do; the record checks
that both depths cover the same pixels as rfw's floor (``raw_depth_check``).

The scene is ``k`` copies of one UV sphere (``4 n²`` triangles) on a square grid, framed whole by
the default camera: more copies make each one smaller on screen, so the covered pixels stay
about the same while the vertex and per-draw work grows. Textures on: a 512² base colour,
normal and metal-roughness texture each (mip-mapped by the upload); off: no texture, constant
material values.

The sweep is one axis at a time around a base point (``--grid full`` for a GPU, ``reduced``
for lavapipe, which is slow; ``auto`` picks by the Vulkan device type):

    .venv/bin/python benchmarks/bench_scaling.py --out out/scaling            # lavapipe
    python3 benchmarks/bench_scaling.py --grid full --budget 200 --out $OUT   # a GPU

Writes ``OUT/scaling.json`` (every point: its axis, parameters, per pass the GPU ms of every
timed frame and their median), ``OUT/scaling.md`` (tables, ratios to the floor) and
``OUT/scaling_<axis>.png`` (matplotlib; skipped with a note where it is not installed).
``--budget S`` starts no point that would likely end after S seconds: the report covers the
points done and names the others.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import time
import traceback
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT)]

from rfw.bench.runner import NO_CLOCKS, environment, gpu_clocks  # noqa: E402
from rfw.config import apply_overrides, load_config  # noqa: E402
from rfw.scene.model import Instance, Material, Mesh, Scene, Texture  # noqa: E402

PASSES = ("shadow", "floor", "gbuffer", "forward")
RASTER = ("shadow", "gbuffer", "forward")  # measured against the floor
RAW = ("raw_draws", "raw_instanced")  # raw_floor.py: the floor outside the frame graph
SERIES = PASSES + RAW
GRAPH = """# written by benchmarks/bench_scaling.py: every raster pass of one frame, and the floor
name = "scaling"
scene = "default"
size = [1280, 720]
outputs = ["gbuffer.albedo", "forward.hdr", "floor.depth", "shadow.depth"]

[[pass]]
name = "shadow"
use = "shadow_map"

[[pass]]
name = "floor"
use = "depth_prepass"

[[pass]]
name = "gbuffer"

[[pass]]
name = "forward"
inputs = { shadow = "shadow.depth" }
"""

# the base point and the values of each axis; (w, h), instances, n (4 n² triangles), textures
GRIDS: dict[str, dict[str, Any]] = {
    "full": {"base": {"size": (1280, 720), "instances": 400, "n": 16, "textures": True},
             "size": [(640, 360), (1280, 720), (1920, 1080), (2560, 1440), (3840, 2160)],
             "instances": [1, 10, 100, 400, 1000, 10_000, 100_000],
             "n": [4, 8, 16, 32, 64, 128],
             "frames": 30, "warmup": 5},
    "reduced": {"base": {"size": (640, 360), "instances": 100, "n": 8, "textures": True},
                "size": [(640, 360), (1280, 720), (1920, 1080), (3840, 2160)],
                "instances": [1, 10, 100, 1000, 10_000],
                "n": [4, 8, 16, 32, 64],
                "frames": 5, "warmup": 1},
}
AXES = ("size", "instances", "n", "textures")
AXIS_TITLES = {"size": "resolution (pixels)", "instances": "instances (copies of one mesh)",
               "n": "triangles per instance", "textures": "textures"}
MAX_DRAWS_PER_RUN = 2_000_000  # instances x timed frames: fewer frames for huge instance counts


# ---------------------------------------------------------------------------------------------
# the scene


def sphere(n: int) -> Mesh:
    """A UV sphere of radius 1: ``n`` rings of ``2 n`` quads, ``4 n²`` triangles."""
    theta = np.linspace(0.0, np.pi, n + 1, dtype=np.float64)  # pole to pole
    phi = np.linspace(0.0, 2 * np.pi, 2 * n + 1, dtype=np.float64)  # seam duplicated for uvs
    t, p = np.meshgrid(theta, phi, indexing="ij")
    pos = np.stack([np.sin(t) * np.cos(p), np.cos(t), np.sin(t) * np.sin(p)], -1).reshape(-1, 3)
    uv = np.stack([p / (2 * np.pi), t / np.pi], -1).reshape(-1, 2)
    tangent = np.stack([-np.sin(p), np.zeros_like(p), np.cos(p), np.ones_like(p)],
                       -1).reshape(-1, 4)
    cols = 2 * n + 1
    r, c = np.meshgrid(np.arange(n), np.arange(2 * n), indexing="ij")
    a = (r * cols + c).ravel()
    b, d, e = a + cols, a + 1, a + cols + 1
    # counter-clockwise seen from outside
    idx = np.stack([a, d, b, d, e, b], -1).reshape(-1).astype(np.uint32)
    return Mesh(f"sphere{n}", pos.astype(np.float32), pos.astype(np.float32),
                uv.astype(np.float32), tangent.astype(np.float32), idx)


def _textures() -> list[Texture]:
    y, x = np.mgrid[0:512, 0:512]
    check = ((x // 32 + y // 32) % 2).astype(np.uint8)
    color = np.stack([200 - 120 * check, 160 + 60 * check, 90 + 40 * check,
                      np.full_like(check, 255)], -1).astype(np.uint8)
    normal = np.zeros((512, 512, 4), np.uint8)
    normal[..., :] = (128, 128, 255, 255)
    normal[..., 0] = (128 + 40 * np.sin(x / 9.0)).astype(np.uint8)  # a ripple to sample
    rough = np.stack([np.full_like(check, 255), 90 + 120 * check, 30 * check,
                      np.full_like(check, 255)], -1).astype(np.uint8)
    return [Texture("base", color), Texture("normal", normal, srgb=False),
            Texture("metal_rough", rough, srgb=False)]


def grid_scene(instances: int, n: int, textures: bool) -> Scene:
    """``instances`` copies of ``sphere(n)`` on a square grid in the xz plane."""
    side = math.ceil(math.sqrt(instances))
    k = np.arange(instances)
    x, z = (k % side - (side - 1) / 2) * 2.5, (k // side - (side - 1) / 2) * 2.5
    transforms = np.tile(np.eye(4, dtype=np.float32), (instances, 1, 1))
    transforms[:, 0, 3], transforms[:, 2, 3] = x, z
    if textures:
        material = Material("textured", base_color_texture=0, normal_texture=1,
                            metallic_roughness_texture=2, metallic=1.0, roughness=1.0)
    else:
        material = Material("plain", base_color=(0.6, 0.7, 0.4, 1.0), metallic=0.1,
                            roughness=0.6)
    return Scene(f"spheres{instances}x{4 * n * n}", [sphere(n)], [material],
                 _textures() if textures else [],
                 [Instance(0, t, f"s{i}") for i, t in enumerate(transforms)])


# ---------------------------------------------------------------------------------------------
# the sweep


def points(grid: dict[str, Any], axes: list[str]) -> list[dict[str, Any]]:
    """One point per axis value, the other parameters at the base; the base point once."""
    base = grid["base"]
    out: list[dict[str, Any]] = []
    seen: dict[tuple, dict[str, Any]] = {}
    for axis in axes:
        values = [True, False] if axis == "textures" else grid[axis]
        for v in values:
            p = {**base, axis: v}
            key = (p["size"], p["instances"], p["n"], p["textures"])
            if key in seen:  # the base point: measured once, on every axis
                seen[key]["axes"].append(axis)
                continue
            seen[key] = {**p, "axes": [axis]}
            out.append(seen[key])
    return out


def frames_for(point: dict[str, Any], frames: int) -> int:
    """Fewer timed frames where every frame records a huge number of draws."""
    return min(frames, max(3, MAX_DRAWS_PER_RUN // max(1, point["instances"])))


def measure(point: dict[str, Any], config: Path, *, backend: str, frames: int,
            warmup: int) -> dict[str, Any]:
    """Render the point's scene; per pass the GPU ms of every timed frame."""
    from rfw.render import render

    w, h = point["size"]
    t0 = time.perf_counter()
    load_before = os.getloadavg()[0]
    scene = grid_scene(point["instances"], point["n"], point["textures"])
    build_s = time.perf_counter() - t0
    cfg = apply_overrides(load_config(config), [f"size={w}x{h}"])
    t1 = time.perf_counter()
    result = render(cfg, scene=scene, frames=frames, warmup=warmup, backend=backend)
    render_s = time.perf_counter() - t1
    clocks = gpu_clocks()  # right after the frames: the clocks they ran at, or close
    ex = result.executor
    passes = {}
    for name in PASSES:
        t = ex.timings.get(name)
        gpu = list(t.gpu_ms)[-frames:] if t is not None else []
        cpu = list(t.cpu_ms)[-frames:] if t is not None else []
        passes[name] = {"gpu_ms": gpu, "cpu_ms": cpu,
                        "gpu_ms_median": statistics.median(gpu) if gpu else None,
                        "cpu_ms_median": statistics.median(cpu) if cpu else None}
    try:
        raw, check = measure_raw(scene, cfg, result, frames=frames, warmup=warmup)
    except Exception as e:  # the rfw passes stand; the report names why the floor is missing
        raw, check = {}, {"error": f"{type(e).__name__}: {e}".splitlines()[0]}
    passes.update(raw)
    return {"device": result.timings.get("device"), "driver": result.timings.get("driver"),
            "triangles": scene.triangle_count, "frames": frames, "warmup": warmup,
            "passes": passes, "raw_depth_check": check, "gpu_clocks": clocks,
            "build_s": build_s, "render_s": render_s, "wall_s": time.perf_counter() - t0,
            "loadavg": [load_before, os.getloadavg()[0]]}


def measure_raw(scene: Scene, cfg: Any, result: Any, *, frames: int,
                warmup: int) -> tuple[dict[str, Any], dict[str, Any]]:
    """The raw-Vulkan floor (raw_floor.py) of the same geometry, camera and size, and how
    its depth compares with rfw's floor pass's (the same surface, so the same pixels)."""
    import raw_floor

    from rfw.frame import camera_for

    w, h = cfg.size
    cam = camera_for(cfg, scene)
    view_proj = cam.projection(w / h) @ cam.view()
    transforms = np.stack([i.transform for i in scene.instances])
    depth: dict[str, np.ndarray] = {}
    times = raw_floor.measure(scene.meshes[0], transforms, view_proj, (w, h), frames=frames,
                              warmup=warmup, depth_out=depth)
    ours = np.asarray(result.images["floor.depth"], dtype=np.float32).reshape(h, w, -1)[..., 0]
    check = {"coverage_floor": float((ours < 1).mean())}
    for mode, d in depth.items():
        both = (ours < 1) & (d < 1)
        check[f"coverage_{mode}"] = float((d < 1).mean())
        check[f"max_depth_diff_{mode}"] = float(np.abs(ours - d)[both].max()) if both.any() \
            else None
    out = {f"raw_{mode}": {"gpu_ms": t, "cpu_ms": [],
                           "gpu_ms_median": statistics.median(t) if t else None,
                           "cpu_ms_median": None} for mode, t in times.items()}
    return out, check


def cost(point: dict[str, Any]) -> float:
    """A rough size of a point's work: triangles plus pixels (points run cheapest first, so
    a --budget cuts the extremes)."""
    w, h = point["size"]
    return point["instances"] * 4 * point["n"] ** 2 + point["instances"] * 50 + w * h / 4


def _guess_s(done: list[dict[str, Any]], point: dict[str, Any]) -> float:
    """Seconds a point will likely take: the done point of the nearest cost, scaled up
    by the cost ratio where this one is dearer."""
    fits = [r for r in done if "process_s" in r]
    if not fits:
        return 0.0
    near = min(fits, key=lambda r: abs(math.log(cost(r) / cost(point))))
    return near["process_s"] * max(1.0, cost(point) / cost(near))


def run_worker(spec: dict[str, Any], timeout: float) -> dict[str, Any]:
    """``measure`` in a child process, so that a crash of one point (a driver's segfault)
    is that point's error and the sweep goes on."""
    t0 = time.perf_counter()
    try:
        done = subprocess.run([sys.executable, "-X", "faulthandler", __file__, "--worker",
                               json.dumps(spec)],
                              capture_output=True, text=True, timeout=timeout, check=False)
    except subprocess.TimeoutExpired:
        return {"error": f"timed out after {timeout:g} s", "wall_s": timeout}
    for line in done.stdout.splitlines():
        if line.startswith("RFW_POINT "):
            return {**json.loads(line[len("RFW_POINT "):]),
                    "process_s": time.perf_counter() - t0}
    tail = (done.stderr or done.stdout).strip().splitlines()[-3:]
    if "Current thread" in done.stderr:  # a crash: where it happened, innermost first
        crashed = done.stderr.split("Current thread", 1)[1].split("\n\n", 1)[0]
        tail = [x.strip() for x in crashed.splitlines() if x.strip().startswith("File")][:4]
    why = f"signal {-done.returncode}" if done.returncode < 0 else f"exit {done.returncode}"
    return {"error": f"{why}: " + " | ".join(tail), "wall_s": time.perf_counter() - t0}


def worker(spec: dict[str, Any]) -> int:
    point = {**spec["point"], "size": tuple(spec["point"]["size"])}
    try:
        rec = measure(point, Path(spec["config"]), backend=spec["backend"],
                      frames=spec["frames"], warmup=spec["warmup"])
    except Exception as e:  # reported, and the sweep goes on
        first = str(e).strip().splitlines()[0] if str(e).strip() else ""
        rec = {"error": f"{type(e).__name__}: {first}",
               "traceback": traceback.format_exc(limit=6)}
    print("RFW_POINT " + json.dumps(rec), flush=True)
    return 0


def sweep(plan: list[dict[str, Any]], config: Path, *, backend: str, frames: int,
          warmup: int, budget: float | None, timeout: float) -> list[dict[str, Any]]:
    records: list[dict[str, Any]] = []
    t0 = time.perf_counter()
    plan = sorted(plan, key=cost)
    for k, point in enumerate(plan, 1):
        label = _label(point)
        if budget is not None and time.perf_counter() - t0 + _guess_s(records, point) > budget:
            print(f"[{k}/{len(plan)}] {label}: skipped (--budget {budget:g} s)", flush=True)
            records.append({**point, "skipped": f"--budget {budget:g} s"})
            continue
        spec = {"point": point, "config": str(config), "backend": backend,
                "frames": frames_for(point, frames), "warmup": warmup}
        rec = {**point, **run_worker(spec, timeout)}
        if "error" in rec:
            print(f"[{k}/{len(plan)}] {label}: FAILED {rec['error']}", flush=True)
        else:
            ms = ", ".join(f"{p} {_ms(rec['passes'].get(p, {}).get('gpu_ms_median'))}"
                           for p in SERIES)
            print(f"[{k}/{len(plan)}] {label}: {ms} ({rec['wall_s']:.1f} s)", flush=True)
        records.append(rec)
    return records


# ---------------------------------------------------------------------------------------------
# the report


def _label(p: dict[str, Any]) -> str:
    w, h = p["size"]
    return (f"{w}x{h}, {p['instances']:,} x {4 * p['n'] ** 2:,} tris, textures "
            f"{'on' if p['textures'] else 'off'}")


def _clocks(records: list[dict[str, Any]]) -> str:
    """SM clocks after each point's frames (range over points), or why there are none."""
    sm = [g["sm_mhz"] for r in records for g in r.get("gpu_clocks") or [] if g.get("sm_mhz")]
    top = {g["max_sm_mhz"] for r in records for g in r.get("gpu_clocks") or []
           if g.get("max_sm_mhz")}
    if not sm:
        return NO_CLOCKS
    return (f"SM {min(sm)}-{max(sm)} MHz after the points' frames (max "
            f"{', '.join(map(str, sorted(top))) or '?'} MHz; nvidia-smi, every GPU it lists)")


def _load(records: list[dict[str, Any]]) -> str:
    loads = [x for r in records for x in r.get("loadavg", [])]
    return f"{min(loads):.2f}-{max(loads):.2f}" if loads else "?"


def _ratio(a: float | None, b: float | None) -> str:
    return f"{a / b:.2f}x" if a and b else "-"


def _ms(v: float | None) -> str:
    return "-" if v is None else f"{v:.3f}"


def _x(value: Any) -> float:
    """A point's position on its axis's chart."""
    return value[0] * value[1] if isinstance(value, tuple | list) else float(value)


def _axis_value(axis: str, rec: dict[str, Any]) -> str:
    v = rec[axis]
    if axis == "size":
        return f"{v[0]}x{v[1]}"
    if axis == "n":
        return f"{4 * v * v:,}"
    if axis == "textures":
        return "on" if v else "off"
    return f"{v:,}"


def axis_rows(records: list[dict[str, Any]], axis: str) -> list[dict[str, Any]]:
    return sorted((r for r in records if axis in r["axes"]), key=lambda r: _x(r[axis]))


def report(records: list[dict[str, Any]], meta: dict[str, Any], charts: list[str],
           notes: list[str]) -> str:
    first = next((r for r in records if r.get("device")), {})
    base = meta["grid"]["base"]
    lines = ["# G-buffer scaling curves (bench_scaling.py)", "",
             f"{first.get('device', '?')} ({first.get('driver', '?')}), backend "
             f"`{meta['backend']}`; rfw `{meta['env']['rfw_commit']}`; CPU "
             f"{meta['env']['cpu']}; grid `{meta['grid_name']}`; base point "
             f"{_label({**base, 'axes': []})}; {meta['frames']} timed frames after "
             f"{meta['warmup']} (fewer for huge instance counts: see the frames column); "
             f"{meta['total_s']:.0f} s in all.", "", f"GPU clocks: {_clocks(records)}.", "",
             "GPU ms: median over the timed frames (timestamps around each pass). floor: "
             "`depth_prepass` over the same geometry (one pipeline, no fragment shader, no "
             "textures), the cheapest raster pass through rfw's backend; x floor: the "
             "pass's time over the floor's in the same frame. raw_draws, raw_instanced: the "
             "same depth drawn by raw Vulkan outside the frame graph (`raw_floor.py`: a draw "
             "per instance, or one instanced draw; no descriptor set), on the same pixels "
             "(checked per point); floor x raw_instanced: what rfw's way of drawing costs "
             "over the least. shadow draws into its own 2048² map whatever the resolution.",
             "", f"Host load (1-minute average) over the points: {_load(records)} on "
             f"{os.cpu_count()} CPUs (on a CPU driver other work shows in the GPU times).",
             ""]
    lines += notes
    for axis in AXES:
        rows = axis_rows(records, axis)
        if not rows:
            continue
        lines += ["", f"## {AXIS_TITLES[axis]}", "",
                  "| " + " | ".join([axis if axis != "n" else "triangles", "triangles total",
                                      *(f"{p} ms" for p in SERIES),
                                      *(f"{p} x floor" for p in RASTER),
                                      "floor x raw_instanced", "frames"]) + " |",
                  "|" + "---|" * (4 + len(SERIES) + len(RASTER))]
        for r in rows:
            if "passes" not in r:
                lines.append(f"| {_axis_value(axis, r)} | | "
                             f"{r.get('error') or 'skipped: ' + r.get('skipped', '?')} |")
                continue
            med = {p: r["passes"].get(p, {}).get("gpu_ms_median") for p in SERIES}
            ratio = [_ratio(med[p], med["floor"]) for p in RASTER]
            lines.append("| " + " | ".join([_axis_value(axis, r), f"{r['triangles']:,}",
                                             *(_ms(med[p]) for p in SERIES), *ratio,
                                             _ratio(med["floor"], med["raw_instanced"]),
                                             str(r["frames"])]) + " |")
    if charts:
        lines += ["", "## Charts", ""] + [f"![{c}]({c})" for c in charts]
    return "\n".join(lines) + "\n"


def charts(records: list[dict[str, Any]], out: Path) -> tuple[list[str], list[str]]:
    """One PNG per axis: GPU ms of each pass (log-log where the axis spans decades)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        import matplotlib.ticker
    except ImportError:
        return [], ["", "No charts: matplotlib is not installed."]
    names = []
    for axis in AXES:
        rows = [r for r in axis_rows(records, axis) if "passes" in r]
        if len(rows) < 2:
            continue
        fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=110)
        xs = [_x(r[axis]) if axis != "n" else float(r["triangles"]) / r["instances"]
              for r in rows]
        for p in SERIES:
            ys = [r["passes"].get(p, {}).get("gpu_ms_median") for r in rows]
            if all(y is None for y in ys):
                continue
            if axis == "textures":
                ax.bar([f"{p}\n{'on' if r['textures'] else 'off'}" for r in rows], ys)
            else:
                ax.plot(xs, ys, marker="o", label=p,
                        linestyle=":" if p in RAW else "--" if p == "floor" else "-")
        if axis != "textures":
            ax.set_xscale("log")
            ax.set_yscale("log")
            # one label per measured value, none between
            ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
            ax.set_xticks(xs, [_axis_value(axis, r) for r in rows],
                          rotation=30 if axis == "size" else 0)
            ax.legend()
        ax.set_xlabel(AXIS_TITLES[axis])
        ax.set_ylabel("GPU ms (median)")
        ax.set_title(f"GPU ms against {AXIS_TITLES[axis]}")
        ax.grid(True, which="both", alpha=0.3)
        fig.tight_layout()
        name = f"scaling_{axis}.png"
        fig.savefig(out / name)
        plt.close(fig)
        names.append(name)
    return names, []


# ---------------------------------------------------------------------------------------------
# main


def _device_type(backend: str) -> str:
    if backend != "vk":
        return "unknown"
    from vkext.device import VkDevice

    dev = VkDevice()
    try:
        return dev.device_type
    finally:
        dev.destroy()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=str(ROOT / "out" / "scaling"), help="folder for the "
                    "JSON, the report and the charts (default: out/scaling)")
    ap.add_argument("--backend", default="vk", choices=("vk", "wgpu"))
    ap.add_argument("--grid", default="auto", choices=("auto", *GRIDS),
                    help="full (a GPU), reduced (lavapipe), auto: by the Vulkan device type")
    ap.add_argument("--axes", default=",".join(AXES),
                    help=f"comma-separated, of {', '.join(AXES)} (default: all)")
    ap.add_argument("--frames", type=int, help="timed frames per point (default: the grid's)")
    ap.add_argument("--warmup", type=int, help="untimed frames first (default: the grid's)")
    ap.add_argument("--budget", type=float, metavar="SECONDS",
                    help="start no point that would likely end after SECONDS")
    ap.add_argument("--timeout", type=float, default=600.0,
                    help="seconds one point's process may take (default: 600)")
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        return worker(json.loads(args.worker))
    axes = [a.strip() for a in args.axes.split(",") if a.strip()]
    for a in axes:
        if a not in AXES:
            ap.error(f"unknown axis '{a}' (known: {', '.join(AXES)})")
    for key, lo in (("frames", 1), ("warmup", 0)):
        v = getattr(args, key)
        if v is not None and not lo <= v <= 10_000:
            ap.error(f"--{key} must be {lo}..10000, got {v}")
    grid_name = args.grid
    if grid_name == "auto":
        grid_name = "reduced" if _device_type(args.backend) == "cpu" else "full"
    grid = GRIDS[grid_name]
    frames = args.frames or grid["frames"]
    warmup = grid["warmup"] if args.warmup is None else args.warmup
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    config = out / "scaling.toml"
    config.write_text(GRAPH)
    env = environment()
    plan = points(grid, axes)
    print(f"{len(plan)} points ({grid_name} grid, backend {args.backend}), {frames} frames "
          f"after {warmup}; {env['cpu']}; rfw {env['rfw_commit']}", flush=True)
    t0 = time.perf_counter()
    records = sweep(plan, config, backend=args.backend, frames=frames, warmup=warmup,
                    budget=args.budget, timeout=args.timeout)
    meta = {"backend": args.backend, "grid_name": grid_name, "grid": grid, "frames": frames,
            "warmup": warmup, "env": env, "total_s": time.perf_counter() - t0,
            "python": platform.python_version(), "loadavg": os.getloadavg()}
    names, notes = charts(records, out)
    skipped = [r for r in records if "skipped" in r]
    failed = [r for r in records if "error" in r]
    if skipped:
        notes.append(f"\n**{len(skipped)} of {len(records)} points skipped by --budget "
                     f"{args.budget:g} s**: " + "; ".join(_label(r) for r in skipped) + ".")
    if failed:
        notes.append(f"\n**{len(failed)} points failed**: " + "; ".join(
            f"{_label(r)}: {r['error']}" for r in failed) + ".")
    text = report(records, meta, names, notes)
    (out / "scaling.md").write_text(text)
    (out / "scaling.json").write_text(json.dumps({**meta, "points": records}, default=list,
                                                 indent=1))
    print()
    print(text)
    print(f"wrote {out / 'scaling.md'}, {out / 'scaling.json'} and {len(names)} charts")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
