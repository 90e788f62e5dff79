"""The built-in test scene: an arcaded courtyard generated with numpy alone.

A tiled floor inside four walls; a two-storey arcade on each side (columns carrying round
arches, a walkway with a balustrade, a roof); a fountain and four plinths with metal spheres
in the open court; crates and urns in the covered galleries; houses and towers outside the
walls. It is built to exercise a renderer: one column mesh is drawn 64 times and one baluster
192 times (instancing), the arcades and walls hide much of the scene from any viewpoint
(culling), a low sun throws long shadows through the arches, five coloured point lights sit in
the galleries, the water is blended and the metals are metallic. Textures (tiles with grout,
stone blocks, limestone, wood) and their normal and roughness maps are generated too.

Units are metres, +Y is up, the court spans x, z in [-12, 12]. The ~690 lines are the
scene's geometry and texture recipes, one builder per part, kept together as one scene.
"""

from __future__ import annotations

import math

import numpy as np

from .model import Camera, Instance, Light, Material, Mesh, Scene, Texture
from .util import compute_tangents, normalize

HALF = 12.0  # inner face of the walls
ARCADE = 8.0  # the arcade's centre line
BAY = 2.0  # column spacing
WALL_T = 0.8
WALL_H = 8.2
COLUMN_H = 3.2
ABACUS = 0.7  # capital width = arch depth
ARCH_TOP = 1.1  # arch block height above the springing line
SLAB_T = 0.25
UPPER = 0.75  # scale of the upper storey's columns


def courtyard(seed: int = 0) -> Scene:
    """Generate the courtyard scene.

    Parameters
    ----------
    seed : int
        Varies texture detail and the placement of crates, urns and houses; the architecture
        is the same for every seed. The same seed always gives identical arrays.

    Returns
    -------
    Scene
    """
    rng = np.random.default_rng(seed)
    b = _SceneBuilder()
    _textures_and_materials(b, rng)
    _floor_and_ground(b)
    _walls(b)
    _arcades(b)
    _fountain(b)
    _props(b, rng)
    _outside(b, rng)
    _lights_and_camera(b)
    return Scene(name="courtyard", meshes=b.meshes, materials=b.materials,
                 textures=b.textures, instances=b.instances, lights=b.lights,
                 cameras=b.cameras, source=None)


# ---------------------------------------------------------------------------------------------
# geometry


