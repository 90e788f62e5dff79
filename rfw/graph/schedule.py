"""Where passes go: dependency edges, cull, order, lifetimes and parallel levels."""

from __future__ import annotations

import heapq
import random
from collections import defaultdict
from collections.abc import Iterable

from .errors import GraphError
from .graph import PassDecl
from .plan import Access, Declared
from .resources import ResourceDecl


def _producer_edges(passes: list[PassDecl], accesses: dict[str, tuple[Access, ...]],
                    resources: dict[str, ResourceDecl]) -> dict[tuple[int, int], str]:
    """Hard edges: whoever touches a resource runs after the pass that creates it."""
    index = {p.name: i for i, p in enumerate(passes)}
    edges: dict[tuple[int, int], str] = {}
    for p in passes:
        for a in accesses[p.name]:
            producer = resources[a.resource].producer
            if a.role in ("produce", "history") or producer is None or producer not in index:
                continue
            edges[(index[producer], index[p.name])] = "order" if a.role == "order" else "data"
    return edges


def _stable_toposort(n: int, edges: Iterable[tuple[int, int]], passes: list[PassDecl],
                     keep: Iterable[int] | None = None, seed: int | None = None,
                     priority: dict[int, int] | None = None) -> list[int]:
    """Kahn's algorithm, smallest declaration index first; a cycle raises with its path.

    With a ``seed``, each step takes a ready pass at random instead: every valid order can
    come out (schedule fuzzing, ``vkext.poison``), and the same seed gives the same order.
    A ``priority`` (lower first, then declaration index) puts async compute and what it needs
    early, so the graphics work it can overlap comes after it (``rfw.graph.queues``).
    """
    nodes = set(range(n) if keep is None else keep)
    succ: dict[int, list[int]] = defaultdict(list)
    indeg = dict.fromkeys(nodes, 0)
    for a, b in edges:
        if a in nodes and b in nodes:
            succ[a].append(b)
            indeg[b] += 1
    rank = (lambda i: i) if priority is None or seed is not None else \
        (lambda i: priority.get(i, 0) * n + i)
    ready = [rank(i) for i in nodes if indeg[i] == 0]
    heapq.heapify(ready)
    rng = None if seed is None else random.Random(seed)
    push = heapq.heappush if rng is None else list.append
    order: list[int] = []
    while ready:
        i = (heapq.heappop(ready) if rng is None else _pop_random(ready, rng)) % max(n, 1)
        order.append(i)
        for j in succ[i]:
            indeg[j] -= 1
            if indeg[j] == 0:
                push(ready, rank(j))
    if len(order) != len(nodes):
        raise GraphError(_cycle_message(nodes - set(order), succ, passes))
    return order


def _pop_random(ready: list[int], rng: random.Random) -> int:
    # any ready pass may go next: swap a random one to the end and take it
    k = rng.randrange(len(ready))
    ready[k], ready[-1] = ready[-1], ready[k]
    return ready.pop()


def _cycle_message(stuck: set[int], succ: dict[int, list[int]], passes: list[PassDecl]) -> str:
    # walk inside the unsorted remainder until a node repeats: that loop is a cycle
    start = min(stuck)
    path, seen = [start], {start: 0}
    while True:
        nxt = min(j for j in succ[path[-1]] if j in stuck)
        if nxt in seen:
            loop = [*path[seen[nxt]:], nxt]
            break
        seen[nxt] = len(path)
        path.append(nxt)
    names = " -> ".join(passes[i].name for i in loop)
    return f"cycle between passes: {names}"


def _hazard_edges(passes: list[PassDecl], accesses: dict[str, tuple[Access, ...]],
                  natural: list[int], hard: dict[tuple[int, int], str]
                  ) -> dict[tuple[int, int], str]:
    """Order every write against the other accesses of its resource.

    Where producer edges leave two accesses unordered, the natural order (producer edges,
    then declaration order) decides which version a reader sees; these edges freeze that.
    """
    position = {i: k for k, i in enumerate(natural)}
    index = {p.name: i for i, p in enumerate(passes)}
    per_resource: dict[str, list[tuple[int, Access]]] = defaultdict(list)
    for p in passes:
        for a in accesses[p.name]:
            per_resource[a.resource].append((index[p.name], a))
    edges = dict(hard)

    def add(a: int, b: int, kind: str) -> None:
        if edges.get((a, b)) != "data":
            edges[(a, b)] = kind

    for items in per_resource.values():
        items.sort(key=lambda item: position[item[0]])
        writer: int | None = None
        writers: list[int] = []
        readers: list[int] = []
        for i, a in items:
            if a.role == "history":
                continue
            if a.writes:
                if writer is not None:
                    add(writer, i, "data")  # in-place writes build on the previous value
                for r in readers:
                    add(r, i, "order")  # write after read
                writer, readers = i, []
                writers.append(i)
            elif a.role == "order":
                # ordering only: no data edge keeps the last writer alive, so order after
                # every writer, or culling one would lose the order against the others
                for w in writers:
                    add(w, i, "order")
            else:
                if writer is not None:
                    add(writer, i, "data")
                readers.append(i)
    return edges


