"""Shader programs on Vulkan: compiled stages, layouts reflected from SPIR-V, and their
compute, graphics and ray-tracing pipelines, cached by content."""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rfw.backends.scene_data import SCENE_GROUPS
from rfw.passes import Pass
from rfw.shaders import ShaderError
from rfw.spirv import DescriptorInfo, ShaderCompileError, Spirv, compile_glsl, reflect

from .consts import const, ffi, new, vk
from .device import VkDevice
from .objects import COMPARE, DescriptorSetLayout, VkObject
from .sbt import ShaderBindingTable, check_recursion, create_ray_pipeline, shader_group_handles
from .scene import VkScene

_STAGE_BITS = {"vert": "VK_SHADER_STAGE_VERTEX_BIT", "frag": "VK_SHADER_STAGE_FRAGMENT_BIT",
               "task": "VK_SHADER_STAGE_TASK_BIT_EXT", "mesh": "VK_SHADER_STAGE_MESH_BIT_EXT",
               "comp": "VK_SHADER_STAGE_COMPUTE_BIT", "rgen": "VK_SHADER_STAGE_RAYGEN_BIT_KHR",
               "rmiss": "VK_SHADER_STAGE_MISS_BIT_KHR",
               "rchit": "VK_SHADER_STAGE_CLOSEST_HIT_BIT_KHR",
               "rahit": "VK_SHADER_STAGE_ANY_HIT_BIT_KHR"}
_CULL = {"none": "VK_CULL_MODE_NONE", "front": "VK_CULL_MODE_FRONT_BIT",
         "back": "VK_CULL_MODE_BACK_BIT"}
_BLEND_FACTOR = {
    "zero": "VK_BLEND_FACTOR_ZERO", "one": "VK_BLEND_FACTOR_ONE",
    "src": "VK_BLEND_FACTOR_SRC_COLOR", "one-minus-src": "VK_BLEND_FACTOR_ONE_MINUS_SRC_COLOR",
    "src-alpha": "VK_BLEND_FACTOR_SRC_ALPHA",
    "one-minus-src-alpha": "VK_BLEND_FACTOR_ONE_MINUS_SRC_ALPHA",
    "dst": "VK_BLEND_FACTOR_DST_COLOR", "one-minus-dst": "VK_BLEND_FACTOR_ONE_MINUS_DST_COLOR",
    "dst-alpha": "VK_BLEND_FACTOR_DST_ALPHA",
    "one-minus-dst-alpha": "VK_BLEND_FACTOR_ONE_MINUS_DST_ALPHA",
    "src-alpha-saturated": "VK_BLEND_FACTOR_SRC_ALPHA_SATURATE",
    "constant": "VK_BLEND_FACTOR_CONSTANT_COLOR",
    "one-minus-constant": "VK_BLEND_FACTOR_ONE_MINUS_CONSTANT_COLOR",
}
_BLEND_OP = {"add": "VK_BLEND_OP_ADD", "subtract": "VK_BLEND_OP_SUBTRACT",
             "reverse-subtract": "VK_BLEND_OP_REVERSE_SUBTRACT", "min": "VK_BLEND_OP_MIN",
             "max": "VK_BLEND_OP_MAX"}
# the stages each kind of program runs; raster kinds use the scene's sets 1-3
KINDS = {"compute": ("comp",), "render": ("vert", "frag"), "mesh": ("task", "mesh", "frag"),
         "ray_tracing": ("rgen", "rmiss", "rchit", "rahit")}
RASTER = ("render", "mesh")
# the device capability a kind of program needs (the others run everywhere)
NEEDS = {"mesh": "VK_EXT_mesh_shader", "ray_tracing": "VK_KHR_ray_tracing_pipeline"}
# the scene's vertex buffers (rfw.backends.wgpu.scene.VERTEX_BUFFERS): one attribute per buffer
_VERTEX = ((12, "VK_FORMAT_R32G32B32_SFLOAT"), (12, "VK_FORMAT_R32G32B32_SFLOAT"),
           (8, "VK_FORMAT_R32G32_SFLOAT"), (16, "VK_FORMAT_R32G32B32A32_SFLOAT"))


