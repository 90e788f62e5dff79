"""``compile(graph, size, caps)``: pure, deterministic, GPU-free.

validate -> cull -> order -> resolve -> lifetimes -> assign memory -> plan barriers ->
parallel levels. Each step is a short function; executors make no decision made here.
``place(plan, memory)`` runs the steps from memory on again with other placement rules (a
device's exact sizes), from what compiling found up to lifetimes (``plan.front``).
The steps live beside this driver: validate.py (1: accesses.py and steps.py derive what the
slots and the steps inside passes touch), schedule.py (2, 3, 5, 8), resolve.py (4),
placement.py (6), barriers.py (7); plan.py holds what they pass along and return.
"""

from __future__ import annotations

from collections import OrderedDict, defaultdict
from collections.abc import Iterable
from dataclasses import dataclass, replace
from typing import Any

from .barriers import plan_barriers, plan_step_barriers
from .bridges import insert_bridges
from .errors import GraphError
from .graph import Graph, gc_paused
from .placement import _memory_items, _raptor_reuse_bytes, assign_memory, lower_bound
from .plan import (  # the result types are imported from here too
    IMPLIED_CAPS,
    STATS,
    Access,
    Barrier,
    CompiledGraph,
    Declared,
    Diagnostic,
    MemoryOptions,
    ResourcePlan,
    _Problems,
)
from .queues import (
    names_of,
    overlap_spans,
    plan_order,
    plan_submissions,
    plan_transfers,
    queue_mode,
    queue_plan,
)
from .resolve import Resolved, check_attachment_sizes, resolve
from .resources import ResourceDecl
from .schedule import cull, lifetimes, parallel_levels, unproduced_after_cull
from .validate import validate

__all__ = ["IMPLIED_CAPS", "STATS", "Access", "Barrier", "CompiledGraph", "Diagnostic",
           "MemoryOptions", "ResourcePlan", "compile", "place"]

# ---------------------------------------------------------------------------------------------
# the driver


_CACHE: OrderedDict[tuple, CompiledGraph] = OrderedDict()
_MEMORY_CACHE: OrderedDict[tuple, tuple[tuple[int, ...], dict[str, int]]] = OrderedDict()
_CACHE_SIZE = 64


def _remember(cache: OrderedDict, key: tuple, value: Any) -> Any:
    cache[key] = value
    if len(cache) > _CACHE_SIZE:
        cache.popitem(last=False)
    return value


# hashing a new graph for the cache makes many tuples too
@gc_paused
def compile(graph: Graph, size: tuple[int, int] | None = None,
            caps: Iterable[str] | None = None, *, strict: bool | None = None,
            cull_passes: bool = True, memory: MemoryOptions = MemoryOptions(),  # noqa: B008 (frozen)
            backend: str | None = None, order_seed: int | None = None) -> CompiledGraph:
    """Compile a declared graph for an output size and a device's capabilities.

    Pure and deterministic. Results are memoised: compiling an unchanged graph again is a
    dictionary lookup, and a changed graph reuses the memory plan when lifetimes are equal.
    ``order_seed`` breaks ties in the pass order at random (seeded): another valid order,
    with the lifetimes, aliasing and barriers that follow from it (schedule fuzzing).
    Other placement rules for the same plan (a device's sizes and alignments) are
    :func:`place`'s: it does not compile the graph again.
    """
    size_from = "graph" if size is None else "given"
    size = size or graph.size
    if size is None:
        raise GraphError("no output size given (pass size=(w, h) or declare one in the graph)",
                         file=graph.source)
    if size[0] < 1 or size[1] < 1:
        raise GraphError(f"output size {size[0]}x{size[1]} is not positive", file=graph.source)
    caps = None if caps is None else frozenset(caps)
    strict = graph.strict if strict is None else strict
    front_key = (graph, tuple(size), size_from, caps, strict, cull_passes, backend, order_seed)
    key = (*front_key, memory)
    if key in _CACHE:
        _CACHE.move_to_end(key)
        return _CACHE[key]
    STATS["compile"] += 1
    try:
        graph = insert_bridges(graph, backend)
        front = _front(graph, (int(size[0]), int(size[1])), caps, strict, cull_passes,
                       order_seed, front_key)
        result = replace(_place(front, memory), size_from=size_from)
    except GraphError as e:
        raise e.in_file(graph.source) from None
    return _remember(_CACHE, key, result)


