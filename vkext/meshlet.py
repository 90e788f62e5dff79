"""Mesh-shader geometry for a :class:`VkScene`: meshlets on the GPU and their draws.

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
- four counters (meshlets considered, culled by the cone test, culled by the frustum test,
  drawn) that the task shader adds to; :meth:`MeshletScene.counters` reads the last frame's.

:func:`draw_meshlets` records, inside a pass, one ``vkCmdDrawMeshTasksEXT(ceil(meshlets /
32), 1, 1)`` per instance with push constants (instance, first meshlet, meshlet count,
culling flags), through a task + mesh + fragment pipeline without vertex input.

The culling tests assume model matrices made of rotation, uniform scale and translation: the
sphere radius is scaled by the largest column length (conservative for any scale), the normal
cone is moved with the model matrix, which keeps its angle only for uniform scale; an
instance with a mirroring transform (negative determinant) or a non-uniform scale is never
cone-culled.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rfw.graph.sync import State
from rfw.meshlets import cached_meshlets, pack_for_gpu
from rfw.shaders import ShaderError

from .commands import barrier, image_layout, upload_buffer
from .consts import const, ffi, lib, vk
from .scene import COMPARE, DescriptorPool, DescriptorSetLayout, VkScene, new, update_descriptors
from .spirv import compile_glsl, reflect

ROOT = Path(__file__).resolve().parents[1]
SHADERS = ROOT / "passes" / "meshlet_gbuffer"
FRAGMENT = ROOT / "passes" / "gbuffer" / "gbuffer.frag.glsl"  # reused unchanged
TASK_GROUP = 32  # meshlets per task workgroup (meshlet.glsl's TASK_GROUP)
MAX_VERTICES, MAX_TRIANGLES = 64, 124
CONE, FRUSTUM, OCCLUSION = 1, 2, 4  # culling flag bits
COUNTERS = ("considered", "cone_culled", "frustum_culled", "drawn", "occlusion_culled")

_TASK_MESH = ("VK_SHADER_STAGE_TASK_BIT_EXT", "VK_SHADER_STAGE_MESH_BIT_EXT")
_STAGES = {"task": "VK_SHADER_STAGE_TASK_BIT_EXT", "mesh": "VK_SHADER_STAGE_MESH_BIT_EXT",
           "frag": "VK_SHADER_STAGE_FRAGMENT_BIT"}
_READ = State(None, frozenset({"TASK_SHADER_EXT", "MESH_SHADER_EXT"}),
              frozenset({"SHADER_STORAGE_READ"}))
_TASK_RW = State(None, frozenset({"TASK_SHADER_EXT"}),
                 frozenset({"SHADER_STORAGE_READ", "SHADER_STORAGE_WRITE"}))
_FILL = State(None, frozenset({"CLEAR"}), frozenset({"TRANSFER_WRITE"}))
_HOST = State(None, frozenset({"HOST"}), frozenset({"HOST_READ"}))
# set 0 bindings (meshlet.glsl, the task and mesh shaders)
_BINDINGS = {"camera": 0, "instances": 1, "meshlets": 2, "vertices": 3, "triangles": 4,
             "spheres": 5, "cones": 6, "cone_apex": 7, "counters": 8, "positions": 9,
             "normals": 10, "uvs": 11, "tangents": 12}


def _flags(names: Sequence[str]) -> int:
    out = 0
    for n in names:
        out |= const(n)
    return out


@dataclass
class MeshRange:
    first: int  # first row of the shared meshlet table
    count: int  # meshlets of the mesh


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
    uniform = bool(np.allclose(cols, scale, rtol=1e-4)) and np.linalg.det(model[:3, :3]) > 0
    return (model.T.astype(np.float32).tobytes() + normal.T.astype(np.float32).tobytes()
            + struct.pack("<4f", scale, 1.0 if uniform else 0.0, 0.0, 0.0))


class _Obj:
    """A Vulkan object of this module (destroyed with the scene)."""

    def __init__(self, device, handle, destroy_fn: str):
        self.device, self.handle, self.destroy_fn = device, handle, destroy_fn

    def destroy(self) -> None:
        if self.handle is not None and self.device.alive:
            getattr(vk, self.destroy_fn)(self.device.device, self.handle, None)
        self.handle = None


class MeshletScene:
    """The scene's meshlets on the device, their descriptor set, pipelines and counters."""

    def __init__(self, vscene: VkScene, *, cache_dir: Path | str | None = None):
        self.vscene, self.device = vscene, vscene.device
        dev, scene, alloc = vscene.device, vscene.scene, vscene.allocator
        parts: dict[str, list[np.ndarray]] = {k: [] for k in (
            "meshlets", "vertices", "triangles", "spheres", "cones", "cone_apex", "positions",
            "normals", "uvs", "tangents")}
        self.ranges: list[MeshRange] = []
        rows = words = verts = attrs = 0
        for m in scene.meshes:
            if len(m.indices) == 0:
                self.ranges.append(MeshRange(rows, 0))
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
        self.buffers["counters"] = alloc.create_buffer(
            4 * len(COUNTERS), ("storage", "transfer_dst"), host_visible=True,
            label="meshlets.counters")
        self.buffers["counters"].write(np.zeros(len(COUNTERS), np.uint32))
        self.last: dict[str, int] | None = None

        # set 0: this module's layout (task + mesh stages); sets 1-3 are the scene's
        self.objects: list[Any] = []
        entries = [(b, "uniform_buffer" if n == "camera" else "storage_buffer", 1)
                   for n, b in _BINDINGS.items()]
        self.set_layout = DescriptorSetLayout(dev, entries, _flags(_TASK_MESH),
                                              label="meshlets:set0")
        self.pool = DescriptorPool(dev, 2, {"uniform_buffer": 2, "storage_buffer": 24},
                                   label="meshlets:descriptors")
        # set 4 (occlusion variant only): the previous frame's depth pyramid, allocated per frame
        self.pyramid_layout = DescriptorSetLayout(dev, [(0, "sampled_image", 1)],
                                                  _flags(_TASK_MESH), label="meshlets:set4")
        self.objects += [self.set_layout, self.pool, self.pyramid_layout]
        self.sets = {}
        for cam in ("main", "sun"):
            s = self.pool.allocate([self.set_layout.handle])
            writes = [(s[0], 0, "uniform_buffer", tuple(_range(vscene.camera_range(cam))))]
            writes += [(s[0], b, "storage_buffer", (self.buffers[n].handle, 0,
                                                    self.buffers[n].bytes))
                       for n, b in _BINDINGS.items() if n != "camera"]
            update_descriptors(dev, writes)
            self.sets[cam] = s
        self.modules = {}
        push = 0
        for stage, path, defines in (
                ("task", SHADERS / "meshlet_gbuffer.task.glsl", {}),
                ("task_occlusion", SHADERS / "meshlet_gbuffer.task.glsl", {"OCCLUSION": 1}),
                ("mesh", SHADERS / "meshlet_gbuffer.mesh.glsl", {}),
                ("frag", FRAGMENT, {})):
            spv = compile_glsl(path, defines)
            push = max(push, reflect(spv.code).push_constant_size)
            words_ = ffi.new("uint32_t[]", len(spv.code) // 4)
            ffi.memmove(words_, spv.code, len(spv.code))
            info = new("VkShaderModuleCreateInfo", codeSize=len(spv.code), pCode=words_)
            self.modules[stage] = self._own(vk.vkCreateShaderModule(dev.device, info, None),
                                            "vkDestroyShaderModule")
        layouts = [self.set_layout.handle] + [vscene.layouts[i].handle for i in (1, 2, 3)] + \
            [self.pyramid_layout.handle]
        handles = ffi.new("VkDescriptorSetLayout[]", layouts)
        rng = ffi.new("VkPushConstantRange*")
        rng.stageFlags, rng.offset, rng.size = _flags(_TASK_MESH), 0, push
        info = new("VkPipelineLayoutCreateInfo", setLayoutCount=len(layouts), pSetLayouts=handles,
                   pushConstantRangeCount=1, pPushConstantRanges=rng)
        self.layout = self._own(vk.vkCreatePipelineLayout(dev.device, info, None),
                                "vkDestroyPipelineLayout")
        self.pipelines: dict[tuple, Any] = {}

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

    def pipeline(self, colors: Sequence[int], depth: int | None, depth_compare: str,
                 cull: str, occlusion: bool = False) -> Any:
        key = (tuple(colors), depth, depth_compare, cull, occlusion)
        pipe = self.pipelines.get(key)
        if pipe is not None:
            return pipe
        stages = new("VkPipelineShaderStageCreateInfo", 3)
        entry = ffi.new("char[]", b"main")
        task = "task_occlusion" if occlusion else "task"
        for i, stage in enumerate((task, "mesh", "frag")):
            module = self.modules[stage]
            stages[i].stage, stages[i].module, stages[i].pName = const(_STAGES[stage.split("_")[0]]), module, entry
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

    def counters(self) -> dict[str, int]:
        """The last frame's counters (call after the frame was waited for), with
        ``meshlets_total``: the sum over drawn instances of their meshes' meshlets."""
        values = self.buffers["counters"].read(np.uint32, len(COUNTERS))
        out = dict(zip(COUNTERS, (int(v) for v in values), strict=True))
        out["meshlets_total"] = self.instance_meshlets()
        return out

    def instance_meshlets(self, alpha: tuple[str, ...] = ("OPAQUE", "MASK")) -> int:
        scene = self.vscene.scene
        return sum(self.ranges[i.mesh].count for i in scene.instances
                   if scene.materials[scene.meshes[i.mesh].material].alpha_mode in alpha)

    def destroy(self) -> None:
        # the frames were waited for (the executor idles the device before the scene goes):
        # the last frame's counters stay readable as ``last``
        if self.device.alive and self.buffers["counters"].handle is not None:
            self.last = self.counters()
        for obj in reversed(self.objects):
            obj.destroy()
        self.objects.clear()
        self.pipelines.clear()


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
                  cone: bool = True, frustum: bool = True, depth_compare: str = "less-equal",
                  cull: str = "back", camera: str = "main",
                  alpha: tuple[str, ...] = ("OPAQUE", "MASK"),
                  pyramid: Any = None) -> int:
    """Draw the scene's instances through the task + mesh shaders into ``color`` (and
    ``depth``) with dynamic rendering; returns the draws. Cone culling needs ``cull="back"``
    (it removes meshlets with back faces only) and the perspective main camera; otherwise it
    is left off.

    ``pyramid`` (an ``ImageBinding`` of the previous frame's max-depth pyramid, sampled in the
    task stage; ``passes/depth_pyramid``) turns on occlusion culling of the meshlets that
    survive the other tests: the bounding sphere's screen rectangle against the pyramid level
    where it covers at most 2x2 texels. Single phase: it is conservative while the previous
    frame's depth is no nearer than this frame's (a still camera and scene); main camera
    only."""
    if ctx.scene is None:
        raise ShaderError(f"pass '{ctx.pass_.name}' draws the scene, but none is loaded")
    if "VK_EXT_mesh_shader" not in ctx.device.caps:
        raise ShaderError(f"pass '{ctx.pass_.name}' needs VK_EXT_mesh_shader")
    ms = meshlet_scene(ctx.scene)
    ex, cmd, scene = ctx.executor, ctx.cmd, ctx.scene.scene
    colors = [(ctx.resource(slot), clear) for slot, clear in color]
    targets = [ex.image(r) for r, _ in colors]
    dimage = ex.image(ctx.resource(depth[0])) if depth is not None else None
    first = (targets or [dimage])[0]
    occlusion = pyramid is not None and camera == "main"
    pipe = ms.pipeline([t.vk_format for t in targets],
                       dimage.vk_format if dimage is not None else None, depth_compare, cull,
                       occlusion)
    # the cone test is the perspective one (apex to camera position): main camera only
    flags = (CONE if cone and cull == "back" and camera == "main" else 0) | \
        (FRUSTUM if frustum else 0) | (OCCLUSION if occlusion else 0)
    counters = ms.buffers["counters"]
    # zero the counters after the last frame's task shader, before this frame's
    barrier(cmd, memory_barriers=[(_TASK_RW, _FILL)])
    vk.vkCmdFillBuffer(cmd, counters.handle, 0, counters.bytes, 0)
    barrier(cmd, memory_barriers=[(_FILL, _TASK_RW)])
    point = const("VK_PIPELINE_BIND_POINT_GRAPHICS")
    draws = 0
    ctx._begin_rendering(colors, depth, True, (first.width, first.height))
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
        last_material = None
        for k, inst in enumerate(scene.instances):
            mesh = scene.meshes[inst.mesh]
            rng = ms.ranges[inst.mesh]
            if scene.materials[mesh.material].alpha_mode not in alpha or rng.count == 0:
                continue
            if mesh.material != last_material:
                lib.vkCmdBindDescriptorSets(cmd, point, ms.layout, 2, 1,
                                            ctx.scene.material_sets[mesh.material], 0, ffi.NULL)
                last_material = mesh.material
            lib.vkCmdBindDescriptorSets(cmd, point, ms.layout, 3, 1,
                                        ctx.scene.instance_sets[k], 0, ffi.NULL)
            data = ffi.new("char[]", struct.pack("<4I", k, rng.first, rng.count, flags))
            lib.vkCmdPushConstants(cmd, ms.layout, stage_flags, 0, 16, data)
            ctx.device.fn.vkCmdDrawMeshTasksEXT(cmd, math.ceil(rng.count / TASK_GROUP), 1, 1)
            draws += 1
    finally:
        vk.vkCmdEndRendering(cmd)
    barrier(cmd, memory_barriers=[(_TASK_RW, _HOST)])
    return draws