class _Parts:
    """Accumulates triangles with positions, normals and uvs; turns them into a ``Mesh``."""

    def __init__(self) -> None:
        self.p: list[np.ndarray] = []
        self.n: list[np.ndarray] = []
        self.uv: list[np.ndarray] = []
        self.tri: list[np.ndarray] = []
        self.count = 0

    def add(self, p: np.ndarray, n: np.ndarray, uv: np.ndarray, tri: np.ndarray) -> None:
        p, n = np.asarray(p, np.float64), normalize(n)
        tri = np.asarray(tri, np.int64).reshape(-1, 3)
        # wind every triangle to agree with its vertex normals: no hand-checked orientation
        a, b, c = p[tri[:, 0]], p[tri[:, 1]], p[tri[:, 2]]
        face = np.cross(b - a, c - a)
        flip = np.sum(face * (n[tri[:, 0]] + n[tri[:, 1]] + n[tri[:, 2]]), axis=1) < 0
        tri[flip] = tri[flip][:, ::-1]
        self.p.append(p)
        self.n.append(n)
        self.uv.append(np.asarray(uv, np.float64))
        self.tri.append(tri + self.count)
        self.count += len(p)

    def grid(self, origin, u, v, nu: int, nv: int, density: float,
             normal=None) -> None:
        """A flat nu x nv quad grid spanning ``origin + s*u + t*v``; uvs in metres*density."""
        origin, u, v = (np.asarray(x, np.float64) for x in (origin, u, v))
        s, t = np.meshgrid(np.linspace(0, 1, nu + 1), np.linspace(0, 1, nv + 1))
        s, t = s.ravel(), t.ravel()
        p = origin + s[:, None] * u + t[:, None] * v
        n = np.cross(u, v) if normal is None else np.asarray(normal, np.float64)
        lu, lv = np.linalg.norm(u), np.linalg.norm(v)
        # v runs down the image while t runs along +v: flip so the texture is upright
        uv = np.column_stack([s * lu * density, (1 - t) * lv * density])
        self.add(p, np.tile(n, (len(p), 1)), uv, _grid_triangles(nu, nv))

    def box(self, lo, hi, density: float, faces: str = "xXyYzZ") -> None:
        """An axis-aligned box; ``faces`` picks the sides (lower case = negative side)."""
        lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        size = hi - lo
        for f in faces:
            axis = "xyz".index(f.lower())
            sign = 1.0 if f.isupper() else -1.0
            n = np.zeros(3)
            n[axis] = sign
            up = np.array([0.0, 1.0, 0.0]) if axis != 1 else np.array([0.0, 0.0, -sign])
            right = np.cross(up, n)
            # the face's corner at (-right, -up) on its plane
            center = (lo + hi) / 2 + n * size[axis] / 2
            half_r = abs(right @ size) / 2
            half_u = abs(up @ size) / 2
            origin = center - right * half_r - up * half_u
            self.grid(origin, right * 2 * half_r, up * 2 * half_u, 1, 1, density, n)

    def lathe(self, r, y, segments: int, density: float, *, normals2d=None,
              center=(0.0, 0.0)) -> None:
        """Revolve the profile (r, y) around the vertical axis, smooth-shaded.

        Without ``normals2d`` the surface faces right of the profile's direction of travel
        in the (r, y) plane: outwards for a profile going up, upwards for one going in.
        """
        r, y = np.asarray(r, np.float64), np.asarray(y, np.float64)
        if normals2d is None:
            seg = np.stack([np.diff(y), -np.diff(r)], axis=1)  # (dr, dy) turned clockwise
            seg = normalize(np.column_stack([seg, np.zeros(len(seg))]))[:, :2]
            nrm = np.zeros((len(r), 2))
            nrm[:-1] += seg
            nrm[1:] += seg
            normals2d = normalize(np.column_stack([nrm, np.zeros(len(r))]))[:, :2]
        normals2d = np.asarray(normals2d, np.float64)
        phi = np.linspace(0.0, 2 * math.pi, segments + 1)
        sp, cp = np.sin(phi)[None, :], np.cos(phi)[None, :]
        px = center[0] + r[:, None] * sp
        pz = center[1] + r[:, None] * cp
        py = np.broadcast_to(y[:, None], px.shape)
        p = np.stack([px, py, pz], axis=-1).reshape(-1, 3)
        n = np.stack([normals2d[:, :1] * sp, np.broadcast_to(normals2d[:, 1:2], px.shape),
                      normals2d[:, :1] * cp], axis=-1).reshape(-1, 3)
        arc = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(r), np.diff(y)))])
        around = max(1, round(2 * math.pi * float(r.max()) * density))
        u = np.broadcast_to(phi[None, :] / (2 * math.pi) * around, px.shape)
        v = np.broadcast_to(((arc[-1] - arc) * density)[:, None], px.shape)
        uv = np.stack([u, v], axis=-1).reshape(-1, 2)
        self.add(p, n, uv, _grid_triangles(segments, len(r) - 1))

    def polygon(self, points, density: float) -> None:
        """One flat convex polygon (fan), its normal from its winding."""
        p = np.asarray(points, np.float64)
        n = normalize(np.cross(p[1] - p[0], p[2] - p[0])[None])[0]
        u = normalize((p[1] - p[0])[None])[0]
        w = np.cross(n, u)
        uv = np.column_stack([(p - p[0]) @ u, -((p - p[0]) @ w)]) * density
        tri = [(0, i, i + 1) for i in range(1, len(p) - 1)]
        self.add(p, np.tile(n, (len(p), 1)), uv, np.array(tri))

    def mesh(self, name: str, material: int) -> Mesh:
        p = np.concatenate(self.p)
        n = np.concatenate(self.n)
        uv = np.concatenate(self.uv)
        idx = np.concatenate(self.tri).ravel()
        return Mesh(name=name,
                    positions=np.ascontiguousarray(p, np.float32),
                    normals=np.ascontiguousarray(n, np.float32),
                    uvs=np.ascontiguousarray(uv, np.float32),
                    tangents=np.ascontiguousarray(compute_tangents(p, n, uv, idx)),
                    indices=np.ascontiguousarray(idx, np.uint32),
                    material=material)


def _grid_triangles(nu: int, nv: int) -> np.ndarray:
    """Two triangles per cell of a (nv+1) x (nu+1) vertex grid, row-major."""
    i, j = np.meshgrid(np.arange(nu), np.arange(nv))
    a = (j * (nu + 1) + i).ravel()
    b, c, d = a + 1, a + nu + 2, a + nu + 1
    return np.stack([a, b, c, a, c, d], axis=1).reshape(-1, 3)


def _sphere(parts: _Parts, radius: float, segments: int, rings: int, density: float,
            center=(0.0, 0.0, 0.0)) -> None:
    t = np.linspace(0.0, math.pi, rings + 1)
    r, y = radius * np.sin(t), center[1] - radius * np.cos(t)
    parts.lathe(r, y, segments, density, normals2d=np.column_stack([np.sin(t), -np.cos(t)]),
                center=(center[0], center[2]))


def _torus(parts: _Parts, major: float, minor: float, segments: int, rings: int,
           density: float, y0: float = 0.0) -> None:
    t = np.linspace(-math.pi, math.pi, rings + 1)
    parts.lathe(major + minor * np.cos(t), y0 + minor * np.sin(t), segments, density,
                normals2d=np.column_stack([np.cos(t), np.sin(t)]))


def _disk(parts: _Parts, radius: float, y: float, segments: int, density: float,
          up: bool = True) -> None:
    r = [radius, 0.0] if up else [0.0, radius]
    n = [(0.0, 1.0)] * 2 if up else [(0.0, -1.0)] * 2
    parts.lathe(np.array(r), np.array([y, y]), segments, density, normals2d=n)


