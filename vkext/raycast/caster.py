"""The :class:`Raycaster` (one method's pipeline on a device, casting batches in flight through
reused command buffers and fences) and the :class:`RayBuffers` it casts through. The two share
one module because each names the other: buffers bind the caster's pipeline layout, the caster
makes buffers for :meth:`Raycaster.trace`."""

from __future__ import annotations

import itertools
import threading
import time
from collections import deque
from pathlib import Path
from typing import Any

import numpy as np

from rfw.graph import CompiledGraph
from rfw.graph.sync import State

from ..accel import SceneAccel
from ..accel.plan import PlanRecorder, compiled
from ..allocation import (
    DEVICE_LOCAL,
    HOST_CACHED,
    HOST_COHERENT,
    HOST_VISIBLE,
    DeviceMemory,
    byte_text,
    flags_of,
)
from ..buffers import Buffer, staging_buffer
from ..commands import (
    FENCE_TIMEOUT_NS,
    CommandPool,
    TimestampPool,
    begin_label,
    copy_to_host,
    end_label,
    written_for_host,
)
from ..consts import const, ffi, lib, vk
from ..device import VkDevice, VkMissingFeatureError
from ..rt import BindingSet, ComputePipeline, HitGroup, RayTracingPipeline
from ..sbt import ShaderBindingTable
from .batches import DEFAULT_BATCH, OVERLAP_MIN, SLOTS, batch_graph, batch_rays
from .copies import parallel_copy
from .placement import mapped_streams, mapped_type_bits, rays_in_host_memory
from .streams import (
    HIT_DTYPE,
    HIT_STREAMS,
    HIT_WORDS,
    RAY_DTYPE,
    RAY_WORDS,
    _check_traced,
    hit_arrays,
)

SHADERS = Path(__file__).resolve().parents[1] / "shaders" / "raycast"
METHODS = ("ray_query", "ray_pipeline")

# the parts of a cast's time in Raycaster.last: summed over its batches on the host, and on
# the GPU between STAMPS timestamps per batch (before the copy in, the trace, the copy out)
HOST_PARTS = ("upload_ms", "submit_ms", "wait_ms", "readback_ms")
GPU_PARTS = ("gpu_upload_ms", "gpu_ms", "gpu_readback_ms")
STAMPS = len(GPU_PARTS) + 1

# RayBuffers.generation: new buffers, a new number (commands recorded for old ones expire)
_generations = itertools.count(1)


def pick_method(device: VkDevice, method: str = "auto") -> str:
    """``"auto"``: ray queries where the device has them, else the pipeline. A named method
    the device lacks raises :class:`VkMissingFeatureError`."""
    need = {"ray_query": "VK_KHR_ray_query", "ray_pipeline": "VK_KHR_ray_tracing_pipeline"}
    if method == "auto":
        for m in METHODS:
            if need[m] in device.caps:
                return m
        raise VkMissingFeatureError(f"{device.name} has neither VK_KHR_ray_query nor "
                                    "VK_KHR_ray_tracing_pipeline: it cannot cast rays")
    if method not in need:
        raise ValueError(f"method is 'auto', 'ray_query' or 'ray_pipeline', not {method!r}")
    device.require(need[method])
    return method


def device_lock(device: VkDevice) -> threading.RLock:
    """The lock of ray casting on ``device``: a cast records into the raycaster's command
    buffers, reuses its fences and submits to the device's one queue, none of which may be
    used by two threads at once (Vulkan's external synchronization). Casts from several
    threads take turns; each gets the hits a cast alone would."""
    return device.raycast_lock


