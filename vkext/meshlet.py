"""Mesh-shader geometry for a :class:`VkScene`: the scene's meshlets on the GPU, and the
recording side of the meshlet passes (``passes/meshlet_cull``, ``passes/meshlet_gbuffer``).

:func:`meshlet_scene` builds (once per ``VkScene``, cached on it and destroyed with it) the
meshlets of every mesh (``rfw.meshlets.cached_meshlets``: 64 vertices, 124 triangles) and
uploads them as storage buffers, bound by name to the blocks of ``shaders/common/meshlet.glsl``
and the meshlet shaders (:meth:`MeshletScene.bindings`):

- the packed meshlet arrays of :func:`rfw.meshlets.pack_for_gpu` for all meshes, rebased so
  every mesh shares them (meshlet rows index the shared ``vertices`` / ``triangles`` arrays,
  meshlet vertices index the shared attribute arrays),
- positions, normals, uvs and tangents as std430 ``vec4`` arrays,
- per instance its model and normal matrices, its largest column scale (sphere radii) and
  whether the cone test holds for it,
- the draws: one per opaque or alpha-masked instance, sorted (stably) by material, with the
  mesh's meshlet range, triangle count, bounding sphere and the first word of its
  visibility.

Everything a frame writes is a graph resource the passes declare, so the compiler plans
every barrier: the indirect commands (``meshlet_cull``'s output, read as indirect commands
by ``meshlet_gbuffer``), the counters (:data:`COUNTERS`) and the visibility one word per
(draw, meshlet) that two-phase culling carries from frame to frame (both persistent
buffers). The counters come back to the host through the executor's readback
(:func:`meshlet_counters`). Layouts are reflected from the SPIR-V; nothing here records a
barrier.

:func:`draw_meshlets` records, inside a mesh pass, per material one
``vkCmdDrawMeshTasksIndirectEXT`` over that material's draws (``gl_DrawIDARB`` from a pushed
base), through a task + mesh + fragment pipeline without vertex input.

The culling tests assume model matrices made of rotation, uniform scale and translation: the
sphere radius is scaled by the largest column length (conservative for any scale), the normal
cone is moved with the model matrix, which keeps its angle only for uniform scale; an
instance with a non-uniform scale is never cone-culled. A mirroring transform (negative
determinant) keeps angles: its cone moves with it, and the mesh shader emits its triangles
with two corners swapped (and the tangent sign flipped), so front faces stay
counter-clockwise on screen.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rfw.backends.scene_data import main_camera_bytes
from rfw.meshlets import cached_meshlets, pack_for_gpu
from rfw.scene.model import is_mirrored
from rfw.shaders import ShaderError

from .commands import upload_buffer
from .scene import VkScene

ROOT = Path(__file__).resolve().parents[1]
# the meshlet_gbuffer pass's stages, and the gbuffer pass's fragment shader (MESHLET_COLORS:
# the debug colors)
MESH, TASK = "meshlet_gbuffer.mesh.glsl", "meshlet_gbuffer.task.glsl"
FRAGMENT = ROOT / "passes" / "gbuffer" / "gbuffer.frag.glsl"
TASK_GROUP = 32  # meshlets per task workgroup (meshlet.glsl's TASK_GROUP)
MAX_VERTICES, MAX_TRIANGLES = 64, 124
# meshlet.glsl's F_* flags and PHASE_* values
CONE, FRUSTUM, OCCLUSION, TRIANGLES, COLORS = 1, 2, 4, 8, 16
PHASES = {"single": 0, "early": 1, "late": 2}
# meshlet.glsl's C_* counters, in order
COUNTERS = ("considered", "cone_culled", "frustum_culled", "occlusion_culled", "drawn",
            "triangles", "triangles_cone", "triangles_frustum", "triangles_occlusion",
            "triangles_in_drawn", "triangles_backface", "instances_culled", "drawn_late")
COMMAND_BYTES = 16  # VkDrawMeshTasksIndirectCommandEXT, padded to meshlet_cull's uvec4
ALPHA = ("OPAQUE", "MASK")  # the materials meshlets draw (blended ones need sorting)

_PUSH = struct.Struct("<4I2f")  # meshlet.glsl's MPush


@dataclass
class MeshRange:
    first: int  # first row of the shared meshlet table
    count: int  # meshlets of the mesh


@dataclass
class DrawGroup:
    """Consecutive draws of one material: one ``vkCmdDrawMeshTasksIndirectEXT``."""

    material: int
    first: int  # first draw (row of the draws and commands buffers)
    count: int
    instance: int  # the first draw's instance (its set 3 is bound for layout compatibility)


def _vec4(a: np.ndarray, fill_w: float = 0.0) -> np.ndarray:
    a = np.asarray(a, np.float32).reshape(len(a), -1)
    out = np.full((len(a), 4), fill_w, np.float32)
    out[:, :a.shape[1]] = a
    return out


def _instance_rows(transform: np.ndarray) -> bytes:
    model = np.asarray(transform, np.float64)
    normal = np.linalg.inv(model).T
    cols = np.linalg.norm(model[:3, :3], axis=0)
    scale = float(cols.max())
    uniform = bool(np.allclose(cols, scale, rtol=1e-4))
    # z: -1 for a mirroring transform, whose triangles the mesh shader emits the other way
    # round; a mirror keeps angles, so its cone (moved by the model matrix) still holds
    sign = -1.0 if is_mirrored(model) else 1.0
    return (model.T.astype(np.float32).tobytes() + normal.T.astype(np.float32).tobytes()
            + struct.pack("<4f", scale, 1.0 if uniform else 0.0, sign, 0.0))


def _bounding_sphere(positions: np.ndarray) -> tuple[float, float, float, float]:
    """A sphere around every vertex: the box center and the farthest vertex from it."""
    p = np.asarray(positions, np.float64)
    center = (p.min(axis=0) + p.max(axis=0)) / 2
    radius = float(np.sqrt(((p - center) ** 2).sum(axis=1).max()))
    return (*(float(c) for c in center), radius * (1 + 1e-5) + 1e-6)




class MeshletScene:
    """The scene's meshlets on the device, their draws, the mesh programs and pipelines of
    the meshlet passes, and the culling camera while culling is frozen."""

    def __init__(self, vscene: VkScene, *, cache_dir: Path | str | None = None):
        self.vscene, self.device = vscene, vscene.device
        scene = vscene.scene
        parts: dict[str, list[np.ndarray]] = {k: [] for k in (
            "meshlets", "vertices", "triangles", "spheres", "cones", "cone_apex", "positions",
            "normals", "uvs", "tangents")}
        self.ranges: list[MeshRange] = []
        mesh_triangles: list[int] = []
        rows = words = verts = attrs = 0
        for m in scene.meshes:
            if len(m.indices) == 0:
                self.ranges.append(MeshRange(rows, 0))
                mesh_triangles.append(0)
                continue
            packed = pack_for_gpu(cached_meshlets(
                m.positions, m.indices, max_vertices=MAX_VERTICES, max_triangles=MAX_TRIANGLES,
                cache_dir=cache_dir))
            table = packed["meshlets"].copy()
            table[:, 0] += verts
            table[:, 1] += words
            parts["meshlets"].append(table)
            parts["vertices"].append(packed["vertices"] + np.uint32(attrs))
            parts["triangles"].append(packed["triangles"])
            for k in ("spheres", "cones", "cone_apex"):
                parts[k].append(packed[k])
            parts["positions"].append(_vec4(m.positions, 1.0))
            parts["normals"].append(_vec4(m.normals))
            parts["uvs"].append(_vec4(m.uvs))
            parts["tangents"].append(_vec4(m.tangents))
            self.ranges.append(MeshRange(rows, len(table)))
            mesh_triangles.append(int(table[:, 3].sum()))
            rows += len(table)
            words += len(packed["triangles"])
            verts += len(packed["vertices"])
            attrs += len(m.positions)
        self.meshlet_count = rows
        self.buffers: dict[str, Any] = {}
        for name, arrays in parts.items():
            data = np.concatenate(arrays) if arrays else np.zeros(4, np.uint32)
            self._upload(name, data)
        if vscene.meshlet_instances is not None:  # moved by animations: the scene's rows
            self.buffers["instances"] = vscene.meshlet_instances
        else:
            inst = b"".join(_instance_rows(i.transform) for i in scene.instances) or bytes(144)
            self._upload("instances", np.frombuffer(inst, np.uint8))

        # the draws: opaque and masked instances with meshlets, sorted by material (stable)
        spheres = [_bounding_sphere(m.positions) if len(m.indices) else (0.0, 0.0, 0.0, 0.0)
                   for m in scene.meshes]
        order = [k for k, i in enumerate(scene.instances)
                 if self.ranges[i.mesh].count
                 and scene.materials[scene.meshes[i.mesh].material].alpha_mode in ALPHA]
        order.sort(key=lambda k: scene.meshes[scene.instances[k].mesh].material)
        rows_, words_ = [], 0
        self.groups: list[DrawGroup] = []
        for d, k in enumerate(order):
            mesh = scene.instances[k].mesh
            rng = self.ranges[mesh]
            rows_.append(struct.pack("<4I4I4f", k, rng.first, rng.count, words_,
                                     mesh_triangles[mesh], 0, 0, 0, *spheres[mesh]))
            words_ += rng.count
            material = scene.meshes[mesh].material
            if self.groups and self.groups[-1].material == material:
                self.groups[-1].count += 1
            else:
                self.groups.append(DrawGroup(material, d, 1, k))
        self.draw_count = len(order)
        self.draw_instances = order  # draw -> instance
        self.instance_meshlet_count = words_  # visibility words
        self.triangle_count = sum(mesh_triangles[scene.instances[k].mesh] for k in order)
        self._upload("draws", np.frombuffer(b"".join(rows_) or bytes(48), np.uint8))
        self.frozen: bytes | None = None  # the culling camera while frozen

    def _upload(self, name: str, data: np.ndarray) -> None:
        data = np.ascontiguousarray(data)
        buf = self.vscene.allocator.create_buffer(max(16, data.nbytes), ("storage", "transfer_dst"),
                                                  label=f"meshlets.{name}")
        if data.nbytes:
            upload_buffer(self.device, buf, data)
        self.buffers[name] = buf

    def bindings(self) -> dict[str, Any]:
        """The scene's meshlet buffers by their block names in the meshlet shaders."""
        return dict(self.buffers)

    def cull_camera(self, freeze: bool) -> Any:
        """The camera culling tests use: the main camera's uniforms (the scene's, each
        frame's own: ``VkScene.copy_camera``), or (``freeze``) the bytes it was when the
        freeze began, while the view moves on. Never the live camera as bytes: those would
        be a host write into a uniform buffer the frames in flight read."""
        if not freeze:
            self.frozen = None
            return self.vscene.camera_range("main")
        if self.frozen is None:
            self.frozen = main_camera_bytes(self.vscene.camera, self.vscene.size)
        return self.frozen

    def push(self, flags: int, phase: str, *, draw_base: int = 0, count: int | None = None,
             viewport: tuple[int, int] = (0, 0)) -> bytes:
        """meshlet.glsl's MPush."""
        return _PUSH.pack(draw_base, flags, PHASES[phase],
                          self.draw_count if count is None else count,
                          float(viewport[0]), float(viewport[1]))

    def flags(self, *, cone: bool = False, frustum: bool = False, occlusion: bool = False,
              triangles: bool = False, colors: bool = False) -> int:
        """meshlet.glsl's F_* flags (:func:`flags_of`)."""
        return flags_of(cone=cone, frustum=frustum, occlusion=occlusion, triangles=triangles,
                        colors=colors)

    def check_capacity(self, ctx: Any) -> None:
        """The pass's buffers hold every draw's command and visibility word
        (:func:`check_capacity`)."""
        check_capacity(ctx, self)

    def destroy(self) -> None:
        """The buffers belong to the scene's allocator, which frees them."""
        self.buffers.clear()


