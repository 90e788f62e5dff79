"""``compile(graph, size, caps)``: pure, deterministic, GPU-free.

validate -> cull -> order -> resolve -> lifetimes -> assign memory -> plan barriers ->
parallel levels. Each step is a short function; executors make no decision made here.
"""

from __future__ import annotations

import bisect
import gc
import heapq
import itertools
import math
from bisect import bisect_left, bisect_right
from collections import Counter, OrderedDict, defaultdict
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from typing import Any

from ..units import align_up
from .bridges import insert_bridges
from .errors import GraphError, did_you_mean
from .formats import UnknownFormatError, canonical, format_info, image_bytes
from .graph import Graph, PassDecl
from .resources import BUFFER_USAGES, IMAGE_USAGES, Binding, ResourceDecl, SizeRule, Slot
from .sync import State, merge_states, state_for

# step executions (cache misses), so tests and benchmarks can see what a recompile redid
STATS: Counter[str] = Counter()

# pass types whose attachments are real render targets (compute writes them as storage)
RASTER = frozenset({"graphics", "mesh"})
MAX_DIMENSION = 65536  # beyond any device's image limit: a size rule gone wrong
KNOWN_USAGES = BUFFER_USAGES | IMAGE_USAGES | {"accel_build", "accel_read"}
IMPLIED_CAPS = {"mesh": ("VK_EXT_mesh_shader",), "ray_tracing": ("VK_KHR_ray_tracing_pipeline",)}


@dataclass(frozen=True)
class MemoryOptions:
    """Placement rules for transient resources."""

    alias: bool = True
    image_alignment: int = 64 * 1024
    buffer_alignment: int = 256
    # (resource, bytes) a device reports for a resource, replacing the texel-count estimate:
    # drivers pad rows and tiles, and a plan must hold what the driver will bind
    sizes: tuple[tuple[str, int], ...] = ()


@dataclass(frozen=True)
class Diagnostic:
    level: str  # "error" | "warning" | "info"
    message: str

    def to_json(self) -> dict[str, str]:
        return {"level": self.level, "message": self.message}


@dataclass(frozen=True)
class Access:
    """One pass touching one resource (all its slots on that resource merged)."""

    pass_name: str
    resource: str
    role: str  # produce | modify | read | order | history
    usages: frozenset[str]
    state: State | None  # None: ordering only
    slots: tuple[str, ...]
    load: str | None = None

    @property
    def writes(self) -> bool:
        return self.role in ("produce", "modify")


@dataclass(frozen=True)
class ResourcePlan:
    name: str
    kind: str  # image | buffer | accel
    format: str | None
    width: int
    height: int
    mips: int
    layers: int
    samples: int
    raw_bytes: int  # texel or buffer bytes
    bytes: int  # raw_bytes rounded up to the placement alignment
    usages: frozenset[str]
    producer: str | None
    first: str | None
    last: str | None
    transient: bool
    external: bool
    history: bool
    heap: int | None = None
    offset: int | None = None

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "kind": self.kind, "format": self.format,
                "width": self.width, "height": self.height, "bytes": self.bytes,
                "heap": self.heap, "offset": self.offset, "first": self.first,
                "last": self.last, "transient": self.transient}


@dataclass(frozen=True)
class Barrier:
    pass_name: str
    resource: str
    src: State
    dst: State
    aliased: tuple[str, ...] = ()  # resources whose memory this one takes over

    def to_json(self) -> dict[str, Any]:
        src = self.src.to_json()
        if self.aliased:
            src["aliased"] = list(self.aliased)
        return {"pass": self.pass_name, "resource": self.resource, "from": src,
                "to": self.dst.to_json()}


