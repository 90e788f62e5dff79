"""The agreement scenes: small scenes that rfw's path tracer and Mitsuba 3 express alike.

``cornell`` is a Cornell box lit by one point light, ``spheres`` a Lambert sphere and a rough
metal sphere on a plane under a sun. Their materials are the two the two renderers share
exactly (``rfw.truth.mitsuba`` says why): pure Lambert (``specular = 0``, no dielectric lobe)
and metals (``metallic = 1``); there are no textures, no spot lights and no emissive
surfaces, and every surface a ray can reach is seen from its front. They are computed, never
random, so every call gives identical arrays. Units are metres, +Y is up. The third
agreement scene is a glTF file read by rfw's loader, ``tests/data/agreement/still_life.gltf``
(written by ``scripts/make_still_life.py``): a textured floor, a metal, mirrored instances and
KHR_lights_punctual lights.
"""

from __future__ import annotations

import math

import numpy as np

from .model import Camera, Instance, Light, Material, Mesh, Scene
from .util import compute_tangents, normalize

# the classic box's colours (linear reflectances)
WHITE = (0.73, 0.73, 0.73, 1.0)
RED = (0.63, 0.065, 0.05, 1.0)
GREEN = (0.14, 0.45, 0.091, 1.0)


def lambert(name: str, color: tuple[float, float, float, float]) -> Material:
    """A pure Lambert material: base / pi, no specular lobe."""
    return Material(name, base_color=color, metallic=0.0, roughness=1.0, specular=0.0)


def _mesh(name: str, p: np.ndarray, n: np.ndarray, uv: np.ndarray, tri: np.ndarray,
          material: int) -> Mesh:
    """A ``Mesh`` from float64 arrays, its triangles wound to agree with the vertex normals
    (so no orientation is checked by hand) and its tangents computed."""
    p, n = np.asarray(p, np.float64), normalize(n)
    tri = np.asarray(tri, np.int64).reshape(-1, 3)
    face = np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]])
    flip = np.sum(face * n[tri].sum(axis=1), axis=1) < 0
    tri[flip] = tri[flip][:, ::-1]
    idx = tri.ravel()
    return Mesh(name, np.ascontiguousarray(p, np.float32), np.ascontiguousarray(n, np.float32),
                np.ascontiguousarray(uv, np.float32),
                np.ascontiguousarray(compute_tangents(p, n, uv, idx)),
                np.ascontiguousarray(idx, np.uint32), material)


def _quads(name: str, quads: list[tuple], material: int) -> Mesh:
    """Flat quads ``(corner, u, v, normal)``, two triangles each, uv 0..1 across each."""
    p, n, uv, tri = [], [], [], []
    for corner, u, v, normal in quads:
        corner, u, v = (np.asarray(x, np.float64) for x in (corner, u, v))
        base = len(p)
        for s, t in ((0, 0), (1, 0), (1, 1), (0, 1)):
            p.append(corner + s * u + t * v)
            n.append(normal)
            uv.append((s, 1 - t))
        tri += [(base, base + 1, base + 2), (base, base + 2, base + 3)]
    return _mesh(name, np.array(p), np.array(n), np.array(uv), np.array(tri), material)


def _cube(name: str, material: int) -> Mesh:
    """The unit cube x, z in [-0.5, 0.5], y in [0, 1] (standing on y = 0), faces outward."""
    faces = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            n = np.zeros(3)
            n[axis] = sign
            u, v = np.zeros(3), np.zeros(3)
            u[(axis + 1) % 3], v[(axis + 2) % 3] = 1.0, 1.0
            corner = 0.5 * n - 0.5 * u - 0.5 * v + (0.0, 0.5, 0.0)
            faces.append((corner, u, v, n))
    return _quads(name, faces, material)


def _sphere(name: str, radius: float, segments: int, rings: int, material: int) -> Mesh:
    """A UV sphere about the origin with its analytic normals; the poles' zero-area
    triangles are left out."""
    theta, phi = np.meshgrid(np.linspace(0.0, math.pi, rings + 1),
                             np.linspace(0.0, 2 * math.pi, segments + 1), indexing="ij")
    n = np.stack([np.sin(theta) * np.sin(phi), -np.cos(theta), np.sin(theta) * np.cos(phi)],
                 -1).reshape(-1, 3)
    uv = np.stack([phi / (2 * math.pi), 1 - theta / math.pi], -1).reshape(-1, 2)
    i, j = np.meshgrid(np.arange(segments), np.arange(rings))
    a = (j * (segments + 1) + i).ravel()
    b, c, d = a + 1, a + segments + 2, a + segments + 1
    ring = j.ravel()
    tri = np.concatenate([np.stack([a, b, c], 1)[ring > 0],  # a-b is the pole row at j = 0
                          np.stack([a, c, d], 1)[ring < rings - 1]])
    return _mesh(name, radius * n, n, uv, tri, material)


