"""The plan of a frame (:class:`FramePlan`): its compiled plan and what each backend runs of
it. A frame on one backend is one side and no bridges (``FramePlan.whole``); a frame that
mixes backends (passes pinned to wgpu and to vk) is cut into sides joined by bridges
(:func:`split`).

``compile(graph, backend=...)`` inserts a ``bridge.<resource>.<from>-<to>`` transfer pass
wherever a resource crosses backends (``rfw.graph.bridges``); each says what it copies in a
typed :class:`Bridge` (source and destination backend, resource and copy), and each plan
lists its bridge passes (``CompiledGraph.bridges``). Here that plan runs:

* **Per-backend sub-plans.** Each backend compiles its own part of the bridged graph: its
  passes, plus each bridge cut in half (the source side keeps the read, as a side-effect pass
  so nothing culls it; the destination side keeps the write of ``<resource>@<to>``, sized as
  the full plan sized it). So each executor owns only its passes and the resources they
  touch (a crossing resource exists on both sides: the original on the producer's, the copy
  on the consumer's), the vk side's transients are placed and aliased among themselves in
  ``plan_heaps`` with the device's exact sizes (``fit_graph``), and its barriers are the
  compiler's for exactly the vk work, bridge transitions to transfer src/dst included.
  Each sub-plan's order must be the full plan's order restricted to its passes (checked).
* **Walking the full order.** Consecutive passes of one backend are recorded into that
  backend's frame. At a bridge both ends record their side of it (on vk: the plan's
  barriers, e.g. to ``TRANSFER_SRC_OPTIMAL``) and flush (submit and wait), then the
  resource is read back to numpy and written into the copy: wgpu reads with
  ``Executor.read`` and writes with ``queue.write_texture``; vk reads with
  ``read_image``/``read_buffer`` from the state the plan has it in at the bridge and
  writes with ``upload_image``/``upload_buffer`` leaving the copy in the plan's
  ``TRANSFER_DST_OPTIMAL`` state, which the consumer's planned barrier starts from.
  The destination is flushed too before the write: uploads are queued ahead of anything
  still unsubmitted, and the copy's memory may be shared with a resource such work uses.
  (The reads and writes are each backend's ``read_bridge`` and ``write_bridge``.)
* **Timing.** Each bridge is its own entry in ``timings["passes"]``: ``cpu_ms`` is the wall
  time of the readback and the upload (``perf_counter``), ``gpu_ms`` is ``None`` (no
  timestamp brackets a host copy, and keeping it out leaves ``gpu_ms_total`` the sum of
  timestamped GPU work, comparable with single-backend runs); ``bridge_ms_total`` sums them.

wgpu-native exposes no Vulkan handles, so nothing is shared between the two devices: every
crossing costs a device-to-host and a host-to-device copy, and a flush on both sides.

Here is the plan (``split``); :class:`rfw.frame.Frame` runs it, as ``rfw.render.render`` does
for a config that pins a pass to a backend other than the run's. Nothing here knows a
backend's API: each side's device, plan, executor and host copies come from its
:class:`rfw.backend.Backend`, found by name in the ``rfw.backends`` entry-point group.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

from .backend import get_backend, installed, order
from .config import Built
from .graph import CompiledGraph, compile
from .graph.bridges import backend_of, insert_bridges
from .graph.formats import format_info
from .graph.graph import Bridge, Graph
from .graph.resources import Binding, SizeRule
from .shaders import ShaderError

__all__ = ["Bridge", "FramePlan", "split"]


@dataclass
class FramePlan:
    """The plan of one frame and what each backend runs of it (a frame on one backend: one
    side, no bridges)."""

    plan: CompiledGraph  # the full plan: order, bridges, every resource
    backend: str  # the run's backend (for unpinned passes)
    side: dict[str, str]  # pass -> the backend that records it (bridges: in bridges)
    bridges: dict[str, Bridge]  # bridge pass -> what it copies, between which backends
    graphs: dict[str, Graph]  # backend -> its part of the bridged graph
    slots: dict[str, dict[str, str]]  # pass -> slot -> resource, consumers on the copies
    owner: dict[str, str]  # resource -> backend holding it

    @classmethod
    def whole(cls, plan: CompiledGraph, backend: str, graph: Graph,
              slots: dict[str, dict[str, str]]) -> FramePlan:
        """A frame all on ``backend``: ``plan`` (``graph`` compiled for its device) is the
        one side's."""
        return cls(plan, backend, dict.fromkeys(plan.order, backend), {}, {backend: graph},
                   slots, {r.name: backend for r in plan.resources})

    @property
    def sides(self) -> tuple[str, ...]:
        """The backends the frame runs on, built-ins first."""
        used = set(self.side.values())
        for b in self.bridges.values():
            used |= {b.src, b.dst}
        return tuple(order(used))

    @property
    def single(self) -> bool:
        """One side and no bridges: the frame is that backend's executor's own."""
        return len(self.sides) == 1 and not self.bridges

    def backend_of(self, name: str) -> str | None:
        """The backend pass ``name`` runs on (a bridge: ``src>dst``, as timings.json says);
        None for a pass the frame does not schedule."""
        br = self.bridges.get(name)
        return br.route if br is not None else self.side.get(name)

    def passes_of(self, backend: str) -> tuple[str, ...]:
        """The full order's passes that ``backend`` records (its bridge halves included)."""
        return tuple(n for n in self.plan.order if self.side.get(n) == backend or (
            n in self.bridges and backend in (self.bridges[n].src, self.bridges[n].dst)))

    def check(self, backend: str, sub: CompiledGraph) -> None:
        """A backend's sub-plan schedules its passes in the full plan's order (where bridges
        join sides; a frame on one side runs the sub-plan's own order)."""
        want = self.passes_of(backend)
        if not self.bridges and sorted(sub.order) == sorted(want):
            return  # one side, nothing between: its own order is the frame's (a second queue's)
        if tuple(sub.order) != want:
            raise ShaderError(f"the {backend} part of '{self.plan.name}' schedules "
                              f"{', '.join(sub.order)}; the mixed plan needs "
                              f"{', '.join(want)} in that order")


