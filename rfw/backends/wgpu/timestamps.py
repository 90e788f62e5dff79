"""Per-pass GPU timestamps: what a frame in flight owns until it is finished
(:class:`FrameSlot`) and frames' timestamps read back in batches (:class:`Stamps`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import wgpu

from .calls import FrameCalls


@dataclass(eq=False)
class FrameSlot:
    """What one frame in flight owns until it is finished: its timestamp query set and
    the buffer its queries resolve into (copied from there into the executor's
    :class:`Stamps`), a mappable copy for a frame's earlier submits (``flush``: read at
    once), and the index of the submit that finishes the frame (waited for when the slot
    comes round again)."""

    query_set: Any
    resolve: Any
    readback: Any
    calls: FrameCalls
    index: int | None = None  # the last submit of the slot's frame, until waited for

    def wait(self) -> None:
        """Wait until the slot's last submit is done."""
        index, self.index = self.index, None
        if index is not None:
            self.calls.wait(index)

    def destroy(self) -> None:
        for obj in (self.query_set, self.resolve, self.readback):
            if obj is not None:
                obj.destroy()


STAMP_BATCH = 32  # frames whose timestamps are read back together (Stamps)


class Stamps:
    """Frames' timestamps, read back ``frames`` frames at a time (a mapping costs more
    than the rest of a short frame's fixed calls together). Frame ``f`` copies its
    resolved queries into buffer ``(f // frames) % 2`` at its place in that batch; once
    the batch's last frame is finished (or the executor drains), the buffer is mapped,
    read and unmapped in one go. Frames in flight (at most ``frames``) write the other
    buffer meanwhile, so a mapped buffer is never one a submitted copy writes."""

    def __init__(self, device: Any, frame_bytes: int, frames: int):
        self.frame_bytes, self.frames = frame_bytes, frames
        self.buffers = [device.create_buffer(
            size=frame_bytes * frames,
            usage=wgpu.BufferUsage.MAP_READ | wgpu.BufferUsage.COPY_DST,
            label=f"rfw:timestamps:read{k}") for k in range(2)]
        # frames finished and not read yet: (frame index, bytes used, what to do with them)
        self.unread: list[tuple[int, int, Callable[[np.ndarray], None]]] = []

    def place(self, frame: int) -> tuple[Any, int]:
        """The buffer and offset frame ``frame`` copies its timestamps to."""
        return self.buffers[(frame // self.frames) % 2], (frame % self.frames) * self.frame_bytes

    def finished(self, frame: int, used: int, done: Callable[[np.ndarray], None]) -> None:
        """Frame ``frame`` is finished: ``done(stamps)`` gets its ``used`` bytes of
        timestamps (as uint64) once its batch is read."""
        self.unread.append((frame, used, done))
        if frame % self.frames == self.frames - 1:
            self.read()

    def read(self) -> None:
        """Read every finished frame's timestamps (their submits are done), oldest first."""
        unread, self.unread = self.unread, []
        for k in dict.fromkeys((f // self.frames) % 2 for f, _, _ in unread):
            buf = self.buffers[k]
            buf.map_sync("READ_NOSYNC")
            try:
                raw = np.frombuffer(buf.read_mapped(), np.uint64)
            finally:
                buf.unmap()
            for f, used, done in unread:
                if (f // self.frames) % 2 == k:
                    at = (f % self.frames) * self.frame_bytes // 8
                    done(raw[at:at + used // 8])

    def destroy(self) -> None:
        for b in self.buffers:
            b.destroy()
        self.unread.clear()
