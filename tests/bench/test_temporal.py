"""rfw.bench.temporal on analytic frames: the flicker index is the mean luminance change
over still pixels, in linear units; per-frame errors give their mean and spread; and
``run_flicker`` reads what ``rfw run --save-every 1`` writes."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from rfw.bench.temporal import (
    box_down,
    flicker_index,
    frame_errors,
    linear_luminance,
    run_flicker,
    run_frames,
    still_pixels,
)
from rfw.errors import RfwError


def _grey(level: float, shape=(4, 6)) -> np.ndarray:
    return np.full((*shape, 3), level, np.float32)


def test_luminance_decodes_8_bit_srgb_and_keeps_floats_linear():
    assert linear_luminance(np.full((1, 1, 4), 255, np.uint8))[0, 0] == pytest.approx(1.0)
    # sRGB level 188 is 0.5029 linear (the standard curve), 0 stays 0
    assert linear_luminance(np.full((1, 1, 3), 188, np.uint8))[0, 0] == pytest.approx(
        0.50289, abs=1e-4)
    rgb = np.array([[[1.0, 0.0, 0.0]]], np.float32)
    assert linear_luminance(rgb)[0, 0] == pytest.approx(0.2126)
    assert linear_luminance(np.full((2, 2, 1), 3.0, np.float16))[0, 0] == 3.0


def test_still_frames_do_not_flicker_and_alternating_ones_do_by_their_change():
    still = flicker_index([_grey(0.25)] * 4)
    assert still.index == 0.0 and still.still_share == 1.0
    # every other frame 0.25 brighter in a quarter of the pixels: 0.0625 on average
    a, b = _grey(0.5), _grey(0.5)
    b[:1] += 0.25
    out = flicker_index([a, b, a, b])
    assert out.index == pytest.approx(0.0625) and out.per_pair == pytest.approx([0.0625] * 3)


def test_moving_pixels_are_left_out_by_velocity_and_depth():
    a, b = _grey(0.5), _grey(0.5)
    b[:, :3] = 0.9  # the left half changes...
    velocity = [np.zeros((4, 6, 2), np.float32) for _ in range(2)]
    depth = [np.full((4, 6), 0.5, np.float32) for _ in range(2)]
    assert flicker_index([a, b], velocity=velocity, depth=depth).index == pytest.approx(0.2)
    velocity[1][:, :3, 0] = 1.5  # ... because it moved: then only the still half counts
    out = flicker_index([a, b], velocity=velocity, depth=depth)
    assert out.index == 0.0 and out.still_share == 0.5
    depth[1][:, 3:] = 0.2  # something came in front of the other half: nothing counts
    out = flicker_index([a, b], velocity=velocity, depth=depth)
    assert out.index is None and out.per_pair == [None] and out.still_share == 0.0


def test_a_surface_from_around_the_pixel_is_still_a_nearer_one_is_not():
    velocity = np.zeros((1, 4, 2))
    # 1 - depth (near / distance): an edge between 0.01 and 0.005, a jitter may show either
    before = np.array([[0.99, 0.99, 0.995, 0.995]])
    now = np.array([[0.9896, 0.995, 0.99, 0.9894]])
    # 4 % nearer, the neighbour's surface, the other neighbour's, and twice as near as any
    # surface around it
    assert still_pixels(velocity, now, before).tolist() == [[True, True, True, False]]


def test_background_is_not_counted_as_still_when_motion_is_given():
    velocity = np.zeros((2, 2, 2))
    depth = np.array([[1.0, 0.5], [0.5, 0.5]])
    assert still_pixels(velocity, depth, depth).tolist() == [[False, True], [True, True]]


def test_bad_sequences_are_refused():
    with pytest.raises(RfwError, match="at least two frames"):
        flicker_index([_grey(0.1)])
    with pytest.raises(RfwError, match="differ in size"):
        flicker_index([_grey(0.1), _grey(0.1, (2, 2))])
    with pytest.raises(RfwError, match="both velocity and depth"):
        flicker_index([_grey(0.1)] * 2, velocity=[np.zeros((4, 6, 2))] * 2)


def test_frame_errors_give_each_frame_and_the_spread():
    frames = [_grey(0.5), _grey(0.6), _grey(0.8)]
    refs = [_grey(0.5)] * 3
    out = frame_errors(frames, refs)
    assert out.per_frame == pytest.approx([0.0, 0.1, 0.3])
    assert out.mean == pytest.approx(0.4 / 3)
    assert out.std == pytest.approx(np.std([0.0, 0.1, 0.3], ddof=1))
    with pytest.raises(RfwError, match="one reference per frame"):
        frame_errors(frames, refs[:2])


def test_box_down_averages_linear_values():
    img = np.zeros((4, 4, 4), np.uint8)
    img[:2, :2] = 255  # one 2x2 block white
    out = box_down(img, 2)
    assert out.shape == (2, 2, 4)
    assert out[0, 0, :3] == pytest.approx([1.0] * 3) and out[1, 1, :3] == pytest.approx([0] * 3)
    half = box_down(np.array([[[0, 0, 0], [255, 255, 255]]], np.uint8), 1)
    assert half[0, 1, 0] == 1.0  # linear, so 8-bit 255 is 1


def test_run_flicker_reads_the_saved_frames(tmp_path):
    frames = tmp_path / "frames"
    frames.mkdir()
    for k in range(4):
        level = 100 if k % 2 else 120
        Image.fromarray(np.full((3, 5, 3), level, np.uint8)).save(
            frames / f"tonemap.ldr.{k:04d}.png")
    levels = [linear_luminance(np.full((1, 1, 3), v, np.uint8))[0, 0] for v in (100, 120)]
    assert run_flicker(tmp_path).index == pytest.approx(abs(levels[1] - levels[0]))
    assert len(run_flicker(tmp_path, skip=2).per_pair) == 1  # frames 2 and 3
    assert len(run_frames(tmp_path, "tonemap.ldr")) == 4
    with pytest.raises(RfwError, match=r"no frames of 'fxaa\.color'"):
        run_frames(tmp_path, "fxaa.color")
    (frames / "tonemap.ldr.0002.png").unlink()
    with pytest.raises(RfwError, match="not consecutive"):
        run_frames(tmp_path)


def test_run_flicker_of_rfw_runs_saving_every_frame(tmp_path):
    from ..cli.warm import warm_cli
    from ..conftest import ROOT

    def flicker(aa: str) -> float:
        out = tmp_path / aa
        done = warm_cli("run", ROOT / "configs" / "deferred_ssao_shadows.toml", "--size",
                        "32x18", "--frames", "6", "--save-every", "1", "--set", f"aa={aa}",
                        "--out", out)
        assert done.returncode == 0, done.stderr
        return run_flicker(out, "fxaa.color", skip=2).index

    assert flicker("none") == 0.0  # the same frame six times
    assert flicker("taa") > 0.0  # jittered
