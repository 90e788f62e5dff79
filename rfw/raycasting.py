"""``rfw.RayScene`` and ``rfw.raycast``: closest hits of many rays against triangles, on the GPU.

Defined here and exported lazily by ``rfw`` (``rfw.RayScene``, ``rfw.raycast``); the module has
another name so that importing it never turns the attribute ``rfw.raycast`` into a module.

The numpy face of a backend's ray casting: check the arrays, hand them to the first
installed backend (``rfw.backends`` entry points) that has a ``ray_scene`` method (``vk``:
``vkext.backend.VkBackend.ray_scene``), hand back arrays. rfw imports no backend itself, so
``import rfw`` never loads Vulkan.

A :class:`RayScene` builds its acceleration structures once and keeps them, with the ray
and hit buffers, for every :meth:`RayScene.cast`; :func:`raycast` is the one-shot
convenience (a scene made, cast once and closed). The default device is made on first use
and destroyed at exit. Rays are checked where the GPU reads them (finite origins and
directions, no zero direction): a bad ray is not traced and the cast raises naming the
argument and the first bad row, as it does for shapes and dtypes before any GPU work.
"""

from __future__ import annotations

import atexit
import threading
from typing import Any

import numpy as np

from . import interop
from .backend import Backend, get_backend, installed
from .errors import RfwError, RfwTypeError, RfwValueError, check_type, type_name
from .options import RunOptions
from .scene.model import Instance, Mesh, Scene

_default_device: Any = None
_default_lock = threading.Lock()  # two threads' first scenes make one default device
METHODS = ("auto", "ray_query", "ray_pipeline")
OUT_MODES = ("device", "host")


def _floats(name: str, a: Any, width: int, *, finite: bool = False,
            convert: bool = True) -> np.ndarray:
    """``a`` checked as a real (N, width) array; float32 C-contiguous with ``convert``, else
    as it is (rays are converted as they are copied to the GPU: one pass, not two)."""
    arr = _array(name, a)
    if arr.dtype.kind not in "fiu":  # floats, or integers that convert exactly enough
        raise RfwTypeError(f"{name} must be a real-valued (float) array, got dtype "
                           f"{arr.dtype}")
    if arr.ndim != 2 or arr.shape[1] != width:
        raise RfwValueError(f"{name} must have shape (N, {width}), got {arr.shape}")
    if not convert:
        return arr
    out = np.ascontiguousarray(arr, np.float32)
    if finite:
        bad = ~np.isfinite(out).all(axis=1)
        if bad.any():
            raise RfwError(f"{name} has non-finite values (first in row {int(np.argmax(bad))})")
    return out


def _array(name: str, a: Any) -> np.ndarray:
    # numpy's own errors (ragged lists, objects) become one line naming the argument
    if isinstance(a, str | bytes) or a is None:
        raise RfwTypeError(f"{name} must be an array, not {type_name(a)}")
    try:
        return np.asarray(a)
    except (TypeError, ValueError) as e:
        raise RfwTypeError(f"{name} must be an array ({e})") from None


def _interval(name: str, value: Any, n: int) -> np.ndarray | float:
    """A number stays a number (the GPU gets it once); anything else is (n,) float32."""
    arr = _array(name, value)
    if arr.dtype.kind not in "fiu" or arr.dtype == bool:
        raise RfwTypeError(f"{name} must be a number or a float array, got dtype "
                           f"{arr.dtype}")
    arr = arr.astype(np.float64)
    if arr.ndim > 1 or (arr.ndim == 1 and arr.shape != (n,)):
        raise RfwValueError(f"{name} must be a number or have shape ({n},), got {arr.shape}")
    if np.isnan(arr).any() or (arr < 0).any():
        raise RfwValueError(f"{name} must be non-negative and not NaN")
    if arr.ndim == 0:
        return float(np.float32(arr))
    return arr.astype(np.float32)


def _intervals(t_min: Any, t_max: Any, n: int, names: tuple[str, str],
               ) -> tuple[np.ndarray | float, np.ndarray | float]:
    return _ordered(_interval(names[0], t_min, n), _interval(names[1], t_max, n), names)


def _ordered(lo: np.ndarray | float, hi: np.ndarray | float, names: tuple[str, str],
             ) -> tuple[np.ndarray | float, np.ndarray | float]:
    """``lo``, ``hi`` (checked by :func:`_interval`) unless ``hi`` is below ``lo``."""
    below = np.asarray(hi) < np.asarray(lo)
    if below.any():
        first = int(np.argmax(below)) if below.ndim else 0
        raise RfwError(f"{names[1]} is below {names[0]} (first in ray {first})")
    return lo, hi


