"""Ray-tracing building blocks: reflected layouts, pipelines and the shader binding table.

What a ray-traced pass needs besides acceleration structures (:mod:`vkext.accel`):

- :class:`ReflectedLayout`: descriptor set layouts and the pipeline layout that a group of
  shader stages declares, read from their SPIR-V (never hand-written), acceleration
  structures included; bindings used by several stages get all their stage bits.
- :class:`BindingSet`: one pool and set per layout set, written by binding *name*; a missing
  or unknown name raises, naming the binding and the shaders.
- :class:`ComputePipeline`: a compute shader (ray queries run in one).
- :class:`RayTracingPipeline`: raygen, miss shaders and triangle hit groups (closest hit,
  optional any hit); groups are numbered raygen, misses, hit groups, in that order.
- :class:`ShaderBindingTable`: the group handles (``vkGetRayTracingShaderGroupHandlesKHR``)
  laid out by the device's ``shaderGroupHandleSize``, ``shaderGroupHandleAlignment`` and
  ``shaderGroupBaseAlignment``, with optional per-record data, and ``trace()``.

Shaders compile through :func:`vkext.spirv.compile_glsl` (cached by content).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rfw.graph.sync import State
from rfw.units import align_up

from .accel import AccelerationStructure
from .commands import upload_buffer
from .consts import const, ffi, lib, vk
from .device import VkDevice
from .memory import Buffer
from .scene import DESCRIPTOR_TYPES, VkObject, new
from .spirv import DescriptorInfo, Reflection, compile_glsl, reflect

# reflect()'s stage names -> shader stage bits
STAGE_BITS = {
    "comp": "VK_SHADER_STAGE_COMPUTE_BIT", "rgen": "VK_SHADER_STAGE_RAYGEN_BIT_KHR",
    "rmiss": "VK_SHADER_STAGE_MISS_BIT_KHR", "rchit": "VK_SHADER_STAGE_CLOSEST_HIT_BIT_KHR",
    "rahit": "VK_SHADER_STAGE_ANY_HIT_BIT_KHR", "rint": "VK_SHADER_STAGE_INTERSECTION_BIT_KHR",
    "rcall": "VK_SHADER_STAGE_CALLABLE_BIT_KHR",
}
# the scene's descriptor kinds, and the one ray tracing adds
KINDS = {**DESCRIPTOR_TYPES,
         "acceleration_structure": "VK_DESCRIPTOR_TYPE_ACCELERATION_STRUCTURE_KHR"}
# who reads a shader binding table
SBT_READ = State(None, frozenset({"RAY_TRACING_SHADER_KHR"}),
                 frozenset({"SHADER_BINDING_TABLE_READ_KHR"}))


class ShaderModule(VkObject):
    """A compiled GLSL file (``name.<stage>.glsl``) and its reflection."""

    destroy_fn, object_type = "vkDestroyShaderModule", "SHADER_MODULE"

    def __init__(self, device: VkDevice, path: str | Path,
                 defines: Mapping[str, object] | None = None, *, label: str = ""):
        spv = compile_glsl(path, dict(defines or {}))
        self.path, self.spirv = Path(path), spv
        self.reflection: Reflection = reflect(spv.code)
        self.stage = self.reflection.stage
        if self.stage not in STAGE_BITS:
            raise ValueError(f"{path}: stage '{self.stage}' is not a compute or ray-tracing "
                             "stage")
        self.stage_bit = const(STAGE_BITS[self.stage])
        words = ffi.new("uint32_t[]", len(spv.code) // 4)
        ffi.memmove(words, spv.code, len(spv.code))
        info = new("VkShaderModuleCreateInfo", codeSize=len(spv.code), pCode=words)
        super().__init__(device, vk.vkCreateShaderModule(device.device, info, None),
                         label or self.path.name)


class _SetLayout(VkObject):
    destroy_fn, object_type = "vkDestroyDescriptorSetLayout", "DESCRIPTOR_SET_LAYOUT"


class _PipelineLayout(VkObject):
    destroy_fn, object_type = "vkDestroyPipelineLayout", "PIPELINE_LAYOUT"


class ReflectedLayout:
    """The descriptor set layouts and pipeline layout of some shader stages, from SPIR-V.

    ``descriptors`` maps binding names to :class:`DescriptorInfo`; ``stages`` maps them to
    the stage bits of the shaders that use them; ``push_size`` is the largest push-constant
    block (visible to every stage of the group)."""

    def __init__(self, device: VkDevice, modules: Sequence[ShaderModule], *, label: str = ""):
        self.device, self.label = device, label
        self.files = ", ".join(sorted({m.path.name for m in modules}))
        self.descriptors: dict[str, DescriptorInfo] = {}
        self.stages: dict[str, int] = {}
        by_slot: dict[tuple[int, int], str] = {}
        for m in modules:
            for d in m.reflection.descriptors.values():
                other = by_slot.get((d.set, d.binding))
                if other is not None and (other != d.name
                                          or self.descriptors[other].kind != d.kind):
                    o = self.descriptors[other]
                    raise ValueError(f"{label}: set {d.set} binding {d.binding} is '{o.name}' "
                                     f"({o.kind}) in one shader and '{d.name}' ({d.kind}) in "
                                     f"{m.path.name}")
                by_slot[(d.set, d.binding)] = d.name
                self.descriptors.setdefault(d.name, d)
                self.stages[d.name] = self.stages.get(d.name, 0) | m.stage_bit
        self.push_size = max((m.reflection.push_constant_size for m in modules), default=0)
        self.push_stages = 0
        for m in modules:
            self.push_stages |= m.stage_bit
        self.set_layouts: list[_SetLayout] = []
        try:
            count = max((d.set + 1 for d in self.descriptors.values()), default=0)
            for s in range(count):  # a set no shader uses still needs a (empty) layout
                entries = sorted((d for d in self.descriptors.values() if d.set == s),
                                 key=lambda d: d.binding)
                arr = ffi.new("VkDescriptorSetLayoutBinding[]", max(1, len(entries)))
                for i, d in enumerate(entries):
                    arr[i].binding, arr[i].descriptorCount = d.binding, max(1, d.count)
                    arr[i].descriptorType = const(KINDS[d.kind])
                    arr[i].stageFlags = self.stages[d.name]
                info = new("VkDescriptorSetLayoutCreateInfo", bindingCount=len(entries),
                           pBindings=arr)
                self.set_layouts.append(_SetLayout(
                    device, vk.vkCreateDescriptorSetLayout(device.device, info, None),
                    f"{label}:set{s}"))
            handles = ffi.new("VkDescriptorSetLayout[]", [s.handle for s in self.set_layouts]
                              or [ffi.NULL])
            info = new("VkPipelineLayoutCreateInfo", setLayoutCount=len(self.set_layouts),
                       pSetLayouts=handles)
            if self.push_size:
                rng = ffi.new("VkPushConstantRange*")
                rng.stageFlags, rng.offset, rng.size = self.push_stages, 0, self.push_size
                info.pushConstantRangeCount, info.pPushConstantRanges = 1, rng
            self.pipeline_layout = _PipelineLayout(
                device, vk.vkCreatePipelineLayout(device.device, info, None), f"{label}:layout")
        except BaseException:
            self.destroy()
            raise

    @property
    def handle(self) -> Any:
        return self.pipeline_layout.handle

    def destroy(self) -> None:
        if getattr(self, "pipeline_layout", None) is not None:
            self.pipeline_layout.destroy()
            self.pipeline_layout = None
        for s in self.set_layouts:
            s.destroy()
        self.set_layouts = []


class _Pool(VkObject):
    destroy_fn, object_type = "vkDestroyDescriptorPool", "DESCRIPTOR_POOL"


class BindingSet:
    """A descriptor set for each set of a :class:`ReflectedLayout`, written by name.

    ``write(tlas=accel.tlas, rays=buffer, hits=(buffer, offset, size))``: acceleration
    structures, buffers (whole) or (buffer, offset, size) ranges. Every binding of the
    layout must be written before :meth:`bind`."""

    def __init__(self, layout: ReflectedLayout, *, label: str = ""):
        self.layout, self.device = layout, layout.device
        counts: dict[str, int] = {}
        for d in layout.descriptors.values():
            counts[d.kind] = counts.get(d.kind, 0) + max(1, d.count)
        sizes = ffi.new("VkDescriptorPoolSize[]", max(1, len(counts)))
        for i, (kind, n) in enumerate(counts.items()):
            sizes[i].type, sizes[i].descriptorCount = const(KINDS[kind]), n
        n_sets = max(1, len(layout.set_layouts))
        info = new("VkDescriptorPoolCreateInfo", maxSets=n_sets, poolSizeCount=len(counts),
                   pPoolSizes=sizes)
        self.pool = _Pool(self.device, vk.vkCreateDescriptorPool(self.device.device, info, None),
                          label or f"{layout.label}:descriptors")
        self.sets = None
        if layout.set_layouts:
            handles = ffi.new("VkDescriptorSetLayout[]", [s.handle for s in layout.set_layouts])
            alloc = new("VkDescriptorSetAllocateInfo", descriptorPool=self.pool.handle,
                        descriptorSetCount=len(layout.set_layouts), pSetLayouts=handles)
            self.sets = vk.vkAllocateDescriptorSets(self.device.device, alloc)
        self.written: set[str] = set()

    def write(self, **resources: Any) -> None:
        layout = self.layout
        unknown = sorted(set(resources) - set(layout.descriptors))
        if unknown:
            raise ValueError(f"{layout.label}: no binding named {', '.join(unknown)} in "
                             f"{layout.files} (it has: {', '.join(sorted(layout.descriptors))})")
        writes = new("VkWriteDescriptorSet", len(resources))
        keep = []
        for i, (name, res) in enumerate(resources.items()):
            d = layout.descriptors[name]
            w = writes[i]
            w.dstSet, w.dstBinding, w.descriptorCount = self.sets[d.set], d.binding, 1
            w.descriptorType = const(KINDS[d.kind])
            if d.kind == "acceleration_structure":
                if not isinstance(res, AccelerationStructure):
                    raise ValueError(f"{layout.label}: binding '{name}' takes an "
                                     f"acceleration structure, not {type(res).__name__}")
                handles = ffi.new("VkAccelerationStructureKHR[1]", [res.handle])
                ext = new("VkWriteDescriptorSetAccelerationStructureKHR",
                          accelerationStructureCount=1, pAccelerationStructures=handles)
                w.pNext = ext
                keep += [handles, ext]
            elif d.kind in ("storage_buffer", "uniform_buffer"):
                buf, offset, size = (res, 0, res.bytes) if isinstance(res, Buffer) else res
                info = ffi.new("VkDescriptorBufferInfo*")
                info.buffer = buf.handle if isinstance(buf, Buffer) else buf
                info.offset, info.range = offset, size
                w.pBufferInfo = info
                keep.append(info)
            else:
                raise ValueError(f"{layout.label}: binding '{name}' is a {d.kind}, which "
                                 "BindingSet does not write (yet)")
        vk.vkUpdateDescriptorSets(self.device.device, len(resources), writes, 0, ffi.NULL)
        self.written |= set(resources)

    def bind(self, cmd: Any, bind_point: int) -> None:
        missing = sorted(set(self.layout.descriptors) - self.written)
        if missing:
            raise ValueError(f"{self.layout.label}: binding(s) {', '.join(missing)} of "
                             f"{self.layout.files} were never written")
        if self.sets is not None:
            lib.vkCmdBindDescriptorSets(cmd, bind_point, self.layout.handle, 0,
                                        len(self.layout.set_layouts), self.sets, 0, ffi.NULL)

    def destroy(self) -> None:
        self.pool.destroy()  # frees the sets
        self.sets = None


class _Reflected:
    """A pipeline with a reflected layout of its own: both go together."""

    pipeline: Any
    layout: Any

    def destroy(self) -> None:
        if self.pipeline is not None:
            self.pipeline.destroy()
            self.pipeline = None
        if self.layout is not None:
            self.layout.destroy()
            self.layout = None


class _Pipeline(VkObject):
    destroy_fn, object_type = "vkDestroyPipeline", "PIPELINE"


class ComputePipeline(_Reflected):
    """One compute shader with its reflected layout (ray queries run in one)."""

    def __init__(self, device: VkDevice, path: str | Path,
                 defines: Mapping[str, object] | None = None, *, label: str = ""):
        self.device, self.label = device, label or Path(path).name
        self.bind_point = const("VK_PIPELINE_BIND_POINT_COMPUTE")
        module = ShaderModule(device, path, defines, label=f"{self.label}:module")
        self.layout = self.pipeline = None
        try:
            self.local_size = module.reflection.local_size
            self.layout = ReflectedLayout(device, [module], label=self.label)
            entry = ffi.new("char[]", b"main")
            info = new("VkComputePipelineCreateInfo", layout=self.layout.handle,
                       basePipelineIndex=-1)
            info.stage.sType = const("VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO")
            info.stage.stage, info.stage.module, info.stage.pName = \
                module.stage_bit, module.handle, entry
            handle = vk.vkCreateComputePipelines(device.device, ffi.NULL, 1, info, None)[0]
            self.pipeline = _Pipeline(device, handle, f"{self.label}:pipeline")
        except BaseException:
            self.destroy()
            raise
        finally:
            module.destroy()  # the pipeline keeps what it needs

    @property
    def handle(self) -> Any:
        return self.pipeline.handle

    def dispatch(self, cmd: Any, threads: int) -> None:
        """Bind and dispatch ``threads`` invocations along x (rounded up to whole groups)."""
        vk.vkCmdBindPipeline(cmd, self.bind_point, self.pipeline.handle)
        groups = -(-int(threads) // self.local_size[0])
        limit = self.device.limits["maxComputeWorkGroupCount"][0]
        if groups > limit:
            raise ValueError(f"{self.label}: {threads} threads need {groups} groups, more than "
                             f"maxComputeWorkGroupCount[0] = {limit}")
        vk.vkCmdDispatch(cmd, groups, 1, 1)


def check_recursion(device: VkDevice, max_recursion: int, label: str) -> None:
    """``max_recursion`` within 1..maxRayRecursionDepth of the device, else ValueError."""
    device.require("VK_KHR_ray_tracing_pipeline")
    limit = device.extension_properties["VK_KHR_ray_tracing_pipeline"]["maxRayRecursionDepth"]
    if not 1 <= max_recursion <= limit:
        raise ValueError(f"{label}: max recursion {max_recursion} is outside 1..{limit} "
                         f"({device.name})")


def create_ray_pipeline(device: VkDevice, stages: Sequence[tuple[int, Any]],
                        groups: Sequence[tuple[int, int, int, int]], max_recursion: int,
                        layout: Any) -> Any:
    """``vkCreateRayTracingPipelinesKHR`` of ``stages`` (stage bit, module handle) and
    ``groups`` (type, general, closest hit, any hit: stage indices or
    VK_SHADER_UNUSED_KHR); returns the pipeline handle."""
    entry = ffi.new("char[]", b"main")
    sinfo = new("VkPipelineShaderStageCreateInfo", len(stages))
    for i, (bit, module) in enumerate(stages):
        sinfo[i].stage, sinfo[i].module, sinfo[i].pName = bit, module, entry
    ginfo = new("VkRayTracingShaderGroupCreateInfoKHR", len(groups))
    for i, (kind, gen, closest, any_) in enumerate(groups):
        g = ginfo[i]
        g.type, g.generalShader, g.closestHitShader = kind, gen, closest
        g.anyHitShader, g.intersectionShader = any_, const("VK_SHADER_UNUSED_KHR")
    info = new("VkRayTracingPipelineCreateInfoKHR", stageCount=len(stages), pStages=sinfo,
               groupCount=len(groups), pGroups=ginfo, maxPipelineRayRecursionDepth=max_recursion,
               layout=layout, basePipelineIndex=-1)
    return device.fn.vkCreateRayTracingPipelinesKHR(device.device, ffi.NULL, ffi.NULL, 1, info,
                                                    ffi.NULL)[0]


def shader_group_handles(device: VkDevice, pipeline: Any, count: int) -> list[bytes]:
    """Each group's opaque handle (``shaderGroupHandleSize`` bytes), in group order."""
    size = device.extension_properties["VK_KHR_ray_tracing_pipeline"]["shaderGroupHandleSize"]
    data = ffi.new("char[]", size * count)
    device.fn.vkGetRayTracingShaderGroupHandlesKHR(device.device, pipeline, 0, count,
                                                   size * count, data)
    raw = bytes(ffi.buffer(data))
    return [raw[i * size:(i + 1) * size] for i in range(count)]


