"""The device's raycasters (:func:`raycaster`, made once per method and kept) and
:class:`RayScene`, a scene ready for many casts: what ``rfw.RayScene`` and ``rfw.raycast``
run on."""

from __future__ import annotations

from typing import Any

import numpy as np

from rfw.errors import RfwError, RfwTypeError, RfwValueError, type_name
from rfw.scene.model import Scene

from ..accel import SceneAccel
from ..device import VkDevice
from .batches import DEFAULT_BATCH
from .caster import RayBuffers, Raycaster, device_lock, pick_method
from .streams import check_rays, fill_misses, hit_arrays


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
        self.shared = None  # .shared.SharedRays, made by the first device cast
        self._pending_gpu = None  # the SharedRays whose timestamps `last` still has to read
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
            arrays = fill_misses(hit_arrays(len(origins), hits, out))
            self._last = {"method": self.method, "rays": len(origins), "batches": 0}
            self._pending_gpu = None
            return {k: arrays[k] for k in hits}
        with self.lock:  # the caster is the device's: its last is this cast's only here
            if self.closed:  # closed by another thread while this one waited
                raise RfwError("the ray scene is closed: make a new rfw.RayScene")
            got = self.caster.cast(self.accel, self.buffers, origins, directions, tmin,
                                   tmax, batch=self.batch, hits=hits, out=out)
            self._last = dict(self.caster.last)
            self._pending_gpu = None
            return got

    @property
    def last(self) -> dict[str, Any]:
        """This scene's last cast's counts and times (see :attr:`Raycaster.last`)."""
        with self.lock:
            shared, self._pending_gpu = self._pending_gpu, None
            if shared is not None and shared is self.shared:  # the last device cast's
                parts = shared.gpu_parts()
                self._last.update(parts, mrays_per_s=self._last["rays"]
                                  / max(parts["gpu_ms"], 1e-9) / 1e3)
            return dict(self._last)

    def device_rays(self, n: int) -> tuple[Any, Any]:
        """(origins, directions): writable (n, 3) float32 device arrays that are this
        scene's exported ray buffer (:meth:`.shared.SharedRays.device_rays`): write rays
        into them (``torch.from_dlpack(o).copy_(...)``) and :meth:`cast_device` them, and
        nothing is copied in. Valid until a cast of more rays grows the buffer (older views
        then still work, copied like any caller's array)."""
        with self.lock:
            if self.closed:
                raise RfwError("the ray scene is closed: make a new rfw.RayScene")
            if self.accel is None:
                raise RfwError("a ray scene with nothing to hit has no ray buffer")
            return self.shared_rays().device_rays(n)

    def shared_rays(self, link: Any = None) -> Any:
        """The scene's :class:`.shared.SharedRays` (made on first use; ``link``: the device's
        CUDA link where the caller has it), under :attr:`lock`, with something to hit."""
        if self.shared is None:
            from .shared import SharedRays, link_of

            self.shared = SharedRays(self.caster, self.accel.tlas,
                                     link if link is not None else link_of(self.device),
                                     label=self.label)
        return self.shared

    def sharing(self) -> str | None:
        """None where casts can keep rays and hits on the GPU (the device shares memory
        with CUDA: :func:`vkext.external.cuda_link`), else one line saying why not."""
        from ..external import CudaLink, cuda_link

        link = cuda_link(self.device)
        return None if isinstance(link, CudaLink) else link

    def cast_device(self, origins: Any, directions: Any, tmin: Any = 0.0, tmax: Any = np.inf,
                    *, hits: tuple[str, ...] = ("t", "primitive", "instance", "barycentrics"),
                    ) -> dict[str, Any]:
        """A cast whose hits stay on the GPU (:func:`.shared.cast_shared`): zero-copy
        ``rfw.interop.DeviceArray`` views, overwritten by this scene's next device cast."""
        from .shared import cast_shared

        return cast_shared(self, origins, directions, tmin, tmax, hits)

    def destroy(self) -> None:
        with self.lock:  # never while another thread's cast uses the buffers
            self.closed = True
            if self.shared is not None:
                self.shared.destroy()
                self.shared = None
            if self.buffers is not None:
                self.buffers.destroy()
                self.buffers = None
            if self.accel is not None:
                self.accel.destroy()
                self.accel = None
            self.device.unregister(self)
