"""Run a compiled frame graph on raw Vulkan: the twin of ``rfw.backends.wgpu_backend``.

Transient images and buffers live in the plan's aliased heaps (``plan_heaps``); persistent,
external and history ones come from a :class:`BlockAllocator`. A frame is one command buffer:
per pass a debug label, the plan's barriers for that pass (the only synchronization between
passes: nothing a pass records waits on anything), a timestamp before and after, and the
pass's unchanged ``record(ctx)``. Passes run their GLSL twins (``X.comp.wgsl`` ->
``X.comp.glsl``, ``X.wgsl`` -> ``X.vert.glsl`` + ``X.frag.glsl``); layouts are reflected
from SPIR-V, and image descriptors are written in the layout the plan puts the image in for
the pass.
"""

from __future__ import annotations

import math
import time
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from rfw.backends.base import FrameExecutor, SlotContext
from rfw.errors import naming
from rfw.graph import CompiledGraph
from rfw.graph.compile import MemoryOptions, compile
from rfw.graph.formats import format_info
from rfw.graph.graph import Graph
from rfw.graph.sync import State
from rfw.passes import Pass, Settings
from rfw.shaders import ShaderError
from rfw.units import MiB, align_up

from .commands import (
    GLOBAL,
    CommandPool,
    ImageBarrier,
    TimestampPool,
    as_state,
    barrier,
    image_layout,
    label,
    one_time,
    read_buffer,
    read_image,
    record_barriers,
    submit,
    upload_image,
)
from .consts import const, ffi, lib, vk
from .device import VkDevice
from .memory import (
    BlockAllocator,
    Buffer,
    Image,
    ImageView,
    image_view,
    memory_options,
    plan_heaps,
    requirements,
)
from .scene import (
    COMPARE,
    SCENE_SETS,
    BufferRange,
    DescriptorPool,
    DescriptorSetLayout,
    Sampler,
    VkObject,
    VkScene,
    new,
    update_descriptors,
)
from .spirv import DescriptorInfo, ShaderCompileError, compile_glsl, reflect

TIMESTAMP_STAGE = "ALL_COMMANDS"