def _rays(origins: Any, directions: Any, t_min: Any, t_max: Any, names: tuple[str, str],
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray | float, np.ndarray | float]:
    o = _floats("origins", origins, 3, convert=False)
    d = _floats("directions", directions, 3, convert=False)
    if len(o) != len(d):
        raise RfwError(f"origins has {len(o)} rows, directions {len(d)}")
    return (o, d, *_intervals(t_min, t_max, len(o), names))


def _rows(a: Any) -> int:
    return len(a) if isinstance(a, np.ndarray) else int(a.shape[0])


def _out_mode(out: Any) -> str | None:
    """``out`` as RayScene.cast takes it: a mode name, None or a dict (the dict is checked
    later)."""
    if isinstance(out, str):
        if out not in OUT_MODES:
            raise RfwValueError(f"out is 'device', 'host', None or a dict of arrays, not "
                                f"{out!r}")
        return out
    return None


def _mesh_scene(vertices: Any, indices: Any) -> Scene:
    v = _floats("vertices", vertices, 3, finite=True)
    if len(v) == 0:
        raise RfwError("vertices is empty")
    idx = _array("indices", indices)
    if idx.dtype.kind not in "iu":
        raise RfwTypeError(f"indices must be an integer array, got dtype {idx.dtype}")
    if idx.ndim != 2 or idx.shape[1] != 3:
        raise RfwValueError(f"indices must have shape (T, 3), got {idx.shape}")
    if idx.size and (int(idx.min()) < 0 or int(idx.max()) >= len(v)):
        raise RfwError(f"indices must lie in [0, {len(v)}) (the vertex count), found "
                       f"{int(idx.min())}..{int(idx.max())}")
    zeros = np.zeros((len(v), 4), np.float32)
    mesh = Mesh("raycast", v, zeros[:, :3], zeros[:, :2], zeros,
                np.ascontiguousarray(idx, np.uint32).reshape(-1))
    return Scene("raycast", meshes=[mesh], instances=[Instance(0, np.identity(4, np.float32))])


def _caster() -> Backend:
    """The first installed backend that casts rays."""
    for name in installed():
        backend = get_backend(name, element=None)
        if hasattr(backend, "ray_scene"):
            return backend
    raise RfwError(f"no installed backend casts rays (rfw.backends: "
                   f"{', '.join(installed()) or 'none'})", element="rfw.RayScene")


def _device(backend: Backend) -> Any:
    global _default_device
    with _default_lock:
        if _default_device is None or not getattr(_default_device, "alive", True):
            # an edge, as rfw.render is: the device RFW_GPU (and the rest) asks for
            _default_device = backend.make_device(label="rfw.raycast",
                                                  options=RunOptions.from_env())
            atexit.register(backend.destroy_device, _default_device)
        return _default_device


