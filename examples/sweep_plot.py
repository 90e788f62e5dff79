"""Sweep one setting and plot each pass's GPU ms against it (matplotlib, into a PNG).

    python examples/sweep_plot.py ssao.samples 4 8 16 32 64 \
        --config configs/deferred_ssao_shadows.toml --out sweep.png
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # headless: no window, a PNG
import matplotlib.pyplot as plt
from _common import out_problem  # this folder is on the path: the script runs from it

import rfw

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("key", help="the setting to sweep, as --set names it (e.g. ssao.samples)")
    ap.add_argument("values", nargs="+", help="its values")
    ap.add_argument("--config", default=str(ROOT / "configs" / "deferred_ssao_shadows.toml"))
    ap.add_argument("--size", default="320x180", help="WxH")
    ap.add_argument("--frames", type=int, default=10, help="timed frames per value")
    ap.add_argument("--backend", default=None)
    ap.add_argument("--out", default="sweep.png", help="the plot (PNG)")
    args = ap.parse_args()
    out = Path(args.out)
    why = f"{out}: --out: is a folder, not a PNG" if out.is_dir() else out_problem(out.parent)
    if why:
        print(f"sweep_plot: error: {why}", file=sys.stderr)
        return 2

    rows = []
    try:
        with rfw.Session(args.backend) as session:
            cfg = rfw.load(args.config, f"size={args.size}")
            for value in args.values:
                result = session.render(cfg, f"{args.key}={value}", frames=args.frames)
                rows.append((value, result.gpu_ms))
    except rfw.RfwError as e:
        print(f"sweep_plot: error: {e}", file=sys.stderr)
        return 2

    passes = list(rows[0][1])
    print(f"{args.key:>16} " + " ".join(f"{p:>12}" for p in passes))
    for value, ms in rows:
        print(f"{value:>16} " + " ".join("-".rjust(12) if ms[p] is None else f"{ms[p]:>12.3f}"
                                          for p in passes))

    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=100)
    x = list(range(len(rows)))
    for p in passes:
        ax.plot(x, [ms[p] for _, ms in rows], marker="o", label=p)
    ax.set_xticks(x, [v for v, _ in rows])
    ax.set_xlabel(args.key)
    ax.set_ylabel("GPU ms (median per frame)")
    ax.set_title(f"{Path(args.config).stem}, {args.size}")
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