@dataclass(frozen=True)
class CompiledGraph:
    name: str
    size: tuple[int, int]
    order: tuple[str, ...]
    culled: tuple[str, ...]
    disabled: tuple[str, ...]
    resources: tuple[ResourcePlan, ...]
    heaps: tuple[int, ...]
    transient_bytes: int
    unaliased_bytes: int
    lower_bound_bytes: int
    raptor_reuse_bytes: int
    barriers: tuple[Barrier, ...]
    parallel_levels: tuple[tuple[str, ...], ...]
    diagnostics: tuple[Diagnostic, ...]
    accesses: dict[str, tuple[Access, ...]] = field(compare=False)  # per scheduled pass
    edges: tuple[tuple[str, str, str], ...] = ()  # (from, to, "data" | "order")
    outputs: tuple[str, ...] = ()
    # where the output size came from: "graph" (its own) or "given" (the caller's)
    size_from: str = field(default="graph", compare=False)
    # images sized from the output size (directly or through others); 0: all fixed
    follow_output: int = field(default=0, compare=False)

    def resource(self, name: str) -> ResourcePlan:
        for r in self.resources:
            if r.name == name:
                return r
        raise KeyError(name)

    def to_json(self) -> dict[str, Any]:
        return {
            "order": list(self.order),
            "culled": list(self.culled),
            "disabled": list(self.disabled),
            "resources": [r.to_json() for r in self.resources],
            "heaps": [{"index": i, "bytes": b} for i, b in enumerate(self.heaps)],
            "transient_bytes": self.transient_bytes,
            "unaliased_bytes": self.unaliased_bytes,
            "lower_bound_bytes": self.lower_bound_bytes,
            "raptor_reuse_bytes": self.raptor_reuse_bytes,
            "barriers": [b.to_json() for b in self.barriers],
            "parallel_levels": [list(level) for level in self.parallel_levels],
            "diagnostics": [d.to_json() for d in self.diagnostics],
        }


# ---------------------------------------------------------------------------------------------
# the result of validation: everything later steps need, nothing they must re-derive


@dataclass
class Declared:
    passes: list[PassDecl]  # enabled, in declaration order
    disabled: list[str]
    resources: dict[str, ResourceDecl]
    accesses: dict[str, tuple[Access, ...]]
    edges: dict[tuple[int, int], str]  # (from, to) pass indices -> "data" | "order"
    outputs: tuple[str, ...]
    history: dict[str, str]  # history copy -> resource it follows
    diagnostics: list[Diagnostic]
    history_of: dict[str, str] = field(default_factory=dict)  # resource -> its history copy


class _Problems:
    """Collects errors (raised together) and warnings (kept as diagnostics)."""

    def __init__(self, graph: Graph, strict: bool):
        self.graph, self.strict = graph, strict
        self.errors: list[str] = []
        self.diagnostics = [Diagnostic(level, msg) for level, msg in graph.diagnostics]

    def error(self, message: str) -> None:
        self.errors.append(message)

    def lenient(self, message: str) -> None:
        # an error in strict mode, a warning in lenient mode
        if self.strict:
            self.errors.append(message)
        else:
            self.diagnostics.append(Diagnostic("warning", message))

    def info(self, message: str) -> None:
        self.diagnostics.append(Diagnostic("info", message))

    def raise_if_any(self) -> None:
        if self.errors:
            raise GraphError(self.errors[0], file=self.graph.source, more=self.errors[1:])


def _slot_where(p: PassDecl, b: Binding) -> str:
    return f"{p.where()}, slot '{b.slot}'"


# ---------------------------------------------------------------------------------------------
# step 1: validate