class RayBuffers:
    """The rays and hits of one batch, each stream placed one of two ways (``mapped``:
    (rays, hits), by default :func:`mapped_streams`):

    - staged: a device-local buffer (``<label>.rays``, ``<label>.hits``) that the trace
      reads or writes, and :data:`SLOTS` staging buffers (one per batch in flight) the host
      fills or reads, copied on the GPU;
    - mapped: :data:`SLOTS` host-visible buffers that the trace itself reads or writes (no
      copy): on unified memory (lavapipe, integrated GPUs) the host then works at memory
      speed; on a discrete GPU the rays go to device-local host-visible memory (a BAR), or
      with :func:`rays_in_host_memory` to host-cached memory, and the hits to host-cached
      memory, across the bus.

    ``up[slot]`` and ``down[slot]`` are what the host writes and reads either way, and
    ``sets[slot]`` the descriptor set binding the slot's buffers with a TLAS.
    :meth:`reserve` grows them for a larger batch (``allocations`` counts the times buffers
    were made) and never shrinks them."""

    def __init__(self, caster: Raycaster, tlas: Any, *, label: str = "raycast",
                 mapped: tuple[bool, bool] | None = None):
        self.caster, self.device, self.tlas, self.label = caster, caster.device, tlas, label
        self.mapped_rays, self.mapped_hits = \
            mapped_streams(self.device) if mapped is None else mapped
        self.host_rays = self.mapped_rays and mapped is None and rays_in_host_memory()
        self.capacity = self.allocations = 0
        self.generation = 0  # new buffers, new number: commands recorded for old ones expire
        self.up_cached = True  # whether the host writes rays into host-cached memory
        # (GPU, host) nanoseconds per ray of the last cast of at least OVERLAP_MIN rays
        # through these buffers, with timestamps: what batch_rays decides overlap by
        self.rates: tuple[float, float] | None = None
        self._made: list[Any] = []
        self.rays = self.hits = None
        self.up: list[Buffer] = []
        self.down: list[Buffer] = []
        self.sets: list[BindingSet] = []

    def reserve(self, rays: int) -> None:
        if rays <= self.capacity:
            return
        self._free()
        try:
            self._make(rays)
        except BaseException:
            self._free()
            raise
        self.capacity = rays
        self.allocations += 1
        self.generation = next(_generations)
        self.up_cached = bool(self.up[0].memory.properties & flags_of([HOST_CACHED]))

    def _make(self, rays: int) -> None:
        dev, label = self.device, self.label
        size = {"rays": rays * RAY_WORDS * 4, "hits": rays * HIT_WORDS * 4}
        if not self.mapped_rays:
            self.rays = self._keep(Buffer(dev, size["rays"], ("storage", "transfer_dst"),
                                          label=f"{label}.rays"))
            self.rays.allocate()
        if not self.mapped_hits:
            self.hits = self._keep(Buffer(dev, size["hits"], ("storage", "transfer_src"),
                                          label=f"{label}.hits"))
            self.hits.allocate()
        for slot in range(SLOTS):
            # staging is host-cached where there is such memory (readback=True prefers it):
            # a converting copy writes partial lines, slow in write-combined memory
            self.up.append(
                self._mapped(size["rays"], readback=self.host_rays, name=f"rays {slot}")
                if self.mapped_rays else self._keep(staging_buffer(
                    dev, size["rays"], readback=True, label=f"{label}:rays upload {slot}")))
            self.down.append(
                self._mapped(size["hits"], readback=True, name=f"hits {slot}")
                if self.mapped_hits else self._keep(staging_buffer(
                    dev, size["hits"], readback=True, label=f"{label}:hits readback {slot}")))
            if slot == 0 or self.mapped_rays or self.mapped_hits:
                self.sets.append(self._binding_set(
                    self.up[slot] if self.mapped_rays else self.rays,
                    self.down[slot] if self.mapped_hits else self.hits, f" {slot}"))
            else:  # both staged: the slots share the device buffers and their set
                self.sets.append(self.sets[0])

    @property
    def placement(self) -> str:
        """``staged``, ``mapped`` (both streams), which one is mapped, or ``host`` (both, the
        rays in host-cached memory)."""
        if self.host_rays:
            return "host"
        return {(False, False): "staged", (True, True): "mapped", (True, False): "rays mapped",
                (False, True): "hits mapped"}[(self.mapped_rays, self.mapped_hits)]

    def _mapped(self, size: int, *, readback: bool, name: str) -> Buffer:
        """A storage buffer in host-visible memory, device-local where it can be."""
        buf = self._keep(Buffer(self.device, size, ("storage",), label=f"{self.label}.{name}"))
        bits = buf.type_bits & mapped_type_bits(self.device, readback=readback)
        mem = DeviceMemory(self.device, buf.size, bits or buf.type_bits, host_visible=True,
                           readback=readback, label=f"{self.label}:{name} memory")
        self._made.insert(self._made.index(buf), mem)  # freed after the buffer
        buf.bind(mem, 0)
        return buf

    def _binding_set(self, rays: Buffer, hits: Buffer, suffix: str) -> BindingSet:
        bindings = self._keep(BindingSet(self.caster.pipeline.layout,
                                         label=f"{self.label}:descriptors{suffix}"))
        bindings.write(tlas=self.tlas, rays=rays, hits=hits)
        return bindings

    def memory(self) -> dict[str, str]:
        """Where the host's rays and hits live: memory properties and heap size, for
        reports (empty before the first cast)."""
        names = (("DEVICE_LOCAL", DEVICE_LOCAL), ("HOST_VISIBLE", HOST_VISIBLE),
                 ("HOST_COHERENT", HOST_COHERENT), ("HOST_CACHED", HOST_CACHED))
        out = {}
        for stream, bufs in (("rays", self.up), ("hits", self.down)):
            if bufs:
                mem = bufs[0].memory
                props, heap = self.device.memory_types[mem.type_index]
                flags = "|".join(n for n, f in names if props & flags_of([f])) or "none"
                size = byte_text(self.device.memory_heaps[heap][0])
                out[stream] = f"type {mem.type_index} {flags} (heap {heap}: {size})"
        return out

    def _keep(self, obj: Any) -> Any:
        self._made.append(obj)
        return obj

    def write_rays(self, slot: int, origins: np.ndarray, directions: np.ndarray, tmin: Any,
                   tmax: Any) -> int:
        """Rays into upload buffer ``slot`` as raycast.glsl's streams, each converted to
        float32 while it is copied (one pass over the caller's arrays, whatever their
        layout); returns their bytes."""
        k = len(origins)
        words = self.up[slot].map().view(np.float32)
        jobs = [(words[:3 * k].reshape(k, 3), origins),
                (words[3 * k:6 * k].reshape(k, 3), directions)]
        if np.ndim(tmin) or np.ndim(tmax):
            jobs += [(words[6 * k:7 * k], tmin), (words[7 * k:8 * k], tmax)]
        parallel_copy(jobs, cached=self.up_cached)
        return (8 if len(jobs) > 2 else 6) * k * 4

    def read_hits(self, slot: int, k: int, out: dict[str, np.ndarray], start: int) -> bool:
        """The ``k`` hits in readback buffer ``slot`` into ``out``'s arrays (those it has)
        at ``start``; returns whether any ``t`` is NaN (a ray the shaders refused), checked
        as the copy lands."""
        words = self.down[slot].map()[:k * HIT_WORDS * 4].view(np.float32)
        at, jobs, check = 0, [], None
        for name, width in HIT_STREAMS:
            if name in out:
                dst = out[name][start:start + k].reshape(-1)
                check = len(jobs) if name == "t" else check
                jobs.append((dst, words[at:at + width * k].view(dst.dtype)))
            at += width * k
        return parallel_copy(jobs, check=check)

    def _free(self) -> None:
        for obj in reversed(self._made):
            obj.destroy()
        self._made.clear()
        self.rays = self.hits = None
        self.up, self.down, self.sets = [], [], []
        self.capacity = 0

    def destroy(self) -> None:
        self._free()


