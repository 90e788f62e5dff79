"""Debug view modes against their formulas, on analytic inputs and on a real depth buffer."""

from __future__ import annotations

import numpy as np
import pytest
from pass_scenes import corner_scene, wall_scene
from precision import assert_unorm8

from rfw import SettingsError, get_pass
from rfw.config import load_config
from rfw.render import render
from rfw.testing import run_pass


def view(fmt: str, source: np.ndarray, device, scene=None, **settings) -> np.ndarray:
    return run_pass(get_pass("debug_view"), {"source": (fmt, source)}, settings=settings,
                    scene=scene, device=device)["view"]


def linear_depth(d: np.ndarray, near: float, far: float) -> np.ndarray:
    """(distance - near) / (far - near) for a 0..1 perspective depth."""
    d = d.astype(np.float64)
    z = near * far / (far - d * (far - near))
    return (z - near) / (far - near)


def turbo(x: np.ndarray) -> np.ndarray:
    """Mikhailov's polynomial turbo map, as debug_view.comp.glsl evaluates it."""
    x = np.clip(x.astype(np.float64), 0.0, 1.0)
    v4 = np.stack([np.ones_like(x), x, x * x, x * x * x], axis=-1)
    v2 = v4[..., 2:4] * v4[..., 2:3]
    c4 = np.array([[0.13572138, 4.61539260, -42.66032258, 132.13108234],
                   [0.09140261, 2.19418839, 4.84296658, -14.18503333],
                   [0.10667330, 12.64194608, -60.58204836, 110.36276771]])
    c2 = np.array([[-152.94239396, 59.28637943], [4.27729857, 2.82956604],
                   [-89.90310912, 27.34824973]])
    return np.clip(v4 @ c4.T + v2 @ c2.T, 0.0, 1.0)


def test_normals_map_to_half_plus_half(device):
    n = np.random.default_rng(7).uniform(-1, 1, (8, 8, 4)).astype(np.float16)
    out = view("rgba16float", n, device, mode="normals")
    expected = (n[..., :3].astype(np.float64) * 0.5 + 0.5) * 255
    assert_unorm8(out[..., :3], expected)
    np.testing.assert_array_equal(out[..., 3], 255)


@pytest.mark.parametrize("fmt", ["rgba8unorm", "rgba8unorm-srgb"])
def test_color_mode_passes_bytes_through(fmt, device):
    img = np.random.default_rng(3).integers(0, 256, (8, 8, 4), dtype=np.uint8)
    np.testing.assert_array_equal(view(fmt, img, device, mode="albedo"), img)


def test_depth_linearised_with_camera_near_and_far(device):
    sc = wall_scene()  # only its camera matters: near 0.1, far 50
    d = np.linspace(0.5, 0.999, 64, dtype=np.float32).reshape(8, 8, 1)
    out = view("r32float", d, device, scene=sc, mode="depth", range=(0.0, 0.1))
    expected = np.clip(linear_depth(d[..., 0], 0.1, 50.0) / 0.1, 0, 1) * 255
    assert_unorm8(out[..., 0], expected)
    assert (out[..., 0] == out[..., 1]).all() and (out[..., 0] == out[..., 2]).all()
    assert len(np.unique(out[..., 0])) > 20  # the range spreads the values


def test_heatmap_of_one_channel(device):
    src = np.zeros((4, 16, 4), np.float32)
    src[..., 2] = np.linspace(-1.5, 3.5, 64, dtype=np.float32).reshape(4, 16)
    src[..., 0] = 0.75  # other channels are ignored
    out = view("rgba32float", src, device, mode="heatmap", channel=2, range=(-1.0, 3.0))
    expected = turbo((src[..., 2] + 1.0) / 4.0) * 255
    assert_unorm8(out[..., :3], expected)
    # negative control: the map over a range 2.5 % wider is told apart
    with pytest.raises(AssertionError, match="nearest"):
        assert_unorm8(out[..., :3], turbo((src[..., 2] + 1.0) / 4.1) * 255)
    # below and above the range clamp to the map's ends
    np.testing.assert_array_equal(out[0, 0], out[0, 1])
    np.testing.assert_array_equal(out[-1, -1], out[-1, -2])


def test_depth_buffer_binds_as_a_depth_texture(tmp_path, device):
    path = tmp_path / "depth_view.toml"
    path.write_text("""
name = "depth_view"
size = [64, 48]
outputs = ["gbuffer.depth", "debug.view"]

[[pass]]
name = "gbuffer"

[[pass]]
name = "debug"
use = "debug_view"
inputs = { source = "gbuffer.depth" }
settings = { mode = "depth", range = [0.0, 0.2] }
""")
    sc = corner_scene()
    images = render(load_config(path), scene=sc, device=device).images
    cam = sc.cameras[0]
    d = images["gbuffer.depth"][..., 0]
    expected = np.clip(linear_depth(d, cam.znear, cam.zfar) / 0.2, 0, 1) * 255
    got = images["debug.view"][..., 0]
    assert_unorm8(got, expected)
    # negative control: a far plane 5 % off is told apart
    wrong = np.clip(linear_depth(d, cam.znear, cam.zfar * 1.05) / 0.2, 0, 1) * 255
    with pytest.raises(AssertionError, match="nearest"):
        assert_unorm8(got, wrong)
    assert int(got.max()) - int(got.min()) > 20  # near floor darker than the far wall


def test_eight_bit_check_allows_the_two_nearest_codes_only():
    # Vulkan lets a float to UNORM conversion give either neighbour: 127.5 may be 127 or 128
    assert_unorm8(np.array([127, 128, 10, 11], np.uint8), np.array([127.5, 127.5, 10.3, 10.3]))
    for wrong in (9, 12):
        with pytest.raises(AssertionError, match="nearest"):
            assert_unorm8(np.array([wrong], np.uint8), np.array([10.3]))
    with pytest.raises(AssertionError, match="nearest"):
        assert_unorm8(np.array([254], np.uint8), np.array([255.0]), slack=0)


def test_unknown_mode_suggests_the_closest():
    with pytest.raises(SettingsError, match="heatmap"):
        get_pass("debug_view")("debug", mode="heatmpa")
    assert get_pass("debug_view")("debug", mode=3).mode == 3
