"""The scene's GPU-visible bytes, shared by the wgpu and Vulkan backends.

Layouts follow ``shaders/common/scene.glsl`` (group 1) and ``mesh.glsl`` (groups 2 and 3);
the GLSL twins declare the same offsets.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Iterator
from dataclasses import replace
from typing import Any

import numpy as np

from ..scene.animation import Animator
from ..scene.limits import check_texture_size
from ..scene.model import Camera, Light, Material, Mesh, Scene, SceneError, Texture

# the scene's groups (Vulkan: sets) as scene.glsl and mesh.glsl declare them: (name, binding,
# kind as rfw.spirv reflects it). Both backends build their scene layouts from this one table,
# and a pass that declares one of these groups binds the scene's own
SCENE_GROUPS: dict[int, tuple[tuple[str, int, str], ...]] = {
    1: (("camera", 0, "uniform_buffer"), ("lights", 1, "uniform_buffer")),
    2: (("material", 0, "uniform_buffer"), ("base_color_tex", 1, "sampled_image"),
        ("metal_rough_tex", 2, "sampled_image"), ("normal_tex", 3, "sampled_image"),
        ("occlusion_tex", 4, "sampled_image"), ("emissive_tex", 5, "sampled_image"),
        ("material_sampler", 6, "sampler")),
    3: (("scene_instances", 0, "storage_buffer"),),
}
INSTANCE_BYTES = 128  # mesh.glsl's InstanceData (model and normal matrices), std430 stride
MAX_LIGHTS = 16
DEFAULT_SUN = Light("directional", (1.0, 0.97, 0.92), 3.0, direction=(-0.35, -1.0, -0.45),
                    name="rfw default sun")
# lights.ambient: the raster passes' ambient term and the path tracer's uniform sky radiance
AMBIENT = (0.03, 0.035, 0.045)
_ALPHA = {"OPAQUE": 0, "MASK": 1, "BLEND": 2}


def mip_chain(pixels: np.ndarray, *, srgb: bool = False) -> list[np.ndarray]:
    """A box-filtered chain on the CPU, each level the mean of 2x2 (or 2x1) texels.

    Linear textures (and every texture's alpha) take the rounded mean of the bytes: sums in
    uint16 (half a float32 level's bytes), the same bytes as averaging in float32 and
    rounding half up, since every partial mean is exact there. Where ``srgb`` (base colour
    and emissive, which glTF stores sRGB-encoded) the colour channels are averaged as the
    GPU filters them: each byte decoded to linear (``SRGB_TO_LINEAR``), the mean taken in
    float64 and encoded back to the nearest sRGB byte (``_LINEAR_EDGES``); averaging the
    encoded bytes instead darkens every level where texels differ (a red/white checker's
    green and blue come out 128, linear 0.22, not 188, linear 0.50)."""
    return list(mip_levels(pixels, srgb=srgb))


def mip_levels(pixels: np.ndarray, *, srgb: bool = False) -> Iterator[np.ndarray]:
    """``mip_chain`` one level at a time (``pixels`` first), so an uploader holds one level
    and the next, not the whole chain; each level is built in bands of rows, so the sums
    are a few tens of MiB however large the image."""
    level = pixels
    yield level
    while max(level.shape[:2]) > 1:
        level = _half(level, srgb)
        yield level


MIP_BAND_TEXELS = 1 << 20  # output texels per band (32 MiB of RGBA uint16 sums in, or 48
# MiB of float64 RGB sums of an sRGB texture: one output-sized array and one lookup)


def _srgb_decode(c: np.ndarray) -> np.ndarray:
    """The sRGB transfer function taken off values in [0, 1], in float64."""
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


# every sRGB byte's linear value, and the linear values halfway (in sRGB) between
# neighbouring bytes: a linear mean m encodes to the byte of the edges at or below it,
# which is round-half-up of 255 * encode(m) without evaluating the encoding's power
SRGB_TO_LINEAR = _srgb_decode(np.arange(256) / 255.0)
_LINEAR_EDGES = _srgb_decode((np.arange(255) + 0.5) / 255.0)


def _half(src: np.ndarray, srgb: bool = False) -> np.ndarray:
    h, w = src.shape[:2]
    rows, cols = (2 if h >= 2 else 1), (2 if w >= 2 else 1)
    out = np.empty((max(h // 2, 1), max(w // 2, 1), *src.shape[2:]), np.uint8)
    step = max(1, MIP_BAND_TEXELS // out.shape[1])
    for y in range(0, out.shape[0], step):
        end = min(y + step, out.shape[0])
        # an odd last row or column is dropped, as the whole-level chain did
        band = src[y * rows:end * rows, :out.shape[1] * cols]
        if srgb:  # colour in linear light, alpha as a linear texture's
            out[y:end, :, :3] = _srgb_mean(band[..., :3], rows, cols)
            out[y:end, :, 3:] = _byte_mean(band[..., 3:], rows, cols)
        else:
            out[y:end] = _byte_mean(band, rows, cols)
    return out


def _byte_mean(band: np.ndarray, rows: int, cols: int) -> np.ndarray:
    """The rounded (half up) means of ``band``'s ``rows`` x ``cols`` blocks, in uint16."""
    n = rows * cols
    p = band.astype(np.uint16)
    if rows == 2:
        p = p[0::2] + p[1::2]
    if cols == 2:
        p = p[:, 0::2] + p[:, 1::2]
    p += n // 2
    p //= n
    return p


def _srgb_mean(band: np.ndarray, rows: int, cols: int) -> np.ndarray:
    """The sRGB bytes nearest the linear means of ``band``'s ``rows`` x ``cols`` blocks."""
    total = SRGB_TO_LINEAR[band[0::rows, 0::cols]]
    for dy, dx in ((0, 1), (1, 0), (1, 1)):
        if dy < rows and dx < cols:
            total += SRGB_TO_LINEAR[band[dy::rows, dx::cols]]
    total /= rows * cols
    return np.searchsorted(_LINEAR_EDGES, total, side="right")


def check_instance_limits(scene: Scene, limits: dict[str, Any], keys: tuple[str, ...]) -> int:
    """The bytes of ``scene``'s instance buffer (one row per instance, then per stroke
    instance), or a SceneError naming the scene when it is over one of the device's
    ``limits`` named by ``keys`` (the backend's: how much one storage binding can reach;
    wgpu-native would abort, a driver might read past the range)."""
    rows = len(scene.instances) + len(scene.stroke_instances)
    size = max(1, rows) * INSTANCE_BYTES
    for key in keys:
        limit = int(limits.get(key, size))
        if size > limit:
            raise SceneError(f"{rows:,} instances need {size:,} bytes of instance data, over "
                             f"this device's {key} ({limit:,}): at most "
                             f"{limit // INSTANCE_BYTES:,} fit", file=scene.name,
                             element="instances")
    return size


def texture_views(scene: Scene, limit: int | None, key: str,
                  make: Callable[[Texture], Any]) -> list[Any]:
    """One view per ``scene.textures``, made by ``make``. All are checked against the
    device's 2D ``limit`` (``key`` names it) before the first is made, and textures sharing
    an image in one colour space (a glTF image named by many textures) share one upload.
    Where the scene does not keep its pixels (``Scene.keep_pixels``), each image is dropped
    from its textures once its last view is made."""
    for t in scene.textures:
        if t.pixels is None:
            raise SceneError(f"texture '{t.name}': its pixels were dropped after an earlier "
                             "upload (Scene.keep_pixels is False): load the scene again",
                             file=scene.source)
        check_texture_size(t.pixels.shape[1], t.pixels.shape[0], limit, key,
                           file=scene.source, name=t.name)
    keys = [(id(t.pixels), t.srgb) for t in scene.textures]
    sharing: dict[int, list[Texture]] = {}
    for t in scene.textures:
        sharing.setdefault(id(t.pixels), []).append(t)
    last = {k[0]: i for i, k in enumerate(keys)}
    views: dict[tuple[int, bool], Any] = {}
    for i, (t, k) in enumerate(zip(scene.textures, keys, strict=True)):
        if k not in views:
            views[k] = make(t)
        if not scene.keep_pixels and last[k[0]] == i:
            for u in sharing[k[0]]:
                u.pixels = None
    return [views[k] for k in keys]


def sun_view_proj(scene: Scene, direction: np.ndarray) -> np.ndarray:
    """An orthographic light camera that encloses the scene's bounds along ``direction``
    (where animations move instances, wherever their keys take them: ``posed_bounds``)."""
    lo, hi = posed_bounds(scene)
    if not np.all(np.isfinite(lo)):  # nothing drawable: any box will do
        lo, hi = np.zeros(3), np.ones(3)
    center = (lo + hi) / 2
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 1e-3)
    d = direction / np.linalg.norm(direction)
    up = np.array([0.0, 1.0, 0.0]) if abs(d[1]) < 0.99 else np.array([1.0, 0.0, 0.0])
    cam = Camera(tuple(center - d * radius * 2), tuple(center), tuple(up))
    view = cam.view().astype(np.float64)
    n, f = radius * 0.5, radius * 3.5
    proj = np.identity(4)
    proj[0, 0] = proj[1, 1] = 1.0 / radius
    proj[2, 2] = 1.0 / (n - f)
    proj[2, 3] = n / (n - f)
    return (proj @ view).astype(np.float32)




def posed_bounds(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """``scene.bounds()``, and where animations move instances, theirs at every key time of
    the clips too (``Animator.key_times``: a linear path lies between its keys)."""
    lo, hi = scene.bounds()
    if not scene.animations:
        return lo, hi
    frames = InstanceFrames(replace(scene, stroke_instances=[]))
    if not frames.moves:
        return lo, hi
    parts = [np.stack([lo, hi])] if np.all(np.isfinite(lo)) else []
    keep = [k for k in frames.moving if len(scene.meshes[scene.instances[k].mesh].positions)]
    if not keep:
        return lo, hi
    boxes = [scene.meshes[scene.instances[k].mesh].bounds() for k in keep]
    corners = np.array([[[x, y, z, 1.0] for x in (a[0], b[0]) for y in (a[1], b[1])
                         for z in (a[2], b[2])] for a, b in boxes])  # (n, 8, 4)
    for t in frames.animator.key_times(limit=64):
        world = frames.transforms(float(t))[keep].astype(np.float64)
        pts = np.einsum("nij,nkj->nki", world, corners)[..., :3].reshape(-1, 3)
        parts.append(pts[np.isfinite(pts).all(axis=1)])
    pts = np.concatenate(parts)
    return pts.min(axis=0), pts.max(axis=0)


def material_bytes(m: Material) -> bytes:
    """material.glsl's MaterialFactors: flags x alpha mode, y double-sided, z the specular
    factor's float bits (uintBitsToFloat)."""
    return struct.pack("<4f4f4f2If1I", *m.base_color, *m.emissive, m.normal_scale,
                       m.metallic, m.roughness, m.occlusion_strength, m.alpha_cutoff,
                       _ALPHA.get(m.alpha_mode, 0), int(m.double_sided), m.specular, 0)


def instance_bytes(model: np.ndarray) -> bytes:
    """The model matrix, then its inverse-transpose for normals (which keeps a mirrored
    instance's normals pointing out; ``Scene.drawable`` has dropped singular ones)."""
    return instance_blocks([model]).tobytes()


def instance_blocks(models: Any) -> np.ndarray:
    """``instance_bytes`` of every model at once: one float32 row of 32 per instance (one
    batched inverse instead of one per instance). A singular model (an animated node's
    rest pose may scale it to zero) gets ``pose_blocks``' zero row."""
    m = np.asarray(models, np.float64).reshape(-1, 4, 4)
    try:
        inverse = np.linalg.inv(m)
    except np.linalg.LinAlgError:
        return pose_blocks(m)
    # GLSL matrices are column-major: the model's columns, then those of inv(model).T,
    # which are inv(model)'s rows
    return np.concatenate([m.transpose(0, 2, 1).reshape(-1, 16),
                           inverse.reshape(-1, 16)], axis=1).astype(np.float32)


def pose_blocks(models: Any) -> np.ndarray:
    """``instance_blocks`` of transforms an animation made, where a scale may reach zero:
    a singular transform's row is all zeros (its mesh collapses to nothing drawn)."""
    m = np.asarray(models, np.float64).reshape(-1, 4, 4)
    a = m[:, :3, :3]
    scale = np.abs(a).max(axis=(1, 2))
    ok = np.isfinite(m).all(axis=(1, 2)) & (scale > 0.0)
    with np.errstate(all="ignore"):
        ok[ok] = np.abs(np.linalg.det(a[ok] / scale[ok, None, None])) >= 1e-12
    out = np.zeros((len(m), 32), np.float32)
    if ok.any():
        out[ok] = np.concatenate([m[ok].transpose(0, 2, 1).reshape(-1, 16),
                                  np.linalg.inv(m[ok]).reshape(-1, 16)], axis=1)
    return out


def mirrored_mask(models: Any) -> np.ndarray:
    """``is_mirrored`` of every model at once (one batched determinant): bool per model."""
    m = np.asarray(models, np.float64).reshape(-1, 4, 4)
    return np.linalg.det(m[:, :3, :3]) < 0.0


def mirrored_arrays(mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """Indices and tangents for drawing ``mesh`` under a mirroring transform.

    A negative determinant reverses every triangle's winding on screen, so its front faces
    would be culled: swapping two corners restores counter-clockwise front faces for every
    pass and backend with the pipelines unchanged. The tangent's w flips too, because
    ``cross(M n, M t)`` points against ``M cross(n, t)`` when M mirrors.
    """
    indices = np.ascontiguousarray(mesh.indices.astype(np.uint32).reshape(-1, 3)[:, [0, 2, 1]])
    tangents = mesh.tangents.astype(np.float32, copy=True)
    tangents[:, 3] *= -1.0
    return indices.ravel(), tangents


def lights_bytes(scene: Scene) -> tuple[bytes, np.ndarray, bool]:
    """The lights uniform, the sun's view-projection and whether the default sun was used
    (a scene without lights, like most fetched models, gets one so it is not black)."""
    lights = scene.lights[:MAX_LIGHTS] or [DEFAULT_SUN]
    sun = next((i for i, li in enumerate(lights) if li.kind == "directional"), MAX_LIGHTS)
    direction = np.array(lights[sun].direction if sun < MAX_LIGHTS else (-0.3, -1, -0.2))
    matrix = sun_view_proj(scene, direction)
    out = struct.pack("<4I", len(lights), sun, 0, 0)
    out += matrix.T.tobytes()
    out += struct.pack("<4f", *AMBIENT, 0.0)
    kinds = {"directional": 0, "point": 1, "spot": 2}
    for li in lights:
        out += struct.pack("<4f", *li.position, kinds[li.kind])
        out += struct.pack("<4f", *li.direction, li.range or 0.0)
        out += struct.pack("<4f", *li.color, li.intensity)
        out += struct.pack("<4f", np.cos(li.inner_cone), np.cos(li.outer_cone), 0, 0)
    return out + b"\0" * (64 * (MAX_LIGHTS - len(lights))), matrix, not scene.lights


def camera_bytes(camera: Camera, view: np.ndarray, proj: np.ndarray, pos: tuple,
                 size: tuple[int, int]) -> bytes:
    vp = proj.astype(np.float64) @ view.astype(np.float64)
    inv = np.linalg.inv(vp)
    out = b"".join(np.asarray(m, np.float32).T.tobytes() for m in (view, proj, vp, inv))
    out += struct.pack("<4f", *pos, 1.0)
    out += struct.pack("<4f", size[0], size[1], 1 / size[0], 1 / size[1])
    out += struct.pack("<4f", camera.znear, camera.zfar, 0, 0)
    return out


def main_camera_bytes(camera: Camera, size: tuple[int, int]) -> bytes:
    return camera_bytes(camera, camera.view(), camera.projection(size[0] / size[1]),
                        camera.position, size)


MOTION_BYTES = 208  # motion.glsl's MotionBlock


def halton(index: int, base: int) -> float:
    """The radical inverse of ``index`` in ``base``: the Halton sequence's ``index``-th point."""
    out, f = 0.0, 1.0
    while index > 0:
        f /= base
        out += f * (index % base)
        index //= base
    return out


def jitter_offset(frame: int, phases: int) -> tuple[float, float]:
    """Frame ``frame``'s sub-pixel shift of the image in pixels (x right, y down, each in
    [-0.5, 0.5)): Halton (2, 3) point ``frame % phases + 1`` (point 0 is the corner); (0, 0)
    without ``phases``."""
    if phases <= 0:
        return 0.0, 0.0
    k = frame % phases + 1
    return halton(k, 2) - 0.5, halton(k, 3) - 0.5


def jittered(proj: np.ndarray, offset: tuple[float, float], size: tuple[int, int]
             ) -> np.ndarray:
    """``proj`` followed by a shift of normalised device coordinates that moves the image
    by ``offset`` pixels (y down, ndc y up): any projection, not only a perspective one."""
    shift = np.identity(4)
    shift[0, 3] = 2.0 * offset[0] / size[0]
    shift[1, 3] = -2.0 * offset[1] / size[1]
    return (shift @ proj.astype(np.float64)).astype(np.float32)


class CameraFrames:
    """The main camera as each frame sees it: its projection jittered by ``jitter`` phases
    of sub-pixel offsets (0: none, the camera as it is), and the motion block
    (``motion.glsl``) holding last frame's view-projection for motion vectors.

    ``begin(camera, size, index)`` gives the bytes of frame ``index`` when it begins. The
    frame after the one begun last takes that frame's matrices as its previous ones; any
    other frame (the first, an executor's first on a kept scene) has no previous frame and
    gets its own (zero motion). A camera set between frames is the next frame's: nothing
    of the frame that ran is changed by it."""

    def __init__(self) -> None:
        self.jitter = 0  # Halton (2, 3) phases: set by the frame from its passes
        self.index: int | None = None  # the frame begun last
        self._ran: tuple[np.ndarray, np.ndarray, tuple[float, float]] | None = None

    def begin(self, camera: Camera, size: tuple[int, int], index: int
              ) -> tuple[bytes, bytes] | None:
        """The main camera's and the motion block's bytes for frame ``index``; None when
        that frame has begun already (a second executor on the scene, the same frame)."""
        if index == self.index:
            return None
        prev = self._ran if self.index is not None and index == self.index + 1 else None
        self.index = index
        main, motion, self._ran = self._frame(camera, size, index, prev)
        return main, motion

    def still(self, camera: Camera, size: tuple[int, int]) -> tuple[bytes, bytes]:
        """The bytes before any frame begins (``set_viewport``): the camera as it is, no
        jitter, no motion."""
        main, motion, _ = self._frame(camera, size, 0, None, jitter=0)
        return main, motion

    def _frame(self, camera: Camera, size: tuple[int, int], index: int,
               prev: tuple[np.ndarray, np.ndarray, tuple[float, float]] | None, *,
               jitter: int | None = None) -> tuple[bytes, bytes, tuple]:
        view = camera.view()
        proj = camera.projection(size[0] / size[1])
        offset = jitter_offset(index, self.jitter if jitter is None else jitter)
        # unjittered: motion vectors carry the motion alone, not the jitter
        vp = proj.astype(np.float64) @ view.astype(np.float64)
        now = (vp, np.linalg.inv(vp), offset)
        before = prev if prev is not None else now
        main = camera_bytes(camera, view, jittered(proj, offset, size) if any(offset)
                            else proj, camera.position, size)
        motion = b"".join(np.asarray(m, np.float32).T.tobytes()
                          for m in (before[0], before[1], vp))
        motion += struct.pack("<4f", *offset, *before[2])
        return main, motion, now


class InstanceFrames:
    """Every placed instance's row (``instance_blocks``: the instances', then the stroke
    instances') as each frame sees it, where the scene's animations move them: the twin of
    :class:`CameraFrames`.

    ``time`` is the scene's time in seconds (its animations' timeline), set between frames
    by the frame driver (:mod:`rfw.timeline`) and read when a frame begins.
    ``begin(index)`` gives frame ``index``'s rows and last frame's (for motion vectors):
    the frame after the one begun last takes that frame's rows as its previous ones; any
    other frame has none and gets its own (zero motion), as does an instance whose last
    transform was singular. ``pose`` counts the frames whose rows differ from the frame
    begun before them (a path tracer restarts its sums when it changes). A scene without
    animations never moves (``moves`` False): ``begin`` then gives nothing to write."""

    def __init__(self, scene: Scene):
        animator = Animator(scene.nodes, scene.animations) if scene.animations else None
        self.animator = animator
        # a still scene keeps nothing: 100,000 instances cost no copy of their transforms
        placed = [*scene.instances, *scene.stroke_instances] if animator is not None else []
        self.nodes = [i.node for i in placed]
        # the rows that move: those of instances placed by a node an animation moves
        self.moving = np.array([k for k, n in enumerate(self.nodes)
                                if n in animator.moving], np.int64) if placed else \
            np.zeros(0, np.int64)
        self.rest = np.asarray([i.transform for i in placed], np.float32).reshape(-1, 4, 4)
        self.time = 0.0
        self.index: int | None = None  # the frame begun last
        self.pose = 0
        self._ran: tuple[np.ndarray, np.ndarray] | None = None  # its transforms and rows

    @property
    def moves(self) -> bool:
        return len(self.moving) > 0

    @property
    def last_rows(self) -> np.ndarray | None:
        """The rows of the frame begun last (None before the first, or when nothing
        moves): for a copy of the rows made mid-run."""
        return None if self._ran is None else self._ran[1]

    @property
    def last_transforms(self) -> np.ndarray | None:
        """The (n, 4, 4) transforms of the frame begun last (None as ``last_rows``)."""
        return None if self._ran is None else self._ran[0]

    def transforms(self, t: float) -> np.ndarray:
        """Every placed instance's (4, 4) float32 transform at ``t`` seconds."""
        out = self.rest.copy()
        if self.moves:
            world = self.animator.world(t)
            out[self.moving] = np.asarray([world[self.nodes[k]] for k in self.moving],
                                          np.float32)
        return out

    def rows(self, transforms: np.ndarray) -> np.ndarray:
        """``pose_blocks`` of ``transforms``: (n, 32) float32."""
        return pose_blocks(transforms)

    def begin(self, index: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """Frame ``index``'s transforms, rows and last frame's rows; None when that frame
        has begun already, or nothing moves."""
        if not self.moves or index == self.index:
            return None
        now = self.transforms(self.time)
        before = self._ran if self.index is not None and index == self.index + 1 else None
        rows = self.rows(now)
        if before is None:
            prev = rows
        else:
            prev = before[1].copy()
            lost = ~prev.any(axis=1)  # singular last frame: no motion to measure
            prev[lost] = rows[lost]
        if self._ran is not None and not np.array_equal(rows, self._ran[1]):
            self.pose += 1
        self.index = index
        self._ran = (now, rows)
        return now, rows, prev


def sun_camera_bytes(camera: Camera, sun: np.ndarray, size: tuple[int, int]) -> bytes:
    # the sun camera: view_proj carries everything the shadow pass needs
    return camera_bytes(camera, np.identity(4, np.float32), sun, (0, 0, 0), size)