class Raycaster:
    """The pipeline of one method on a device; :meth:`cast` casts rays against a scene's
    acceleration structures. Registered with the device, so it dies with it at the latest."""

    def __init__(self, device: VkDevice, method: str = "auto", *, label: str = "raycast"):
        device.require("VK_KHR_acceleration_structure")
        self.device, self.label = device, label
        self.method = pick_method(device, method)
        self.pipeline: ComputePipeline | RayTracingPipeline | None = None
        self._tables: dict[int, ShaderBindingTable] = {}  # by hit-record count
        self.timer = self.commands = None
        self._host: dict[str, float] = {}  # the cast under way: host seconds of its parts
        # per batch index of a cast: its command buffer and what it was recorded for
        self.cmds: list[tuple[Any, tuple | None]] = []
        self._submits: list[Any] = []  # per batch index: (cmd, its submit info structs)
        self.fences: list[Any] = []  # per slot, reset and reused by every cast
        self._refused = False  # the cast under way read a NaN t
        self.recorded = self._timer_generation = 0
        self.last: dict[str, Any] = {}
        self.plan: CompiledGraph = compiled(batch_graph(self.method))
        try:
            self.commands = CommandPool(device, transient=False, label=f"{label}:commands")
            if self.method == "ray_query":
                self.pipeline = ComputePipeline(device, SHADERS / "raycast.comp.glsl",
                                                label=f"{label}:ray_query")
            else:
                self.pipeline = RayTracingPipeline(
                    device, SHADERS / "raycast.rgen.glsl", [SHADERS / "raycast.rmiss.glsl"],
                    [HitGroup(closest=SHADERS / "raycast.rchit.glsl")],
                    label=f"{label}:ray_pipeline")
            if "timestamp" in device.caps:
                self.timer = TimestampPool(device, STAMPS * SLOTS, label=f"{label}:timestamps")
        except BaseException:
            self.destroy()
            raise
        device.register(self)

    def _table(self, records: int) -> ShaderBindingTable:
        # every hit record runs the one closest-hit group, whatever SBT offsets the
        # instances carry
        sbt = self._tables.get(records)
        if sbt is None:
            sbt = self._tables[records] = ShaderBindingTable(
                self.pipeline, hit=[0] * records, label=f"{self.label}:sbt{records}")
        return sbt

    def cast(self, accel: SceneAccel, buffers: RayBuffers, origins: np.ndarray,
             directions: np.ndarray, tmin: Any = 0.0, tmax: Any = np.inf, *,
             batch: int = DEFAULT_BATCH, hits: tuple[str, ...] = ("t", "primitive",
                                                                   "instance", "barycentrics"),
             out: dict[str, np.ndarray] | None = None) -> dict[str, np.ndarray]:
        """Closest hits of rays given as real (R, 3) ``origins`` and ``directions`` of any
        layout (converted to float32 as they are copied to the GPU) with ``tmin``/``tmax``
        numbers or (R,) float32 arrays, through ``buffers`` (grown to the batch if needed).
        Returns the arrays named in ``hits``: ``t`` (inf on a miss), ``primitive`` and
        ``instance`` (-1), ``barycentrics`` (R, 2); those in ``out`` (C-contiguous, of
        :func:`hit_arrays`' dtypes and shapes) are filled and returned instead of new ones.

        A ray the shaders refuse (non-finite origin or direction, zero direction) raises
        :class:`RfwError` naming the argument and the first such row, after the cast.
        ``last`` then holds the ray and batch counts, ``wall_ms`` (the host's time for
        everything, copies and waits included) and its parts summed over the batches
        (``upload_ms``: rays into staging or mapped memory; ``submit_ms``: recording and
        submitting; ``wait_ms``: waiting for the GPU; ``readback_ms``: hits out of it). With
        timestamps also the GPU's parts: ``gpu_upload_ms`` and ``gpu_readback_ms`` (the
        copies), ``gpu_ms`` (the traces alone) and its ``mrays_per_s``."""
        with device_lock(self.device):  # one cast at a time on the device's queue
            return self._cast(accel, buffers, origins, directions, tmin, tmax, batch=batch,
                              hits=hits, out=out)

    def _cast(self, accel: SceneAccel, buffers: RayBuffers, origins: np.ndarray,
              directions: np.ndarray, tmin: Any, tmax: Any, *, batch: int,
              hits: tuple[str, ...], out: dict[str, np.ndarray] | None,
              ) -> dict[str, np.ndarray]:
        if batch < 1:
            raise ValueError(f"batch must be positive, got {batch}")
        n = len(origins)
        want = dict(dict.fromkeys(hits), t=None, primitive=None)  # the check reads both
        arrays = hit_arrays(n, want, out)
        self.last = {"method": self.method, "rays": n, "batches": 0}
        if n == 0:
            return {k: arrays[k] for k in hits}
        wall = time.perf_counter()
        per = batch_rays(n, batch, device_type=self.device.device_type, rates=buffers.rates)
        buffers.reserve(per)
        sbt = self._table(accel.hit_records) if self.method == "ray_pipeline" else None
        per_ray = not (np.ndim(tmin) == 0 and np.ndim(tmax) == 0)
        if per_ray:  # one of them an array: both are streams
            tmin, tmax = (np.broadcast_to(np.asarray(x, np.float32), (n,)) for x in (tmin, tmax))
        self._host = dict.fromkeys(HOST_PARTS, 0.0)
        batches = -(-n // per)
        self._timestamps(batches)
        flight: deque[tuple[int, int, int, Any]] = deque()  # (slot, start, rays, fence)
        self._refused = False
        try:
            for j, start in enumerate(range(0, n, per)):
                slot = j % SLOTS
                if len(flight) == SLOTS:  # the slot's last batch must be done and read
                    self._finish(flight.popleft(), buffers, arrays)
                k = min(per, n - start)
                part = slice(start, start + k)
                lo, hi = (tmin[part], tmax[part]) if per_ray else (tmin, tmax)
                t0 = time.perf_counter()
                size = buffers.write_rays(slot, origins[part], directions[part], lo, hi)
                t1 = time.perf_counter()
                fence = self._submit(j, k, size, buffers, sbt, per_ray, lo, hi)
                self._host["upload_ms"] += t1 - t0
                self._host["submit_ms"] += time.perf_counter() - t1
                flight.append((slot, start, k, fence))
            while flight:
                self._finish(flight.popleft(), buffers, arrays)
        finally:
            for *_, fence in flight:  # after an error: nothing may still run on the buffers
                self._wait(fence)
        self._report(n, batches, time.perf_counter() - wall)
        if n >= OVERLAP_MIN and "gpu_ms" in self.last:
            gpu = sum(self.last[k] for k in GPU_PARTS)
            host = self.last["upload_ms"] + self.last["readback_ms"]
            buffers.rates = (gpu * 1e6 / n, host * 1e6 / n)
        if self._refused:  # read_hits saw a NaN t: find the first
            _check_traced(arrays["t"], arrays["primitive"])
        return {k: arrays[k] for k in hits}

    def _timestamps(self, batches: int) -> None:
        # every batch of a cast has its own queries, read once after the last fence: a
        # query read with WAIT while later batches run may wait for them too (lavapipe does)
        if self.timer is None or self.timer.count >= STAMPS * batches:
            return
        self.timer.destroy()
        self.timer = None
        self.timer = TimestampPool(self.device, STAMPS * batches,
                                   label=f"{self.label}:timestamps")
        self._timer_generation += 1

    def _report(self, n: int, batches: int, wall_s: float) -> None:
        """``last``'s times, in milliseconds."""
        self.last["wall_ms"] = wall_s * 1e3
        self.last.update({k: v * 1e3 for k, v in self._host.items()})
        if self.timer is None:
            return
        stamps = np.array(self.timer.results(0, STAMPS * batches), np.int64)
        gpu_ns = np.diff(stamps.reshape(batches, STAMPS), axis=1).sum(axis=0)
        self.last.update({k: int(v) / 1e6 for k, v in zip(GPU_PARTS, gpu_ns, strict=True)})
        self.last["mrays_per_s"] = n / max(int(gpu_ns[1]), 1) * 1e3

    def trace(self, accel: SceneAccel, rays: np.ndarray, *,
              batch: int = DEFAULT_BATCH) -> np.ndarray:
        """:meth:`cast` of ``rays`` given as a :data:`RAY_DTYPE` array, hits as a
        :data:`HIT_DTYPE` array, through buffers made for this call."""
        rays = np.ascontiguousarray(rays)
        if rays.dtype != RAY_DTYPE or rays.ndim != 1:
            raise ValueError(f"rays must be a 1-D array of RAY_DTYPE, got {rays.dtype} "
                             f"{rays.shape}")
        buffers = RayBuffers(self, accel.tlas, label=self.label)
        try:
            got = self.cast(accel, buffers, np.ascontiguousarray(rays["origin"]),
                            np.ascontiguousarray(rays["direction"]),
                            np.ascontiguousarray(rays["tmin"]),
                            np.ascontiguousarray(rays["tmax"]), batch=batch)
        finally:
            buffers.destroy()
        out = np.empty(len(rays), HIT_DTYPE)
        for key in ("t", "primitive", "instance"):
            out[key] = got[key]
        out["u"], out["v"] = got["barycentrics"][:, 0], got["barycentrics"][:, 1]
        return out

    def _submit(self, j: int, k: int, size: int, buffers: RayBuffers,
                sbt: ShaderBindingTable | None, per_ray: bool, tmin: Any, tmax: Any) -> Any:
        """Submit batch ``j`` of ``k`` rays and return its fence (the caller waits in
        :meth:`_finish`). Its command buffer is recorded again only when what it records
        changed since the last cast (``recorded`` counts the recordings): a cast like the
        last one records nothing."""
        slot = j % SLOTS
        if per_ray:  # the numbers are not recorded then
            tmin = tmax = 0.0
        key = (buffers.generation, slot, k, size, per_ray, float(tmin), float(tmax), id(sbt),
               self._timer_generation)
        while len(self.cmds) <= j:
            self.cmds.append((self.commands.allocate(1)[0], None))
        cmd, recorded = self.cmds[j]
        if recorded != key:
            vk.vkBeginCommandBuffer(cmd, vk.VkCommandBufferBeginInfo())
            begin_label(self.device, cmd, f"{self.label}: {k} rays")
            self._record_batch(cmd, PlanRecorder(self.plan), slot, STAMPS * j, k, size,
                               buffers, sbt, per_ray, tmin, tmax)
            end_label(self.device, cmd)
            vk.vkEndCommandBuffer(cmd)
            self.cmds[j] = (cmd, key)
            self.recorded += 1
        return self._submit_slot(slot, j, cmd)

    def _submit_slot(self, slot: int, j: int, cmd: Any) -> Any:
        """Submit ``cmd`` (batch ``j``'s) with slot ``slot``'s fence, kept from cast to cast
        (reset here: the slot's last batch was waited for), and return the fence; the
        submit info is built once per command buffer."""
        dev = self.device.device
        while len(self.fences) <= slot:
            self.fences.append(vk.vkCreateFence(dev, vk.VkFenceCreateInfo(), None))
        while len(self._submits) <= j:
            self._submits.append(None)
        made = self._submits[j]
        if made is None or made[0] != cmd:
            infos = ffi.new("VkCommandBufferSubmitInfo*")
            infos.sType = const("VK_STRUCTURE_TYPE_COMMAND_BUFFER_SUBMIT_INFO")
            infos.commandBuffer = cmd
            info = ffi.new("VkSubmitInfo2*")
            info.sType = const("VK_STRUCTURE_TYPE_SUBMIT_INFO_2")
            info.commandBufferInfoCount, info.pCommandBufferInfos = 1, infos
            made = self._submits[j] = (cmd, infos, info)
        fence = self.fences[slot]
        vk.vkResetFences(dev, 1, [fence])
        try:
            vk.vkQueueSubmit2(self.device.queue, 1, made[2], fence)
        except BaseException:
            vk.vkDeviceWaitIdle(dev)
            raise
        return fence

    def _wait(self, fence: Any) -> None:
        vk.vkWaitForFences(self.device.device, 1, [fence], vk.VK_TRUE, FENCE_TIMEOUT_NS)

    def _finish(self, batch: tuple[int, int, int, Any], buffers: RayBuffers,
                out: dict[str, np.ndarray]) -> None:
        """Wait for a submitted batch, then read its hits."""
        slot, start, k, fence = batch
        t0 = time.perf_counter()
        self._wait(fence)
        t1 = time.perf_counter()
        self._refused |= buffers.read_hits(slot, k, out, start)
        self._host["wait_ms"] += t1 - t0
        self._host["readback_ms"] += time.perf_counter() - t1
        self.last["batches"] += 1

    def _record_batch(self, cmd: Any, plan: PlanRecorder, slot: int, first: int, k: int,
                      size: int, buffers: RayBuffers, sbt: ShaderBindingTable | None,
                      per_ray: bool, tmin: Any, tmax: Any) -> None:
        # the work of each pass of batch_graph, behind the barriers its plan puts before it;
        # timestamps between the passes time the copies and the trace apart
        if self.timer is not None:
            vk.vkCmdResetQueryPool(cmd, self.timer.handle, first, STAMPS)
        # a mapped stream skips its copy (its stamps meet); its buffer is the slot's own,
        # reused only after the host waited for the batch before, and the submit makes the
        # host's rays visible: only mapped hits need a barrier more, to the host's reads
        plan.enter(cmd, "rays")
        self._stamp(cmd, first)
        if not buffers.mapped_rays:
            copy = ffi.new("VkBufferCopy*")
            copy.size = size
            lib.vkCmdCopyBuffer(cmd, buffers.up[slot].handle, buffers.rays.handle, 1, copy)
        plan.enter(cmd, "trace")
        self._stamp(cmd, first + 1)
        self._record(cmd, buffers.sets[slot], sbt, k, per_ray,
                     0.0 if per_ray else tmin, 0.0 if per_ray else tmax)
        self._stamp(cmd, first + 2)
        plan.enter(cmd, "hits")
        if buffers.mapped_hits:
            written_for_host(cmd, buffers.down[slot], self._trace_state(), k * HIT_WORDS * 4)
        else:
            copy_to_host(cmd, buffers.hits, buffers.down[slot], k * HIT_WORDS * 4)
        self._stamp(cmd, first + 3)

    def _trace_state(self) -> State:
        stage = "COMPUTE_SHADER" if self.method == "ray_query" else "RAY_TRACING_SHADER_KHR"
        return State(None, frozenset({stage}), frozenset({"SHADER_STORAGE_WRITE"}))

    def _stamp(self, cmd: Any, query: int) -> None:
        if self.timer is not None:
            self.timer.write(cmd, "ALL_COMMANDS", query)

    def _record(self, cmd: Any, bindings: BindingSet, sbt: ShaderBindingTable | None,
                count: int, per_ray: bool, tmin: float, tmax: float) -> None:
        pipe = self.pipeline
        vk.vkCmdBindPipeline(cmd, pipe.bind_point, pipe.handle)
        bindings.bind(cmd, pipe.bind_point)
        layout = pipe.layout
        push = np.array([count, int(per_ray), 0, 0], np.uint32)
        push[2:].view(np.float32)[:] = (tmin, tmax)
        data = ffi.from_buffer("uint32_t[]", push)
        lib.vkCmdPushConstants(cmd, layout.handle, layout.push_stages, 0, push.nbytes, data)
        if sbt is None:
            pipe.dispatch(cmd, count)
        else:
            sbt.trace(cmd, count)

    def destroy(self) -> None:
        for sbt in self._tables.values():
            sbt.destroy()
        self._tables.clear()
        if self.timer is not None:
            self.timer.destroy()
            self.timer = None
        if self.pipeline is not None:
            self.pipeline.destroy()
            self.pipeline = None
        if self.fences and self.device.alive:
            for fence in self.fences:
                vk.vkDestroyFence(self.device.device, fence, None)
        self.fences = []
        if self.commands is not None:
            self.commands.destroy()
            self.commands = None
        self.device.unregister(self)