def _column() -> _Parts:
    """Plinth, torus moulding, tapering shaft, astragal, echinus and abacus: 3.2 m tall."""
    c = _Parts()
    seg = 24
    c.box((-0.3, 0.0, -0.3), (0.3, 0.22, 0.3), 1.0, faces="xXYzZ")
    _torus(c, 0.25, 0.07, seg, 8, 1.0, y0=0.29)
    y = np.linspace(0.3, 2.86, 9)
    r = 0.245 - 0.045 * ((y - 0.3) / 2.56) ** 1.5  # entasis: a gentle taper
    c.lathe(r, y, seg, 1.0)
    _torus(c, 0.205, 0.04, seg, 6, 1.0, y0=2.86)
    t = np.linspace(0.0, 1.0, 5)
    c.lathe(0.2 + 0.13 * t ** 1.6, 2.88 + 0.12 * np.sin(t * math.pi / 2), seg, 1.0)
    c.box((-ABACUS / 2, 3.0, -ABACUS / 2), (ABACUS / 2, COLUMN_H, ABACUS / 2), 1.0)
    return c


def _arch_block(segments: int = 24) -> _Parts:
    """One bay: a block BAY wide, ABACUS deep, ARCH_TOP tall, with a semicircular opening.

    Local origin at the springing line's centre; the bay spans x in [-1, 1].
    """
    a = _Parts()
    half = BAY / 2
    r0 = half - ABACUS / 2
    d = ABACUS / 2
    corner = math.atan2(ARCH_TOP, half)
    theta = np.unique(np.concatenate([np.linspace(0.0, math.pi, segments + 1),
                                      [corner, math.pi - corner]]))[::-1]
    c, s = np.cos(theta), np.sin(theta)
    with np.errstate(divide="ignore"):
        reach = np.minimum(np.where(np.abs(c) > 1e-12, half / np.abs(c), np.inf),
                           np.where(s > 1e-12, ARCH_TOP / s, np.inf))
    inner = np.column_stack([r0 * c, r0 * s])
    outer = np.column_stack([reach * c, reach * s])
    k = len(theta)
    quads = np.array([(i, i + 1, k + i + 1, k + i) for i in range(k - 1)])
    tri = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    for z in (d, -d):
        p2 = np.concatenate([inner, outer])
        p = np.column_stack([p2, np.full(len(p2), z)])
        uv = np.column_stack([p2[:, 0] * np.sign(z), -p2[:, 1]])
        a.add(p, np.tile([0.0, 0.0, np.sign(z)], (len(p), 1)), uv, tri)
    # the intrados, facing into the opening
    zz = np.array([-d, d])
    p = np.stack([np.broadcast_to(inner[:, None, 0], (k, 2)),
                  np.broadcast_to(inner[:, None, 1], (k, 2)),
                  np.broadcast_to(zz[None, :], (k, 2))], axis=-1).reshape(-1, 3)
    n = np.stack([-np.broadcast_to(c[:, None], (k, 2)), -np.broadcast_to(s[:, None], (k, 2)),
                  np.zeros((k, 2))], axis=-1).reshape(-1, 3)
    arc = np.repeat(theta * r0, 2)
    uv = np.column_stack([np.tile(zz, k), arc])
    a.add(p, n, uv, _grid_triangles(1, k - 1))
    a.box((-half, 0.0, -d), (half, ARCH_TOP, d), 1.0, faces="xXY")
    return a


def _baluster() -> _Parts:
    """A turned baluster, 0.85 m."""
    b = _Parts()
    y = np.array([0.0, 0.08, 0.1, 0.2, 0.32, 0.45, 0.58, 0.68, 0.74, 0.77, 0.85])
    r = np.array([0.075, 0.075, 0.05, 0.075, 0.085, 0.07, 0.045, 0.035, 0.05, 0.07, 0.07])
    b.lathe(r, y, 12, 1.0)
    _disk(b, 0.07, 0.85, 12, 1.0)
    return b


_HOUSES = ((5.0, 7.0, 4.0), (4.0, 11.0, 4.0), (6.0, 5.0, 5.0))  # width, height, depth


def _roof(w: float, d: float, y: float, rise: float) -> _Parts:
    r = _Parts()
    a, b, c, e = (-w / 2, y, d / 2), (w / 2, y, d / 2), (w / 2, y, -d / 2), (-w / 2, y, -d / 2)
    top = (0.0, y + rise, 0.0)
    for p, q in ((a, b), (b, c), (c, e), (e, a)):
        r.polygon([p, q, top], 1.0)
    return r


# ---------------------------------------------------------------------------------------------
# textures


