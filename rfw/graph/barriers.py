"""Step 7 of ``compile``: the barriers between accesses, planned once for the executors."""

from __future__ import annotations

import bisect
from collections import defaultdict

from .plan import STATS, Barrier, Declared
from .resolve import Resolved
from .steps import whole
from .sync import State

# ---------------------------------------------------------------------------------------------
# step 7: barriers


def plan_barriers(declared: Declared, schedule: list[int], resolved: dict[str, Resolved],
                  placement: dict[str, tuple[int, int, int]], transient: set[str],
                  spans: dict[str, tuple[int, int]]) -> list[Barrier]:
    """For each pass and resource, the transition from the previous access to this one.

    Reads that find the resource already visible to their stages in the same layout need
    nothing. A transient's first access starts from UNDEFINED and waits for the resources
    whose memory it takes over; a persistent one starts from how the last frame left it.
    """
    STATS["plan_barriers"] += 1
    finals = _final_states(declared, schedule)
    aliases = alias_predecessors(placement, spans)
    track: dict[str, _Track] = {}
    barriers: list[Barrier] = []
    for i in schedule:
        p = declared.passes[i]
        for a in declared.accesses[p.name]:
            if a.state is None:
                continue
            t = track.get(a.resource)
            aliased: tuple[str, ...] = ()
            if t is None:
                t = track[a.resource] = _initial(a.resource, declared, finals, resolved,
                                                 transient, aliases)
                aliased = t.aliased
            src = t.visit(a.state)
            if src is not None:
                barriers.append(Barrier(p.name, a.resource, src, a.state, aliased))
    return barriers


def plan_step_barriers(declared: Declared, schedule: list[int]) -> list[Barrier]:
    """Barriers between the steps of a pass, per span of mips or bytes.

    A step's accesses are merged into its pass's, so the barrier before the pass makes all
    earlier work visible to every step: inside a pass a span starts with nothing to wait for
    and only the earlier steps' accesses are tracked, with the layout the plan gives the pass.
    """
    barriers: list[Barrier] = []
    for i in schedule:
        p = declared.passes[i]
        steps = declared.steps.get(p.name)
        if not steps:
            continue
        tracks: dict[str, _Spans] = {}
        for k, accesses in enumerate(steps):
            for sa in accesses:
                r = declared.resources[sa.resource]
                t = tracks.get(sa.resource)
                if t is None:
                    t = tracks[sa.resource] = _Spans(sa.state.layout, whole(r))
                for lo, hi, src in t.visit(sa.lo, sa.hi, sa.state):
                    barriers.append(Barrier(p.name, sa.resource, src, sa.state, step=k,
                                            **_part(r.kind, lo, hi, t.end)))
    return barriers


def _part(kind: str, lo: int, hi: int, end: int) -> dict[str, tuple[int, int]]:
    if lo == 0 and hi == end:
        return {}  # all of it
    return {"mips" if kind == "image" else "bytes": (lo, hi - lo)}


class _Spans:
    """The tracks of one resource's disjoint spans ``[lo, hi)`` inside one pass; a step's
    access splits them where it starts and ends."""

    def __init__(self, layout: str | None, end: int):
        self.end = end
        self.cuts = [0, end]  # span k is [cuts[k], cuts[k + 1])
        self.tracks = [_Track(layout)]

    def _cut(self, at: int) -> None:
        k = bisect.bisect_left(self.cuts, at)
        if k < len(self.cuts) and self.cuts[k] == at:
            return
        self.cuts.insert(k, at)
        self.tracks.insert(k - 1, self.tracks[k - 1].copy())

    def visit(self, lo: int, hi: int, s: State) -> list[tuple[int, int, State]]:
        """Record an access of ``[lo, hi)``; the barriers it needs, neighbouring spans with
        the same source merged into one."""
        self._cut(lo)
        self._cut(hi)
        out: list[tuple[int, int, State]] = []
        for k in range(self.cuts.index(lo), self.cuts.index(hi)):
            src = self.tracks[k].visit(s)
            if src is None:
                continue
            a, b = self.cuts[k], self.cuts[k + 1]
            if out and out[-1][1] == a and out[-1][2] == src:
                out[-1] = (out[-1][0], b, src)
            else:
                out.append((a, b, src))
        return out


def _write_access(s: State | None) -> frozenset[str]:
    return s.write_access if s else frozenset()


def _stages_of(s: State | None) -> frozenset[str]:
    return s.stages if s else frozenset()


