"""Host time to record a frame: CPU record ms per pass, per backend (not a test).

    .venv/bin/python benchmarks/bench_record.py [--backend wgpu|vk|both] [--frames 10]
        [--sizes 320x180,640x360] [--copies 4] [--configs deferred,forward,...]
        [--out out/bench_record.json]

For each backend and config (default: deferred, forward, forward_prepass and
deferred_ssao_shadows on the courtyard) the script renders ``--frames`` frames after one
warm-up frame through ``rfw.render.render`` and reads timings.json's ``cpu_ms`` per pass (the
median over the frames of the time ``Pass.record`` took, which is all the host does per pass
on both backends). It does so at every ``--sizes`` entry: recording should not depend on the
size, and two sizes show whether it does. Then, at the first size, the courtyard with every
instance repeated ``--copies`` times (each copy moved sideways by the scene's width, so draws
and triangles grow together) gives the growth per extra instance: the frame's record ms
difference over the instances added, in microseconds.

Prints a table and writes one JSON document (``--out``) with the machine, the device and
driver of each backend, every row and the growth. GPU times are listed beside, but a CPU
driver (lavapipe) shares the cores with the recording, so only ratios in one run compare.
On the GPU machine, after ``source benchmarks/device_env.sh``, it runs without network.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from rfw.config import apply_overrides, load_config  # noqa: E402
from rfw.render import render  # noqa: E402
from rfw.scene import Instance, Scene, default_scene  # noqa: E402

CONFIGS = ("deferred", "forward", "forward_prepass", "deferred_ssao_shadows")
BACKENDS = ("wgpu", "vk")


def repeated(scene: Scene, copies: int) -> Scene:
    """``scene`` with every instance drawn ``copies`` times, copy k moved k scene widths
    along x (the camera and lights stay: the extra copies cost recording, not pixels)."""
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


def measure(backend: str, config: str, size: tuple[int, int], scene: Scene,
            frames: int) -> dict:
    cfg = apply_overrides(load_config(ROOT / "configs" / f"{config}.toml"),
                          [f"size={size[0]}x{size[1]}"])
    t = time.perf_counter()
    result = render(cfg, scene=scene, frames=frames, backend=backend)
    wall = time.perf_counter() - t
    tm = result.timings
    passes = {p["name"]: p["cpu_ms"] for p in tm["passes"]}
    return {"backend": backend, "config": config, "size": list(size), "frames": frames,
            "instances": len(scene.instances), "triangles": tm["triangles"],
            "device": tm["device"], "driver": tm["driver"],
            "cpu_ms": passes, "cpu_ms_frame": sum(v or 0.0 for v in passes.values()),
            "gpu_ms_total": tm["gpu_ms_total"], "run_s": wall}


def growth(base: dict, more: dict) -> float:
    """Microseconds of record time per extra instance, for the whole frame."""
    extra = more["instances"] - base["instances"]
    return (more["cpu_ms_frame"] - base["cpu_ms_frame"]) * 1e3 / extra


def table(rows: list[dict], grows: list[dict]) -> str:
    out = [f"{'backend':<6} {'config':<22} {'size':>9} {'inst':>6} {'record ms':>10} "
           f"{'gpu ms':>9}  per pass (cpu ms)"]
    for r in rows:
        per = ", ".join(f"{k} {v:.3f}" for k, v in r["cpu_ms"].items() if v is not None)
        out.append(f"{r['backend']:<6} {r['config']:<22} {r['size'][0]:>4}x{r['size'][1]:<4} "
                   f"{r['instances']:>6} {r['cpu_ms_frame']:>10.3f} {r['gpu_ms_total']:>9.3f}"
                   f"  {per}")
    out.append("")
    out.append("growth per extra instance (record time of the whole frame):")
    for g in grows:
        out.append(f"  {g['backend']:<6} {g['config']:<22} {g['us_per_instance']:>8.2f} us "
                   f"({g['instances'][0]} -> {g['instances'][1]} instances)")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--backend", choices=(*BACKENDS, "both"), default="both")
    ap.add_argument("--configs", default=",".join(CONFIGS))
    ap.add_argument("--sizes", default="320x180,640x360")
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--copies", type=int, default=4,
                    help="instance multiplier for the growth rows (1: none)")
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "bench_record.json")
    args = ap.parse_args(argv)
    backends = BACKENDS if args.backend == "both" else (args.backend,)
    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    configs = args.configs.split(",")
    base = default_scene()
    big = repeated(base, args.copies)
    rows, grows = [], []
    for backend in backends:
        for config in configs:
            mine = [measure(backend, config, size, base, args.frames) for size in sizes]
            if args.copies > 1:
                more = measure(backend, config, sizes[0], big, args.frames)
                grows.append({"backend": backend, "config": config,
                              "instances": [mine[0]["instances"], more["instances"]],
                              "us_per_instance": growth(mine[0], more)})
                mine.append(more)
            rows += mine
            print(table(mine, grows[-1:]), flush=True)
    print()
    print(table(rows, grows))
    doc = {"bench": "record", "commit": os.environ.get("RFW_COMMIT") or _commit(),
           "machine": {"cpu": platform.processor() or platform.machine(),
                       "cores": os.cpu_count(), "python": platform.python_version()},
           "rows": rows, "growth": grows}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(doc, indent=2) + "\n")
    print(f"wrote {args.out}")


def _commit() -> str:
    import subprocess

    try:
        return subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                              capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


if __name__ == "__main__":
    main()
