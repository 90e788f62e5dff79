"""Casts whose rays and hits stay on the GPU: :class:`SharedRays`, the ray and hit buffers of
a scene exported to CUDA (``vkext.external``), and :func:`cast_shared`, one cast through them.

The caller's CUDA rays are copied device to device (``cuMemcpyDtoDAsync``, or a strided
view gathered by one kernel launch: ``rfw.interop.gather_of``; after ``cuCtxSynchronize`` so
every stream's writes landed) into the exported ray buffer, which the
trace reads as it is; the trace writes the exported hit buffer, and the hits go back as
zero-copy :class:`rfw.interop.DeviceArray` views of it once the fence is waited for. Nothing
is mapped, staged or copied to the host. All rays of a cast are one dispatch (the buffers
grow to the largest cast, never shrink). The buffers change hands by queue-family transfers
(acquired from the external world before the trace, released after).

:meth:`SharedRays.device_rays` hands the ray buffer itself out as writable device arrays: a
cast of exactly those views (:meth:`SharedRays.in_place`) copies nothing in and needs one
``cuCtxSynchronize`` (the caller's writes landed). The command buffer is recorded once per
buffer, size and interval; the submit and the fence wait go straight to the loader
(``Submitter``); the GPU time is read from the timestamps only when ``last`` is asked for.
``last["phases_us"]`` has the cast's own clock: copy in, record, submit and wait, hit views.

Rays the shaders refuse (non-finite origin or direction, zero direction) are not checked on
the host (that would read the hits back): their ``t`` is NaN and ``primitive`` the code of
``streams.INVALID`` (-2, -3, -4).
"""

from __future__ import annotations

import ctypes
import time
from typing import Any

import numpy as np

from rfw.errors import RfwError
from rfw.interop import CudaView, DeviceArray, copies, cuda, gather_of

from ..commands import TimestampPool
from ..external import CudaLink, ExportedBuffer, Submitter, cuda_link, ownership
from ..rt import BindingSet
from .streams import HIT_STREAMS, HIT_WORDS, RAY_WORDS

HIT_DTYPES = {"t": np.float32, "primitive": np.int32, "instance": np.int32,
              "barycentrics": np.float32}