def meshlet_scene(vscene: VkScene) -> MeshletScene:
    """The scene's :class:`MeshletScene`, built on first use and destroyed with the scene."""
    if vscene.meshlets is None:
        vscene.meshlets = MeshletScene(vscene)
        vscene._objects.append(vscene.meshlets)  # destroyed with the scene, before its allocator
    return vscene.meshlets


def scene_of(ctx: Any) -> MeshletScene:
    """The meshlets of the scene a meshlet pass records for, checked."""
    # (the graph refuses a pass that requires VK_EXT_mesh_shader on a device without it)
    if ctx.scene is None:
        raise ShaderError(f"pass '{ctx.pass_.name}' draws the scene, but none is loaded")
    return meshlet_scene(ctx.scene)


def check_capacity(ctx: Any, ms: MeshletScene) -> None:
    """The graph buffers hold every draw's command and every (draw, meshlet)'s visibility."""
    for slot, size, count, what, setting in (
            ("commands", COMMAND_BYTES, ms.draw_count, "drawn instances", "max_draws"),
            ("visibility", 4, ms.instance_meshlet_count, "meshlets over its instances",
             "max_meshlets")):
        if ctx.has(slot) and ctx.buffer(slot).bytes < size * count:
            raise ShaderError(f"pass '{ctx.pass_.name}': the scene has {count} {what}, more "
                              f"than its '{slot}' buffer holds: set the meshlet_cull pass's "
                              f"'{setting}' to at least {count}")


