"""Closest-hit ray casting against a :class:`SceneAccel`, by ray query or ray-tracing pipeline.

Two ways to the same answer, so either can be checked against the other and against a CPU
reference (``rfw.RayScene`` and ``rfw.raycast`` are the numpy front end):

- ``"ray_query"``: a compute shader with ``GL_EXT_ray_query`` (``raycast.comp.glsl``);
- ``"ray_pipeline"``: raygen + miss + closest hit through a shader binding table and
  ``vkCmdTraceRaysKHR``; it needs no ray-query support (NVIDIA drivers may offer pipelines
  only).

A :class:`RayScene` keeps what casting needs from call to call: the scene's acceleration
structures (built once), the device's pipeline (:func:`raycaster`) and the ray and hit
buffers (:class:`RayBuffers`, grown when a batch is larger, never shrunk). Rays and hits are
*streams* (origins, directions, optional per-ray tmin and tmax; t, primitive, instance,
barycentrics), so the host fills and reads each with one copy of the caller's arrays, the
rays converted to float32 in that same copy whatever their dtype and layout (split among
threads when large: :func:`parallel_copy`); hits go into new arrays or the caller's
(``out``). The shaders check every ray as they read it (finite origin and direction, a
direction that is not zero): such a ray is not traced, and :meth:`Raycaster.cast` raises
naming the argument and the first bad row.

Rays go through in batches of at most ``batch`` rays, :data:`SLOTS` in flight, so the host
fills one batch's rays and reads another's hits while the GPU works; memory stays bounded
for any ray count. A cast of at most ``batch`` rays is one batch unless overlap pays
(:func:`batch_rays`: a GPU that is not the host's CPU, with measured GPU and host times both
large enough to hide behind each other; then :data:`OVERLAP_PARTS` batches): on the
H200 and on lavapipe a batch more cost more than it hid. Every batch reuses its slot's
fence and, for a cast like the last, its command buffer: a cast only submits. Where
the buffers live (:func:`mapped_streams`, per stream): on a discrete GPU, per batch one
submit copies the rays from a staging buffer to device-local memory, traces, and copies the
hits back (about 160 bytes a ray of the batch, staging included); where memory is
device-local and host-cached at once (lavapipe, integrated GPUs) the trace reads and writes
mapped buffers, one pair per slot, and nothing is copied. Timestamps around each copy and each trace give
``last``'s GPU parts, read once after the last batch; ``last`` also has the host's.

A batch is a tiny frame graph (:func:`batch_graph`: copy the rays in, trace, copy the hits
out), compiled once; its barriers are recorded by ``vkext.accel.plan.PlanRecorder``, as the
acceleration-structure builds record theirs. Both buffers persist from batch to batch, so
the plan also orders a batch's copy of the rays after the last batch's trace read them, and
its trace after the last batch's hits were copied out. A mapped stream skips its copy, and
mapped hits are made visible to the host (``commands.written_for_host``).
"""

from __future__ import annotations

import itertools
import os
import threading
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from rfw.errors import RfwError, RfwTypeError, RfwValueError, type_name
from rfw.graph import Buffer as BufferSlot
from rfw.graph import CompiledGraph, Graph, GraphBuilder
from rfw.graph.sync import State
from rfw.scene.model import Scene

from .accel import SceneAccel
from .accel.plan import PlanRecorder, compiled
from .allocation import (
    DEVICE_LOCAL,
    HOST_CACHED,
    HOST_COHERENT,
    HOST_VISIBLE,
    DeviceMemory,
    byte_text,
    flags_of,
)
from .buffers import Buffer, staging_buffer
from .commands import (
    FENCE_TIMEOUT_NS,
    CommandPool,
    TimestampPool,
    begin_label,
    copy_to_host,
    end_label,
    written_for_host,
)
from .consts import const, ffi, lib, vk
from .device import VkDevice, VkMissingFeatureError
from .rt import BindingSet, ComputePipeline, HitGroup, RayTracingPipeline
from .sbt import ShaderBindingTable

