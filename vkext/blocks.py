"""Persistent resources: large blocks with good-fit sub-allocation from binned free ranges.

Scenes make thousands of small buffers (the OpenStreetMap city: about 12,000), so an
allocation must not scan what is already allocated: each block keeps its free ranges binned
by size class, and an allocation looks at a bounded number of them. The first-fit scan this
replaced stays as ``strategy="first-fit"``, for benchmarks and as a negative control.
"""

from __future__ import annotations

import bisect
from collections.abc import Iterable
from dataclasses import dataclass

from rfw.errors import RfwError
from rfw.units import MiB, align_up

from .allocation import DEVICE_LOCAL, HOST_COHERENT, HOST_VISIBLE, DeviceMemory, find_memory_type
from .buffers import Buffer
from .device import VkDevice
from .images import Image

STRATEGIES = ("good-fit", "first-fit")


@dataclass(eq=False)
class SubAllocation:
    """A range of a block; ``linear`` is True for buffers (and linear images)."""

    block: _Block | _FirstFitBlock
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


def _page_clash(a_last: int, b_first: int, granularity: int) -> bool:
    """Whether bytes ``a_last`` and ``b_first`` share a ``bufferImageGranularity`` page."""
    return a_last // granularity == b_first // granularity


def _place(start: int, stop: int, size: int, alignment: int, linear: bool, granularity: int,
           prev: SubAllocation | None, nxt: SubAllocation | None) -> int | None:
    """The lowest offset in the free range [start, stop) where ``size`` bytes fit, aligned,
    sharing no granularity page with a neighbour of the other kind; None if none does."""
    o = align_up(start, alignment)
    if prev and prev.linear != linear and _page_clash(prev.end - 1, o, granularity):
        o = align_up(o, max(alignment, granularity))
    if o + size > stop:
        return None
    if nxt and nxt.linear != linear and _page_clash(o + size - 1, nxt.offset, granularity):
        return None
    return o


def _sure_fit(size: int, alignment: int, granularity: int) -> int:
    # a free range this long always fits, whatever its neighbours: the alignment, a page
    # skipped after the previous allocation and one before the next
    return size + alignment + max(alignment, granularity) + granularity


PROBES = 8  # free ranges tried below the sure-fit size class before taking a sure one


class _Block:
    """One ``VkDeviceMemory`` and its free ranges, kept maximal (neighbours merge on free)
    and binned by size class (``floor(log2(bytes))``).

    An allocation tries at most ``PROBES`` ranges that might be too small, lowest class
    first, then the lowest-offset range of the smallest class sure to fit (a bit mask finds
    that class): its cost does not grow with the number of allocations in the block."""

    def __init__(self, owner: BlockAllocator, memory: DeviceMemory):
        self.owner, self.memory = owner, memory
        self.allocs: dict[int, SubAllocation] = {}  # by offset
        self._by_end: dict[int, SubAllocation] = {}
        self._free: dict[int, int] = {}  # free range start -> stop
        self._free_by_stop: dict[int, int] = {}  # stop -> start
        self._bins: dict[int, list[int]] = {}  # size class -> range starts, sorted
        self._mask = 0  # bit c set while bin c holds a range
        self.used = 0
        self._add_free(0, memory.size)

    def _add_free(self, start: int, stop: int) -> None:
        self._free[start], self._free_by_stop[stop] = stop, start
        c = (stop - start).bit_length() - 1
        bisect.insort(self._bins.setdefault(c, []), start)
        self._mask |= 1 << c

    def _take_free(self, start: int) -> int:
        stop = self._free.pop(start)
        del self._free_by_stop[stop]
        c = (stop - start).bit_length() - 1
        starts = self._bins[c]
        del starts[bisect.bisect_left(starts, start)]
        if not starts:
            self._mask &= ~(1 << c)
        return stop

    def gaps(self) -> list[tuple[int, int]]:
        return sorted(self._free.items())

    def _try(self, start: int, size: int, alignment: int, linear: bool,
             granularity: int) -> tuple[int, int] | None:
        self.owner.visits += 1
        stop = self._free[start]
        o = _place(start, stop, size, alignment, linear, granularity,
                   self._by_end.get(start), self.allocs.get(stop))
        return None if o is None else (start, o)

    def fit(self, size: int, alignment: int, linear: bool,
            granularity: int) -> tuple[int, int] | None:
        """(free range start, offset) to allocate at, or None when no free range holds it."""
        low = size.bit_length() - 1  # every range of a smaller class is too small
        sure = _sure_fit(size, alignment, granularity).bit_length()  # 2**sure is a sure fit
        probes = 0
        window = self._mask >> low & ((1 << (sure - low)) - 1)  # classes that may fit
        while window and probes < PROBES:
            bit = window & -window
            window ^= bit
            for start in self._bins[low + bit.bit_length() - 1][:PROBES - probes]:
                found = self._try(start, size, alignment, linear, granularity)
                if found:
                    return found
                probes += 1
        above = self._mask >> sure
        if not above:
            return None
        c = sure + (above & -above).bit_length() - 1
        return self._try(self._bins[c][0], size, alignment, linear, granularity)

    def insert(self, a: SubAllocation, start: int) -> None:
        """Take ``a``'s bytes out of the free range that begins at ``start``."""
        stop = self._take_free(start)
        if start < a.offset:
            self._add_free(start, a.offset)
        if a.end < stop:
            self._add_free(a.end, stop)
        self.allocs[a.offset], self._by_end[a.end] = a, a
        self.used += a.size

    def remove(self, a: SubAllocation) -> bool:
        """Give ``a``'s bytes back, merged with free neighbours; False if ``a`` is not here."""
        if self.allocs.get(a.offset) is not a:
            return False
        del self.allocs[a.offset], self._by_end[a.end]
        self.used -= a.size
        start, stop = a.offset, a.end
        if start in self._free_by_stop:
            start = self._free_by_stop[start]
            self._take_free(start)
        if stop in self._free:
            stop = self._take_free(stop)
        self._add_free(start, stop)
        return True


