"""Run a compiled frame graph on raw Vulkan, as ``rfw.backends.wgpu.executor`` runs it on wgpu.

Transient images and buffers live in the plan's aliased heaps (``plan_heaps``); persistent,
external and history ones come from a :class:`BlockAllocator`. A frame is one command buffer:
per pass a debug label, the plan's barriers for that pass (the only synchronization between
passes: nothing a pass records waits on anything), a timestamp before and after, and the
pass's unchanged ``record(ctx)``. Passes run the same GLSL as on wgpu (the files
``rfw.shaders.program_files`` names); layouts are reflected from SPIR-V, and image
descriptors are written in the layout the plan puts the image in for the pass.

The pass runtime, module by module: :mod:`vkext.fitting` compiles the graph for the device
and finds each pass's shader files; :mod:`vkext.programs` is the one program and pipeline
cache (compute, render, mesh, ray tracing); :mod:`vkext.bundles` keeps a pass's own
descriptor sets and its scene draws (secondary command buffers) from frame to frame, so a frame
records no Python per draw; :mod:`vkext.descriptors` holds a frame's descriptor sets and
uniforms where those caches are off (``RFW_VK_BUNDLES=0``); :mod:`vkext.context` is what a pass
records through; this module owns the resources and records the frames.

A frame that would record what its slot's command buffer already holds (every pass replays,
in order, the bundle it executed when that buffer was recorded, over the same resources)
records nothing: the buffer is submitted again. A pass that records anything else makes the
frame record its buffer there and then (``catch_up``); ``RFW_VK_FRAME_REPLAY=0`` records
every frame (the benchmarks' baseline).

The frame protocol, the ring of frames in flight, timings, history and teardown are
:class:`rfw.exec.core.ExecutorCore`'s; the ~730 lines here are Vulkan's primitives under it
(memory in the plan's heaps, initial layouts, barriers, timestamps, whole-frame replay).
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from rfw.exec.core import ExecutorCore
from rfw.graph import CompiledGraph
from rfw.graph.sync import State
from rfw.options import RunOptions, check_options
from rfw.passes import Pass
from rfw.shaders import ShaderError
from rfw.units import MiB

from . import poison
from .bundles import BundleCache, SetCache
from .commands import (
    FENCE_TIMEOUT_NS,
    GLOBAL,
    CommandPool,
    ImageBarrier,
    TimestampPool,
    access_flags,
    as_state,
    barrier,
    begin_label,
    end_label,
    image_layout,
    label,
    one_time,
    read_buffer,
    read_image,
    record_barriers,
    stage_flags,
    submit,
    upload_image,
)
from .consts import ffi, lib, vk
from .context import VkPassContext
from .descriptors import FrameDescriptors, UniformRing
from .device import VkDevice
from .fitting import check_passes, shader_paths
from .memory import BlockAllocator, Buffer, Image, ImageView, image_view, plan_heaps
from .objects import Sampler, make_sampler
from .programs import Programs
from .queues import async_queues
from .scene import VkScene

TIMESTAMP_STAGE = "ALL_COMMANDS"

# with frames in flight a frame opens with this barrier: everything submitted before it
# (the last frame, still on the GPU) is done and its writes are visible
FRAME_BEFORE = State(None, frozenset({"ALL_COMMANDS"}), frozenset({"MEMORY_WRITE"}))
FRAME_AFTER = State(None, frozenset({"ALL_COMMANDS"}), frozenset({"MEMORY_READ", "MEMORY_WRITE"}))


def _memory_dependency(src: State, dst: State) -> tuple[Any, Any]:
    """One global memory barrier as a ``VkDependencyInfo`` made once (with the array it
    points into, which must live as long): the same every frame."""
    arr = ffi.new("VkMemoryBarrier2[1]")
    m = arr[0]
    m.sType = vk.VK_STRUCTURE_TYPE_MEMORY_BARRIER_2
    m.srcStageMask, m.srcAccessMask = stage_flags(src.stages), access_flags(src.access)
    m.dstStageMask, m.dstAccessMask = stage_flags(dst.stages), access_flags(dst.access)
    dep = ffi.new("VkDependencyInfo*")
    dep.sType = vk.VK_STRUCTURE_TYPE_DEPENDENCY_INFO
    dep.memoryBarrierCount, dep.pMemoryBarriers = 1, arr
    return dep, arr


def _check(result: int) -> None:
    # the frame loop calls the C entry points (no wrapper converting arguments per call):
    # a failure raises what the wrapper would
    if result != 0:  # VK_SUCCESS
        from vulkan._vulkan import exception_codes

        raise exception_codes[result]


def vk_wait(*args: Any) -> int:
    """``vkWaitForFences`` (C): a frame's wait for its slot; benchmarks time it apart."""
    return lib.vkWaitForFences(*args)