def place(plan: CompiledGraph, memory: MemoryOptions) -> CompiledGraph:
    """``plan`` with its transients placed by other rules (``memory``: e.g. a device's exact
    sizes and alignments): the memory, barrier and queue-transfer steps again, from what
    :func:`compile` found before it placed memory; the graph is not compiled again. The
    same plan ``compile`` gives with ``memory``, and memoised with it."""
    front = plan.front
    key = (*front.key, memory)
    if key in _CACHE:
        _CACHE.move_to_end(key)
        return _CACHE[key]
    STATS["place"] += 1
    try:
        result = replace(_place(front, memory), size_from=plan.size_from)
    except GraphError as e:
        raise e.in_file(front.graph.source) from None
    return _remember(_CACHE, key, result)


@dataclass(frozen=True)
class _Front:
    """What compiling found before memory is placed: every step up to lifetimes."""

    key: tuple  # compile's memo key, without the memory options
    graph: Graph  # with its bridges
    size: tuple[int, int]
    declared: Declared
    diagnostics: tuple[Diagnostic, ...]
    culled: list[str]
    mode: str
    why: str
    schedule: list[int]
    on_compute: set[int]
    queue_of: Any
    submissions: Any
    used: list[str]
    resolved: dict[str, Resolved]
    spans: dict[str, tuple[int, int]]
    transient: set[str]
    unproduced: list[tuple[Any, str, str, str]]


def _front(graph: Graph, size: tuple[int, int], caps: frozenset[str] | None, strict: bool,
           cull_passes: bool, order_seed: int | None, key: tuple) -> _Front:
    declared = validate(graph, caps, strict)
    problems = _Problems(graph, strict)
    problems.diagnostics = list(declared.diagnostics)
    if cull_passes:
        keep, culled = cull(declared)
    else:
        keep, culled = list(range(len(declared.passes))), []
    # ordering-only inputs may lose their producer to the cull (data reads keep theirs); the
    # pass may depend on what it did, so say so, but as a warning even when strict: the
    # pass reads nothing through the input (an unproduced read is an error when strict)
    unproduced = unproduced_after_cull(declared, keep)
    for p, slot, resource, producer in unproduced:
        problems.diagnostics.append(Diagnostic(
            "warning", f"{p.where()}, slot '{slot}': no kept pass produces '{resource}' (its "
                       f"producer '{producer}' is culled: no graph output needs it)"))
    mode, why = queue_mode(graph, declared, caps)
    schedule, on_compute = plan_order(declared, keep, mode, order_seed)
    queue_of, submissions = plan_submissions(declared, schedule, on_compute)
    used = _used_resources(declared, schedule)
    declared = _kept_history(declared, set(used))
    resolved = resolve(declared, used, size, problems)
    problems.raise_if_any()
    check_attachment_sizes(declared, schedule, resolved, problems)
    problems.raise_if_any()
    spans = lifetimes(declared, schedule)
    if on_compute:  # memory in use on both queues at once is never shared
        spans = overlap_spans(spans, names_of(declared, schedule), submissions,
                              declared.accesses)
    transient = {n for n in used if n in spans and _is_transient(n, declared, resolved)}
    return _Front(key, graph, size, declared, tuple(problems.diagnostics), culled, mode, why,
                  schedule, on_compute, queue_of, submissions, used, resolved, spans,
                  transient, unproduced)