class SharedRays:
    """A scene's exported ray and hit buffers and the command buffer casting through them
    (recorded again only when the cast differs from the last: size, intervals, buffers)."""

    def __init__(self, caster: Any, tlas: Any, link: CudaLink, *, label: str = "raycast"):
        self.caster, self.device, self.tlas, self.link = caster, caster.device, tlas, link
        self.label = label
        self.capacity = self.generation = 0
        self.rays = self.hits = self.set = None
        self._views: tuple[Any, dict[str, DeviceArray]] | None = None
        self._rays: tuple[Any, tuple[Any, Any]] | None = None
        self.submitter = Submitter(self.device, label=f"{label}:shared")
        # stamps: before the acquire, before the trace, after it, after the release
        self.timer = TimestampPool(self.device, 4, label=f"{label}:shared timestamps") \
            if "timestamp" in self.device.caps else None

    def reserve(self, n: int) -> None:
        if n <= self.capacity:
            return
        self._release()
        self.rays = ExportedBuffer(self.device, n * RAY_WORDS * 4, ("storage",),
                                   link=self.link, label=f"{self.label}.shared rays")
        self.hits = ExportedBuffer(self.device, n * HIT_WORDS * 4, ("storage",),
                                   link=self.link, label=f"{self.label}.shared hits")
        self.set = BindingSet(self.caster.pipeline.layout,
                              label=f"{self.label}:shared descriptors")
        self.set.write(tlas=self.tlas, rays=self.rays.binding(), hits=self.hits.binding())
        self.capacity, self.generation = n, self.generation + 1

    def record(self, n: int, sbt: Any, per_ray: bool, tmin: float, tmax: float) -> None:
        key = (self.generation, n, per_ray, tmin, tmax, id(sbt))
        if self.submitter.key == key:
            return
        cmd = self.submitter.begin()
        shared = [self.rays, self.hits]
        timer = self.timer
        if timer is not None:
            timer.reset(cmd)
            timer.write(cmd, "ALL_COMMANDS", 0)
        ownership(self.device, cmd, shared, acquire=True)
        if timer is not None:
            timer.write(cmd, "ALL_COMMANDS", 1)
        self.caster._record(cmd, self.set, sbt, n, per_ray, tmin, tmax)
        if timer is not None:
            timer.write(cmd, "ALL_COMMANDS", 2)
        ownership(self.device, cmd, shared, acquire=False)
        if timer is not None:
            timer.write(cmd, "ALL_COMMANDS", 3)
        self.submitter.end(key)

    def gpu_parts(self) -> dict[str, float] | None:
        """The last cast's GPU ms: the trace (``gpu_ms``), the acquire barrier before it and
        the release after it (``gpu_acquire_ms``, ``gpu_release_ms``)."""
        if self.timer is None:
            return None
        a, b, c, d = (int(x) for x in self.timer.results(0, 4))
        return {"gpu_ms": max(0, c - b) / 1e6, "gpu_acquire_ms": max(0, b - a) / 1e6,
                "gpu_release_ms": max(0, d - c) / 1e6}

    @property
    def base(self) -> int:
        """Where the ray buffer starts as callers' arrays point at it: the CUDA pointer,
        or without a link (lavapipe) the host address of its memfd mapping."""
        if self.rays.cuda_ptr is not None:
            return self.rays.cuda_ptr
        return int(self.rays.host_view().ctypes.data)

    def device_rays(self, n: int) -> tuple[Any, Any]:
        """(origins, directions): writable (n, 3) float32 views of the ray buffer itself,
        where a cast of ``n`` rays reads them (made once per buffer and size). A cast of
        exactly these views copies nothing in (:meth:`in_place`). Zero-copy
        :class:`DeviceArray` with a link; without one (lavapipe) host arrays of the
        buffer's memfd mapping, for tests."""
        self.reserve(max(n, 1))
        key = (self.generation, n)
        if self._rays is not None and self._rays[0] == key:
            return self._rays[1]
        if self.rays.cuda_ptr is not None:
            pair = (self.rays.array(0, (n, 3), np.float32),
                    self.rays.array(12 * n, (n, 3), np.float32))
        else:
            words = self.rays.host_view().view(np.float32)
            pair = tuple(DeviceArray.of_host(words[k * 3 * n:(k + 1) * 3 * n].reshape(n, 3))
                         for k in (0, 1))
        self._rays = (key, pair)
        return pair

    def in_place(self, n: int, origins: Any, directions: Any) -> bool:
        """Whether ``origins``/``directions`` (CudaView or DeviceArray) are the ray
        buffer's own (n, 3) views where a cast of ``n`` rays reads them: nothing to copy."""
        if self.rays is None or n > self.capacity:
            return False
        base = self.base
        for view, at in ((origins, base), (directions, base + 12 * n)):
            if getattr(view, "ptr", None) != at or tuple(view.shape) != (n, 3) \
                    or getattr(view, "strides", None) is not None:
                return False
        return True

    def hit_views(self, n: int, names: tuple[str, ...]) -> dict[str, DeviceArray]:
        """The views of ``n`` hits, made once per buffer and size (the same memory)."""
        key = (self.generation, n, names)
        if self._views is not None and self._views[0] == key:
            return dict(self._views[1])
        out, at = {}, 0
        for name, width in HIT_STREAMS:
            if name in names:
                shape = (n, width) if width > 1 else (n,)
                out[name] = self.hits.array(at, shape, HIT_DTYPES[name])
            at += width * n * 4
        views = {k: out[k] for k in names}
        self._views = (key, views)
        return dict(views)

    def _release(self) -> None:
        # arrays handed out keep their buffers alive; the scene lets go of them here
        for buf in (self.rays, self.hits):
            if buf is not None:
                buf.release()
        if self.set is not None:
            self.set.destroy()
        self.rays = self.hits = self.set = None
        self._views = None
        self.capacity = 0

    def destroy(self) -> None:
        self._release()
        if self.timer is not None:
            self.timer.destroy()
            self.timer = None
        self.submitter.destroy()


def link_of(device: Any) -> CudaLink:
    link = cuda_link(device)
    if not isinstance(link, CudaLink):
        raise RfwError(f"device arrays need a Vulkan device that shares memory with CUDA: "
                       f"{link}")
    return link


def _check_on(name: str, view: Any, link: CudaLink, device_name: str) -> None:
    if isinstance(view, CudaView) and view.ordinal != link.ordinal:
        raise RfwError(f"{name} is on cuda:{view.ordinal}, but the ray scene's device "
                       f"({device_name}) is cuda:{link.ordinal}: move it there first "
                       f"(e.g. tensor.to('cuda:{link.ordinal}'))")


