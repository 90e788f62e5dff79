"""Async compute on Vulkan: the compiled plan's submissions (``rfw.graph.queues``) run on the
device's graphics queue and its second queue, with a timeline semaphore per queue.

The executor asks :meth:`AsyncQueues.command_buffer` for the command buffer of each pass's
submission and hands the last one back through :meth:`AsyncQueues.submit`; everything else is
here. Submission ``k`` of a queue signals ``base + k`` on that queue's semaphore, where
``base`` is the queue's submission count times the frames submitted before; waits name the
other queue's values the same way. Batches go to the queues in the plan's order, so on a
device with one queue (``async_compute = on`` on lavapipe) the same batches and semaphores
run on it one after the other. With a compute-only family, resources cross with the plan's
ownership transfers: the acquire replaces the plan's barrier before the pass, the release is
recorded after the pass that used the resource last on the other queue.

A frame's cameras (``VkScene.copy_camera``: the frame slot's bytes into the buffer the camera
sets bind) are a graphics batch of their own ahead of the frame's (:attr:`AsyncQueues.prologue`):
it signals the graphics semaphore first, and a compute submission that needs nothing of this
frame waits for it instead of the last frame's end, so every pass reads its frame's cameras on
either queue (the graphics values of a frame move up by one).

Frame GPU time, with passes on two queues overlapping, is the span from a timestamp before
the frame's first graphics batch to one after its last (which waits for the compute queue):
:attr:`AsyncQueues.frame_gpu_ms`, one value per finished frame. Per-pass timestamps stay as
they are (a pass's begin and end are on its own queue).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any

from rfw.errors import RfwError
from rfw.graph import CompiledGraph
from rfw.graph.queues import COMPUTE, GRAPHICS, PREVIOUS_FRAME, QueuePlan, Submission, Transfer
from rfw.graph.sync import State

from .commands import BufferBarrier, ImageBarrier, barrier, stage_flags
from .commands.barriers import _buffer_barrier, _image_barrier
from .consts import const, ffi, lib, vk
from .device import VkDevice
from .memory import Buffer, Image

# the prologue's batch: first on the graphics queue, waiting for nothing (its commands order
# themselves after what ran before on the queue), signalling the frame's graphics base
PROLOGUE = Submission(-1, GRAPHICS, (), 0)
# the frame's first graphics batch opens with this (frames in flight: what ran before on
# the queue is done; the executor's barriers chain after it); compute batches wait for it
_BEFORE = State(None, frozenset({"ALL_COMMANDS"}), frozenset({"MEMORY_WRITE"}))
_AFTER = State(None, frozenset({"ALL_COMMANDS"}), frozenset({"MEMORY_READ", "MEMORY_WRITE"}))


# what a compute-only family's command buffers cannot name (VUID-vkCmdPipelineBarrier2-
# srcStageMask-03849): the graphics pipeline's stages and the accesses only they make
GRAPHICS_STAGES = frozenset({
    "VERTEX_INPUT", "INDEX_INPUT", "VERTEX_ATTRIBUTE_INPUT", "VERTEX_SHADER",
    "TESSELLATION_CONTROL_SHADER", "TESSELLATION_EVALUATION_SHADER", "GEOMETRY_SHADER",
    "PRE_RASTERIZATION_SHADERS", "FRAGMENT_SHADER", "EARLY_FRAGMENT_TESTS",
    "LATE_FRAGMENT_TESTS", "COLOR_ATTACHMENT_OUTPUT", "ALL_GRAPHICS", "TASK_SHADER_EXT",
    "MESH_SHADER_EXT", "FRAGMENT_SHADING_RATE_ATTACHMENT_KHR", "TRANSFORM_FEEDBACK_EXT",
    "CONDITIONAL_RENDERING_EXT", "FRAGMENT_DENSITY_PROCESS_EXT"})
GRAPHICS_ACCESS = frozenset({
    "INDEX_READ", "VERTEX_ATTRIBUTE_READ", "INPUT_ATTACHMENT_READ", "COLOR_ATTACHMENT_READ",
    "COLOR_ATTACHMENT_WRITE", "DEPTH_STENCIL_ATTACHMENT_READ",
    "DEPTH_STENCIL_ATTACHMENT_WRITE"})


def on_compute_family(state: State) -> State:
    """``state`` as a barrier on a compute-only family's queue can name it: graphics stages
    become ALL_COMMANDS (every earlier command on the queue; what ran on the graphics queue
    is ordered by the semaphore the batch waits for), graphics-only accesses the generic
    MEMORY_READ/MEMORY_WRITE."""
    if not state.stages & GRAPHICS_STAGES and not state.access & GRAPHICS_ACCESS:
        return state
    stages = state.stages - GRAPHICS_STAGES
    if stages != state.stages:
        stages = frozenset({"ALL_COMMANDS"})
    access = state.access - GRAPHICS_ACCESS
    for a in state.access & GRAPHICS_ACCESS:
        access |= {"MEMORY_WRITE" if a.endswith("WRITE") else "MEMORY_READ"}
    return State(state.layout, stages, frozenset(access))


def async_queues(device: VkDevice, plan: CompiledGraph,
                 barriers: tuple[dict[str, list], ...] = (), *,
                 span: bool = False) -> AsyncQueues | None:
    """The runner of ``plan``'s submissions, or None when the plan has one queue (unless
    ``span``, the run option ``frame_span`` (``RFW_VK_FRAME_SPAN=1``): then a one-queue frame
    is one batch through the runner too, and its GPU span is measured the same way, the
    baseline ``benchmarks/bench_async.py`` compares against). The
    barriers an ownership acquire replaces are taken out of each ``barriers`` dict (pass ->
    its barriers, the executor's), and those of a pass on another family than the graphics
    one are put as its queue can record them (:meth:`AsyncQueues.barriers_for`)."""
    q = plan.queues
    if q is None or (COMPUTE not in q.queues and not span):
        return None
    runner = AsyncQueues(device, q)
    for table in barriers:
        for t in q.transfers:
            table[t.before] = [b for b in table.get(t.before, ())
                               if b.resource != t.resource]
        for p in runner.elsewhere & table.keys():  # as the pass's queue records them: once
            table[p] = runner.barriers_for(p, table[p])
    return runner


class _Pool:
    """A command pool on one queue family; its buffers are reset one by one (each begin)."""

    def __init__(self, device: VkDevice, family: int, label: str):
        self.device = device
        info = vk.VkCommandPoolCreateInfo(
            flags=vk.VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT, queueFamilyIndex=family)
        self.handle = vk.vkCreateCommandPool(device.device, info, None)
        device.register(self)
        device.set_name(self.handle, "COMMAND_POOL", label)

    def allocate(self, count: int) -> list[Any]:
        info = vk.VkCommandBufferAllocateInfo(commandPool=self.handle,
                                              level=vk.VK_COMMAND_BUFFER_LEVEL_PRIMARY,
                                              commandBufferCount=count)
        return list(vk.vkAllocateCommandBuffers(self.device.device, info))

    def destroy(self) -> None:
        if self.handle is not None and self.device.alive:
            vk.vkDestroyCommandPool(self.device.device, self.handle, None)
        self.handle = None
        self.device.unregister(self)


class _Timeline:
    """A timeline semaphore (starts at 0)."""

    def __init__(self, device: VkDevice, label: str):
        self.device = device
        kind = vk.VkSemaphoreTypeCreateInfo(semaphoreType=vk.VK_SEMAPHORE_TYPE_TIMELINE,
                                            initialValue=0)
        self.handle = vk.vkCreateSemaphore(device.device,
                                           vk.VkSemaphoreCreateInfo(pNext=kind), None)
        device.register(self)
        device.set_name(self.handle, "SEMAPHORE", label)

    def destroy(self) -> None:
        if self.handle is not None and self.device.alive:
            vk.vkDestroySemaphore(self.device.device, self.handle, None)
        self.handle = None
        self.device.unregister(self)


class _Slot:
    """One frame slot's command buffers: one per submission, and two that write the frame's
    begin and end timestamps (recorded once)."""

    def __init__(self, runner: AsyncQueues, label: str):
        q, dev = runner.plan, runner.device
        self.cmds = [runner.pools[s.queue].allocate(1)[0] for s in q.submissions]
        self.begun: set[int] = set()
        self.owner: Any = None  # the executor's frame slot it serves
        self.prologue: Any = None  # its prologue's command buffer, recorded once
        self.span: Any = None  # a 2-query timestamp pool
        self.span_pending = False
        self.ts_cmds: tuple[Any, Any] | None = None
        if "timestamp" in dev.caps:
            info = vk.VkQueryPoolCreateInfo(queryType=vk.VK_QUERY_TYPE_TIMESTAMP, queryCount=2)
            self.span = vk.vkCreateQueryPool(dev.device, info, None)
            dev.set_name(self.span, "QUERY_POOL", f"{label}:frame span")
            vk.vkResetQueryPool(dev.device, self.span, 0, 2)
            self.ts_cmds = tuple(runner.pools[GRAPHICS].allocate(2))
            for k, cmd in enumerate(self.ts_cmds):
                vk.vkBeginCommandBuffer(cmd, vk.VkCommandBufferBeginInfo())
                lib.vkCmdWriteTimestamp2(cmd, stage_flags("ALL_COMMANDS"), self.span, k)
                vk.vkEndCommandBuffer(cmd)

    def destroy(self, device: VkDevice) -> None:
        if self.span is not None and device.alive:
            vk.vkDestroyQueryPool(device.device, self.span, None)
        self.span = None


class AsyncQueues:
    """Records each pass into its submission's command buffer and submits the plan's batches
    with their semaphores (see the module)."""

    def __init__(self, device: VkDevice, plan: QueuePlan):
        device.require("timeline_semaphore", "synchronization2")
        if "timestamp" in device.caps and "host_query_reset" not in device.caps:
            raise RfwError("async compute needs host query resets on this device (its passes' "
                           "timestamps are reset from the host)", element="async_compute")
        if plan.mode == "two families" and device.compute_family in (None, device.queue_family):
            raise RfwError("the plan puts compute passes on a compute-only queue family, and "
                           f"{device.name} has none", element="async_compute")
        self.device, self.plan = device, plan
        second = device.compute_queue if plan.mode in ("one family", "two families") else None
        self.queue = {GRAPHICS: device.queue, COMPUTE: second or device.queue}
        self.family = {GRAPHICS: device.queue_family,
                       COMPUTE: device.compute_family if second is not None
                       else device.queue_family}
        self.count = {q: plan.count(q) for q in (GRAPHICS, COMPUTE)}
        self.sub_of = {p: s.index for s in plan.submissions for p in s.passes}
        self.first_graphics = next(s.index for s in plan.submissions if s.queue == GRAPHICS)
        self.position = {p: k for k, p in enumerate(p for s in sorted(
            plan.submissions, key=lambda s: s.index) for p in s.passes)}
        # passes whose batches go to a queue of another family than the graphics one
        self.elsewhere = frozenset(p for p, k in self.sub_of.items()
                                   if self.family[plan.submissions[k].queue]
                                   != device.queue_family)
        # each transfer with its barrier as the queue recording it can name it (once)
        self.acquires: dict[str, list[tuple[Transfer, Any]]] = {}
        self.releases: dict[str, list[tuple[Transfer, Any]]] = {}
        for t in plan.transfers:
            self.acquires.setdefault(t.before, []).append((t, self._on_queue(t.acquire, t.dst)))
            self.releases.setdefault(t.after, []).append((t, self._on_queue(t.release, t.src)))
        self.frames = 0  # frames submitted
        # records a frame's first commands (the executor's: the cameras' copy) into a command
        # buffer of its own, given the executor's frame slot; None: no prologue batch
        self.prologue: Callable[[Any, Any], None] | None = None
        self.frame_gpu_ms: list[float] = []
        self._slots: dict[int, _Slot] = {}  # by id of the executor's frame slot
        self._owners: list[Any] = []
        self._slot: _Slot | None = None
        self._last: str | None = None
        self._resources: dict[str, Any] = {}
        self.pools: dict[str, _Pool] = {}
        self.sems: dict[str, _Timeline] = {}
        try:
            for q in (GRAPHICS, COMPUTE):
                self.pools[q] = _Pool(device, self.family[q], f"rfw:{q} queue")
                self.sems[q] = _Timeline(device, f"rfw:{q} timeline")
        except BaseException:
            self.destroy()
            raise

    # recording ----------------------------------------------------------------------------
    def command_buffer(self, name: str, slot: Any, resources: dict[str, Any]) -> Any:
        """The command buffer pass ``name`` records into (begun), in the frame slot ``slot``
        (any object, one per frame in flight: its buffers are reused when it comes round, so
        the caller waits for its last frame first). A pass at or before the last one starts
        a new frame. Ownership releases of the pass before are recorded first, then the
        acquires of this one."""
        if self._last is None or self.position[name] <= self.position[self._last]:
            self._start(slot)
        elif self._last is not None:
            self._release(self._last)
        self._resources = resources
        s = self._slot
        k = self.sub_of[name]
        cmd = s.cmds[k]
        if k not in s.begun:
            vk.vkBeginCommandBuffer(cmd, vk.VkCommandBufferBeginInfo(
                flags=vk.VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT))
            if k == self.first_graphics:  # compute batches wait for it, or the last frame
                barrier(cmd, memory_barriers=[(_BEFORE, _AFTER)])
            s.begun.add(k)
        self._last = name
        self._acquire(cmd, name)
        return cmd

    def barriers_for(self, name: str, barriers: list[Any]) -> list[Any]:
        """Pass ``name``'s plan barriers as its queue can record them (a compute-only
        family's: see :func:`on_compute_family`)."""
        if name not in self.elsewhere:
            return barriers
        return [replace(b, src=on_compute_family(b.src), dst=on_compute_family(b.dst))
                for b in barriers]

    def _start(self, slot: Any) -> None:
        s = self._slots.get(id(slot))
        if s is None:
            s = self._slots[id(slot)] = _Slot(self, f"rfw:slot{len(self._slots)}")
            self._owners.append(slot)  # kept: its id stays its own
            s.owner = slot
        self._read_span(s)  # its last frame is done: the caller waited for it
        s.begun.clear()
        self._slot, self._last = s, None

    def _on_queue(self, b: Any, queue: str) -> Any:
        # ``b`` as a command buffer of ``queue`` (the release's or the acquire's) can record it
        if self.family[queue] != self.device.queue_family:
            return replace(b, src=on_compute_family(b.src), dst=on_compute_family(b.dst))
        return b

    def _transfer_barrier(self, cmd: Any, t: Transfer, b: Any) -> None:
        # ``b``: the transfer's barrier as ``cmd``'s queue can record it (see _on_queue)
        res = self._resources[t.resource]
        dep = ffi.new("VkDependencyInfo*")
        dep.sType = const("VK_STRUCTURE_TYPE_DEPENDENCY_INFO")
        if isinstance(res, Image):
            arr = ffi.new("VkImageMemoryBarrier2[]", 1)
            _image_barrier(arr[0], ImageBarrier(res, b.src, b.dst))
            dep.imageMemoryBarrierCount, dep.pImageMemoryBarriers = 1, arr
        elif isinstance(res, Buffer):
            arr = ffi.new("VkBufferMemoryBarrier2[]", 1)
            _buffer_barrier(arr[0], BufferBarrier(res, b.src, b.dst))
            dep.bufferMemoryBarrierCount, dep.pBufferMemoryBarriers = 1, arr
        else:  # the plan gives transfers for images and buffers only
            raise RfwError(f"'{t.resource}' cannot change queue family", element="async_compute")
        arr[0].srcQueueFamilyIndex = self.family[t.src]
        arr[0].dstQueueFamilyIndex = self.family[t.dst]
        vk.vkCmdPipelineBarrier2(cmd, dep)

    def _acquire(self, cmd: Any, name: str) -> None:
        for t, b in self.acquires.get(name, ()):
            self._transfer_barrier(cmd, t, b)

    def _release(self, name: str) -> None:
        for t, b in self.releases.get(name, ()):
            self._transfer_barrier(self._slot.cmds[self.sub_of[name]], t, b)

    # submitting ---------------------------------------------------------------------------
    def submit(self, last: Any) -> Any:
        """Submit the frame's batches; ``last`` (the command buffer handed out last) is
        ended already, the others are ended here. Returns the fence of the last batch (the
        last graphics one, after every other): waiting for it waits for the frame."""
        s, q = self._slot, self.plan
        if self._last is not None:
            self._release(self._last)
        for k in sorted(s.begun):
            if s.cmds[k] is not last:
                vk.vkEndCommandBuffer(s.cmds[k])
        pre = int(self.prologue is not None)  # the prologue: one more graphics batch
        base = {GRAPHICS: self.frames * (self.count[GRAPHICS] + pre) + pre,
                COMPUTE: self.frames * self.count[COMPUTE]}
        fence = vk.vkCreateFence(self.device.device, vk.VkFenceCreateInfo(), None)
        graphics = [sub.index for sub in q.submissions if sub.queue == GRAPHICS]
        if s.span is not None:
            vk.vkResetQueryPool(self.device.device, s.span, 0, 2)
        try:
            if pre:
                self._batch(PROLOGUE, [self._prologue(s)], base, None)
            for sub in q.submissions:
                cmds = [s.cmds[sub.index]] if sub.index in s.begun else []
                if s.ts_cmds is not None and sub.index == graphics[0]:
                    cmds.insert(0, s.ts_cmds[0])
                if s.ts_cmds is not None and sub.index == graphics[-1]:
                    cmds.append(s.ts_cmds[1])
                self._batch(sub, cmds, base, fence if sub is q.submissions[-1] else None)
        except BaseException:
            vk.vkDeviceWaitIdle(self.device.device)
            vk.vkDestroyFence(self.device.device, fence, None)
            raise
        s.span_pending = s.span is not None
        self.frames += 1
        self._last = None
        return fence

    def _prologue(self, s: _Slot) -> Any:
        if s.prologue is None:  # the same commands every frame of the slot
            cmd = self.pools[GRAPHICS].allocate(1)[0]
            vk.vkBeginCommandBuffer(cmd, vk.VkCommandBufferBeginInfo())
            self.prologue(cmd, s.owner)  # type: ignore[misc]
            vk.vkEndCommandBuffer(cmd)
            s.prologue = cmd
        return s.prologue

    def _batch(self, sub: Any, cmds: list[Any], base: dict[str, int], fence: Any) -> None:
        infos = ffi.new("VkCommandBufferSubmitInfo[]", max(1, len(cmds)))
        for i, c in enumerate(cmds):
            infos[i].sType = const("VK_STRUCTURE_TYPE_COMMAND_BUFFER_SUBMIT_INFO")
            infos[i].commandBuffer = c
        waits = ffi.new("VkSemaphoreSubmitInfo[]", max(1, len(sub.waits)))
        for i, w in enumerate(sub.waits):
            value = base[w.queue] + (0 if w.submission == PREVIOUS_FRAME else w.value)
            _semaphore(waits[i], self.sems[w.queue].handle, value, w.stages)
        signal = ffi.new("VkSemaphoreSubmitInfo*")
        _semaphore(signal, self.sems[sub.queue].handle, base[sub.queue] + sub.value,
                   sub.signal_stages)
        info = ffi.new("VkSubmitInfo2*")
        info.sType = const("VK_STRUCTURE_TYPE_SUBMIT_INFO_2")
        info.commandBufferInfoCount, info.pCommandBufferInfos = len(cmds), infos
        info.waitSemaphoreInfoCount, info.pWaitSemaphoreInfos = len(sub.waits), waits
        info.signalSemaphoreInfoCount, info.pSignalSemaphoreInfos = 1, signal
        vk.vkQueueSubmit2(self.queue[sub.queue], 1, info,
                          fence if fence is not None else ffi.NULL)

    # frame GPU time -----------------------------------------------------------------------
    def _read_span(self, s: _Slot) -> None:
        if not s.span_pending:
            return
        data = ffi.new("uint64_t[2]")
        vk.vkGetQueryPoolResults(self.device.device, s.span, 0, 2, 16, data, 8,
                                 vk.VK_QUERY_RESULT_64_BIT | vk.VK_QUERY_RESULT_WAIT_BIT)
        bits = self.device.timestamp_bits
        mask = (1 << bits) - 1 if bits < 64 else (1 << 64) - 1
        ticks = ((data[1] & mask) - (data[0] & mask)) & mask
        self.frame_gpu_ms.append(ticks * self.device.timestamp_period * 1e-6)
        s.span_pending = False

    def spans(self) -> list[float]:
        """Every submitted frame's GPU span in ms (waits for frames still running)."""
        for s in self._slots.values():
            self._read_span(s)
        return list(self.frame_gpu_ms)

    def destroy(self) -> None:
        """Destroy what the runner made; the spans of frames not yet read are read first
        (the executor finishes its frames before)."""
        if self.device.alive:
            self.spans()
        for s in self._slots.values():
            s.destroy(self.device)
        self._slots.clear()
        for obj in (*self.pools.values(), *self.sems.values()):
            obj.destroy()
        self.pools, self.sems = {}, {}


def _semaphore(out: Any, handle: Any, value: int, stages: frozenset[str]) -> None:
    out.sType = const("VK_STRUCTURE_TYPE_SEMAPHORE_SUBMIT_INFO")
    out.semaphore = handle
    out.value = value
    out.stageMask = stage_flags(stages)
    out.deviceIndex = 0
