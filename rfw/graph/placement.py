"""Step 6 of ``compile``: where transient resources live in memory (aliasing), its lower
bound, and what Raptor's allocator would need for comparison."""

from __future__ import annotations

import bisect
import heapq
import itertools
from bisect import bisect_left, bisect_right
from collections import defaultdict
from collections.abc import Iterable
from dataclasses import dataclass

from ..units import align_up
from .plan import STATS, Declared, MemoryOptions
from .resolve import Resolved

# ---------------------------------------------------------------------------------------------
# step 6: memory


@dataclass(frozen=True)
class Item:
    name: str
    size: int
    first: int
    last: int


def assign_memory(items_by_heap: tuple[tuple[Item, ...], ...],
                  alias: bool) -> tuple[tuple[int, ...], dict[str, int]]:
    """Offsets per heap so that resources alive at the same time never share bytes."""
    STATS["assign_memory"] += 1
    heaps: list[int] = []
    offsets: dict[str, int] = {}
    for items in items_by_heap:
        if not alias:
            top = 0
            for it in items:
                offsets[it.name] = top
                top += it.size
            heaps.append(top)
            continue
        best: tuple[int, dict[str, int]] | None = None
        floor = lower_bound(items, max(it.last for it in items) + 1)
        for key in _PLACEMENT_ORDERS:
            top, placed = _place(sorted(items, key=key))
            if best is None or top < best[0]:
                best = (top, placed)
            if best[0] == floor:
                break  # optimal: no other order can do better
        assert best is not None
        heaps.append(best[0])
        offsets.update(best[1])
    return tuple(heaps), offsets


_PLACEMENT_ORDERS = (
    lambda it: (-it.size, it.first, it.name),  # greedy by size
    lambda it: (it.first, -it.size, it.name),  # linear scan
    lambda it: (it.first - it.last, -it.size, it.name),  # longest-lived first
)


def _place(items: list[Item]) -> tuple[int, dict[str, int]]:
    """Best fit: each item takes the smallest gap among live neighbours that holds it.

    The gaps depend only on the union of the byte ranges of the placed items whose
    lifetimes overlap the item's, so a segment tree over schedule positions keeps such
    unions: scanning every overlapping item made graphs with many long-lived resources
    quadratic.
    """
    if any(it.size <= 0 for it in items):
        return _place_buckets(items)  # empty items can sit in zero-byte gaps
    if all(a.first <= b.first for a, b in itertools.pairwise(items)):
        return _place_sweep(items)
    if _scan_is_cheaper(items):
        return _place_buckets(items)
    return _place_tree(items)


def _place_sweep(items: list[Item]) -> tuple[int, dict[str, int]]:
    """Best fit for items in order of first use: the placed items an item overlaps are
    exactly those still alive, which share no bytes, so their gaps are kept sorted by
    (length, offset) and the best one is a bisection away."""
    starts: list[int] = []  # live ranges, by offset
    end_at: dict[int, int] = {}
    gaps: list[tuple[int, int]] = []  # (length, offset) of the holes below and between them
    expiry: list[tuple[int, int]] = []  # (last position, offset)
    offsets: dict[str, int] = {}
    top = 0
    for it in items:
        while expiry and expiry[0][0] < it.first:
            _sweep_remove(heapq.heappop(expiry)[1], starts, end_at, gaps)
        k = bisect.bisect_left(gaps, (it.size, -1))
        if k < len(gaps):
            length, offset = gaps.pop(k)
            if length > it.size:
                bisect.insort(gaps, (length - it.size, offset + it.size))
        else:
            offset = end_at[starts[-1]] if starts else 0
        bisect.insort(starts, offset)
        end_at[offset] = offset + it.size
        heapq.heappush(expiry, (it.last, offset))
        offsets[it.name] = offset
        top = max(top, offset + it.size)
    return top, offsets


def _sweep_remove(start: int, starts: list[int], end_at: dict[int, int],
                  gaps: list[tuple[int, int]]) -> None:
    i = bisect.bisect_left(starts, start)
    end = end_at.pop(start)
    below = end_at[starts[i - 1]] if i > 0 else 0
    if start > below:
        gaps.pop(bisect.bisect_left(gaps, (start - below, below)))
    if i + 1 < len(starts):
        after = starts[i + 1]
        if after > end:
            gaps.pop(bisect.bisect_left(gaps, (after - end, end)))
        bisect.insort(gaps, (after - below, below))
    del starts[i]


