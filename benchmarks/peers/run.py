"""Run one peer in its own process; ``rfw bench --peers`` calls this.

    python benchmarks/peers/run.py PEER [--scene default] [--size WxH] [--frames N]
        [--warmup N] [--sun DX,DY,DZ] --out DIR

``--sun`` replaces the direction the scene's sun travels (raster peers): the negative control
of ``tests/bench/test_peer_images.py``.

Writes ``DIR/record.json`` (``{"peer", "kind", "available", "frame_ms", ...}``; a peer that
cannot run here is ``available: false`` with the reason) and ``DIR/image.png``.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
import traceback
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks.peers import ALL, RASTER  # noqa: E402
from benchmarks.peers.common import Unavailable, geometry, load_scene, primary_rays  # noqa: E402


def measure(peer: str, *, scene: str, size: tuple[int, int], frames: int,
            warmup: int, sun: tuple[float, float, float] | None = None) -> dict:
    """The peer's record (no image); raises ``Unavailable`` where it cannot run."""
    w, h = size
    sc = load_scene(scene)
    cam = sc.default_camera()
    geo = geometry(sc)
    if sun is not None:
        d = -np.asarray(sun, np.float64)
        geo.light_dir = (d / np.linalg.norm(d)).astype(np.float32)
    module = importlib.import_module(f"benchmarks.peers.{peer}_peer")
    if peer in RASTER:
        return module.measure(geo, cam, w, h, frames=frames, warmup=warmup)
    origins, directions = primary_rays(cam, w, h)
    return module.measure(geo, origins, directions, w, h, frames=frames, warmup=warmup)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="benchmarks/peers/run.py")
    ap.add_argument("peer", choices=ALL)
    ap.add_argument("--scene", default="default")
    ap.add_argument("--size", default="1280x720")
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--warmup", type=int, default=2)
    ap.add_argument("--sun", help="direction the sun travels, DX,DY,DZ (default: the scene's)")
    ap.add_argument("--out", required=True)
    args = ap.parse_args(argv)
    w, h = (int(v) for v in args.size.lower().split("x"))
    sun = _sun(ap, args.sun)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    record = {"peer": args.peer, "kind": "raster" if args.peer in RASTER else "raycast",
              "size": [w, h], "scene": args.scene, "frames": args.frames}
    try:
        got = measure(args.peer, scene=args.scene, size=(w, h), frames=args.frames,
                      warmup=args.warmup, sun=sun)
    except Unavailable as e:
        record.update(available=False, reason=str(e))
    except Exception as e:
        first = (str(e).strip().splitlines() or [""])[0]
        record.update(available=False, reason=f"{type(e).__name__}: {first}",
                      traceback=traceback.format_exc(limit=6))
    else:
        image = got.pop("image", None)
        record.update(available=True, **got)
        if image is not None:
            from PIL import Image

            Image.fromarray(image).save(out / "image.png")
    (out / "record.json").write_text(json.dumps(record))
    print(json.dumps({k: v for k, v in record.items() if not k.endswith("_ms")}))
    return 0


def _sun(ap: argparse.ArgumentParser, text: str | None) -> tuple[float, float, float] | None:
    if text is None:
        return None
    try:
        d = tuple(float(v) for v in text.split(","))
    except ValueError:
        d = ()
    if len(d) != 3 or not np.isfinite(d).all() or not any(d):
        ap.error(f"--sun: expected three finite numbers, not all zero, got '{text}'")
    return d


if __name__ == "__main__":
    sys.exit(main())