def flags_of(*, cone: bool = False, frustum: bool = False, occlusion: bool = False,
             triangles: bool = False, colors: bool = False) -> int:
    """meshlet.glsl's F_* flags."""
    return (CONE if cone else 0) | (FRUSTUM if frustum else 0) | \
        (OCCLUSION if occlusion else 0) | (TRIANGLES if triangles else 0) | \
        (COLORS if colors else 0)


def draw_meshlets(ctx: Any, *, color: Sequence[tuple[str, Any]], depth: tuple[str, Any] | None,
                  flags: int, phase: str, freeze: bool = False,
                  depth_compare: str = "less-equal", cull: str = "back") -> int:
    """Draw the scene's opaque and masked instances through the task + mesh shaders into
    ``color`` (and ``depth``), one ``vkCmdDrawMeshTasksIndirectEXT`` per material over the
    ``commands`` slot; returns the draw calls. Set 0 binds by name: the scene's meshlet
    buffers, the ``counters`` and ``visibility`` slots and the cameras; set 4 (``flags``
    with OCCLUSION) the ``pyramid`` slot's max-depth pyramid."""
    ms = scene_of(ctx)
    check_capacity(ctx, ms)
    occlusion = bool(flags & OCCLUSION)
    defines = {**({"OCCLUSION": 1} if occlusion else {}),
               **({"MESHLET_COLORS": 1} if flags & COLORS else {})}
    prog = ctx.program("mesh", shader=MESH, stages=(TASK, FRAGMENT), defines=defines)
    values = {**ms.bindings(), "view_camera": ctx.scene.bindings()["camera"],
              "cull_camera": ms.cull_camera(freeze), "counters": ctx.buffer("counters"),
              "visibility": ctx.buffer("visibility")}
    if occlusion:
        values["t_pyramid"] = ctx.sampled("pyramid")
    commands = ctx.buffer("commands")
    with ctx.render_pass(color=color, depth=depth) as rp:
        rp.use(prog, depth_compare=depth_compare, cull=cull)
        rp.bind(**{k: v for k, v in values.items() if k in prog.descriptors})
        size = (rp.targets or [rp.depth])[0]
        for g in ms.groups:
            rp.bind_scene(material=g.material, instance=g.instance)
            rp.push(ms.push(flags, phase, draw_base=g.first, viewport=(size.width, size.height)))
            rp.draw_mesh_tasks_indirect(commands, offset=COMMAND_BYTES * g.first, count=g.count,
                                        stride=COMMAND_BYTES)
    return len(ms.groups)


