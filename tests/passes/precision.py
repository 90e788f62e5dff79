"""What a conforming GPU may return, as checks: tolerances come from the formats and the
Vulkan spec's conversion rules, not from one driver's rounding."""

from __future__ import annotations

import numpy as np

# the shaders' f32 arithmetic, in 8-bit codes: the turbo polynomial's terms reach about 150,
# so its f32 error is about 400 * 2**-23 of full scale (0.012 codes); depth linearisation
# in range is smaller. 1/16 of a code covers either several times over.
F32_SLACK = 1 / 16


def assert_unorm8(actual: np.ndarray, expected: np.ndarray, *, slack: float = F32_SLACK) -> None:
    """``actual`` (8-bit codes) stores ``expected`` (0..255 floats) as Vulkan allows: a float
    to UNORM conversion may give either of the two codes nearest to ``value * 255`` (round
    to nearest is only recommended; NVIDIA and lavapipe differ), after ``slack`` codes of
    shader arithmetic."""
    e = np.asarray(expected, np.float64)
    a = np.asarray(actual).astype(np.float64)
    bad = (a < np.floor(e - slack)) | (a > np.ceil(e + slack))
    if bad.any():
        i = np.unravel_index(np.argmax(bad), bad.shape)
        raise AssertionError(f"{int(bad.sum())} of {bad.size} codes are not one of the two "
                             f"nearest to the expected value; at {tuple(map(int, i))}: "
                             f"{a[i]:.0f} for {e[i]:.4f}")


def open_tolerance(dtype: np.dtype) -> float:
    """How far below 1.0 an unoccluded AO texel of ``dtype`` may read: the shader's f32
    arithmetic is a few ulps (2**-21) off, and storing to a 16-bit float may round toward
    zero, to the value one step below 1 (1 - 2**-11)."""
    one = np.dtype(dtype).type(1)
    step = float(one - np.nextafter(one, np.dtype(dtype).type(0)))
    return max(step, 2.0**-21)


def assert_open(ao: np.ndarray) -> None:
    """Every texel of ``ao`` is 1.0 (unoccluded) up to ``open_tolerance`` of its format."""
    tol = open_tolerance(ao.dtype)
    worst = float(np.abs(ao.astype(np.float64) - 1.0).max())
    if worst > tol:
        below = int((np.abs(ao.astype(np.float64) - 1.0) > tol).sum())
        raise AssertionError(f"{below} of {ao.size} texels are occluded: the farthest from 1 "
                             f"is {1 - worst:.6g} (tolerance {tol:.3g} for {ao.dtype})")
