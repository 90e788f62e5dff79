"""A/B one pass setting: render A and B in one session, alternating which goes first over
several repeats, and print per pass the median GPU ms of each side with its 95% CI, B/A and
whether B differs beyond the noise; then how much the image changed.

    python examples/ab_setting.py lighting.ambient=0.2 lighting.ambient=1.5
    python examples/ab_setting.py ssao.samples=8 ssao.samples=32 \
        --config configs/deferred_ssao_shadows.toml --repeats 10
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

import rfw
from rfw.bench.stats import MIN_SAMPLES, change_text, no_mark, significant, summarize_passes

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("a", help="setting A, as --set takes it (e.g. lighting.ambient=0.2)")
    ap.add_argument("b", help="setting B")
    ap.add_argument("--config", default=str(ROOT / "configs" / "deferred.toml"))
    ap.add_argument("--size", default="320x180", help="WxH")
    ap.add_argument("--frames", type=int, default=5, help="timed frames per render")
    ap.add_argument("--repeats", type=int, default=8,
                    help="renders per side (default 8; below 6 no difference gets a mark)")
    ap.add_argument("--backend", default=None, help="wgpu, vk, ... (default: as rfw run)")
    args = ap.parse_args()

    sets = {"A": args.a, "B": args.b}
    times: dict[str, list] = {"A": [], "B": []}  # per side: each render's {pass: GPU ms}
    order = ["AB" if r % 2 == 0 else "BA" for r in range(args.repeats)]  # who goes first
    try:
        with rfw.Session(args.backend) as session:  # one device and scene for both sides
            cfg = rfw.load(args.config, f"size={args.size}")
            session.render(cfg, args.a, frames=1)  # warm-up (pipelines, caches): not timed
            last = {}
            for pair in order:
                for side in pair:
                    last[side] = session.render(cfg, sets[side], frames=args.frames)
                    times[side].append({**last[side].gpu_ms, "total": last[side].gpu_ms_total})
    except rfw.RfwError as e:  # the line rfw run prints
        print(f"ab_setting: error: {e}", file=sys.stderr)
        return 2

    a, b = summarize_passes(times["A"]), summarize_passes(times["B"])
    print(f"A: {args.a}   B: {args.b}   ({last['A'].timings['device']}, {args.size}, "
          f"{args.repeats} renders a side of {args.frames} frames, order {' '.join(order)})")
    print(f"{'pass':<16} {'A ms':>9} {'A 95% CI':>17} {'B ms':>9} {'B 95% CI':>17} {'B/A':>6}  "
          "B vs A")
    for name in a:
        sa, sb = a[name], b.get(name)
        if sa is None or sb is None:  # a device without timestamps
            print(f"{name:<16} {'-':>9} {'-':>17} {'-':>9} {'-':>17} {'-':>6}  -")
            continue
        ratio = f"{sb['median'] / sa['median']:.3f}" if sa["median"] > 0 else "-"
        print(f"{name:<16} {sa['median']:>9.3f} {sa['ci_lo']:>8.3f}-{sa['ci_hi']:<8.3f} "
              f"{sb['median']:>9.3f} {sb['ci_lo']:>8.3f}-{sb['ci_hi']:<8.3f} {ratio:>6}  "
              f"{change_text(sa, sb)}")
    moved = [n for n in a if n != "total" and significant(a[n], b.get(n))]
    why = no_mark(a["total"], b["total"])
    print(f"beyond the noise (95% CI of the ratio clear of 1): {', '.join(moved) or 'no pass'}" if not why else
          f"no marks: {why} (use --repeats {MIN_SAMPLES} or more)")
    for name in last["A"].images:  # the image side of the A/B
        da = last["A"].images[name].astype(np.float64)
        db = last["B"].images[name].astype(np.float64)
        changed = np.any(da != db, axis=2).mean() * 100
        print(f"image {name}: mean |B-A| {np.abs(db - da).mean():.4f}, "
              f"{changed:.1f}% of pixels changed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
