"""The scene as renderers see it: flat arrays ready for upload, world-space instances.

Loaders (glTF, OBJ/PLY through trimesh, the built-in courtyard) all produce a ``Scene``;
backends never see a file format.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import RfwError, warn
from .animation import Animation, Animator, Node


@dataclass
class Texture:
    """An RGBA8 image, row-major, top row first."""

    name: str
    pixels: np.ndarray | None  # (H, W, 4) uint8; None once uploaded (Scene.keep_pixels)
    srgb: bool = True  # base color and emissive are sRGB; normal, metal-rough, occlusion linear
    # sampler, in WebGPU terms
    mag_filter: str = "linear"  # linear | nearest
    min_filter: str = "linear"
    mipmap_filter: str = "linear"
    address_u: str = "repeat"  # repeat | mirror-repeat | clamp-to-edge
    address_v: str = "repeat"


@dataclass
class Material:
    """glTF 2.0 metallic-roughness material; texture fields index ``Scene.textures``."""

    name: str = "default"
    base_color: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)  # linear
    metallic: float = 0.0
    roughness: float = 1.0
    emissive: tuple[float, float, float] = (0.0, 0.0, 0.0)
    base_color_texture: int | None = None
    metallic_roughness_texture: int | None = None  # G: roughness, B: metallic
    normal_texture: int | None = None
    normal_scale: float = 1.0
    occlusion_texture: int | None = None  # R
    occlusion_strength: float = 1.0
    emissive_texture: int | None = None
    alpha_mode: str = "OPAQUE"  # OPAQUE | MASK | BLEND
    alpha_cutoff: float = 0.5
    double_sided: bool = False
    # KHR_materials_specular's specularFactor: the strength of a dielectric's specular lobe
    # (0: pure Lambert). The path tracer reads it; the raster passes shade it as 1.
    specular: float = 1.0


# how a mesh's indices join its vertices, in WebGPU's names: triangles for ``Scene.meshes``,
# points or lines (one index per point, two per segment) for ``Scene.strokes``
TOPOLOGIES = ("triangle-list", "line-list", "point-list")


@dataclass
class Mesh:
    """One primitive with one material: triangles, or (in ``Scene.strokes``) points or
    line segments. Arrays are contiguous."""

    name: str
    positions: np.ndarray  # (V, 3) float32
    normals: np.ndarray  # (V, 3) float32, unit length
    uvs: np.ndarray  # (V, 2) float32 (zeros when the source has none)
    tangents: np.ndarray  # (V, 4) float32, xyz + handedness w
    indices: np.ndarray  # (T*3,) uint32
    material: int = 0  # index into Scene.materials
    topology: str = "triangle-list"  # one of TOPOLOGIES
    # (V, 4) float32 linear RGBA, the COLOR_0 of a stroke (a point or line primitive), which
    # is drawn per vertex; triangles carry theirs in the material (None)
    colors: np.ndarray | None = None

    @property
    def triangle_count(self) -> int:
        return len(self.indices) // 3

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self.positions.min(axis=0), self.positions.max(axis=0)


@dataclass
class Instance:
    """A mesh placed in the world."""

    mesh: int  # index into Scene.meshes
    transform: np.ndarray  # (4, 4) float32, column vectors: world = T @ local
    name: str = ""
    # the node of Scene.nodes that places it, where the scene is animated (None: it is
    # placed by its transform alone); its transform is that node's rest world matrix
    node: int | None = None


def transform_problem(transform: np.ndarray) -> str | None:
    """Why ``transform`` cannot place an instance, or None when it can.

    Renderers need a finite affine matrix whose float32 inverse-transpose (the normal
    matrix) is finite too: a zero scale (valid glTF) collapses the mesh and has no normal.
    """
    m = np.asarray(transform, np.float64)
    if m.shape != (4, 4):
        return f"transform has shape {m.shape}, not (4, 4)"
    if not np.all(np.isfinite(m)) or not np.all(np.isfinite(m.astype(np.float32))):
        return "transform has NaN or infinite entries (in float32)"
    if not np.array_equal(m[3], [0.0, 0.0, 0.0, 1.0]):
        return "transform is not affine (last row is not 0 0 0 1)"
    a = m[:3, :3]
    scale = float(np.abs(a).max())
    # relative to the largest entry: a scale of 1e-3 is fine, a collapsed axis is not
    if scale == 0.0 or abs(float(np.linalg.det(a / scale))) < 1e-12:
        return "transform is singular (a zero scale collapses the mesh)"
    normal = np.linalg.inv(a).T.astype(np.float32)
    if not np.all(np.isfinite(normal)):
        return "transform's normal matrix overflows float32"
    return None


def _stacked(transforms: list) -> tuple[np.ndarray, np.ndarray]:
    """``transforms`` as one (n, 4, 4) float64 array (identity where one is not 4x4), and
    which were 4x4."""
    try:
        m = np.asarray(transforms, np.float64)
        if m.shape == (len(transforms), 4, 4):
            return m, np.ones(len(transforms), bool)
    except (ValueError, TypeError):  # ragged: some are not 4x4
        pass
    shaped = np.array([np.shape(t) == (4, 4) for t in transforms], bool)
    m = np.tile(np.identity(4), (len(transforms), 1, 1))
    for k in np.flatnonzero(shaped):
        m[k] = transforms[k]
    return m, shaped


# world coordinates beyond this lose every digit a renderer needs (their squares, taken in
# float32 for distances, overflow near 1.8e19)
WORLD_LIMIT = 1e18


def _corners(mesh: Mesh, transform: np.ndarray) -> np.ndarray:
    a, b = mesh.bounds()
    corners = np.array([[x, y, z, 1.0] for x in (a[0], b[0]) for y in (a[1], b[1])
                        for z in (a[2], b[2])])
    with np.errstate(all="ignore"):
        return (corners @ np.asarray(transform, np.float64).T)[:, :3]


def is_mirrored(transform: np.ndarray) -> bool:
    """True when ``transform`` turns the mesh inside out (negative determinant): its
    triangles' winding flips on screen, so front faces must be chosen the other way."""
    return float(np.linalg.det(np.asarray(transform, np.float64)[:3, :3])) < 0.0


