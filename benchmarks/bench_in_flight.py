"""Frames in flight: wall time per frame against GPU time, with 1 and with 2 frames in flight.

    .venv/bin/python benchmarks/bench_in_flight.py [--variants flat flat@vk deferred deferred@vk]
        [--size 1280x720] [--frames 60] [--warmup 5] [--repeat 3] [--in-flight 1 2]
        [--out out/bench_in_flight.json]

Each variant (``config`` or ``config@backend``) is opened once, on the default scene (the
courtyard), and run in blocks: per repeat one block per frames-in-flight setting, in an order
that rotates per repeat, on the same executor (``keep_in_flight``), so both settings share
device, pipelines and caches. A block runs ``--warmup`` frames, then ``--frames`` timed ones;
its wall ms per frame is the block's wall time over its frames, the final drain included
(``run`` returns with its frames done), and its GPU ms per frame the median over frames of
the sum of the passes' timestamps. The report gives per setting the medians over repeats of
wall ms, GPU ms, wall/GPU (per block) and the wall ratio to the first setting's block of the
same repeat (by default 1 frame in flight, measured in the same run).

On lavapipe the "GPU" is the same CPU cores that record, so little can overlap; the number
that matters is the GPU machine's. There, after ``source benchmarks/device_env.sh``, it runs
without network.
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from rfw.config import apply_overrides, build, load_config  # noqa: E402
from rfw.frame import camera_for, load_scene_for, open_frame  # noqa: E402


def _median(values: list[float]) -> float | None:
    return statistics.median(values) if values else None


def _gpu_per_frame(frame, frames: int) -> list[float]:
    """Per timed frame, the sum of the passes' GPU ms (every side of a mixed frame)."""
    lists = [t.gpu_ms[-frames:] for ex in frame.executors.values()
             for t in ex.timings.values() if t.gpu_ms]
    return [sum(v) for v in zip(*lists, strict=True)] if lists else []


def block(frame, k: int, frames: int, warmup: int) -> dict:
    """One block of ``frames`` timed frames with ``k`` frames in flight."""
    for ex in frame.executors.values():
        ex.keep_in_flight(k)
    frame.run(warmup)
    frame.clear_timings()
    t = time.perf_counter()
    frame.run(frames)  # returns with its frames done: the drain is in the wall time
    wall = (time.perf_counter() - t) * 1e3 / frames
    gpu = _median(_gpu_per_frame(frame, frames))
    return {"in_flight": k, "wall_ms": wall, "gpu_ms": gpu,
            "wall_over_gpu": wall / gpu if gpu else None}


def bench_variant(variant: str, size: str, ks: list[int], frames: int, warmup: int,
                  repeat: int, scene) -> dict:
    config, _, backend = variant.partition("@")
    cfg = apply_overrides(load_config(ROOT / "configs" / f"{config}.toml"), [f"size={size}"])
    backend = backend or "wgpu"
    frame = open_frame(build(cfg), backend, scene=scene, camera=camera_for(cfg, scene),
                       size=cfg.size)
    try:
        described = {b: frame.backends[b].describe(frame.devices[b]) for b in frame.executors}
        blocks = []
        for r in range(repeat):
            order = ks[r % len(ks):] + ks[:r % len(ks)]  # rotate who goes first
            blocks += [{"repeat": r, **block(frame, k, frames, warmup)} for k in order]
    finally:
        frame.destroy()
    out = {"variant": variant, "config": config, "backend": backend, "size": size,
           "frames": frames, "warmup": warmup, "repeat": repeat, "devices": described,
           "blocks": blocks, "summary": {}}
    first = {b["repeat"]: b["wall_ms"] for b in blocks if b["in_flight"] == ks[0]}
    for k in ks:
        mine = [b for b in blocks if b["in_flight"] == k]
        ratios = [b["wall_over_gpu"] for b in mine if b["wall_over_gpu"] is not None]
        out["summary"][str(k)] = {
            "wall_ms": _median([b["wall_ms"] for b in mine]),
            "gpu_ms": _median([b["gpu_ms"] for b in mine if b["gpu_ms"] is not None]),
            # per block, then the median: a loaded host moves both together
            "wall_over_gpu": _median(ratios),
            # paired with the first setting's block of the same repeat
            "wall_vs_first": _median([b["wall_ms"] / first[b["repeat"]] for b in mine])}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--variants", nargs="+",
                    default=["flat", "flat@vk", "deferred", "deferred@vk"])
    ap.add_argument("--size", default="1280x720")
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--warmup", type=int, default=5)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--in-flight", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--scene", default="default")
    ap.add_argument("--out", default="out/bench_in_flight.json")
    args = ap.parse_args(argv)
    cfg = apply_overrides(load_config(ROOT / "configs" / "flat.toml"), [f"scene={args.scene}"])
    scene = load_scene_for(cfg)
    results = []
    for v in args.variants:
        res = bench_variant(v, args.size, args.in_flight, args.frames, args.warmup,
                            args.repeat, scene)
        results.append(res)
        dev = " + ".join(f"{d['device']} ({d['driver']})" for d in res["devices"].values())
        print(f"{v} at {args.size} on {dev}, {args.frames} frames x {args.repeat}:")
        for k, s in res["summary"].items():
            ratio = "-" if s["wall_over_gpu"] is None else f"{s['wall_over_gpu']:.2f}x"
            gpu = "-" if s["gpu_ms"] is None else f"{s['gpu_ms']:.3f}"
            print(f"  in flight {k}: wall {s['wall_ms']:.3f} ms, GPU {gpu} ms, wall/GPU "
                  f"{ratio}, wall vs in flight {args.in_flight[0]}: {s['wall_vs_first']:.3f}x")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"host": platform.node(), "cpu": platform.processor(),
                               "scene": scene.name, "results": results}, indent=2) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