def split(built: Built, backend: str = "wgpu") -> FramePlan:
    """Compile ``built`` for ``backend`` with bridges and cut it into per-backend graphs."""
    graph = built.graph
    plan = compile(graph, backend=backend)
    bridged = insert_bridges(graph, backend)
    scheduled = set(plan.order)
    decls = {p.name: p for p in bridged.passes if p.enabled and p.name in scheduled}
    side: dict[str, str] = {}
    bridges: dict[str, Bridge] = {}
    known = installed()
    for name, p in decls.items():
        if p.bridge is not None:
            bridges[name] = p.bridge
            continue
        b = backend_of(p, backend) or backend
        side[name] = b
        if b not in known:
            raise ShaderError(f"pass '{name}' is pinned to unknown backend '{b}' "
                              f"(installed: {', '.join(known)})", file=graph.source)
    owner: dict[str, str] = {}
    for r in plan.resources:
        if r.producer in side:
            owner[r.name] = side[r.producer]
        elif r.producer in bridges:
            owner[r.name] = bridges[r.producer].dst
        else:
            owner[r.name] = backend
    for name, p in decls.items():
        if name in bridges:
            continue
        for b in p.inputs:  # bridges carry this frame's values, not last frame's
            if b.spec.type == "history" and owner.get(b.resource, side[name]) != side[name]:
                raise ShaderError(f"pass '{name}' ({side[name]}) reads the history of "
                                  f"'{b.resource}', made on {owner[b.resource]}: bridges do "
                                  "not carry history; pin both passes to one backend",
                                  file=graph.source)
    graphs = {}
    for s in order({*side.values(), *(b for br in bridges.values() for b in (br.src, br.dst))}):
        passes = []
        for p in bridged.passes:
            if p.name not in decls:
                continue
            if p.name in bridges:
                br = bridges[p.name]
                if br.src == s:  # the read: keep it scheduled though nothing reads its result
                    passes.append(replace(p, outputs=(), side_effect=True))
                elif br.dst == s:  # the write of the copy, sized as the full plan sized it
                    out = p.outputs[0]
                    r = plan.resource(out.resource)
                    if r.mips != 1 or r.layers != 1:
                        raise ShaderError(f"{p.name}: bridges copy one mip of one layer; "
                                          f"'{br.resource}' has {r.mips} mips, {r.layers} "
                                          "layers", file=graph.source)
                    spec = out.spec if out.spec.type == "buffer" else \
                        out.spec.with_(size=SizeRule.fixed(r.width, r.height))
                    if r.kind != "buffer" and format_info(r.format).depth and \
                            not get_backend(s, file=graph.source, element=None).host_writes_depth:
                        spec = _depth_as_float(spec, r.format, br, _readers(decls, side,
                                                                            br), graph.source)
                    passes.append(replace(p, inputs=(), outputs=(replace(out, spec=spec),)))
            elif side[p.name] == s:
                passes.append(replace(p, outputs=tuple(_sized(b, plan) for b in p.outputs),
                                      backend=None))
        if not passes:
            continue
        outputs = None if bridged.outputs is None else \
            tuple(o for o in bridged.outputs if owner.get(o, backend) == s)
        graphs[s] = replace(bridged, passes=tuple(passes), outputs=outputs)
    slots: dict[str, dict[str, str]] = {}
    for name, mapping in built.slots.items():
        if name not in decls:
            continue
        # bridges rewire reads to copies; history slots keep their "@prev" resource
        rewired = {b.slot: b.resource for b in decls[name].inputs if b.spec.type != "history"}
        slots[name] = {slot: rewired.get(slot, res) for slot, res in mapping.items()}
    return FramePlan(plan, backend, side, bridges, graphs, slots, owner)


