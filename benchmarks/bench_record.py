"""Host time to record a frame: CPU record ms per pass, per backend (not a test).

    .venv/bin/python benchmarks/bench_record.py [--backend wgpu|vk|both] [--frames 10]
        [--sizes 320x180,640x360] [--copies 4] [--cases deferred,meshlet@vk,...]
        [--baseline DIR] [--repeat 1] [--out out/bench_record.json]

Cases (default: every config the issue's record target names) are ``CONFIG``,
``CONFIG:key=value;key=value`` (``--set`` overrides, e.g. ``deferred_ssao_shadows:ao=off``)
and either with ``@wgpu`` or ``@vk`` for one backend only (``meshlet@vk``: it needs Vulkan).
For each backend and case the script renders ``--frames`` frames after one warm-up frame
through ``rfw.render.render`` on the courtyard and reads timings.json's ``cpu_ms`` per pass
(the median over the frames of the time ``Pass.record`` took, which is all the host does per
pass on both backends). It does so at every ``--sizes`` entry: recording should not depend on
the size, and two sizes show whether it does. Then, at the first size, the courtyard with every
instance repeated ``--copies`` times (each copy moved sideways by the scene's width, so draws
and triangles grow together) gives the growth per extra instance: the frame's record ms
difference over the instances added, in microseconds.

Every measurement runs in a process of its own. ``--baseline DIR`` (another checkout of rfw,
e.g. ``git worktree add /tmp/old HEAD~3``) measures the same case with that code right after
each one (``--repeat`` times, interleaved), so both see the same machine load: the table then
gives the ratio new / baseline per case. ``RFW_VK_BUNDLES=0`` in the environment is the vk
backend's own inline baseline.

Prints a table and writes one JSON document (``--out``) with the machine, the device and
driver of each backend, every row (per pass) and the growth. GPU times are listed beside, but
a CPU driver (lavapipe) shares the cores with the recording, so only ratios in one run compare.
On the GPU machine, after ``source benchmarks/device_env.sh``, it runs without network.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

CASES = ("deferred", "forward", "forward_prepass", "deferred_ssao_shadows:ao=on",
         "deferred_ssao_shadows:ao=off", "flat", "meshlet@vk")
BACKENDS = ("wgpu", "vk")


def parse_case(spec: str) -> tuple[str, list[str], str | None]:
    """``CONFIG[:k=v;k=v][@backend]`` -> (config, --set overrides, backend or None)."""
    backend = None
    if "@" in spec:
        spec, backend = spec.rsplit("@", 1)
        if backend not in BACKENDS:
            raise SystemExit(f"bench_record: case '{spec}@{backend}': backend must be one of "
                             f"{', '.join(BACKENDS)}")
    config, _, sets = spec.partition(":")
    return config, [s for s in sets.split(";") if s], backend


def repeated(scene: Any, copies: int) -> Any:
    """``scene`` with every instance drawn ``copies`` times, copy k moved k scene widths
    along x (the camera and lights stay: the extra copies cost recording, not pixels)."""
    from rfw.scene import Instance

    if copies <= 1:
        return scene
    lo, hi = scene.bounds()
    width = float(hi[0] - lo[0]) * 1.1
    out = []
    for k in range(copies):
        shift = np.identity(4, np.float32)
        shift[0, 3] = k * width
        out += [Instance(i.mesh, (shift @ i.transform).astype(np.float32),
                         f"{i.name}#{k}" if k else i.name) for i in scene.instances]
    return replace(scene, instances=out, name=f"{scene.name} x{copies}")


def measure_here(job: dict) -> dict:
    """One measurement in this process, with rfw imported from ``job['root']``."""
    sys.path.insert(0, job["root"])
    from rfw.config import apply_overrides, load_config
    from rfw.render import render
    from rfw.scene import default_scene

    size = job["size"]
    cfg = apply_overrides(load_config(Path(job["root"]) / "configs" / f"{job['config']}.toml"),
                          [f"size={size[0]}x{size[1]}", *job["sets"]])
    scene = repeated(default_scene(), job["copies"])
    t = time.perf_counter()
    result = render(cfg, scene=scene, frames=job["frames"], backend=job["backend"])
    wall = time.perf_counter() - t
    tm = result.timings
    passes = {p["name"]: p["cpu_ms"] for p in tm["passes"] if p.get("cpu_ms") is not None}
    return {"instances": len(scene.instances), "triangles": tm["triangles"],
            "device": tm["device"], "driver": tm["driver"], "cpu_ms": passes,
            "cpu_ms_frame": sum(passes.values()), "gpu_ms_total": tm["gpu_ms_total"],
            "run_s": wall}


def measure(job: dict) -> dict:
    """One measurement in a process of its own (its crash is this row's error)."""
    # the checkout first, then what the environment adds (the GPU machine's wheels)
    path = os.pathsep.join(p for p in (job["root"], os.environ.get("PYTHONPATH")) if p)
    proc = subprocess.run([sys.executable, __file__, "--one", json.dumps(job)],
                          capture_output=True, text=True, cwd=job["root"],
                          env={**os.environ, "PYTHONPATH": path})
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    if proc.returncode or not lines:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or ["no output"]
        return {"error": f"exit {proc.returncode}: {tail[0]}"}
    return json.loads(lines[-1])


def run_case(backend: str, case: str, size: tuple[int, int], copies: int, frames: int,
             baseline: str | None, repeat: int) -> dict:
    """The row of one case: medians over ``repeat`` runs, new and baseline interleaved."""
    config, sets, _ = parse_case(case)
    job = {"backend": backend, "config": config, "sets": sets, "size": list(size),
           "copies": copies, "frames": frames}
    runs: dict[str, list[dict]] = {"new": [], "baseline": []}
    for _ in range(repeat):
        runs["new"].append(measure({**job, "root": str(ROOT)}))
        if baseline:
            runs["baseline"].append(measure({**job, "root": baseline}))
    row = {"backend": backend, "case": case, "size": list(size), "frames": frames}
    row.update(_median(runs["new"]))
    if baseline:
        row["baseline"] = _median(runs["baseline"])
    return row


def _median(runs: list[dict]) -> dict:
    """The first good run's facts with every number the median over the good runs."""
    good = [r for r in runs if "error" not in r]
    if not good:
        return {"error": runs[0]["error"]}
    out = dict(good[0])
    out["cpu_ms"] = {k: statistics.median(r["cpu_ms"].get(k, 0.0) for r in good)
                     for k in good[0]["cpu_ms"]}
    for k in ("cpu_ms_frame", "gpu_ms_total", "run_s"):
        out[k] = statistics.median(r[k] for r in good)
    out["runs"] = len(good)
    return out


def growth(base: dict, more: dict) -> float:
    """Microseconds of record time per extra instance, for the whole frame."""
    extra = more["instances"] - base["instances"]
    return (more["cpu_ms_frame"] - base["cpu_ms_frame"]) * 1e3 / extra


def table(rows: list[dict], grows: list[dict]) -> str:
    out = [f"{'backend':<6} {'case':<30} {'size':>9} {'inst':>6} {'record ms':>10} "
           f"{'baseline':>9} {'ratio':>6} {'gpu ms':>9}  per pass (cpu ms; baseline)"]
    for r in rows:
        if "error" in r:
            out.append(f"{r['backend']:<6} {r['case']:<30} error: {r['error']}")
            continue
        b = r.get("baseline") or {}
        have = "error" not in b and b
        per = ", ".join(f"{k} {v:.3f}" + (f" ({b['cpu_ms'][k]:.3f})" if have and k in
                                           b["cpu_ms"] else "")
                        for k, v in r["cpu_ms"].items())
        base = f"{b['cpu_ms_frame']:>9.3f}" if have else f"{'-':>9}"
        ratio = f"{r['cpu_ms_frame'] / b['cpu_ms_frame']:>6.2f}" if have and \
            b["cpu_ms_frame"] else f"{'-':>6}"
        out.append(f"{r['backend']:<6} {r['case']:<30} {r['size'][0]:>4}x{r['size'][1]:<4} "
                   f"{r['instances']:>6} {r['cpu_ms_frame']:>10.3f} {base} {ratio} "
                   f"{r['gpu_ms_total']:>9.3f}  {per}")
    out.append("")
    out.append("growth per extra instance (record time of the whole frame; baseline):")
    for g in grows:
        base = f" ({g['baseline_us_per_instance']:.2f} us)" \
            if g.get("baseline_us_per_instance") is not None else ""
        out.append(f"  {g['backend']:<6} {g['case']:<30} {g['us_per_instance']:>8.2f} us"
                   f"{base} ({g['instances'][0]} -> {g['instances'][1]} instances)")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--backend", choices=(*BACKENDS, "both"), default="both")
    ap.add_argument("--cases", "--configs", default=",".join(CASES))
    ap.add_argument("--sizes", default="320x180,640x360")
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--copies", type=int, default=4,
                    help="instance multiplier for the growth rows (1: none)")
    ap.add_argument("--baseline", type=Path, default=None,
                    help="another rfw checkout measured right after each case (ratios)")
    ap.add_argument("--repeat", type=int, default=1, help="runs per case (medians)")
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "bench_record.json")
    ap.add_argument("--one", help=argparse.SUPPRESS)  # a child: one measurement as JSON
    args = ap.parse_args(argv)
    if args.one:
        print(json.dumps(measure_here(json.loads(args.one))))
        return
    backends = BACKENDS if args.backend == "both" else (args.backend,)
    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    cases = [c for c in args.cases.split(",") if c]
    baseline = str(args.baseline.resolve()) if args.baseline else None
    rows, grows = [], []
    for backend in backends:
        for case in cases:
            only = parse_case(case)[2]
            if only is not None and only != backend:
                continue
            mine = [run_case(backend, case, size, 1, args.frames, baseline, args.repeat)
                    for size in sizes]
            if args.copies > 1:
                more = run_case(backend, case, sizes[0], args.copies, args.frames, baseline,
                                args.repeat)
                if "error" not in more and "error" not in mine[0]:
                    g = {"backend": backend, "case": case,
                         "instances": [mine[0]["instances"], more["instances"]],
                         "us_per_instance": growth(mine[0], more)}
                    b0, b1 = mine[0].get("baseline"), more.get("baseline")
                    if b0 and b1 and "error" not in b0 and "error" not in b1:
                        g["baseline_us_per_instance"] = growth(b0, b1)
                    grows.append(g)
                mine.append(more)
            rows += mine
            print(table(mine, [g for g in grows[-1:] if g["case"] == case
                               and g["backend"] == backend]), flush=True)
    print()
    print(table(rows, grows))
    doc = {"bench": "record", "commit": os.environ.get("RFW_COMMIT") or _commit(ROOT),
           "baseline": {"root": baseline, "commit": _commit(Path(baseline))}
           if baseline else None,
           "machine": {"cpu": platform.processor() or platform.machine(),
                       "cores": os.cpu_count(), "python": platform.python_version()},
           "rows": rows, "growth": grows}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(doc, indent=2) + "\n")
    print(f"wrote {args.out}")


def _commit(root: Path) -> str:
    try:
        return subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"],
                              capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


if __name__ == "__main__":
    main()
