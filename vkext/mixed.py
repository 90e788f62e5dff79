"""Frames that mix backends: passes pinned to wgpu and to vk in one frame, joined by bridges.

``compile(graph, backend=...)`` inserts a ``bridge.<resource>.<from>-<to>`` transfer pass
wherever a resource crosses backends (``rfw.graph.bridges``). Here that plan runs:

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
* **Timing.** Each bridge is its own entry in ``timings["passes"]``: ``cpu_ms`` is the wall
  time of the readback and the upload (``perf_counter``), ``gpu_ms`` is ``None`` (no
  timestamp brackets a host copy, and keeping it out leaves ``gpu_ms_total`` the sum of
  timestamped GPU work, comparable with single-backend runs); ``bridge_ms_total`` sums them.

wgpu-native exposes no Vulkan handles, so nothing is shared between the two devices: every
crossing costs a device-to-host and a host-to-device copy, and a flush on both sides.

``render_mixed`` is ``rfw.render.render`` for such configs (``render`` calls it when a pass
is pinned to a backend other than the run's); ``open_frame`` gives the ``MixedFrame`` itself.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from rfw.config import Built, Config, build
from rfw.frame import Result, camera_for, frame_record, load_scene_for, median
from rfw.graph import CompiledGraph, compile
from rfw.graph.bridges import backend_of, insert_bridges
from rfw.graph.formats import format_info
from rfw.graph.graph import Graph
from rfw.graph.resources import Binding, SizeRule
from rfw.shaders import ShaderError

from .commands import read_buffer, read_image, upload_buffer, upload_image
from .frame_stats import accel_stats, culling_counters

BACKENDS = ("wgpu", "vk")


@dataclass(frozen=True)
class Bridge:
    name: str  # bridge.<resource>.<src>-<dst>
    src: str  # backend that made the resource
    dst: str  # backend that reads the copy
    resource: str  # the original, on src
    copy: str  # <resource>@<dst>, on dst


@dataclass
class MixedPlan:
    """The full plan with bridges, and what each backend runs of it."""

    plan: CompiledGraph  # the full plan: order, bridges, every resource
    backend: str  # the run's backend (for unpinned passes)
    side: dict[str, str]  # pass -> backend (bridges: "src>dst")
    bridges: dict[str, Bridge]
    graphs: dict[str, Graph]  # backend -> its part of the bridged graph
    slots: dict[str, dict[str, str]]  # pass -> slot -> resource, consumers on the copies
    owner: dict[str, str]  # resource -> backend holding it

    @property
    def sides(self) -> tuple[str, ...]:
        used = {s for s in self.side.values() if ">" not in s}
        for b in self.bridges.values():
            used |= {b.src, b.dst}
        return tuple(s for s in BACKENDS if s in used)

    def passes_of(self, backend: str) -> tuple[str, ...]:
        """The full order's passes that ``backend`` records (its bridge halves included)."""
        return tuple(n for n in self.plan.order if self.side[n] == backend or (
            n in self.bridges and backend in (self.bridges[n].src, self.bridges[n].dst)))

    def check(self, backend: str, sub: CompiledGraph) -> None:
        """A backend's sub-plan schedules its passes in the full plan's order."""
        want = self.passes_of(backend)
        if tuple(sub.order) != want:
            raise ShaderError(f"the {backend} part of '{self.plan.name}' schedules "
                              f"{', '.join(sub.order)}; the mixed plan needs "
                              f"{', '.join(want)} in that order")


