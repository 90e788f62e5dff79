"""vkext.commands.record_upload: batched copies out of one staging buffer (buffers and every
mip of fresh images) with the barriers before and after them, the primitive the scene's
upload records through."""

from __future__ import annotations

import numpy as np
import pytest

from rfw.graph.sync import State
from vkext import Buffer, Image, one_time, read_buffer, read_image
from vkext.buffers import staging_buffer
from vkext.commands import BufferBarrier, barrier, record_upload
from vkext.consts import vk

from ..golden_util import changed_share

SAMPLED = State("SHADER_READ_ONLY_OPTIMAL", frozenset({"FRAGMENT_SHADER", "COMPUTE_SHADER"}),
                frozenset({"SHADER_SAMPLED_READ"}))
COPY_READ = State(None, frozenset({"COPY"}), frozenset({"TRANSFER_READ"}))
FRAGMENT_READ = State(None, frozenset({"FRAGMENT_SHADER"}), frozenset({"UNIFORM_READ"}))


def _staged(device, parts: list[np.ndarray]) -> tuple[Buffer, list[int]]:
    offsets, blob = [], bytearray()
    for p in parts:
        blob += b"\0" * (-len(blob) % 16)
        offsets.append(len(blob))
        blob += p.tobytes()
    staging = staging_buffer(device, len(blob), label="test:upload")
    staging.write(np.frombuffer(bytes(blob), np.uint8))
    return staging, offsets


def test_buffers_and_mips_arrive(vk_device):
    rng = np.random.default_rng(3)
    words = rng.integers(0, 1 << 32, 300, dtype=np.uint32)
    mips = [rng.integers(0, 256, (h, w, 4), dtype=np.uint8) for w, h in ((13, 7), (6, 3))]
    buf = Buffer(vk_device, words.nbytes, {"storage", "transfer_src", "transfer_dst"},
                 label="test:words")
    img = Image(vk_device, 13, 7, "rgba8unorm", {"sampled", "transfer_src", "transfer_dst"},
                mips=2, label="test:mips")
    made = [buf, img]
    try:
        buf.allocate()
        img.allocate()
        staging, (w0, m0, m1) = _staged(vk_device, [words, *mips])
        made.append(staging)
        with one_time(vk_device) as cmd:
            record_upload(cmd, staging, buffers=[(buf, w0, words.nbytes)],
                          images=[(img, [(m0, 0, 13, 7), (m1, 1, 6, 3)])], images_to=SAMPLED)
        assert np.array_equal(read_buffer(vk_device, buf, dtype=np.uint32), words)
        for k, want in enumerate(mips):
            got = read_image(vk_device, img, layout_now=SAMPLED, mip=k)
            assert np.array_equal(got, want), f"mip {k}"
        # the comparison can fail: the mips are not each other
        assert changed_share(mips[0][:3, :6], mips[1], over=0) > 0.5  # all 18 texels
    finally:
        for obj in reversed(made):
            obj.destroy()


def _copy_out(vk_device, buffers_to: State) -> list[str]:
    """Upload a buffer and, in the same command buffer (sync validation judges within a
    submit), copy it on; returns the validation messages."""
    data = np.arange(64, dtype=np.uint32)
    buf = Buffer(vk_device, data.nbytes, {"storage", "transfer_src", "transfer_dst"},
                 label="test:buf")
    out = staging_buffer(vk_device, data.nbytes, readback=True, label="test:out")
    made = [buf, out]
    try:
        buf.allocate()
        staging, (offset,) = _staged(vk_device, [data])
        made.append(staging)
        vk_device.check_validation()
        with one_time(vk_device) as cmd:
            record_upload(cmd, staging, buffers=[(buf, offset, data.nbytes)],
                          buffers_to=buffers_to)
            vk.vkCmdCopyBuffer(cmd, buf.handle, out.handle, 1,
                               [vk.VkBufferCopy(srcOffset=0, dstOffset=0, size=data.nbytes)])
            barrier(cmd, buffer_barriers=[BufferBarrier(
                out, State(None, frozenset({"COPY"}), frozenset({"TRANSFER_WRITE"})),
                State(None, frozenset({"HOST"}), frozenset({"HOST_READ"})))])
        texts = [m.text for m in vk_device.messages]
        if not texts:
            assert np.array_equal(out.read(np.uint32), data)
        return texts
    finally:
        vk_device.messages.clear()
        for obj in reversed(made):
            obj.destroy()


def test_the_barrier_after_the_copies_reaches_the_reader(vk_device):
    assert _copy_out(vk_device, COPY_READ) == []


def test_a_barrier_for_other_readers_is_a_hazard(vk_device):
    """Negative control: made visible to fragment shaders only, the copy that reads the
    uploaded bytes races with the upload; synchronization validation reports it."""
    if not vk_device.sync_validation:
        pytest.fail("synchronization validation is not available: this control needs it")
    texts = _copy_out(vk_device, FRAGMENT_READ)
    assert any("SYNC-HAZARD-READ-AFTER-WRITE" in t for t in texts), texts