def validate(graph: Graph, caps: frozenset[str] | None, strict: bool) -> Declared:
    """Check the declarations and turn slots into accesses and dependency edges."""
    STATS["validate"] += 1
    problems = _Problems(graph, strict)
    passes = _enabled_passes(graph, problems)
    _check_capabilities(passes, caps, problems)
    _check_settings(passes, problems)
    resources = _declare_resources(graph, passes, problems)
    problems.raise_if_any()
    accesses, history = _derive_accesses(passes, resources, problems)
    problems.raise_if_any()
    hard = _producer_edges(passes, accesses, resources)
    natural = _stable_toposort(len(passes), hard, passes)  # raises on a cycle
    edges = _hazard_edges(passes, accesses, natural, hard)
    outputs = _graph_outputs(graph, passes, accesses, resources, natural, problems)
    problems.raise_if_any()
    disabled = [p.name for p in graph.passes if not p.enabled]
    return Declared(passes, disabled, resources, accesses, edges, outputs, history,
                    problems.diagnostics, {r: c for c, r in history.items()})


def _enabled_passes(graph: Graph, problems: _Problems) -> list[PassDecl]:
    seen: set[str] = set()
    for p in graph.passes:
        if p.name in seen:
            problems.error(f"pass '{p.name}' is declared twice")
        seen.add(p.name)
    return [p for p in graph.passes if p.enabled]


def _check_capabilities(passes: list[PassDecl], caps: frozenset[str] | None,
                        problems: _Problems) -> None:
    # caps=None means "no device given": plan for any device
    if caps is None:
        return
    for p in passes:
        missing = [c for c in (*IMPLIED_CAPS.get(p.type, ()), *p.requires) if c not in caps]
        if missing:
            problems.error(f"{p.where()} needs {', '.join(missing)}, which the device lacks")


def _check_settings(passes: list[PassDecl], problems: _Problems) -> None:
    for p in passes:
        if p.schema is None:
            continue
        for key, _ in p.settings:
            if key not in p.schema:
                problems.error(f"{p.where()}: unknown setting '{key}'"
                               + did_you_mean(key, p.schema))


def _declare_resources(graph: Graph, passes: list[PassDecl],
                       problems: _Problems) -> dict[str, ResourceDecl]:
    """One declaration per resource: from its import or its single producer."""
    resources: dict[str, ResourceDecl] = {}
    for name, spec in graph.imports:
        if name in resources:
            problems.error(f"external resource '{name}' is imported twice")
        resources[name] = _resource_from(name, spec, None, None, problems, "external")
    for p in passes:
        for b in p.outputs:
            if b.spec.type == "reference":
                continue
            where = _slot_where(p, b)
            if b.resource in resources:
                other = resources[b.resource].producer
                what = f"pass '{other}'" if other else "an external import"
                problems.error(f"{where}: resource '{b.resource}' is already produced by {what}"
                               " (write it in place with a reference output or an attachment "
                               "input instead)")
                continue
            resources[b.resource] = _resource_from(b.resource, b.spec, p, b, problems, where)
    return resources


def _resource_from(name: str, spec: Slot, p: PassDecl | None, b: Binding | None,
                   problems: _Problems, where: str) -> ResourceDecl:
    kind = {"buffer": "buffer", "accel": "accel"}.get(spec.type, "image")
    external = spec.external
    # an external resource may stay undescribed: the application owns and sizes it
    if kind == "image" and spec.format is None and not external:
        problems.lenient(f"{where}: image '{name}' has no format")
        external = True
    elif kind == "image" and spec.format is not None:
        try:
            format_info(spec.format)
        except UnknownFormatError as e:
            problems.error(f"{where}: {e}")
    if kind == "buffer" and spec.bytes is None and not external:
        problems.lenient(f"{where}: buffer '{name}' has no size (bytes)")
        external = True
    elif kind == "buffer" and spec.bytes is not None and spec.bytes <= 0:
        problems.error(f"{where}: buffer '{name}' has a non-positive size ({spec.bytes} bytes)")
    for attr in ("mips", "layers", "samples"):
        if getattr(spec, attr) < 1:
            problems.error(f"{where}: '{name}' has {attr} = {getattr(spec, attr)} (must be >= 1)")
    size = spec.size or (SizeRule.output() if kind == "image" else None)
    return ResourceDecl(name, kind, spec.format, size, spec.mips, spec.layers, spec.samples,
                        spec.bytes, external, p.name if p else None, b.slot if b else None)