SHADERS = Path(__file__).resolve().parent / "shaders" / "raycast"
METHODS = ("ray_query", "ray_pipeline")
DEFAULT_BATCH = 1 << 20
# Batches go SLOTS in flight: the host copies one batch's rays in and another's hits out
# while the GPU works. A cast of at most ``batch`` rays is one batch unless overlap pays
# (batch_rays): then OVERLAP_PARTS batches of at least OVERLAP_MIN rays. Overlap hides at
# most the smaller of the GPU's time and the host's copies, and each batch more costs a
# submit, a wait and smaller copies. Measured (benchmarks/bench_rt.py --sections cast,
# courtyard primary rays, medians, ms):
# - NVIDIA H200 (driver 580.159.04, 16-thread Xeon), 921,600 rays, staged: 4 batches 11.85
#   wall (into new arrays), 1 batch 5.92 (into out= arrays); mapped: 10.84 against 5.87.
#   The GPU's share is 1.3-1.7 ms (copies 0.6 + 0.35, trace 0.4), the host's copies 3-8
#   ms; 4 submits cost 1.68 ms against 0.48 for one, and the host's copies in four pieces
#   took 4.8 ms (in) and 3.0 (out, page faults of new arrays included) against 1.6 and 1.4:
#   about 2 ms a batch more (OVERLAP_BATCH_MS), for at most the GPU's 1.5 ms hidden.
# - lavapipe (2 cores; mapped, ray_query), 921,600 rays: 4 batches 348-350 ms wall (host
#   copies 14-19 in, 10-15 out; trace 340), 1 batch 313-325 (copies 5 in, 3-4 out; trace
#   303-311). The "GPU" is the host's own cores: the host's copies compete with the trace
#   instead of hiding behind it, so a CPU device never overlaps.
# So on a GPU a cast overlaps only when the last cast of at least OVERLAP_MIN rays through
# the same buffers measured GPU and host rates (timestamps; upload + readback) that put
# both over OVERLAP_PARTS * OVERLAP_BATCH_MS for this one; the first cast is one batch.
OVERLAP_PARTS, OVERLAP_MIN, SLOTS = 4, 1 << 16, 2
OVERLAP_BATCH_MS = 2.0

# raycast.glsl's streams: 4-byte words per ray, in this order
RAY_STREAMS = (("origin", 3), ("direction", 3), ("tmin", 1), ("tmax", 1))
HIT_STREAMS = (("t", 1), ("primitive", 1), ("instance", 1), ("barycentrics", 2))
RAY_WORDS, HIT_WORDS = 8, 5
# what the shaders write as the primitive of a ray they refuse (t is NaN), by argument
INVALID = {-2: ("origins", "non-finite values"), -3: ("directions", "non-finite values"),
           -4: ("directions", "zero-length rows")}

# the parts of a cast's time in Raycaster.last: summed over its batches on the host, and on
# the GPU between STAMPS timestamps per batch (before the copy in, the trace, the copy out)
HOST_PARTS = ("upload_ms", "submit_ms", "wait_ms", "readback_ms")
GPU_PARTS = ("gpu_upload_ms", "gpu_ms", "gpu_readback_ms")
STAMPS = len(GPU_PARTS) + 1

# rays and hits as records, for callers of Raycaster.trace
RAY_DTYPE = np.dtype([("origin", "<f4", 3), ("tmin", "<f4"), ("direction", "<f4", 3),
                      ("tmax", "<f4")])
HIT_DTYPE = np.dtype([("t", "<f4"), ("primitive", "<i4"), ("instance", "<i4"), ("u", "<f4"),
                      ("v", "<f4")])

# host copies of a cast are split among threads (numpy copies release the GIL): one core
# cannot fill a wide memory bus, and first touches of fresh output pages fault in parallel
COPY_THREADS = min(8, os.cpu_count() or 1)
COPY_SPLIT = 1 << 18  # bytes: the least a part gets; jobs smaller in all stay on this thread
_copy_pool: ThreadPoolExecutor | None = None
_generations = itertools.count(1)

