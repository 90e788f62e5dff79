"""Persistent resources: large blocks with first-fit sub-allocation."""

from __future__ import annotations

import bisect
from collections.abc import Iterable
from dataclasses import dataclass

from rfw.units import MiB, align_up

from .allocation import DEVICE_LOCAL, HOST_COHERENT, HOST_VISIBLE, DeviceMemory, find_memory_type
from .buffers import Buffer
from .device import VkDevice
from .images import Image


@dataclass(eq=False)
class SubAllocation:
    """A range of a block; ``linear`` is True for buffers (and linear images)."""

    block: _Block
    offset: int
    size: int
    linear: bool
    label: str = ""

    @property
    def memory(self) -> DeviceMemory:
        return self.block.memory

    @property
    def end(self) -> int:
        return self.offset + self.size

    def free(self) -> None:
        self.block.owner.free(self)


class _Block:
    def __init__(self, owner: BlockAllocator, memory: DeviceMemory):
        self.owner, self.memory = owner, memory
        self.allocs: list[SubAllocation] = []  # sorted by offset

    @property
    def used(self) -> int:
        return sum(a.size for a in self.allocs)

    def gaps(self) -> list[tuple[int, int]]:
        out, cursor = [], 0
        for a in self.allocs:
            if a.offset > cursor:
                out.append((cursor, a.offset))
            cursor = max(cursor, a.end)
        if cursor < self.memory.size:
            out.append((cursor, self.memory.size))
        return out

    def fit(self, size: int, alignment: int, linear: bool, granularity: int) -> int | None:
        """First fit: the lowest offset where the range fits, aligned, and shares no
        bufferImageGranularity page with a neighbour of the other kind."""
        def page(x: int) -> int:
            return x // granularity

        prev: SubAllocation | None = None
        for i in range(len(self.allocs) + 1):
            nxt = self.allocs[i] if i < len(self.allocs) else None
            start = prev.end if prev else 0
            stop = nxt.offset if nxt else self.memory.size
            o = align_up(start, alignment)
            if prev and prev.linear != linear and page(prev.end - 1) == page(o):
                o = align_up(o, max(alignment, granularity))
            fits = o + size <= stop
            if fits and nxt and nxt.linear != linear and page(o + size - 1) == page(nxt.offset):
                fits = False
            if fits:
                return o
            prev = nxt
        return None

    def insert(self, a: SubAllocation) -> None:
        bisect.insort(self.allocs, a, key=lambda x: x.offset)


class BlockAllocator:
    """Persistent resources (meshes, textures, history images) sub-allocated from large
    blocks, one list of blocks per memory type; a request larger than a block gets a block
    of its own. First fit, alignment and ``bufferImageGranularity`` respected."""

    def __init__(self, device: VkDevice, *, block_size: int = 64 * MiB,
                 label: str = "blocks"):
        self.device, self.block_size, self.label = device, int(block_size), label
        self.granularity = max(1, int(device.limits["bufferImageGranularity"]))
        self.blocks: dict[int, list[_Block]] = {}
        self.resources: list[Image | Buffer] = []  # what create_* made, destroyed with it
        device.register(self)

    def allocate(self, size: int, alignment: int, type_bits: int, *, linear: bool,
                 host_visible: bool = False, label: str = "") -> SubAllocation:
        required = [HOST_VISIBLE, HOST_COHERENT] if host_visible else []
        type_index = find_memory_type(self.device, type_bits, required,
                                      [] if host_visible else [DEVICE_LOCAL])
        blocks = self.blocks.setdefault(type_index, [])
        for block in blocks:
            o = block.fit(size, alignment, linear, self.granularity)
            if o is not None:
                break
        else:
            block_bytes = max(self.block_size, align_up(size, self.granularity))
            mem = DeviceMemory(self.device, block_bytes, 1 << type_index,
                               host_visible=host_visible,
                               label=f"{self.label}:block{sum(map(len, self.blocks.values()))}")
            block = _Block(self, mem)
            blocks.append(block)
            o = 0
        a = SubAllocation(block, o, int(size), linear, label)
        block.insert(a)
        return a

    def free(self, a: SubAllocation) -> None:
        block = a.block
        if a not in block.allocs:
            return
        block.allocs.remove(a)
        self.resources = [r for r in self.resources if r.sub_allocation is not a]
        blocks = self.blocks.get(block.memory.type_index, [])
        # an empty block goes back unless it is the last regular one of its type
        if not block.allocs and (len(blocks) > 1 or block.memory.size > self.block_size):
            blocks.remove(block)
            block.memory.destroy()

    def _bind(self, res: Image | Buffer, *, host_visible: bool) -> Image | Buffer:
        try:
            a = self.allocate(res.size, res.alignment, res.type_bits,
                              linear=isinstance(res, Buffer), host_visible=host_visible,
                              label=res.label)
            res.sub_allocation = a
            res.bind(a.memory, a.offset)
        except BaseException:
            res.destroy()
            raise
        self.resources.append(res)
        return res

    def create_image(self, width: int, height: int, format: str, usage: Iterable[str] | int,
                     *, mips: int = 1, layers: int = 1, samples: int = 1,
                     label: str = "") -> Image:
        img = Image(self.device, width, height, format, usage, mips=mips, layers=layers,
                    samples=samples, label=label)
        return self._bind(img, host_visible=False)  # type: ignore[return-value]

    def create_buffer(self, size: int, usage: Iterable[str] | int, *,
                      host_visible: bool = False, label: str = "") -> Buffer:
        buf = Buffer(self.device, size, usage, label=label)
        return self._bind(buf, host_visible=host_visible)  # type: ignore[return-value]

    def stats(self) -> dict[str, int]:
        blocks = [b for bs in self.blocks.values() for b in bs]
        block_bytes = sum(b.memory.size for b in blocks)
        used = sum(b.used for b in blocks)
        gaps = [e - s for b in blocks for s, e in b.gaps()]
        return {"blocks": len(blocks), "block_bytes": block_bytes, "used_bytes": used,
                "free_bytes": block_bytes - used,
                "allocations": sum(len(b.allocs) for b in blocks),
                "largest_free": max(gaps, default=0)}

    def destroy(self) -> None:
        for res in self.resources:
            res.destroy()
        self.resources.clear()
        for blocks in self.blocks.values():
            for b in blocks:
                b.memory.destroy()
        self.blocks.clear()
        self.device.unregister(self)