def _missing_resource(p: PassDecl, b: Binding, names: Iterable[str],
                      pass_names: dict[str, PassDecl]) -> str:
    where = _slot_where(p, b)
    head, _, tail = b.resource.rpartition(".")
    if head in pass_names:
        producer = pass_names[head]
        slots = [o.slot for o in producer.outputs]
        if not producer.enabled:
            return f"{where}: '{b.resource}' comes from pass '{head}', which is disabled"
        return (f"{where}: pass '{head}' has no output slot '{tail}'" + did_you_mean(tail, slots))
    return (f"{where}: no enabled pass produces '{b.resource}' and it is not external"
            + did_you_mean(b.resource, names))


def _derive_accesses(passes: list[PassDecl], resources: dict[str, ResourceDecl],
                     problems: _Problems) -> tuple[dict[str, tuple[Access, ...]], dict[str, str]]:
    """Merge each pass's slots per resource into one access with one state."""
    all_passes = {p.name: p for p in problems.graph.passes}
    history: dict[str, str] = {}
    accesses: dict[str, tuple[Access, ...]] = {}
    for p in passes:
        merged: dict[str, Access] = {}
        for b in p.bindings:
            if b.resource not in resources:
                problems.lenient(_missing_resource(p, b, resources, all_passes))
                continue
            access = _access_for(p, b, resources[b.resource], problems)
            if access is None:
                continue
            if access.role == "history":
                copy = f"{b.resource}@prev"
                history[copy] = b.resource
                access = Access(p.name, copy, "history", access.usages, access.state,
                                access.slots)
            prior = merged.get(access.resource)
            merged[access.resource] = access if prior is None else \
                _merge_access(p, b, prior, access, problems)
        accesses[p.name] = tuple(merged.values())
    for copy, name in history.items():
        r = resources[name]
        resources[copy] = ResourceDecl(copy, r.kind, r.format, r.size, r.mips, r.layers,
                                       r.samples, r.bytes, r.external, None, None)
    return accesses, history


_ROLE = {"reference": "order", "history": "history"}


def _access_for(p: PassDecl, b: Binding, r: ResourceDecl, problems: _Problems) -> Access | None:
    spec = b.spec
    # big graphs repeat a few kinds of slot: each kind is checked and worked out once
    key = (spec.type, spec.format, spec.usage, spec.read_only, spec.load, spec.stages,
           b.direction, p.type, r.kind, r.format)
    known = _KINDS.get(key)
    if known is None:
        known = _access_kind(p, b, r, problems)
        if known is None:
            return None
        _KINDS[key] = known
    role, usages, state = known
    if role == "order":
        return Access(p.name, r.name, role, usages, None, (b.slot,))
    return Access(p.name, r.name, role, usages, state, (b.slot,), spec.load)


def _access_kind(p: PassDecl, b: Binding, r: ResourceDecl, problems: _Problems
                 ) -> tuple[str, frozenset[str], State | None] | None:
    """(role, usages, state) of a slot on a resource, or None after reporting an error."""
    spec = b.spec
    if spec.format and r.format and canonical(spec.format) != canonical(r.format):
        problems.error(f"{_slot_where(p, b)}: declares format {spec.format} but '{r.name}' is "
                       f"{r.format}")
        return None
    if b.direction == "out":
        if spec.type in ("history", "shading_rate"):
            problems.error(f"{_slot_where(p, b)}: a {spec.type} slot can only be an input")
            return None
        role = "modify" if spec.type == "reference" else "produce"
    else:
        role = _ROLE.get(spec.type, "modify" if spec.type in ("attachment", "depth", "storage")
                         and not spec.read_only else "read")
    if role == "order":
        return role, frozenset(), None
    slot_kind = {"buffer": "buffer", "accel": "accel"}.get(spec.type, "image")
    if r.kind != slot_kind and spec.type != "reference":
        what = {"image": "an image", "buffer": "a buffer", "accel": "an acceleration structure"}
        problems.error(f"{_slot_where(p, b)}: '{r.name}' is {what[r.kind]}, not usable as "
                       f"{spec.type}")
        return None
    unknown = sorted(spec.usage - KNOWN_USAGES)
    if unknown:
        problems.error(f"{_slot_where(p, b)}: unknown usage '{unknown[0]}'"
                       + did_you_mean(unknown[0], KNOWN_USAGES))
        return None
    usages = _usages(p, b, r)
    key = (usages, p.type, role, spec.load == "load", r.format, r.kind, spec.stages)
    state = _STATES.get(key)
    if state is None:
        state = _STATES[key] = _state_of(*key)
    return role, usages, state