def _place_tree(items: list[Item]) -> tuple[int, dict[str, int]]:
    end = max((it.last for it in items), default=0)
    tree = _SpanTree(end + 1)
    # items alive to the end overlap the same items if they reach the tree's last leaf
    # instead, and such a span splits into fewer nodes
    right = tree.leaves - 1
    offsets: dict[str, int] = {}
    top = 0
    for it in items:
        nodes = tree.nodes(it.first, right if it.last == end else it.last)
        offset = _best_gap(tree.busy(nodes), it.size)
        tree.add(nodes, offset, offset + it.size)
        offsets[it.name] = offset
        top = max(top, offset + it.size)
    return top, offsets


def _best_gap(busy: list[tuple[int, int]], size: int) -> int:
    """The start of the smallest free gap (lowest first on ties) that holds ``size`` bytes
    below or between ``busy`` ranges (sorted by start); else the top of them."""
    offset, gap_best, cursor = None, None, 0
    for start, end in busy:
        gap = start - cursor
        if gap >= size and (gap_best is None or gap < gap_best):
            offset, gap_best = cursor, gap
        if end > cursor:
            cursor = end
    return cursor if offset is None else offset


class _SpanTree:
    """Byte ranges of items keyed by their schedule span [first, last].

    Node ``n`` covers a range of positions; ``here[n]`` unites the items stored at ``n``
    (their span covers n's range: its canonical pieces) and ``below[n]`` those stored at n or
    under it. The items overlapping a span are exactly those stored under its canonical
    nodes or at one of their ancestors. Nodes index flat lists (None: nothing stored).
    """

    def __init__(self, positions: int):
        self.leaves = 1 << max(positions - 1, 0).bit_length()
        self.here: list[_Union | None] = [None] * (2 * self.leaves)
        self.below: list[_Union | None] = [None] * (2 * self.leaves)

    def nodes(self, first: int, last: int) -> tuple[list[int], set[int]]:
        """The canonical nodes of [first, last] and their ancestors."""
        canonical: list[int] = []
        lo, hi = first + self.leaves, last + self.leaves + 1
        while lo < hi:
            if lo & 1:
                canonical.append(lo)
                lo += 1
            if hi & 1:
                hi -= 1
                canonical.append(hi)
            lo >>= 1
            hi >>= 1
        above: set[int] = set()
        for n in canonical:
            n >>= 1
            while n and n not in above:
                above.add(n)
                n >>= 1
        return canonical, above

    def add(self, nodes: tuple[list[int], set[int]], start: int, end: int) -> None:
        here, below, leaves = self.here, self.below, self.leaves
        for n in nodes[0]:
            if n < leaves:  # a leaf is nobody's ancestor: its own items are read as below
                u = here[n]
                if u is None:
                    u = here[n] = _Union()
                u.add(start, end)
            # an ancestor's union holds its children's: once a node already covers the
            # range, every node above it does too
            while n:
                u = below[n]
                if u is None:
                    u = below[n] = _Union()
                if not u.add(start, end):
                    break
                n >>= 1

    def busy(self, nodes: tuple[list[int], set[int]]) -> list[tuple[int, int]]:
        canonical, above = nodes
        below, here = self.below, self.here
        parts = []
        for n in canonical:
            if below[n] is not None:
                parts.append(below[n])
        for n in above:
            if here[n] is not None:
                parts.append(here[n])
        if not parts:
            return []
        if len(parts) == 1:
            return list(zip(parts[0].starts, parts[0].ends, strict=True))
        busy: list[tuple[int, int]] = []
        for u in parts:
            busy += zip(u.starts, u.ends, strict=True)
        busy.sort()
        return busy


class _Union:
    """Disjoint byte ranges, sorted; touching or overlapping ranges are merged."""

    __slots__ = ("ends", "starts")

    def __init__(self) -> None:
        self.starts: list[int] = []
        self.ends: list[int] = []

    def add(self, start: int, end: int) -> bool:
        """Unite [start, end) in; False if it was covered already."""
        starts, ends = self.starts, self.ends
        if not ends or start > ends[-1]:  # on top of everything: the common case
            starts.append(start)
            ends.append(end)
            return True
        i = bisect_left(ends, start)  # first range ending at or after start
        first = starts[i]
        if first <= start and end <= ends[i]:
            return False
        j = bisect_right(starts, end, i)  # past the last range starting at or before end
        if i < j:  # it touches ranges i..j-1: one range replaces them
            if first < start:
                start = first
            if ends[j - 1] > end:
                end = ends[j - 1]
        starts[i:j] = [start]
        ends[i:j] = [end]
        return True


_BUCKET = 64  # schedule positions per bucket of the scanning placement


