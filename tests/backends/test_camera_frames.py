"""rfw.backends.scene_data's per-frame camera (no GPU): the Halton jitter, the jittered
projection, and which frame's matrices are "last frame's" in the motion block."""

from __future__ import annotations

import struct
from dataclasses import replace

import numpy as np

from rfw.backends.scene_data import (
    MOTION_BYTES,
    CameraFrames,
    halton,
    jitter_offset,
    jittered,
    main_camera_bytes,
)
from rfw.scene.model import Camera

SIZE = (64, 36)


def _motion(data: bytes) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple]:
    assert len(data) == MOTION_BYTES
    m = np.frombuffer(data[:192], np.float32).reshape(3, 4, 4).transpose(0, 2, 1)
    return m[0], m[1], m[2], struct.unpack("<4f", data[192:])


def _f32(*values: float) -> tuple[float, ...]:
    return tuple(float(np.float32(v)) for v in values)


def _vp(cam: Camera) -> np.ndarray:
    return (cam.projection(SIZE[0] / SIZE[1]).astype(np.float64)
            @ cam.view().astype(np.float64)).astype(np.float32)


def test_halton_points_are_the_radical_inverses():
    assert [halton(k, 2) for k in range(1, 5)] == [0.5, 0.25, 0.75, 0.125]
    assert np.allclose([halton(k, 3) for k in range(1, 5)], [1 / 3, 2 / 3, 1 / 9, 4 / 9])


def test_jitter_cycles_its_phases_inside_the_pixel():
    offsets = [jitter_offset(k, 8) for k in range(16)]
    assert offsets[:8] == offsets[8:]  # 8 phases, then again
    assert len(set(offsets[:8])) == 8
    assert all(-0.5 <= c < 0.5 for o in offsets for c in o)
    assert np.abs(np.mean(offsets[:8], axis=0)).max() < 0.1  # centred on the pixel
    assert jitter_offset(5, 0) == (0.0, 0.0)


def test_a_jittered_projection_moves_the_image_by_its_offset():
    cam = Camera((1.0, 2.0, 5.0), (0.0, 0.5, 0.0))
    proj = cam.projection(SIZE[0] / SIZE[1])
    p = cam.view().astype(np.float64) @ np.array([0.3, 0.7, -0.2, 1.0])

    def pixel(m):
        c = m.astype(np.float64) @ p
        return np.array([(c[0] / c[3] + 1) / 2 * SIZE[0], (1 - c[1] / c[3]) / 2 * SIZE[1]])

    moved = pixel(jittered(proj, (0.25, -0.375), SIZE)) - pixel(proj)
    assert np.allclose(moved, (0.25, -0.375), atol=1e-4)  # x right, y down
    assert np.array_equal(jittered(proj, (0.0, 0.0), SIZE), proj)


def test_without_jitter_the_camera_is_the_unjittered_one():
    # the bytes every existing config uploads: unchanged, frame after frame
    cam = Camera((1.0, 2.0, 5.0), (0.0, 0.5, 0.0))
    frames = CameraFrames()
    assert frames.still(cam, SIZE)[0] == main_camera_bytes(cam, SIZE)
    for k in range(3):
        assert frames.begin(cam, SIZE, k)[0] == main_camera_bytes(cam, SIZE)
    frames.jitter = 8  # negative control: jitter changes the projection
    assert frames.begin(cam, SIZE, 3)[0] != main_camera_bytes(cam, SIZE)


def test_last_frames_matrices_are_those_of_the_frame_begun_before():
    a = Camera((1.0, 2.0, 5.0), (0.0, 0.5, 0.0))
    b = replace(a, position=(1.5, 2.0, 5.0))
    c = replace(a, position=(2.0, 2.0, 5.0))
    frames = CameraFrames()
    frames.jitter = 8
    prev, prev_inv, now, jitter = _motion(frames.begin(a, SIZE, 0)[1])
    assert np.array_equal(prev, now) and np.allclose(now, _vp(a))  # the first: its own
    assert np.allclose(prev_inv @ prev, np.identity(4), atol=1e-4)
    assert jitter[:2] == _f32(*jitter_offset(0, 8)) and jitter[2:] == jitter[:2]
    assert frames.begin(b, SIZE, 0) is None  # the same frame again: nothing to write
    prev, _, now, jitter = _motion(frames.begin(b, SIZE, 1)[1])
    assert np.allclose(prev, _vp(a)) and np.allclose(now, _vp(b))
    assert jitter == _f32(*jitter_offset(1, 8), *jitter_offset(0, 8))
    # a camera set between frames is the next frame's: frame 1's matrices stay b's
    frames.still(c, SIZE)
    prev, _, now, _ = _motion(frames.begin(c, SIZE, 2)[1])
    assert np.allclose(prev, _vp(b)) and np.allclose(now, _vp(c))
    # a frame that does not follow the last one (a new executor) has no last frame
    prev, _, now, _ = _motion(frames.begin(a, SIZE, 0)[1])
    assert np.array_equal(prev, now)