@dataclass
class Light:
    kind: str  # directional | point | spot
    color: tuple[float, float, float] = (1.0, 1.0, 1.0)  # linear
    intensity: float = 1.0  # lux for directional, candela for point and spot (KHR_lights)
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    direction: tuple[float, float, float] = (0.0, -1.0, 0.0)  # where the light travels
    range: float | None = None
    inner_cone: float = 0.0
    outer_cone: float = np.pi / 4
    name: str = ""


@dataclass
class Camera:
    """A perspective camera looking down its local -Z with +Y up."""

    position: tuple[float, float, float] = (0.0, 1.0, 5.0)
    target: tuple[float, float, float] = (0.0, 0.0, 0.0)
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)
    yfov: float = np.radians(60.0)
    znear: float = 0.05
    zfar: float = 500.0
    name: str = ""

    def view(self) -> np.ndarray:
        eye, at, up = (np.asarray(v, np.float64) for v in (self.position, self.target, self.up))
        f = at - eye
        length = float(np.linalg.norm(f))
        if not (np.all(np.isfinite(eye)) and 0.0 < length < np.inf):
            raise SceneError(f"position {tuple(map(float, eye))} and target "
                             f"{tuple(map(float, at))} must be finite and apart",
                             element=f"camera {self.name!r}" if self.name else "camera")
        f /= length
        s = np.cross(f, up)
        if not np.linalg.norm(s) > 1e-6 * (np.linalg.norm(up) or 1.0):
            # looking along 'up' (straight down, say): any other axis gives the image a top
            s = np.cross(f, np.identity(3)[int(np.argmin(np.abs(f)))])
        s /= np.linalg.norm(s)
        u = np.cross(s, f)
        m = np.identity(4)
        m[0, :3], m[1, :3], m[2, :3] = s, u, -f
        m[:3, 3] = -m[:3, :3] @ eye
        return m.astype(np.float32)

    def projection(self, aspect: float) -> np.ndarray:
        """Reverse-free, right-handed, depth 0..1 (WebGPU and Vulkan clip space)."""
        f = 1.0 / np.tan(self.yfov / 2)
        n, z = self.znear, self.zfar
        m = np.zeros((4, 4))
        m[0, 0] = f / aspect
        m[1, 1] = f
        m[2, 2] = z / (n - z)
        m[2, 3] = n * z / (n - z)
        m[3, 2] = -1.0
        return m.astype(np.float32)