# depth formats a bridge carries as r32float into a backend that cannot upload depth images
# (wgpu); the host copy has the depth values
_DEPTH_AS_FLOAT = ("depth32float", "depth16unorm")


def _readers(decls: dict[str, Any], side: dict[str, str], br: Bridge) -> list[tuple[str, Any]]:
    """(pass, slot spec) of every pass on the bridge's destination that reads its copy."""
    return [(name, b.spec) for name, p in decls.items() if side.get(name) == br.dst
            for b in p.inputs if b.resource == br.copy]


def _depth_as_float(spec: Any, fmt: str, br: Bridge, readers: list[tuple[str, Any]],
                    source: str | None) -> Any:
    """WebGPU cannot write depth textures from the host (``write_texture`` and copies into
    them are refused; its backend says ``host_writes_depth = False``), so a depth image
    crossing into wgpu arrives as r32float: the depth values themselves, for passes that
    sample depth as a texture (ssao accepts r32float). A reader that needs a real depth
    texture, or a stencil, cannot be served: one line."""
    why = f"{br.dst} cannot write depth textures from the host"
    if fmt not in _DEPTH_AS_FLOAT:
        raise ShaderError(f"'{br.resource}' ({fmt}) is made on {br.src} and read on "
                          f"{br.dst}, but {why} and only {', '.join(_DEPTH_AS_FLOAT)} cross "
                          f"as r32float: pin its readers to {br.src}",
                          element=f"bridge '{br.name}'", file=source)
    for name, slot in readers:
        if slot.type != "texture":
            raise ShaderError(f"reads '{br.resource}' ({fmt}, made on {br.src}) as a "
                              f"{slot.type} slot on {br.dst}, but {why} (a bridge carries "
                              f"it as r32float, for sampling only): pin '{name}' to {br.src}",
                              element=f"pass '{name}'", file=source)
    return spec.with_(format="r32float")


def _sized(b: Binding, plan: CompiledGraph) -> Binding:
    """An output sized like another resource, sized as the full plan sized it: that
    resource may be on the other backend (``tonemap.ldr`` like ``lighting.hdr``, whose
    reader here is its copy)."""
    rule = b.spec.size
    if rule is None or rule.mode != "relative":
        return b
    try:
        r = plan.resource(b.resource)
    except KeyError:
        return b
    return replace(b, spec=b.spec.with_(size=SizeRule.fixed(r.width, r.height)))
