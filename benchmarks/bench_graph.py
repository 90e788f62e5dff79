"""Frame-graph compiler benchmark: compile times and memory plans (not a test).

    .venv/bin/python benchmarks/bench_graph.py [--repeat 7] [--out out/bench_graph.jsonl]
        [--sizes 1000,10000,100000] [--big-mb 50] [--only scaling|raptor]

Prints three tables (compile time; growth with size, from files and in memory; memory of the
28 Raptor graphs at their own size and at 3840x2160) and writes one JSON line per
measurement. Times are medians over --repeat runs with the compile cache cleared before each
run (one run from 100,000 passes on); wall and CPU seconds are both kept, as a busy machine
inflates the first. The machine and Python are recorded.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from rfw.graph import compile, load_graph, loads_raptor, to_toml  # noqa: E402
from rfw.graph.compile import _CACHE, _MEMORY_CACHE  # noqa: E402
from rfw.graph.synthetic import chain_graph, synthetic_graph, to_raptor_json  # noqa: E402

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


def _time_cpu(fn, repeat: int) -> tuple[float, float]:
    """Median wall and CPU seconds of ``fn()`` with the compile caches cleared."""
    wall, cpu = [], []
    for _ in range(repeat):
        _CACHE.clear()
        _MEMORY_CACHE.clear()
        t, c = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    return statistics.median(wall), statistics.median(cpu)


def _scaling_graphs(sizes: list[int], big_mb: float) -> Iterator[tuple[str, int, str]]:
    """(kind, passes, Raptor JSON text): chains and random DAGs, and a DAG of about big_mb;
    made one at a time, as the big ones take a while and hundreds of MB."""
    for n in sizes:
        yield "chain", n, to_raptor_json(chain_graph(n))
        yield "dag", n, to_raptor_json(synthetic_graph(n, seed=1))
    if big_mb > 0:
        probe = len(to_raptor_json(synthetic_graph(2000, seed=1))) / 2000
        n = int(big_mb * 1e6 / probe)
        yield "dag", n, to_raptor_json(synthetic_graph(n, seed=1))


def scaling(sizes: list[int], big_mb: float, repeat: int, env: dict) -> list[dict]:
    """Load + compile from Raptor JSON and from TOML, and compile alone, by size.

    The TOML file is the JSON graph converted (``rfw graph convert``), so all three compile
    the same graph: Raptor declares no outputs, so resources nobody reads live to the end
    of the frame, the hard case for memory placement.
    """
    print(f"growth with size (wall s median of {repeat} below 100k passes, else 1; "
          f"CPU s beside; load average {os.getloadavg()[0]:.1f} at start)")
    print(f"{'graph':<8} {'from':<6} {'passes':>7} {'MB':>6} {'wall s':>8} {'cpu s':>8} "
          f"{'us/pass':>8}")
    records = []
    with tempfile.TemporaryDirectory() as tmp:
        for kind, n, text in _scaling_graphs(sizes, big_mb):
            graph = loads_raptor(text)
            files = {"json": Path(tmp) / f"{kind}_{n}.json", "toml": Path(tmp) / f"{kind}_{n}.toml"}
            files["json"].write_text(text)
            files["toml"].write_text(to_toml(graph))
            r = repeat if n < 100_000 else 1
            runs = {"memory": lambda g=graph: compile(g)}
            for src, path in files.items():
                runs[src] = lambda p=path: compile(load_graph(p))
            for src, fn in runs.items():
                mb = files[src].stat().st_size / 1e6 if src in files else 0.0
                wall, cpu = _time_cpu(fn, r)
                print(f"{kind:<8} {src:<6} {n:>7} {mb:>6.1f} {wall:>8.3f} {cpu:>8.3f} "
                      f"{wall / n * 1e6:>8.1f}", flush=True)
                records.append({**env, "kind": "scaling", "graph": kind, "source": src,
                                "passes": n, "file_mb": mb, "wall_s": wall, "cpu_s": cpu,
                                "us_per_pass": wall / n * 1e6, "repeat": r,
                                "loadavg": os.getloadavg()[0]})
    print()
    return records


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
    ap.add_argument("--sizes", default="1000,10000,100000",
                    help="pass counts of the growth table (chains and random DAGs)")
    ap.add_argument("--big-mb", type=float, default=50.0,
                    help="also a random DAG whose Raptor JSON is about this many MB (0: none)")
    ap.add_argument("--only", choices=["scaling", "raptor"],
                    help="only the growth table, or only the Raptor and synthetic tables")
    args = ap.parse_args()
    env = _env()
    records = []
    if args.only != "raptor":
        sizes = [int(v) for v in args.sizes.split(",") if v]
        records += scaling(sizes, args.big_mb, min(args.repeat, 3), env)
    if args.only == "scaling":
        return _write(records, env, Path(args.out))

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

    return _write(records, env, Path(args.out))


def _write(records: list[dict], env: dict, out: Path) -> int:
    out.parent.mkdir(parents=True, exist_ok=True)
    with out.open("w") as f:
        for r in records:
            f.write(json.dumps({**env, **r}) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