def split(built: Built, backend: str = "wgpu") -> MixedPlan:
    """Compile ``built`` for ``backend`` with bridges and cut it into per-backend graphs."""
    graph = built.graph
    plan = compile(graph, backend=backend)
    bridged = insert_bridges(graph, backend)
    scheduled = set(plan.order)
    decls = {p.name: p for p in bridged.passes if p.enabled and p.name in scheduled}
    side: dict[str, str] = {}
    bridges: dict[str, Bridge] = {}
    for name, p in decls.items():
        b = backend_of(p, backend) or backend
        side[name] = b
        if ">" in b:
            src, dst = b.split(">")
            bridges[name] = Bridge(name, src, dst, p.inputs[0].resource, p.outputs[0].resource)
        elif b not in BACKENDS:
            raise ShaderError(f"pass '{name}' is pinned to unknown backend '{b}'",
                              file=graph.source)
    owner: dict[str, str] = {}
    for r in plan.resources:
        if r.producer in side and ">" not in side[r.producer]:
            owner[r.name] = side[r.producer]
        elif r.producer in bridges:
            owner[r.name] = bridges[r.producer].dst
        else:
            owner[r.name] = backend
    for name, p in decls.items():
        for b in p.inputs:  # bridges carry this frame's values, not last frame's
            if b.spec.type == "history" and owner.get(b.resource, side[name]) != side[name]:
                raise ShaderError(f"pass '{name}' ({side[name]}) reads the history of "
                                  f"'{b.resource}', made on {owner[b.resource]}: bridges do "
                                  "not carry history; pin both passes to one backend",
                                  file=graph.source)
    graphs = {}
    for s in BACKENDS:
        passes = []
        for p in bridged.passes:
            if p.name not in decls:
                continue
            if p.name in bridges:
                br = bridges[p.name]
                if br.src == s:  # the read: keep it scheduled though nothing reads its result
                    passes.append(replace(p, outputs=(), side_effect=True, backend=None))
                elif br.dst == s:  # the write of the copy, sized as the full plan sized it
                    out = p.outputs[0]
                    r = plan.resource(out.resource)
                    if r.mips != 1 or r.layers != 1:
                        raise ShaderError(f"{p.name}: bridges copy one mip of one layer; "
                                          f"'{br.resource}' has {r.mips} mips, {r.layers} "
                                          "layers", file=graph.source)
                    spec = out.spec if out.spec.type == "buffer" else \
                        out.spec.with_(size=SizeRule.fixed(r.width, r.height))
                    if s == "wgpu" and r.kind != "buffer" and format_info(r.format).depth:
                        spec = _depth_for_wgpu(spec, r.format, br, _readers(decls, side,
                                                                            br), graph.source)
                    passes.append(replace(p, inputs=(), outputs=(replace(out, spec=spec),),
                                          backend=None))
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
    return MixedPlan(plan, backend, side, bridges, graphs, slots, owner)


# depth formats a bridge carries into wgpu as r32float (the host copy has the depth values)
_DEPTH_AS_FLOAT = ("depth32float", "depth16unorm")


def _readers(decls: dict[str, Any], side: dict[str, str], br: Bridge) -> list[tuple[str, Any]]:
    """(pass, slot spec) of every pass on the bridge's destination that reads its copy."""
    return [(name, b.spec) for name, p in decls.items() if side[name] == br.dst
            for b in p.inputs if b.resource == br.copy]