def _placed(mesh: int, name: str, at, *, yaw: float = 0.0, scale=(1.0, 1.0, 1.0)) -> Instance:
    """Scale, then turn about +Y by ``yaw`` radians, then move to ``at``."""
    c, s = math.cos(yaw), math.sin(yaw)
    m = np.identity(4)
    m[:3, :3] = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]) @ np.diag(scale)
    m[:3, 3] = at
    return Instance(mesh, m.astype(np.float32), name)


def cornell() -> Scene:
    """A Cornell box, open at the front (+Z), lit by one point light below the ceiling.

    The room spans x, z in [-1, 1] and y in [0, 2]: white floor, ceiling and back wall, a red
    wall on the left (-X) and a green one on the right (+X), all facing in. A tall box (left,
    back) and a short one (right, front) are one unit cube placed twice with turns and
    non-uniform scales. 34 triangles; the camera looks in through the open side.
    """
    materials = [lambert("white", WHITE), lambert("red", RED), lambert("green", GREEN)]
    lo, hi = -1.0, 1.0
    walls = _quads("walls white", [
        ((lo, 0.0, hi), (2.0, 0, 0), (0, 0, -2.0), (0, 1, 0)),  # floor
        ((lo, 2.0, lo), (2.0, 0, 0), (0, 0, 2.0), (0, -1, 0)),  # ceiling
        ((lo, 0.0, lo), (2.0, 0, 0), (0, 2.0, 0), (0, 0, 1)),  # back wall
    ], 0)
    red = _quads("wall red", [((lo, 0.0, hi), (0, 0, -2.0), (0, 2.0, 0), (1, 0, 0))], 1)
    green = _quads("wall green", [((hi, 0.0, lo), (0, 0, 2.0), (0, 2.0, 0), (-1, 0, 0))], 2)
    meshes = [walls, red, green, _cube("box", 0)]
    instances = [
        Instance(0, np.identity(4, np.float32), "walls white"),
        Instance(1, np.identity(4, np.float32), "wall red"),
        Instance(2, np.identity(4, np.float32), "wall green"),
        _placed(3, "tall box", (-0.36, 0.0, -0.32), yaw=math.radians(18.0),
                scale=(0.58, 1.2, 0.58)),
        _placed(3, "short box", (0.36, 0.0, 0.3), yaw=math.radians(-17.0),
                scale=(0.58, 0.6, 0.58)),
    ]
    # 0.4 m below the ceiling: closer, its hot spot there would dominate the indirect light
    # (and the noise of every estimate of it)
    light = Light("point", (1.0, 0.92, 0.8), 8.0, position=(0.0, 1.6, 0.0), name="ceiling lamp")
    camera = Camera(position=(0.0, 1.0, 3.9), target=(0.0, 1.0, 0.0), yfov=math.radians(40.0),
                    znear=0.05, zfar=20.0, name="front")
    return Scene(name="cornell", meshes=meshes, materials=materials, instances=instances,
                 lights=[light], cameras=[camera])


# the metal sphere: copper, rough enough that its highlight is a lobe, not a mirror image
METAL = Material("copper", base_color=(0.95, 0.64, 0.54, 1.0), metallic=1.0, roughness=0.4)


def spheres() -> Scene:
    """A Lambert sphere and a rough metal sphere on a Lambert plane, under a sun.

    The plane is a 40 m square at y = 0 (the camera sees past its far edge, where camera rays
    miss everything); the spheres have radius 0.6 and 48 x 24 segments, smooth-shaded, and
    stand apart so that the sun throws each one's shadow beside the other. 4,418 triangles.
    """
    materials = [lambert("plane", (0.7, 0.7, 0.7, 1.0)), lambert("clay", (0.8, 0.35, 0.2, 1.0)),
                 METAL]
    half = 20.0
    plane = _quads("plane", [((-half, 0.0, half), (2 * half, 0, 0), (0, 0, -2 * half),
                              (0, 1, 0))], 0)
    meshes = [plane, _sphere("clay sphere", 0.6, 48, 24, 1), _sphere("metal sphere", 0.6, 48,
                                                                      24, 2)]
    instances = [Instance(0, np.identity(4, np.float32), "plane"),
                 _placed(1, "clay sphere", (-0.75, 0.6, 0.2)),
                 _placed(2, "metal sphere", (0.75, 0.6, -0.35))]
    travel = normalize(np.array([[0.45, -0.75, -0.5]]))[0]
    sun = Light("directional", (1.0, 0.95, 0.88), 3.0, direction=tuple(map(float, travel)),
                name="sun")
    camera = Camera(position=(0.0, 1.4, 4.6), target=(0.0, 0.55, 0.0), yfov=math.radians(45.0),
                    znear=0.05, zfar=100.0, name="front")
    return Scene(name="spheres", meshes=meshes, materials=materials, instances=instances,
                 lights=[sun], cameras=[camera])
