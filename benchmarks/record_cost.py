"""Host time of each call of an executor's ``record`` (per pass), ``begin_frame`` and
``end_frame``, around the whole method, beside the pass CPU ms rfw reports (not a test).

    python3 benchmarks/record_cost.py TREE FRAMES BACKEND CONFIG WxH

TREE is the tree whose rfw runs (this one, or a ``git archive`` of an earlier commit, first
on PYTHONPATH); it prints one JSON line: ``host_us`` (median per call over the frames after
the 30th, in µs) and ``cpu_us`` (rfw's per-pass CPU ms, mean, in µs). Wrapping the methods
times everything an executor does per pass, wherever its own timer starts and stops, so two
trees whose timed regions differ can be compared. benchmarks/record_cost_ab.sh alternates
two trees.
"""

import json
import statistics
import sys
import time


def main() -> None:
    tree, frames, backend, config, size = (sys.argv[1], int(sys.argv[2]), sys.argv[3],
                                           sys.argv[4], sys.argv[5])
    if backend == "vk":
        from vkext.executor import VkExecutor as Executor
    else:
        try:
            from rfw.backends.wgpu.executor import Executor
        except ImportError:  # a tree from before the wgpu backend's split
            from rfw.backends.wgpu_backend import Executor
    acc: dict[str, list[int]] = {}

    def wrap(meth: str) -> None:
        orig = getattr(Executor, meth)

        def timed(self, *a):
            t = time.perf_counter_ns()
            orig(self, *a)
            acc.setdefault(meth + (":" + a[0] if a else ""), []).append(
                time.perf_counter_ns() - t)

        setattr(Executor, meth, timed)

    for m in ("record", "begin_frame", "end_frame"):
        wrap(m)
    import rfw
    from rfw.config import apply_overrides, load_config

    cfg = apply_overrides(load_config(f"{tree}/configs/{config}.toml"), [f"size={size}"])
    r = rfw.run(cfg, backend=backend, frames=frames)
    out = {n: round(statistics.median(v[30:]) / 1e3, 1) for n, v in acc.items()}
    cpu = {p["name"]: round(p["cpu_ms"] * 1e3, 1) for p in r.timings["passes"]}
    print(json.dumps({"host_us": out, "cpu_us": cpu}))


if __name__ == "__main__":
    main()