def vk_query(*args: Any) -> int:
    """``vkGetQueryPoolResults`` (C), waiting: benchmarks time it apart."""
    return lib.vkGetQueryPoolResults(*args)


@dataclass(eq=False)
class FrameSlot:
    """What one frame in flight owns until it is finished: its command buffer (and pool),
    timestamp queries, per-frame descriptor sets and uniforms, and its submit's fence."""

    pool: CommandPool
    cmd: Any
    timestamps: TimestampPool | None
    descriptors: FrameDescriptors
    ring: UniformRing
    fence: Any = None  # the last submit's, until a wait resets (or destroys) it
    # made once per slot, not per frame: the slot's own fence (reset after each wait), the
    # submit of its command buffer and the memory its timestamps are read into
    own_fence: Any = None
    fences: Any = None  # VkFence[1] holding own_fence, for the C calls that take an array
    submit_info: Any = None
    ts_data: Any = None
    keep: list = field(default_factory=list)  # the ffi structs submit_info points into
    # what the command buffer holds, for a frame that would record the same (whole-frame
    # replay): the frame's resources and each pass's (name, bundle); None: not reusable
    holds: tuple | None = None
    # the scene's cameras as this slot's frame began (host-visible, copied into the scene's
    # camera buffer at the frame's start: VkScene.copy_camera), and the bytes it holds
    camera: Buffer | None = None
    camera_data: bytes | None = None
    # the same for the instance rows animations move (VkScene.copy_pose); None: none move
    pose: Buffer | None = None
    pose_data: bytes | None = None

    def destroy(self, device: VkDevice) -> None:
        if device.alive:
            for f in dict.fromkeys(f for f in (self.fence, self.own_fence) if f is not None):
                vk.vkDestroyFence(device.device, f, None)
        self.fence = self.own_fence = self.submit_info = None
        self.keep.clear()
        for obj in (self.descriptors, self.timestamps, self.pool, self.camera, self.pose):
            if obj is not None:
                obj.destroy()


def _copy_frame(scene: Any, cmd: Any, slot: FrameSlot) -> None:
    """Record the copies of a frame's own bytes (its slot's) into what the passes bind: the
    cameras (``VkScene.copy_camera``) and the instance rows animations move
    (``copy_pose``)."""
    scene.copy_camera(cmd, slot.camera)
    if slot.pose is not None:
        scene.copy_pose(cmd, slot.pose)


def _chained(b: Any) -> Any:
    # a barrier that waits for nothing (a transient's first use, from UNDEFINED) waits for
    # its own stages instead: its layout change then chains after the frame's first barrier
    if b.src.stages or not b.dst.stages:
        return b
    return replace(b, src=State(b.src.layout, b.dst.stages, frozenset()))


def _runs(slots: list[int]) -> list[tuple[int, int]]:
    """Sorted slot numbers as (first, count) runs of consecutive ones."""
    out: list[tuple[int, int]] = []
    for k in slots:
        if out and out[-1][0] + out[-1][1] == k:
            out[-1] = (out[-1][0], out[-1][1] + 1)
        else:
            out.append((k, 1))
    return out