@dataclass(frozen=True)
class HitGroup:
    """A triangle hit group: a closest-hit shader and/or an any-hit shader."""

    closest: str | Path | None = None
    any: str | Path | None = None


class RayTracingPipeline(_Reflected):
    """A ray-tracing pipeline: one raygen shader, miss shaders, triangle hit groups.

    Shader groups are numbered raygen (0), misses (1..), hit groups (after the misses); a
    :class:`ShaderBindingTable` lays them out. ``max_recursion`` is the deepest
    ``traceRayEXT`` nesting (1: only raygen traces), checked against the device's limit."""

    def __init__(self, device: VkDevice, raygen: str | Path, miss: Sequence[str | Path] = (),
                 hit: Sequence[HitGroup] = (), *, defines: Mapping[str, object] | None = None,
                 max_recursion: int = 1, label: str = ""):
        self.device, self.label = device, label or Path(raygen).stem
        check_recursion(device, max_recursion, self.label)
        self.bind_point = const("VK_PIPELINE_BIND_POINT_RAY_TRACING_KHR")
        self.counts = {"raygen": 1, "miss": len(miss), "hit": len(hit)}
        self.layout = self.pipeline = None
        modules: dict[Path, ShaderModule] = {}
        unused = const("VK_SHADER_UNUSED_KHR")

        def stage(path: str | Path | None) -> int:
            if path is None:
                return unused
            p = Path(path).resolve()
            if p not in modules:
                modules[p] = ShaderModule(device, p, defines, label=f"{self.label}:{p.name}")
            return list(modules).index(p)

        try:
            general = const("VK_RAY_TRACING_SHADER_GROUP_TYPE_GENERAL_KHR")
            triangles = const("VK_RAY_TRACING_SHADER_GROUP_TYPE_TRIANGLES_HIT_GROUP_KHR")
            groups = [(general, stage(raygen), unused, unused)]
            groups += [(general, stage(m), unused, unused) for m in miss]
            for h in hit:
                if h.closest is None and h.any is None:
                    raise ValueError(f"{self.label}: a hit group needs a closest-hit or an "
                                     "any-hit shader")
                groups.append((triangles, unused, stage(h.closest), stage(h.any)))
            expected = {"rgen": [raygen], "rmiss": list(miss),
                        "rchit": [h.closest for h in hit if h.closest],
                        "rahit": [h.any for h in hit if h.any]}
            for kind, paths in expected.items():
                for p in paths:
                    m = modules[Path(p).resolve()]
                    if m.stage != kind:
                        raise ValueError(f"{self.label}: {m.path.name} is a {m.stage} shader, "
                                         f"used as {kind}")
            mods = list(modules.values())
            self.layout = ReflectedLayout(device, mods, label=self.label)
            handle = create_ray_pipeline(device, [(m.stage_bit, m.handle) for m in mods], groups,
                                         max_recursion, self.layout.handle)
            self.pipeline = _Pipeline(device, handle, f"{self.label}:pipeline")
            self.group_count = len(groups)
        except BaseException:
            self.destroy()
            raise
        finally:
            for m in modules.values():
                m.destroy()

    @property
    def handle(self) -> Any:
        return self.pipeline.handle

    def group_handles(self) -> list[bytes]:
        """Each group's opaque handle (``shaderGroupHandleSize`` bytes), in group order."""
        return shader_group_handles(self.device, self.pipeline.handle, self.group_count)