# big graphs repeat a few kinds of access: their states are worked out once
_STATES: dict[tuple, State] = {}
_KINDS: dict[tuple, tuple[str, frozenset[str], State | None]] = {}


def _state_of(usages: frozenset[str], pass_type: str, role: str, loads: bool,
              format: str | None, kind: str, stages: frozenset[str]) -> State:
    fmt = format_info(format) if format else None
    states = [state_for(u, pass_type=pass_type, write=role in ("produce", "modify"),
                        read=role != "produce" or loads,
                        depth=bool(fmt and fmt.depth), stencil=bool(fmt and fmt.stencil),
                        image=kind == "image", stages=stages) for u in sorted(usages)]
    state = states[0]
    for s in states[1:]:
        state = merge_states(state, s) or state
    return state


def _usages(p: PassDecl, b: Binding, r: ResourceDecl) -> frozenset[str]:
    """What the slot type means for this pass type and format."""
    spec = b.spec
    if p.type == "transfer" and spec.usage & {"transfer_src", "transfer_dst"}:
        return spec.usage & {"transfer_src", "transfer_dst"}  # copies only copy
    if r.kind == "buffer":
        return spec.usage or frozenset({"storage"})
    if r.kind == "accel":  # built (or refit in place) by writers, traced by readers
        return frozenset({"accel_build" if b.direction == "out" else "accel_read"})
    fmt = format_info(r.format) if r.format else None
    depth = bool(fmt and fmt.depth)
    raster = p.type in RASTER
    kind = spec.type
    if kind == "reference":  # in-place write of an existing image
        kind = "attachment" if raster else "storage"
    if kind == "texture":
        usage = {"storage" if b.direction == "out" else "sampled"}
    elif kind in ("attachment", "depth"):
        if not raster:
            usage = {"storage"}
        elif depth:
            usage = {"depth_read" if spec.read_only else "depth"}
        else:
            usage = {"color"}
    elif kind == "history":
        usage = {"sampled"}
    elif kind == "shading_rate":
        usage = {"shading_rate"}
    else:
        usage = {"storage"}
    return frozenset(usage) | (spec.usage & {"transfer_src", "transfer_dst"})