class VkExecutor(ExecutorCore):
    """Owns the images and buffers of one compiled graph on one device and records frames."""

    def __init__(self, device: VkDevice, plan: CompiledGraph, passes: dict[str, Pass],
                 slots: dict[str, dict[str, str]], scene: VkScene | None = None,
                 readback: tuple[str, ...] = (), *, alias: bool = True,
                 memory_info: dict[str, Any] | None = None,
                 options: RunOptions | None = None):
        options = check_options(options)
        plan, self.poison = poison.prepare(plan, options)  # fuzzing: poisoned transients
        self.device = device
        self._init_core(plan, passes, slots, scene, readback, options)
        self.alias = alias
        self.memory_info = dict(memory_info or {})
        self._position = {name: k for k, name in enumerate(plan.order)}
        self._accels = {r.name: GLOBAL for r in plan.resources if r.kind == "accel"}
        check_passes(plan, passes)
        self._states: dict[tuple[str, str], State] = {}
        self._final: dict[str, State] = {}
        self._start: dict[str, str] = {}
        self._barriers: dict[str, list] = defaultdict(list)
        for b in plan.barriers:
            self._barriers[b.pass_name].append(b)
        for p in plan.order:
            for a in plan.accesses[p]:
                if a.state is None:
                    continue
                self._states[(p, a.resource)] = a.state
                self._final[a.resource] = a.state
                if a.resource not in self._start:
                    first = next((b for b in self._barriers[p] if b.resource == a.resource),
                                 None)
                    self._start[a.resource] = (first.src if first else a.state).layout or \
                        "UNDEFINED"
        self._views: dict[tuple[int, bool, int | None], ImageView] = {}
        self._paths: dict[tuple[str, str | None], list[Path]] = {}
        # VkRenderingInfo per pass, targets and clears (vkext.context builds them)
        self.rendering_infos: dict[tuple, tuple[Any, list[Any]]] = {}
        self._ts_stage = stage_flags(TIMESTAMP_STAGE)
        # acceleration structures by plan resource, published by the passes that build them
        self.accels: dict[str, Any] = {}
        self.transients = None
        # graph outputs the frames copy into exported memory (vkext.external.export_outputs)
        self.frame_exports: Any = None
        self.allocator: BlockAllocator | None = None
        self.programs = self.descriptors = self.ring = None
        self.bundles: BundleCache | None = None
        self.sets: SetCache | None = None
        self.pool: CommandPool | None = None
        self.timestamps: TimestampPool | None = None
        # llvmpipe resolves a timestamp when its binned scene is flushed, i.e. at the next
        # timestamp write: one scratch write per pass pins the begin before the pass's work
        # (without it compute passes read ~0 ms)
        self._pin_begin = "timestamp" in device.caps and device.driver_name == "llvmpipe"
        self._host_reset = "host_query_reset" in device.caps
        # whole-frame replay: a frame that would record what its slot's command buffer holds
        # submits it again (so it is not one-time-submit); frame_replay=False records
        # every frame, the baseline a benchmark measures against in the same run
        self.frame_replay = options.frame_replay
        self.primaries = 0  # primary command buffers begun (what tests count)
        self._begin_info = ffi.new("VkCommandBufferBeginInfo*", {
            "sType": vk.VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO,
            "flags": 0 if self.frame_replay else vk.VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT})
        self._query_flags = vk.VK_QUERY_RESULT_64_BIT | vk.VK_QUERY_RESULT_WAIT_BIT
        self._frame_start = _memory_dependency(FRAME_BEFORE, FRAME_AFTER)
        self._inputs: tuple | None = None  # what the last frame recorded from (see begin_frame)
        self._frame_barriers = {p: [_chained(b) for b in bs] for p, bs in self._barriers.items()}
        # async compute: the plan's submissions on two queues (vkext.queues); None: one
        self.queues = async_queues(device, plan, (self._barriers, self._frame_barriers),
                                   span=options.frame_span)
        if self.queues is not None and scene is not None:  # the cameras' copy: its own batch
            self.queues.prologue = lambda cmd, slot: _copy_frame(scene, cmd, slot)
        try:
            self._allocate()
            self.programs = Programs(device, scene)
            self.keep_in_flight(options.in_flight())
            # descriptor sets written once and scene draws recorded once, then replayed
            # (vkext.bundles); RunOptions(bundles=False) (RFW_VK_BUNDLES=0) writes and
            # records them every frame: the baseline a benchmark measures against
            if options.bundles:
                self.sets = SetCache(device, self.allocator)
                self.bundles = BundleCache(device)
            self._setup_passes(frozenset(device.caps))
        except BaseException:
            self.destroy()
            raise

    # setup --------------------------------------------------------------------------------
    def _allocate(self) -> None:
        dev, plan = self.device, self.plan
        self.transients = plan_heaps(plan, dev, no_alias=not self.alias,
                                     readback=bool(self.readback))
        self.images: dict[str, Image] = dict(self.transients.images)
        self.buffers: dict[str, Buffer] = dict(self.transients.buffers)
        self.allocator = BlockAllocator(dev, block_size=8 * MiB, label="rfw:persistent")
        persistent = []
        for r in plan.resources:
            if r.transient:
                continue
            if r.kind == "image":
                if not r.format:
                    continue  # an undescribed external image: the application binds its own
                usages = set(r.usages) | {"transfer_dst"} | \
                    ({"transfer_src"} if self.readback else set())
                self.images[r.name] = self.allocator.create_image(
                    r.width, r.height, r.format, usages, mips=r.mips, layers=r.layers,
                    samples=r.samples, label=r.name)
                persistent.append(r.name)
            elif r.raw_bytes > 0:
                usages = (set(r.usages) & {"storage", "uniform", "indirect", "vertex", "index"}
                          or {"storage"}) | {"transfer_src", "transfer_dst"}
                self.buffers[r.name] = self.allocator.create_buffer(r.raw_bytes, usages,
                                                                    label=r.name)
        self._initial_states(persistent)

    def _initial_states(self, names: list[str]) -> None:
        """Persistent images enter the first frame in the layout the plan's steady state
        leaves them in (the ``from`` of their first barrier), cleared to zero like wgpu's."""
        todo = [n for n in names if self._start.get(n, "UNDEFINED") != "UNDEFINED"]
        if not todo:
            return
        dst = State("TRANSFER_DST_OPTIMAL", frozenset({"CLEAR"}), frozenset({"TRANSFER_WRITE"}))
        with one_time(self.device, label="rfw:initial states") as cmd:
            barrier(cmd, [ImageBarrier(self.images[n], "UNDEFINED", dst) for n in todo])
            for n in todo:
                img = self.images[n]
                rng = ffi.new("VkImageSubresourceRange*")
                rng.aspectMask, rng.levelCount, rng.layerCount = img.aspect, img.mips, img.layers
                if img.info.depth or img.info.stencil:
                    value = ffi.new("VkClearDepthStencilValue*")
                    lib.vkCmdClearDepthStencilImage(cmd, img.handle, image_layout(dst.layout),
                                                    value, 1, rng)
                else:
                    value = ffi.new("VkClearColorValue*")
                    lib.vkCmdClearColorImage(cmd, img.handle, image_layout(dst.layout), value,
                                             1, rng)
            barrier(cmd, [ImageBarrier(self.images[n], dst, as_state(self._start[n],
                                                                      source=False))
                          for n in todo])

    # resources ----------------------------------------------------------------------------
    def image(self, resource: str) -> Image:
        try:
            return self.images[resource]
        except KeyError:
            raise ShaderError(f"'{resource}' is not an image of the plan") from None

    def buffer(self, resource: str) -> Buffer:
        try:
            return self.buffers[resource]
        except KeyError:
            raise ShaderError(f"'{resource}' is not a buffer of the plan") from None

    def view(self, resource: str, *, sampled: bool = False, mip: int | None = None) -> ImageView:
        """The image's view; ``sampled`` views of depth(-stencil) images see depth only;
        ``mip``: a view of that one mip level (per-level storage views of a mip chain)."""
        img = self.image(resource)
        depth = sampled and bool(img.info.depth)
        key = (id(img), depth, mip)
        v = self._views.get(key)
        if v is None or v.handle is None:
            name = ("depth" if depth else "view") + ("" if mip is None else f":mip{mip}")
            v = self._views[key] = image_view(img, aspect="depth" if depth else None,
                                              mips=None if mip is None else (mip, 1),
                                              label=f"{resource}:{name}")
        return v

    @property
    def resources(self) -> dict[str, Any]:
        """Images and buffers by plan name; acceleration structures map to ``GLOBAL``
        (their barriers are memory barriers)."""
        return {**self.images, **self.buffers, **self._accels}

    def state_in(self, pass_name: str, resource: str) -> State | None:
        """The state the plan puts ``resource`` in for ``pass_name``."""
        return self._states.get((pass_name, resource))

    def _make_buffer(self, label: str, data: np.ndarray, usage: tuple[str, ...]) -> Buffer:
        """A host-visible buffer holding ``data`` (a pass's setup tables), freed with the
        persistent allocator."""
        buf = self.allocator.create_buffer(data.nbytes, usage, host_visible=True, label=label)
        buf.write(data)
        return buf

    def _make_sampler(self, filter: str, address: str, compare: str | None) -> Sampler:
        return make_sampler(
            self.device, mag=filter, min=filter, mip=filter, address_u=address,
            address_v=address, address_w=address, compare=compare,
            label=f"rfw:sampler:{filter}:{address}" + (f":{compare}" if compare else ""))

    def shader_paths(self, pass_: Pass, shader: str | None = None) -> list[Path]:
        """``vkext.fitting.shader_paths``, looked up once per pass and shader: a bare name
        scans the pass folder for every stage, too slow for each frame (edits to the files
        still recompile: ``Programs.get`` checks their times)."""
        key = (pass_.name, shader)
        paths = self._paths.get(key)
        if paths is None:
            paths = self._paths[key] = shader_paths(pass_, shader)
        return paths

    def memory(self) -> dict[str, Any]:
        """Transient bytes allocated against the plan's numbers."""
        tm = self.transients
        out = {"transient_allocated_bytes": tm.allocated_bytes if tm else 0,
               "plan_transient_bytes": self.plan.transient_bytes,
               "unaliased_bytes": self.plan.unaliased_bytes, "alias": self.alias,
               "allocations": len(tm.memories) if tm else 0}
        out.update({k: v for k, v in self.memory_info.items() if k != "alias"})
        return out

    # frames -------------------------------------------------------------------------------
    def _make_slot(self, k: int) -> FrameSlot:
        dev = self.device
        pool = CommandPool(dev, transient=False, label=f"rfw:frames{k}")
        slot = FrameSlot(pool, pool.allocate(1)[0], None, FrameDescriptors(dev),
                         UniformRing(self.allocator,
                                     int(dev.limits["minUniformBufferOffsetAlignment"])))
        if "timestamp" in dev.caps:
            n = len(self.plan.order)
            slot.timestamps = TimestampPool(dev, max(2, (3 if self._pin_begin else 2) * n),
                                            label=f"rfw:timestamps{k}")
            slot.ts_data = ffi.new("uint64_t[]", slot.timestamps.count)
        slot.own_fence = vk.vkCreateFence(dev.device, vk.VkFenceCreateInfo(), None)
        slot.fences = ffi.new("VkFence[1]", [slot.own_fence])
        cmds = ffi.new("VkCommandBufferSubmitInfo[1]")
        cmds[0].sType = vk.VK_STRUCTURE_TYPE_COMMAND_BUFFER_SUBMIT_INFO
        cmds[0].commandBuffer = slot.cmd
        info = ffi.new("VkSubmitInfo2*")
        info.sType = vk.VK_STRUCTURE_TYPE_SUBMIT_INFO_2
        info.commandBufferInfoCount, info.pCommandBufferInfos = 1, cmds
        slot.submit_info, slot.keep = info, [cmds]
        if self.scene is not None:
            slot.camera = self.allocator.create_buffer(
                self.scene.camera_span, ("transfer_src",), host_visible=True,
                label=f"rfw:camera{k}")
            if getattr(self.scene, "pose_span", 0):  # animations move instances
                slot.pose = self.allocator.create_buffer(
                    self.scene.pose_span, ("transfer_src",), host_visible=True,
                    label=f"rfw:pose{k}")
        return slot

    # a frame driven pass by pass (mixed-backend frames: rfw.frame) -----------------------
    def _before_frame(self) -> None:
        """A frame's descriptors and uniforms live until its slot comes round again.

        A frame records while earlier ones run, so what it writes from the host must not
        be what they read: settings (a pass's ``params``) and the scene it draws are host
        writes (uniform values, bundles recorded again), so a frame that finds any of them
        changed first drains the frames in flight. The scene's camera is not one of them:
        the frame writes the cameras it begins with (``VkScene.set_viewport``'s bytes) into
        its slot's own buffer, and its command buffer first copies them into the buffer the
        camera sets bind (``VkScene.copy_camera``; async compute: a batch of its own ahead
        of the frame's, ``vkext.queues``), so frames in flight keep theirs."""
        inputs = (self.scene, *(getattr(p, "params", None) for p in self.passes.values()))
        last, self._inputs = self._inputs, inputs  # objects kept: their ids stay theirs
        if last is not None and (len(last) != len(inputs) or
                                 any(a is not b for a, b in zip(last, inputs, strict=False))):
            self.drain()

    def _open(self, slot: FrameSlot) -> None:
        if slot.camera is not None and slot.camera_data != self.scene.camera_blob:
            # its last frame is finished (slot() waited for it): no copy reads these bytes
            slot.camera_data = self.scene.camera_blob
            slot.camera.write(np.frombuffer(slot.camera_data, np.uint8))
        if slot.pose is not None and slot.pose_data != self.scene.pose_blob:
            slot.pose_data = self.scene.pose_blob  # its last frame is finished, as above
            slot.pose.write(np.frombuffer(slot.pose_data, np.uint8))
        self.pool, self.cmd, self.timestamps = slot.pool, slot.cmd, slot.timestamps
        self.descriptors, self.ring = slot.descriptors, slot.ring
        dev, ts = self.device, self.timestamps
        # the resource map the frame's barriers use, made once per frame (after the swap)
        self._frame_resources = self.resources
        self.descriptors.reset()
        self.ring.reset()
        if ts is not None and self._host_reset:
            lib.vkResetQueryPool(dev.device, ts.handle, 0, ts.count)
        self._recording = False
        # replayed while every pass replays what the slot's command buffer holds, in order
        held = slot.holds if self.frame_replay and self.queues is None and \
            self.poison is None else None
        self._replaying = held is not None and len(held[0]) == len(self._frame_resources) \
            and all(a is b for a, b in zip(held[0], self._frame_resources.values(),
                                           strict=True))
        self._done: list[tuple[str, Any]] = []  # (pass, bundle) replayed so far
        self._split = False  # flushed mid-frame: not one submit, not kept for replay
        if not self._replaying:
            self._reset_primary()
        self._pending: list[int] = []  # timestamp slots written since the last flush

    def _swap(self, a: str, b: str) -> None:
        if a in self.images and b in self.images:
            self.images[a], self.images[b] = self.images[b], self.images[a]

    def _reset_primary(self) -> None:
        slot = self._frame_slot
        slot.holds = None
        _check(lib.vkResetCommandPool(self.device.device, slot.pool.handle, 0))

    def replays(self, bundle: Any) -> bool:
        """Whether the pass being recorded in a replayed frame executes the bundle the
        slot's command buffer executes there (then nothing is recorded for it)."""
        if not self._replaying:
            return False
        held, i = self._frame_slot.holds[1], len(self._done)
        return i < len(held) and held[i][0] == self._name and held[i][1] is bundle

    def catch_up(self) -> Any:
        """Leave whole-frame replay: record the frame so far into the slot's command
        buffer (its passes' barriers, timestamps and bundles; the current pass's barriers
        and begin timestamp) and return it."""
        self._replaying = False
        self._reset_primary()
        self._begin()
        for name, bundle in self._done:
            with label(self.device, self.cmd, name):
                k = self._prefix(name)
                lib.vkCmdExecuteCommands(self.cmd, 1, bundle.handles)
                self._suffix(k)
        if self._name is not None:  # the pass being recorded: its label ends after it
            begin_label(self.device, self.cmd, self._name)
            self._prefix(self._name)
        return self.cmd

    def _begin(self) -> None:
        dev, cmd, ts = self.device, self.cmd, self.timestamps
        _check(lib.vkBeginCommandBuffer(cmd, self._begin_info))
        self.primaries += 1
        self._recording = True
        if ts is not None and "host_query_reset" not in dev.caps:
            ts.reset(cmd)
        if len(self.in_flight) > 1:  # the last frame may still run: wait for it here
            lib.vkCmdPipelineBarrier2(cmd, self._frame_start[0])
        if self._frame_slot.camera is not None:  # the frame's own cameras, before any pass
            _copy_frame(self.scene, cmd, self._frame_slot)

    def _prefix(self, name: str) -> int:
        # a pass's barriers and begin timestamp; its position
        cmd, ts, k = self.cmd, self.timestamps, self._position[name]
        # (async compute: vkext.queues.async_queues put them as the pass's queue records them)
        barriers = (self._frame_barriers if len(self.in_flight) > 1 else self._barriers)[name]
        if self.poison is not None:  # fill what starts its lifetime here first
            barriers = self.poison.fill(cmd, name, barriers, self._frame_resources)
        record_barriers(cmd, barriers, self._frame_resources)
        if ts is not None and self.passes.get(name) is not None:
            self._timestamp(cmd, 2 * k)
            if self._pin_begin:
                self._timestamp(cmd, 2 * len(self.plan.order) + k)
        return k

    def _suffix(self, k: int) -> None:
        if self.timestamps is not None:
            self._timestamp(self.cmd, 2 * k + 1)

    def _enter(self, name: str, *, bridge: bool) -> None:
        # the command buffer pass ``name`` records into: its batch's (async compute), the
        # frame's (begun on first use), or none while the frame is replayed whole
        if self.queues is not None:
            self.cmd = self.queues.command_buffer(name, self._frame_slot, self._frame_resources)
            self._recording = True
        self._name = None
        if self._replaying and bridge:  # a bridge's side: recorded from here on
            self.catch_up()
        if not self._replaying and not self._recording:
            self._begin()
        self._name = name

    def _bridge(self, name: str) -> None:
        """A bridge's side on this device records its barriers only: the copy itself goes
        through the host (``rfw.frame``), between flushes."""
        try:
            self._enter(name, bridge=True)
            with label(self.device, self.cmd, name):
                self._prefix(name)
                self._done.append((name, None))
        except BaseException:
            self._abandon()
            raise
        finally:
            self._name = None

    def _context(self, name: str, p: Pass) -> VkPassContext:
        """Pass ``name``'s context, after its debug label, the plan's barriers for it and
        its begin timestamp. In a frame replayed whole it has no command buffer: it gets
        one (``catch_up``) once it records anything but the bundle the slot's command
        buffer executes here."""
        self._enter(name, bridge=False)
        self._pass_replaying = self._replaying
        if self._replaying:
            return VkPassContext(self, p, None, self.slots[name])
        begin_label(self.device, self.cmd, name)
        self._prefix(name)
        return VkPassContext(self, p, self.cmd, self.slots[name])

    def _recorded_pass(self, name: str, ctx: VkPassContext) -> None:
        # the end timestamp and label; what the slot's command buffer now executes here
        try:
            if self.timestamps is not None:
                self._pending.append(self._position[name])
            if self._pass_replaying and self._replaying:
                if ctx.executed is None:  # it recorded nothing: nor did it then
                    self.catch_up()
                else:
                    self._done.append((name, ctx.executed))
                    return
            self._suffix(self._position[name])
            end_label(self.device, self.cmd)
            self._done.append((name, ctx.executed) if not ctx.direct else (name, None))
        finally:
            self._name = None

    def _abandon(self) -> None:
        self._recording = self._replaying = False
        self._name = None
        if self._frame_slot is not None:
            self._frame_slot.holds = None
        if self.pool is not None:
            self.pool.reset()  # drop the half-recorded commands

    def _timestamp(self, cmd: Any, index: int) -> None:
        # TimestampPool.write without its checks: the executor numbers its own queries
        lib.vkCmdWriteTimestamp2(cmd, self._ts_stage, self.timestamps.handle, index)

    def _submit(self, slot: FrameSlot, *, last: bool) -> Any:
        """Submit what was recorded (``_send_frame``) and return how to finish it: wait for
        its fence, then read its timestamps. A flush (not ``last``) that submits splits the
        frame (no longer one submit kept for replay); the frame's last submit records what
        the slot's command buffer now holds, for a frame to replay."""
        fence = self._send_frame(last=last)
        if last and fence is not None and self.frame_exports is not None:
            self.frame_exports.submitted(slot)  # the frame copied its device outputs
        if not last:
            if fence is None:
                return None
            self._split = True
            pending, self._pending = self._pending, []
            return lambda append: self._finish(slot, fence, pending, append)
        slot.fence = fence
        if self._keep:
            slot.holds = (tuple(self._frame_resources.values()), tuple(self._done))
        pending, self._pending = self._pending, []
        return lambda append: self._finish(slot, None, pending, append)

    def _send_frame(self, *, last: bool) -> Any:
        """End the command buffer and submit it: its fence, or None if nothing was recorded
        (``last``: the frame's last submit, which copies the device outputs).
        A replayed frame submits the slot's command buffer as it is (or records the rest
        of it first, if the frame had fewer passes)."""
        slot = self._frame_slot
        self._keep = False
        if self._replaying:
            self._replaying = False
            if len(self._done) == len(slot.holds[1]):
                return self._send(slot)
            self.catch_up()
        if not self._recording:
            return None
        self._recording = False
        try:
            if last and self.frame_exports is not None:  # outputs to exported memory
                self.frame_exports.record(self.cmd, slot)
            _check(lib.vkEndCommandBuffer(self.cmd))
        except BaseException:
            self.pool.reset()
            raise
        self._keep = self.frame_replay and self.queues is None and self.poison is None \
            and not self._split and self.cmd is slot.cmd and \
            all(b is not None for _, b in self._done)
        if self.queues is not None:  # async compute: every batch, with its semaphores
            return self.queues.submit(self.cmd)
        if slot.own_fence is None or self.cmd is not slot.cmd:
            return submit(self.device, [self.cmd], wait=False)
        return self._send(slot)

    def _send(self, slot: FrameSlot) -> Any:
        # the slot's submit info and fence, made once (the fence is unsignalled: reset
        # after its last wait)
        try:
            _check(lib.vkQueueSubmit2(self.device.queue, 1, slot.submit_info, slot.own_fence))
        except BaseException:
            vk.vkDeviceWaitIdle(self.device.device)
            raise
        return slot.own_fence

    def _wait(self, fence: Any) -> None:
        dev = self.device.device
        slot = next((s for s in self.in_flight.slots if fence is s.own_fence), None)
        if slot is not None:  # the slot's own fence: waited for, then reset for its next submit
            try:
                _check(vk_wait(dev, 1, slot.fences, vk.VK_TRUE, FENCE_TIMEOUT_NS))
            finally:
                _check(lib.vkResetFences(dev, 1, slot.fences))
            return
        try:
            vk.vkWaitForFences(dev, 1, [fence], vk.VK_TRUE, FENCE_TIMEOUT_NS)
        finally:
            vk.vkDestroyFence(dev, fence, None)

    def _finish(self, slot: FrameSlot, fence: Any, pending: list[int], append: Any) -> None:
        """Wait for a submit (``fence``; None: the slot's frame), then hand its GPU ms per
        pass to ``append`` (None without timestamps)."""
        if fence is None:
            fence, slot.fence = slot.fence, None
        if fence is not None:
            self._wait(fence)
        gpu: dict[str, float] = {}
        self._collect(slot, pending, gpu)
        append(gpu if slot.timestamps is not None else None)

    def _collect(self, slot: FrameSlot, pending: list[int], gpu: dict[str, float]) -> None:
        # a finished submit's timestamps, per pass, added to the frame's GPU ms: one query
        # read per run of passes into the slot's own memory (TimestampPool.results' values)
        ts = slot.timestamps
        if ts is None or not pending:
            return
        order, data, dev = self.plan.order, slot.ts_data, self.device
        mask, period = ts.mask, dev.timestamp_period
        for first, count in _runs(sorted(pending)):
            _check(vk_query(dev.device, ts.handle, 2 * first, 2 * count, 16 * count, data, 8,
                            self._query_flags))
            for i in range(count):
                name = order[first + i]
                begin = round((data[2 * i] & mask) * period)
                ms = max(0, round((data[2 * i + 1] & mask) * period) - begin) * 1e-6
                gpu[name] = gpu.get(name, 0.0) + ms

    def upload(self, resource: str, array: np.ndarray) -> None:
        """Fill an external image from an (H, W, C) array of its texel type; it stays in the
        layout the plan expects at the start of a frame."""
        self.drain()  # a frame in flight may read it
        start = self._start.get(resource, "UNDEFINED")
        after = start if start != "UNDEFINED" else "SHADER_READ_ONLY_OPTIMAL"
        upload_image(self.device, self.image(resource), array, layout_after=after,
                     layout_before=start)

    def read(self, resource: str) -> np.ndarray:
        """Read an image back as (H, W, C) in its own texel type (buffers as bytes), left in
        the state the frame leaves it in, once every frame in flight is done."""
        self.drain()
        state = self._final.get(resource)
        if resource in self.buffers:
            return read_buffer(self.device, self.buffers[resource], state)
        img = self.image(resource)
        now = state or "UNDEFINED"
        return read_image(self.device, img, layout_now=now,
                          layout_after=state if state is not None else None)

    # teardown (ExecutorCore.destroy calls these) -----------------------------------------
    def _can_drain(self) -> bool:
        return self.device.alive

    def _idle(self) -> None:
        if self.device.alive:
            self.device.wait_idle()

    def _destroy_slot(self, slot: FrameSlot) -> None:
        slot.destroy(self.device)

    def _release(self) -> None:
        if self.frame_exports is not None:
            self.frame_exports.destroy()
            self.frame_exports = None
        for obj in (self.bundles, self.sets, self.programs, getattr(self, "queues", None),
                    self.transients, self.allocator):
            if obj is not None:
                obj.destroy()
        for smp in self._samplers:
            smp.destroy()
        for v in self._views.values():
            v.destroy()
        self._views.clear()
        self.programs = self.descriptors = self.timestamps = self.pool = None
        self.bundles = self.sets = None
        self.transients = self.allocator = None
        self.ring = None
