"""Mesh-shader geometry for a :class:`VkScene`: meshlets on the GPU, GPU-driven draws and
two-phase occlusion culling.

:func:`meshlet_scene` builds (once per ``VkScene``, cached on it and destroyed with it) the
meshlets of every mesh (``rfw.meshlets.cached_meshlets``: 64 vertices, 124 triangles) and
uploads, as storage buffers of one descriptor set (the layout of
``passes/meshlet_gbuffer/meshlet.glsl``):

- the packed meshlet arrays of :func:`rfw.meshlets.pack_for_gpu` for all meshes, rebased so
  every mesh shares them (meshlet rows index the shared ``vertices`` / ``triangles`` arrays,
  meshlet vertices index the shared attribute arrays),
- positions, normals, uvs and tangents as std430 ``vec4`` arrays,
- per instance its model and normal matrices, its largest column scale (sphere radii) and
  whether the cone test holds for it,
- the draws: one per opaque or alpha-masked instance, sorted (stably) by material, with the
  mesh's meshlet range, triangle count, bounding sphere and the first word of its
  visibility; the indirect commands a compute pass fills from them each frame; one
  visibility word per (draw, meshlet) that two-phase culling carries from frame to frame,
- the culling camera (a copy of the main camera, kept while culling is frozen) and the
  counters (:data:`COUNTERS`) the shaders add to; :meth:`MeshletScene.counters` reads the
  last frame's.

:func:`draw_meshlets` records, inside a pass: the draw-culling compute pass (each instance's
bounding sphere against the frustum; the indirect commands), then per material one
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

import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rfw.backends.scene_data import main_camera_bytes
from rfw.graph.sync import State
from rfw.meshlets import cached_meshlets, pack_for_gpu
from rfw.scene.model import is_mirrored
from rfw.shaders import ShaderError

from .commands import barrier, image_layout, read_buffer, upload_buffer
from .consts import const, ffi, lib, vk
from .scene import (
    CAMERA_BYTES,
    COMPARE,
    DescriptorPool,
    DescriptorSetLayout,
    VkScene,
    new,
    update_descriptors,
)
from .spirv import compile_glsl, reflect

ROOT = Path(__file__).resolve().parents[1]
SHADERS = ROOT / "passes" / "meshlet_gbuffer"
FRAGMENT = ROOT / "passes" / "gbuffer" / "gbuffer.frag.glsl"  # reused (MESHLET_COLORS: debug)
TASK_GROUP = 32  # meshlets per task workgroup (meshlet.glsl's TASK_GROUP)
DRAW_GROUP = 64  # draws per workgroup of meshlet_draws.comp.glsl
MAX_VERTICES, MAX_TRIANGLES = 64, 124
# meshlet.glsl's F_* flags and PHASE_* values
CONE, FRUSTUM, OCCLUSION, TRIANGLES, COLORS = 1, 2, 4, 8, 16
PHASES = {"single": 0, "early": 1, "late": 2}
# meshlet.glsl's C_* counters, in order
COUNTERS = ("considered", "cone_culled", "frustum_culled", "occlusion_culled", "drawn",
            "triangles", "triangles_cone", "triangles_frustum", "triangles_occlusion",
            "triangles_in_drawn", "triangles_backface", "instances_culled", "drawn_late")
ALPHA = ("OPAQUE", "MASK")  # the materials meshlets draw (blended ones need sorting)

_TASK_MESH = ("VK_SHADER_STAGE_TASK_BIT_EXT", "VK_SHADER_STAGE_MESH_BIT_EXT")
_SET0_STAGES = (*_TASK_MESH, "VK_SHADER_STAGE_COMPUTE_BIT")
_STAGES = {"task": "VK_SHADER_STAGE_TASK_BIT_EXT", "mesh": "VK_SHADER_STAGE_MESH_BIT_EXT",
           "frag": "VK_SHADER_STAGE_FRAGMENT_BIT", "comp": "VK_SHADER_STAGE_COMPUTE_BIT"}
_SHADER = frozenset({"TASK_SHADER_EXT", "MESH_SHADER_EXT", "COMPUTE_SHADER"})
_READ = State(None, frozenset({"TASK_SHADER_EXT", "MESH_SHADER_EXT"}),
              frozenset({"SHADER_STORAGE_READ"}))
# everything the meshlet passes' own buffers see in a frame: the counters' clear, the
# culling compute pass, the indirect reads, the task and mesh shaders
_ALL = State(None, _SHADER | {"CLEAR", "COPY", "DRAW_INDIRECT"},
             frozenset({"SHADER_STORAGE_READ", "SHADER_STORAGE_WRITE", "TRANSFER_WRITE",
                        "INDIRECT_COMMAND_READ"}))
_COMPUTE_RW = State(None, frozenset({"COMPUTE_SHADER"}),
                    frozenset({"SHADER_STORAGE_READ", "SHADER_STORAGE_WRITE"}))
_DRAW = State(None, frozenset({"DRAW_INDIRECT", "TASK_SHADER_EXT", "MESH_SHADER_EXT"}),
              frozenset({"INDIRECT_COMMAND_READ", "SHADER_STORAGE_READ",
                         "SHADER_STORAGE_WRITE"}))
_SHADERS_RW = State(None, _SHADER, frozenset({"SHADER_STORAGE_READ", "SHADER_STORAGE_WRITE"}))
# vkCmdFillBuffer is a CLEAR-stage command; validation layers of 1.3.239 track it as COPY
_FILL = State(None, frozenset({"CLEAR", "COPY"}), frozenset({"TRANSFER_WRITE"}))
_HOST = State(None, frozenset({"HOST"}), frozenset({"HOST_READ"}))
# set 0 bindings (meshlet.glsl and the shaders that include it)
_BINDINGS = {"camera": 0, "instances": 1, "meshlets": 2, "vertices": 3, "triangles": 4,
             "spheres": 5, "cones": 6, "cone_apex": 7, "counters": 8, "positions": 9,
             "normals": 10, "uvs": 11, "tangents": 12, "cull_camera": 13, "draws": 14,
             "commands": 15, "visibility": 16}
_UNIFORMS = ("camera", "cull_camera")
_PUSH = struct.Struct("<4I2f")  # meshlet.glsl's MPush



def _flags(names: Sequence[str]) -> int:
    out = 0
    for n in names:
        out |= const(n)
    return out


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


class _Obj:
    """A Vulkan object of this module (destroyed with the scene)."""

    def __init__(self, device, handle, destroy_fn: str):
        self.device, self.handle, self.destroy_fn = device, handle, destroy_fn

    def destroy(self) -> None:
        if self.handle is not None and self.device.alive:
            getattr(vk, self.destroy_fn)(self.device.device, self.handle, None)
        self.handle = None


class MeshletScene:
    """The scene's meshlets on the device, their draws, descriptor sets, pipelines and
    counters."""

    def __init__(self, vscene: VkScene, *, cache_dir: Path | str | None = None):
        self.vscene, self.device = vscene, vscene.device
        dev, scene, alloc = vscene.device, vscene.scene, vscene.allocator
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
        self.instance_meshlet_count = words_
        self.triangle_count = sum(mesh_triangles[scene.instances[k].mesh] for k in order)
        self._upload("draws", np.frombuffer(b"".join(rows_) or bytes(48), np.uint8))
        self.buffers["commands"] = alloc.create_buffer(
            16 * max(1, self.draw_count), ("storage", "indirect", "transfer_src"),
            label="meshlets.commands")
        self.buffers["visibility"] = alloc.create_buffer(
            4 * max(1, words_), ("storage", "transfer_dst", "transfer_src"),
            label="meshlets.visibility")
        self.buffers["cull_camera"] = alloc.create_buffer(
            CAMERA_BYTES, ("uniform",), host_visible=True, label="meshlets.cull_camera")
        self.buffers["counters"] = alloc.create_buffer(
            4 * len(COUNTERS), ("storage", "transfer_dst"), host_visible=True,
            label="meshlets.counters")
        self.buffers["counters"].write(np.zeros(len(COUNTERS), np.uint32))
        # nothing was visible before the first frame: its early phase draws nothing
        upload_buffer(dev, self.buffers["visibility"], np.zeros(max(1, words_), np.uint32),
                      _READ)
        self.last: dict[str, int] | None = None
        self.frozen: bytes | None = None  # the culling camera while frozen

        # set 0: this module's layout; sets 1-3 are the scene's, set 4 the late phase's pyramid
        self.objects: list[Any] = []
        entries = [(b, "uniform_buffer" if n in _UNIFORMS else "storage_buffer", 1)
                   for n, b in _BINDINGS.items()]
        self.set_layout = DescriptorSetLayout(dev, entries, _flags(_SET0_STAGES),
                                              label="meshlets:set0")
        self.pool = DescriptorPool(dev, 2, {"uniform_buffer": 4, "storage_buffer": 32},
                                   label="meshlets:descriptors")
        self.pyramid_layout = DescriptorSetLayout(dev, [(0, "sampled_image", 1)],
                                                  _flags(_TASK_MESH), label="meshlets:set4")
        self.objects += [self.set_layout, self.pool, self.pyramid_layout]
        self.sets = {}
        for cam in ("main", "sun"):
            s = self.pool.allocate([self.set_layout.handle])
            view = _range(vscene.camera_range(cam))
            # the sun is never culled from another camera: both bindings are its camera
            cull = view if cam == "sun" else (self.buffers["cull_camera"].handle, 0, CAMERA_BYTES)
            writes = [(s[0], 0, "uniform_buffer", view), (s[0], 13, "uniform_buffer", cull)]
            writes += [(s[0], b, "storage_buffer", (self.buffers[n].handle, 0,
                                                    self.buffers[n].bytes))
                       for n, b in _BINDINGS.items() if n not in _UNIFORMS]
            update_descriptors(dev, writes)
            self.sets[cam] = s
        self.modules: dict[tuple[str, tuple], Any] = {}
        layouts = [self.set_layout.handle] + [vscene.layouts[i].handle for i in (1, 2, 3)] + \
            [self.pyramid_layout.handle]
        self.layout = self._pipeline_layout(layouts, _TASK_MESH)
        self.compute_layout = self._pipeline_layout([self.set_layout.handle],
                                                    ("VK_SHADER_STAGE_COMPUTE_BIT",))
        self.pipelines: dict[tuple, Any] = {}
        self.compute = self._compute_pipeline()

    def _own(self, handle: Any, destroy_fn: str) -> Any:
        obj = _Obj(self.device, handle, destroy_fn)
        self.objects.append(obj)
        return handle

    def _upload(self, name: str, data: np.ndarray) -> None:
        data = np.ascontiguousarray(data)
        buf = self.vscene.allocator.create_buffer(max(16, data.nbytes), ("storage", "transfer_dst"),
                                                  label=f"meshlets.{name}")
        if data.nbytes:
            upload_buffer(self.device, buf, data, _READ)
        self.buffers[name] = buf

    def _pipeline_layout(self, layouts: list[Any], stages: Sequence[str]) -> Any:
        handles = ffi.new("VkDescriptorSetLayout[]", layouts)
        rng = ffi.new("VkPushConstantRange*")
        rng.stageFlags, rng.offset, rng.size = _flags(stages), 0, _PUSH.size
        info = new("VkPipelineLayoutCreateInfo", setLayoutCount=len(layouts), pSetLayouts=handles,
                   pushConstantRangeCount=1, pPushConstantRanges=rng)
        return self._own(vk.vkCreatePipelineLayout(self.device.device, info, None),
                         "vkDestroyPipelineLayout")

    def module(self, path: Path, **defines: Any) -> Any:
        """The shader module of ``path`` compiled with ``defines`` (cached)."""
        key = (str(path), tuple(sorted(defines.items())))
        handle = self.modules.get(key)
        if handle is None:
            spv = compile_glsl(path, defines)
            if reflect(spv.code).push_constant_size > _PUSH.size:
                raise ShaderError(f"{path.name}: push constants larger than MPush")
            words = ffi.new("uint32_t[]", len(spv.code) // 4)
            ffi.memmove(words, spv.code, len(spv.code))
            info = new("VkShaderModuleCreateInfo", codeSize=len(spv.code), pCode=words)
            handle = self.modules[key] = self._own(
                vk.vkCreateShaderModule(self.device.device, info, None), "vkDestroyShaderModule")
        return handle

    def _compute_pipeline(self) -> Any:
        stage = new("VkPipelineShaderStageCreateInfo", stage=const(_STAGES["comp"]),
                    module=self.module(SHADERS / "meshlet_draws.comp.glsl"))
        entry = ffi.new("char[]", b"main")
        stage.pName = entry
        info = new("VkComputePipelineCreateInfo", stage=stage[0], layout=self.compute_layout,
                   basePipelineIndex=-1)
        handle = vk.vkCreateComputePipelines(self.device.device, ffi.NULL, 1, info, None)[0]
        return self._own(handle, "vkDestroyPipeline")

    def pipeline(self, colors: Sequence[int], depth: int | None, depth_compare: str,
                 cull: str, occlusion: bool = False, colors_debug: bool = False) -> Any:
        key = (tuple(colors), depth, depth_compare, cull, occlusion, colors_debug)
        pipe = self.pipelines.get(key)
        if pipe is not None:
            return pipe
        debug = {"MESHLET_COLORS": 1} if colors_debug else {}
        modules = (("task", self.module(SHADERS / "meshlet_gbuffer.task.glsl",
                                        **({"OCCLUSION": 1} if occlusion else {}))),
                   ("mesh", self.module(SHADERS / "meshlet_gbuffer.mesh.glsl", **debug)),
                   ("frag", self.module(FRAGMENT, **debug)))
        stages = new("VkPipelineShaderStageCreateInfo", 3)
        entry = ffi.new("char[]", b"main")
        for i, (stage, module) in enumerate(modules):
            stages[i].stage, stages[i].module, stages[i].pName = const(_STAGES[stage]), module, entry
        viewport = new("VkPipelineViewportStateCreateInfo", viewportCount=1, scissorCount=1)
        cull_bits = {"none": "VK_CULL_MODE_NONE", "back": "VK_CULL_MODE_BACK_BIT",
                     "front": "VK_CULL_MODE_FRONT_BIT"}[cull]
        raster = new("VkPipelineRasterizationStateCreateInfo",
                     polygonMode=const("VK_POLYGON_MODE_FILL"), cullMode=const(cull_bits),
                     frontFace=const("VK_FRONT_FACE_COUNTER_CLOCKWISE"), lineWidth=1.0)
        multisample = new("VkPipelineMultisampleStateCreateInfo", rasterizationSamples=1)
        ds = new("VkPipelineDepthStencilStateCreateInfo", depthTestEnable=int(depth is not None),
                 depthWriteEnable=int(depth is not None),
                 depthCompareOp=const(COMPARE[depth_compare]))
        atts = ffi.new("VkPipelineColorBlendAttachmentState[]", max(1, len(colors)))
        for i in range(len(colors)):
            atts[i].colorWriteMask = 0xF
        blend = new("VkPipelineColorBlendStateCreateInfo", attachmentCount=len(colors),
                    pAttachments=atts)
        dyn_states = ffi.new("VkDynamicState[2]", [const("VK_DYNAMIC_STATE_VIEWPORT"),
                                                   const("VK_DYNAMIC_STATE_SCISSOR")])
        dynamic = new("VkPipelineDynamicStateCreateInfo", dynamicStateCount=2,
                      pDynamicStates=dyn_states)
        formats = ffi.new("VkFormat[]", list(colors) or [0])
        rendering = new("VkPipelineRenderingCreateInfo", colorAttachmentCount=len(colors),
                        pColorAttachmentFormats=formats,
                        depthAttachmentFormat=depth if depth is not None else 0)
        info = new("VkGraphicsPipelineCreateInfo", pNext=rendering, stageCount=3, pStages=stages,
                   pViewportState=viewport, pRasterizationState=raster,
                   pMultisampleState=multisample, pDepthStencilState=ds, pColorBlendState=blend,
                   pDynamicState=dynamic, layout=self.layout, basePipelineIndex=-1)
        handle = vk.vkCreateGraphicsPipelines(self.device.device, ffi.NULL, 1, info, None)[0]
        pipe = self.pipelines[key] = self._own(handle, "vkDestroyPipeline")
        return pipe

    def set_cull_camera(self, freeze: bool) -> None:
        """Culling follows the main camera, or (``freeze``) keeps the camera it had when the
        freeze began while the view moves on. Host write: frames are waited for before the
        next records."""
        view = main_camera_bytes(self.vscene.camera, self.vscene.size)
        if freeze and self.frozen is None:
            self.frozen = view
        elif not freeze:
            self.frozen = None
        self.buffers["cull_camera"].write(np.frombuffer(self.frozen or view, np.uint8))

    def counters(self) -> dict[str, int]:
        """The last frame's counters (call after the frame was waited for), with
        ``meshlets_total``: the meshlets of every drawn instance, and ``triangles_total``."""
        values = self.buffers["counters"].read(np.uint32, len(COUNTERS))
        out = dict(zip(COUNTERS, (int(v) for v in values), strict=True))
        out["meshlets_total"] = self.instance_meshlet_count
        out["triangles_total"] = self.triangle_count
        return out

    def visibility(self) -> dict[int, np.ndarray]:
        """Per drawn instance, which of its mesh's meshlets passed the last single or late
        phase's tests (instance culling included); call after the frame was waited for."""
        commands = read_buffer(self.device, self.buffers["commands"], dtype=np.uint32)
        words = read_buffer(self.device, self.buffers["visibility"], dtype=np.uint32)
        out = {}
        first = 0
        for d, k in enumerate(self.draw_instances):
            n = self.ranges[self.vscene.scene.instances[k].mesh].count
            out[k] = (words[first:first + n] != 0) & bool(commands[4 * d] > 0)
            first += n
        return out

    def geometry_bytes(self) -> int:
        """Device bytes of the meshlet path's scene data (meshlets, attributes, draws)."""
        return sum(b.bytes for n, b in self.buffers.items() if n != "counters")

    def destroy(self) -> None:
        # the frames were waited for (the executor idles the device before the scene goes):
        # the last frame's counters stay readable as ``last``
        if self.device.alive and self.buffers["counters"].handle is not None:
            self.last = self.counters()
        for obj in reversed(self.objects):
            obj.destroy()
        self.objects.clear()
        self.pipelines.clear()
        self.modules.clear()


