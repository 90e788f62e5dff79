"""The host's fixed cost per frame: wall time of a frame minus the time spent waiting for
the GPU (fence waits, timestamp reads that wait, readback mappings).

    .venv/bin/python benchmarks/bench_frame_host.py [--variants flat@vk deferred_vis@vk flat
        deferred] [--scene default] [--size 16x16] [--frames 300] [--warmup 20] [--repeat 3]
        [--trees DIR ...] [--profile K] [--out out/bench_frame_host.json]

Each variant (``config`` or ``config@backend``) is opened once and run in blocks of
``--frames`` frames after ``--warmup`` (frames in flight as configured, default 2). Per
block: wall ms per frame (``run``, the final drain included), wait ms per frame (vk: the
executor's fence waits and waiting timestamp reads, and any other ``vkWaitForFences``; wgpu:
the frame slot's wait for its readback mapping), host ms = wall - wait, the median GPU ms
of a frame (sum of the passes' timestamps) and the CPU record ms (sum of the passes'). On
lavapipe the GPU is the same CPU, so measure at a tiny size on a small scene (``--scene
stress:1``): the host's cost then is most of the frame.

``--trees A B``: run the whole measurement once per tree per repeat, in subprocesses that
import rfw from that tree (e.g. a ``git archive`` of an older commit), in an order that
alternates per repeat: before and after in the same run. Results are JSON lines.
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
from pathlib import Path

ROOT = Path(os.environ.get("RFW_TREE") or Path(__file__).resolve().parents[1])
sys.path.insert(0, str(ROOT))


def _timed(owner, name: str, waited: list[float]) -> None:
    """Wrap ``owner.name`` so the time spent inside it adds to ``waited[0]``."""
    real = getattr(owner, name)

    def wrapper(*args, **kwargs):
        t = time.perf_counter()
        try:
            return real(*args, **kwargs)
        finally:
            waited[0] += time.perf_counter() - t

    setattr(owner, name, wrapper)


def count_waits(backend: str) -> list[float]:
    """Seconds spent in the backend's GPU waits from now on (a one-element list)."""
    waited = [0.0]
    if backend == "vk":
        import vkext.executor as ex
        from vkext.consts import vk

        for owner, name in ((vk, "vkWaitForFences"), (vk, "vkGetQueryPoolResults"),
                            (ex, "vk_wait"), (ex, "vk_query")):
            if hasattr(owner, name):  # an older tree calls the wrapper only
                _timed(owner, name, waited)
    else:
        from rfw.backends.wgpu.timestamps import FrameSlot

        _timed(FrameSlot, "wait", waited)
    return waited


def _profiled(run, frames: int, top: int) -> list[list]:
    """Run ``run(frames)`` under cProfile; the ``top`` functions by own time, per frame."""
    import cProfile
    import pstats

    prof = cProfile.Profile()
    prof.runcall(run, frames)
    stats = pstats.Stats(prof).stats
    rows = sorted(stats.items(), key=lambda kv: kv[1][2], reverse=True)[:top]
    return [[f"{Path(f).name}:{line}:{name}", calls / frames, tt * 1e3 / frames,
             ct * 1e3 / frames] for (f, line, name), (_, calls, tt, ct, _) in rows]


def measure(variant: str, size: str, scene_name: str, frames: int, warmup: int,
            profile: int = 0) -> dict:
    from rfw.config import apply_overrides, build, load_config
    from rfw.frame import camera_for, load_scene_for, open_frame
    from rfw.scene import load_scene

    config, _, backend = variant.partition("@")
    backend = backend or "wgpu"
    waited = count_waits(backend)
    cfg = apply_overrides(load_config(ROOT / "configs" / f"{config}.toml"), [f"size={size}"])
    scene = load_scene_for(cfg) if scene_name == "default" else load_scene(scene_name)
    frame = open_frame(build(cfg), backend, scene=scene, camera=camera_for(cfg, scene))
    try:
        frame.run(warmup)
        frame.clear_timings()
        waited[0] = 0.0
        t = time.perf_counter()
        frame.run(frames)
        wall = (time.perf_counter() - t) * 1e3 / frames
        wait = waited[0] * 1e3 / frames
        top = _profiled(frame.run, frames, profile) if profile else None
        timings = [t for ex in frame.executors.values() for t in ex.timings.values()]
        gpu = [sum(v) for v in zip(*(t.gpu_ms for t in timings if t.gpu_ms), strict=True)]
        record = [sum(v) for v in zip(*(t.cpu_ms for t in timings if t.cpu_ms), strict=True)]
    finally:
        frame.destroy()
    return {"variant": variant, "size": size, "scene": scene_name, "frames": frames,
            "wall_ms": wall, "wait_ms": wait, "host_ms": wall - wait,
            "gpu_ms": statistics.median(gpu) if gpu else None,
            "record_ms": statistics.median(record) if record else None,
            **({"profile": top} if top else {})}


def _in_tree(tree: str, args: argparse.Namespace) -> list[dict]:
    cmd = [sys.executable, __file__, "--variants", *args.variants, "--size", args.size,
           "--scene", args.scene, "--frames", str(args.frames), "--warmup", str(args.warmup),
           "--repeat", "1"]
    env = {**os.environ, "RFW_TREE": str(Path(tree).resolve()),
           "PYTHONPATH": os.pathsep.join([str(Path(tree).resolve()),
                                          os.environ.get("PYTHONPATH", "")])}
    out = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout
    return [{**json.loads(line), "tree": tree} for line in out.splitlines() if line.strip()]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--variants", nargs="+",
                    default=["flat@vk", "deferred_vis@vk", "flat", "deferred"])
    ap.add_argument("--scene", default="default")
    ap.add_argument("--size", default="16x16")
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--warmup", type=int, default=20)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--trees", nargs="*", default=[])
    ap.add_argument("--out", type=Path)
    ap.add_argument("--profile", type=int, default=0, metavar="K",
                    help="after each block, run it again under cProfile and add the K "
                         "functions of most own time (calls, own ms and total ms per frame)")
    args = ap.parse_args()
    rows = []
    for r in range(args.repeat):
        if args.trees:  # before and after alternate: neither always runs first
            order = args.trees if r % 2 == 0 else args.trees[::-1]
            for tree in order:
                rows += [{**row, "repeat": r} for row in _in_tree(tree, args)]
        else:
            rows += [{**measure(v, args.size, args.scene, args.frames, args.warmup,
                                    args.profile),
                      "repeat": r} for v in args.variants]
    host = {"host": platform.node(), "python": platform.python_version()}
    text = "\n".join(json.dumps({**row, **host}) for row in rows)
    print(text)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