def _depth_for_wgpu(spec: Any, fmt: str, br: Bridge, readers: list[tuple[str, Any]],
                    source: str | None) -> Any:
    """WebGPU cannot write depth textures from the host (``write_texture`` and copies into
    them are refused), so a depth image crossing into wgpu arrives as r32float: the depth
    values themselves, for passes that sample depth as a texture (ssao accepts r32float).
    A reader that needs a real depth texture, or a stencil, cannot be served: one line."""
    why = "wgpu cannot write depth textures from the host"
    if fmt not in _DEPTH_AS_FLOAT:
        raise ShaderError(f"'{br.resource}' ({fmt}) is made on {br.src} and read on wgpu, but "
                          f"{why} and only {', '.join(_DEPTH_AS_FLOAT)} cross as r32float: pin "
                          f"its readers to {br.src}", element=f"bridge '{br.name}'", file=source)
    for name, slot in readers:
        if slot.type != "texture":
            raise ShaderError(f"reads '{br.resource}' ({fmt}, made on {br.src}) as a "
                              f"{slot.type} slot on wgpu, but {why} (a bridge carries it as "
                              f"r32float, for sampling only): pin '{name}' to {br.src}",
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


# ---------------------------------------------------------------------------------------------
# running it


@dataclass
class BridgeTiming:
    name: str
    cpu_ms: list[float] = field(default_factory=list)
    bytes: int = 0


class MixedFrame:
    """Drives one executor per backend through the full plan's order, bridges in between.

    ``executors`` maps "wgpu" / "vk" to an ``rfw.backends.wgpu_backend.Executor`` /
    ``vkext.executor.VkExecutor`` built on that backend's sub-plan."""

    def __init__(self, mixed: MixedPlan, executors: dict[str, Any]):
        self.mixed = mixed
        self.plan = mixed.plan
        self.executors = executors
        self.scenes: list[Any] = []  # GpuScene / VkScene the frame owns
        self.devices: dict[str, Any] = {}
        self.frame_index = 0
        self.bridge_timings = {n: BridgeTiming(n) for n in mixed.bridges}
        self.default_light = False

    def run(self, frames: int = 1) -> None:
        for _ in range(frames):
            self.frame()

    def frame(self) -> None:
        exs = self.executors
        for ex in exs.values():
            ex.begin_frame()
        for name in self.plan.order:
            br = self.mixed.bridges.get(name)
            if br is None:
                exs[self.mixed.side[name]].record(name)
                continue
            src, dst = exs[br.src], exs[br.dst]
            src.record(name)  # vk: the plan's barriers to transfer src
            dst.record(name)  # vk: ... and to transfer dst, aliasing included
            src.flush()
            dst.flush()  # uploads go ahead of unsubmitted work: submit it first
            t = time.perf_counter()
            data = self._read(br.src, src, name, br.resource)
            self._write(br.dst, dst, name, br.copy, data)
            timing = self.bridge_timings[name]
            timing.cpu_ms.append((time.perf_counter() - t) * 1e3)
            timing.bytes = int(data.nbytes)
        for ex in exs.values():
            ex.end_frame()
        self.frame_index += 1

    def clear_timings(self) -> None:
        for ex in self.executors.values():
            for t in ex.timings.values():
                t.gpu_ms.clear()
                t.cpu_ms.clear()
        for t in self.bridge_timings.values():
            t.cpu_ms.clear()

    @staticmethod
    def _read(backend: str, ex: Any, bridge: str, resource: str) -> np.ndarray:
        if backend == "wgpu":
            if ex.plan.resource(resource).kind == "buffer":
                raw = ex.device.device.queue.read_buffer(ex.buffer(resource))
                return np.frombuffer(raw, np.uint8)
            return ex.read(resource)
        state = ex.state_in(bridge, resource)  # the plan's transfer-src state at the bridge
        if resource in ex.buffers:
            return read_buffer(ex.device, ex.buffers[resource], state)
        return read_image(ex.device, ex.image(resource), layout_now=state, layout_after=state)

    @staticmethod
    def _write(backend: str, ex: Any, bridge: str, resource: str, data: np.ndarray) -> None:
        if backend == "wgpu":
            r = ex.plan.resource(resource)
            if r.kind == "buffer":
                ex.device.device.queue.write_buffer(ex.buffer(resource), 0,
                                                    np.ascontiguousarray(data).tobytes())
                return
            if r.format == "r32float" and data.dtype == np.uint16:  # depth16unorm's words
                data = data.astype(np.float32) / np.float32(65535)
            ex.upload(resource, data)
            return
        state = ex.state_in(bridge, resource)  # transfer dst: the consumer's barrier's from
        if resource in ex.buffers:
            upload_buffer(ex.device, ex.buffers[resource], data, dst=state)
        else:
            upload_image(ex.device, ex.image(resource), data, layout_after=state,
                         layout_before=state)

    def read(self, resource: str) -> np.ndarray:
        """An output (or any resource) from the backend that holds it."""
        return self.executors[self.mixed.owner[resource]].read(resource)

    def pass_timings(self) -> list[dict[str, Any]]:
        """timings.json's ``passes``: every pass of the full order, bridges included."""
        out = []
        for name in self.plan.order:
            side = self.mixed.side[name]
            if name in self.mixed.bridges:
                t = self.bridge_timings[name]
                out.append({"name": name, "gpu_ms": None, "cpu_ms": median(t.cpu_ms),
                            "backend": side, "bytes": t.bytes})
            else:
                t = self.executors[side].timings[name]
                out.append({"name": name, "gpu_ms": median(t.gpu_ms),
                            "cpu_ms": median(t.cpu_ms), "backend": side})
        return out

    def destroy(self) -> None:
        """Destroy the executors, then the scenes."""
        for ex in self.executors.values():
            ex.destroy()
        for sc in reversed(self.scenes):
            sc.destroy()
        self.scenes = []


def open_frame(built: Built, backend: str = "wgpu", *, wgpu_device: Any = None,
               vk_device: Any = None, scene: Any = None, camera: Any = None,
               size: tuple[int, int] | None = None, alias: bool = True) -> MixedFrame:
    """Split ``built`` (``split``), compile each backend's part (Vulkan's fitted to
    ``vk_device``'s memory requirements), upload ``scene`` to each backend used and make its
    executor. A backend with passes needs its device (``wgpu_device`` may be left out: one
    is made). The frame owns executors and scenes: ``destroy()`` them."""
    from rfw.backends.gpu_scene import GpuScene
    from rfw.backends.wgpu_backend import Device, Executor

    from .executor import VkExecutor, check_passes, fit_graph
    from .scene import VkScene

    mixed = split(built, backend)
    sides = mixed.sides
    if "vk" in sides and vk_device is None:
        raise ShaderError(f"'{mixed.plan.name}' runs passes on Vulkan: give a vk_device")
    plans: dict[str, tuple[CompiledGraph, dict[str, Any]]] = {}
    outputs = {s: tuple(o for o in mixed.plan.outputs if mixed.owner.get(o) == s)
               for s in sides}
    for s in sides:
        if s == "vk":
            plans[s] = fit_graph(mixed.graphs[s], vk_device, alias=alias,
                                 readback=bool(outputs[s]))
        else:
            plans[s] = (compile(mixed.graphs[s]), {})
        mixed.check(s, plans[s][0])
    instances = {s: {n: built.passes[n] for n in plans[s][0].order if n in built.passes}
                 for s in sides}
    if "vk" in sides:  # a missing GLSL twin fails before any upload
        check_passes(plans["vk"][0], instances["vk"])
    frame = MixedFrame(mixed, {})
    try:
        if "wgpu" in sides:
            wgpu_device = wgpu_device or Device()
            wscene = None
            if scene is not None:
                wscene = GpuScene(wgpu_device.device, scene, camera)
                frame.scenes.append(wscene)
                wscene.set_viewport(size or mixed.plan.size)
            frame.executors["wgpu"] = Executor(wgpu_device, plans["wgpu"][0],
                                               instances["wgpu"], mixed.slots, wscene,
                                               readback=outputs["wgpu"])
        if "vk" in sides:
            vscene = None
            if scene is not None:
                vscene = VkScene(vk_device, scene, camera)
                frame.scenes.append(vscene)
                vscene.set_viewport(size or mixed.plan.size)
            frame.executors["vk"] = VkExecutor(vk_device, plans["vk"][0], instances["vk"],
                                               mixed.slots, vscene, readback=outputs["vk"],
                                               alias=alias, memory_info=plans["vk"][1])
    except BaseException:
        frame.destroy()
        raise
    frame.devices = {"wgpu": wgpu_device, "vk": vk_device}
    frame.default_light = bool(frame.scenes and frame.scenes[0].default_light)
    return frame


def render_mixed(cfg: Config, *, scene: Any = None, frames: int | None = None,
                 warmup: int = 1, backend: str = "wgpu", wgpu_device: Any = None,
                 vk_device: Any = None, validation: bool = False,
                 alias: bool = True) -> Result:
    """Run ``cfg``, whose passes are pinned to more than one backend, as ``rfw.render.render``
    does: images of the graph outputs and timings.json's fields, one entry per pass of the
    full plan (bridges included, ``backend`` naming where each ran). ``backend`` is the
    backend of unpinned passes. Devices not given are made here (the Vulkan one with the
    validation layer when ``validation``) and destroyed; ``timings["validation"]`` counts
    the Vulkan side's messages; ``timings["memory"]`` is the Vulkan side's transients."""
    from .device import VkDevice

    built = build(cfg)
    on_vk = "vk" in split(built, backend).sides
    n = frames or cfg.frames
    own_vk = on_vk and vk_device is None
    if own_vk:
        vk_device = VkDevice(validation=validation)
    validation = on_vk and (validation or vk_device.validation)
    frame = None
    try:
        scene = load_scene_for(cfg, scene)
        frame = open_frame(built, backend, wgpu_device=wgpu_device, vk_device=vk_device,
                           scene=scene, camera=camera_for(cfg, scene), size=cfg.size,
                           alias=alias)
        frame.run(warmup)
        frame.clear_timings()
        frame.run(n)
        images = {name: frame.read(name) for name in frame.plan.outputs}
        memory = frame.executors["vk"].memory() if on_vk else None
        # before the scenes, which own the structures, go
        accel = accel_stats(frame.executors["vk"]) if on_vk else None
    finally:
        if frame is not None:
            frame.destroy()
        if own_vk:
            vk_device.destroy()  # leak reports arrive here, so count messages after it
    sides = frame.mixed.sides
    passes = frame.pass_timings()
    described = {s: frame.devices[s].describe() for s in sides}
    timings: dict[str, Any] = {
        **{k: " + ".join(dict.fromkeys(d[k] for d in described.values()))
           for k in ("device", "driver", "api")},
        "backend": "+".join(sides), "backends": described,
        **frame_record(cfg, n, scene, frame.default_light, passes,
                       timestamps=all(_timestamps(frame.devices[s]) for s in sides)),
        "bridge_ms_total": sum(p["cpu_ms"] or 0.0 for p in passes
                               if p["name"] in frame.mixed.bridges),
        "bridges": [p["name"] for p in passes if p["name"] in frame.mixed.bridges]}
    if memory is not None:
        timings["memory"] = memory
    # the vk side's counters, as a vk-only run reports them
    culling = culling_counters(frame.executors["vk"]) if on_vk else None
    if culling is not None:
        timings["culling"] = culling
    if accel is not None:
        timings["accel"] = accel
    if validation:
        timings["validation"] = {"messages": len(vk_device.messages),
                                 "texts": [m.text for m in vk_device.messages[:20]]}
    return Result(cfg, images, timings, frame)


def _timestamps(device: Any) -> bool:
    # wgpu's Device.caps names WebGPU features, VkDevice.caps vkext's capabilities
    return bool({"timestamp-query", "timestamp"} & set(device.caps))
