"""Closest-hit ray casting against a :class:`SceneAccel`, by ray query or ray-tracing pipeline.

Two ways to the same answer, so either can be checked against the other and against a CPU
reference (``rfw.raycast`` is the numpy front end):

- ``"ray_query"``: a compute shader with ``GL_EXT_ray_query`` (``raycast.comp.glsl``);
- ``"ray_pipeline"``: raygen + miss + closest hit through a shader binding table and
  ``vkCmdTraceRaysKHR``; it needs no ray-query support (NVIDIA drivers may offer pipelines
  only).

Rays go through in batches of at most ``batch`` rays: per batch one submit copies the rays
from a staging buffer to device-local memory, traces, and copies the hits back, so memory
stays bounded (about 100 bytes a ray of the batch, staging included) for any ray count.
Timestamps around each trace (the copies excluded) give ``last["gpu_ms"]`` and Mrays/s.

A batch is a tiny frame graph (:func:`batch_graph`: copy the rays in, trace, copy the hits
out), compiled once; its barriers are recorded by ``vkext.accel.plan.PlanRecorder``, as the
acceleration-structure builds record theirs. Both buffers persist from batch to batch, so
the plan also orders a batch's copy of the rays after the last batch's trace read them, and
its trace after the last batch's hits were copied out.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from rfw.graph import Buffer as BufferSlot
from rfw.graph import CompiledGraph, Graph, GraphBuilder

from .accel import SceneAccel
from .accel.plan import PlanRecorder, compiled
from .commands import TimestampPool, copy_to_host, one_time
from .consts import ffi, lib, vk
from .device import VkDevice, VkMissingFeatureError
from .memory import Buffer, staging_buffer
from .rt import BindingSet, ComputePipeline, HitGroup, RayTracingPipeline
from .sbt import ShaderBindingTable

SHADERS = Path(__file__).resolve().parent / "shaders" / "raycast"
METHODS = ("ray_query", "ray_pipeline")
DEFAULT_BATCH = 1 << 20

# the std430 twins of raycast.glsl's Ray and Hit
RAY_DTYPE = np.dtype([("origin", "<f4", 3), ("tmin", "<f4"), ("direction", "<f4", 3),
                      ("tmax", "<f4")])
HIT_DTYPE = np.dtype([("t", "<f4"), ("primitive", "<i4"), ("instance", "<i4"), ("u", "<f4"),
                      ("v", "<f4")])
assert RAY_DTYPE.itemsize == 32 and HIT_DTYPE.itemsize == 20

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


class Raycaster:
    """The pipeline of one method on a device; :meth:`trace` casts rays against a scene's
    acceleration structures. Registered with the device, so it dies with it at the latest."""

    def __init__(self, device: VkDevice, method: str = "auto", *, label: str = "raycast"):
        device.require("VK_KHR_acceleration_structure")
        self.device, self.label = device, label
        self.method = pick_method(device, method)
        self.pipeline: ComputePipeline | RayTracingPipeline | None = None
        self._tables: dict[int, ShaderBindingTable] = {}  # by hit-record count
        self.timer = None
        self.last: dict[str, Any] = {}
        self.plan: CompiledGraph = compiled(batch_graph(self.method))
        try:
            if self.method == "ray_query":
                self.pipeline = ComputePipeline(device, SHADERS / "raycast.comp.glsl",
                                                label=f"{label}:ray_query")
            else:
                self.pipeline = RayTracingPipeline(
                    device, SHADERS / "raycast.rgen.glsl", [SHADERS / "raycast.rmiss.glsl"],
                    [HitGroup(closest=SHADERS / "raycast.rchit.glsl")],
                    label=f"{label}:ray_pipeline")
            if "timestamp" in device.caps:
                self.timer = TimestampPool(device, 2, label=f"{label}:timestamps")
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

    def trace(self, accel: SceneAccel, rays: np.ndarray, *,
              batch: int = DEFAULT_BATCH) -> np.ndarray:
        """Closest hits of ``rays`` (a :data:`RAY_DTYPE` array) as a :data:`HIT_DTYPE` array.

        ``last`` then holds the ray and batch counts and, with timestamps, the GPU time of
        the traces alone (``gpu_ms``) and ``mrays_per_s``; ``wall_ms`` is the host's time for
        everything (copies and waits included)."""
        rays = np.ascontiguousarray(rays)
        if rays.dtype != RAY_DTYPE or rays.ndim != 1:
            raise ValueError(f"rays must be a 1-D array of RAY_DTYPE, got {rays.dtype} "
                             f"{rays.shape}")
        if batch < 1:
            raise ValueError(f"batch must be positive, got {batch}")
        n = len(rays)
        out = np.empty(n, HIT_DTYPE)
        self.last = {"method": self.method, "rays": n, "batches": 0}
        if n == 0:
            return out
        dev = self.device
        per = min(batch, n)
        wall = time.perf_counter()
        made: list[Any] = []
        try:
            ray_buf = Buffer(dev, per * RAY_DTYPE.itemsize, ("storage", "transfer_dst"),
                             label=f"{self.label}.rays")
            made.append(ray_buf)
            ray_buf.allocate()
            hit_buf = Buffer(dev, per * HIT_DTYPE.itemsize, ("storage", "transfer_src"),
                             label=f"{self.label}.hits")
            made.append(hit_buf)
            hit_buf.allocate()
            ray_up = staging_buffer(dev, ray_buf.bytes, label=f"{self.label}:rays upload")
            made.append(ray_up)
            hit_down = staging_buffer(dev, hit_buf.bytes, readback=True,
                                      label=f"{self.label}:hits readback")
            made.append(hit_down)
            bindings = BindingSet(self.pipeline.layout, label=f"{self.label}:descriptors")
            made.append(bindings)
            bindings.write(tlas=accel.tlas, rays=ray_buf, hits=hit_buf)
            sbt = self._table(accel.hit_records) if self.method == "ray_pipeline" else None
            gpu_ns = 0
            for start in range(0, n, per):
                k = min(per, n - start)
                ray_up.write(rays[start:start + k])
                with one_time(dev, label=f"{self.label}: {k} rays") as cmd:
                    self._record_batch(cmd, PlanRecorder(self.plan), k, bindings, sbt,
                                       ray_up, ray_buf, hit_buf, hit_down)
                out[start:start + k] = hit_down.read(HIT_DTYPE, k)
                if self.timer is not None:
                    t0, t1 = self.timer.results()
                    gpu_ns += t1 - t0
                self.last["batches"] += 1
        finally:
            for obj in reversed(made):
                obj.destroy()
        self.last["wall_ms"] = (time.perf_counter() - wall) * 1e3
        if self.timer is not None:
            self.last["gpu_ms"] = gpu_ns / 1e6
            self.last["mrays_per_s"] = n / max(gpu_ns, 1) * 1e3
        return out

    def _record_batch(self, cmd: Any, plan: PlanRecorder, k: int, bindings: BindingSet,
                      sbt: ShaderBindingTable | None, ray_up: Buffer, ray_buf: Buffer,
                      hit_buf: Buffer, hit_down: Buffer) -> None:
        # the work of each pass of batch_graph, behind the barriers its plan puts before it
        plan.enter(cmd, "rays")
        copy = ffi.new("VkBufferCopy*")
        copy.size = k * RAY_DTYPE.itemsize
        lib.vkCmdCopyBuffer(cmd, ray_up.handle, ray_buf.handle, 1, copy)
        plan.enter(cmd, "trace")
        if self.timer is not None:
            self.timer.reset(cmd)
            self.timer.write(cmd, "ALL_COMMANDS", 0)
        self._record(cmd, bindings, sbt, k)
        if self.timer is not None:
            self.timer.write(cmd, "ALL_COMMANDS", 1)
        plan.enter(cmd, "hits")
        copy_to_host(cmd, hit_buf, hit_down, k * HIT_DTYPE.itemsize)

    def _record(self, cmd: Any, bindings: BindingSet, sbt: ShaderBindingTable | None,
                count: int) -> None:
        pipe = self.pipeline
        vk.vkCmdBindPipeline(cmd, pipe.bind_point, pipe.handle)
        bindings.bind(cmd, pipe.bind_point)
        layout = pipe.layout
        if layout.push_size:
            data = ffi.new("uint32_t[1]", [count])
            lib.vkCmdPushConstants(cmd, layout.handle, layout.push_stages, 0, 4, data)
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
        self.device.unregister(self)


def raycaster(device: VkDevice, method: str = "auto") -> Raycaster:
    """The device's :class:`Raycaster` for ``method``, created on first use and kept (its
    pipeline takes longest to make); the device destroys it with everything else."""
    method = pick_method(device, method)
    cache = device.__dict__.setdefault("_rfw_raycasters", {})
    rc = cache.get(method)
    if rc is None or rc.pipeline is None:
        rc = cache[method] = Raycaster(device, method)
    return rc
