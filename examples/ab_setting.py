"""A/B one pass setting: render a config twice in one session, print per-pass GPU ms of each,
the difference, and how much the image changed.

    python examples/ab_setting.py lighting.ambient=0.2 lighting.ambient=1.5
    python examples/ab_setting.py ssao.samples=8 ssao.samples=32 \
        --config configs/deferred_ssao_shadows.toml --frames 20
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

import rfw

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("a", help="setting A, as --set takes it (e.g. lighting.ambient=0.2)")
    ap.add_argument("b", help="setting B")
    ap.add_argument("--config", default=str(ROOT / "configs" / "deferred.toml"))
    ap.add_argument("--size", default="320x180", help="WxH")
    ap.add_argument("--frames", type=int, default=10, help="timed frames per side")
    ap.add_argument("--backend", default=None, help="wgpu, vk, ... (default: as rfw run)")
    args = ap.parse_args()

    try:
        with rfw.Session(args.backend) as session:  # one device and scene for both sides
            cfg = rfw.load(args.config, f"size={args.size}")
            a = session.render(cfg, args.a, frames=args.frames)
            b = session.render(cfg, args.b, frames=args.frames)
    except rfw.RfwError as e:  # the line rfw run prints
        print(f"ab_setting: error: {e}", file=sys.stderr)
        return 2

    print(f"A: {args.a}   B: {args.b}   ({a.timings['device']}, {args.size}, "
          f"{args.frames} frames)")
    print(f"{'pass':<24} {'A ms':>9} {'B ms':>9} {'B-A ms':>9} {'B/A':>7}")
    for name, ms_a in a.gpu_ms.items():
        ms_b = b.gpu_ms[name]
        if ms_a is None or ms_b is None:  # a device without timestamps
            print(f"{name:<24} {'-':>9} {'-':>9} {'-':>9} {'-':>7}")
            continue
        ratio = f"{ms_b / ms_a:.3f}" if ms_a > 0 else "-"
        print(f"{name:<24} {ms_a:>9.3f} {ms_b:>9.3f} {ms_b - ms_a:>+9.3f} {ratio:>7}")
    print(f"{'total':<24} {a.gpu_ms_total:>9.3f} {b.gpu_ms_total:>9.3f} "
          f"{b.gpu_ms_total - a.gpu_ms_total:>+9.3f}")
    for name in a.images:  # the image side of the A/B
        da = a.images[name].astype(np.float64)
        db = b.images[name].astype(np.float64)
        changed = np.any(da != db, axis=2).mean() * 100
        print(f"image {name}: mean |B-A| {np.abs(db - da).mean():.4f}, "
              f"{changed:.1f}% of pixels changed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
