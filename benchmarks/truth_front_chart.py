"""Redraw a bench's error-versus-cost fronts from its ``truth.csv`` against any error it
holds (``hdr_flip``, ``hdr_flip_p99``, ``rel_mse``, ``rmse``, ``flip``), and list what
dominates what: the numbers are all in the file, so no image is needed.

    python benchmarks/truth_front_chart.py DIR/truth.csv --metric hdr_flip --out front.png

The GPU ms CIs are taken as CIs (a bench of fewer runs or samples than a CI needs marks
its dominance by the medians in its own report).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from rfw.bench.report.truth import WORDS, draw_front, points_from_csv
from rfw.bench.truth import dominance


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("csv", type=Path)
    ap.add_argument("--metric", default="hdr_flip")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--title")
    args = ap.parse_args()
    pts = points_from_csv(args.csv, args.metric)
    draw_front(args.out, pts, WORDS.get(args.metric, args.metric), title=args.title)
    for label, by in dominance(pts).items():
        if by:
            print(f"{label} dominated by " + ", ".join(
                f"{b}{' *' if sure else ' (n.s.)'}" for b, sure in by))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