def _merge_access(p: PassDecl, b: Binding, a: Access, c: Access, problems: _Problems) -> Access:
    roles = {a.role, c.role}
    if "produce" in roles and len(roles - {"order"}) > 1:
        what = "writes in place" if "modify" in roles else "reads"
        problems.error(f"{_slot_where(p, b)}: the pass {what} '{a.resource}', which it "
                       "produces itself")
        return a
    if a.state is None or c.state is None:  # ordering merges into any real access
        keep, other = (c, a) if a.state is None else (a, c)
        return Access(keep.pass_name, keep.resource, keep.role, keep.usages, keep.state,
                      keep.slots + other.slots, keep.load)
    state = merge_states(a.state, c.state)
    if state is None:
        problems.error(f"{_slot_where(p, b)}: '{a.resource}' is used as "
                       f"{'/'.join(sorted(a.usages))} and {'/'.join(sorted(c.usages))} in the "
                       "same pass (two layouts at once)")
        return a
    role = next(r for r in ("produce", "modify", "read", "history") if r in roles)
    return Access(a.pass_name, a.resource, role, a.usages | c.usages, state, a.slots + c.slots,
                  a.load or c.load)


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
                     keep: Iterable[int] | None = None) -> list[int]:
    """Kahn's algorithm, smallest declaration index first; a cycle raises with its path."""
    nodes = set(range(n) if keep is None else keep)
    succ: dict[int, list[int]] = defaultdict(list)
    indeg = dict.fromkeys(nodes, 0)
    for a, b in edges:
        if a in nodes and b in nodes:
            succ[a].append(b)
            indeg[b] += 1
    ready = [i for i in nodes if indeg[i] == 0]
    heapq.heapify(ready)
    order: list[int] = []
    while ready:
        i = heapq.heappop(ready)
        order.append(i)
        for j in succ[i]:
            indeg[j] -= 1
            if indeg[j] == 0:
                heapq.heappush(ready, j)
    if len(order) != len(nodes):
        raise GraphError(_cycle_message(nodes - set(order), succ, passes))
    return order


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


def _graph_outputs(graph: Graph, passes: list[PassDecl], accesses: dict[str, tuple[Access, ...]],
                   resources: dict[str, ResourceDecl], natural: list[int],
                   problems: _Problems) -> tuple[str, ...]:
    """Declared outputs, else what leaves the frame: external writes and never-read values."""
    if graph.outputs is not None:
        for name in graph.outputs:
            if name not in resources:
                problems.error(f"graph output '{name}' is not a resource of the graph"
                               + did_you_mean(name, resources))
        return tuple(n for n in graph.outputs if n in resources)
    last_role: dict[str, str] = {}
    written: set[str] = set()
    for i in natural:
        for a in accesses[passes[i].name]:
            if a.role not in ("order", "history"):
                last_role[a.resource] = a.role
                if a.writes:
                    written.add(a.resource)
    return tuple(name for name, role in last_role.items()
                 if role != "read" or (resources[name].external and name in written))


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


# ---------------------------------------------------------------------------------------------
# step 3: order


def order(declared: Declared, keep: list[int]) -> list[int]:
    """Stable topological order of the kept passes (ties: declaration order)."""
    return _stable_toposort(len(declared.passes), declared.edges, declared.passes, keep)


# ---------------------------------------------------------------------------------------------
# step 4: resolve sizes and formats


@dataclass(frozen=True)
class Resolved:
    name: str
    kind: str
    format: str | None
    width: int
    height: int
    mips: int
    layers: int
    samples: int
    raw_bytes: int


def resolve(declared: Declared, used: Iterable[str], size: tuple[int, int],
            problems: _Problems) -> dict[str, Resolved]:
    """Turn size rules into texels and formats into bytes."""
    out: dict[str, Resolved] = {}
    sizes: dict[str, tuple[int, int]] = {}
    for name in used:
        r = declared.resources[name]
        if r.kind == "buffer":
            out[name] = Resolved(name, "buffer", None, 0, 0, 1, 1, 1, r.bytes or 0)
            continue
        if r.kind == "accel":  # its builder owns its memory: nothing for the heaps
            out[name] = Resolved(name, "accel", None, 0, 0, 1, 1, 1, 0)
            continue
        if r.format is None:  # lenient: application-owned image of unknown shape
            out[name] = Resolved(name, "image", None, 0, 0, 1, 1, 1, 0)
            continue
        w, h = _resolve_size(name, declared.resources, size, sizes, [])
        if not (1 <= w <= MAX_DIMENSION and 1 <= h <= MAX_DIMENSION):
            where = f"pass '{r.producer}', slot '{r.slot}'" if r.producer else "external"
            shape = f"{w}x{h}" if max(w, h) <= MAX_DIMENSION else f"over {MAX_DIMENSION}"
            problems.error(f"{where}: '{name}' resolves to {shape} texels "
                           f"(size rule {r.size.describe()}; 1..{MAX_DIMENSION} allowed)")
            continue
        shape = (r.format, w, h, r.mips, r.layers, r.samples)
        raw = _IMAGE_BYTES.get(shape)
        if raw is None:
            if len(_IMAGE_BYTES) > 4096:  # many output sizes over a long session
                _IMAGE_BYTES.clear()
            try:
                raw = _IMAGE_BYTES[shape] = image_bytes(r.format, w, h, mips=r.mips,
                                                        layers=r.layers, samples=r.samples)
            except ValueError as e:
                where = f"pass '{r.producer}', slot '{r.slot}': " if r.producer else ""
                problems.error(f"{where}'{name}': {e}")
                continue
        out[name] = Resolved(name, "image", r.format, w, h, r.mips, r.layers, r.samples, raw)
    return out


