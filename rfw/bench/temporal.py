"""Temporal stability of a frame sequence: its flicker index, and its error frame by frame.

The **flicker index** is the mean absolute change of linear luminance between consecutive
frames, over the pixels that do not move between them: a still image scores 0, and what a
technique adds on a still camera (jitter that no resolve settles, noise that changes every
frame) raises it. Which pixels do not move comes from each frame's motion vectors (the
G-buffer's ``velocity``, in pixels) and depth: a pixel counts where its motion is below
``max_motion`` pixels and its surface is one that was there the frame before (nothing came
in front of it: :func:`still_pixels`; pixels where nothing is drawn have no motion to tell
and are left out); without them (a still camera over a still scene) every pixel counts.
``still_share`` says how many pixels were counted. 8-bit images are display-encoded
(rfw's tonemapped output and its PNGs) and are decoded from sRGB first, so the index is in
linear units of the display range (0 to 1); float images are linear already.

The **per-frame error** against per-frame references (a reference render of each frame's
camera) is the mean absolute difference of linear luminance of each frame, with its mean
and spread over the sequence.

``run_flicker(folder)`` reads what ``rfw run --frames N --save-every 1`` wrote
(``frames/<output>.<k>.png``, or the EXR frames ``--exr`` adds for float outputs);
``rfw bench`` records the flicker index of runs along a camera path and of runs with a
jittered camera (``temporal`` in each record, :func:`along_run`).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import RfwError

# Rec. 709 / sRGB primaries: the luminance of linear RGB
LUMA = np.array([0.2126, 0.7152, 0.0722])


def linear_luminance(image: np.ndarray) -> np.ndarray:
    """(H, W) float64 linear luminance of an (H, W, C) image as rfw reads it back or loads
    it: uint8 is display-encoded sRGB (decoded here), float is linear. Alpha is ignored; a
    one-channel image is its own luminance."""
    a = np.asarray(image)
    if a.ndim == 2:
        a = a[..., None]
    if a.dtype == np.uint8:
        c = a.astype(np.float64) / 255.0
        c = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    else:
        c = a.astype(np.float64)
    if c.shape[-1] == 1:
        return c[..., 0]
    return c[..., :3] @ LUMA


@dataclass(frozen=True)
class Flicker:
    """A sequence's flicker index: ``index`` (the mean of ``per_pair``), ``per_pair`` (the
    mean absolute luminance change of each consecutive pair over its still pixels; None
    where no pixel was still) and ``still_share`` (the mean share of pixels counted)."""

    index: float | None
    per_pair: list[float | None]
    still_share: float

    def as_dict(self) -> dict[str, Any]:
        return {"flicker": self.index, "per_pair": self.per_pair,
                "still_share": self.still_share}


def still_pixels(velocity: np.ndarray, depth: np.ndarray, prev_depth: np.ndarray, *,
                 max_motion: float = 0.01, max_depth_change: float = 0.05) -> np.ndarray:
    """(H, W) bool: pixels whose surface did not move on screen (|velocity| below
    ``max_motion`` pixels) and is one the frame before had there: its distance within
    the range of the frame before's 3x3 neighbourhood, widened by ``max_depth_change`` of
    itself (a sub-pixel jitter moves an edge's sample from one of its surfaces to the
    other; something that comes in front is nearer than all of them). Distance is read as
    ``1 - depth``, near / distance for rfw's projection (depth 0 near, 1 far, the far plane
    well beyond the scene), so the share holds at any distance. Where nothing is drawn
    (depth 1) the motion is unknown (the G-buffer clears it to 0): not counted."""
    v = np.asarray(velocity, np.float64)
    moved = np.hypot(v[..., 0], v[..., 1]) >= max_motion
    d, p = (1.0 - np.asarray(x, np.float64).reshape(v.shape[:2]) for x in (depth, prev_depth))
    padded = np.pad(p, 1, mode="edge")
    around = np.stack([padded[y:y + p.shape[0], x:x + p.shape[1]]
                       for y in range(3) for x in range(3)])
    lo, hi = around.min(axis=0), around.max(axis=0)
    inside = (d >= lo * (1.0 - max_depth_change)) & (d <= hi * (1.0 + max_depth_change))
    return ~moved & (d > 0.0) & inside


def flicker_index(frames: Sequence[np.ndarray], *,
                  velocity: Sequence[np.ndarray] | None = None,
                  depth: Sequence[np.ndarray] | None = None, max_motion: float = 0.01,
                  max_depth_change: float = 0.05) -> Flicker:
    """The flicker index of ``frames`` (at least two images of one size, in order).
    ``velocity`` and ``depth``, one per frame, pick the still pixels of each pair (frame k's
    motion to frame k - 1, and both frames' depth: :func:`still_pixels`); without them every
    pixel counts."""
    if len(frames) < 2:
        raise RfwError(f"a flicker index needs at least two frames, not {len(frames)}",
                       element="flicker_index")
    if (velocity is None) != (depth is None):
        raise RfwError("give both velocity and depth (the still pixels need both), or neither",
                       element="flicker_index")
    for name, per in (("velocity", velocity), ("depth", depth)):
        if per is not None and len(per) != len(frames):
            raise RfwError(f"{len(per)} {name} images for {len(frames)} frames",
                           element="flicker_index")
    lum = [linear_luminance(f) for f in frames]
    shapes = {x.shape for x in lum}
    if len(shapes) != 1:
        raise RfwError(f"the frames differ in size: {sorted(shapes)}", element="flicker_index")
    per_pair: list[float | None] = []
    shares = []
    for k in range(1, len(lum)):
        change = np.abs(lum[k] - lum[k - 1])
        if velocity is None:
            mask = np.ones(change.shape, bool)
        else:
            mask = still_pixels(velocity[k], depth[k], depth[k - 1], max_motion=max_motion,
                                max_depth_change=max_depth_change)
        shares.append(float(mask.mean()))
        per_pair.append(float(change[mask].mean()) if mask.any() else None)
    counted = [x for x in per_pair if x is not None]
    return Flicker(float(np.mean(counted)) if counted else None, per_pair,
                   float(np.mean(shares)))


@dataclass(frozen=True)
class FrameErrors:
    """Each frame's mean absolute luminance error against its reference, and their mean
    and spread (the sample standard deviation; 0 for one frame)."""

    per_frame: list[float]
    mean: float
    std: float

    def as_dict(self) -> dict[str, Any]:
        return {"per_frame": self.per_frame, "mean": self.mean, "std": self.std}


def frame_errors(frames: Sequence[np.ndarray], references: Sequence[np.ndarray]
                 ) -> FrameErrors:
    """The error of each of ``frames`` against the reference of the same frame (same size;
    references may be float or 8-bit, each decoded to linear luminance)."""
    if len(frames) != len(references) or not frames:
        raise RfwError(f"{len(frames)} frames and {len(references)} references: one "
                       "reference per frame", element="frame_errors")
    errors = []
    for k, (f, r) in enumerate(zip(frames, references, strict=True)):
        a, b = linear_luminance(f), linear_luminance(r)
        if a.shape != b.shape:
            raise RfwError(f"frame {k} is {a.shape[1]}x{a.shape[0]}, its reference "
                           f"{b.shape[1]}x{b.shape[0]}", element="frame_errors")
        errors.append(float(np.abs(a - b).mean()))
    std = float(np.std(errors, ddof=1)) if len(errors) > 1 else 0.0
    return FrameErrors(errors, float(np.mean(errors)), std)


def box_down(image: np.ndarray, factor: int) -> np.ndarray:
    """``image`` averaged over ``factor`` x ``factor`` blocks in linear values (8-bit sRGB
    decoded first): a supersampled render brought down to the size it stands for. Returns
    float64 linear RGB(A)."""
    a = np.asarray(image)
    if a.dtype == np.uint8:
        c = a.astype(np.float64) / 255.0
        rgb = np.where(c[..., :3] <= 0.04045, c[..., :3] / 12.92,
                       ((c[..., :3] + 0.055) / 1.055) ** 2.4)
        a = np.concatenate([rgb, c[..., 3:]], axis=-1)
    h, w = a.shape[0] // factor, a.shape[1] // factor
    a = a[:h * factor, :w * factor].astype(np.float64)
    return a.reshape(h, factor, w, factor, -1).mean(axis=(1, 3))


_FRAME = re.compile(r"^(?P<output>.+)\.(?P<k>\d{4})\.(?P<ext>png|exr)$")


def run_frames(folder: str | Path, output: str | None = None) -> list[np.ndarray]:
    """The frames ``rfw run --save-every 1`` wrote for ``output`` (default: the only output
    it saved) under ``folder/frames``, in frame order: EXR where it wrote them (float
    outputs with ``--exr``: linear values), else PNG."""
    from ..fileio import read_exr
    from .images import load_png

    frames_dir = Path(folder) / "frames"
    found: dict[str, dict[int, Path]] = {}
    for p in sorted(frames_dir.glob("*.[0-9][0-9][0-9][0-9].*")):
        m = _FRAME.match(p.name)
        if m is None:
            continue
        by_k = found.setdefault(m["output"], {})
        k = int(m["k"])
        if m["ext"] == "exr" or k not in by_k:  # the exact values over the 8-bit ones
            by_k[k] = p
    if not found:
        raise RfwError(f"no frames in {frames_dir} (rfw run --frames N --save-every 1 "
                       "writes them)", element="run_frames")
    if output is None:
        if len(found) != 1:
            raise RfwError(f"{frames_dir} holds frames of {', '.join(sorted(found))}: name "
                           "one as output", element="run_frames")
        (output,) = found
    if output not in found:
        raise RfwError(f"no frames of '{output}' in {frames_dir} (it has "
                       f"{', '.join(sorted(found))})", element="run_frames")
    by_k = found[output]
    ks = sorted(by_k)
    if ks != list(range(ks[0], ks[0] + len(ks))):
        raise RfwError(f"the frames of '{output}' in {frames_dir} are not consecutive "
                       f"({ks[:8]}...): write every frame (--save-every 1)",
                       element="run_frames")
    return [read_exr(by_k[k]) if by_k[k].suffix == ".exr" else load_png(by_k[k])
            for k in ks]


def run_flicker(folder: str | Path, output: str | None = None, *, skip: int = 0) -> Flicker:
    """The flicker index of what ``rfw run --frames N --save-every 1 --out FOLDER`` wrote
    (every pixel counts: for a still camera), leaving out the first ``skip`` frames (a
    temporal resolve's history filling up)."""
    frames = run_frames(folder, output)
    return flicker_index(frames[skip:])


def along_run(cfg: Any, *, backend: str, options: Any) -> dict[str, Any] | None:
    """The flicker index of ``cfg``'s timed frames (the first output), from an untimed
    replay that reads each frame back (which the timed run must not: it waits for every
    frame). Along a camera path the still pixels come from the G-buffer's motion vectors
    and depth, turned on for the replay (they add an output, the image is the same); a
    config without a ``gbuffer`` pass has none to tell them by (``flicker`` None, and
    ``why``). On a still camera every pixel counts. None for a run that neither moves nor
    jitters its camera: it renders one image, again and again."""
    from ..config import apply_overrides, build
    from ..render import render

    path = "path" in (cfg.camera or {})
    jitter = max((p.camera_jitter() for p in build(cfg).passes.values()), default=0)
    if not path and not jitter:
        return None
    first = cfg.outputs[0]
    still = None
    if path:
        entry = next((e for e in cfg.passes if e.enabled and e.use == "gbuffer"), None)
        if entry is None:
            return {"flicker": None, "frames": options.frames, "why": "the camera moves, and "
                    "no gbuffer pass gives the motion vectors that tell still pixels"}
        cfg = apply_overrides(cfg, [f"{entry.name}.velocity=true"])
        gbuffer = build(cfg).passes[entry.name]
        depth = entry.inputs.get("depth") if gbuffer.params.prepass else f"{entry.name}.depth"
        still = (f"{entry.name}.velocity", depth)
        cfg = replace(cfg, outputs=list(dict.fromkeys([first, *still])))
    images: list[np.ndarray] = []
    velocity: list[np.ndarray] = []
    depths: list[np.ndarray] = []

    def read(k: int, frame: Any) -> None:
        images.append(frame.read(first).copy())
        if still is not None:
            velocity.append(frame.read(still[0]).copy())
            depths.append(frame.read(still[1]).copy())

    render(cfg, backend=backend, each_frame=read, options=options)
    if len(images) < 2:
        return {"flicker": None, "frames": len(images), "why": "one frame: nothing to compare"}
    out = flicker_index(images, velocity=velocity or None, depth=depths or None)
    return {**out.as_dict(), "frames": len(images), "output": first, "jitter": jitter,
            "still": "velocity and depth" if still else "every pixel (a still camera)"}
