"""Sweep one setting and plot each pass's GPU ms against it, with 95% CIs as error bars
(matplotlib, into a PNG). Every repeat renders each value once, in a shuffled order, so
drift and order effects spread over all values instead of biasing the first.

    python examples/sweep_plot.py ssao.samples 4 8 16 32 64 \
        --config configs/deferred_ssao_shadows.toml --out sweep.png
"""

from __future__ import annotations

import argparse
import random
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # headless: no window, a PNG
import matplotlib.pyplot as plt
from _common import out_problem  # this folder is on the path: the script runs from it

import rfw
from rfw.bench.stats import MIN_SAMPLES, change_text, no_mark, significant, summarize_passes

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("key", help="the setting to sweep, as --set names it (e.g. ssao.samples)")
    ap.add_argument("values", nargs="+", help="its values")
    ap.add_argument("--config", default=str(ROOT / "configs" / "deferred_ssao_shadows.toml"))
    ap.add_argument("--size", default="320x180", help="WxH")
    ap.add_argument("--frames", type=int, default=5, help="timed frames per render")
    ap.add_argument("--repeats", type=int, default=6,
                    help="renders per value (default 6; below 6 no difference gets a mark)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the shuffled order")
    ap.add_argument("--backend", default=None)
    ap.add_argument("--out", default="sweep.png", help="the plot (PNG)")
    args = ap.parse_args()
    out = Path(args.out)
    why = f"{out}: --out: is a folder, not a PNG" if out.is_dir() else out_problem(out.parent)
    if why:
        print(f"sweep_plot: error: {why}", file=sys.stderr)
        return 2

    times: dict[str, list] = {v: [] for v in args.values}  # each render's {pass: GPU ms}
    shuffle = random.Random(args.seed).shuffle
    try:
        with rfw.Session(args.backend) as session:
            cfg = rfw.load(args.config, f"size={args.size}")
            session.render(cfg, frames=1)  # warm-up (pipelines, caches): not timed
            for _ in range(args.repeats):
                order = list(args.values)
                shuffle(order)  # a new order each repeat
                for value in order:
                    result = session.render(cfg, f"{args.key}={value}", frames=args.frames)
                    times[value].append(result.gpu_ms)
    except rfw.RfwError as e:
        print(f"sweep_plot: error: {e}", file=sys.stderr)
        return 2

    stats = {v: summarize_passes(t) for v, t in times.items()}  # median, 95% CI per pass
    first, *rest = args.values
    passes = list(stats[first])
    print(f"GPU ms, median [95% CI] over {args.repeats} renders of {args.frames} frames")
    print(f"{args.key:>16} " + " ".join(f"{p:>22}" for p in passes))
    for value, st in stats.items():
        print(f"{value:>16} " + " ".join(
            "-".rjust(22) if s is None else
            f"{s['median']:>7.3f} [{s['ci_lo']:.3f}-{s['ci_hi']:.3f}]".rjust(22)
            for s in st.values()))
    for value in rest:  # each value against the first: only what is beyond the noise
        a, b = stats[first], stats[value]
        why = no_mark(*a.values(), *b.values())
        moved = [f"{p} {change_text(a[p], b[p])}" for p in passes if significant(a[p], b[p])]
        print(f"{args.key}={value} vs {first}: " + (
            f"no marks: {why} (use --repeats {MIN_SAMPLES} or more)" if why
            else ", ".join(moved) or "no pass beyond the noise"))

    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=100)
    x = list(range(len(stats)))
    for p in passes:
        s = [st[p] for st in stats.values()]
        med = [q["median"] if q else float("nan") for q in s]
        err = [[q["median"] - q["ci_lo"] if q else 0 for q in s],
               [q["ci_hi"] - q["median"] if q else 0 for q in s]]
        ax.errorbar(x, med, yerr=err, marker="o", capsize=3, label=p)
    ax.set_xticks(x, list(stats))
    ax.set_xlabel(args.key)
    ax.set_ylabel("GPU ms (median, 95% CI)")
    ax.set_title(f"{Path(args.config).stem}, {args.size}, {args.repeats} renders per value")
    ax.legend()
    fig.tight_layout()
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out)
    except OSError as e:  # the folder changed while the sweep ran
        print(f"sweep_plot: error: {out}: --out: {e.strerror or e}", file=sys.stderr)
        return 2
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