def _value_noise(rng: np.random.Generator, size: int, cells: int) -> np.ndarray:
    """Tileable smooth value noise in [0, 1]."""
    grid = rng.random((cells, cells))
    x = np.arange(size) * cells / size
    i0 = np.floor(x).astype(np.int64)
    f = x - i0
    f = f * f * (3 - 2 * f)
    i1 = (i0 + 1) % cells
    fx, fy = f[None, :], f[:, None]
    top = grid[i0][:, i0] * (1 - fx) + grid[i0][:, i1] * fx
    bottom = grid[i1][:, i0] * (1 - fx) + grid[i1][:, i1] * fx
    return top * (1 - fy) + bottom * fy


def _fbm(rng: np.random.Generator, size: int, cells: int = 4, octaves: int = 5) -> np.ndarray:
    out = np.zeros((size, size))
    total = 0.0
    for o in range(octaves):
        amp = 0.5 ** o
        out += amp * _value_noise(rng, size, min(cells * 2 ** o, size))
        total += amp
    return out / total


def _rgba(rgb: np.ndarray, alpha: float = 1.0) -> np.ndarray:
    a = np.full((*rgb.shape[:2], 1), alpha)
    return np.ascontiguousarray(np.clip(np.concatenate([rgb, a], -1) * 255 + 0.5, 0, 255)
                                .astype(np.uint8))


