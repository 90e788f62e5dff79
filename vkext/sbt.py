"""Ray-tracing pipelines on the device: creation, group handles and the shader binding table.

:class:`ShaderBindingTable` lays the group handles of a pipeline (``vkGetRayTracingShader
GroupHandlesKHR``) out by the device's ``shaderGroupHandleSize``, ``shaderGroupHandleAlignment``
and ``shaderGroupBaseAlignment``, with optional per-record data, and ``trace()`` launches rays
through it. The pipelines themselves are programs of :class:`vkext.programs.Programs`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from rfw.graph.sync import State
from rfw.units import align_up

from .buffers import Buffer
from .commands import upload_buffer
from .consts import const, ffi, new
from .device import VkDevice

# who reads a shader binding table
SBT_READ = State(None, frozenset({"RAY_TRACING_SHADER_KHR"}),
                 frozenset({"SHADER_BINDING_TABLE_READ_KHR"}))


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

    def __init__(self, pipeline: Any, *, miss: Sequence[int] | None = None,
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