def cast_shared(scene: Any, origins: CudaView | np.ndarray, directions: CudaView | np.ndarray,
                tmin: Any, tmax: Any, hits: tuple[str, ...]) -> dict[str, DeviceArray]:
    """One cast of ``scene`` (a ``vkext.raycast.RayScene``) whose hits stay on the GPU.

    ``origins``/``directions``: (R, 3) float32 as :class:`CudaView` (copied device to device)
    or host arrays (copied host to device); ``tmin``/``tmax``: numbers, or (R,) float32 as
    :class:`CudaView` or host arrays. Returns zero-copy views of the scene's hit buffer,
    overwritten by its next cast."""
    device = scene.device
    link = link_of(device)
    for name, v in (("origins", origins), ("directions", directions), ("t_min", tmin),
                    ("t_max", tmax)):
        _check_on(name, v, link, device.name)
    n = len(origins) if isinstance(origins, np.ndarray) else origins.shape[0]
    drv = cuda()
    clock = time.perf_counter_ns
    with scene.lock:
        if scene.closed:
            raise RfwError("the ray scene is closed: make a new rfw.RayScene")
        t0 = clock()
        if scene.accel is None:  # nothing to hit: misses written on the host
            return _misses(scene, n, hits)
        shared = scene.shared_rays(link)
        shared.reserve(max(n, 1))
        per_ray = not (np.ndim(tmin) == 0 and not isinstance(tmin, CudaView)
                       and np.ndim(tmax) == 0 and not isinstance(tmax, CudaView))
        base = shared.rays.cuda_ptr
        own = shared.in_place(n, origins, directions)  # scene.device_rays: nothing to copy
        jobs = [] if own else [(origins, 0), (directions, 12 * n)]
        if per_ray:
            jobs += [(_stream(tmin, n), 24 * n), (_stream(tmax, n), 28 * n)]
        with drv.push(link.ordinal):
            # the caller's work on any stream is done (its writes into device_rays included)
            drv.call("cuCtxSynchronize")
            t_sync = clock()
            for src, offset in jobs:
                if isinstance(src, CudaView):  # strided views gathered by a kernel
                    drv.gather(gather_of(src.ptr, src.shape, src.strides, base + offset),
                               link.ordinal)
                    copies["device_to_device"] += 1
                else:  # the context is current: the copy alone (CudaDriver.copy_htod)
                    src = np.ascontiguousarray(src, np.float32)
                    drv.call("cuMemcpyHtoD_v2", ctypes.c_ulonglong(base + offset),
                             ctypes.c_void_p(src.ctypes.data), ctypes.c_size_t(src.nbytes))
                    copies["host_to_device"] += 1
            t_copies = clock()
            if jobs:
                drv.call("cuCtxSynchronize")  # the copies landed before Vulkan reads
        t_in = clock()
        sbt = scene.caster._table(scene.accel.hit_records) \
            if scene.method == "ray_pipeline" else None
        lo, hi = (0.0, 0.0) if per_ray else (float(tmin), float(tmax))
        shared.record(n, sbt, per_ray, lo, hi)
        t_rec = clock()
        shared.submitter.run()
        done = clock()
        out = shared.hit_views(n, hits)
        t_out = clock()
        # gpu_ms is read from the timestamps when `last` is asked for (RayScene.last), not
        # here: vkGetQueryPoolResults is a wrapped call the cast need not wait for
        scene._last = {"method": scene.method, "rays": n, "batches": 1, "path": "zero_copy",
                       "rays_in_place": own, "wall_ms": (done - t0) / 1e6,
                       "copy_in_ms": (t_in - t0) / 1e6, "submit_wait_ms": (done - t_in) / 1e6,
                       "phases_us": {"copy_in": (t_in - t0) / 1e3,
                                     "copy_in_first_sync": (t_sync - t0) / 1e3,
                                     "copy_in_queue_copies": (t_copies - t_sync) / 1e3,
                                     "copy_in_last_sync": (t_in - t_copies) / 1e3,
                                     "record": (t_rec - t_in) / 1e3,
                                     "submit_wait": (done - t_rec) / 1e3,
                                     "hit_views": (t_out - done) / 1e3}}
        scene._pending_gpu = shared if shared.timer is not None else None
        return out


def _stream(x: Any, n: int) -> Any:
    """A per-ray interval: a CudaView as it is, else (n,) float32 on the host."""
    if isinstance(x, CudaView):
        return x
    return np.ascontiguousarray(np.broadcast_to(np.asarray(x, np.float32), (n,)))


def _misses(scene: Any, n: int, hits: tuple[str, ...]) -> dict[str, Any]:
    from .streams import fill_misses, hit_arrays

    arrays = fill_misses(hit_arrays(n, hits))
    scene._last = {"method": scene.method, "rays": n, "batches": 0, "path": "host"}
    return {k: DeviceArray.of_host(arrays[k]) for k in hits}
