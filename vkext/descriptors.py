"""Per-frame descriptor sets and uniform data: pools and a ring rewound each frame."""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Sequence
from typing import Any

import numpy as np

from rfw.units import align_up

from .device import VkDevice
from .memory import BlockAllocator, Buffer
from .objects import BufferRange, DescriptorPool


class FrameDescriptors:
    """Descriptor sets for one frame from pools that are reset together each frame; a new
    pool is added when the current one would run out (counted here, never by failing)."""

    SETS, PER_KIND = 64, 256
    KINDS = ("uniform_buffer", "storage_buffer", "sampled_image", "storage_image",
             "combined_image_sampler", "sampler", "acceleration_structure")

    def __init__(self, device: VkDevice):
        self.device = device
        self.pools: list[tuple[DescriptorPool, int]] = []  # (pool, descriptors per kind)
        self.current = 0
        self.sets = 0
        self.counts: dict[str, int] = defaultdict(int)

    def allocate(self, layout: Any, entries: Sequence[tuple[int, str, int]]) -> Any:
        """``VkDescriptorSet[1]`` of ``layout``, whose bindings are ``entries``."""
        need: dict[str, int] = defaultdict(int)
        for _, kind, n in entries:
            need[kind] += n
        while True:
            if self.current >= len(self.pools):
                size = max(self.PER_KIND, *need.values()) if need else self.PER_KIND
                pool = DescriptorPool(self.device, self.SETS, dict.fromkeys(self.KINDS, size),
                                      label=f"rfw:frame-descriptors{len(self.pools)}")
                self.pools.append((pool, size))
            pool, size = self.pools[self.current]
            if self.sets < self.SETS and all(self.counts[k] + n <= size
                                             for k, n in need.items()):
                break
            self.current, self.sets, self.counts = self.current + 1, 0, defaultdict(int)
        out = pool.allocate([layout])
        self.sets += 1
        for k, n in need.items():
            self.counts[k] += n
        return out

    def reset(self) -> None:
        for pool, _ in self.pools:
            pool.reset()
        self.current, self.sets, self.counts = 0, 0, defaultdict(int)

    def destroy(self) -> None:
        for pool, _ in self.pools:
            pool.destroy()
        self.pools.clear()


class UniformRing:
    """Settings and raw bytes as uniform buffers: host-visible chunks written in order,
    rewound each frame (frames are waited for before the next one records)."""

    def __init__(self, allocator: BlockAllocator, alignment: int, chunk: int = 64 * 1024):
        self.allocator, self.alignment, self.chunk = allocator, max(16, alignment), chunk
        self.chunks: list[Buffer] = []
        self.index, self.offset = 0, 0

    def push(self, data: bytes) -> BufferRange:
        size = max(16, align_up(len(data), 16))
        while True:
            if self.index >= len(self.chunks):
                self.chunks.append(self.allocator.create_buffer(
                    max(self.chunk, size), ("uniform",), host_visible=True,
                    label=f"rfw:uniforms{len(self.chunks)}"))
            buf = self.chunks[self.index]
            offset = align_up(self.offset, self.alignment)
            if offset + size <= buf.bytes:
                break
            self.index, self.offset = self.index + 1, 0
        padded = np.zeros(size, np.uint8)
        padded[:len(data)] = np.frombuffer(data, np.uint8)
        buf.write(padded, offset)
        self.offset = offset + size
        return BufferRange(buf.handle, offset, size)

    def reset(self) -> None:
        self.index, self.offset = 0, 0