def _cull_resource(ex: Any, slot: str) -> str | None:
    """The resource behind ``slot`` of the frame's first meshlet culling pass (the one
    that makes the counters and the visibility)."""
    for name, p in ex.passes.items():
        if getattr(p, "counts_meshlets", False) and slot in ex.slots.get(name, {}) and \
                p.params.phase != "late":
            return ex.slots[name][slot]
    return None


def meshlet_counters(ex: Any) -> dict[str, int] | None:
    """The last frame's counters, read back through the executor (after the frame, before
    the executor goes), with ``meshlets_total`` (the meshlets of every drawn instance) and
    ``triangles_total``; None without a meshlet culling pass or scene."""
    name = _cull_resource(ex, "counters")
    if name is None or ex.scene is None:
        return None
    values = np.frombuffer(ex.read(name).tobytes(), np.uint32)[:len(COUNTERS)]
    out = dict(zip(COUNTERS, (int(v) for v in values), strict=True))
    ms = meshlet_scene(ex.scene)
    out["meshlets_total"] = ms.instance_meshlet_count
    out["triangles_total"] = ms.triangle_count
    return out


def meshlet_visibility(ex: Any) -> dict[int, np.ndarray] | None:
    """Per drawn instance, which of its mesh's meshlets passed the last single or late
    phase's tests (instance culling included: the culling pass clears a culled instance's
    words), read back through the executor after the frame."""
    name = _cull_resource(ex, "visibility")
    if name is None or ex.scene is None:
        return None
    ms = meshlet_scene(ex.scene)
    words = np.frombuffer(ex.read(name).tobytes(), np.uint32)
    out, first = {}, 0
    for k in ms.draw_instances:
        n = ms.ranges[ex.scene.scene.instances[k].mesh].count
        out[k] = words[first:first + n] != 0
        first += n
    return out
