"""Async compute: which queue each pass runs on, the submissions, and the sync between them.

A compute pass goes to the ``compute`` queue when some raster pass can overlap it (no path
between them in the graph) and no pass it could overlap on the graphics queue touches a
resource it touches: then every pair of accesses of one resource on two queues is ordered by
a path, and a semaphore wait lies on that path. The serial order is split into submissions at
those waits and signals: a pass that needs work of the other queue starts a new submission
that waits for it, and a submission that other work waits for ends there. Each queue has a
timeline semaphore; submission ``k`` of a queue signals value ``base + k`` (``base`` grows by
the queue's submission count each frame); waits and signals cover ``ALL_COMMANDS``, so the
barriers the plan records on the waiting side chain to them. The last graphics submission
waits for the compute queue's last one (the frame ends on the graphics queue), and a compute
submission that needs nothing of this frame waits for the graphics queue's end of the last.

When the compute queue is in another queue family, resources stay exclusive to one family and
cross with ownership transfers (a release after the last access on one queue, an acquire in
place of the barrier before the next on the other; the plan's layouts on both halves);
concurrent sharing would need every image and buffer made for it, and costs compression on
some devices. There, a pass goes async only if it touches transient graph resources alone
(persistent ones would have to go home to the graphics family at every frame's end).

The device says what it has through capabilities: ``compute_queue`` (a second queue of the
graphics family) or ``compute_family`` (a queue of a compute-only family). The graph's
``async_compute`` switch is ``auto`` (on where the device has either), ``on`` (on: without a
second queue the submissions go to the one queue, with the same semaphores) or ``off``.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field
from typing import Any

from .plan import RASTER, Barrier, Declared
from .schedule import order
from .sync import NONE, State

GRAPHICS, COMPUTE = "graphics", "compute"
SWITCH = ("auto", "on", "off")
ALL = frozenset({"ALL_COMMANDS"})
PREVIOUS_FRAME = -1  # a wait for the other queue's end of the last frame


@dataclass(frozen=True)
class Wait:
    queue: str  # the queue signalling
    submission: int  # its submission index in the plan; PREVIOUS_FRAME: its last, a frame ago
    value: int  # the timeline value relative to the frame's base (0: the last frame's end)
    stages: frozenset[str] = ALL

    def to_json(self) -> dict[str, Any]:
        return {"queue": self.queue, "submission": self.submission, "value": self.value,
                "stages": "|".join(sorted(self.stages))}


@dataclass(frozen=True)
class Submission:
    index: int
    queue: str
    passes: tuple[str, ...]
    value: int  # the timeline value it signals, relative to its queue's frame base
    waits: tuple[Wait, ...] = ()
    signal_stages: frozenset[str] = ALL

    def to_json(self) -> dict[str, Any]:
        return {"index": self.index, "queue": self.queue, "passes": list(self.passes),
                "signal": {"queue": self.queue, "value": self.value,
                           "stages": "|".join(sorted(self.signal_stages))},
                "waits": [w.to_json() for w in self.waits]}


@dataclass(frozen=True)
class Transfer:
    """A queue-family ownership transfer: ``release`` recorded after pass ``after`` on queue
    ``src``, ``acquire`` before pass ``before`` on queue ``dst`` (replacing the plan's barrier
    there); both halves name the same layouts."""

    resource: str
    src: str
    dst: str
    after: str
    before: str
    release: Barrier
    acquire: Barrier

    def to_json(self) -> dict[str, Any]:
        return {"resource": self.resource, "from": self.src, "to": self.dst,
                "release_after": self.after, "acquire_before": self.before,
                "layout": [self.release.src.layout or "-", self.acquire.dst.layout or "-"]}


@dataclass(frozen=True)
class QueuePlan:
    """Where passes run and how the queues meet; one graphics submission when off."""

    mode: str  # "off" | "one queue" | "one family" | "two families"
    why: str
    queues: tuple[str, ...] = (GRAPHICS,)
    queue_of: dict[str, str] = field(default_factory=dict, compare=False)
    submissions: tuple[Submission, ...] = ()
    transfers: tuple[Transfer, ...] = ()

    @property
    def on(self) -> bool:
        return self.mode != "off"

    def async_passes(self) -> tuple[str, ...]:
        return tuple(p for s in self.submissions if s.queue == COMPUTE for p in s.passes)

    def count(self, queue: str) -> int:
        return sum(s.queue == queue for s in self.submissions)

    def to_json(self) -> dict[str, Any]:
        return {"mode": self.mode, "why": self.why, "queues": list(self.queues),
                "submissions": [s.to_json() for s in self.submissions],
                "transfers": [t.to_json() for t in self.transfers]}


# ---------------------------------------------------------------------------------------------
# the switch and the device


def choose(switch: str, caps: frozenset[str] | None) -> tuple[str, str]:
    """The queue mode for a switch value and a device's capabilities, and why."""
    caps = caps or frozenset()
    family = "compute_family" in caps
    second = family or "compute_queue" in caps
    if switch == "off":
        return "off", "async_compute = off"
    if switch == "auto" and not second:
        return "off", "async_compute = auto and the device has no second queue that runs compute"
    if family:
        return "two families", f"async_compute = {switch}; a compute-only queue family"
    if second:
        return "one family", f"async_compute = {switch}; a second queue of the graphics family"
    return "one queue", ("async_compute = on and the device has one queue: the submissions go "
                         "to it in order, with the same semaphores")