class _FirstFitBlock:
    """The scan this module used before: every allocation walks the allocations of the
    block in offset order (quadratic in their number). Kept for benchmarks and tests."""

    def __init__(self, owner: BlockAllocator, memory: DeviceMemory):
        self.owner, self.memory = owner, memory
        self.sorted: list[SubAllocation] = []
        self.allocs: dict[int, SubAllocation] = {}
        self.used = 0

    def gaps(self) -> list[tuple[int, int]]:
        out, cursor = [], 0
        for a in self.sorted:
            if a.offset > cursor:
                out.append((cursor, a.offset))
            cursor = a.end
        if cursor < self.memory.size:
            out.append((cursor, self.memory.size))
        return out

    def fit(self, size: int, alignment: int, linear: bool,
            granularity: int) -> tuple[int, int] | None:
        prev: SubAllocation | None = None
        for i in range(len(self.sorted) + 1):
            self.owner.visits += 1
            nxt = self.sorted[i] if i < len(self.sorted) else None
            start = prev.end if prev else 0
            stop = nxt.offset if nxt else self.memory.size
            o = _place(start, stop, size, alignment, linear, granularity, prev, nxt)
            if o is not None:
                return start, o
            prev = nxt
        return None

    def insert(self, a: SubAllocation, start: int) -> None:
        bisect.insort(self.sorted, a, key=lambda x: x.offset)
        self.allocs[a.offset] = a
        self.used += a.size

    def remove(self, a: SubAllocation) -> bool:
        if self.allocs.get(a.offset) is not a:
            return False
        del self.allocs[a.offset]
        self.sorted.remove(a)
        self.used -= a.size
        return True


class BlockAllocator:
    """Persistent resources (meshes, textures, history images) sub-allocated from large
    blocks, one list of blocks per memory type; a request larger than a block gets a block
    of its own. Every alignment the driver asks for and ``bufferImageGranularity`` are kept.

    ``strategy``: ``"good-fit"`` (binned free ranges, a bounded number of them looked at per
    allocation) or ``"first-fit"`` (the old scan over every allocation); ``visits`` counts
    the free ranges (good fit) or gaps (first fit) looked at, so tests can count work."""

    default_strategy = "good-fit"

    def __init__(self, device: VkDevice, *, block_size: int = 64 * MiB,
                 label: str = "blocks", strategy: str | None = None):
        strategy = strategy or self.default_strategy
        if strategy not in STRATEGIES:
            raise RfwError(f"unknown allocation strategy {strategy!r} "
                           f"(known: {', '.join(STRATEGIES)})", element=label)
        self.device, self.block_size, self.label = device, int(block_size), label
        self.strategy = strategy
        self._block_class = _Block if strategy == "good-fit" else _FirstFitBlock
        self.granularity = max(1, int(device.limits["bufferImageGranularity"]))
        self.blocks: dict[int, list[_Block | _FirstFitBlock]] = {}
        self.resources: dict[int, Image | Buffer] = {}  # id(sub-allocation) -> resource
        self.visits = 0
        self.made_blocks = 0
        device.register(self)

    def allocate(self, size: int, alignment: int, type_bits: int, *, linear: bool,
                 host_visible: bool = False, label: str = "") -> SubAllocation:
        required = [HOST_VISIBLE, HOST_COHERENT] if host_visible else []
        type_index = find_memory_type(self.device, type_bits, required,
                                      [] if host_visible else [DEVICE_LOCAL])
        size, alignment = int(size), max(1, int(alignment))
        blocks = self.blocks.setdefault(type_index, [])
        # good fit tries the newest block first: a scene fills one block after another
        for block in reversed(blocks) if self.strategy == "good-fit" else blocks:
            found = block.fit(size, alignment, linear, self.granularity)
            if found is not None:
                break
        else:
            block_bytes = max(self.block_size, align_up(size, self.granularity))
            mem = DeviceMemory(self.device, block_bytes, 1 << type_index,
                               host_visible=host_visible,
                               label=f"{self.label}:block{self.made_blocks}")
            self.made_blocks += 1
            block = self._block_class(self, mem)
            blocks.append(block)
            found = (0, 0)
        a = SubAllocation(block, found[1], size, linear, label)
        block.insert(a, found[0])
        return a

    def free(self, a: SubAllocation) -> None:
        block = a.block
        if not block.remove(a):
            return
        self.resources.pop(id(a), None)
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
        self.resources[id(a)] = res
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
        for res in list(self.resources.values()):
            res.destroy()
        self.resources.clear()
        for blocks in self.blocks.values():
            for b in blocks:
                b.memory.destroy()
        self.blocks.clear()
        self.device.unregister(self)