class _Track:
    """Synchronization state of one resource while walking the schedule."""

    __slots__ = ("aliased", "layout", "reads", "visible", "write")

    def __init__(self, layout: str | None, write: State | None = None,
                 reads: State | None = None, visible: State | None = None,
                 aliased: tuple[str, ...] = ()):
        self.layout = layout
        self.write = write  # last write (its stages and write access)
        self.reads = reads  # union of reads since that write: a later write must wait for them
        self.visible = visible  # what the last write has been made visible to
        self.aliased = aliased

    def copy(self) -> _Track:
        return _Track(self.layout, self.write, self.reads, self.visible)

    def visit(self, s: State) -> State | None:
        """Record an access; return the barrier source it needs, or None."""
        same_layout = self.layout == s.layout
        if not s.writes and same_layout:
            if self.visible is not None and s.stages <= self.visible.stages \
                    and s.access <= self.visible.access:
                src = None  # read after read in the same layout
            else:  # read after write: make the write visible to these stages
                # the stages it was made visible to chain to these: a layout transition
                # made for earlier readers is ordered only before their stages
                src = _source(self.layout, self.write, self.visible)
            self.reads = s if self.reads is None else self.reads.merge(s)
            self.visible = s if self.visible is None else self.visible.merge(s)
            return None if src is None or not (src.stages or src.access) else src
        # a write or a layout change waits for the last write and every read since (WAR)
        src = _source(self.layout, self.write, self.reads)
        self.layout = s.layout
        if s.writes:
            # nothing has seen this write yet, not even reads in the writer's own stages
            self.write, self.reads, self.visible = s, None, None
        else:
            self.reads = s if self.reads is None else self.reads.merge(s)
            self.visible = s
        if same_layout and not src.stages:
            return None  # nothing earlier to wait for and no transition
        return src


def _source(layout: str | None, write: State | None, seen: State | None) -> State:
    """A barrier's source: ``write``'s stages and write access, and the stages of the
    accesses ``seen`` since; a schedule repeats a few of these, so each is made once."""
    key = (layout, write, seen)
    src = _SOURCES.get(key)
    if src is None:
        src = _SOURCES[key] = State(layout, _stages_of(write) | _stages_of(seen),
                                    _write_access(write))
    return src


_SOURCES: dict[tuple, State] = {}


def _final_states(declared: Declared, schedule: list[int]) -> dict[str, _Track]:
    """How each resource is left at the end of the frame (the next frame starts from it)."""
    tracks: dict[str, _Track] = {}
    for i in schedule:
        for a in declared.accesses[declared.passes[i].name]:
            if a.state is not None:
                t = tracks.get(a.resource)
                if t is None:
                    t = tracks[a.resource] = _Track(a.state.layout)
                t.visit(a.state)
    return tracks


def alias_predecessors(placement: dict[str, tuple[int, int, int]],
                       spans: dict[str, tuple[int, int]]) -> dict[str, tuple[str, ...]]:
    """For each transient, the resources that last used its bytes before it.

    A sweep in first-use order over a map of byte ranges to their latest occupant: older
    occupants are reached through the chain of barriers, so only the latest are listed.
    """
    by_heap: dict[int, list[str]] = defaultdict(list)
    for name, (heap, _, _) in placement.items():
        by_heap[heap].append(name)
    out: dict[str, tuple[str, ...]] = {}
    for names in by_heap.values():
        names.sort(key=lambda n: (spans[n][0], n))
        segments: list[tuple[int, int, str]] = []  # disjoint, sorted by start
        for name in names:
            _, start, end = placement[name]
            k = bisect.bisect_right(segments, (start, float("inf"), "")) - 1
            k = max(k, 0)
            before: set[str] = set()
            kept: list[tuple[int, int, str]] = []
            j = k
            while j < len(segments) and segments[j][0] < end:
                s, e, who = segments[j]
                if e > start:
                    before.add(who)
                    if s < start:
                        kept.append((s, start, who))
                    if e > end:
                        kept.append((end, e, who))
                else:
                    kept.append((s, e, who))
                j += 1
            segments[k:j] = sorted([*kept, (start, end, name)])
            out[name] = tuple(sorted(before))
    return out


def _initial(name: str, declared: Declared, finals: dict[str, _Track],
             resolved: dict[str, Resolved], transient: set[str],
             aliases: dict[str, tuple[str, ...]]) -> _Track:
    if name in transient:
        earlier = aliases.get(name, ())
        stages: frozenset[str] = frozenset()
        access: frozenset[str] = frozenset()
        for other in earlier:
            f = finals[other]
            stages |= _stages_of(f.write) | _stages_of(f.reads)
            access |= _write_access(f.write)
        image = resolved[name].kind == "image"
        write = State(None, stages, access) if earlier else None
        return _Track("UNDEFINED" if image else None, write, aliased=earlier)
    # persistent: ping-pong history pairs hand their final state to each other every frame
    twin = declared.history.get(name) or declared.history_of.get(name)
    prev = finals.get(twin or name)
    if prev is None:  # nothing this frame leaves it in a known state
        return _Track("UNDEFINED" if resolved[name].kind == "image" else None)
    return prev.copy()