# ---------------------------------------------------------------------------------------------
# which passes go async


def _reach(n: int, edges: Any, keep: set[int]) -> list[set[int]]:
    succ: dict[int, list[int]] = defaultdict(list)
    for a, b in edges:
        if a in keep and b in keep:
            succ[a].append(b)
    below: list[set[int]] = [set() for _ in range(n)]
    done: dict[int, set[int]] = {}

    def down(i: int) -> set[int]:
        if i in done:
            return done[i]
        out: set[int] = set()
        stack = list(succ[i])
        while stack:
            j = stack.pop()
            if j not in out:
                out.add(j)
                stack.extend(succ[j])
        done[i] = out
        return out

    for i in keep:
        below[i] = down(i)
    return below


def async_candidates(declared: Declared, keep: list[int], mode: str) -> set[int]:
    """Compute passes that can overlap raster work and share no resource with any pass they
    could overlap (a fixpoint: a pass dropped from the set may disqualify another)."""
    if mode == "off":
        return set()
    passes, kept = declared.passes, set(keep)
    below = _reach(len(passes), declared.edges, kept)

    def apart(i: int, j: int) -> bool:
        return i != j and j not in below[i] and i not in below[j]

    touched = {i: {a.resource for a in declared.accesses[passes[i].name] if a.role != "order"}
               for i in kept}
    transient_only = mode == "two families"
    raster = [i for i in kept if passes[i].type in RASTER]
    cand = {i for i in kept if passes[i].type == "compute" and passes[i].backend in (None, "vk")
            and any(apart(i, r) for r in raster)
            and not (transient_only and not _transient_only(declared, touched[i]))}
    changed = True
    while changed:
        changed = False
        for i in sorted(cand):
            if any(apart(i, j) and touched[i] & touched[j] for j in kept - cand):
                cand.discard(i)
                changed = True
    return cand


def _transient_only(declared: Declared, names: set[str]) -> bool:
    # what compile will make transient: not external, no history pair, no accel structure
    history = {*declared.history, *declared.history.values()}
    return all(n in declared.resources and not declared.resources[n].external
               and n not in history and declared.resources[n].kind != "accel" for n in names)


def overlap_first(declared: Declared, keep: list[int], cand: set[int]) -> dict[int, int]:
    """Priorities for the order: async passes and what they need first, so that the graphics
    work they can overlap comes after them (lower runs earlier among ready passes)."""
    preds: dict[int, list[int]] = defaultdict(list)
    for a, b in declared.edges:
        preds[b].append(a)
    need: set[int] = set()
    stack = list(cand)
    while stack:
        i = stack.pop()
        if i not in need:
            need.add(i)
            stack.extend(preds[i])
    return {i: 0 if i in need else 1 for i in keep}


# ---------------------------------------------------------------------------------------------
# submissions


class _Split:
    def __init__(self) -> None:
        self.subs: list[dict[str, Any]] = []
        self.open: dict[str, int | None] = {GRAPHICS: None, COMPUTE: None}
        self.count: dict[str, int] = {GRAPHICS: 0, COMPUTE: 0}
        self.sub_of: dict[str, int] = {}

    def new(self, queue: str) -> int:
        self.count[queue] += 1
        self.subs.append({"queue": queue, "passes": [], "value": self.count[queue],
                          "waits": {}})
        self.open[queue] = len(self.subs) - 1
        return self.open[queue]

    def waited(self, sub: int, other: str) -> int:
        w = self.subs[sub]["waits"].get(other)
        return -1 if w is None else self.subs[w]["value"] if w >= 0 else 0