def _range(r: Any) -> tuple[Any, int, int]:
    return (r.buffer, r.offset, r.size)


def meshlet_scene(vscene: VkScene) -> MeshletScene:
    """The scene's :class:`MeshletScene`, built on first use and destroyed with the scene."""
    ms = getattr(vscene, "_rfw_meshlets", None)
    if ms is None:
        ms = MeshletScene(vscene)
        vscene._rfw_meshlets = ms
        vscene._objects.append(ms)  # VkScene.destroy() destroys it (before its allocator)
    return ms


def draw_meshlets(ctx: Any, *, color: Sequence[tuple[str, Any]], depth: tuple[str, Any] | None,
                  cone: bool = True, frustum: bool = True, phase: str = "single",
                  pyramid: Any = None, triangles: bool = False, colors: bool = False,
                  freeze: bool = False, depth_compare: str = "less-equal", cull: str = "back",
                  camera: str = "main") -> int:
    """Draw the scene's opaque and masked instances through the task + mesh shaders into
    ``color`` (and ``depth``) with dynamic rendering; returns the indirect draw calls (one
    per material).

    ``phase``: ``"single"`` runs the cone and frustum tests; two-phase occlusion culling is
    two passes, ``"early"`` (clears the targets, draws what was visible last frame) and
    ``"late"`` (loads them; ``pyramid``, an ``ImageBinding`` of this frame's max-depth
    pyramid of the early pass's depth, culls the rest; draws the newly visible and records
    visibility for the next frame). The counters are cleared by the single and early phases.

    Cone culling needs ``cull="back"`` (it removes meshlets with back faces only) and the
    perspective main camera; otherwise it is left off, as are ``triangles`` (per-triangle
    backface culling in the mesh shader). ``colors`` writes a color per meshlet as the
    albedo (debug view). ``freeze`` keeps culling from the camera of the frame the freeze
    began while the view moves (occlusion then stays off: the pyramid is the view's)."""
    if ctx.scene is None:
        raise ShaderError(f"pass '{ctx.pass_.name}' draws the scene, but none is loaded")
    if "VK_EXT_mesh_shader" not in ctx.device.caps:
        raise ShaderError(f"pass '{ctx.pass_.name}' needs VK_EXT_mesh_shader")
    if phase not in PHASES:
        raise ShaderError(f"pass '{ctx.pass_.name}': phase must be one of {', '.join(PHASES)}, "
                          f"got {phase!r}")
    if phase == "late" and pyramid is None:
        raise ShaderError(f"pass '{ctx.pass_.name}': the late phase needs a depth pyramid")
    ms = meshlet_scene(ctx.scene)
    ex, cmd = ctx.executor, ctx.cmd
    main = camera == "main"
    if freeze and main and phase != "single":
        phase = "single" if phase == "early" else "skip"  # frozen: no occlusion culling
    if phase == "skip":
        return 0
    targets_ = [(ctx.resource(slot), clear) for slot, clear in color]
    targets = [ex.image(r) for r, _ in targets_]
    dimage = ex.image(ctx.resource(depth[0])) if depth is not None else None
    first = (targets or [dimage])[0]
    occlusion = phase == "late"
    pipe = ms.pipeline([t.vk_format for t in targets],
                       dimage.vk_format if dimage is not None else None, depth_compare, cull,
                       occlusion, colors)
    # the cone test is the perspective one (apex to camera position): main camera only
    back = cull == "back" and main
    flags = (CONE if cone and back else 0) | (FRUSTUM if frustum else 0) | \
        (OCCLUSION if occlusion else 0) | (TRIANGLES if triangles and back else 0) | \
        (COLORS if colors else 0)
    push = ffi.new("char[]", _PUSH.pack(0, flags, PHASES[phase], ms.draw_count,
                                        float(first.width), float(first.height)))
    counters = ms.buffers["counters"]
    if phase != "late":
        if main:
            ms.set_cull_camera(freeze)
        # zero the counters after the last frame's shaders, before this frame's
        barrier(cmd, memory_barriers=[(_ALL, _FILL)])
        vk.vkCmdFillBuffer(cmd, counters.handle, 0, counters.bytes, 0)
        barrier(cmd, memory_barriers=[(_FILL, _SHADERS_RW)])
    # the draw-culling compute pass writes the commands the last draws read, and counts
    barrier(cmd, memory_barriers=[(_ALL, _COMPUTE_RW)])
    compute = const("VK_PIPELINE_BIND_POINT_COMPUTE")
    vk.vkCmdBindPipeline(cmd, compute, ms.compute)
    lib.vkCmdBindDescriptorSets(cmd, compute, ms.compute_layout, 0, 1, ms.sets[camera], 0,
                                ffi.NULL)
    lib.vkCmdPushConstants(cmd, ms.compute_layout, const(_STAGES["comp"]), 0, _PUSH.size, push)
    vk.vkCmdDispatch(cmd, max(1, math.ceil(ms.draw_count / DRAW_GROUP)), 1, 1)
    barrier(cmd, memory_barriers=[(_COMPUTE_RW, _DRAW)])
    point = const("VK_PIPELINE_BIND_POINT_GRAPHICS")
    calls = 0
    ctx._begin_rendering(targets_, depth, True, (first.width, first.height))
    try:
        vk.vkCmdBindPipeline(cmd, point, pipe)
        vp = ffi.new("VkViewport*")
        vp.width, vp.height, vp.maxDepth = float(first.width), float(first.height), 1.0
        sc = ffi.new("VkRect2D*")
        sc.extent.width, sc.extent.height = first.width, first.height
        lib.vkCmdSetViewport(cmd, 0, 1, vp)
        lib.vkCmdSetScissor(cmd, 0, 1, sc)
        lib.vkCmdBindDescriptorSets(cmd, point, ms.layout, 0, 1, ms.sets[camera], 0, ffi.NULL)
        lib.vkCmdBindDescriptorSets(cmd, point, ms.layout, 1, 1, ctx.scene.camera_sets[camera],
                                    0, ffi.NULL)
        if occlusion:
            layout = ctx.executor.state_in(ctx.pass_.name, pyramid.resource).layout
            pset = ctx.executor.descriptors.allocate(ms.pyramid_layout.handle,
                                                     [(0, "sampled_image", 1)])
            update_descriptors(ctx.device, [(pset[0], 0, "sampled_image",
                                             (pyramid.view.handle, image_layout(layout)))])
            lib.vkCmdBindDescriptorSets(cmd, point, ms.layout, 4, 1, pset, 0, ffi.NULL)
        stage_flags = _flags(_TASK_MESH)
        commands = ms.buffers["commands"].handle
        for g in ms.groups:
            lib.vkCmdBindDescriptorSets(cmd, point, ms.layout, 2, 1,
                                        ctx.scene.material_sets[g.material], 0, ffi.NULL)
            lib.vkCmdBindDescriptorSets(cmd, point, ms.layout, 3, 1,
                                        ctx.scene.instance_sets[g.instance], 0, ffi.NULL)
            push = ffi.new("char[]", _PUSH.pack(g.first, flags, PHASES[phase], ms.draw_count,
                                                float(first.width), float(first.height)))
            lib.vkCmdPushConstants(cmd, ms.layout, stage_flags, 0, _PUSH.size, push)
            ctx.device.fn.vkCmdDrawMeshTasksIndirectEXT(cmd, commands, 16 * g.first, g.count, 16)
            calls += 1
    finally:
        vk.vkCmdEndRendering(cmd)
    barrier(cmd, memory_barriers=[(_DRAW, _HOST)])
    return calls
