"""Image differences: PSNR, the magnified difference image, FLIP."""

from __future__ import annotations

import math

import numpy as np

from rfw.bench.images import compare, diff_image, hdr_flip, psnr, scaled_diff


def _image(seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, size=(18, 32, 4), dtype=np.uint8)


def test_psnr_of_identical_images_is_inf():
    a = _image()
    assert psnr(a, a.copy()) == math.inf
    c = compare(a, a.copy())
    assert c["psnr"] == math.inf
    assert not scaled_diff(c["abs_diff"], c["diff_max"]).any()
    if "flip" in c:
        assert c["flip"] == 0.0


def test_psnr_known_value_and_alpha_ignored():
    a = np.zeros((4, 4, 4), np.uint8)
    b = a.copy()
    b[..., :3] = 1  # mse 1 over RGB
    b[..., 3] = 200  # alpha does not count
    assert abs(psnr(a, b) - 20 * math.log10(255)) < 1e-9


def test_diff_image_scales_to_its_largest_difference_and_flip_sees_a_change():
    a = _image(1)
    b = a.copy()
    b[5, 7, 1] ^= 3
    d, top = diff_image(a, b)
    assert top == 3 and d.shape == (18, 32, 3)
    # the one changed pixel takes the map's top colour; every other pixel stays black
    assert d[5, 7].min() > 100 and np.count_nonzero(d.any(axis=2)) == 1
    c = compare(a, b)
    assert 0 < c["psnr"] < math.inf and c["diff_max"] == 3
    if "flip" in c:
        assert c["flip"] > 0 and c["flip_map"].shape == (18, 32, 3)


def test_hdr_flip_of_linear_radiance():
    """0 for the same image (alpha and negative noise aside), growing with a brightness
    change, and it sees a change above 1 that an 8-bit image would clip."""
    rng = np.random.default_rng(2)
    ref = rng.uniform(0.0, 4.0, size=(24, 32, 3)).astype(np.float32)
    with_alpha = np.concatenate([ref, np.zeros((24, 32, 1), np.float32)], axis=2)
    same = hdr_flip(ref, with_alpha)
    if same is None:  # flip-evaluator not installed
        return
    noisy = ref.copy()
    noisy[0, 0] = -0.5  # a noisy estimate may dip below 0: FLIP sees it as 0
    assert same == 0.0 and hdr_flip(np.maximum(noisy, 0), noisy) == 0.0
    small, large = (hdr_flip(ref, ref * k) for k in (1.05, 1.3))
    assert 0 < small < large
    bright = ref.copy()
    bright[ref > 1.0] *= 1.5  # only values an 8-bit image would clip
    assert hdr_flip(ref, bright) > 0.01
