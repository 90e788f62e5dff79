"""The G-buffer's motion vectors on both backends: zero for a still camera (jittered or
not), and the analytic screen motion of a known camera move (each pixel's surface, found
from its depth, projected by last frame's camera), with the negative control of a frame
that forgets last frame's matrices."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from pass_scenes import still, tiny_scene

from rfw.backends.scene_data import CameraFrames, jitter_offset, jittered
from rfw.config import apply_overrides, load_config
from rfw.render import render

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
W, H = 64, 36
# float16 steps by 2^-10 between 1 and 2 pixels: measured on lavapipe, the largest error of
# a 1.9 px motion is 0.00098 px on both backends
TOLERANCE = 0.01



def _frames(backend, config: str, sets: list[str], frames: int) -> list[dict]:
    """Each timed frame's velocity, depth and the index the scene's camera began it with."""
    name, dev = backend
    cfg = apply_overrides(load_config(CONFIGS / config), [f"size={W}x{H}", f"frames={frames}",
                                                          *sets])
    cfg = replace(cfg, outputs=[*cfg.outputs, "gbuffer.velocity", "gbuffer.depth"])
    got: list[dict] = []

    def read(k, frame):
        got.append({"velocity": frame.read("gbuffer.velocity").astype(np.float64),
                    "depth": frame.read("gbuffer.depth")[..., 0].astype(np.float64),
                    "index": frame.scenes[0].frames.index})

    render(cfg, scene=tiny_scene(), backend=name, device=dev, each_frame=read)
    return got


def _path(a, b) -> str:
    return (f"camera.path.keys=[{{position={list(a.position)}, target={list(a.target)}}}, "
            f"{{position={list(b.position)}, target={list(b.target)}}}]")


def _analytic(depth: np.ndarray, before, now, jitter: tuple[float, float]) -> np.ndarray:
    """Pixels from each pixel's surface now to where ``before`` saw it: the surface from the
    depth through this frame's (jittered) camera, projected by both unjittered cameras."""
    size = (depth.shape[1], depth.shape[0])

    def vp(cam, offset=(0.0, 0.0)):
        proj = cam.projection(size[0] / size[1])
        return jittered(proj, offset, size).astype(np.float64) @ cam.view().astype(np.float64)

    y, x = np.mgrid[0:size[1], 0:size[0]] + 0.5
    ndc = np.stack([x / size[0] * 2 - 1, 1 - y / size[1] * 2, depth, np.ones_like(depth)], -1)
    world = ndc @ np.linalg.inv(vp(now, jitter)).T
    world /= world[..., 3:]

    def pixels(cam):
        p = world @ vp(cam).T
        p = p[..., :2] / p[..., 3:]
        return np.stack([(p[..., 0] + 1) / 2 * size[0], (1 - p[..., 1]) / 2 * size[1]], -1)

    return pixels(before) - pixels(now)


@pytest.mark.parametrize(("config", "sets"), [
    ("deferred.toml", ["gbuffer.velocity=true"]),
    ("deferred_ssao_shadows.toml", ["aa=taa"]),  # jittered: the motion leaves the jitter out
])
def test_a_still_camera_has_no_motion(backend, config, sets):
    frames = _frames(backend, config, sets, 3)
    for f in frames:
        assert still(f["velocity"])
        assert (f["depth"] < 1).mean() > 0.3  # the scene covers the frame: a real test


@pytest.mark.parametrize(("config", "sets", "jitter"), [
    ("deferred.toml", ["gbuffer.velocity=true"], 0),
    ("deferred_ssao_shadows.toml", ["aa=taa"], 8),
])
def test_a_camera_move_gives_the_analytic_motion(backend, config, sets, jitter):
    base = tiny_scene().cameras[0]
    before = replace(base, position=(3.0, 2.5, 4.0), target=(0.0, 0.3, 0.0))
    now = replace(base, position=(3.2, 2.6, 3.8), target=(0.1, 0.3, 0.0))
    frames = _frames(backend, config, [*sets, _path(before, now)], 2)
    f = frames[1]
    drawn = f["depth"] < 1
    want = _analytic(f["depth"], before, now, jitter_offset(f["index"], jitter))
    assert np.abs(want[drawn]).max() > 1.5  # the move is pixels, not a rounding
    assert np.abs(f["velocity"] - want)[drawn].max() < TOLERANCE
    assert still(f["velocity"][~drawn])  # the clear where nothing is drawn
    assert still(frames[0]["velocity"])  # the first frame: its own matrices


def test_a_frame_that_forgets_last_frames_camera_fails_the_check(backend, monkeypatch):
    """Negative control: last frame's view-projection ignored (every frame begins as a
    first frame) gives no motion, far from the analytic one."""
    begin = CameraFrames.begin

    def forgetful(self, camera, size, index):
        self.index = None
        return begin(self, camera, size, index)

    monkeypatch.setattr(CameraFrames, "begin", forgetful)
    base = tiny_scene().cameras[0]
    before = replace(base, position=(3.0, 2.5, 4.0), target=(0.0, 0.3, 0.0))
    now = replace(base, position=(3.2, 2.6, 3.8), target=(0.1, 0.3, 0.0))
    f = _frames(backend, "deferred.toml", ["gbuffer.velocity=true", _path(before, now)], 2)[1]
    drawn = f["depth"] < 1
    want = _analytic(f["depth"], before, now, (0.0, 0.0))
    assert still(f["velocity"])
    assert np.abs(f["velocity"] - want)[drawn].max() > 100 * TOLERANCE
