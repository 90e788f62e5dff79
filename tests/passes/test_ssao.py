"""SSAO on G-buffers rendered from analytic scenes: a plane is open, a crease is not."""

from __future__ import annotations

import numpy as np
import pytest
from pass_scenes import corner_scene, quad, scene, translate, wall_scene
from precision import assert_open, open_tolerance

from rfw import get_pass
from rfw.scene.model import Camera
from rfw.testing import run_pass


def gbuffer(sc, device) -> dict[str, np.ndarray]:
    return run_pass(get_pass("gbuffer"), {}, scene=sc, device=device)


def ssao(g: dict[str, np.ndarray], sc, device, **settings) -> dict[str, np.ndarray]:
    # depth32float cannot be a copy destination, so the depth goes in as r32float
    return run_pass(get_pass("ssao"), {"depth": ("r32float", g["depth"]),
                                       "normal": ("rgba16float", g["normal"])},
                    settings=settings, scene=sc, device=device)


@pytest.fixture(scope="module")
def corner(device):
    sc = corner_scene()
    g = gbuffer(sc, device)
    return sc, g, ssao(g, sc, device)


def test_plane_square_to_the_camera_is_unoccluded(device):
    sc = wall_scene()
    g = gbuffer(sc, device)
    assert (g["depth"] < 1).all()  # the plane fills the view
    out = ssao(g, sc, device)
    assert out["ao"].shape == (32, 32, 4)  # half the 64x64 input
    assert out["ao_raw"].shape == (32, 32, 1)
    assert_open(out["ao_raw"])
    assert_open(out["ao"])


def test_concave_crease_is_occluded_and_open_floor_is_not(corner):
    _, g, out = corner
    # the first half-resolution row whose source pixel sees the floor (normal +y)
    floor = g["normal"][::2, ::2, 1].astype(np.float32) > 0.5
    crease = int(np.argmax(floor.all(axis=1)))
    assert 8 < crease < 24
    ao = out["ao"][..., 0].astype(np.float32)
    # the floor is foreshortened, so most of the darkening shows on the wall side
    near = ao[crease - 2:crease + 1]
    assert (near.min(axis=0) < 0.8).all()  # every column darkens at the crease
    assert ao[crease - 1].mean() < 0.8
    assert (ao[crease] < 1).all()
    # more than radius + blur away from the crease (0.12 world units a texel) it is open
    assert_open(out["ao"][:crease - 8, :, 0])
    assert_open(out["ao"][crease + 8:, :, 0])
    # negative control: the open check sees the crease
    with pytest.raises(AssertionError, match="occluded"):
        assert_open(out["ao"][crease - 2:crease + 1, :, 0])


def test_is_deterministic_and_blur_zero_is_the_raw_result(corner, device):
    sc, g, out = corner
    again = ssao(g, sc, device)
    np.testing.assert_array_equal(again["ao"], out["ao"])
    sharp = ssao(g, sc, device, blur_radius=0)
    # the same values, rounded to rgba16float
    np.testing.assert_allclose(sharp["ao"][..., 0], out["ao_raw"][..., 0], rtol=2**-10)
    # the blur smooths the noise: less variation from texel to texel along the rows
    assert np.abs(np.diff(out["ao"][..., 0].astype(np.float32), axis=1)).sum() < \
        np.abs(np.diff(out["ao_raw"][..., 0], axis=1)).sum()


def test_intensity_zero_is_open_everywhere(corner, device):
    sc, g, _ = corner
    out = ssao(g, sc, device, intensity=0.0)
    assert_open(out["ao"])


def test_occluder_beyond_the_radius_leaves_no_halo(device):
    # a plane 2 radii in front of a wall covers the left half of the view: the wall beside
    # its edge is too far behind to be occluded by it, and the plane faces open space
    sc = scene("step", [(quad(40, 40), np.identity(4)), (quad(20, 40), translate(-10, 0, 1))],
               Camera((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), znear=0.1, zfar=50.0))
    g = gbuffer(sc, device)
    depth = g["depth"][32, :, 0]
    assert depth[0] < depth[-1]  # the step is in view
    out = ssao(g, sc, device, radius=0.5)
    assert_open(out["ao"])


def test_open_tolerance_is_one_format_step():
    # a blur's f32 normalisation can end one ulp below 1, which a 16-bit store may truncate
    # to 1 - 2**-11 (NVIDIA does): accepted; the next value down is occlusion
    assert open_tolerance(np.float16) == 2.0**-11
    assert_open(np.array([1.0, 1 - 2.0**-11], np.float16))
    with pytest.raises(AssertionError, match="occluded"):
        assert_open(np.array([1.0, 1 - 2.0**-10], np.float16))
    assert open_tolerance(np.float32) == 2.0**-21
    with pytest.raises(AssertionError, match="occluded"):
        assert_open(np.array([1 - 2.0**-20], np.float32))
