"""The image comparison of rfw's golden scheme: how far two 8-bit renders of the same picture
may differ (``Bounds``, measured across CPUs) and the measures it bounds (``image_diff``).

The test suite compares its goldens with it (``tests/golden_util.py``), and
``rfw bench replay`` judges a bundle's images re-rendered on another adapter with it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Bounds:
    """How far two 8-bit renders of the same picture may differ.

    llvmpipe compiles shaders for the host CPU, so the same driver on another processor
    rounds differently. Measured at 192x108 (20736 pixels) with
    ``tests/data/golden-other-cpu/`` (every golden re-rendered on an AMD EPYC) against the
    committed goldens (an Intel Xeon; those since regenerated kept in its ``intel/``), worst
    image per measure
    (``test_golden_scheme.py`` checks every file):

    - FLIP mean 0.00173 (deferred, meshlet courtyard); 16 of 22 images identical;
    - pixels over 2 levels: 14, 0.068 % (deferred_ssao_shadows courtyard: shadow-edge
      pixels, 8 over 4 levels, 2 over 8, largest 42); everywhere else none;
    - pixels over 1 level: 40, 0.19 % (meshlet courtyard);
    - mean |difference| over RGBA 0.0104 (deferred_ssao_shadows courtyard);
    - mean signed difference of one channel 0.0030 (rt_shadows courtyard).

    The negative controls (same file; each a mutated render against the unmutated one on
    the same adapter) that come closest, on the tiny scene, which has the fewest pixels to
    change: SSAO off moves 105-109 pixels (0.5 %) by more than 2 levels with a FLIP mean
    of only 0.0010 and a mean |difference| under 0.02, so the outlier count is what rejects
    it; FXAA skipped 417 pixels (FLIP 0.0041), the shadow toggled 184 (FLIP 0.011), a
    one-pixel shift 278 or more (FLIP 0.020); exposure +3 % moves no more than 26 pixels
    over 2 levels but shifts a channel's mean by 1.77 levels (1.40 on the courtyard; FLIP
    0.045).

    Each bound sits between the two: outliers over 2 levels 0.2 % (41 pixels here: 3x the
    AMD worst, 2.6x below SSAO off), FLIP mean 0.005 (2.9x the AMD worst), pixels over 1
    level 1 % (5x), mean |difference| 0.1 (10x) and mean signed difference per channel 0.1
    (33x the AMD worst, 14x below exposure +3 % on the courtyard). A few large outliers are allowed on
    purpose (shadow edges cross a texel on another CPU); many small ones are not.
    """

    flip_mean: float = 0.005
    over2_fraction: float = 0.002
    over1_fraction: float = 0.01
    mean_abs: float = 0.1
    mean_signed: float = 0.1


BOUNDS = Bounds()

#: How far the same render may differ between GPU vendors and drivers (lavapipe against the
#: NVIDIA H200's driver 580.159.04, both through the same backend): rasterization, texture
#: filtering and transcendental rounding differ there, far more than across CPUs. Measured
#: over the 24 goldens both adapters have (``tests/golden/``; ``test_golden_scheme.py``
#: recomputes it), worst image per measure: FLIP mean 0.0157 (deferred courtyard), pixels
#: over 2 levels 4.2 % and over 1 level 12.2 % (the same), mean |difference| 0.335, mean
#: signed difference of a channel 0.149 (NVIDIA brighter by about 1/7 level). Each bound is
#: about twice that worst. What it still rejects: exposure +3 % (a channel's mean moves
#: 1.4-1.8 levels, 3.5x over its bound; FLIP 0.045) and a shifted image on the courtyard
#: (FLIP 0.02 and more, with most pixels moved). What it cannot tell from another vendor's
#: rounding: SSAO switched off (FLIP 0.0010), FXAA skipped (0.0041) or a shadow toggled on
#: the tiny scene (0.011): across vendors only coarse changes are caught; on one adapter
#: ``rfw bench replay`` asks for bit-identical images instead.
VENDOR_BOUNDS = Bounds(flip_mean=0.03, over2_fraction=0.08, over1_fraction=0.25, mean_abs=0.6,
                       mean_signed=0.4)


@dataclass(frozen=True)
class ImageDiff:
    """Differences of two 8-bit images; ``d`` is a pixel's largest channel difference."""

    pixels: int
    largest: int  # max d
    over1: int  # pixels with d > 1
    over2: int  # pixels with d > 2
    mean_abs: float  # mean |difference| over pixels and channels
    mean_signed: float  # largest |mean signed difference| of one channel
    flip: float  # mean LDR FLIP error over RGB

    def violations(self, bounds: Bounds = BOUNDS) -> list[str]:
        """What exceeds ``bounds``, one phrase each; empty when the images match."""
        checks = [
            (self.flip, bounds.flip_mean, "FLIP mean"),
            (self.over2 / self.pixels, bounds.over2_fraction, "fraction of pixels over 2 levels"),
            (self.over1 / self.pixels, bounds.over1_fraction, "fraction of pixels over 1 level"),
            (self.mean_abs, bounds.mean_abs, "mean |difference|"),
            (self.mean_signed, bounds.mean_signed, "mean signed difference of a channel"),
        ]
        return [f"{what} {value:.4g} > {bound:g}" for value, bound, what in checks
                if value > bound]

    def __str__(self) -> str:
        return (f"largest {self.largest}, {self.over2} pixels over 2 levels and {self.over1} "
                f"over 1 (of {self.pixels}), mean |d| {self.mean_abs:.4f}, mean signed "
                f"{self.mean_signed:.4f}, FLIP {self.flip:.5f}")


