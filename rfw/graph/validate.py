"""Step 1 of ``compile``: check the declarations and turn slots into accesses and edges."""


from __future__ import annotations

from collections.abc import Iterable

from .errors import did_you_mean
from .formats import UnknownFormatError, canonical, format_info
from .graph import Graph, PassDecl
from .plan import IMPLIED_CAPS, KNOWN_USAGES, RASTER, STATS, Access, Declared, _Problems
from .resources import Binding, ResourceDecl, SizeRule, Slot
from .schedule import _hazard_edges, _producer_edges, _stable_toposort
from .sync import State, merge_states, state_for


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