def split(order: list[str], queue_of: dict[str, str],
          preds: dict[str, set[str]]) -> list[Submission]:
    """Cut the serial order into submissions per queue with the waits between them."""
    s = _Split()
    for name in order:
        q = queue_of[name]
        other = COMPUTE if q == GRAPHICS else GRAPHICS
        deps = [s.sub_of[d] for d in preds[name] if d in s.sub_of and queue_of[d] != q]
        need = max(deps, key=lambda k: s.subs[k]["value"], default=None)
        cur = s.open[q]
        if cur is None or (need is not None and s.waited(cur, other) < s.subs[need]["value"]):
            cur = s.new(q)
            if need is not None:
                s.subs[cur]["waits"][other] = need
                if s.open[other] == need:
                    s.open[other] = None  # it signals now: later work goes to a new one
            elif q == COMPUTE:
                s.subs[cur]["waits"][GRAPHICS] = PREVIOUS_FRAME
        s.subs[cur]["passes"].append(name)
        s.sub_of[name] = cur
    _join(s)
    return [Submission(i, d["queue"], tuple(d["passes"]), d["value"],
                       tuple(Wait(q, k, s.subs[k]["value"] if k >= 0 else 0)
                             for q, k in sorted(d["waits"].items())))
            for i, d in enumerate(s.subs)]


def _join(s: _Split) -> None:
    """The frame ends on the graphics queue, after the compute queue's last submission."""
    last_c = max((i for i, d in enumerate(s.subs) if d["queue"] == COMPUTE), default=None)
    if last_c is None:
        return
    last_g = max((i for i, d in enumerate(s.subs) if d["queue"] == GRAPHICS), default=None)
    if last_g is None or last_g < last_c:
        last_g = s.new(GRAPHICS)  # an empty submission that only waits
    if s.waited(last_g, COMPUTE) < s.subs[last_c]["value"]:
        s.subs[last_g]["waits"][COMPUTE] = last_c


# ---------------------------------------------------------------------------------------------
# lifetimes: what may overlap shares no memory


def overlap_spans(spans: dict[str, tuple[int, int]], order: list[str],
                  subs: list[Submission], accesses: dict[str, tuple[Any, ...]]
                  ) -> dict[str, tuple[int, int]]:
    """Stretch the lifetime of each resource an async pass touches over the graphics passes
    that can run beside it, so that placement never aliases memory in use on both queues."""
    pos = {n: k for k, n in enumerate(order)}
    out = dict(spans)
    graphics = [sub for sub in subs if sub.queue == GRAPHICS]
    for sub in subs:
        if sub.queue != COMPUTE:
            continue
        fork = next((w.value for w in sub.waits if w.queue == GRAPHICS), 0)
        join = min((g.value for g in graphics
                    if any(w.queue == COMPUTE and w.value >= sub.value for w in g.waits)),
                   default=len(graphics) + 1)
        beside = [pos[p] for g in graphics if fork < g.value < join for p in g.passes]
        if not beside:
            continue
        lo, hi = min(beside), max(beside)
        for p in sub.passes:
            for a in accesses[p]:
                if a.role != "order" and a.resource in out:
                    first, last = out[a.resource]
                    out[a.resource] = (min(first, lo), max(last, hi))
    return out


# ---------------------------------------------------------------------------------------------
# ownership transfers between families


def plan_transfers(order: list[str], queue_of: dict[str, str],
                   accesses: dict[str, tuple[Any, ...]], barriers: list[Barrier]
                   ) -> list[Transfer]:
    """Release/acquire pairs where a resource's next access is on the other family and its
    contents matter (not the start of a transient's lifetime: that starts UNDEFINED)."""
    before = {(b.pass_name, b.resource): b for b in barriers}
    last: dict[str, tuple[str, State]] = {}
    out: list[Transfer] = []
    for name in order:
        for a in accesses[name]:
            if a.state is None:
                continue
            prev = last.get(a.resource)
            last[a.resource] = (name, a.state)
            if prev is None or queue_of[prev[0]] == queue_of[name]:
                continue
            b = before.get((name, a.resource))
            src = b.src if b is not None else State(prev[1].layout, prev[1].stages, NONE)
            if src.layout == "UNDEFINED":
                continue  # contents discarded: no transfer
            release = Barrier(prev[0], a.resource, src, State(a.state.layout, NONE, NONE))
            acquire = Barrier(name, a.resource, State(src.layout, NONE, NONE), a.state)
            out.append(Transfer(a.resource, queue_of[prev[0]], queue_of[name], prev[0], name,
                                release, acquire))
    return out


