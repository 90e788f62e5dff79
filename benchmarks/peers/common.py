"""What every peer shares: the scene as flat arrays, the camera, primary rays, a timer."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

# rfw's `flat` technique (passes/flat), which every raster peer renders: per vertex,
# base colour x (AMBIENT + (1 - AMBIENT) x max(n.l, 0)) with the scene's sun, unencoded
AMBIENT = 0.25
# rfw.backends.scene_data's suns: its default for a scene without lights, and the shadow
# direction where no light is directional
DEFAULT_SUN = (-0.35, -1.0, -0.45)
NO_SUN = (-0.3, -1.0, -0.2)


class Unavailable(Exception):
    """The peer cannot run here (package missing, no EGL, ...): reported, never dropped."""


@dataclass
class Geometry:
    positions: np.ndarray  # (V, 3) float32, world space (every instance flattened)
    normals: np.ndarray  # (V, 3) float32, world space, unit
    colors: np.ndarray  # (V, 3) float32, linear base colour of the material
    indices: np.ndarray  # (T, 3) uint32
    light_dir: np.ndarray  # (3,) unit, towards the light
    scene_name: str

    @property
    def triangles(self) -> int:
        return len(self.indices)

    def shaded_colors(self) -> np.ndarray:
        """rfw's ``flat`` colour of each vertex, for peers that take colours rather than
        shaders (interpolated across the triangle, as rfw's is)."""
        lam = np.clip(self.normals @ self.light_dir, 0.0, 1.0)[:, None]
        return np.clip(self.colors * (AMBIENT + (1 - AMBIENT) * lam), 0.0, 1.0)


def load_scene(name: str = "default") -> Any:
    from rfw.scene import default_scene
    from rfw.scene import load_scene as load

    return default_scene() if name == "default" else load(name)


def geometry(scene: Any) -> Geometry:
    """All instances baked into world space: the same triangles rfw draws."""
    pos, nrm, col, idx = [], [], [], []
    base = 0
    for inst in scene.instances:
        m = scene.meshes[inst.mesh]
        t = np.asarray(inst.transform, np.float64)
        det = np.linalg.det(t[:3, :3]) if np.isfinite(t).all() else 0.0
        if det == 0.0:
            continue  # rfw skips instances it cannot draw
        p = m.positions.astype(np.float64) @ t[:3, :3].T + t[:3, 3]
        n = m.normals.astype(np.float64) @ np.linalg.inv(t[:3, :3])  # inverse transpose
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
        c = np.asarray(scene.materials[m.material].base_color[:3], np.float32)
        pos.append(p.astype(np.float32))
        nrm.append(n.astype(np.float32))
        col.append(np.broadcast_to(c, (len(p), 3)))
        tri = m.indices.reshape(-1, 3).astype(np.uint32) + base
        # a mirroring transform turns the winding round: rfw swaps two corners, so do we
        idx.append(tri[:, [0, 2, 1]] if det < 0 else tri)
        base += len(p)
    d = -np.asarray(sun_direction(scene), np.float64)
    return Geometry(np.concatenate(pos), np.concatenate(nrm),
                    np.concatenate(col).astype(np.float32), np.concatenate(idx),
                    (d / np.linalg.norm(d)).astype(np.float32), scene.name)


def sun_direction(scene: Any) -> tuple[float, float, float]:
    """The direction rfw's sun travels (rfw.backends.scene_data.lights_bytes' choice)."""
    if not scene.lights:
        return DEFAULT_SUN
    sun = next((li for li in scene.lights[:16] if li.kind == "directional"), None)
    return tuple(sun.direction) if sun else NO_SUN


def primary_rays(camera: Any, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """One ray through each pixel centre, row 0 at the top: origins and unit directions,
    (W*H, 3) float32, from the camera's view and vertical field of view."""
    view = camera.view().astype(np.float64)
    rot = view[:3, :3].T  # camera to world
    eye = np.asarray(camera.position, np.float64)
    tan = np.tan(camera.yfov / 2)
    aspect = width / height
    x = ((np.arange(width) + 0.5) / width * 2 - 1) * tan * aspect
    y = (1 - (np.arange(height) + 0.5) / height * 2) * tan
    xx, yy = np.meshgrid(x, y)
    d = np.stack([xx, yy, -np.ones_like(xx)], axis=-1).reshape(-1, 3) @ rot.T
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.broadcast_to(eye, d.shape)
    return np.ascontiguousarray(o, np.float32), np.ascontiguousarray(d, np.float32)


def time_frames(frame: Callable[[], Any], *, frames: int, warmup: int) -> list[float]:
    """Wall ms of each of ``frames`` calls after ``warmup`` untimed ones. ``frame`` must
    return only once its work is finished (each peer syncs in its own way)."""
    for _ in range(warmup):
        frame()
    out = []
    for _ in range(frames):
        t = time.perf_counter()
        frame()
        out.append((time.perf_counter() - t) * 1e3)
    return out


def depth_image(t: np.ndarray, width: int, height: int) -> np.ndarray:
    """Hit distances as an 8-bit grey image (near bright, misses black): a sanity picture."""
    t = np.asarray(t, np.float64).reshape(height, width)
    hit = np.isfinite(t) & (t > 0) & (t < 1e30)
    img = np.zeros((height, width), np.uint8)
    if hit.any():
        lo, hi = np.percentile(t[hit], [1, 99])
        v = 1 - np.clip((t - lo) / max(hi - lo, 1e-9), 0, 1)
        img[hit] = (40 + 215 * v[hit]).astype(np.uint8)
    return np.repeat(img[..., None], 3, axis=2)
