"""Overdraw counts fragments: coplanar quads add up, culling decides what counts."""

from __future__ import annotations

import numpy as np
import pytest
from pass_scenes import quad, scene, translate

from rfw import SettingsError, get_pass
from rfw.scene.model import Camera
from rfw.testing import run_pass


def count(sc, device, **settings) -> np.ndarray:
    return run_pass(get_pass("overdraw"), {}, scene=sc, settings=settings,
                    device=device)["count"].astype(np.float32)


def turned() -> np.ndarray:
    m = np.identity(4, np.float32)  # half a turn about y: the quad faces away
    m[0, 0] = m[2, 2] = -1
    return m


@pytest.mark.parametrize("n", [1, 3, 5])
def test_n_coplanar_quads_count_n_in_their_overlap(n, device):
    # quads 2 wide, 0.1 apart, all cover the middle; depth testing would keep only one
    offsets = [0.1 * (k - (n - 1) / 2) for k in range(n)]
    sc = scene("quads", [(quad(2, 2), translate(x, 0, 0)) for x in offsets],
               Camera((0, 0, 3), (0, 0, 0)))
    c = count(sc, device)
    assert c.shape == (64, 64, 4)
    assert (c == c[..., :1]).all()  # every channel holds the count
    np.testing.assert_array_equal(c[24:40, 28:36, 0], n)  # the centre: all quads
    assert c[0, 0, 0] == 0  # background
    assert c.max() == n
    # outside the overlap fewer quads cover a pixel
    assert sorted(np.unique(c[32, :, 0])) == list(range(n + 1))


def test_culling_decides_whether_back_faces_count(device):
    sc = scene("two", [(quad(2, 2), np.identity(4)), (quad(2, 2), turned())],
               Camera((0, 0, 3), (0, 0, 0)))
    assert count(sc, device)[32, 32, 0] == 1
    assert count(sc, device, cull="none")[32, 32, 0] == 2


def test_unknown_cull_mode_is_an_error():
    with pytest.raises(SettingsError, match="'none'"):
        get_pass("overdraw")("overdraw", cull="non")
