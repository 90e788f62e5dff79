"""Frame-graph compiler benchmark: compile times and memory plans (not a test).

    .venv/bin/python benchmarks/bench_graph.py [--repeat 7] [--out out/bench_graph.jsonl]

Prints two tables (compile time; memory of the 28 Raptor graphs at their own size and at
3840x2160) and writes one JSON line per measurement. Times are medians over --repeat runs
with the compile cache cleared before each run; the machine and Python are recorded.
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from rfw.graph import compile, load_graph  # noqa: E402
from rfw.graph.compile import _CACHE, _MEMORY_CACHE  # noqa: E402
from rfw.graph.synthetic import synthetic_graph  # noqa: E402

RAPTOR = sorted((ROOT / "tests" / "data" / "raptor").glob("*.json"))
MIB = 1 << 20


def _time(fn, repeat: int) -> tuple[float, float, float]:
    runs = []
    for _ in range(repeat):
        _CACHE.clear()
        _MEMORY_CACHE.clear()
        t = time.perf_counter()
        fn()
        runs.append(time.perf_counter() - t)
    runs.sort()
    return statistics.median(runs), runs[0], runs[-1]


def _env() -> dict:
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                                capture_output=True, text=True, check=False).stdout.strip()
    except OSError:
        commit = ""
    return {"commit": commit, "python": platform.python_version(),
            "machine": platform.machine(), "cpu": platform.processor() or platform.machine()}


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--out", default=str(ROOT / "out" / "bench_graph.jsonl"))
    args = ap.parse_args()
    env = _env()
    records = []

    print(f"compile time (median of {args.repeat}, cache cleared; min..max)  "
          f"python {env['python']} on {env['machine']}")
    print(f"{'graph':<36} {'passes':>6} {'median ms':>10} {'min..max ms':>16}")
    for path in RAPTOR:
        graph = load_graph(path)
        med, lo, hi = _time(lambda g=graph: compile(g), args.repeat)
        print(f"{path.name:<36} {len(graph.passes):>6} {med * 1e3:>10.3f} "
              f"{lo * 1e3:>7.3f}..{hi * 1e3:<7.3f}")
        records.append({"kind": "compile_time", "graph": path.name, "passes": len(graph.passes),
                        "median_s": med, "min_s": lo, "max_s": hi})
    for n in (100, 1000, 10000):
        graph = synthetic_graph(n, seed=1)
        repeat = args.repeat if n <= 1000 else max(3, args.repeat // 2)
        med, lo, hi = _time(lambda g=graph: compile(g), repeat)
        c = compile(graph)
        print(f"{f'synthetic_{n}':<36} {n:>6} {med * 1e3:>10.3f} "
              f"{lo * 1e3:>7.3f}..{hi * 1e3:<7.3f}")
        records.append({"kind": "compile_time", "graph": f"synthetic_{n}", "passes": n,
                        "median_s": med, "min_s": lo, "max_s": hi,
                        "transient_over_lower_bound": c.transient_bytes / c.lower_bound_bytes})
    # recompiling an unchanged graph is a cache lookup
    graph = synthetic_graph(1000, seed=1)
    compile(graph)
    t = time.perf_counter()
    for _ in range(1000):
        compile(graph)
    cached = (time.perf_counter() - t) / 1000
    cold = next(r["median_s"] for r in records if r["graph"] == "synthetic_1000")
    print(f"recompile unchanged synthetic_1000: {cached * 1e6:.2f} us "
          f"({cold / cached:,.0f}x faster than a cold compile)")
    records.append({"kind": "recompile_cached", "graph": "synthetic_1000", "mean_s": cached,
                    "cold_over_cached": cold / cached})

    print()
    print("memory (MiB): transient = aliased heaps; lower bound = largest live total; "
          "raptor = Raptor's same-description reuse")
    head = f"{'graph':<36} {'size':>9} {'transient':>9} {'unaliased':>9} {'lower':>7} " \
           f"{'raptor':>7} {'T/LB':>6} {'T/raptor':>8}"
    print(head)
    worst = 0.0
    for path in RAPTOR:
        graph = load_graph(path)
        for size in (None, (3840, 2160)):
            c = compile(graph, size)
            ratio = c.transient_bytes / c.lower_bound_bytes if c.lower_bound_bytes else 1.0
            worst = max(worst, ratio)
            vs = c.transient_bytes / c.raptor_reuse_bytes if c.raptor_reuse_bytes else 1.0
            label = "own" if size is None else f"{size[0]}x{size[1]}"
            print(f"{path.name:<36} {label:>9} {c.transient_bytes / MIB:>9.2f} "
                  f"{c.unaliased_bytes / MIB:>9.2f} {c.lower_bound_bytes / MIB:>7.2f} "
                  f"{c.raptor_reuse_bytes / MIB:>7.2f} {ratio:>6.3f} {vs:>8.3f}")
            records.append({"kind": "memory", "graph": path.name, "size": list(c.size),
                            "transient_bytes": c.transient_bytes,
                            "unaliased_bytes": c.unaliased_bytes,
                            "lower_bound_bytes": c.lower_bound_bytes,
                            "raptor_reuse_bytes": c.raptor_reuse_bytes})
    print(f"worst transient / lower bound over all Raptor graphs and sizes: {worst:.3f}")

    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with out.open("w") as f:
        for r in records:
            f.write(json.dumps({**env, **r}) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