_STAGE_BITS = {"vert": "VK_SHADER_STAGE_VERTEX_BIT", "frag": "VK_SHADER_STAGE_FRAGMENT_BIT",
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
# the scene's vertex buffers (gpu_scene.VERTEX_BUFFERS): one attribute per buffer
_VERTEX = ((12, "VK_FORMAT_R32G32B32_SFLOAT"), (12, "VK_FORMAT_R32G32B32_SFLOAT"),
           (8, "VK_FORMAT_R32G32_SFLOAT"), (16, "VK_FORMAT_R32G32B32A32_SFLOAT"))
_COLOR_ATTACHMENT_LAYOUTS = {"COLOR_ATTACHMENT_OPTIMAL", "GENERAL", "ATTACHMENT_OPTIMAL"}


# ---------------------------------------------------------------------------------------------
# compiling for a device


def fit_plan(graph: Graph, device: VkDevice, *, alias: bool = True,
             readback: bool = True) -> tuple[CompiledGraph, dict[str, Any]]:
    """Compile ``graph`` for the vk backend with placement rules that fit ``device``.

    The compiler's default placement (texel bytes, 64 KiB image / 256 B buffer alignment) is
    checked against the driver's real requirements (``vkext.memory.memory_options``: its
    alignments and exact padded sizes); where they differ the graph is compiled again with
    the device's, so the plan's bytes are the bytes the driver binds. The returned dict says
    what happened: ``recompiled``, ``default_fits`` (whether ``plan_heaps`` would have
    accepted the default plan at all), the alignments and a ``reason``.
    """
    for p in graph.passes:
        if p.enabled and p.backend not in (None, "vk"):
            raise ShaderError(f"pass '{p.name}' is pinned to backend '{p.backend}': the vk "
                              "backend runs every pass on Vulkan (frames that mix backends "
                              "run through rfw.render.render or vkext.mixed.render_mixed)",
                              file=graph.source)
    return fit_graph(graph, device, alias=alias, readback=readback)


def fit_graph(graph: Graph, device: VkDevice, *, alias: bool = True,
              readback: bool = True) -> tuple[CompiledGraph, dict[str, Any]]:
    """``fit_plan`` without the check for pins (a backend's part of a mixed frame, whose
    bridge passes carry ``"vk>wgpu"``-style backends, compiles through here)."""
    base = MemoryOptions(alias=alias)
    # the device's capabilities: a pass needing a feature it lacks is refused here, by name
    plan = compile(graph, caps=device.caps, backend="vk", memory=base)
    opts = memory_options(plan, device, base=base, readback=readback)
    info: dict[str, Any] = {"recompiled": False, "image_alignment": base.image_alignment,
                            "buffer_alignment": base.buffer_alignment, "default_fits": True}
    fitted = compile(graph, caps=device.caps, backend="vk", memory=opts)
    placement = [(r.name, r.bytes, r.offset) for r in plan.resources if r.transient]
    if placement != [(r.name, r.bytes, r.offset) for r in fitted.resources if r.transient]:
        fits = plan_fits(plan, device, readback=readback)
        padded = [r.name for r in plan.resources
                  if r.transient and dict(opts.sizes).get(r.name, 0) > r.raw_bytes]
        info = {"recompiled": True, "image_alignment": opts.image_alignment,
                "buffer_alignment": opts.buffer_alignment, "default_fits": fits,
                "reason": (f"the default placement ({base.image_alignment} B image, "
                           f"{base.buffer_alignment} B buffer alignment, texel bytes) "
                           + ("fits but over-reserves on" if fits else "does not fit")
                           + f" {device.name}: re-compiled with its {opts.image_alignment} B / "
                           f"{opts.buffer_alignment} B alignment and exact sizes"
                           + (f" ({len(padded)} padded by the driver)" if padded else ""))}
        plan = fitted
    return plan, info


def plan_fits(plan: CompiledGraph, device: VkDevice, *, readback: bool = True) -> bool:
    """Whether every transient's driver size and alignment fit its planned bytes and offset."""
    reqs = requirements(plan, device, readback=readback)
    for r in plan.resources:
        if r.name in reqs:
            size, alignment = reqs[r.name]
            if size > r.bytes or (r.offset or 0) % alignment:
                return False
    return True


# ---------------------------------------------------------------------------------------------
# shaders: GLSL twins, programs, pipelines


def glsl_twins(folder: Path, shader: str, kind: str) -> list[Path]:
    """The GLSL files that stand for a pass's WGSL shader (``kind``: compute | render);
    the first is required, the rest (a fragment shader) optional."""
    if shader.endswith(".glsl"):
        return [folder / shader]
    stem = shader.removesuffix(".wgsl").removesuffix(".comp")
    if kind == "compute":
        return [folder / f"{stem}.comp.glsl"]
    return [folder / f"{stem}.vert.glsl", folder / f"{stem}.frag.glsl"]


def twin_paths(pass_: Pass, shader: str | None, kind: str) -> list[Path]:
    """Existing twins of ``shader`` (default: the pass's), or a ShaderError naming the pass
    and the missing file."""
    name = shader or pass_.shader
    if not name:
        raise ShaderError(f"pass '{pass_.name}' ({type(pass_).id or type(pass_).__name__}) "
                          "records work but declares no shader")
    paths = glsl_twins(pass_.folder(), name, kind)
    if not paths[0].is_file():
        raise ShaderError(f"pass '{pass_.name}' ({type(pass_).id or type(pass_).__name__}) "
                          f"has no GLSL twin of {name}: {paths[0]} is missing (the vk backend "
                          f"runs {paths[0].name} beside {name})")
    return [paths[0], *(p for p in paths[1:] if p.is_file())]


def check_passes(plan: CompiledGraph, passes: dict[str, Pass]) -> None:
    """Every scheduled pass has an instance and GLSL twins of its shader: a ShaderError
    naming the pass and the missing file, before any GPU object is made."""
    for name in plan.order:
        p = passes.get(name)
        if p is None:
            if is_bridge(plan, name) and len(plan.accesses[name]) > 1:
                raise ShaderError(f"pass '{name}' copies between backends: the plan mixes "
                                  "them, and runs through vkext.mixed (each backend gets its "
                                  "part of it)")
            if is_bridge(plan, name):
                continue  # its barriers are recorded; vkext.mixed copies through the host
            raise ShaderError(f"pass '{name}' has no pass instance")
        if p.shader:
            twin_paths(p, None, "compute" if p.type == "compute" else "render")


def is_bridge(plan: CompiledGraph, name: str) -> bool:
    """Whether ``name`` is a bridge pass (``rfw.graph.bridges``): named ``bridge.*`` and
    touching its resources only as a transfer source or destination."""
    return name.startswith("bridge.") and all(
        a.usages <= {"transfer_src", "transfer_dst"} for a in plan.accesses.get(name, ()))


class ShaderModule(VkObject):
    destroy_fn, object_type = "vkDestroyShaderModule", "SHADER_MODULE"


class PipelineLayout(VkObject):
    destroy_fn, object_type = "vkDestroyPipelineLayout", "PIPELINE_LAYOUT"


class Pipeline(VkObject):
    destroy_fn, object_type = "vkDestroyPipeline", "PIPELINE"


@dataclass
class Program:
    """Compiled stages of one shader variant, their reflected layouts and pipelines."""

    paths: tuple[Path, ...]
    kind: str  # compute | render | ray_tracing
    modules: dict[str, ShaderModule]  # stage -> module
    descriptors: dict[str, DescriptorInfo]
    set_layouts: list[Any]  # VkDescriptorSetLayout per set index
    scene_sets: frozenset[int]  # sets whose layout is the scene's
    pipeline_layout: PipelineLayout
    stage_flags: int
    push_size: int
    local_size: tuple[int, int, int]
    pipelines: dict[Any, Pipeline] = field(default_factory=dict)

    @property
    def name(self) -> str:
        return " + ".join(str(p) for p in self.paths)

    def sets(self) -> list[int]:
        return sorted({d.set for d in self.descriptors.values()})


class Programs:
    """Programs keyed by their SPIR-V (content-addressed: source, includes and defines)."""

    def __init__(self, device: VkDevice, scene: VkScene | None):
        self.device, self.scene = device, scene
        self.programs: dict[tuple, Program] = {}
        self.layouts: dict[tuple, DescriptorSetLayout] = {}
        self.objects: list[VkObject] = []
        self.compiled: dict[tuple, list[Any]] = {}

    def get(self, pass_: Pass, paths: list[Path], defines: dict[str, object],
            kind: str) -> Program:
        # compile_glsl hashes every include and asks glslang its version: once per variant
        # and file version, not once per dispatch
        memo = (kind, tuple(paths), tuple(sorted((k, str(v)) for k, v in defines.items())),
                tuple(_mtime(p) for p in paths))
        spirvs = self.compiled.get(memo)
        if spirvs is None:
            try:
                spirvs = self.compiled[memo] = [compile_glsl(p, defines) for p in paths]
            except ShaderCompileError as e:
                raise ShaderCompileError(f"pass '{pass_.name}': {e}") from None
        key = (kind, *(s.key for s in spirvs))
        prog = self.programs.get(key)
        if prog is None:
            prog = self.programs[key] = self._build(pass_, paths, spirvs, kind)
        return prog

    def _own(self, obj: VkObject) -> Any:
        self.objects.append(obj)
        return obj

    def _build(self, pass_: Pass, paths: list[Path], spirvs: list[Any], kind: str) -> Program:
        dev = self.device
        descriptors: dict[str, DescriptorInfo] = {}
        stage_flags, push, local = 0, 0, (1, 1, 1)
        modules: dict[str, ShaderModule] = {}
        where = " + ".join(str(p) for p in paths)
        for path, spv in zip(paths, spirvs, strict=True):
            refl = reflect(spv.code)
            if spv.stage in modules:
                raise ShaderError(f"pass '{pass_.name}': {where} has two {spv.stage} shaders "
                                  "(a program takes one of each stage)")
            stage_flags |= const(_STAGE_BITS[spv.stage])
            push = max(push, refl.push_constant_size)
            if spv.stage == "comp":
                local = refl.local_size
            for d in refl.descriptors.values():
                prior = descriptors.get(d.name)
                if prior is not None and (prior.set, prior.binding, prior.kind) != (
                        d.set, d.binding, d.kind):
                    raise ShaderError(f"pass '{pass_.name}': '{d.name}' is set {prior.set} "
                                      f"binding {prior.binding} ({prior.kind}) in one stage "
                                      f"and set {d.set} binding {d.binding} ({d.kind}) in "
                                      f"{path}")
                descriptors[d.name] = d
            words = ffi.new("uint32_t[]", len(spv.code) // 4)
            ffi.memmove(words, spv.code, len(spv.code))
            info = new("VkShaderModuleCreateInfo", codeSize=len(spv.code), pCode=words)
            modules[spv.stage] = self._own(ShaderModule(
                dev, vk.vkCreateShaderModule(dev.device, info, None), path.name))
        if kind == "render" and "vert" not in modules:
            raise ShaderError(f"pass '{pass_.name}': {where} has no vertex shader")

        by_set: dict[int, list[DescriptorInfo]] = defaultdict(list)
        for d in descriptors.values():
            by_set[d.set].append(d)
        top = max(by_set, default=-1)
        if kind == "render" and self.scene is not None:
            top = max(top, max(SCENE_SETS))
        layouts, scene_sets = [], set()
        for s in range(top + 1):
            mine = by_set.get(s, [])
            # the scene's layouts are for raster and compute stages: ray-tracing programs
            # get their own layouts (and per-frame sets holding the same buffers)
            scene_like = kind != "ray_tracing" and self.scene is not None and s in SCENE_SETS \
                and all(
                (d.name, d.binding, d.kind) in SCENE_SETS[s] for d in mine)
            if kind == "render" and s in SCENE_SETS and self.scene is not None:
                if not scene_like:
                    odd = [d.name for d in mine if (d.name, d.binding, d.kind)
                           not in SCENE_SETS[s]]
                    raise ShaderError(f"pass '{pass_.name}': {where} declares "
                                      f"{', '.join(odd)} in set {s}, which the scene owns "
                                      f"({', '.join(n for n, _, _ in SCENE_SETS[s])})")
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
                       layout, stage_flags, push, local)

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
                          cull: str, blend: dict | None) -> Pipeline:
        key = ("graphics", tuple(colors), depth, stencil, samples, depth_compare, depth_write,
               cull, repr(blend))
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
        bindings = ffi.new("VkVertexInputBindingDescription[4]")
        attributes = ffi.new("VkVertexInputAttributeDescription[4]")
        for i, (stride, fmt) in enumerate(_VERTEX):
            bindings[i].binding, bindings[i].stride = i, stride
            bindings[i].inputRate = const("VK_VERTEX_INPUT_RATE_VERTEX")
            attributes[i].location, attributes[i].binding = i, i
            attributes[i].format, attributes[i].offset = const(fmt), 0
        vertex = new("VkPipelineVertexInputStateCreateInfo", vertexBindingDescriptionCount=4,
                     pVertexBindingDescriptions=bindings, vertexAttributeDescriptionCount=4,
                     pVertexAttributeDescriptions=attributes)
        assembly = new("VkPipelineInputAssemblyStateCreateInfo",
                       topology=const("VK_PRIMITIVE_TOPOLOGY_TRIANGLE_LIST"))
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
        keep += [entry, bindings, attributes, formats, dyn_states]
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
    table (``vkext.rt.ShaderBindingTable``: raygen, one miss record, one hit record)."""

    def __init__(self, device: VkDevice, prog: Program, max_recursion: int):
        from .rt import ShaderBindingTable, check_recursion, create_ray_pipeline

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
        from .rt import shader_group_handles

        return shader_group_handles(self.device, self.pipeline.handle, self.group_count)

    def destroy(self) -> None:
        if self.sbt is not None:
            self.sbt.destroy()
            self.sbt = None
        self.pipeline.destroy()


def _runs(slots: list[int]) -> list[tuple[int, int]]:
    """Sorted slot numbers as (first, count) runs of consecutive ones."""
    out: list[tuple[int, int]] = []
    for k in slots:
        if out and out[-1][0] + out[-1][1] == k:
            out[-1] = (out[-1][0], out[-1][1] + 1)
        else:
            out.append((k, 1))
    return out


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


# ---------------------------------------------------------------------------------------------
# per-frame descriptors and uniforms


class FrameDescriptors:
    """Descriptor sets for one frame from pools that are reset together each frame; a new
    pool is added when the current one would run out (counted here, never by failing)."""

    SETS, PER_KIND = 64, 256
    KINDS = ("uniform_buffer", "storage_buffer", "sampled_image", "storage_image",
             "combined_image_sampler", "sampler", "acceleration_structure")

    def __init__(self, device: VkDevice):
        self.device = device
        self.pools: list[tuple[DescriptorPool, int]] = []  # (pool, descriptors per kind)
        self.current = 0
        self.sets = 0
        self.counts: dict[str, int] = defaultdict(int)

    def allocate(self, layout: Any, entries: Sequence[tuple[int, str, int]]) -> Any:
        """``VkDescriptorSet[1]`` of ``layout``, whose bindings are ``entries``."""
        need: dict[str, int] = defaultdict(int)
        for _, kind, n in entries:
            need[kind] += n
        while True:
            if self.current >= len(self.pools):
                size = max(self.PER_KIND, *need.values()) if need else self.PER_KIND
                pool = DescriptorPool(self.device, self.SETS, dict.fromkeys(self.KINDS, size),
                                      label=f"rfw:frame-descriptors{len(self.pools)}")
                self.pools.append((pool, size))
            pool, size = self.pools[self.current]
            if self.sets < self.SETS and all(self.counts[k] + n <= size
                                             for k, n in need.items()):
                break
            self.current, self.sets, self.counts = self.current + 1, 0, defaultdict(int)
        out = pool.allocate([layout])
        self.sets += 1
        for k, n in need.items():
            self.counts[k] += n
        return out

    def reset(self) -> None:
        for pool, _ in self.pools:
            pool.reset()
        self.current, self.sets, self.counts = 0, 0, defaultdict(int)

    def destroy(self) -> None:
        for pool, _ in self.pools:
            pool.destroy()
        self.pools.clear()


class UniformRing:
    """Settings and raw bytes as uniform buffers: host-visible chunks written in order,
    rewound each frame (frames are waited for before the next one records)."""

    def __init__(self, allocator: BlockAllocator, alignment: int, chunk: int = 64 * 1024):
        self.allocator, self.alignment, self.chunk = allocator, max(16, alignment), chunk
        self.chunks: list[Buffer] = []
        self.index, self.offset = 0, 0

    def push(self, data: bytes) -> BufferRange:
        size = max(16, align_up(len(data), 16))
        while True:
            if self.index >= len(self.chunks):
                self.chunks.append(self.allocator.create_buffer(
                    max(self.chunk, size), ("uniform",), host_visible=True,
                    label=f"rfw:uniforms{len(self.chunks)}"))
            buf = self.chunks[self.index]
            offset = align_up(self.offset, self.alignment)
            if offset + size <= buf.bytes:
                break
            self.index, self.offset = self.index + 1, 0
        padded = np.zeros(size, np.uint8)
        padded[:len(data)] = np.frombuffer(data, np.uint8)
        buf.write(padded, offset)
        self.offset = offset + size
        return BufferRange(buf.handle, offset, size)

    def reset(self) -> None:
        self.index, self.offset = 0, 0


# ---------------------------------------------------------------------------------------------
# the per-pass recording context


@dataclass
class PassTiming:
    name: str
    gpu_ms: list[float] = field(default_factory=list)
    cpu_ms: list[float] = field(default_factory=list)


@dataclass(frozen=True)
class ImageBinding:
    """An image slot bound to a descriptor: written in the layout the plan gives the image
    in the recording pass (sampled, storage and attachment alike)."""

    resource: str
    image: Image
    view: ImageView


def _check_storage_format(what: str, d: DescriptorInfo, view: ImageView, resource: str) -> None:
    """A storage image's declared format (``layout(rgba8)``) must be the view's: Vulkan
    leaves a mismatch undefined and no validation message reports it."""
    have = format_info(view.format)
    if d.format is None or have.vk is None or have.vk == d.format:
        return
    declared = format_info(d.format)
    raise ShaderError(f"{what} declared {declared.wgpu or declared.name} ({d.format}), but "
                      f"'{resource}' is {have.wgpu or have.name} ({have.vk})")


# one dispatch's shader writes, made visible to the next dispatch of the same pass
_SHADER_WRITE = State(None, frozenset({"COMPUTE_SHADER"}), frozenset({"SHADER_WRITE"}))
_SHADER_RW = State(None, frozenset({"COMPUTE_SHADER"}),
                   frozenset({"SHADER_READ", "SHADER_WRITE"}))


class VkPassContext(SlotContext):
    """What ``Pass.record`` sees on Vulkan: the wgpu ``PassContext``'s interface."""

    def __init__(self, executor: VkExecutor, pass_: Pass, cmd: Any, slots: dict[str, str]):
        self.executor = executor
        self.pass_ = pass_
        self.cmd = cmd
        self.slots = slots
        self.scene = executor.scene
        self.device = executor.device
        self.frame = executor.frame_index
        self._dispatched = False

    # resources ----------------------------------------------------------------------------
    def texture(self, slot: str) -> Image:
        return self.executor.image(self.resource(slot))

    def extent(self, slot: str) -> tuple[int, int]:
        r = self.executor.plan.resource(self.resource(slot))
        return r.width, r.height

    def view(self, slot: str, *, mip: int | None = None) -> ImageBinding:
        """The slot's image view; ``mip``: a view of that one mip level only."""
        name = self.resource(slot)
        return ImageBinding(name, self.executor.image(name), self.executor.view(name, mip=mip))

    def sampled(self, slot: str) -> ImageBinding:
        name = self.resource(slot)
        return ImageBinding(name, self.executor.image(name),
                            self.executor.view(name, sampled=True))

    storage = view

    def buffer(self, slot: str) -> Buffer:
        return self.executor.buffer(self.resource(slot))

    def accel(self, slot: str) -> Any:
        """The acceleration structures behind an ``AccelStructure`` slot (the
        ``vkext.accel.SceneAccel`` its builder published), to bind or to read mesh data of."""
        name = self.resource(slot)
        acc = self.executor.accels.get(name)
        if acc is None:
            raise ShaderError(f"pass '{self.pass_.name}': '{name}' has no acceleration "
                              "structure yet (its builder publishes one with set_accel)")
        return acc

    def set_accel(self, slot: str, accel: Any) -> None:
        """Publish the structures this pass builds for its ``AccelStructure`` output."""
        self.executor.accels[self.resource(slot)] = accel

    def format(self, slot: str) -> str:
        """The format's WebGPU name where it has one (as the wgpu backend answers)."""
        name = self.executor.plan.resource(self.resource(slot)).format
        return format_info(name).wgpu or name

    # recording ----------------------------------------------------------------------------
    def program(self, kind: str, *, shader: str | None = None,
                defines: dict[str, object] | None = None) -> Program:
        paths = twin_paths(self.pass_, shader, kind)
        return self.executor.programs.get(self.pass_, paths, defines or {}, kind)

    def _check_extra(self, prog: Program, values: dict[str, Any]) -> None:
        extra = [k for k in values if k not in prog.descriptors]
        if extra:
            raise ShaderError(f"pass '{self.pass_.name}': {prog.name} has no binding named "
                              f"{', '.join(extra)} (it declares "
                              f"{', '.join(sorted(prog.descriptors)) or 'none'})")

    def bind(self, prog: Program, values: dict[str, Any], point: int,
             sets: Sequence[int] | None = None) -> None:
        """Bind ``sets`` (default: every set of ``prog``), matching binding names to
        ``values``; the scene's own sets are bound as they are."""
        ex = self.executor
        for s in prog.sets() if sets is None else sets:
            wanted = sorted((d for d in prog.descriptors.values() if d.set == s),
                            key=lambda d: d.binding)
            if not wanted:
                continue
            missing = [d.name for d in wanted if d.name not in values]
            if missing:
                raise ShaderError(f"pass '{self.pass_.name}': shader {prog.name} binds "
                                  f"{', '.join(missing)} but the pass gives "
                                  f"{', '.join(sorted(values)) or 'nothing'}")
            handle = self._scene_set(prog, s, values, wanted)
            if handle is None:
                entries = [(d.binding, d.kind, max(1, d.count)) for d in wanted]
                arr = ex.descriptors.allocate(prog.set_layouts[s], entries)
                update_descriptors(ex.device, [
                    (arr[0], d.binding, d.kind, self._payload(prog, d, values[d.name]))
                    for d in wanted])
                handle = arr
            lib.vkCmdBindDescriptorSets(self.cmd, point, prog.pipeline_layout.handle, s, 1,
                                        handle, 0, ffi.NULL)

    def _scene_set(self, prog: Program, s: int, values: dict[str, Any],
                   wanted: list[DescriptorInfo]) -> Any:
        scene = self.scene
        if scene is None or s != 1 or s not in prog.scene_sets:
            return None
        lights = values.get("lights")
        for cam in ("main", "sun"):
            if values.get("camera") == scene.camera_range(cam) and \
                    lights in (None, scene.lights_range):
                return scene.camera_sets[cam]
        return None

    def _payload(self, prog: Program, d: DescriptorInfo, value: Any) -> tuple | list:
        ex, kind = self.executor, d.kind
        what = f"pass '{self.pass_.name}': binding '{d.name}' of {prog.name} is a {kind}"
        if isinstance(value, list):
            # an array binding: one payload per element, the last repeated to fill it
            if not value:
                raise ShaderError(f"{what} array, but the pass gives no element")
            items = [self._payload(prog, replace(d, count=1), v) for v in value]
            return (items + items[-1:] * d.count)[:d.count]
        if kind == "acceleration_structure":
            handle = getattr(getattr(value, "tlas", value), "handle", None)
            if handle is None:
                raise ShaderError(f"{what}, but the pass gives {type(value).__name__} (give "
                                  "ctx.accel(slot), a SceneAccel or its tlas)")
            return (handle,)
        if kind in ("uniform_buffer", "storage_buffer"):
            if kind == "uniform_buffer" and isinstance(value, Settings):
                r = ex.ring.push(value.pack())
            elif kind == "uniform_buffer" and isinstance(value, bytes | bytearray | np.ndarray):
                data = value.tobytes() if isinstance(value, np.ndarray) else bytes(value)
                r = ex.ring.push(data)
            elif isinstance(value, BufferRange):
                r = value
            elif isinstance(value, Buffer):
                r = BufferRange(value.handle, 0, value.bytes)
            else:
                raise ShaderError(f"{what}, but the pass gives {type(value).__name__}")
            return (r.buffer, r.offset, r.size)
        if kind == "sampler":
            if not isinstance(value, Sampler):
                raise ShaderError(f"{what}, but the pass gives {type(value).__name__}")
            return (value.handle,)
        sampler = None
        if kind == "combined_image_sampler":
            if not (isinstance(value, tuple) and len(value) == 2
                    and isinstance(value[1], Sampler)):
                raise ShaderError(f"{what}: give (image, sampler), not "
                                  f"{type(value).__name__}")
            value, sampler = value
        if isinstance(value, ImageBinding):
            state = ex.state_in(self.pass_.name, value.resource)
            if state is None or state.layout is None:
                raise ShaderError(f"{what}, but '{value.resource}' is not a resource of "
                                  "this pass in the plan")
            layout = state.layout
            if kind == "storage_image" and layout != "GENERAL":
                raise ShaderError(f"{what}, but the plan has '{value.resource}' in {layout} "
                                  "in this pass (declare the slot as a storage output)")
            view, resource = value.view, value.resource
        elif isinstance(value, ImageView):
            layout = "GENERAL" if kind == "storage_image" else "SHADER_READ_ONLY_OPTIMAL"
            view, resource = value, value.image.label
        else:
            raise ShaderError(f"{what}, but the pass gives {type(value).__name__}")
        if kind == "storage_image":
            _check_storage_format(what, d, view, resource)
        payload = (view.handle, image_layout(layout))
        return (*payload, sampler.handle) if sampler is not None else payload

    def dispatch(self, *, threads: tuple[int, ...], shader: str | None = None,
                 entry: str = "main", defines: dict[str, object] | None = None,
                 push_constants: bytes | None = None, **bindings: Any) -> None:
        """Run a compute shader over ``threads`` (rounded up to whole workgroups)."""
        prog = self.program("compute", shader=shader, defines=defines)
        self._check_extra(prog, bindings)
        values = {**self.executor.scene_bindings(), **bindings}
        pipe = self.executor.programs.compute_pipeline(prog)
        point = const("VK_PIPELINE_BIND_POINT_COMPUTE")
        vk.vkCmdBindPipeline(self.cmd, point, pipe.handle)
        self.bind(prog, values, point)
        self._push(prog, push_constants)
        # a pass's dispatches run in order, as on wgpu: each sees the shader writes of the
        # ones before it (the plan's barriers only order passes)
        if self._dispatched:
            barrier(self.cmd, memory_barriers=[(_SHADER_WRITE, _SHADER_RW)])
        self._dispatched = True
        t = (*threads, 1, 1)[:3]
        vk.vkCmdDispatch(self.cmd, *(max(1, math.ceil(t[i] / prog.local_size[i]))
                                     for i in range(3)))

    def trace_rays(self, *, size: tuple[int, ...], shader: str | None = None,
                   miss: str | None = None, closest_hit: str | None = None,
                   any_hit: str | None = None, defines: dict[str, object] | None = None,
                   max_recursion: int = 1, push_constants: bytes | None = None,
                   **bindings: Any) -> None:
        """``vkCmdTraceRaysKHR`` over ``size`` launches: ``shader`` (default: the pass's) is
        the raygen shader, ``miss``/``closest_hit``/``any_hit`` the files of the other
        stages beside it; bindings as for ``dispatch`` (scene camera and lights by name)."""
        raygen = shader or self.pass_.shader
        names = [raygen, *(n for n in (miss, closest_hit, any_hit) if n)]
        paths = [twin_paths(self.pass_, n, "compute")[0] for n in names]
        prog = self.executor.programs.get(self.pass_, paths, defines or {}, "ray_tracing")
        self._check_extra(prog, bindings)
        values = {**self.executor.scene_bindings(), **bindings}
        pipe = self.executor.programs.ray_pipeline(prog, max_recursion=max_recursion)
        point = const("VK_PIPELINE_BIND_POINT_RAY_TRACING_KHR")
        vk.vkCmdBindPipeline(self.cmd, point, pipe.handle)
        self.bind(prog, values, point)
        self._push(prog, push_constants)
        pipe.sbt.trace(self.cmd, *(*size, 1, 1)[:3])

    def _push(self, prog: Program, data: bytes | None) -> None:
        if data is None:
            return
        if len(data) > prog.push_size:
            raise ShaderError(f"pass '{self.pass_.name}': {len(data)} bytes of push constants, "
                              f"{prog.name} declares {prog.push_size}")
        buf = ffi.new("char[]", bytes(data))
        lib.vkCmdPushConstants(self.cmd, prog.pipeline_layout.handle, prog.stage_flags, 0,
                               len(data), buf)

    def draw_scene(self, *, color: Sequence[tuple[str, Any]] = (),
                   depth: tuple[str, Any] | None = None, shader: str | None = None,
                   defines: dict[str, object] | None = None, depth_compare: str = "less",
                   depth_write: bool = True, cull: str = "back", camera: str = "main",
                   blend: dict | None = None, alpha: tuple[str, ...] = ("OPAQUE", "MASK"),
                   push_constants: bytes | None = None, **bindings: Any) -> int:
        """Draw the scene's instances into ``color`` targets (and ``depth``) with dynamic
        rendering; set 0 takes ``bindings``, sets 1-3 are the scene's. Returns the draws."""
        if self.scene is None:
            raise ShaderError(f"pass '{self.pass_.name}' draws the scene, but none is loaded")
        ex = self.executor
        prog = self.program("render", shader=shader, defines=defines)
        self._check_extra(prog, {**bindings, "camera": 0, "lights": 0})
        colors = [(self.resource(slot), clear) for slot, clear in color]
        targets = [ex.image(r) for r, _ in colors]
        dimage = ex.image(self.resource(depth[0])) if depth is not None else None
        first = (targets or [dimage])[0]
        if first is None:
            raise ShaderError(f"pass '{self.pass_.name}': draw_scene needs a color or depth "
                              "target")
        dinfo = dimage.info if dimage is not None else None
        pipe = ex.programs.graphics_pipeline(
            prog, colors=[t.vk_format for t in targets],
            depth=dimage.vk_format if dimage is not None else None,
            stencil=bool(dinfo and dinfo.stencil), samples=first.samples,
            depth_compare=depth_compare, depth_write=depth_write, cull=cull, blend=blend)
        point = const("VK_PIPELINE_BIND_POINT_GRAPHICS")
        own = [s for s in prog.sets() if s not in prog.scene_sets]
        self._begin_rendering(colors, depth, depth_write, (first.width, first.height))
        try:
            vk.vkCmdBindPipeline(self.cmd, point, pipe.handle)
            vp = ffi.new("VkViewport*")
            vp.width, vp.height, vp.maxDepth = float(first.width), float(first.height), 1.0
            sc = ffi.new("VkRect2D*")
            sc.extent.width, sc.extent.height = first.width, first.height
            lib.vkCmdSetViewport(self.cmd, 0, 1, vp)
            lib.vkCmdSetScissor(self.cmd, 0, 1, sc)
            self.bind(prog, bindings, point, own)
            self._push(prog, push_constants)
            return self.scene.draw(self.cmd, prog.pipeline_layout.handle, camera=camera,
                                   alpha=alpha)
        finally:
            vk.vkCmdEndRendering(self.cmd)

    def _begin_rendering(self, colors: list[tuple[str, Any]], depth: tuple[str, Any] | None,
                         depth_write: bool, extent: tuple[int, int]) -> None:
        ex = self.executor
        atts = new("VkRenderingAttachmentInfo", len(colors))
        for i, (name, clear) in enumerate(colors):
            layout = self._attachment_layout(name)
            if layout not in _COLOR_ATTACHMENT_LAYOUTS:
                raise ShaderError(f"pass '{self.pass_.name}': '{name}' is a color target, but "
                                  f"the plan has it in {layout} (declare an Attachment slot)")
            a = atts[i]
            a.imageView = ex.view(name).handle
            a.imageLayout = image_layout(layout)
            a.loadOp = const("VK_ATTACHMENT_LOAD_OP_LOAD" if clear is None
                             else "VK_ATTACHMENT_LOAD_OP_CLEAR")
            a.storeOp = const("VK_ATTACHMENT_STORE_OP_STORE")
            if clear is not None:
                kind = format_info(ex.plan.resource(name).format).kind
                values = (*tuple(clear), 0, 0, 0, 0)[:4]
                for k in range(4):
                    if kind == "uint":
                        a.clearValue.color.uint32[k] = int(values[k])
                    elif kind == "sint":
                        a.clearValue.color.int32[k] = int(values[k])
                    else:
                        a.clearValue.color.float32[k] = float(values[k])
        info = new("VkRenderingInfo", layerCount=1, colorAttachmentCount=len(colors),
                   pColorAttachments=atts)
        info.renderArea.extent.width, info.renderArea.extent.height = extent
        keep = [atts]
        if depth is not None:
            name, clear = self.resource(depth[0]), depth[1]
            layout = self._attachment_layout(name)
            read_only = "READ_ONLY" in layout
            d = new("VkRenderingAttachmentInfo", imageView=ex.view(name).handle,
                    imageLayout=image_layout(layout))
            if read_only or (not depth_write and clear is None):
                d.loadOp = const("VK_ATTACHMENT_LOAD_OP_LOAD")
                d.storeOp = const("VK_ATTACHMENT_STORE_OP_NONE" if read_only
                                  else "VK_ATTACHMENT_STORE_OP_STORE")
            else:
                d.loadOp = const("VK_ATTACHMENT_LOAD_OP_LOAD" if clear is None
                                 else "VK_ATTACHMENT_LOAD_OP_CLEAR")
                d.storeOp = const("VK_ATTACHMENT_STORE_OP_STORE")
                d.clearValue.depthStencil.depth = float(clear or 0.0)
            info.pDepthAttachment = d
            if format_info(ex.plan.resource(name).format).stencil:
                info.pStencilAttachment = d
            keep.append(d)
        vk.vkCmdBeginRendering(self.cmd, info)

    def _attachment_layout(self, name: str) -> str:
        state = self.executor.state_in(self.pass_.name, name)
        if state is None or state.layout is None:
            raise ShaderError(f"pass '{self.pass_.name}': '{name}' is not a resource of this "
                              "pass in the plan")
        return state.layout