# (format, width, height, mips, layers, samples) -> bytes: big graphs repeat a few shapes
_IMAGE_BYTES: dict[tuple, int] = {}


def _resolve_size(name: str, resources: dict[str, ResourceDecl], size: tuple[int, int],
                  memo: dict[str, tuple[int, int]], stack: list[str]) -> tuple[int, int]:
    if name in memo:
        return memo[name]
    if name in stack:
        raise GraphError("size rules form a cycle: " + " -> ".join([*stack, name]))
    rule = resources[name].size or SizeRule.output()
    if rule.mode == "fixed":
        wh = (rule.width, rule.height)
    else:
        if rule.mode == "relative":
            if rule.of not in resources or resources[rule.of].kind != "image":
                raise GraphError(f"'{name}' is sized like '{rule.of}', which is not an image "
                                 "of the graph" + did_you_mean(str(rule.of), resources))
            base = _resolve_size(rule.of, resources, size, memo, [*stack, name])
        else:
            base = size
        # truncation, as Raptor does: a 0.5 scale of 1281 is 640
        sx, sy = (base[0] * rule.scale[0], base[1] * rule.scale[1])
        wh = (int(sx) if math.isfinite(sx) else 0, int(sy) if math.isfinite(sy) else 0)
    memo[name] = wh
    return wh


def check_attachment_sizes(declared: Declared, kept: list[int], resolved: dict[str, Resolved],
                           problems: _Problems) -> None:
    """A render pass has one framebuffer size: its attachments must agree."""
    for i in kept:
        p = declared.passes[i]
        if p.type not in RASTER:
            continue
        sizes = {(a.resource, resolved[a.resource].width, resolved[a.resource].height)
                 for a in declared.accesses[p.name]
                 if a.usages & {"color", "depth", "depth_read"} and a.resource in resolved
                 and resolved[a.resource].format}
        if len({(w, h) for _, w, h in sizes}) > 1:
            listed = ", ".join(f"{n} {w}x{h}" for n, w, h in sorted(sizes))
            problems.error(f"{p.where()}: attachments differ in size: {listed}")


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


def compile(graph: Graph, size: tuple[int, int] | None = None,
            caps: Iterable[str] | None = None, *, strict: bool | None = None,
            cull_passes: bool = True, memory: MemoryOptions = MemoryOptions(),
            backend: str | None = None) -> CompiledGraph:
    """Compile a declared graph for an output size and a device's capabilities.

    Pure and deterministic. Results are memoised: compiling an unchanged graph again is a
    dictionary lookup, and a changed graph reuses the memory plan when lifetimes are equal.
    """
    # compile builds many small acyclic objects, and hashing a new graph for the cache makes
    # many tuples: the cycle collector, sweeping the whole heap, would dominate its time
    paused = gc.isenabled()
    gc.disable()
    try:
        return _compile_cached(graph, size, caps, strict=strict, cull_passes=cull_passes,
                               memory=memory, backend=backend)
    finally:
        if paused:
            gc.enable()