def _place(f: _Front, memory: MemoryOptions) -> CompiledGraph:
    declared, schedule, resolved, spans, transient = (f.declared, f.schedule, f.resolved,
                                                      f.spans, f.transient)
    items, heap_of, align = _memory_items(declared, resolved, spans, transient, memory)
    mem_key = (items, memory.alias)
    if mem_key in _MEMORY_CACHE:
        heaps, offsets = _MEMORY_CACHE[mem_key]
    else:
        heaps, offsets = _remember(_MEMORY_CACHE, mem_key, assign_memory(items, memory.alias))
    placement = {n: (heap_of[n], offsets[n], offsets[n] + align[n]) for n in transient}
    barriers = plan_barriers(declared, schedule, resolved, placement, transient, spans)
    transfers = plan_transfers(names_of(declared, schedule), f.queue_of, declared.accesses,
                               barriers) if f.mode == "two families" and f.on_compute else []
    flat = [it for heap in items for it in heap]
    names = [declared.passes[i].name for i in schedule]
    kept = set(schedule)
    plans = _resource_plans(declared, f.used, resolved, spans, transient, placement, align,
                            names)
    return CompiledGraph(
        name=f.graph.name, size=f.size, order=tuple(names), culled=tuple(f.culled),
        disabled=tuple(declared.disabled), resources=tuple(plans), heaps=heaps,
        transient_bytes=sum(heaps), unaliased_bytes=sum(it.size for it in flat),
        lower_bound_bytes=lower_bound(flat, len(schedule)),
        raptor_reuse_bytes=_raptor_reuse_bytes(declared, flat, resolved, spans, schedule),
        barriers=tuple(barriers),
        parallel_levels=tuple(tuple(level) for level in parallel_levels(declared, schedule)),
        diagnostics=f.diagnostics,
        accesses={n: declared.accesses[n] for n in names},
        edges=tuple((declared.passes[a].name, declared.passes[b].name, kind)
                    for (a, b), kind in sorted(declared.edges.items())
                    if a in kept and b in kept),
        outputs=declared.outputs,
        step_barriers=tuple(plan_step_barriers(declared, schedule)),
        steps={n: tuple(s.name for s in declared.passes[i].steps)
               for n, i in zip(names, schedule, strict=True) if declared.passes[i].steps},
        queues=queue_plan(f.mode, f.why, f.queue_of, f.submissions, transfers),
        unproduced=tuple((p.name, slot, resource, producer)
                         for p, slot, resource, producer in f.unproduced),
        follow_output=sum(_follows_output(n, declared.resources) for n, r in resolved.items()
                          if r.kind == "image" and r.format),
        bridges=tuple(declared.passes[i].name for i in schedule
                      if declared.passes[i].bridge is not None),
        front=f,
    )


def _follows_output(name: str, resources: dict[str, ResourceDecl]) -> bool:
    seen: set[str] = set()
    while name in resources and name not in seen:
        seen.add(name)
        rule = resources[name].size
        if rule is None or rule.mode == "output":
            return True
        if rule.mode == "fixed" or rule.of is None:
            return False
        name = rule.of
    return False


def _kept_history(declared: Declared, used: set[str]) -> Declared:
    """History pairs that scheduled passes read; a culled reader makes no pair."""
    history = {c: r for c, r in declared.history.items() if c in used}
    if history == declared.history:
        return declared
    return replace(declared, history=history, history_of={r: c for c, r in history.items()})


def _used_resources(declared: Declared, schedule: list[int]) -> list[str]:
    seen: dict[str, None] = {}
    for i in schedule:
        for a in declared.accesses[declared.passes[i].name]:
            if a.role != "order" or a.resource in declared.resources:
                seen.setdefault(a.resource)
    return list(seen)


def _is_transient(name: str, declared: Declared, resolved: dict[str, Resolved]) -> bool:
    r = declared.resources[name]
    followed_by_history = name in declared.history.values()
    return not (r.external or name in declared.history or followed_by_history) \
        and resolved[name].raw_bytes > 0


def _resource_plans(declared: Declared, used: list[str], resolved: dict[str, Resolved],
                    spans: dict[str, tuple[int, int]], transient: set[str],
                    placement: dict[str, tuple[int, int, int]], align: dict[str, int],
                    names: list[str]) -> list[ResourcePlan]:
    usages: dict[str, set[str]] = defaultdict(set)
    for n in names:
        for a in declared.accesses[n]:
            usages[a.resource] |= a.usages
    for copy, name in declared.history.items():  # ping-pong pairs swap roles each frame
        usages[copy] |= usages[name]
        usages[name] |= usages[copy]
    paired = {*declared.history, *declared.history.values()}
    plans = []
    for name in used:
        r, d = resolved.get(name), declared.resources[name]
        if r is None:
            continue
        first, last = spans.get(name, (None, None))
        heap, offset, _ = placement.get(name, (None, None, None))
        plans.append(ResourcePlan(
            name=name, kind=r.kind, format=r.format, width=r.width, height=r.height,
            mips=r.mips, layers=r.layers, samples=r.samples, raw_bytes=r.raw_bytes,
            bytes=align.get(name, r.raw_bytes), usages=frozenset(usages[name]),
            producer=d.producer, first=None if first is None else names[first],
            last=None if last is None else names[last], transient=name in transient,
            external=d.external, history=name in paired, heap=heap, offset=offset))
    return plans
