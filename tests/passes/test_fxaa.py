"""FXAA on analytic images: flat stays flat, a hard edge softens symmetrically."""

from __future__ import annotations

import numpy as np

from rfw import get_pass
from rfw.testing import run_pass


def fxaa(image: np.ndarray, device, **settings) -> np.ndarray:
    return run_pass(get_pass("fxaa"), {"ldr": ("rgba8unorm", image)}, settings=settings,
                    device=device)["color"]


def edge(width: int = 16, height: int = 12) -> np.ndarray:
    """Black left half, white right half."""
    img = np.zeros((height, width, 4), np.uint8)
    img[..., 3] = 255
    img[:, width // 2:, :3] = 255
    return img


def test_flat_image_is_unchanged(device):
    img = np.empty((12, 16, 4), np.uint8)
    img[...] = (200, 60, 17, 255)
    np.testing.assert_array_equal(fxaa(img, device), img)


def test_hard_vertical_edge_softens_symmetrically(device):
    img = edge()
    out = fxaa(img, device).astype(int)
    # a long straight edge gets no edge blend; the subpixel term moves the two pixels beside
    # it toward each other by subpixel * ease(1/3)^2 = 0.75 * (7/27)^2 of a texel
    shift = 255 * 0.75 * (7 / 27) ** 2  # 12.85
    dark, light = out[:, 7, :3], out[:, 8, :3]
    assert (np.abs(dark - shift) <= 1).all(), dark
    assert (np.abs(light - (255 - shift)) <= 1).all(), light
    assert (np.abs(dark + light - 255) <= 1).all()  # symmetric about the edge
    np.testing.assert_array_equal(out[:, :7], img[:, :7])
    np.testing.assert_array_equal(out[:, 9:], img[:, 9:])
    np.testing.assert_array_equal(out[..., 3], 255)
    assert (out == out[:1]).all()  # every row alike, the image borders included


def test_no_subpixel_blend_keeps_a_long_straight_edge(device):
    img = edge()
    np.testing.assert_array_equal(fxaa(img, device, subpixel=0.0), img)


def test_edge_below_the_contrast_threshold_is_kept(device):
    img = edge()
    img[:, 8:, :3] = 20  # luma contrast 20/255 = 0.078, below the 0.1 asked for
    out = fxaa(img, device, edge_threshold_min=0.1)
    np.testing.assert_array_equal(out, img)