# ---------------------------------------------------------------------------------------------
# the executor


class VkExecutor(FrameExecutor):
    """Owns the images and buffers of one compiled graph on one device and records frames."""

    def __init__(self, device: VkDevice, plan: CompiledGraph, passes: dict[str, Pass],
                 slots: dict[str, dict[str, str]], scene: VkScene | None = None,
                 readback: tuple[str, ...] = (), *, alias: bool = True,
                 memory_info: dict[str, Any] | None = None):
        self.device, self.plan, self.passes, self.slots = device, plan, passes, slots
        self.scene = scene
        self.readback = tuple(readback)
        self.alias = alias
        self.memory_info = dict(memory_info or {})
        self.frame_index = 0
        self.timings = {name: PassTiming(name) for name in plan.order}
        check_passes(plan, passes)
        self._states: dict[tuple[str, str], State] = {}
        self._final: dict[str, State] = {}
        self._start: dict[str, str] = {}
        self._barriers: dict[str, list] = defaultdict(list)
        for b in plan.barriers:
            self._barriers[b.pass_name].append(b)
        for p in plan.order:
            for a in plan.accesses[p]:
                if a.state is None:
                    continue
                self._states[(p, a.resource)] = a.state
                self._final[a.resource] = a.state
                if a.resource not in self._start:
                    first = next((b for b in self._barriers[p] if b.resource == a.resource),
                                 None)
                    self._start[a.resource] = (first.src if first else a.state).layout or \
                        "UNDEFINED"
        self._history = [(copy, name) for copy, name in
                         ((r.name, r.name.removesuffix("@prev")) for r in plan.resources
                          if r.history and r.name.endswith("@prev"))]
        self._views: dict[tuple[int, bool, int | None], ImageView] = {}
        # acceleration structures by plan resource, published by the passes that build them
        self.accels: dict[str, Any] = {}
        self.transients = None
        self.allocator: BlockAllocator | None = None
        self.programs = self.descriptors = self.ring = None
        self.pool: CommandPool | None = None
        self.timestamps: TimestampPool | None = None
        self._pin_begin = False
        try:
            self._allocate()
            self.pool = CommandPool(device, transient=False, label="rfw:frames")
            self.cmd = self.pool.allocate(1)[0]
            if "timestamp" in device.caps:
                # llvmpipe resolves a timestamp when its binned scene is flushed, i.e. at the
                # next timestamp write: one scratch write per pass pins the begin before the
                # pass's work (without it compute passes read ~0 ms)
                self._pin_begin = device.driver_name == "llvmpipe"
                n = len(plan.order)
                self.timestamps = TimestampPool(device, max(2, (3 if self._pin_begin else 2) * n),
                                                label="rfw:timestamps")
            self.programs = Programs(device, scene)
            self.descriptors = FrameDescriptors(device)
            self.ring = UniformRing(self.allocator,
                                    int(device.limits["minUniformBufferOffsetAlignment"]))
            for p in passes.values():
                p.setup(self)
        except BaseException:
            self.destroy()
            raise

    # setup --------------------------------------------------------------------------------
    def _allocate(self) -> None:
        dev, plan = self.device, self.plan
        self.transients = plan_heaps(plan, dev, no_alias=not self.alias,
                                     readback=bool(self.readback))
        self.images: dict[str, Image] = dict(self.transients.images)
        self.buffers: dict[str, Buffer] = dict(self.transients.buffers)
        self.allocator = BlockAllocator(dev, block_size=8 * MiB, label="rfw:persistent")
        persistent = []
        for r in plan.resources:
            if r.transient:
                continue
            if r.kind == "image":
                if not r.format:
                    continue  # an undescribed external image: the application binds its own
                usages = set(r.usages) | {"transfer_dst"} | \
                    ({"transfer_src"} if self.readback else set())
                self.images[r.name] = self.allocator.create_image(
                    r.width, r.height, r.format, usages, mips=r.mips, layers=r.layers,
                    samples=r.samples, label=r.name)
                persistent.append(r.name)
            elif r.raw_bytes > 0:
                usages = (set(r.usages) & {"storage", "uniform", "indirect", "vertex", "index"}
                          or {"storage"}) | {"transfer_src", "transfer_dst"}
                self.buffers[r.name] = self.allocator.create_buffer(r.raw_bytes, usages,
                                                                    label=r.name)
        self._initial_states(persistent)

    def _initial_states(self, names: list[str]) -> None:
        """Persistent images enter the first frame in the layout the plan's steady state
        leaves them in (the ``from`` of their first barrier), cleared to zero like wgpu's."""
        todo = [n for n in names if self._start.get(n, "UNDEFINED") != "UNDEFINED"]
        if not todo:
            return
        dst = State("TRANSFER_DST_OPTIMAL", frozenset({"CLEAR"}), frozenset({"TRANSFER_WRITE"}))
        with one_time(self.device, label="rfw:initial states") as cmd:
            barrier(cmd, [ImageBarrier(self.images[n], "UNDEFINED", dst) for n in todo])
            for n in todo:
                img = self.images[n]
                rng = ffi.new("VkImageSubresourceRange*")
                rng.aspectMask, rng.levelCount, rng.layerCount = img.aspect, img.mips, img.layers
                if img.info.depth or img.info.stencil:
                    value = ffi.new("VkClearDepthStencilValue*")
                    lib.vkCmdClearDepthStencilImage(cmd, img.handle, image_layout(dst.layout),
                                                    value, 1, rng)
                else:
                    value = ffi.new("VkClearColorValue*")
                    lib.vkCmdClearColorImage(cmd, img.handle, image_layout(dst.layout), value,
                                             1, rng)
            barrier(cmd, [ImageBarrier(self.images[n], dst, as_state(self._start[n],
                                                                      source=False))
                          for n in todo])

    # resources ----------------------------------------------------------------------------
    def image(self, resource: str) -> Image:
        try:
            return self.images[resource]
        except KeyError:
            raise ShaderError(f"'{resource}' is not an image of the plan") from None

    def buffer(self, resource: str) -> Buffer:
        try:
            return self.buffers[resource]
        except KeyError:
            raise ShaderError(f"'{resource}' is not a buffer of the plan") from None

    def view(self, resource: str, *, sampled: bool = False, mip: int | None = None) -> ImageView:
        """The image's view; ``sampled`` views of depth(-stencil) images see depth only;
        ``mip``: a view of that one mip level (per-level storage views of a mip chain)."""
        img = self.image(resource)
        depth = sampled and bool(img.info.depth)
        key = (id(img), depth, mip)
        v = self._views.get(key)
        if v is None or v.handle is None:
            name = ("depth" if depth else "view") + ("" if mip is None else f":mip{mip}")
            v = self._views[key] = image_view(img, aspect="depth" if depth else None,
                                              mips=None if mip is None else (mip, 1),
                                              label=f"{resource}:{name}")
        return v

    @property
    def resources(self) -> dict[str, Any]:
        """Images and buffers by plan name; acceleration structures map to ``GLOBAL``
        (their barriers are memory barriers)."""
        accels = {r.name: GLOBAL for r in self.plan.resources if r.kind == "accel"}
        return {**self.images, **self.buffers, **accels}

    def state_in(self, pass_name: str, resource: str) -> State | None:
        """The state the plan puts ``resource`` in for ``pass_name``."""
        return self._states.get((pass_name, resource))

    def scene_bindings(self) -> dict[str, Any]:
        return self.scene.bindings() if self.scene is not None else {}

    def memory(self) -> dict[str, Any]:
        """Transient bytes allocated against the plan's numbers."""
        tm = self.transients
        out = {"transient_allocated_bytes": tm.allocated_bytes if tm else 0,
               "plan_transient_bytes": self.plan.transient_bytes,
               "unaliased_bytes": self.plan.unaliased_bytes, "alias": self.alias,
               "allocations": len(tm.memories) if tm else 0}
        out.update({k: v for k, v in self.memory_info.items() if k != "alias"})
        return out

    # frames -------------------------------------------------------------------------------
    # a frame driven pass by pass (mixed-backend frames: vkext.mixed) ----------------------
    def begin_frame(self) -> None:
        """Start a frame: ``record`` passes into it, ``flush`` to submit what was recorded
        and wait, ``end_frame`` to finish. Descriptors and uniforms live until the next
        ``begin_frame``."""
        dev, ts = self.device, self.timestamps
        if self.frame_index:  # ping-pong: last frame's value is this frame's @prev
            for copy, name in self._history:
                if copy in self.images and name in self.images:
                    self.images[copy], self.images[name] = self.images[name], self.images[copy]
        self.descriptors.reset()
        self.ring.reset()
        self.pool.reset()
        if ts is not None and "host_query_reset" in dev.caps:
            ts.reset()
        self._recording = False
        self._cpu: dict[str, float] = {}
        self._gpu: dict[str, float] = {}
        self._pending: list[int] = []  # timestamp slots written since the last flush
        self._recorded: list[str] = []
        self._position = {name: k for k, name in enumerate(self.plan.order)}

    def record(self, name: str) -> None:
        """Record pass ``name``: its debug label, the plan's barriers for it, a timestamp
        before and after, and ``record(ctx)``. A pass without an instance (a bridge's side
        on this device) records its barriers only: the copy itself goes through the host
        (``vkext.mixed``), between flushes."""
        dev, cmd, ts = self.device, self.cmd, self.timestamps
        if not self._recording:
            vk.vkBeginCommandBuffer(cmd, vk.VkCommandBufferBeginInfo(
                flags=vk.VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT))
            self._recording = True
            if ts is not None and "host_query_reset" not in dev.caps:
                ts.reset(cmd)
        k = self._position[name]
        p = self.passes.get(name)
        try:
            with label(dev, cmd, name):
                record_barriers(cmd, self._barriers[name], self.resources)
                if p is None:
                    return
                if ts is not None:
                    ts.write(cmd, TIMESTAMP_STAGE, 2 * k)
                    if self._pin_begin:
                        ts.write(cmd, TIMESTAMP_STAGE, 2 * len(self.plan.order) + k)
                ctx = VkPassContext(self, p, cmd, self.slots[name])
                t = time.perf_counter()
                with naming(f"pass '{name}'"):
                    p.record(ctx)
                self._cpu[name] = self._cpu.get(name, 0.0) + (time.perf_counter() - t) * 1e3
                if ts is not None:
                    ts.write(cmd, TIMESTAMP_STAGE, 2 * k + 1)
                    self._pending.append(k)
                self._recorded.append(name)
        except BaseException:
            self._recording = False
            self.pool.reset()  # drop the half-recorded commands
            raise

    def flush(self) -> None:
        """Submit what was recorded since the last flush, wait for it and collect its
        timestamps. Nothing recorded: nothing happens."""
        if not self._recording:
            return
        dev, cmd, ts = self.device, self.cmd, self.timestamps
        self._recording = False
        try:
            vk.vkEndCommandBuffer(cmd)
        except BaseException:
            self.pool.reset()
            raise
        submit(dev, [cmd])
        if ts is not None and self._pending:
            order = self.plan.order
            for first, count in _runs(sorted(self._pending)):
                ns = ts.results(2 * first, 2 * count)
                for i in range(count):
                    name = order[first + i]
                    ms = max(0, ns[2 * i + 1] - ns[2 * i]) * 1e-6
                    self._gpu[name] = self._gpu.get(name, 0.0) + ms
        self._pending = []

    def end_frame(self) -> None:
        """Flush what is left and append the frame's timings of the passes recorded."""
        self.flush()
        for name in dict.fromkeys(self._recorded):
            self.timings[name].cpu_ms.append(self._cpu[name])
            if self.timestamps is not None:
                self.timings[name].gpu_ms.append(self._gpu[name])
        self.frame_index += 1

    def upload(self, resource: str, array: np.ndarray) -> None:
        """Fill an external image from an (H, W, C) array of its texel type; it stays in the
        layout the plan expects at the start of a frame."""
        start = self._start.get(resource, "UNDEFINED")
        after = start if start != "UNDEFINED" else "SHADER_READ_ONLY_OPTIMAL"
        upload_image(self.device, self.image(resource), array, layout_after=after,
                     layout_before=start)

    def read(self, resource: str) -> np.ndarray:
        """Read an image back as (H, W, C) in its own texel type (buffers as bytes), left in
        the state the frame leaves it in."""
        state = self._final.get(resource)
        if resource in self.buffers:
            return read_buffer(self.device, self.buffers[resource], state)
        img = self.image(resource)
        now = state or "UNDEFINED"
        return read_image(self.device, img, layout_now=now,
                          layout_after=state if state is not None else None)

    def destroy(self) -> None:
        """Destroy every Vulkan object the executor made (safe to call twice)."""
        if self.device.alive:
            self.device.wait_idle()
        for obj in (self.programs, self.descriptors, self.timestamps, self.pool,
                    self.transients, self.allocator):
            if obj is not None:
                obj.destroy()
        for v in self._views.values():
            v.destroy()
        self._views.clear()
        self.programs = self.descriptors = self.timestamps = self.pool = None
        self.transients = self.allocator = None
        self.ring = None
