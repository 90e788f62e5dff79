"""Step 1c of ``compile``: each pass's slots on a resource merged into one access with one
state (layout, stages, access) and one role (produce, modify, read, order, history)."""

from __future__ import annotations

from collections.abc import Iterable

from .errors import did_you_mean
from .formats import canonical, format_info
from .graph import PassDecl
from .plan import KNOWN_USAGES, RASTER, Access, _Problems
from .resources import Binding, ResourceDecl
from .sync import State, merge_states, state_for


def slot_where(p: PassDecl, b: Binding) -> str:
    return f"{p.where()}, slot '{b.slot}'"


def _missing_resource(p: PassDecl, b: Binding, names: Iterable[str],
                      pass_names: dict[str, PassDecl]) -> str:
    where = slot_where(p, b)
    head, _, tail = b.resource.rpartition(".")
    if head in pass_names:
        producer = pass_names[head]
        slots = [o.slot for o in producer.outputs]
        if not producer.enabled:
            return f"{where}: '{b.resource}' comes from pass '{head}', which is disabled"
        return (f"{where}: pass '{head}' has no output slot '{tail}'" + did_you_mean(tail, slots))
    return (f"{where}: no enabled pass produces '{b.resource}' and it is not external"
            + did_you_mean(b.resource, names))


def derive_accesses(passes: list[PassDecl], resources: dict[str, ResourceDecl],
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
        problems.error(f"{slot_where(p, b)}: declares format {spec.format} but '{r.name}' is "
                       f"{r.format}")
        return None
    if b.direction == "out":
        if spec.type in ("history", "shading_rate"):
            problems.error(f"{slot_where(p, b)}: a {spec.type} slot can only be an input")
            return None
        role = "modify" if spec.type == "reference" else "produce"
    else:
        role = _ROLE.get(spec.type, "modify" if spec.type in ("attachment", "depth", "storage")
                         and not spec.read_only else "read")
    if role == "order":
        return role, frozenset(), None
    slot_kind = {"buffer": "buffer", "accel": "accel"}.get(spec.type, "image")
    if spec.type == "storage" and r.kind == "buffer":
        slot_kind = "buffer"  # a storage input reads and writes a buffer in place too
    if r.kind != slot_kind and spec.type != "reference":
        what = {"image": "an image", "buffer": "a buffer", "accel": "an acceleration structure"}
        problems.error(f"{slot_where(p, b)}: '{r.name}' is {what[r.kind]}, not usable as "
                       f"{spec.type}")
        return None
    unknown = sorted(spec.usage - KNOWN_USAGES)
    if unknown:
        problems.error(f"{slot_where(p, b)}: unknown usage '{unknown[0]}'"
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
        problems.error(f"{slot_where(p, b)}: the pass {what} '{a.resource}', which it "
                       "produces itself")
        return a
    if a.state is None or c.state is None:  # ordering merges into any real access
        keep, other = (c, a) if a.state is None else (a, c)
        return Access(keep.pass_name, keep.resource, keep.role, keep.usages, keep.state,
                      keep.slots + other.slots, keep.load)
    state = merge_states(a.state, c.state)
    if state is None:
        problems.error(f"{slot_where(p, b)}: '{a.resource}' is used as "
                       f"{'/'.join(sorted(a.usages))} and {'/'.join(sorted(c.usages))} in the "
                       "same pass (two layouts at once)")
        return a
    role = next(r for r in ("produce", "modify", "read", "history") if r in roles)
    return Access(a.pass_name, a.resource, role, a.usages | c.usages, state, a.slots + c.slots,
                  a.load or c.load)