# ---------------------------------------------------------------------------------------------
# step 2: cull


def cull(declared: Declared) -> tuple[list[int], list[str]]:
    """Keep passes that feed a graph output through data edges, or that have side effects."""
    passes = declared.passes
    preds: dict[int, list[int]] = defaultdict(list)
    for (a, b), kind in declared.edges.items():
        if kind == "data":
            preds[b].append(a)
    # reading last frame's value needs its writers to run every frame (no ordering edge)
    writers: dict[str, list[int]] = defaultdict(list)
    for i, p in enumerate(passes):
        for a in declared.accesses[p.name]:
            if a.writes:
                writers[a.resource].append(i)
    for i, p in enumerate(passes):
        for a in declared.accesses[p.name]:
            if a.role == "history":
                preds[i].extend(writers[declared.history[a.resource]])
    outputs = set(declared.outputs)
    live = [i for i, p in enumerate(passes)
            if p.side_effect or not any(a.writes for a in declared.accesses[p.name])
            or any(a.writes and a.resource in outputs for a in declared.accesses[p.name])]
    keep = set(live)
    while live:
        for j in preds[live.pop()]:
            if j not in keep:
                keep.add(j)
                live.append(j)
    culled = [p.name for i, p in enumerate(passes) if i not in keep]
    return sorted(keep), culled


def unproduced_after_cull(declared: Declared, keep: list[int]
                          ) -> list[tuple[PassDecl, str, str, str]]:
    """(pass, slot, resource, producer) of each kept pass's input whose producer is culled.

    Data reads keep their producers, so only ordering-only inputs can lose one: a pass
    orders after a producer because it depends on what that producer does (Raptor's
    reference inputs were loaded so once, and culling dropped what depth of field reads)."""
    kept = {declared.passes[i].name for i in keep}
    out = []
    for i in keep:
        p = declared.passes[i]
        for a in declared.accesses[p.name]:
            r = declared.resources.get(a.resource)
            if a.role not in ("produce", "history") and r is not None \
                    and r.producer is not None and r.producer not in kept:
                out.append((p, a.slots[0], a.resource, r.producer))
    return out


# ---------------------------------------------------------------------------------------------
# step 3: order


def order(declared: Declared, keep: list[int], seed: int | None = None,
          priority: dict[int, int] | None = None) -> list[int]:
    """Stable topological order of the kept passes (ties: declaration order; with a
    ``seed``, ties broken at random: another valid order, for schedule fuzzing; with a
    ``priority``, lower first among ready passes)."""
    return _stable_toposort(len(declared.passes), declared.edges, declared.passes, keep, seed,
                            priority)


# ---------------------------------------------------------------------------------------------
# step 5: lifetimes


def lifetimes(declared: Declared, schedule: list[int]) -> dict[str, tuple[int, int]]:
    """First and last schedule position at which each resource's memory is touched."""
    span: dict[str, tuple[int, int]] = {}
    for pos, i in enumerate(schedule):
        for a in declared.accesses[declared.passes[i].name]:
            if a.role == "order":
                continue
            first, _ = span.get(a.resource, (pos, pos))
            span[a.resource] = (first, pos)
    end = len(schedule) - 1
    for name in declared.outputs:  # outputs are read after the frame
        if name in span:
            span[name] = (span[name][0], end)
    return span


# ---------------------------------------------------------------------------------------------
# step 8: parallel levels


def parallel_levels(declared: Declared, schedule: list[int]) -> list[list[str]]:
    """Passes at the same longest-path depth have no path between them."""
    preds: dict[int, list[int]] = defaultdict(list)
    kept = set(schedule)
    for a, b in declared.edges:
        if a in kept and b in kept:
            preds[b].append(a)
    level: dict[int, int] = {}
    for i in schedule:
        level[i] = 1 + max((level[j] for j in preds[i]), default=-1)
    out: list[list[str]] = [[] for _ in range(max(level.values(), default=-1) + 1)]
    for i in schedule:
        out[level[i]].append(declared.passes[i].name)
    return out