class ShaderBindingTable:
    """The records a ``vkCmdTraceRaysKHR`` reads: raygen, miss and hit regions.

    ``miss``/``hit`` list, per record, the index *within its kind* of the group it runs
    (default: each miss shader, each hit group once); a TLAS whose instances use SBT offsets
    up to ``n - 1`` needs ``n`` hit records (``SceneAccel.hit_records``), which may repeat a
    group. ``data`` maps (kind, record) to bytes placed after the handle (shaderRecordEXT).

    Layout rules (VkStridedDeviceAddressRegionKHR): every region starts at a multiple of
    ``shaderGroupBaseAlignment``; a stride is the handle plus data rounded up to
    ``shaderGroupHandleAlignment``; the raygen region's size equals its stride. The buffer is
    device-local and written once through a staging copy.
    """

    def __init__(self, pipeline: RayTracingPipeline, *, miss: Sequence[int] | None = None,
                 hit: Sequence[int] | None = None,
                 data: Mapping[tuple[str, int], bytes] | None = None, label: str = ""):
        dev = self.device = pipeline.device
        self.label = label or f"{pipeline.label}:sbt"
        props = dev.extension_properties["VK_KHR_ray_tracing_pipeline"]
        hsize, halign = props["shaderGroupHandleSize"], props["shaderGroupHandleAlignment"]
        balign = props["shaderGroupBaseAlignment"]
        n_miss, n_hit = pipeline.counts["miss"], pipeline.counts["hit"]
        miss = list(range(n_miss)) if miss is None else list(miss)
        hit = list(range(n_hit)) if hit is None else list(hit)
        for kind, recs, n in (("miss", miss, n_miss), ("hit", hit, n_hit)):
            bad = [r for r in recs if not 0 <= r < n]
            if bad:
                raise ValueError(f"{self.label}: {kind} record(s) name group(s) {bad}, the "
                                 f"pipeline has {n} {kind} group(s)")
        data = dict(data or {})
        extra = max((len(v) for v in data.values()), default=0)
        stride = align_up(hsize + extra, halign)
        if stride > props["maxShaderGroupStride"]:
            raise ValueError(f"{self.label}: record stride {stride} exceeds "
                             f"maxShaderGroupStride {props['maxShaderGroupStride']}")
        handles = pipeline.group_handles()
        # (kind, group of each record, stride, region size)
        raygen_stride = align_up(stride, balign)
        kinds = [("raygen", [0], raygen_stride, raygen_stride),
                 ("miss", [1 + m for m in miss], stride, align_up(len(miss) * stride, balign)),
                 ("hit", [1 + n_miss + h for h in hit], stride, align_up(len(hit) * stride,
                                                                         balign))]
        total = sum(size for *_, size in kinds)
        blob = np.zeros(total, np.uint8)
        self.offsets: dict[str, tuple[int, int, int]] = {}  # kind -> (offset, stride, size)
        offset = 0
        for kind, groups, kstride, size in kinds:
            for r, g in enumerate(groups):
                at = offset + r * kstride
                blob[at:at + hsize] = np.frombuffer(handles[g], np.uint8)
                payload = data.pop((kind, r), b"")
                blob[at + hsize:at + hsize + len(payload)] = np.frombuffer(payload, np.uint8)
            self.offsets[kind] = (offset, kstride, size if groups else 0)
            offset += size
        if data:
            raise ValueError(f"{self.label}: data for records that do not exist: "
                             f"{sorted(data)}")
        # room to move the start up to the base alignment: buffers promise less
        self.buffer = Buffer(dev, total + balign, ("shader_binding_table", "transfer_dst"),
                             label=self.label)
        try:
            self.buffer.allocate()
            base = align_up(self.buffer.address, balign)
            upload_buffer(dev, self.buffer, blob, SBT_READ, offset=base - self.buffer.address)
        except BaseException:
            self.buffer.destroy()
            raise
        self.regions = {}
        for kind, (off, kstride, size) in self.offsets.items():
            r = ffi.new("VkStridedDeviceAddressRegionKHR*")
            if size:
                r.deviceAddress, r.stride, r.size = base + off, kstride, size
            self.regions[kind] = r
        self.regions["callable"] = ffi.new("VkStridedDeviceAddressRegionKHR*")  # none

    def trace(self, cmd: Any, width: int, height: int = 1, depth: int = 1) -> None:
        """``vkCmdTraceRaysKHR`` over width x height x depth launches (the pipeline and its
        descriptor sets bound)."""
        r = self.regions
        self.device.fn.vkCmdTraceRaysKHR(cmd, r["raygen"], r["miss"], r["hit"], r["callable"],
                                         int(width), int(height), int(depth))

    def destroy(self) -> None:
        self.buffer.destroy()
