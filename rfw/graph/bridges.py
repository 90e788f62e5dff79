"""Cross-API graphs: where a resource made on one backend is used on another, a bridge pass
copies it through host memory (wgpu-native exposes no Vulkan handles to share). A bridge
pass says what it copies in its ``bridge`` (:class:`rfw.graph.graph.Bridge`: the resource,
the copy, the backends on either side); it is pinned to no backend itself."""

from __future__ import annotations

from dataclasses import replace

from .errors import GraphError
from .graph import Bridge, Graph, PassDecl
from .resources import Binding, SizeRule, Slot

# slot types that write the resource they name in place
_IN_PLACE = {"attachment", "depth", "storage"}


def backend_of(p: PassDecl, default: str | None) -> str | None:
    return p.backend or default


def insert_bridges(graph: Graph, backend: str | None) -> Graph:
    """The graph with a ``bridge.<resource>.<from>-<to>`` transfer pass wherever a resource
    crosses backends; consumers read the copy. Unchanged when every pass runs on one backend."""
    passes = [p for p in graph.passes if p.enabled]
    if not any(p.backend for p in passes):
        return graph
    made: dict[str, tuple[PassDecl, Binding]] = {}
    for p in passes:
        for b in p.outputs:
            if b.spec.type != "reference":
                made.setdefault(b.resource, (p, b))
    bridges: dict[tuple[str, str], PassDecl] = {}
    rewired: dict[str, PassDecl] = {}
    for q in passes:
        bq = backend_of(q, backend)
        new_inputs = []
        for b in q.inputs:
            source = made.get(b.resource)
            bp = backend_of(source[0], backend) if source else None
            if source is None or bp is None or bq is None or bp == bq or b.spec.type in (
                    "reference", "history"):
                new_inputs.append(b)
                continue
            if b.spec.type in _IN_PLACE and not b.spec.read_only:
                raise GraphError(f"pass '{q.name}' ({bq}) writes '{b.resource}' in place, but "
                                 f"pass '{source[0].name}' made it on {bp}: in-place writes "
                                 "across backends are not supported; give the pass its own "
                                 "output or pin both passes to one backend", file=graph.source)
            key = (b.resource, bq)
            if key not in bridges:
                bridges[key] = _bridge(b.resource, source[1].spec, bp, bq)
            new_inputs.append(replace(b, resource=bridges[key].outputs[0].resource))
        if new_inputs != list(q.inputs):
            rewired[q.name] = replace(q, inputs=tuple(new_inputs))
    if not bridges:
        return graph
    # each bridge follows its producer in declaration order, so ties keep a natural order
    out: list[PassDecl] = []
    for p in graph.passes:
        out.append(rewired.get(p.name, p))
        out.extend(br for (res, _), br in bridges.items() if made[res][0].name == p.name)
    return replace(graph, passes=tuple(out))


def _bridge(resource: str, spec: Slot, src: str, dst: str) -> PassDecl:
    copy = f"{resource}@{dst}"
    if spec.type == "buffer":
        out = Slot("buffer", bytes=spec.bytes, usage=frozenset({"transfer_dst"}),
                   desc=f"{resource} copied from {src}")
        read = Slot("buffer", usage=frozenset({"transfer_src"}))
    else:
        out = Slot("texture", spec.format, size=SizeRule.like(resource), mips=spec.mips,
                   format_of="src" if spec.format_of else None,
                   layers=spec.layers, usage=frozenset({"transfer_dst"}),
                   desc=f"{resource} copied from {src}")
        read = Slot("texture", usage=frozenset({"transfer_src"}))
    name = f"bridge.{resource}.{src}-{dst}"
    return PassDecl(name, "transfer", inputs=(Binding("src", "in", read, resource),),
                    outputs=(Binding("dst", "out", out, copy),),
                    bridge=Bridge(name, src, dst, resource, copy))