@dataclass
class Scene:
    name: str
    meshes: list[Mesh] = field(default_factory=list)
    materials: list[Material] = field(default_factory=lambda: [Material()])
    textures: list[Texture] = field(default_factory=list)
    instances: list[Instance] = field(default_factory=list)
    lights: list[Light] = field(default_factory=list)
    cameras: list[Camera] = field(default_factory=list)
    source: str | None = None
    # False: a backend drops each texture's pixels (Texture.pixels = None) once it has
    # uploaded them, so a texture-heavy scene is not held on the host and on the device at
    # once; rfw.run sets it for a scene it loaded itself and uploads once
    keep_pixels: bool = True
    # points and line segments (glTF modes 0 to 3, point clouds, polylines), drawn one pixel
    # wide by the points_lines pass; stroke_instances place them (Instance.mesh: a stroke)
    strokes: list[Mesh] = field(default_factory=list)
    stroke_instances: list[Instance] = field(default_factory=list)
    # node animations (rfw.scene.animation): the node hierarchy instances are placed by
    # (Instance.node) and the clips that move it; both empty for a still scene
    nodes: list[Node] = field(default_factory=list)
    animations: list[Animation] = field(default_factory=list)

    @property
    def triangle_count(self) -> int:
        return sum(self.meshes[i.mesh].triangle_count for i in self.instances)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """World-space axis-aligned bounds of all drawable instances (degenerate
        transforms and empty meshes are left out, as renderers leave them out)."""
        problems, world, usable = self._instance_checks()
        keep = usable & np.array([why is None for why in problems], bool)
        corners = [world[keep].reshape(-1, 3), *self._stroke_corners()]
        corners = np.concatenate(corners)
        if not len(corners):
            return np.full(3, np.inf), np.full(3, -np.inf)
        return corners.min(axis=0), corners.max(axis=0)

    def draw_count(self, topology: str = "triangle-list") -> int:
        """How many draws a backend's ``draw`` records for ``topology`` at most: the
        instances for triangles, else the stroke instances of that kind (0: a caller need
        not begin a render pass)."""
        if topology == "triangle-list":
            return len(self.instances)
        return sum(1 for i in self.stroke_instances if self.strokes[i.mesh].topology == topology)

    def _stroke_corners(self) -> list[np.ndarray]:
        """The world corners of each drawable stroke instance's bounds (strokes are few:
        checked one by one)."""
        return [_corners(self.strokes[i.mesh], i.transform) for i in self.stroke_instances
                if 0 <= i.mesh < len(self.strokes) and len(self.strokes[i.mesh].positions)
                and self.stroke_problem(i) is None]

    def stroke_problem(self, inst: Instance) -> str | None:
        """``instance_problem`` of a stroke instance (``inst.mesh`` indexes ``strokes``)."""
        return replace(self, meshes=self.strokes).instance_problem(inst)

    def _instance_checks(self) -> tuple[list[str | None], np.ndarray, np.ndarray]:
        """``instance_problem`` of every instance, the (n, 8, 3) world corners of its
        mesh's bounds, and where those mean something (the mesh is known and not empty),
        computed for all instances at once: a scene may hold 100,000 of them. An instance
        any batched test doubts is checked again alone, so the reasons are
        ``instance_problem``'s own."""
        n = len(self.instances)
        problems: list[str | None] = [None] * n
        if not n:
            return problems, np.zeros((0, 8, 3)), np.zeros(0, bool)
        m, shaped = _stacked([i.transform for i in self.instances])
        with np.errstate(all="ignore"):
            a = m[:, :3, :3]
            scale = np.abs(a).max(axis=(1, 2))
            ok = np.asarray(shaped) & np.isfinite(m).all(axis=(1, 2)) \
                & np.isfinite(m.astype(np.float32)).all(axis=(1, 2)) \
                & (m[:, 3] == [0.0, 0.0, 0.0, 1.0]).all(axis=1) & (scale > 0.0)
            det = np.zeros(n)
            det[ok] = np.linalg.det(a[ok] / scale[ok, None, None])
            ok &= np.abs(det) >= 1e-12
            normal = np.linalg.inv(a[ok])
            ok[np.flatnonzero(ok)] = np.isfinite(normal.astype(np.float32)).all(axis=(1, 2))
            corners, has = self._mesh_corners()
            mesh = np.fromiter((i.mesh for i in self.instances), np.int64, n)
            known = (mesh >= 0) & (mesh < len(self.meshes))
            mesh = np.where(known, mesh, 0)
            usable = known & has[mesh]
            pts = (corners[mesh] @ m.transpose(0, 2, 1))[:, :, :3]  # as _corners does
            far = np.abs(pts).max(axis=(1, 2))
            ok &= ~usable | (far <= WORLD_LIMIT)
        for k in np.flatnonzero(~ok):
            problems[k] = self.instance_problem(self.instances[k])
        return problems, pts, usable

    def _mesh_corners(self) -> tuple[np.ndarray, np.ndarray]:
        """The 8 homogeneous corners of each mesh's bounds, and which meshes have any."""
        out = np.zeros((max(1, len(self.meshes)), 8, 4))
        has = np.zeros(max(1, len(self.meshes)), bool)
        for j, mesh in enumerate(self.meshes):
            if len(mesh.positions):
                lo, hi = mesh.bounds()
                out[j] = [[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                          for z in (lo[2], hi[2])]
                has[j] = True
        return out, has

    def instance_problem(self, inst: Instance) -> str | None:
        """Why ``inst`` cannot be drawn, or None: its transform (``transform_problem``), or
        a world position too far out for float32 arithmetic."""
        why = transform_problem(inst.transform)
        if why is None and 0 <= inst.mesh < len(self.meshes) \
                and len(self.meshes[inst.mesh].positions):
            far = float(np.abs(_corners(self.meshes[inst.mesh], inst.transform)).max())
            if not far <= WORLD_LIMIT:
                why = f"it reaches {far:.3g} from the origin (more than {WORLD_LIMIT:g})"
        return why

    def _moving(self) -> frozenset[int]:
        """The nodes the scene's animations move (``rfw.scene.animation.Animator``)."""
        if not self.animations:
            return frozenset()
        return Animator(self.nodes, self.animations).moving

    def default_camera(self) -> Camera:
        """The scene's first camera, else one framing its bounds."""
        if self.cameras:
            return self.cameras[0]
        lo, hi = self.bounds()
        if not np.all(np.isfinite(lo)):  # nothing drawable: look at the origin
            lo, hi = np.full(3, -1.0), np.ones(3)
        center = (lo + hi) / 2
        radius = float(np.linalg.norm(hi - lo)) / 2 or 1.0
        eye = center + np.array([0.6, 0.5, 1.0]) / np.linalg.norm([0.6, 0.5, 1.0]) * radius * 2.0
        return Camera(tuple(eye), tuple(center), zfar=radius * 10, znear=radius * 0.01)

    def drawable(self) -> Scene:
        """This scene without instances that cannot be drawn (singular, NaN or infinite
        transforms), each named in a one-line warning; ``self`` when none is dropped.

        A scene with nothing left to draw is rendered as it is (the background only), as
        an empty glTF scene is valid: one warning line says so, whether the file had no
        instances or every one was skipped (for a scene built in code without instances,
        nothing is said)."""
        keep = []
        # an instance an animation moves is drawn as each frame poses it (a zero scale
        # draws nothing): only a rest pose that is not finite leaves it out
        moving = self._moving()
        for k, (inst, why) in enumerate(zip(self.instances, self._instance_checks()[0],
                                            strict=True)):
            if why is None or (inst.node in moving and np.isfinite(inst.transform).all()):
                keep.append(inst)
            else:
                warn(f"{self.source or self.name}: instance {inst.name or k!r} skipped: {why}")
        strokes = []
        for k, inst in enumerate(self.stroke_instances):
            why = self.stroke_problem(inst)
            if why is None or (inst.node in moving and np.isfinite(inst.transform).all()):
                strokes.append(inst)
            else:
                warn(f"{self.source or self.name}: points or lines {inst.name or k!r} "
                     f"skipped: {why}")
        if not keep and not strokes and (self.instances or self.stroke_instances
                                         or self.source):
            # one line for both (and for the backends' second look at the loader's scene)
            warn(f"{self.source or self.name}: nothing is drawable (no instances, or every "
                 "one skipped): the images show the background only")
        if len(keep) == len(self.instances) and len(strokes) == len(self.stroke_instances):
            return self
        return replace(self, instances=keep, stroke_instances=strokes)


class SceneError(RfwError):
    """A scene that cannot be loaded: the message names the file and the element."""
