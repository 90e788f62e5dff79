"""Image differences for the report: PSNR, FLIP (NVIDIA's perceptual error; HDR-FLIP for linear
radiance; SSIM where the ``flip-evaluator`` package is missing) and colour-mapped difference
images, scaled to their own largest difference (or to one scale shared by a report's images:
``--diff-scale shared``), each drawn with a legend stating its scale."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

DIFF_CMAP = "inferno"  # perceptually ordered, black at zero: unchanged pixels stay dark
# rows per step of psnr and abs_diff: a 16384x16384 image (what --size allows) in float64
# would be 6 GiB per operand
_ROWS = 512
# FLIP and SSIM hold several float copies of both images: larger images get PSNR only
PERCEPTUAL_MAX_PIXELS = 4096 * 4096
# the PNG text chunks of every matplotlib figure a report writes: fixed, so a report
# regenerated from a bundle is the same bytes (matplotlib's own names its version)
PNG_METADATA = {"Software": "rfw"}


def _rgb(image: np.ndarray) -> np.ndarray:
    a = np.asarray(image)
    if a.ndim == 2:
        a = a[..., None]
    if a.shape[2] == 1:
        a = np.repeat(a, 3, axis=2)
    return a[..., :3]


def psnr(reference: np.ndarray, test: np.ndarray, *, peak: float = 255.0) -> float:
    """Peak signal-to-noise ratio in dB over RGB (alpha ignored); ``inf`` for identical."""
    a, b = _rgb(reference), _rgb(test)
    if a.shape != b.shape:
        raise ValueError(f"images differ in shape: {a.shape} vs {b.shape}")
    total = 0.0
    for y in range(0, a.shape[0], _ROWS):  # a band at a time: bounded memory at any size
        d = a[y:y + _ROWS].astype(np.float64) - b[y:y + _ROWS]
        total += float(np.sum(d * d))
    mse = total / max(a.size, 1)
    return math.inf if mse == 0.0 else 10.0 * math.log10(peak * peak / mse)


def abs_diff(reference: np.ndarray, test: np.ndarray) -> np.ndarray:
    """``|reference - test|`` in 8-bit steps, max over RGB."""
    a, b = _rgb(reference), _rgb(test)
    if a.shape != b.shape:
        raise ValueError(f"images differ in shape: {a.shape} vs {b.shape}")
    out = np.empty(a.shape[:2], np.uint8)
    for y in range(0, a.shape[0], _ROWS):
        d = a[y:y + _ROWS].astype(np.int16) - b[y:y + _ROWS]
        out[y:y + _ROWS] = np.abs(d).max(axis=2)
    return out


def diff_image(reference: np.ndarray, test: np.ndarray, *,
               scale: int | None = None) -> tuple[np.ndarray, int]:
    """``|reference - test|`` (max over RGB) colour-mapped, and its largest difference.

    The scale's top is that largest difference unless ``scale`` is given (one scale for
    several images), so it neither saturates (a change of 200 stays apart from one of 100)
    nor vanishes (a one-step change takes the map's top colour). Zero maps to black."""
    d = abs_diff(reference, test)
    top = int(d.max())
    return scaled_diff(d, top if scale is None else scale), top


def scaled_diff(d: np.ndarray, top: int) -> np.ndarray:
    """An :func:`abs_diff` colour-mapped from black (0) to ``top`` 8-bit steps (through a
    table of its 256 values: the map's float RGBA of every pixel would be 32 bytes each)."""
    table = colorize(np.arange(256) / max(int(top), 1))
    return table[np.asarray(d, np.uint8)]


def scale_text(top: int, *, own_max: int | None = None) -> str:
    """The scale of a difference image in words: ``scale 0-4/255 (this image's max)``, or
    with a scale shared by several images ``scale 0-78/255 (shared; this image's max 4)``."""
    if own_max is None:
        if int(top) == 0:
            return "no difference (max 0/255)"
        return f"scale 0-{int(top)}/255 (this image's max)"
    return f"scale 0-{max(int(top), 1)}/255 (shared; this image's max {int(own_max)})"


def colorize(x: np.ndarray) -> np.ndarray:
    """Values in [0, 1] as 8-bit RGB through ``DIFF_CMAP``; exactly 0 is black."""
    from matplotlib import colormaps

    rgb = colormaps[DIFF_CMAP](np.clip(x, 0.0, 1.0))[..., :3]
    rgb[x <= 0] = 0.0
    return (rgb * 255 + 0.5).astype(np.uint8)


def diff_legend(path: Path, top: int, *, own_max: int | None = None) -> None:
    """A colour bar for a difference image: 0 to ``top`` 8-bit steps, its title the scale
    (:func:`scale_text`; ``own_max`` where the scale is shared by several images)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import Normalize
    from matplotlib.ticker import MaxNLocator

    path.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(2.6, 0.55))
    norm = Normalize(0, max(top, 1))
    fig.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=DIFF_CMAP), cax=ax,
                 orientation="horizontal")
    ax.set_title(f"|difference|, {scale_text(top, own_max=own_max)}", fontsize=6)
    ax.tick_params(labelsize=6)
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))  # 8-bit steps are whole
    fig.savefig(path, dpi=100, bbox_inches="tight", metadata=PNG_METADATA)
    plt.close(fig)


def flip(reference: np.ndarray, test: np.ndarray) -> tuple[float, np.ndarray] | None:
    """Mean LDR FLIP error (0 = identical) and its magma error map as 8-bit RGB; None when
    the ``flip-evaluator`` package is not installed."""
    try:
        import flip_evaluator
    except ImportError:
        return None
    a = _rgb(reference).astype(np.float32) / 255.0
    b = _rgb(test).astype(np.float32) / 255.0
    error_map, mean, _ = flip_evaluator.evaluate(a, b, "LDR")
    rgb = (np.clip(error_map, 0.0, 1.0) * 255 + 0.5).astype(np.uint8)
    return float(mean), rgb


def hdr_flip(reference: np.ndarray, test: np.ndarray) -> float | None:
    """Mean HDR-FLIP error of linear (H, W, 3) radiance images (0 = identical; FLIP picks
    its exposure range from ``reference``); None when ``flip-evaluator`` is not installed.
    Negative values (a noisy estimate's) are clipped to 0, as FLIP takes none."""
    try:
        import flip_evaluator
    except ImportError:
        return None
    a, b = (np.ascontiguousarray(np.maximum(x[..., :3], 0.0), np.float32)
            for x in (reference, test))
    _, mean, _ = flip_evaluator.evaluate(a, b, "HDR", applyMagma=False)
    return float(mean)


def ssim(reference: np.ndarray, test: np.ndarray) -> float | None:
    """Structural similarity (scikit-image) over RGB; None when it is not installed."""
    try:
        from skimage.metrics import structural_similarity
    except ImportError:
        return None
    a, b = _rgb(reference), _rgb(test)
    win = min(7, *a.shape[:2]) // 2 * 2 + 1 if min(a.shape[:2]) >= 3 else 3
    return float(structural_similarity(a, b, channel_axis=2, win_size=win, data_range=255))


def compare(reference: np.ndarray, test: np.ndarray) -> dict[str, Any]:
    """PSNR plus FLIP (or SSIM) and the difference of ``test`` against ``reference``
    (``abs_diff`` and its largest value ``diff_max``: draw it with :func:`scaled_diff`)."""
    d = abs_diff(reference, test)
    out: dict[str, Any] = {"psnr": psnr(reference, test), "diff_max": int(d.max()),
                           "abs_diff": d}
    if reference.shape[0] * reference.shape[1] > PERCEPTUAL_MAX_PIXELS:
        out["ssim"] = None  # too large for either: PSNR and the difference only
        return out
    f = flip(reference, test)
    if f is not None:
        out["flip"], out["flip_map"] = f
    else:
        out["ssim"] = ssim(reference, test)
    return out


def load_png(path: Path) -> np.ndarray:
    """RGB of a PNG rfw wrote: at any size ``--size`` allows (16384x16384 is over Pillow's
    decompression-bomb limit, which guards against files rfw did not write)."""
    from PIL import Image

    from ..errors import RfwError
    from ..scene.limits import MAX_IMAGE_SIDE, pillow_unbounded

    with pillow_unbounded():
        im = Image.open(path)
    with im:
        if max(im.size) > MAX_IMAGE_SIDE:  # not an image rfw wrote: refused before decoding
            raise RfwError(f"{im.size[0]}x{im.size[1]} pixels is over the {MAX_IMAGE_SIDE} "
                           f"per side of any image rfw writes", file=str(path))
        return np.asarray(im.convert("RGB"))


def save_png(path: Path, rgb: np.ndarray) -> None:
    from PIL import Image

    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.ascontiguousarray(rgb)).save(path, format="PNG")
