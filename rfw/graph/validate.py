"""Step 1 of ``compile``: check the declarations and turn slots into accesses and edges."""

from __future__ import annotations

from .accesses import derive_accesses, slot_where
from .errors import did_you_mean
from .format_of import resolve_formats_of
from .formats import UnknownFormatError, format_info
from .graph import Graph, PassDecl
from .plan import IMPLIED_CAPS, STATS, Access, Declared, _Problems
from .resources import Binding, ResourceDecl, SizeRule, Slot
from .schedule import _hazard_edges, _producer_edges, _stable_toposort
from .steps import derive_steps

# ---------------------------------------------------------------------------------------------
# step 1: validate


def validate(graph: Graph, caps: frozenset[str] | None, strict: bool) -> Declared:
    """Check the declarations and turn slots into accesses and dependency edges."""
    STATS["validate"] += 1
    problems = _Problems(graph, strict)
    # 1a: passes, and what they need of the device
    passes = _enabled_passes(graph, problems)
    _check_capabilities(passes, caps, problems)
    _check_settings(passes, problems)
    # 1b: one declaration per resource
    resources = _declare_resources(graph, passes, problems)
    resolve_formats_of(passes, resources, problems)  # format_of="<slot>" outputs
    problems.raise_if_any()
    # 1c: slots become accesses with states; 1d: steps inside passes, their parts of them
    accesses, history = derive_accesses(passes, resources, problems)
    problems.raise_if_any()
    steps = derive_steps(passes, resources, accesses, problems)
    problems.raise_if_any()
    # 1e: producer edges, the natural order they allow, and the hazards that order freezes
    hard = _producer_edges(passes, accesses, resources)
    natural = _stable_toposort(len(passes), hard, passes)  # raises on a cycle
    edges = _hazard_edges(passes, accesses, natural, hard)
    # 1f: what leaves the frame
    outputs = _graph_outputs(graph, passes, accesses, resources, natural, problems)
    problems.raise_if_any()
    disabled = [p.name for p in graph.passes if not p.enabled]
    return Declared(passes, disabled, resources, accesses, edges, outputs, history,
                    problems.diagnostics, {r: c for c, r in history.items()}, steps)


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
            where = slot_where(p, b)
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
    if kind == "image" and spec.format is None and not external and spec.format_of is None:
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