# ---------------------------------------------------------------------------------------------
# the compiler's step


def queue_mode(graph: Any, declared: Declared, caps: frozenset[str] | None) -> tuple[str, str]:
    """The mode for a graph on a device; a frame that mixes backends stays on one queue
    (its bridges copy through the host between submissions)."""
    if any(p.backend not in (None, "vk") or p.bridge is not None for p in declared.passes):
        return "off", "the frame mixes backends"
    return choose(getattr(graph, "async_compute", "auto"), caps)


def plan_order(declared: Declared, keep: list[int], mode: str, seed: int | None
               ) -> tuple[list[int], set[int]]:
    """The serial order (async work and what it needs first) and the async passes."""
    cand = async_candidates(declared, keep, mode)
    priority = overlap_first(declared, keep, cand) if cand else None
    return order(declared, keep, seed, priority), cand


def plan_submissions(declared: Declared, schedule: list[int], cand: set[int]
                     ) -> tuple[dict[str, str], list[Submission]]:
    names = [declared.passes[i].name for i in schedule]
    queue_of = {declared.passes[i].name: COMPUTE if i in cand else GRAPHICS for i in schedule}
    preds: dict[str, set[str]] = defaultdict(set)
    kept = set(schedule)
    for a, b in declared.edges:
        if a in kept and b in kept:
            preds[declared.passes[b].name].add(declared.passes[a].name)
    if not cand:
        return queue_of, [Submission(0, GRAPHICS, tuple(names), 1)]
    return queue_of, split(names, queue_of, preds)


def queue_plan(mode: str, why: str, queue_of: dict[str, str], subs: list[Submission],
               transfers: list[Transfer]) -> QueuePlan:
    if mode != "off" and not any(s.queue == COMPUTE for s in subs):
        why += "; no compute pass can overlap raster work without sharing a resource with it"
    queues = (GRAPHICS, COMPUTE) if any(s.queue == COMPUTE for s in subs) else (GRAPHICS,)
    return QueuePlan(mode, why, queues, queue_of, tuple(subs), tuple(transfers))


def names_of(declared: Declared, schedule: list[int]) -> list[str]:
    return [declared.passes[i].name for i in schedule]


def check_sync(plan: QueuePlan, edges: tuple[tuple[str, str, str], ...]) -> None:
    """Raise AssertionError unless every dependency between passes on two queues is covered
    by semaphore waits (directly or through a chain of them), and every wait names an
    earlier submission (batches go out in plan order: on one queue a later one would never
    signal). A check of the compiler's output, for tests."""
    subs = plan.submissions
    where = {p: s for s in subs for p in s.passes}
    known: list[dict[str, int]] = []
    last: dict[str, dict[str, int]] = {}
    for s in subs:
        seen = dict(last.get(s.queue, {}))  # what earlier batches on the queue waited for
        for w in s.waits:
            if w.submission != PREVIOUS_FRAME:
                assert w.submission < s.index, f"batch {s.index} waits for a later one"
                for q, v in known[w.submission].items():
                    seen[q] = max(seen.get(q, 0), v)
                seen[w.queue] = max(seen.get(w.queue, 0), w.value)
        known.append(seen)
        last[s.queue] = seen
    for a, b, _ in edges:
        sa, sb = where[a], where[b]
        if sa.queue != sb.queue:
            assert known[sb.index].get(sa.queue, 0) >= sa.value, \
                f"'{b}' on {sb.queue} does not wait for '{a}' on {sa.queue}"
    ends = [s for s in subs if s.queue == GRAPHICS]
    for s in subs:
        if s.queue == COMPUTE:
            assert known[ends[-1].index].get(COMPUTE, 0) >= s.value, \
                "the frame ends before its compute work"