def _levels(image: np.ndarray) -> np.ndarray:
    a = np.asarray(image)
    if a.ndim != 3 or a.shape[2] not in (3, 4) or a.dtype.kind not in "iu":
        raise TypeError(f"expected (H, W, 3|4) 8-bit levels, got {a.shape} {a.dtype}")
    if a.size and (a.min() < 0 or a.max() > 255):
        raise ValueError("expected 8-bit levels (0-255)")
    return a.astype(np.int16)


def flip_mean(actual: np.ndarray, expected: np.ndarray) -> float:
    """Mean LDR FLIP error (NVIDIA's perceptual metric, 0 = identical) of the RGB channels."""
    import flip_evaluator  # a pinned dependency, also used by rfw.bench.images

    ref = expected[..., :3].astype(np.float32) / 255.0
    test = actual[..., :3].astype(np.float32) / 255.0
    _, mean, _ = flip_evaluator.evaluate(ref, test, "LDR")
    return float(mean)


def image_diff(actual: np.ndarray, expected: np.ndarray) -> ImageDiff:
    """The measures ``Bounds`` limits, for two images of the same shape (RGB or RGBA)."""
    a, b = _levels(actual), _levels(expected)
    if a.shape != b.shape:
        raise ValueError(f"images differ in shape: {a.shape} vs {b.shape}")
    d = a - b
    per_pixel = np.abs(d).max(axis=-1)
    return ImageDiff(pixels=int(per_pixel.size), largest=int(per_pixel.max()),
                     over1=int((per_pixel > 1).sum()), over2=int((per_pixel > 2).sum()),
                     mean_abs=float(np.abs(d).mean()),
                     mean_signed=float(np.abs(d.reshape(-1, d.shape[-1]).mean(axis=0)).max()),
                     flip=flip_mean(a, b) if d.any() else 0.0)  # FLIP of equal images is 0


def mismatch(actual: np.ndarray, expected: np.ndarray, bounds: Bounds = BOUNDS) -> str:
    """Why ``actual`` is not ``expected`` within ``bounds``, in one line; "" when it is."""
    if np.shape(actual) != np.shape(expected):
        return f"shapes differ: {np.shape(actual)} vs {np.shape(expected)}"
    diff = image_diff(actual, expected)
    bad = diff.violations(bounds)
    return f"{'; '.join(bad)} ({diff})" if bad else ""