class RayScene:
    """Triangles on the GPU, ready for many casts: the device, the acceleration structures
    (BLAS and TLAS, built once) and the ray and hit buffers are kept between casts.

    Parameters
    ----------
    vertices, indices
        A triangle mesh: float (V, 3) positions and integer (T, 3) vertex indices. For every
        instance of a loaded :class:`rfw.scene.Scene`, use :meth:`from_scene`.
    device
        The ray-casting backend's device, a ``vkext.VkDevice`` (default: one made on first
        use and kept until exit).
    method
        ``"ray_query"`` (compute shader), ``"ray_pipeline"`` (raygen, miss and closest-hit
        shaders through a shader binding table) or ``"auto"``: ray queries where the device
        has them, else the pipeline.
    batch
        Rays per GPU submit (default on vk ``vkext.raycast.DEFAULT_BATCH``, about a million):
        memory stays bounded whatever the ray count. The buffers grow to the largest batch
        cast so far and never shrink.

    Use it as a context manager, or call :meth:`close`; a closed scene refuses to cast.

    Raises
    ------
    RfwError
        (a ValueError) for arrays of the wrong shape or dtype, non-finite vertices, indices
        out of range, no vertices, or a bad ``method``/``batch``; the message names the
        argument.
    """

    def __init__(self, vertices: Any, indices: Any, *, device: Any = None,
                 method: str = "auto", batch: int | None = None):
        try:
            scene = _mesh_scene(vertices, indices)
        except RfwError as e:
            raise e.about("rfw.RayScene") from None
        self._open(scene, device, method, batch, instances=False)

    @classmethod
    def from_scene(cls, scene: Scene, *, device: Any = None, method: str = "auto",
                   batch: int | None = None) -> RayScene:
        """Every instance of ``scene`` (one BLAS per mesh, the TLAS places them); the hits
        then also name the ``instance`` (index into ``scene.instances``)."""
        if not isinstance(scene, Scene):
            raise RfwTypeError(f"scene must be an rfw.scene.Scene, got "
                               f"{type(scene).__name__}", element="RayScene.from_scene")
        self = cls.__new__(cls)
        self._open(scene, device, method, batch, instances=True)
        return self

    def _open(self, scene: Scene, device: Any, method: str, batch: int | None, *,
              instances: bool) -> None:
        self._scene = None
        where = "rfw.RayScene"
        check_type(method, "method", str, "'auto', 'ray_query' or 'ray_pipeline'",
                   element=where)
        if method not in METHODS:
            raise RfwValueError(f"method is 'auto', 'ray_query' or 'ray_pipeline', not "
                                f"{method!r}", element=where)
        if batch is not None and (isinstance(batch, bool) or not isinstance(batch, int)):
            raise RfwTypeError(f"batch must be a positive integer, got {batch!r}",
                               element=where)
        if batch is not None and batch < 1:
            raise RfwValueError(f"batch must be a positive integer, got {batch!r}",
                                element=where)
        backend = _caster()
        self.device = device if device is not None else _device(backend)
        self.instances = instances
        try:  # the backend checks the device (rfw knows no backend's device type)
            self._scene = backend.ray_scene(self.device, scene, method=method, batch=batch)
        except RfwError as e:
            raise e.about(where) from None

    @property
    def closed(self) -> bool:
        """True after :meth:`close` (or once its device was destroyed)."""
        return self._scene is None or bool(getattr(self._scene, "closed", False))

    @property
    def last(self) -> dict[str, Any]:
        """The last cast's ray and batch counts and times: ``wall_ms`` (copies and waits
        included) and, where the device has timestamps, ``gpu_ms`` of the traces alone."""
        return dict(self._scene.last) if not self.closed else {}

    @property
    def zero_copy(self) -> bool:
        """Whether casts with device arrays keep rays and hits on the GPU here (the
        scene's device shares memory with CUDA); :attr:`zero_copy_reason` says why not."""
        return self.zero_copy_reason is None

    @property
    def zero_copy_reason(self) -> str | None:
        """None where :attr:`zero_copy`, else one line saying why not."""
        if self.closed:
            return "the ray scene is closed"
        sharing = getattr(self._scene, "sharing", None)
        if sharing is None:
            return "this backend's ray scenes keep no arrays on the GPU"
        return sharing()

    def cast(self, origins: Any, directions: Any, *, t_min: Any = 0.0,
             t_max: Any = np.inf, out: dict[str, np.ndarray] | str | None = None,
             ) -> dict[str, Any]:
        """Closest hit of each ray ``origins[i] + t * directions[i]``, ``t_min <= t <= t_max``.

        Parameters
        ----------
        origins, directions
            Real (R, 3) arrays of any layout, converted to float32 as they are copied to
            the GPU. Directions need not be unit length: ``t`` is in their units. Or CUDA
            arrays (PyTorch, CuPy, JAX, anything with ``__cuda_array_interface__`` or a CUDA
            ``__dlpack__``): C-contiguous float32 (R, 3), on the scene's GPU, copied device
            to device (see Device arrays).
        t_min, t_max
            Numbers or (R,) arrays, non-negative; ``t_max`` may be infinite. With device
            rays also (R,) float32 CUDA arrays (not checked on the host).
        out
            ``None``: hits of the kind of the rays (device arrays for CUDA rays, else numpy);
            ``"device"``: :class:`rfw.interop.DeviceArray` hits whatever the rays;
            ``"host"``: numpy hits whatever the rays; or a dict of numpy arrays to fill
            instead of new ones, by name (any of the returned ones): each C-contiguous,
            writable and of the dtype and shape below. Repeated casts into the same arrays
            allocate nothing.

        Returns
        -------
        dict of numpy arrays (or of :class:`rfw.interop.DeviceArray`, see ``out``)
            ``t`` float32 (R,), ``inf`` where the ray misses; ``primitive`` int32 (R,), the
            triangle (row of ``indices``, or of the instance's mesh), -1 on a miss;
            ``barycentrics`` float32 (R, 2), the weights of the triangle's 2nd and 3rd
            vertices; from :meth:`from_scene`, also ``instance`` int32 (R,).

        Device arrays
        -------------
        Where :attr:`zero_copy` (vk on a GPU that CUDA also drives, with
        ``VK_KHR_external_memory_fd``), device hits are zero-copy views of the scene's
        hit buffer on the GPU (``.zero_copy`` True, ``.device`` ``"cuda:N"``): nothing
        crosses to the host, and the next device cast of this scene overwrites them
        (``torch.from_dlpack(h["t"]).clone()`` to keep them). Rays the shaders refuse are
        then not raised but flagged: ``t`` NaN, ``primitive`` -2 (origin not finite), -3
        (direction not finite) or -4 (zero direction). Elsewhere (lavapipe, no CUDA)
        ``out="device"`` gives host copies behind the same face (``.zero_copy`` False,
        ``.device`` ``"cpu"``, a CPU ``__dlpack__``), and CUDA rays are refused.

        Raises
        ------
        RfwError
            (a ValueError) for a closed scene, arrays of the wrong shape or dtype, rows that
            differ in number, non-finite origins or directions, zero directions, a bad
            ``t_min``/``t_max`` or unfit ``out`` arrays; for device arrays of the wrong
            dtype, shape or layout, on another GPU, or given where the scene cannot share
            memory with CUDA; the message names the argument.
        """
        element = "RayScene.cast"
        scene = self._scene  # another thread may close it meanwhile: its cast then refuses
        if self.closed:
            raise RfwError("the ray scene is closed: make a new rfw.RayScene", element=element)
        try:
            mode = _out_mode(out)
            on_gpu = [name for name, a in (("origins", origins), ("directions", directions),
                                           ("t_min", t_min), ("t_max", t_max))
                      if interop.is_device_array(a)]
            if on_gpu and isinstance(out, dict):
                raise RfwError(f"{on_gpu[0]} is a CUDA array: out= arrays are filled on the "
                               f"host; take out=None or 'device' (and copy the hits on the "
                               f"GPU where they should go)")
            device = mode == "device" or (out is None and bool(on_gpu))
            if on_gpu or device:
                reason = self.zero_copy_reason
                if reason is None:
                    got = self._cast_device(scene, origins, directions, t_min, t_max)
                    return {k: v.numpy() for k, v in got.items()} if mode == "host" else got
                if on_gpu:
                    raise RfwError(f"{on_gpu[0]} is a CUDA array, but this ray scene cannot "
                                   f"share memory with CUDA ({reason}): pass host arrays "
                                   f"(e.g. tensor.cpu())")
            rays = _rays(interop.host_of(origins), interop.host_of(directions),
                         interop.host_of(t_min), interop.host_of(t_max), ("t_min", "t_max"))
            got = scene.cast(*rays, hits=self._keys(),
                             out=self._out(out) if mode is None else None)
            if device:  # the host path behind the device face
                return {k: interop.DeviceArray.of_host(v) for k, v in got.items()}
            return got
        except RfwError as e:
            raise e.about(element) from None

    def device_rays(self, n: int) -> tuple[Any, Any]:
        """(origins, directions) for ``n`` rays: writable (n, 3) float32
        :class:`rfw.interop.DeviceArray` to fill (``torch.from_dlpack(o).copy_(rays)``,
        or generate them there) and pass to :meth:`cast` as they are.

        Where :attr:`zero_copy`, they are the scene's own ray buffer on the GPU, so such a
        cast copies nothing in (``last["rays_in_place"]``); the same memory each call, and
        a cast of more rays moves the buffer (older views still cast, copied in like any
        array). Elsewhere they are host arrays behind the same face (``device`` ``"cpu"``,
        write them through ``.numpy()``), cast through the host path."""
        element = "RayScene.device_rays"
        n = int(n)
        if n < 1:
            raise RfwError(f"n must be positive, got {n}", element=element)
        if self.closed:
            raise RfwError("the ray scene is closed: make a new rfw.RayScene", element=element)
        if self.zero_copy_reason is None and getattr(self._scene, "accel", None) is not None:
            try:
                return self._scene.device_rays(n)
            except RfwError as e:
                raise e.about(element) from None
        return tuple(interop.DeviceArray.of_host(np.zeros((n, 3), np.float32))
                     for _ in range(2))

    def _cast_device(self, scene: Any, origins: Any, directions: Any, t_min: Any,
                     t_max: Any) -> dict[str, Any]:
        """A cast through the backend's GPU-resident buffers: CUDA arrays as views, host
        arrays checked as the host path checks them."""
        views = []
        for name, a in (("origins", origins), ("directions", directions)):
            views.append(interop.device_view(name, a, 3) if interop.is_device_array(a)
                         else _floats(name, interop.host_of(a), 3))
        if _rows(views[0]) != _rows(views[1]):
            raise RfwError(f"origins has {_rows(views[0])} rows, directions {_rows(views[1])}")
        n = _rows(views[0])
        bounds = []
        for name, a in (("t_min", t_min), ("t_max", t_max)):
            if interop.is_device_array(a):
                view = interop.device_view(name, a, None)
                if view.shape[0] != n:
                    raise RfwError(f"{name} must have shape ({n},), got {view.shape}")
                bounds.append(view)
            else:
                bounds.append(_interval(name, interop.host_of(a), n))
        if not any(isinstance(b, interop.CudaView) for b in bounds):
            bounds = list(_ordered(*bounds, ("t_min", "t_max")))
        return scene.cast_device(*views, *bounds, hits=self._keys())

    def _keys(self) -> tuple[str, ...]:
        return ("t", "primitive", "barycentrics") + (("instance",) * self.instances)

    def _out(self, out: Any) -> dict[str, np.ndarray] | None:
        # the arrays themselves are checked by the backend, which knows the dtypes
        if out is None:
            return None
        if not isinstance(out, dict):
            raise RfwTypeError(f"out must be a dict of arrays by name, got "
                               f"{type(out).__name__} (or 'device', 'host', None)")
        unknown = sorted(set(out) - set(self._keys()), key=str)
        if unknown:
            raise RfwError(f"out has {unknown[0]!r}, which this scene does not return "
                           f"(it returns {', '.join(self._keys())})")
        return out

    def _cast(self, o: np.ndarray, d: np.ndarray, lo: np.ndarray | float,
              hi: np.ndarray | float, *, out: dict[str, np.ndarray] | None = None,
              ) -> dict[str, np.ndarray]:
        """Cast rays that :func:`_rays` has checked."""
        return self._scene.cast(o, d, lo, hi, hits=self._keys(), out=out)

    def close(self) -> None:
        """Free the acceleration structures and buffers now (safe to call twice); the
        device stays."""
        scene, self._scene = self._scene, None
        if scene is not None:
            scene.destroy()

    def __enter__(self) -> RayScene:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self.closed else f"method {self._scene.method}"
        return f"<rfw.RayScene {state}>"