def _place_buckets(items: list[Item]) -> tuple[int, dict[str, int]]:
    """Best fit by scanning the overlapping items themselves, found through buckets of
    positions: fast when few items overlap, and exact for empty items too."""
    index: dict[int, list[tuple[int, int, int, int]]] = defaultdict(list)
    offsets: dict[str, int] = {}
    top = 0
    for it in items:
        seen: set[tuple[int, int, int, int]] = set()
        for b in range(it.first // _BUCKET, it.last // _BUCKET + 1):
            for entry in index[b]:
                if entry[2] <= it.last and it.first <= entry[3]:
                    seen.add(entry)
        offset = _best_gap([(s, e) for s, e, _, _ in sorted(seen)], it.size)
        entry = (offset, offset + it.size, it.first, it.last)
        for b in range(it.first // _BUCKET, it.last // _BUCKET + 1):
            index[b].append(entry)
        offsets[it.name] = offset
        top = max(top, offset + it.size)
    return top, offsets


def _scan_is_cheaper(items: list[Item]) -> bool:
    """Whether scanning overlapping items beats the span tree: the scan costs about the
    squared bucket occupancy (long-lived items crowd every bucket), the tree a few dozen
    range updates per item."""
    last = max((it.last for it in items), default=0) // _BUCKET + 2
    delta = [0] * last
    for it in items:
        delta[it.first // _BUCKET] += 1
        delta[it.last // _BUCKET + 1] -= 1
    crowd = live = 0
    for d in delta:
        live += d
        crowd += live * live
    return crowd // 2 <= 40 * len(items) * max(last.bit_length(), 1)


def lower_bound(items: Iterable[Item], positions: int) -> int:
    """The largest total of resources alive at one schedule position: no plan does better."""
    delta = [0] * (positions + 1)
    for it in items:
        delta[it.first] += it.size
        delta[it.last + 1] -= it.size
    best = live = 0
    for d in delta:
        live += d
        best = max(best, live)
    return best


def raptor_reuse(items: list[Item], keys: dict[str, tuple], freed: set[str],
                 positions: int) -> int:
    """What Raptor's allocator needs: a released texture is reused only by one of identical
    width, height and format; released means its last input was consumed."""
    start: dict[int, list[Item]] = defaultdict(list)
    end: dict[int, list[Item]] = defaultdict(list)
    for it in items:
        start[it.first].append(it)
        if it.name in freed:
            end[it.last].append(it)
    free: list[tuple[tuple, int]] = []
    total = 0
    for pos in range(positions):
        for it in start[pos]:
            match = next((k for k, (key, size) in enumerate(free)
                          if key == keys[it.name] and size >= it.size), None)
            if match is None:
                total += it.size
            else:
                free.pop(match)
        free.extend((keys[it.name], it.size) for it in end[pos])
    return total


def _memory_items(declared: Declared, resolved: dict[str, Resolved],
                  spans: dict[str, tuple[int, int]], transient: set[str],
                  memory: MemoryOptions):
    """Aligned sizes grouped by heap: images and buffers live in separate heaps."""
    groups: dict[str, list[Item]] = {"image": [], "buffer": []}
    align: dict[str, int] = {}
    device_sizes = dict(memory.sizes)
    for name in resolved:
        if name not in transient:
            continue
        r = resolved[name]
        a = memory.image_alignment if r.kind == "image" else memory.buffer_alignment
        align[name] = align_up(max(r.raw_bytes, device_sizes.get(name, 0)), a)
        groups[r.kind].append(Item(name, align[name], *spans[name]))
    kinds = [k for k in ("image", "buffer") if groups[k]]
    heap_of = {it.name: h for h, k in enumerate(kinds) for it in groups[k]}
    return tuple(tuple(groups[k]) for k in kinds), heap_of, align


def _raptor_reuse_bytes(declared: Declared, items: list[Item], resolved: dict[str, Resolved],
                        spans: dict[str, tuple[int, int]], schedule: list[int]) -> int:
    readers: set[str] = set()
    for i in schedule:
        for a in declared.accesses[declared.passes[i].name]:
            if a.role in ("read", "modify", "order"):
                readers.add(a.resource)
    keys = {it.name: _reuse_key(resolved[it.name]) for it in items}
    # Raptor only recycles textures; every buffer is its own allocation
    freed = {it.name for it in items if it.name in readers and resolved[it.name].kind == "image"}
    return raptor_reuse(items, keys, freed, len(schedule))


def _reuse_key(r: Resolved) -> tuple:
    return (r.kind, r.format, r.width, r.height, r.mips, r.layers, r.samples,
            r.raw_bytes if r.kind == "buffer" else 0)
