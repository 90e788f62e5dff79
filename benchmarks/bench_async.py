"""Async compute on vk: the frame's GPU time with compute beside raster work, and without.

    .venv/bin/python benchmarks/bench_async.py [--configs deferred_ssao_shadows]
        [--size 1280x720] [--frames 60] [--warmup 5] [--repeat 3] [--out out/bench_async.json]

Each repeat renders every config twice on vk, ``async_compute=on`` and ``off``, in an order
that rotates per repeat, in this one process on one device. With two queues passes overlap,
so the per-pass GPU times no longer add up to the frame's: the frame's GPU time here is the
span from a timestamp written before the frame's first graphics batch to one after its last
(which waits for the compute queue), ``vkext.queues.AsyncQueues.frame_gpu_ms``. With the
run option ``frame_span`` (on here, ``RFW_VK_FRAME_SPAN``) the one-queue frame goes through
the same runner as one batch, so both are measured the same way. Also reported: the sum of per-pass GPU medians,
and the wall time per frame over the timed frames (frames in flight as the executor keeps
them), each as a median and as the ratio on/off.

On a device without a second queue ``on`` sends the same batches to the one queue (the plan
is printed: ``mode``); lavapipe runs it, but a CPU driver has no second engine to overlap on,
so only the H200 numbers say what overlap gives. On the GPU machine, after
``source benchmarks/device_env.sh``, it runs without network.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from rfw.config import apply_overrides, build, load_config  # noqa: E402
from rfw.frame import load_scene_for, open_frame  # noqa: E402
from rfw.options import RunOptions  # noqa: E402


def _median(values: list[float]) -> float | None:
    return statistics.median(values) if values else None


def run_once(config: str, mode: str, size: str, frames: int, warmup: int,
             scene: object, options: RunOptions) -> dict:
    cfg = apply_overrides(load_config(ROOT / "configs" / f"{config}.toml"),
                          [f"size={size}", f"async_compute={mode}"])
    frame = open_frame(build(cfg), "vk", scene=scene, options=options)
    try:
        ex = frame.executors["vk"]
        frame.run(warmup)
        t = time.perf_counter()
        frame.run(frames)
        wall = (time.perf_counter() - t) * 1e3 / frames
        ex.drain()
        spans = ex.queues.spans()[warmup:] if ex.queues is not None else []
        passes = {n: _median(t.gpu_ms[warmup:]) for n, t in ex.timings.items()}
        q = ex.plan.queues
        return {"config": config, "async_compute": mode, "mode": q.mode,
                "async_passes": list(q.async_passes()), "order": list(ex.plan.order),
                "device": ex.device.name, "driver": ex.device.driver,
                "frame_gpu_ms": spans, "frame_gpu_ms_median": _median(spans),
                "pass_gpu_ms": passes,
                "pass_sum_ms": sum(v for v in passes.values() if v is not None),
                "wall_ms_per_frame": wall}
    finally:
        frame.destroy()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--configs", default="deferred_ssao_shadows")
    ap.add_argument("--size", default="1280x720")
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--warmup", type=int, default=5)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", default="out/bench_async.json")
    args = ap.parse_args(argv)
    configs = [c for c in args.configs.split(",") if c]
    # this script is an edge: the environment's options (RFW_VK_ASYNC_QUEUE, RFW_GPU, ...),
    # the frame span measured on one queue too
    options = RunOptions.from_env(frame_span=True)
    rows = []
    for config in configs:
        scene = load_scene_for(load_config(ROOT / "configs" / f"{config}.toml"))
        for k in range(args.repeat):
            modes = ["on", "off"] if k % 2 == 0 else ["off", "on"]
            for mode in modes:
                r = run_once(config, mode, args.size, args.frames, args.warmup, scene,
                             options)
                r["repeat"] = k
                rows.append(r)
                print(f"{config} async_compute={mode} ({r['mode']}, async: "
                      f"{','.join(r['async_passes']) or '-'}) #{k}: frame GPU span "
                      f"{r['frame_gpu_ms_median']:.3f} ms, pass sum {r['pass_sum_ms']:.3f} ms, "
                      f"wall {r['wall_ms_per_frame']:.3f} ms/frame", flush=True)
    summary = []
    for config in configs:
        def pick(mode, key, config=config):
            return _median([v for r in rows if r["config"] == config
                            and r["async_compute"] == mode for v in (
                                r[key] if isinstance(r[key], list) else [r[key]])])
        row = {"config": config}
        for key in ("frame_gpu_ms", "pass_sum_ms", "wall_ms_per_frame"):
            on, off = pick("on", key), pick("off", key)
            row[key] = {"on": on, "off": off, "on/off": on / off if on and off else None}
        summary.append(row)
        print(f"{config}: frame GPU span on/off = {row['frame_gpu_ms']['on/off']:.3f} "
              f"({row['frame_gpu_ms']['on']:.3f} / {row['frame_gpu_ms']['off']:.3f} ms); wall "
              f"on/off = {row['wall_ms_per_frame']['on/off']:.3f}")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({
        "machine": {"host": platform.node(), "cpu": platform.processor(),
                    "cpus": os.cpu_count(), "python": sys.version.split()[0],
                    "commit": os.environ.get("RFW_COMMIT")},
        "args": vars(args), "summary": summary, "rows": rows}, indent=1))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
