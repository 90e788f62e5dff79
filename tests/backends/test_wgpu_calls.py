"""The wgpu frame's fixed calls (rfw.backends.wgpu.calls) and batched timestamp reads
(rfw.backends.wgpu.timestamps.Stamps): descriptors are built once and replayed, a new
attachment builds a new one, validation errors still raise, a submit's index is what a frame
waits for, and every frame gets its timing samples, whether its batch was read whole or a
drain read part of it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import wgpu

from rfw.backends.wgpu import executor
from rfw.backends.wgpu.calls import FrameCalls
from rfw.backends.wgpu.timestamps import Stamps
from rfw.config import apply_overrides, build, load_config
from rfw.frame import camera_for, open_frame

from ..conftest import tiny_scene

ROOT = Path(__file__).resolve().parents[2]


def _open(name: str = "flat", size: str = "32x24"):
    cfg = apply_overrides(load_config(ROOT / "configs" / f"{name}.toml"), [f"size={size}"])
    scene = tiny_scene()
    return open_frame(build(cfg, scene), "wgpu", scene=scene, camera=camera_for(cfg, scene))


def _target(device, usage=wgpu.TextureUsage.RENDER_ATTACHMENT | wgpu.TextureUsage.COPY_SRC):
    return device.create_texture(size=(8, 8, 1), format="rgba8unorm", usage=usage).create_view()


def _read(device, view) -> np.ndarray:
    data = device.queue.read_texture({"texture": view.texture, "mip_level": 0},
                                     {"offset": 0, "bytes_per_row": 8 * 4}, (8, 8, 1))
    return np.frombuffer(data, np.uint8).reshape(8, 8, 4)


def test_descriptors_are_built_once_per_frame_shape():
    frame = _open()
    try:
        frame.run(2)
        calls = next(iter(frame.executors.values())).calls
        made = calls.made
        assert made > 0
        frame.run(20)
        assert calls.made == made  # 20 more frames replay the same descriptors
    finally:
        frame.destroy()


@pytest.fixture
def gpu(device):
    return device.device  # rfw's Device holds wgpu's


def test_a_changed_attachment_builds_a_new_descriptor_and_renders_it(gpu):
    device = gpu
    calls = FrameCalls(device)
    view = _target(device)
    for clear, made in (((1, 0, 0, 1), 1), ((1, 0, 0, 1), 1), ((0, 0, 1, 1), 2)):
        enc = calls.encoder()
        att = [{"view": view, "load_op": "clear", "store_op": "store", "clear_value": clear}]
        calls.render_pass(enc, "t", att, None, None).end()
        calls.wait(calls.submit(enc))
        assert calls.made == made
        # what the pass cleared to is this call's colour, not the first descriptor's
        assert tuple(_read(device, view)[0, 0]) == tuple(int(255 * c) for c in clear)


def test_validation_errors_still_raise(gpu):
    device = gpu
    calls = FrameCalls(device)
    view = _target(device, usage=wgpu.TextureUsage.TEXTURE_BINDING)  # not renderable
    enc = calls.encoder()
    att = [{"view": view, "load_op": "clear", "store_op": "store", "clear_value": (0, 0, 0, 1)}]
    with pytest.raises(wgpu.GPUValidationError):
        calls.render_pass(enc, "t", att, None, None).end()
        calls.submit(enc)


def test_wait_is_for_the_submit_by_index(gpu):
    device = gpu
    calls = FrameCalls(device)
    src = device.create_buffer_with_data(data=np.arange(64, dtype=np.uint32),
                                         usage=wgpu.BufferUsage.COPY_SRC)
    dst = device.create_buffer(size=256, usage=wgpu.BufferUsage.COPY_DST |
                               wgpu.BufferUsage.MAP_READ)
    enc = calls.encoder()
    enc.copy_buffer_to_buffer(src, 0, dst, 0, 256)
    index = calls.submit(enc)
    assert isinstance(index, int) and index > 0
    calls.wait(index)
    dst.map_sync("READ_NOSYNC")  # no submit left to wait for: the copy is there
    assert np.array_equal(np.frombuffer(dst.read_mapped(), np.uint32), np.arange(64))
    dst.unmap()


@pytest.mark.parametrize("frames", [1, 5, 16, 21, 40])
def test_every_frame_gets_its_samples_across_batches(frames, monkeypatch):
    monkeypatch.setattr(executor, "STAMP_BATCH", 8)
    frame = _open("deferred")
    try:
        ex = next(iter(frame.executors.values()))
        if ex.stamps is None:
            pytest.skip("the device has no timestamp queries")  # lavapipe and NVIDIA have
        frame.run(3)  # a drain mid-batch reads part of it
        frame.clear_timings()
        frame.run(frames)
        for name, t in ex.timings.items():
            assert len(t.cpu_ms) == frames, name
            assert len(t.gpu_ms) == frames, name
            assert all(ms > 0 for ms in t.gpu_ms), (name, t.gpu_ms)
    finally:
        frame.destroy()


def test_a_batch_is_read_only_after_its_last_frame(monkeypatch):
    monkeypatch.setattr(executor, "STAMP_BATCH", 8)
    reads: list[int] = []
    real = Stamps.read

    def counted(self):
        reads.append(len(self.unread))
        real(self)

    monkeypatch.setattr(Stamps, "read", counted)
    frame = _open()
    try:
        frame.run(1)
        reads.clear()
        frame.run(20)  # frames 1..20: batch ends after frames 7 and 15, then the drain
        assert reads == [7, 8, 5]
    finally:
        frame.destroy()
