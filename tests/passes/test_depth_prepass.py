"""The depth pre-pass writes exactly the G-buffer's depth, and leaves masked geometry out."""

from __future__ import annotations

import numpy as np
from pass_scenes import corner_scene, quad, scene, tiny_scene

from rfw import get_pass
from rfw.scene.model import Camera, Material
from rfw.testing import run_pass


def depths(sc, device) -> tuple[np.ndarray, np.ndarray]:
    pre = run_pass(get_pass("depth_prepass"), {}, scene=sc, device=device)["depth"]
    gb = run_pass(get_pass("gbuffer"), {}, scene=sc, device=device)["depth"]
    return pre, gb


def test_depth_equals_gbuffer_depth_bit_for_bit(device):
    for sc in (tiny_scene(), corner_scene()):
        pre, gb = depths(sc, device)
        assert pre.shape == (64, 64, 1) and pre.dtype == np.float32
        assert (pre < 1).mean() > 0.3  # something was drawn
        np.testing.assert_array_equal(pre, gb)


def test_alpha_masked_materials_are_left_to_the_main_pass(device):
    sc = scene("masked", [(quad(2, 2), np.identity(4))], Camera((0, 0, 3), (0, 0, 0)))
    sc.materials = [Material("cutout", alpha_mode="MASK", alpha_cutoff=0.5)]
    pre, gb = depths(sc, device)
    np.testing.assert_array_equal(pre, 1.0)
    assert gb[32, 32, 0] < 1.0
