"""Real A/A pairs: how often the significance mark of the bench report and ``rfw bench
compare`` calls the same config measured twice different, and how often it sees a planted
change (issue 24, item 2).

One ``rfw bench CONFIG --repeat N`` (every run its own process, as always), then the runs cut
into disjoint pairs of sides, each side ``--per-side`` runs (a bench's shape), assigned ABBA
inside each pair so linear drift of the machine falls on both sides alike. Each pair goes
through :func:`rfw.bench.compare.changes` (the summaries compare and the report use) and
:func:`rfw.bench.stats.mark`, pass by pass and for the frame total (GPU ms; CPU record ms
beside). Every ``*`` is a false positive. Then side B's GPU ms are scaled by 1.02 and 1.05
and the marks count detections, beside the power the report states (the median over pairs
of :func:`rfw.bench.stats.power` of side A). Writes ``aa.json``, ``aa.md`` and the runs'
``results.jsonl.gz`` into ``--out`` (default ``$OUT``, else ``out/aa``)::

    python benchmarks/aa_pairs.py --config deferred --runs 120 --size 64x64 --frames 20
    python benchmarks/aa_pairs.py --results out/aa/results.jsonl.gz   # again, from those runs
"""

from __future__ import annotations

import argparse
import copy
import gzip
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from rfw.bench.compare import changes
from rfw.bench.runner import load_results
from rfw.bench.stats import mark, noise, power, summarize

PLANTED = (0.02, 0.05)
METRICS = ("gpu_ms", "cpu_ms")


def wilson(k: int, n: int, z: float = 1.96) -> list[float]:
    """95% Wilson score interval of the rate k/n."""
    if not n:
        return [0.0, 1.0]
    p = k / n
    mid = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return [max(0.0, mid - half), min(1.0, mid + half)]


def run_bench(args: argparse.Namespace, folder: Path) -> Path:
    cmd = [sys.executable, "-m", "rfw.cli", "bench", args.config, "--repeat", str(args.runs),
           "--frames", str(args.frames), "--warmup", str(args.warmup), "--size", args.size,
           "--out", str(folder), "--no-progress", *args.bench_args]
    print(" ".join(cmd), flush=True)
    subprocess.run(cmd, check=True)
    return folder