class ShaderModule(VkObject):
    """One compiled stage: ``vkCreateShaderModule`` of a :class:`rfw.spirv.Spirv`."""

    destroy_fn, object_type = "vkDestroyShaderModule", "SHADER_MODULE"

    def __init__(self, device: VkDevice, spv: Any, label: str = ""):
        words = ffi.new("uint32_t[]", len(spv.code) // 4)
        ffi.memmove(words, spv.code, len(spv.code))
        info = new("VkShaderModuleCreateInfo", codeSize=len(spv.code), pCode=words)
        super().__init__(device, vk.vkCreateShaderModule(device.device, info, None),
                         label or Path(spv.path).name)
        self.stage, self.path = spv.stage, Path(spv.path)


class PipelineLayout(VkObject):
    destroy_fn, object_type = "vkDestroyPipelineLayout", "PIPELINE_LAYOUT"


class Pipeline(VkObject):
    destroy_fn, object_type = "vkDestroyPipeline", "PIPELINE"


@dataclass
class Program:
    """Compiled stages of one shader variant, their reflected layouts and pipelines."""

    paths: tuple[Path, ...]
    kind: str  # compute | render | mesh | ray_tracing
    modules: dict[str, ShaderModule]  # stage -> module
    descriptors: dict[str, DescriptorInfo]
    set_layouts: list[Any]  # VkDescriptorSetLayout per set index
    scene_sets: frozenset[int]  # sets whose layout is the scene's
    pipeline_layout: PipelineLayout
    stage_flags: int
    push_size: int
    local_size: tuple[int, int, int]
    pipelines: dict[Any, Pipeline] = field(default_factory=dict)
    device: VkDevice | None = None
    spirvs: tuple[Spirv, ...] = ()  # its files compiled (rfw.settings_layout reads them)
    # (uniform block, Settings type) pairs whose layout was checked against each other
    settings_checked: set[tuple[str, type]] = field(default_factory=set)

    @property
    def name(self) -> str:
        name = self.__dict__.get("_name")  # worked out once: binding checks name it per call
        if name is None:
            name = self.__dict__["_name"] = " + ".join(str(p) for p in self.paths)
        return name

    @property
    def handle(self) -> Any:
        """The pipeline layout's handle (what descriptor sets and push constants bind to)."""
        return self.pipeline_layout.handle

    @property
    def push_stages(self) -> int:
        """The stages push constants reach: every stage of the program."""
        return self.stage_flags

    def sets(self) -> list[int]:
        out = self.__dict__.get("_sets")  # worked out once: binds ask each frame
        if out is None:
            out = self.__dict__["_sets"] = sorted({d.set for d in self.descriptors.values()})
        return out

    def set_descriptors(self, s: int) -> list[DescriptorInfo]:
        """The descriptors of set ``s`` by binding (worked out once: binds ask each frame)."""
        by_set = self.__dict__.setdefault("_by_set", {})
        out = by_set.get(s)
        if out is None:
            out = by_set[s] = sorted((d for d in self.descriptors.values() if d.set == s),
                                     key=lambda d: d.binding)
        return out


class Programs:
    """Programs keyed by their SPIR-V (content-addressed: source, includes and defines)."""

    def __init__(self, device: VkDevice, scene: VkScene | None):
        self.device, self.scene = device, scene
        self.programs: dict[tuple, Program] = {}
        self.layouts: dict[tuple, DescriptorSetLayout] = {}
        self.objects: list[VkObject] = []
        self.compiled: dict[tuple, list[Any]] = {}

    def get(self, owner: Pass | str, paths: list[Path], defines: dict[str, object],
            kind: str) -> Program:
        """The program of ``paths`` (one file per stage) compiled with ``defines``;
        ``kind``: compute | render (vertex [+ fragment]) | mesh ([task +] mesh [+ fragment])
        | ray_tracing. ``owner`` (a pass or a name) is named by every error."""
        if kind not in KINDS:
            raise ShaderError(f"{_owner(owner)}: unknown program kind '{kind}' "
                              f"({', '.join(KINDS)})")
        need = NEEDS.get(kind)
        if need is not None and need not in self.device.caps:
            raise ShaderError(f"{_owner(owner)}: a {kind} program needs {need}, which "
                              f"{self.device.name} lacks")
        # compile_glsl hashes every include and asks glslang its version: once per variant
        # and file version, not once per dispatch
        memo = (kind, tuple(paths), tuple(sorted((k, str(v)) for k, v in defines.items())),
                tuple(_mtime(p) for p in paths))
        spirvs = self.compiled.get(memo)
        if spirvs is None:
            try:
                # a mesh program never runs on wgpu, and its fragment shader may read the
                # mesh shader's per-primitive outputs (SPIR-V 1.4): every stage targets 1.3
                target = "vulkan1.3" if kind == "mesh" else None
                spirvs = self.compiled[memo] = [compile_glsl(p, defines, target=target)
                                                for p in paths]
            except ShaderCompileError as e:
                raise ShaderCompileError(f"{_owner(owner)}: {e}") from None
        key = (kind, *(s.key for s in spirvs))
        prog = self.programs.get(key)
        if prog is None:
            prog = self.programs[key] = self._build(_owner(owner), paths, spirvs, kind)
        return prog

    def _own(self, obj: VkObject) -> Any:
        self.objects.append(obj)
        return obj

    def _build(self, owner: str, paths: list[Path], spirvs: list[Any], kind: str) -> Program:
        dev = self.device
        descriptors: dict[str, DescriptorInfo] = {}
        stage_flags, push = 0, 0
        sizes: dict[str, tuple[int, int, int]] = {}
        modules: dict[str, ShaderModule] = {}
        where = " + ".join(str(p) for p in paths)
        for path, spv in zip(paths, spirvs, strict=True):
            refl = reflect(spv.code)
            if spv.stage in modules:
                raise ShaderError(f"{owner}: {where} has two {spv.stage} shaders "
                                  "(a program takes one of each stage)")
            stage_flags |= const(_STAGE_BITS[spv.stage])
            push = max(push, refl.push_constant_size)
            sizes[spv.stage] = refl.local_size
            for d in refl.descriptors.values():
                prior = descriptors.get(d.name)
                if prior is not None and (prior.set, prior.binding, prior.kind) != (
                        d.set, d.binding, d.kind):
                    raise ShaderError(f"{owner}: '{d.name}' is set {prior.set} "
                                      f"binding {prior.binding} ({prior.kind}) in one stage "
                                      f"and set {d.set} binding {d.binding} ({d.kind}) in "
                                      f"{path}")
                descriptors[d.name] = d
            modules[spv.stage] = self._own(ShaderModule(dev, spv, path.name))
        # the workgroup a dispatch (or a mesh-task launch) counts in
        local = next((sizes[st] for st in ("comp", "task", "mesh") if st in sizes), (1, 1, 1))
        if kind == "render" and "vert" not in modules:
            raise ShaderError(f"{owner}: {where} has no vertex shader")
        if kind == "mesh" and "mesh" not in modules:
            raise ShaderError(f"{owner}: {where} has no mesh shader")
        odd = sorted(set(modules) - set(KINDS[kind]))
        if odd:
            raise ShaderError(f"{owner}: {where} has {', '.join(odd)} shader(s), which a "
                              f"{kind} program does not run ({', '.join(KINDS[kind])})")

        by_set: dict[int, list[DescriptorInfo]] = defaultdict(list)
        for d in descriptors.values():
            by_set[d.set].append(d)
        top = max(by_set, default=-1)
        if kind in RASTER and self.scene is not None:
            top = max(top, max(SCENE_GROUPS))
        layouts, scene_sets = [], set()
        for s in range(top + 1):
            mine = by_set.get(s, [])
            # the scene's layouts are for raster and compute stages: ray-tracing programs
            # get their own layouts (and per-frame sets holding the same buffers)
            scene_like = kind != "ray_tracing" and self.scene is not None and \
                s in SCENE_GROUPS and all(
                    (d.name, d.binding, d.kind) in SCENE_GROUPS[s] for d in mine)
            if kind in RASTER and s in SCENE_GROUPS and self.scene is not None:
                if not scene_like:
                    odd = [d.name for d in mine if (d.name, d.binding, d.kind)
                           not in SCENE_GROUPS[s]]
                    raise ShaderError(f"{owner}: {where} declares "
                                      f"{', '.join(odd)} in set {s}, which the scene owns "
                                      f"({', '.join(n for n, _, _ in SCENE_GROUPS[s])})")
                layouts.append(self.scene.layouts[s].handle)
                scene_sets.add(s)
            elif scene_like and mine:
                layouts.append(self.scene.layouts[s].handle)
                scene_sets.add(s)
            else:
                entries = tuple(sorted((d.binding, d.kind, max(1, d.count)) for d in mine))
                lkey = (entries, stage_flags)
                if lkey not in self.layouts:
                    self.layouts[lkey] = self._own(DescriptorSetLayout(
                        dev, entries, stage_flags, label=f"{paths[0].name}:set{s}"))
                layouts.append(self.layouts[lkey].handle)
        handles = ffi.new("VkDescriptorSetLayout[]", max(1, len(layouts)))
        for i, h in enumerate(layouts):
            handles[i] = h
        info = new("VkPipelineLayoutCreateInfo", setLayoutCount=len(layouts), pSetLayouts=handles)
        if push:
            rng = ffi.new("VkPushConstantRange*")
            rng.stageFlags, rng.offset, rng.size = stage_flags, 0, push
            info.pushConstantRangeCount, info.pPushConstantRanges = 1, rng
        layout = self._own(PipelineLayout(dev, vk.vkCreatePipelineLayout(dev.device, info, None),
                                          f"{paths[0].name}:layout"))
        return Program(tuple(paths), kind, modules, descriptors, layouts, frozenset(scene_sets),
                       layout, stage_flags, push, local, device=dev, spirvs=tuple(spirvs))

    def compute_pipeline(self, prog: Program) -> Pipeline:
        pipe = prog.pipelines.get("compute")
        if pipe is None:
            info = new("VkComputePipelineCreateInfo", layout=prog.pipeline_layout.handle,
                       basePipelineIndex=-1)
            info.stage.sType = const("VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO")
            info.stage.stage = const("VK_SHADER_STAGE_COMPUTE_BIT")
            info.stage.module = prog.modules["comp"].handle
            entry = ffi.new("char[]", b"main")
            info.stage.pName = entry
            handle = vk.vkCreateComputePipelines(self.device.device, ffi.NULL, 1, info, None)[0]
            pipe = prog.pipelines["compute"] = self._own(
                Pipeline(self.device, handle, f"{prog.paths[0].name}:compute"))
        return pipe

    def ray_pipeline(self, prog: Program, *, max_recursion: int = 1) -> RayPipeline:
        """The ray-tracing pipeline of ``prog`` (raygen, then its miss shader, then a
        triangle hit group of its closest-hit and any-hit shaders, where it has them) and
        its shader binding table, made once per ``max_recursion``."""
        key = ("ray_tracing", max_recursion)
        pipe = prog.pipelines.get(key)
        if pipe is None:
            pipe = prog.pipelines[key] = self._own(RayPipeline(self.device, prog,
                                                               max_recursion))
        return pipe

    def graphics_pipeline(self, prog: Program, *, colors: Sequence[int], depth: int | None,
                          stencil: bool, samples: int, depth_compare: str, depth_write: bool,
                          cull: str, blend: dict | None,
                          topology: str = "triangle-list") -> Pipeline:
        key = ("graphics", tuple(colors), depth, stencil, samples, depth_compare, depth_write,
               cull, repr(blend), topology)
        pipe = prog.pipelines.get(key)
        if pipe is not None:
            return pipe
        keep: list[Any] = []
        stages = new("VkPipelineShaderStageCreateInfo", len(prog.modules))
        entry = ffi.new("char[]", b"main")
        for i, (stage, module) in enumerate(prog.modules.items()):
            stages[i].stage = const(_STAGE_BITS[stage])
            stages[i].module = module.handle
            stages[i].pName = entry
        vertex = assembly = ffi.NULL  # mesh pipelines: the mesh shader fetches its vertices
        if prog.kind == "render":
            vertex, assembly = _vertex_input(keep, topology)
            if topology != "triangle-list":
                cull = "none"  # points and lines have no faces to cull
        viewport = new("VkPipelineViewportStateCreateInfo", viewportCount=1, scissorCount=1)
        if cull not in _CULL:
            raise ShaderError(f"unknown cull mode '{cull}' (none, front or back)")
        raster = new("VkPipelineRasterizationStateCreateInfo",
                     polygonMode=const("VK_POLYGON_MODE_FILL"), cullMode=const(_CULL[cull]),
                     frontFace=const("VK_FRONT_FACE_COUNTER_CLOCKWISE"), lineWidth=1.0)
        multisample = new("VkPipelineMultisampleStateCreateInfo", rasterizationSamples=samples)
        ds = new("VkPipelineDepthStencilStateCreateInfo",
                 depthTestEnable=int(depth is not None),
                 depthWriteEnable=int(depth is not None and depth_write),
                 depthCompareOp=const(COMPARE[depth_compare]))
        attachments = ffi.new("VkPipelineColorBlendAttachmentState[]", max(1, len(colors)))
        for i in range(len(colors)):
            _blend_state(attachments[i], blend)
        blend_info = new("VkPipelineColorBlendStateCreateInfo", attachmentCount=len(colors),
                         pAttachments=attachments)
        dyn_states = ffi.new("VkDynamicState[2]", [const("VK_DYNAMIC_STATE_VIEWPORT"),
                                                   const("VK_DYNAMIC_STATE_SCISSOR")])
        dynamic = new("VkPipelineDynamicStateCreateInfo", dynamicStateCount=2,
                      pDynamicStates=dyn_states)
        formats = ffi.new("VkFormat[]", max(1, len(colors)))
        for i, f in enumerate(colors):
            formats[i] = f
        rendering = new("VkPipelineRenderingCreateInfo", colorAttachmentCount=len(colors),
                        pColorAttachmentFormats=formats,
                        depthAttachmentFormat=depth if depth is not None else 0,
                        stencilAttachmentFormat=depth if stencil and depth is not None else 0)
        info = new("VkGraphicsPipelineCreateInfo", pNext=rendering, stageCount=len(prog.modules),
                   pStages=stages, pVertexInputState=vertex, pInputAssemblyState=assembly,
                   pViewportState=viewport, pRasterizationState=raster,
                   pMultisampleState=multisample, pDepthStencilState=ds,
                   pColorBlendState=blend_info, pDynamicState=dynamic,
                   layout=prog.pipeline_layout.handle, basePipelineIndex=-1)
        keep += [entry, formats, dyn_states]
        handle = vk.vkCreateGraphicsPipelines(self.device.device, ffi.NULL, 1, info, None)[0]
        pipe = prog.pipelines[key] = self._own(
            Pipeline(self.device, handle, f"{prog.paths[0].name}:graphics"))
        return pipe

    def destroy(self) -> None:
        for obj in reversed(self.objects):
            obj.destroy()
        self.objects.clear()
        self.programs.clear()
        self.layouts.clear()
        self.compiled.clear()


class RayPipeline:
    """A ray-tracing pipeline made from a :class:`Program`'s modules, with its shader binding
    table (``vkext.sbt.ShaderBindingTable``: raygen, one miss record, one hit record)."""

    def __init__(self, device: VkDevice, prog: Program, max_recursion: int):
        try:
            check_recursion(device, max_recursion, prog.name)
        except ValueError as e:
            raise ShaderError(str(e)) from None
        if "rgen" not in prog.modules:
            raise ShaderError(f"{prog.name}: a ray-tracing program needs a raygen shader")
        self.device, self.label = device, f"{prog.paths[0].name}:ray_tracing"
        stages = [s for s in ("rgen", "rmiss", "rchit", "rahit") if s in prog.modules]
        unused = const("VK_SHADER_UNUSED_KHR")
        general = const("VK_RAY_TRACING_SHADER_GROUP_TYPE_GENERAL_KHR")
        groups = [(general, 0, unused, unused)]
        if "rmiss" in prog.modules:
            groups.append((general, stages.index("rmiss"), unused, unused))
        hit = "rchit" in prog.modules or "rahit" in prog.modules
        if hit:
            groups.append((const("VK_RAY_TRACING_SHADER_GROUP_TYPE_TRIANGLES_HIT_GROUP_KHR"),
                           unused, stages.index("rchit") if "rchit" in stages else unused,
                           stages.index("rahit") if "rahit" in stages else unused))
        self.counts = {"raygen": 1, "miss": int("rmiss" in prog.modules), "hit": int(hit)}
        handle = create_ray_pipeline(
            device, [(const(_STAGE_BITS[st]), prog.modules[st].handle) for st in stages], groups,
            max_recursion, prog.pipeline_layout.handle)
        self.pipeline = Pipeline(device, handle, self.label)
        self.group_count = len(groups)
        self.sbt = None
        try:
            self.sbt = ShaderBindingTable(self, label=f"{self.label}:sbt")
        except BaseException:
            self.destroy()
            raise

    @property
    def handle(self) -> Any:
        return self.pipeline.handle

    def group_handles(self) -> list[bytes]:
        return shader_group_handles(self.device, self.pipeline.handle, self.group_count)

    def destroy(self) -> None:
        if self.sbt is not None:
            self.sbt.destroy()
            self.sbt = None
        self.pipeline.destroy()



_TOPOLOGY = {"triangle-list": "VK_PRIMITIVE_TOPOLOGY_TRIANGLE_LIST",
             "line-list": "VK_PRIMITIVE_TOPOLOGY_LINE_LIST",
             "point-list": "VK_PRIMITIVE_TOPOLOGY_POINT_LIST"}


def _vertex_input(keep: list[Any], topology: str = "triangle-list") -> tuple[Any, Any]:
    """The scene's vertex buffers as a vertex input, and the ``topology`` assembly state."""
    bindings = ffi.new("VkVertexInputBindingDescription[4]")
    attributes = ffi.new("VkVertexInputAttributeDescription[4]")
    for i, (stride, fmt) in enumerate(_VERTEX):
        bindings[i].binding, bindings[i].stride = i, stride
        bindings[i].inputRate = const("VK_VERTEX_INPUT_RATE_VERTEX")
        attributes[i].location, attributes[i].binding = i, i
        attributes[i].format, attributes[i].offset = const(fmt), 0
    keep += [bindings, attributes]
    vertex = new("VkPipelineVertexInputStateCreateInfo", vertexBindingDescriptionCount=4,
                 pVertexBindingDescriptions=bindings, vertexAttributeDescriptionCount=4,
                 pVertexAttributeDescriptions=attributes)
    assembly = new("VkPipelineInputAssemblyStateCreateInfo",
                   topology=const(_TOPOLOGY[topology]))
    return vertex, assembly


def _owner(owner: Pass | str) -> str:
    return owner if isinstance(owner, str) else f"pass '{owner.name}'"


def _mtime(path: Path) -> int:
    try:
        return path.stat().st_mtime_ns
    except OSError:
        return 0


def _blend_state(out: Any, blend: dict | None) -> None:
    out.colorWriteMask = 0xF
    if not blend:
        out.blendEnable = 0
        return
    out.blendEnable = 1
    color, alpha = blend.get("color", {}), blend.get("alpha", {})
    try:
        out.srcColorBlendFactor = const(_BLEND_FACTOR[color.get("src_factor", "one")])
        out.dstColorBlendFactor = const(_BLEND_FACTOR[color.get("dst_factor", "zero")])
        out.colorBlendOp = const(_BLEND_OP[color.get("operation", "add")])
        out.srcAlphaBlendFactor = const(_BLEND_FACTOR[alpha.get("src_factor", "one")])
        out.dstAlphaBlendFactor = const(_BLEND_FACTOR[alpha.get("dst_factor", "zero")])
        out.alphaBlendOp = const(_BLEND_OP[alpha.get("operation", "add")])
    except KeyError as e:
        raise ShaderError(f"blend state {blend}: unknown factor or operation {e}") from None
