"""One reference of ``rfw bench --reference pathtrace[:SPP]`` in its own process.

    python -m rfw.bench.reference --spp N --per-frame K --size WxH [--scene S]
        [--set camera.KEY=VALUE]... --out DIR

Renders ``configs/pathtrace.toml`` on Vulkan, ``K`` samples per pixel a frame over
``N / K`` frames, and writes ``DIR/hdr.exr`` (linear radiance), ``DIR/error.exr`` (the
convergence estimate; alpha: samples), ``DIR/ldr.png`` (the tone-mapped image) and, last,
``DIR/meta.json``: samples, render seconds, samples per second, device, driver and the
reference's noise floor (:func:`rfw.bench.truth.noise_floor`). Exit 1 with one line on
stderr when it fails."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


def render_reference(*, spp: int, per_frame: int, size: tuple[int, int], scene: str | None,
                     sets: list[str], out: Path) -> dict:
    import numpy as np
    from PIL import Image

    from ..config import apply_overrides, load_config
    from ..fileio import atomic_write, write_exr
    from ..options import RunOptions
    from ..render import render
    from .truth import CONFIG, ERROR_FILE, HDR_FILE, LDR_FILE, META_FILE, noise_floor

    frames = spp // per_frame
    cfg = apply_overrides(load_config(CONFIG), [
        *([f"scene={scene}"] if scene else []), f"size={size[0]}x{size[1]}",
        f"pt.spp={per_frame}", *sets])
    t = time.perf_counter()
    result = render(cfg, backend="vk", options=RunOptions.from_env(frames=frames, warmup=0))
    seconds = time.perf_counter() - t
    hdr, error = result.images["pt.hdr"], result.images["pt.error"]
    samples = float(np.asarray(error)[..., 3].mean())
    if abs(samples - spp) > 0.5:
        raise RuntimeError(f"the reference holds {samples:g} samples per pixel, not {spp}")
    out.mkdir(parents=True, exist_ok=True)
    write_exr(out / HDR_FILE, hdr)
    write_exr(out / ERROR_FILE, error)
    ldr = np.asarray(result.images["tonemap.ldr"])
    atomic_write(out / LDR_FILE, lambda f: Image.fromarray(ldr[..., :3].copy(), "RGB")
                 .save(f, "PNG"))
    from .worker import _samples

    timings = result.timings
    gpu = sum(sum(s["gpu_ms"]) for s in _samples(result.frame).values())
    meta = {"spp": spp, "per_frame": per_frame, "frames": frames, "size": list(size),
            "scene": timings.get("scene"), "scene_arg": scene, "camera": sets,
            "render_s": seconds, "samples_per_s": size[0] * size[1] * spp / seconds,
            "gpu_ms_total": gpu or None,
            "device": timings.get("device"), "driver": timings.get("driver"),
            "noise": noise_floor(hdr, error), "method": _method(result)}
    data = json.dumps(meta, indent=1).encode()
    atomic_write(out / META_FILE, lambda f: f.write(data))  # last: the reference is whole
    return meta


def _method(result) -> str | None:
    for ex in result.frame.executors.values():
        for name, p in getattr(ex, "passes", {}).items():
            if name == "pt":
                return getattr(getattr(p, "params", None), "method", None)
    return None


def main(argv: list[str] | None = None) -> int:
    from ..config import parse_size

    ap = argparse.ArgumentParser(prog="python -m rfw.bench.reference")
    ap.add_argument("--spp", type=int, required=True)
    ap.add_argument("--per-frame", type=int, required=True)
    ap.add_argument("--size", type=parse_size, required=True)
    ap.add_argument("--scene")
    ap.add_argument("--set", action="append", default=[])
    ap.add_argument("--out", required=True)
    args = ap.parse_args(argv)
    try:
        render_reference(spp=args.spp, per_frame=args.per_frame, size=args.size,
                         scene=args.scene, sets=args.set, out=Path(args.out))
    except Exception as e:  # one line: the bench says it beside the reference
        message = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        print(f"rfw bench reference: {type(e).__name__}: {message}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