def _normal_map(height: np.ndarray, strength: float) -> np.ndarray:
    """Tangent-space normals (+X right, +Y up the image) from a tileable height field."""
    dx = (np.roll(height, -1, 1) - np.roll(height, 1, 1)) / 2
    dy = (np.roll(height, 1, 0) - np.roll(height, -1, 0)) / 2  # row 0 is the top
    n = np.stack([-dx * strength, -dy * strength, np.ones_like(height)], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return _rgba(n * 0.5 + 0.5)


def _tiles(rng: np.random.Generator, size: int = 512, count: int = 8):
    """Checkered marble tiles with grout: albedo, normal, occlusion-roughness-metal."""
    cell = size // count
    rows, cols = np.mgrid[0:size, 0:size]
    lr, lc = rows % cell, cols % cell
    edge = np.minimum(np.minimum(lr, cell - 1 - lr), np.minimum(lc, cell - 1 - lc)) + 0.5
    grout = edge < 2.0
    bevel = np.clip((edge - 2.0) / 5.0, 0.0, 1.0)
    noise = _fbm(rng, size, 8)
    fine = _fbm(rng, size, 32, 3)
    tx, ty = cols // cell, rows // cell
    dark = ((tx + ty) % 2).astype(bool)
    # mostly brightness, a little hue: real marble tiles differ in tone, not colour
    tint = (rng.normal(0.0, 0.04, (count, count, 1))
            + rng.normal(0.0, 0.01, (count, count, 3)))[ty, tx]
    light_c = np.array([0.86, 0.82, 0.74])
    dark_c = np.array([0.36, 0.30, 0.27])
    base = np.where(dark[..., None], dark_c, light_c) + tint
    veins = np.abs(np.sin((cols / cell + 3.0 * noise) * math.pi * 2.0))
    base = base * (0.88 + 0.18 * noise[..., None]) * (0.9 + 0.1 * veins[..., None] ** 0.3)
    grout_c = np.array([0.47, 0.45, 0.42]) * (0.8 + 0.4 * fine[..., None])
    albedo = np.where(grout[..., None], grout_c, base)
    height = np.where(grout, 0.0, np.sqrt(bevel) * (0.96 + 0.04 * fine))
    rough = np.where(grout, 0.95, 0.25 + 0.45 * noise)
    ao = np.where(grout, 0.55, 0.8 + 0.2 * bevel)
    orm = np.stack([ao, rough, np.zeros_like(rough)], -1)
    return _rgba(albedo), _normal_map(height, 6.0), _rgba(orm)


def _blocks(rng: np.random.Generator, size: int = 512):
    """Running-bond sandstone blocks with mortar: albedo and normal."""
    bw, bh, mortar = 128, 32, 3
    rows, cols = np.mgrid[0:size, 0:size]
    course = rows // bh
    shifted = cols + (course % 2) * (bw // 2)
    brick = (shifted // bw) % (size // bw)
    lr, lc = rows % bh, shifted % bw
    edge = np.minimum(np.minimum(lr, bh - 1 - lr), np.minimum(lc, bw - 1 - lc)) + 0.5
    joint = edge < mortar / 2 + 0.5
    noise = _fbm(rng, size, 8)
    tone = rng.normal(0.0, 0.06, (size // bh, size // bw))[course, brick]
    warm = rng.random((size // bh, size // bw))[course, brick]
    base = np.array([0.72, 0.58, 0.42]) + np.array([0.05, 0.02, -0.03]) * warm[..., None]
    base = base * (1.0 + tone[..., None]) * (0.8 + 0.3 * noise[..., None])
    albedo = np.where(joint[..., None], np.array([0.62, 0.6, 0.55]) * (0.85 + 0.2 * noise[
        ..., None]), base)
    height = np.where(joint, 0.0, np.clip((edge - mortar / 2) / 4.0, 0, 1) ** 0.5
                      * (0.9 + 0.1 * noise))
    return _rgba(albedo), _normal_map(height, 4.0)


def _limestone(rng: np.random.Generator, size: int = 256):
    noise = _fbm(rng, size, 4, 6)
    veins = 1.0 - np.abs(np.sin((np.arange(size)[None, :] / size * 3 + noise * 4) * math.pi))
    base = np.array([0.8, 0.75, 0.64]) * (0.85 + 0.2 * noise[..., None])
    base = base * (1.0 - 0.15 * (veins ** 8)[..., None])
    rough = 0.45 + 0.35 * _fbm(rng, size, 8, 4)
    orm = np.stack([np.ones_like(rough), rough, np.zeros_like(rough)], -1)
    return _rgba(base), _rgba(orm)


def _wood(rng: np.random.Generator, size: int = 256):
    noise = _fbm(rng, size, 4, 5)
    rows = np.arange(size)[:, None] * np.ones((1, size))
    plank = rows // (size // 4)
    grain = 0.5 + 0.5 * np.sin(rows / size * 60 + noise * 12)
    tone = rng.normal(0.0, 0.07, 4)[plank.astype(np.int64)]
    base = np.array([0.52, 0.36, 0.2]) * (0.8 + 0.2 * grain[..., None]) * (1 + tone[..., None])
    gap = (rows % (size // 4)) < 2
    base = np.where(gap[..., None], np.array([0.15, 0.1, 0.06]), base)
    return _rgba(base)


# ---------------------------------------------------------------------------------------------
# the scene


class _SceneBuilder:
    def __init__(self) -> None:
        self.meshes: list[Mesh] = []
        self.materials: list[Material] = []
        self.textures: list[Texture] = []
        self.instances: list[Instance] = []
        self.lights: list[Light] = []
        self.cameras: list[Camera] = []
        self.mat: dict[str, int] = {}

    def texture(self, name: str, pixels: np.ndarray, srgb: bool) -> int:
        self.textures.append(Texture(name=name, pixels=pixels, srgb=srgb))
        return len(self.textures) - 1

    def material(self, m: Material) -> None:
        self.mat[m.name] = len(self.materials)
        self.materials.append(m)

    def mesh(self, parts: _Parts, name: str, material: str) -> int:
        self.meshes.append(parts.mesh(name, self.mat[material]))
        return len(self.meshes) - 1

    def place(self, mesh: int, name: str, at=(0.0, 0.0, 0.0), yaw: float = 0.0,
              scale: float = 1.0, tilt: float = 0.0) -> None:
        """Rotate about X by ``tilt``, then about Y by ``yaw``, scale uniformly, translate."""
        cy, sy = math.cos(yaw), math.sin(yaw)
        ct, st = math.cos(tilt), math.sin(tilt)
        ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
        rx = np.array([[1, 0, 0], [0, ct, -st], [0, st, ct]])
        m = np.identity(4)
        m[:3, :3] = ry @ rx * scale
        m[:3, 3] = at
        self.instances.append(Instance(mesh, m.astype(np.float32), name))


def _textures_and_materials(b: _SceneBuilder, rng: np.random.Generator) -> None:
    tile_albedo, tile_normal, tile_orm = _tiles(rng)
    block_albedo, block_normal = _blocks(rng)
    stone_albedo, stone_orm = _limestone(rng)
    wood = _wood(rng)
    t = {
        "tile": b.texture("floor_albedo", tile_albedo, True),
        "tile_n": b.texture("floor_normal", tile_normal, False),
        "tile_orm": b.texture("floor_orm", tile_orm, False),
        "block": b.texture("wall_albedo", block_albedo, True),
        "block_n": b.texture("wall_normal", block_normal, False),
        "stone": b.texture("stone_albedo", stone_albedo, True),
        "stone_orm": b.texture("stone_orm", stone_orm, False),
        "wood": b.texture("wood_albedo", wood, True),
    }
    b.material(Material("floor", roughness=1.0, metallic=1.0, base_color_texture=t["tile"],
                        metallic_roughness_texture=t["tile_orm"], normal_texture=t["tile_n"],
                        occlusion_texture=t["tile_orm"]))
    b.material(Material("wall", roughness=0.85, base_color_texture=t["block"],
                        normal_texture=t["block_n"]))
    b.material(Material("stone", roughness=1.0, metallic=1.0, base_color_texture=t["stone"],
                        metallic_roughness_texture=t["stone_orm"]))
    b.material(Material("bronze", (0.45, 0.28, 0.14, 1.0), metallic=1.0, roughness=0.35))
    b.material(Material("gold", (1.0, 0.77, 0.34, 1.0), metallic=1.0, roughness=0.2))
    b.material(Material("chrome", (0.9, 0.9, 0.92, 1.0), metallic=1.0, roughness=0.06))
    b.material(Material("copper", (0.95, 0.64, 0.54, 1.0), metallic=1.0, roughness=0.3))
    b.material(Material("water", (0.02, 0.09, 0.12, 0.7), roughness=0.04,
                        alpha_mode="BLEND"))
    b.material(Material("wood", roughness=0.7, base_color_texture=t["wood"]))
    b.material(Material("terracotta", (0.55, 0.2, 0.09, 1.0), roughness=0.8))
    b.material(Material("roof tiles", (0.4, 0.12, 0.07, 1.0), roughness=0.7))
    b.material(Material("plaster", (0.75, 0.68, 0.55, 1.0), roughness=0.9))
    b.material(Material("glass lamp", (1.0, 0.9, 0.7, 1.0), roughness=0.3,
                        emissive=(4.0, 2.8, 1.4)))


def _floor_and_ground(b: _SceneBuilder) -> None:
    # the court floor: 3 x 3 instances of an 8 m tile, whose uv period (4 m) divides 8
    f = _Parts()
    f.grid((-4.0, 0.0, 4.0), (8.0, 0.0, 0.0), (0.0, 0.0, -8.0), 16, 16, 0.25)
    floor = b.mesh(f, "floor tile", "floor")
    for i in (-1, 0, 1):
        for j in (-1, 0, 1):
            b.place(floor, f"floor {i},{j}", (i * 8.0, 0.0, j * 8.0))
    # the ground outside the walls: a ring, so nothing lies under the court floor
    g = _Parts()
    out, inner = 40.0, HALF + WALL_T
    for x0, z0, x1, z1 in ((-out, inner, out, out), (-out, -out, out, -inner),
                           (-out, -inner, -inner, inner), (inner, -inner, out, inner)):
        g.grid((x0, 0.0, z1), (x1 - x0, 0.0, 0.0), (0.0, 0.0, z0 - z1), 8, 8, 0.25)
    b.place(b.mesh(g, "ground", "plaster"), "ground")


def _walls(b: _SceneBuilder) -> None:
    long = _Parts()
    long.box((-HALF - WALL_T, 0.0, -WALL_T / 2), (HALF + WALL_T, WALL_H, WALL_T / 2), 0.5)
    short = _Parts()
    short.box((-HALF, 0.0, -WALL_T / 2), (HALF, WALL_H, WALL_T / 2), 0.5, faces="yYzZ")
    lw, sw = b.mesh(long, "wall long", "wall"), b.mesh(short, "wall short", "wall")
    mid = HALF + WALL_T / 2
    b.place(lw, "wall north", (0.0, 0.0, -mid))
    b.place(lw, "wall south", (0.0, 0.0, mid))
    b.place(sw, "wall east", (mid, 0.0, 0.0), yaw=math.pi / 2)
    b.place(sw, "wall west", (-mid, 0.0, 0.0), yaw=math.pi / 2)


def _arcades(b: _SceneBuilder) -> None:
    column = b.mesh(_column(), "column", "stone")
    arch = b.mesh(_arch_block(), "arch", "stone")
    baluster = b.mesh(_baluster(), "baluster", "stone")
    corner = _Parts()
    corner.box((0.0, COLUMN_H, 0.0), (ABACUS / 2, COLUMN_H + ARCH_TOP, ABACUS / 2), 1.0,
               faces="XyYZ")
    corner_block = b.mesh(corner, "arch corner", "stone")
    floor2 = COLUMN_H + ARCH_TOP + SLAB_T  # top of the walkway slab
    beam_y = floor2 + COLUMN_H * UPPER
    inner = ARCADE - ABACUS / 2

    def runs(name: str, half_full: float, half_trim: float, y0: float, y1: float, z0: float,
             z1: float, faces: str) -> tuple[int, int]:
        """A long box along a side, full length (south, north) and trimmed (east, west) so
        that the sides meet at the corners without overlapping."""
        out = []
        for half, tag in ((half_full, ""), (half_trim, " trimmed")):
            p = _Parts()
            p.box((-half, y0, z0), (half, y1, z1), 0.5, faces=faces)
            out.append(b.mesh(p, name + tag, "stone"))
        return out[0], out[1]

    # walkway and roof slabs reach the walls; beam and handrail run on the arcade line
    slab = runs("walkway", HALF, inner, floor2 - SLAB_T, floor2, inner, HALF, "xXyYz")
    roof = runs("roof", HALF, inner, beam_y + 0.4, beam_y + 0.4 + SLAB_T, inner, HALF,
                "xXyYz")
    beam = runs("beam", ARCADE + 0.3, ARCADE - 0.3, beam_y, beam_y + 0.4, ARCADE - 0.3,
                ARCADE + 0.3, "xXyYzZ")
    rail = runs("handrail", ARCADE + 0.09, ARCADE - 0.09, floor2 + 0.85, floor2 + 0.95,
                ARCADE - 0.09, ARCADE + 0.09, "xXyYzZ")
    offsets = np.arange(-ARCADE, ARCADE + 1e-9, BAY)
    sides = {"south": 0.0, "east": math.pi / 2, "north": math.pi, "west": -math.pi / 2}
    for side, yaw in sides.items():
        c, s = math.cos(yaw), math.sin(yaw)

        def at(x: float, y: float, z: float, c=c, s=s) -> tuple[float, float, float]:
            return (c * x + s * z, y, -s * x + c * z)

        # each side owns the corner column at its left end
        for k, x in enumerate(offsets[:-1]):
            b.place(column, f"column {side} {k}", at(x, 0.0, ARCADE), yaw)
            b.place(column, f"upper column {side} {k}", at(x, floor2, ARCADE), yaw,
                    scale=UPPER)
            b.place(arch, f"arch {side} {k}", at(x + BAY / 2, COLUMN_H, ARCADE), yaw)
            for j, dx in enumerate(np.linspace(-0.6, 0.6, 6)):
                b.place(baluster, f"baluster {side} {k}.{j}",
                        at(x + BAY / 2 + dx, floor2, ARCADE), yaw)
        b.place(corner_block, f"arch corner {side}", at(ARCADE, 0.0, ARCADE), yaw)
        trim = int(side in ("east", "west"))
        for name, pair in (("walkway", slab), ("roof", roof), ("beam", beam),
                           ("handrail", rail)):
            b.place(pair[trim], f"{name} {side}", (0.0, 0.0, 0.0), yaw)


def _fountain(b: _SceneBuilder) -> None:
    basin = _Parts()
    seg = 48
    basin.lathe(np.array([2.2, 2.2]), np.array([0.0, 0.5]), seg, 1.0)
    basin.lathe(np.array([2.2, 1.95]), np.array([0.5, 0.5]), seg, 1.0)
    basin.lathe(np.array([1.95, 1.95]), np.array([0.5, 0.1]), seg, 1.0)  # faces inward
    _disk(basin, 1.95, 0.1, seg, 1.0)
    # the pedestal and the upper bowl
    y = np.array([0.1, 0.3, 0.5, 0.9, 1.3, 1.5, 1.6])
    r = np.array([0.45, 0.4, 0.25, 0.2, 0.22, 0.35, 0.5])
    basin.lathe(r, y, seg, 1.0)
    t = np.linspace(0.0, 1.0, 6)
    basin.lathe(0.5 + 0.5 * t ** 0.7, 1.6 + 0.35 * t, seg, 1.0)
    basin.lathe(np.array([1.0, 0.92]), np.array([1.95, 1.95]), seg, 1.0)
    basin.lathe(0.92 - 0.87 * t, 1.95 - 0.25 * np.sin(t * math.pi / 2), seg, 1.0)
    b.place(b.mesh(basin, "fountain", "stone"), "fountain")
    water = _Parts()
    _disk(water, 1.95, 0.42, seg, 1.0)
    b.place(b.mesh(water, "water", "water"), "water")
    ball = _Parts()
    _sphere(ball, 0.35, 48, 24, 1.0)
    b.place(b.mesh(ball, "fountain sphere", "bronze"), "fountain sphere", (0.0, 2.25, 0.0))
    ring = _Parts()
    _torus(ring, 0.62, 0.05, 64, 16, 1.0)
    ring_m = b.mesh(ring, "ring", "gold")
    b.place(ring_m, "ring a", (0.0, 2.25, 0.0), tilt=math.radians(35))
    b.place(ring_m, "ring b", (0.0, 2.25, 0.0), yaw=math.pi / 2, tilt=math.radians(35))
    # four plinths, each a stack of boxes under a metal sphere
    plinth = _Parts()
    plinth.box((-0.45, 0.0, -0.45), (0.45, 0.25, 0.45), 1.0, faces="xXYzZ")
    plinth.box((-0.35, 0.25, -0.35), (0.35, 1.15, 0.35), 1.0, faces="xXYzZ")
    plinth.box((-0.42, 1.15, -0.42), (0.42, 1.3, 0.42), 1.0, faces="xXyYzZ")
    plinth_m = b.mesh(plinth, "plinth", "stone")
    sphere = _Parts()
    _sphere(sphere, 0.4, 48, 24, 1.0)
    sphere_m = [b.mesh(sphere, f"sphere {m}", m) for m in ("chrome", "gold", "copper",
                                                            "bronze")]
    for k, (x, z) in enumerate(((5.5, 0.0), (0.0, -5.5), (-5.5, 0.0), (0.0, 5.5))):
        b.place(plinth_m, f"plinth {k}", (x, 0.0, z), yaw=k * 0.3)
        b.place(sphere_m[k], f"sphere {k}", (x, 1.7, z))


def _props(b: _SceneBuilder, rng: np.random.Generator) -> None:
    """Crates and urns in the galleries, where the columns hide them."""
    crate = _Parts()
    crate.box((-0.4, 0.0, -0.4), (0.4, 0.8, 0.4), 1.25, faces="xXyYzZ")
    crate_m = b.mesh(crate, "crate", "wood")
    urn = _Parts()
    y = np.array([0.0, 0.05, 0.3, 0.6, 0.85, 0.95, 1.0])
    r = np.array([0.18, 0.2, 0.33, 0.36, 0.22, 0.17, 0.2])
    urn.lathe(r, y, 24, 1.0)
    _disk(urn, 0.2, 1.0, 24, 1.0)
    urn_m = b.mesh(urn, "urn", "terracotta")
    gallery = (ARCADE + ABACUS / 2 + 0.8, HALF - 0.6)

    def gallery_point(side: int, depth: float, along: float) -> tuple[float, float, float]:
        # side 0..3: south, east, north, west
        yaw = side * math.pi / 2
        c, s = math.cos(yaw), math.sin(yaw)
        return (c * along + s * depth, 0.0, -s * along + c * depth)

    for k in range(10):
        x, _, z = gallery_point(k % 4, rng.uniform(*gallery), rng.uniform(-10.5, 10.5))
        yaw = rng.uniform(0, math.pi / 2)
        for level in range(int(rng.integers(1, 4))):
            jitter = rng.uniform(-0.1, 0.1, 2)
            b.place(crate_m, f"crate {k}.{level}", (x + jitter[0], 0.8 * level, z + jitter[1]),
                    yaw + rng.uniform(-0.2, 0.2))
    for k in range(8):
        along = (-6.0 if k < 4 else 6.0) + rng.uniform(-1.0, 1.0)
        b.place(urn_m, f"urn {k}", gallery_point(k % 4, HALF - 0.6, along),
                rng.uniform(0, math.pi))
    lamp = _Parts()
    _sphere(lamp, 0.12, 16, 8, 1.0)
    lamp_m = b.mesh(lamp, "lamp", "glass lamp")
    for k, (x, z) in enumerate(_LANTERNS):
        # the bulb hangs above its light so it does not shadow it
        b.place(lamp_m, f"lamp {k}", (x, _LANTERN_Y + 0.3, z))


def _outside(b: _SceneBuilder, rng: np.random.Generator) -> None:
    """Houses and towers beyond the walls: mostly hidden from inside, seen above the walls."""
    kinds = []
    for k, (w, h, d) in enumerate(_HOUSES):
        house = _Parts()
        house.box((-w / 2, 0.0, -d / 2), (w / 2, h, d / 2), 0.5, faces="xXzZ")
        kinds.append((b.mesh(house, f"house {k}", "plaster"),
                      b.mesh(_roof(w + 0.4, d + 0.4, h, 2.0), f"house roof {k}",
                             "roof tiles")))
    n = 0
    for side in range(4):
        yaw = side * math.pi / 2
        for along0 in (-9.0, -3.0, 3.0, 9.0):
            # clear of the corner towers: |along| + half a house stays under 13.3
            along = along0 + rng.uniform(-1.0, 1.0)
            dist = rng.uniform(18.0, 23.0)
            c, s = math.cos(yaw), math.sin(yaw)
            pos = (c * along + s * dist, 0.0, -s * along + c * dist)
            body, roof = kinds[int(rng.integers(0, 3))]
            spin = yaw + float(rng.integers(0, 4)) * math.pi / 2
            b.place(body, f"house {n}", pos, spin)
            b.place(roof, f"house roof {n}", pos, spin)
            n += 1
    tower = _Parts()
    tower.box((-2.0, 0.0, -2.0), (2.0, 14.0, 2.0), 0.5, faces="xXzZ")
    tower_m = b.mesh(tower, "tower", "wall")
    spire = b.mesh(_roof(4.6, 4.6, 14.0, 5.0), "tower roof", "roof tiles")
    for k, (x, z) in enumerate(((1, 1), (1, -1), (-1, -1), (-1, 1))):
        pos = (x * (HALF + WALL_T + 2.5), 0.0, z * (HALF + WALL_T + 2.5))
        b.place(tower_m, f"tower {k}", pos)
        b.place(spire, f"tower roof {k}", pos)


_LANTERN_Y = 2.7
_LANTERNS = ((0.0, -10.2), (10.2, 0.0), (0.0, 10.2), (-10.2, 0.0))


def _lights_and_camera(b: _SceneBuilder) -> None:
    elevation, azimuth = math.radians(35.0), math.radians(45.0)
    # the sun stands in the north-west; its light travels south-east and down
    travel = (math.cos(elevation) * math.sin(azimuth), -math.sin(elevation),
              math.cos(elevation) * math.cos(azimuth))
    b.lights.append(Light("directional", (1.0, 0.93, 0.8), 6.0, direction=travel, name="sun"))
    colors = ((1.0, 0.55, 0.25), (0.3, 0.9, 0.85), (1.0, 0.35, 0.8), (1.0, 0.85, 0.6))
    for (x, z), color, name in zip(_LANTERNS, colors, ("north", "east", "south", "west"),
                                   strict=True):
        b.lights.append(Light("point", color, 30.0, position=(x, _LANTERN_Y, z), range=10.0,
                              name=f"lantern {name}"))
    b.lights.append(Light("point", (0.45, 0.65, 1.0), 20.0, position=(0.0, 3.2, 0.0),
                          range=8.0, name="fountain"))
    b.cameras.append(Camera(position=(-7.2, 1.7, 7.2), target=(3.0, 2.0, -3.0),
                            yfov=math.radians(65.0), znear=0.05, zfar=200.0, name="corner"))