def raycast(vertices: Any = None, indices: Any = None, origins: Any = None,
            directions: Any = None, tmin: Any = 0.0, tmax: Any = np.inf, *,
            scene: Scene | None = None, device: Any = None, method: str = "auto",
            batch: int | None = None) -> dict[str, np.ndarray]:
    """Closest hit of each ray ``origins[i] + t * directions[i]``, ``tmin <= t <= tmax``:
    a :class:`RayScene` made, cast once and closed. For many casts against one scene, keep
    a :class:`RayScene` (its acceleration structures are built once).

    Parameters
    ----------
    vertices, indices
        A triangle mesh: float (V, 3) positions and integer (T, 3) vertex indices. Or
        leave them out and give ``scene``: every instance of an :class:`rfw.scene.Scene`.
    origins, directions, tmin, tmax
        As ``t_min``/``t_max`` of :meth:`RayScene.cast`.
    device, method, batch
        As for :class:`RayScene`.

    Returns
    -------
    dict of numpy arrays
        :meth:`RayScene.cast`'s: ``t``, ``primitive``, ``barycentrics`` and, with ``scene``,
        ``instance``.

    Raises
    ------
    RfwError
        (a ValueError) as :class:`RayScene` and :meth:`RayScene.cast`; the message names the
        argument.
    """
    element = "rfw.raycast"
    if scene is None:
        if vertices is None or indices is None:
            raise RfwError("give vertices and indices, or scene=", element=element)
    elif vertices is not None or indices is not None:
        raise RfwError("give vertices and indices, or scene=, not both", element=element)
    if origins is None or directions is None:
        raise RfwError("origins and directions are required", element=element)
    try:
        # the cheap checks before the build
        rays = _rays(origins, directions, tmin, tmax, ("tmin", "tmax"))
        if scene is None:
            rs = RayScene(vertices, indices, device=device, method=method, batch=batch)
        else:
            rs = RayScene.from_scene(scene, device=device, method=method, batch=batch)
    except RfwError as e:
        raise type(e)(e.message, element=element) from None  # RfwTypeError stays one
    with rs:
        try:
            return rs._cast(*rays)
        except RfwError as e:
            raise e.about(element) from None
