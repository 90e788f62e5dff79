"""``rfw.raycast``: closest hits of many rays against triangles, on the GPU.

Defined here and exported lazily by ``rfw`` (``rfw.raycast``); the module has another name
so that importing it never turns the attribute ``rfw.raycast`` into a module.

The numpy face of a backend's ray casting: check the arrays, hand them to the first
installed backend (``rfw.backends`` entry points) that has a ``raycast`` method (``vk``:
``vkext.backend.VkBackend.raycast`` builds the acceleration structures, casts and
destroys them), hand back arrays. rfw imports no backend itself, so ``import rfw`` never
loads Vulkan.

Each call builds its acceleration structures and destroys them afterwards; the pipeline of a
method stays with the device (the default device is made on first use and destroyed at
exit). For many casts against one scene, hold a ``vkext.accel.SceneAccel`` and a
``vkext.raycast.Raycaster`` instead.
"""

from __future__ import annotations

import atexit
from typing import Any

import numpy as np

from .backend import Backend, get_backend, installed
from .errors import RfwError
from .scene.model import Instance, Mesh, Scene

_default_device: Any = None


def _floats(name: str, a: Any, width: int) -> np.ndarray:
    arr = np.asarray(a)
    if arr.dtype.kind not in "fiu":  # floats, or integers that convert exactly enough
        raise ValueError(f"{name} must be a real-valued (float) array, got dtype {arr.dtype}")
    if arr.ndim != 2 or arr.shape[1] != width:
        raise ValueError(f"{name} must have shape (N, {width}), got {arr.shape}")
    out = np.ascontiguousarray(arr, np.float32)
    bad = ~np.isfinite(out).all(axis=1)
    if bad.any():
        raise ValueError(f"{name} has non-finite values (first in row {int(np.argmax(bad))})")
    return out


def _interval(name: str, value: Any, n: int) -> np.ndarray:
    arr = np.asarray(value, np.float64)
    if arr.ndim > 1 or (arr.ndim == 1 and arr.shape != (n,)):
        raise ValueError(f"{name} must be a number or have shape ({n},), got {arr.shape}")
    arr = np.broadcast_to(arr, (n,))
    if np.isnan(arr).any() or (arr < 0).any():
        raise ValueError(f"{name} must be non-negative and not NaN")
    return arr.astype(np.float32)


def _mesh_scene(vertices: Any, indices: Any) -> Scene:
    v = _floats("vertices", vertices, 3)
    if len(v) == 0:
        raise ValueError("vertices is empty")
    idx = np.asarray(indices)
    if idx.dtype.kind not in "iu":
        raise ValueError(f"indices must be an integer array, got dtype {idx.dtype}")
    if idx.ndim != 2 or idx.shape[1] != 3:
        raise ValueError(f"indices must have shape (T, 3), got {idx.shape}")
    if idx.size and (int(idx.min()) < 0 or int(idx.max()) >= len(v)):
        raise ValueError(f"indices must lie in [0, {len(v)}) (the vertex count), found "
                         f"{int(idx.min())}..{int(idx.max())}")
    zeros = np.zeros((len(v), 4), np.float32)
    mesh = Mesh("raycast", v, zeros[:, :3], zeros[:, :2], zeros,
                np.ascontiguousarray(idx, np.uint32).reshape(-1))
    return Scene("raycast", meshes=[mesh], instances=[Instance(0, np.identity(4, np.float32))])


def _caster() -> Backend:
    """The first installed backend that casts rays."""
    for name in installed():
        backend = get_backend(name, element=None)
        if hasattr(backend, "raycast"):
            return backend
    raise RfwError(f"no installed backend casts rays (rfw.backends: "
                   f"{', '.join(installed()) or 'none'})", element="rfw.raycast")


def _device(backend: Backend) -> Any:
    global _default_device
    if _default_device is None or not getattr(_default_device, "alive", True):
        _default_device = backend.make_device(label="rfw.raycast")
        atexit.register(backend.destroy_device, _default_device)
    return _default_device


def raycast(vertices: Any = None, indices: Any = None, origins: Any = None,
            directions: Any = None, tmin: Any = 0.0, tmax: Any = np.inf, *,
            scene: Scene | None = None, device: Any = None, method: str = "auto",
            batch: int | None = None) -> dict[str, np.ndarray]:
    """Closest hit of each ray ``origins[i] + t * directions[i]``, ``tmin <= t <= tmax``.

    Parameters
    ----------
    vertices, indices
        A triangle mesh: float (V, 3) positions and integer (T, 3) vertex indices. Or
        leave them out and give ``scene``: every instance of an :class:`rfw.scene.Scene`.
    origins, directions
        Float (R, 3) arrays. Directions need not be unit length: ``t`` is in their units.
    tmin, tmax
        Numbers or (R,) arrays, non-negative; ``tmax`` may be infinite.
    device
        The ray-casting backend's device, a ``vkext.VkDevice`` (default: one made on first
        use and kept).
    method
        ``"ray_query"`` (compute shader), ``"ray_pipeline"`` (raygen, miss and closest-hit
        shaders through a shader binding table) or ``"auto"``: ray queries where the device
        has them, else the pipeline.
    batch
        Rays per GPU submit (default on vk ``vkext.raycast.DEFAULT_BATCH``, about a million):
        memory stays bounded whatever the ray count.

    Returns
    -------
    dict of numpy arrays
        ``t`` float32 (R,), ``inf`` where the ray misses; ``primitive`` int32 (R,), the
        triangle (row of ``indices``, or of the instance's mesh), -1 on a miss;
        ``barycentrics`` float32 (R, 2), the weights of the triangle's 2nd and 3rd vertices;
        with ``scene``, also ``instance`` int32 (R,), the index into ``scene.instances``.

    Raises
    ------
    ValueError
        For arrays of the wrong shape or dtype, non-finite values, indices out of range, or
        a bad ``tmin``/``tmax``/``method``; the message names the argument.
    """
    if scene is None:
        if vertices is None or indices is None:
            raise ValueError("give vertices and indices, or scene=")
        target = _mesh_scene(vertices, indices)
    else:
        if vertices is not None or indices is not None:
            raise ValueError("give vertices and indices, or scene=, not both")
        if not isinstance(scene, Scene):
            raise ValueError(f"scene must be an rfw.scene.Scene, got {type(scene).__name__}")
        target = scene
    if origins is None or directions is None:
        raise ValueError("origins and directions are required")
    o = _floats("origins", origins, 3)
    d = _floats("directions", directions, 3)
    if len(o) != len(d):
        raise ValueError(f"origins has {len(o)} rows, directions {len(d)}")
    zero = ~d.any(axis=1)
    if zero.any():
        raise ValueError(f"directions has zero-length rows (first: {int(np.argmax(zero))})")
    n = len(o)
    lo, hi = _interval("tmin", tmin, n), _interval("tmax", tmax, n)
    if (hi < lo).any():
        raise ValueError(f"tmax is below tmin (first in ray {int(np.argmax(hi < lo))})")
    if method not in ("auto", "ray_query", "ray_pipeline"):
        raise ValueError(f"method is 'auto', 'ray_query' or 'ray_pipeline', not {method!r}")

    caster = _caster()
    dev = device if device is not None else _device(caster)
    hits = caster.raycast(dev, target, {"origin": o, "direction": d, "tmin": lo, "tmax": hi},
                          method=method, batch=batch)
    out = {"t": hits["t"].copy(), "primitive": hits["primitive"].copy(),
           "barycentrics": np.stack([hits["u"], hits["v"]], axis=1)}
    if scene is not None:
        out["instance"] = hits["instance"].copy()
    return out

