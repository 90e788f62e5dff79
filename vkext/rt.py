"""Ray tracing outside a frame graph: the pipelines of :mod:`vkext.raycast`, descriptor sets
written by name.

Programs, their reflected layouts and their pipelines come from the one cache every pass
uses (:class:`vkext.programs.Programs`); this module only gives them the shape a caller
without a pass context needs:

- :class:`ComputePipeline`: a compute shader (ray queries run in one);
- :class:`RayTracingPipeline`: raygen, a miss shader and a triangle hit group (closest hit,
  optional any hit); groups are numbered raygen, miss, hit group, in that order;
- :class:`BindingSet`: one pool and set per set of a program's layout, written by binding
  *name*; a missing or unknown name raises, naming the binding and the shaders.

Each owns a :class:`Programs` of its own (no scene: every set is reflected), destroyed with
it. Shader binding tables are :class:`vkext.sbt.ShaderBindingTable`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .accel import AccelerationStructure
from .buffers import Buffer
from .consts import const, ffi, lib, new, vk
from .device import VkDevice
from .objects import DESCRIPTOR_TYPES, VkObject
from .programs import Program, Programs


class _Pool(VkObject):
    destroy_fn, object_type = "vkDestroyDescriptorPool", "DESCRIPTOR_POOL"


class BindingSet:
    """A descriptor set for each set of a :class:`Program`'s layout, written by name.

    ``write(tlas=accel.tlas, rays=buffer, hits=(buffer, offset, size))``: acceleration
    structures, buffers (whole) or (buffer, offset, size) ranges. Every binding of the
    layout must be written before :meth:`bind`."""

    def __init__(self, layout: Program, *, label: str = ""):
        self.layout, self.device = layout, layout.device
        self.label = label or f"{layout.paths[0].name}:descriptors"
        self.files = ", ".join(sorted({p.name for p in layout.paths}))
        counts: dict[str, int] = {}
        for d in layout.descriptors.values():
            counts[d.kind] = counts.get(d.kind, 0) + max(1, d.count)
        sizes = ffi.new("VkDescriptorPoolSize[]", max(1, len(counts)))
        for i, (kind, n) in enumerate(counts.items()):
            sizes[i].type, sizes[i].descriptorCount = const(DESCRIPTOR_TYPES[kind]), n
        n_sets = max(1, len(layout.set_layouts))
        info = new("VkDescriptorPoolCreateInfo", maxSets=n_sets, poolSizeCount=len(counts),
                   pPoolSizes=sizes)
        self.pool = _Pool(self.device, vk.vkCreateDescriptorPool(self.device.device, info, None),
                          self.label)
        self.sets = None
        if layout.set_layouts:
            handles = ffi.new("VkDescriptorSetLayout[]", list(layout.set_layouts))
            alloc = new("VkDescriptorSetAllocateInfo", descriptorPool=self.pool.handle,
                        descriptorSetCount=len(layout.set_layouts), pSetLayouts=handles)
            self.sets = vk.vkAllocateDescriptorSets(self.device.device, alloc)
        self.written: set[str] = set()

    def write(self, **resources: Any) -> None:
        layout = self.layout
        unknown = sorted(set(resources) - set(layout.descriptors))
        if unknown:
            raise ValueError(f"{self.label}: no binding named {', '.join(unknown)} in "
                             f"{self.files} (it has: {', '.join(sorted(layout.descriptors))})")
        writes = new("VkWriteDescriptorSet", len(resources))
        keep = []
        for i, (name, res) in enumerate(resources.items()):
            d = layout.descriptors[name]
            w = writes[i]
            w.dstSet, w.dstBinding, w.descriptorCount = self.sets[d.set], d.binding, 1
            w.descriptorType = const(DESCRIPTOR_TYPES[d.kind])
            if d.kind == "acceleration_structure":
                if not isinstance(res, AccelerationStructure):
                    raise ValueError(f"{self.label}: binding '{name}' takes an "
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
                raise ValueError(f"{self.label}: binding '{name}' is a {d.kind}, which "
                                 "BindingSet does not write (yet)")
        vk.vkUpdateDescriptorSets(self.device.device, len(resources), writes, 0, ffi.NULL)
        self.written |= set(resources)

    def bind(self, cmd: Any, bind_point: int) -> None:
        missing = sorted(set(self.layout.descriptors) - self.written)
        if missing:
            raise ValueError(f"{self.label}: binding(s) {', '.join(missing)} of "
                             f"{self.files} were never written")
        if self.sets is not None:
            lib.vkCmdBindDescriptorSets(cmd, bind_point, self.layout.handle, 0,
                                        len(self.layout.set_layouts), self.sets, 0, ffi.NULL)

    def destroy(self) -> None:
        self.pool.destroy()  # frees the sets
        self.sets = None


class _Standalone:
    """A pipeline of a :class:`Programs` cache of its own: both go together."""

    programs: Programs | None = None

    def destroy(self) -> None:
        if self.programs is not None:
            self.programs.destroy()
            self.programs = None


class ComputePipeline(_Standalone):
    """One compute shader with its reflected layout (ray queries run in one)."""

    def __init__(self, device: VkDevice, path: str | Path,
                 defines: Mapping[str, object] | None = None, *, label: str = ""):
        self.device, self.label = device, label or Path(path).name
        self.bind_point = const("VK_PIPELINE_BIND_POINT_COMPUTE")
        self.programs = Programs(device, None)
        try:
            self.layout = self.programs.get(self.label, [Path(path)], dict(defines or {}),
                                            "compute")
            self.pipeline = self.programs.compute_pipeline(self.layout)
        except BaseException:
            self.destroy()
            raise
        self.local_size = self.layout.local_size

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


@dataclass(frozen=True)
class HitGroup:
    """A triangle hit group: a closest-hit shader and/or an any-hit shader."""

    closest: str | Path | None = None
    any: str | Path | None = None


class RayTracingPipeline(_Standalone):
    """A ray-tracing pipeline: one raygen shader, a miss shader, a triangle hit group.

    Shader groups are numbered raygen (0), miss (1), hit group (2); a
    :class:`ShaderBindingTable` lays them out. ``max_recursion`` is the deepest
    ``traceRayEXT`` nesting (1: only raygen traces), checked against the device's limit."""

    def __init__(self, device: VkDevice, raygen: str | Path, miss: Sequence[str | Path] = (),
                 hit: Sequence[HitGroup] = (), *, defines: Mapping[str, object] | None = None,
                 max_recursion: int = 1, label: str = ""):
        self.device, self.label = device, label or Path(raygen).stem
        self.bind_point = const("VK_PIPELINE_BIND_POINT_RAY_TRACING_KHR")
        if len(miss) > 1 or len(hit) > 1:
            raise ValueError(f"{self.label}: a program has one miss shader and one hit group "
                             f"(given {len(miss)} and {len(hit)})")
        if any(h.closest is None and h.any is None for h in hit):
            raise ValueError(f"{self.label}: a hit group needs a closest-hit or an any-hit "
                             "shader")
        roles = {"rgen": [raygen], "rmiss": list(miss),
                 "rchit": [h.closest for h in hit if h.closest],
                 "rahit": [h.any for h in hit if h.any]}
        self.programs = Programs(device, None)
        try:
            paths = [Path(p) for ps in roles.values() for p in ps]
            self.layout = self.programs.get(self.label, paths, dict(defines or {}),
                                            "ray_tracing")
            _check_roles(self.label, self.layout, roles)
            self.pipeline = self.programs.ray_pipeline(self.layout, max_recursion=max_recursion)
        except BaseException:
            self.destroy()
            raise
        self.counts = self.pipeline.counts

    @property
    def handle(self) -> Any:
        return self.pipeline.handle

    def group_handles(self) -> list[bytes]:
        """Each group's opaque handle (``shaderGroupHandleSize`` bytes), in group order."""
        return self.pipeline.group_handles()


def _check_roles(label: str, prog: Program, roles: dict[str, list[Any]]) -> None:
    """Each file is compiled as the stage it is given for (its name says its stage)."""
    by_path = {m.path.resolve(): m.stage for m in prog.modules.values()}
    for stage, paths in roles.items():
        for p in paths:
            have = by_path.get(Path(p).resolve())
            if have != stage:
                raise ValueError(f"{label}: {Path(p).name} is a {have} shader, used as {stage}")