def sides(records: list[dict[str, Any]], per_side: int) -> list[tuple[list, list]]:
    """Disjoint pairs of sides of ``per_side`` runs each, in run order, ABBA inside a pair."""
    pattern = ("A", "B", "B", "A") * per_side
    out = []
    for k in range(len(records) // (2 * per_side)):
        chunk = records[2 * per_side * k: 2 * per_side * (k + 1)]
        a = [r for r, s in zip(chunk, pattern, strict=False) if s == "A"]
        b = [r for r, s in zip(chunk, pattern, strict=False) if s == "B"]
        out.append((a, b))
    return out


def scaled(records: list[dict[str, Any]], factor: float) -> list[dict[str, Any]]:
    """The records with every GPU ms (frames and passes) times ``factor``."""
    out = copy.deepcopy(records)
    for r in out:
        r["frame"]["gpu_ms"] = [v * factor for v in r["frame"]["gpu_ms"]]
        for p in r.get("passes", []):
            p["gpu_ms"] = [v * factor for v in p["gpu_ms"]]
    return out


def analyse(records: list[dict[str, Any]], per_side: int) -> dict[str, Any]:
    """False positives per (pass, metric) and pooled; planted changes' detection and the
    stated power, for pairs of ``per_side`` runs a side."""
    pairs = sides(records, per_side)
    marks: dict[str, list[str]] = {}
    any_mark = 0
    found: dict[str, dict[float, list[bool]]] = {}
    stated: dict[str, dict[float, list[float]]] = {}
    for a, b in pairs:
        got, _ = changes(a, b)
        hit = False
        for c in got:
            if c.metric not in METRICS:
                continue
            key = f"{c.what}.{c.metric}"
            m = mark(c.old, c.new)
            marks.setdefault(key, []).append(m)
            hit |= m == "*"
        any_mark += hit
        for change in PLANTED:
            for c in changes(a, scaled(b, 1 + change))[0]:
                if c.metric != "gpu_ms":
                    continue
                key = f"{c.what}.gpu_ms"
                found.setdefault(key, {}).setdefault(change, []).append(mark(c.old, c.new) == "*")
                p = power(c.old, change)
                if p is not None:
                    stated.setdefault(key, {}).setdefault(change, []).append(p)
    rows = {}
    for key, ms in marks.items():
        k, n = ms.count("*"), sum(m in ("*", "(n.s.)") for m in ms)
        rows[key] = {"pairs": len(ms), "judged": n, "false_positives": k,
                     "rate": k / n if n else None, "ci95": wilson(k, n),
                     "no_mark": len(ms) - n}
        for change in PLANTED:
            det = found.get(key, {}).get(change, [])
            st = stated.get(key, {}).get(change, [])
            rows[key][f"planted_{change:.0%}"] = {
                "detected": sum(det), "pairs": len(det),
                "rate": sum(det) / len(det) if det else None, "ci95": wilson(sum(det), len(det)),
                "stated_power": float(np.median(st)) if st else None}
    k = sum(r["false_positives"] for r in rows.values())
    n = sum(r["judged"] for r in rows.values())
    return {"per_side": per_side, "pairs": len(pairs), "metrics": rows,
            "pooled": {"false_positives": k, "comparisons": n, "rate": k / n if n else None,
                       "ci95": wilson(k, n)},
            "any_metric_marked": {"pairs": len(pairs), "count": any_mark,
                                  "rate": any_mark / len(pairs) if pairs else None}}


def noise_table(records: list[dict[str, Any]]) -> dict[str, Any]:
    """The noise of all runs together, per pass's GPU ms: between and within runs, and the
    lag-1 autocorrelation of the log run medians in run order (the rule takes runs as
    independent; a machine whose load drifts over several runs makes neighbours alike)."""
    out = {}
    names = list(dict.fromkeys(p["name"] for r in records for p in r.get("passes", [])))
    for name in ["frame", *names]:
        runs = [r["frame"]["gpu_ms"] if name == "frame" else
                next(p["gpu_ms"] for p in r["passes"] if p["name"] == name) for r in records]
        out[name] = noise(summarize(runs))
        if out[name]:
            x = np.log([np.median(g) for g in runs])
            out[name]["lag1"] = float(np.corrcoef(x[:-1], x[1:])[0, 1])
    return out


def pct(x: float | None) -> str:
    return "-" if x is None else f"{x:.1%}"


def markdown(result: dict[str, Any]) -> str:
    lines = [f"# A/A pairs: {result['config']} at {result['size']}, {result['frames']} frames",
             "", f"{result['runs']} runs (one process each) on {result['device']}; "
             f"wall time {result['wall_s']:.0f} s. {result['note']}", ""]
    lines += ["GPU ms noise of all runs (log scale): between runs / within a run (one frame) "
              "/ lag-1 autocorrelation of the run medians in run order:", ""]
    lines += [f"- {k}: {pct(v and v['between'])} / {pct(v and v['within'])} / "
              + ("-" if not v or v.get("lag1") is None else f"{v['lag1']:+.2f}")
              for k, v in result["noise"].items()]
    for a in result["analyses"]:
        p = a["pooled"]
        lines += ["", f"## {a['pairs']} disjoint A/A pairs, {a['per_side']} runs a side", "",
                  f"False positives pooled over passes and metrics: {p['false_positives']}/"
                  f"{p['comparisons']} = {pct(p['rate'])} (95% CI {pct(p['ci95'][0])}-"
                  f"{pct(p['ci95'][1])}, too narrow: a pair's comparisons share its runs); "
                  f"pairs with any mark: {a['any_metric_marked']['count']}/{a['pairs']}.", "",
                  "| pass.metric | A/A marked | rate (95% CI) | +2% detected | stated power "
                  "2% | +5% detected | stated power 5% |", "| --- | --- | --- | --- | --- | --- "
                  "| --- |"]
        for key, r in a["metrics"].items():
            cells = [key, f"{r['false_positives']}/{r['judged']}"
                     + (f" ({r['no_mark']} no mark)" if r["no_mark"] else ""),
                     f"{pct(r['rate'])} ({pct(r['ci95'][0])}-{pct(r['ci95'][1])})"]
            for change in PLANTED:
                d = r[f"planted_{change:.0%}"]
                cells += [f"{d['detected']}/{d['pairs']} ({pct(d['rate'])})" if d["pairs"]
                          else "-", pct(d["stated_power"])]
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", default="deferred")
    ap.add_argument("--runs", type=int, default=120, help="bench runs (processes)")
    ap.add_argument("--per-side", type=int, nargs="+", default=[2, 3],
                    help="runs a side; the first must give >= 30 pairs")
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--warmup", type=int, default=2)
    ap.add_argument("--size", default="64x64")
    ap.add_argument("--out", default=os.environ.get("OUT") or "out/aa")
    ap.add_argument("--results", help="analyse this results.jsonl instead of running")
    ap.add_argument("--note", default="", help="said in aa.md (e.g. how loaded the machine was)")
    ap.add_argument("bench_args", nargs="*", help="after --: more rfw bench arguments")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        if args.results:
            opener = gzip.open if args.results.endswith(".gz") else open
            with opener(args.results, "rt") as f:
                records = [json.loads(x) for x in f if x.strip()]
        else:
            records = load_results(run_bench(args, Path(tmp) / "bench"))
    bench_s = time.perf_counter() - t0
    ok = sorted((r for r in records if not r.get("error")), key=lambda r: r.get("repeat", 0))
    with gzip.open(out / "results.jsonl.gz", "wt") as f:
        f.writelines(json.dumps(r) + "\n" for r in records)
    first = ok[0] if ok else {}
    result = {"config": args.config, "size": args.size, "frames": args.frames,
              "runs": len(ok), "failed": len(records) - len(ok),
              "device": f"{first.get('device')} ({first.get('driver')}, "
                        f"{first.get('backend')})", "host": first.get("host"),
              "rfw_commit": first.get("rfw_commit"), "bench_s": bench_s, "note": args.note,
              "noise": noise_table(ok),
              "analyses": [analyse(ok, k) for k in args.per_side]}
    result["wall_s"] = time.perf_counter() - t0
    (out / "aa.json").write_text(json.dumps(result, indent=1) + "\n")
    md = markdown(result)
    (out / "aa.md").write_text(md)
    print(md)
    print(f"aa_pairs: {len(ok)} runs, wall {result['wall_s']:.1f} s (bench {bench_s:.1f} s) "
          f"-> {out}/aa.json, aa.md")
    first_pairs = result["analyses"][0]["pairs"]
    if first_pairs < 30:
        print(f"aa_pairs: only {first_pairs} pairs (< 30): more --runs", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