def _compile_cached(graph: Graph, size: tuple[int, int] | None, caps: Iterable[str] | None, *,
                    strict: bool | None, cull_passes: bool, memory: MemoryOptions,
                    backend: str | None) -> CompiledGraph:
    size_from = "graph" if size is None else "given"
    size = size or graph.size
    if size is None:
        raise GraphError("no output size given (pass size=(w, h) or declare one in the graph)",
                         file=graph.source)
    if size[0] < 1 or size[1] < 1:
        raise GraphError(f"output size {size[0]}x{size[1]} is not positive", file=graph.source)
    caps = None if caps is None else frozenset(caps)
    strict = graph.strict if strict is None else strict
    key = (graph, tuple(size), size_from, caps, strict, cull_passes, memory, backend)
    if key in _CACHE:
        _CACHE.move_to_end(key)
        return _CACHE[key]
    STATS["compile"] += 1
    try:
        graph = insert_bridges(graph, backend)
        result = replace(_compile(graph, (int(size[0]), int(size[1])), caps, strict,
                                  cull_passes, memory), size_from=size_from)
    except GraphError as e:
        raise e.in_file(graph.source) from None
    return _remember(_CACHE, key, result)


def _compile(graph: Graph, size: tuple[int, int], caps: frozenset[str] | None, strict: bool,
             cull_passes: bool, memory: MemoryOptions) -> CompiledGraph:
    declared = validate(graph, caps, strict)
    problems = _Problems(graph, strict)
    problems.diagnostics = list(declared.diagnostics)
    if cull_passes:
        keep, culled = cull(declared)
    else:
        keep, culled = list(range(len(declared.passes))), []
    schedule = order(declared, keep)
    used = _used_resources(declared, schedule)
    declared = _kept_history(declared, set(used))
    resolved = resolve(declared, used, size, problems)
    problems.raise_if_any()
    check_attachment_sizes(declared, schedule, resolved, problems)
    problems.raise_if_any()
    spans = lifetimes(declared, schedule)
    transient = {n for n in used if n in spans and _is_transient(n, declared, resolved)}
    items, heap_of, align = _memory_items(declared, resolved, spans, transient, memory)
    mem_key = (items, memory.alias)
    if mem_key in _MEMORY_CACHE:
        heaps, offsets = _MEMORY_CACHE[mem_key]
    else:
        heaps, offsets = _remember(_MEMORY_CACHE, mem_key, assign_memory(items, memory.alias))
    placement = {n: (heap_of[n], offsets[n], offsets[n] + align[n]) for n in transient}
    barriers = plan_barriers(declared, schedule, resolved, placement, transient, spans)
    flat = [it for heap in items for it in heap]
    names = [declared.passes[i].name for i in schedule]
    kept = set(schedule)
    plans = _resource_plans(declared, used, resolved, spans, transient, placement, align, names)
    return CompiledGraph(
        name=graph.name, size=size, order=tuple(names), culled=tuple(culled),
        disabled=tuple(declared.disabled), resources=tuple(plans), heaps=heaps,
        transient_bytes=sum(heaps), unaliased_bytes=sum(it.size for it in flat),
        lower_bound_bytes=lower_bound(flat, len(schedule)),
        raptor_reuse_bytes=_raptor_reuse_bytes(declared, flat, resolved, spans, schedule),
        barriers=tuple(barriers),
        parallel_levels=tuple(tuple(level) for level in parallel_levels(declared, schedule)),
        diagnostics=tuple(problems.diagnostics),
        accesses={n: declared.accesses[n] for n in names},
        edges=tuple((declared.passes[a].name, declared.passes[b].name, kind)
                    for (a, b), kind in sorted(declared.edges.items())
                    if a in kept and b in kept),
        outputs=declared.outputs,
        follow_output=sum(_follows_output(n, declared.resources) for n, r in resolved.items()
                          if r.kind == "image" and r.format),
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