# the pass type that traces: its shader stages read the rays and write the hits
_PASS_TYPE = {"ray_query": "compute", "ray_pipeline": "ray_tracing"}


def batch_graph(method: str) -> Graph:
    """One batch of ``method``: ``rays`` copies the rays in (buffer ``rays``), ``trace``
    reads them and writes buffer ``hits``, ``hits`` copies those out. Both buffers are
    external (persistent): a plan compiled from this starts from how the last batch left
    them."""
    g = GraphBuilder("raycast", size=(1, 1))
    g.add_pass("rays", "transfer").output(
        "rays", BufferSlot(usage=("transfer_dst",), external=True), name="rays")
    t = g.add_pass("trace", _PASS_TYPE[method])
    t.input("rays", "rays", BufferSlot(usage=("storage",)))
    t.output("hits", BufferSlot(usage=("storage",), external=True), name="hits")
    g.add_pass("hits", "transfer", side_effect=True).input(
        "hits", "hits", BufferSlot(usage=("transfer_src",)))
    return g.build()


def batch_rays(n: int, batch: int, *, device_type: str = "discrete_gpu",
               rates: tuple[float, float] | None = None) -> int:
    """Rays per batch for a cast of ``n`` rays (``n > 0``) capped at ``batch``: all of them
    (at most ``batch``) in one, or OVERLAP_PARTS batches of at least OVERLAP_MIN where
    overlap pays (see OVERLAP_BATCH_MS): on a device that is not the host's CPU
    (``device_type``, :attr:`VkDevice.device_type`), with ``rates`` measured (the GPU's
    and the host's nanoseconds per ray, :attr:`RayBuffers.rates`) that put both the GPU's
    time and the host's copies for ``n`` rays at OVERLAP_PARTS * OVERLAP_BATCH_MS or more."""
    per = min(batch, n)
    if device_type == "cpu" or rates is None or n < 2 * OVERLAP_MIN:
        return per
    if min(rates) * n / 1e6 < OVERLAP_PARTS * OVERLAP_BATCH_MS:
        return per
    return min(per, max(OVERLAP_MIN, -(-n // OVERLAP_PARTS)))


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


def parallel_copy(jobs: list[tuple[np.ndarray, np.ndarray]], *, cached: bool = True,
                  check: int | None = None) -> bool:
    """``dst[...] = src`` for every (dst, src) pair of arrays of one shape (any layout and
    real dtype: a source is converted while it is copied). Jobs of at least two
    :data:`COPY_SPLIT` in all are cut along their first axis into parts of at least that
    (up to ``2 * COPY_THREADS`` a job), which this thread and up to ``COPY_THREADS - 1``
    threads of a pool take one at a time until none is left: a thread that wakes late
    (a busy or virtual host) then copies less instead of holding everyone up, and this
    thread waits only for parts already taken. Without ``cached`` the destinations are
    written in order only (they may be write-combined memory).

    ``check`` names the job (its index) whose destination is scanned for NaN part by part
    as it lands, while in cache; returns whether it has any (False without ``check``)."""
    global _copy_pool
    copy = _copy if cached else _copy_in_order
    total = sum(dst.nbytes for dst, _ in jobs)
    if COPY_THREADS < 2 or total < 2 * COPY_SPLIT:
        parts = [(dst, src, i == check) for i, (dst, src) in enumerate(jobs)]
        return _copy_parts(copy, parts)
    parts = []
    for i, (dst, src) in enumerate(jobs):  # small streams too: they copy beside the large
        n = len(dst)
        pieces = max(1, min(2 * COPY_THREADS, dst.nbytes // COPY_SPLIT, n))
        parts += [(dst[a:b], src[a:b], i == check) for a, b in
                  ((n * k // pieces, n * (k + 1) // pieces) for k in range(pieces))]
    parts.sort(key=lambda p: -p[0].nbytes)  # the largest first: the last parts are short
    if _copy_pool is None:
        _copy_pool = ThreadPoolExecutor(COPY_THREADS - 1,
                                        thread_name_prefix="vkext-raycast-copy")
    shared = _SharedParts(copy, parts)
    for _ in range(min(COPY_THREADS - 1, len(parts) - 1)):
        _copy_pool.submit(shared.run)
    shared.run()
    return shared.wait()


class _SharedParts:
    """Parts that threads take one at a time (``next`` on a list's iterator holds the GIL,
    so each part goes to one thread); :meth:`wait` returns once every part is copied."""

    def __init__(self, copy: Any, parts: list[tuple[np.ndarray, np.ndarray, bool]]):
        self.copy, self.parts, self.left = copy, iter(parts), len(parts)
        self.lock, self.done = threading.Lock(), threading.Event()
        self.nan, self.error = False, None

    def run(self) -> None:
        for part in self.parts:
            nan, error = False, None
            try:
                nan = _copy_parts(self.copy, [part])
            except BaseException as e:  # handed to the waiting thread
                error = e
            with self.lock:
                self.nan |= nan
                self.error = self.error or error
                self.left -= 1
                if self.left == 0:
                    self.done.set()

    def wait(self) -> bool:
        self.done.wait()
        if self.error is not None:
            raise self.error
        return self.nan


def _copy_parts(copy: Any, parts: list[tuple[np.ndarray, np.ndarray, bool]]) -> bool:
    nan = False
    for dst, src, checked in parts:
        copy(dst, src)
        # min() propagates NaN: one pass over the part while it is in cache
        nan = nan or bool(checked and len(dst) and np.isnan(dst.min()))
    return nan


def _copy(dst: np.ndarray, src: np.ndarray) -> None:
    if src.ndim == 2 and 0 < src.strides[0] < src.strides[1]:
        # column-major rows (a transpose's): column by column reads each one in order,
        # about twice as fast as numpy's element order for (N, 3)
        for j in range(src.shape[1]):
            np.copyto(dst[:, j], src[:, j], casting="unsafe")
        return
    _copy_in_order(dst, src)


def _copy_in_order(dst: np.ndarray, src: np.ndarray) -> None:
    # unsafe: float64 and integer rays round to float32 as astype would
    np.copyto(dst, src, casting="unsafe")


def mapped_type_bits(device: VkDevice, *, readback: bool) -> int:
    """The memory types (as bits) that suit a mapped stream: host-visible and coherent and
    device-local, and for one the host reads (``readback``) also host-cached (uncached
    reads are slow); for reads without such memory, any host-cached type."""
    need = [DEVICE_LOCAL, HOST_VISIBLE, HOST_COHERENT] + [HOST_CACHED] * readback
    bits = _type_bits(device, need)
    return bits or (_type_bits(device, [HOST_VISIBLE, HOST_COHERENT, HOST_CACHED])
                    if readback else 0)


def _type_bits(device: VkDevice, names: list[str]) -> int:
    need = flags_of(names)
    return sum(1 << i for i, (props, _) in enumerate(device.memory_types)
               if props & need == need)


# RFW_RAYCAST_MAPPED: which streams the trace reads and writes in mapped memory; "host":
# both, the rays too in host-cached memory (see rays_in_host_memory)
PLACEMENTS = {"0": (False, False), "1": (True, True), "rays": (True, False),
              "hits": (False, True), "host": (True, True)}


def mapped_streams(device: VkDevice) -> tuple[bool, bool]:
    """Whether casts on ``device`` map (rays, hits) rather than stage them (see
    :class:`RayBuffers`). ``RFW_RAYCAST_MAPPED`` says so: ``0`` (neither), ``1`` (both),
    ``rays``, ``hits`` or ``host`` (both, see :func:`rays_in_host_memory`); unset (or
    ``auto``) both where memory is device-local, host-visible and host-cached at once
    (unified memory: no copy is worth making), else neither: a discrete GPU stages."""
    from rfw import env

    value = env.get("RFW_RAYCAST_MAPPED")  # PLACEMENTS or auto, checked there
    if value != "auto":
        return PLACEMENTS[value]
    unified = bool(_type_bits(device, [DEVICE_LOCAL, HOST_VISIBLE, HOST_COHERENT,
                                       HOST_CACHED]))
    return unified, unified


def rays_in_host_memory() -> bool:
    """Whether mapped rays go to host-cached memory (``RFW_RAYCAST_MAPPED=host``) rather
    than device-local host-visible memory where there is such. On a discrete GPU the host
    then writes them at the speed of its own memory, as into a staging buffer, and the
    trace reads them across the bus instead of a copy doing so first (the H200 at 921,600
    rays: the staged copy in took 0.62 ms of GPU time, writing device-local host-visible
    memory 2.64 ms of host time against 1.63 for host-cached staging)."""
    from rfw import env

    return env.get("RFW_RAYCAST_MAPPED") == "host"


def hit_arrays(n: int, names: Any, out: dict[str, np.ndarray] | None = None,
               ) -> dict[str, np.ndarray]:
    """Arrays for ``n`` hits of the streams in ``names``: those in ``out`` (checked:
    C-contiguous and writable, of the stream's dtype and shape), new ones for the rest."""
    arrays = {}
    for name, width in HIT_STREAMS:
        if name not in names:
            continue
        shape = (n, width) if width > 1 else (n,)
        dtype = np.dtype(np.float32 if name in ("t", "barycentrics") else np.int32)
        given = (out or {}).get(name)
        if given is None:
            arrays[name] = np.empty(shape, dtype)
            continue
        if not (isinstance(given, np.ndarray) and given.dtype == dtype and given.shape == shape
                and given.flags.c_contiguous and given.flags.writeable):
            raise RfwError(f"out['{name}'] must be a writable C-contiguous {dtype} array of "
                           f"shape {shape}, got {_describe(given)}")
        arrays[name] = given
    return arrays


def _describe(a: Any) -> str:
    if not isinstance(a, np.ndarray):
        return type(a).__name__
    layout = "" if a.flags.c_contiguous else " not C-contiguous"
    return f"{a.dtype} {a.shape}{layout}{'' if a.flags.writeable else ' read-only'}"


def check_rays(origins: np.ndarray, directions: np.ndarray) -> None:
    """On the host what the shaders check per ray (for casts that trace nothing)."""
    for name, arr in (("origins", origins), ("directions", directions)):
        bad = ~np.isfinite(arr).all(axis=1)
        if bad.any():
            raise RfwError(f"{name} has non-finite values (first in row {int(np.argmax(bad))})")
    zero = ~directions.any(axis=1)
    if zero.any():
        raise RfwError(f"directions has zero-length rows (first: {int(np.argmax(zero))})")


def _check_traced(t: np.ndarray, primitive: np.ndarray) -> None:
    # a refused ray is the only NaN t, and min() propagates NaN: one pass over t
    if len(t) and np.isnan(t.min()):
        first = int(np.argmax(np.isnan(t)))
        name, what = INVALID.get(int(primitive[first]), ("rays", "a ray the GPU refused"))
        where = "first: " if what == "zero-length rows" else "first in row "
        raise RfwError(f"{name} has {what} ({where}{first})")


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


def device_lock(device: VkDevice) -> threading.RLock:
    """The lock of ray casting on ``device``: a cast records into the raycaster's command
    buffers, reuses its fences and submits to the device's one queue, none of which may be
    used by two threads at once (Vulkan's external synchronization). Casts from several
    threads take turns; each gets the hits a cast alone would."""
    return device.raycast_lock


def raycaster(device: VkDevice, method: str = "auto") -> Raycaster:
    """The device's :class:`Raycaster` for ``method``, created on first use and kept (its
    pipeline takes longest to make); the device destroys it with everything else."""
    method = pick_method(device, method)
    with device_lock(device):  # two threads' first scenes make one raycaster
        cache = device.raycasters
        rc = cache.get(method)
        if rc is None or rc.pipeline is None:
            rc = cache[method] = Raycaster(device, method)
        return rc


def check_device(device: Any) -> VkDevice:
    """``device`` if it is a live :class:`VkDevice`, else an RfwError naming it."""
    if not isinstance(device, VkDevice):
        raise RfwTypeError(f"'device' must be a vkext.VkDevice (or None: the default), not "
                           f"{type_name(device)}")
    if not device.alive:
        raise RfwValueError("'device' was destroyed: make a new vkext.VkDevice")
    return device


class RayScene:
    """A scene ready for many casts: its acceleration structures (``builds`` counts them:
    one), the device's :class:`Raycaster` and :class:`RayBuffers` kept between casts.

    A scene without triangles or instances builds nothing and every ray misses. Registered
    with the device, so it dies with it at the latest; :meth:`destroy` frees it sooner."""

    def __init__(self, device: VkDevice, scene: Scene, *, method: str = "auto",
                 batch: int = DEFAULT_BATCH, label: str = "raycast"):
        if batch < 1:
            raise ValueError(f"batch must be positive, got {batch}")
        self.device, self.batch, self.label = check_device(device), int(batch), label
        self.caster = raycaster(device, method)  # a method the device lacks fails here
        self.lock = device_lock(device)
        self._last: dict[str, Any] = {}
        self.method = self.caster.method
        self.accel: SceneAccel | None = None
        self.buffers: RayBuffers | None = None
        self.builds = 0
        self.closed = False
        empty = all(len(m.indices) == 0 for m in scene.meshes) or not scene.instances
        if not empty:
            self.accel = SceneAccel(device, scene, label=label)
            self.builds += 1
            self.buffers = RayBuffers(self.caster, self.accel.tlas, label=label)
        device.register(self)

    @property
    def allocations(self) -> int:
        """How many times ray and hit buffers were made (once, then once per growth)."""
        return self.buffers.allocations if self.buffers is not None else 0

    def cast(self, origins: np.ndarray, directions: np.ndarray, tmin: Any = 0.0,
             tmax: Any = np.inf, *, hits: tuple[str, ...] = ("t", "primitive", "instance",
                                                             "barycentrics"),
             out: dict[str, np.ndarray] | None = None) -> dict[str, np.ndarray]:
        """:meth:`Raycaster.cast` against this scene (see there for the arguments)."""
        if self.accel is None:  # nothing to hit: no GPU work, so the host checks the rays
            origins, directions = (np.asarray(a, np.float32) for a in (origins, directions))
            check_rays(origins, directions)
            arrays = hit_arrays(len(origins), hits, out)
            for name, value in (("t", np.inf), ("primitive", -1), ("instance", -1),
                                ("barycentrics", 0.0)):
                if name in arrays:
                    arrays[name][...] = value
            self._last = {"method": self.method, "rays": len(origins), "batches": 0}
            return {k: arrays[k] for k in hits}
        with self.lock:  # the caster is the device's: its last is this cast's only here
            if self.closed:  # closed by another thread while this one waited
                raise RfwError("the ray scene is closed: make a new rfw.RayScene")
            got = self.caster.cast(self.accel, self.buffers, origins, directions, tmin,
                                   tmax, batch=self.batch, hits=hits, out=out)
            self._last = dict(self.caster.last)
            return got

    @property
    def last(self) -> dict[str, Any]:
        """This scene's last cast's counts and times (see :attr:`Raycaster.last`)."""
        return dict(self._last)

    def destroy(self) -> None:
        with self.lock:  # never while another thread's cast uses the buffers
            self.closed = True
            if self.buffers is not None:
                self.buffers.destroy()
                self.buffers = None
            if self.accel is not None:
                self.accel.destroy()
                self.accel = None
            self.device.unregister(self)
