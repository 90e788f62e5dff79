"""Bottom levels: one BLAS per mesh with triangles, built in batches that share one scratch
buffer, and optionally compacted.

Each build gets its own range of the scratch, aligned to
``minAccelerationStructureScratchOffsetAlignment``. When the scratch of all builds would pass
the budget they go in batches, each reusing the scratch from its start: the build plan
(:mod:`vkext.accel.plan`) makes every batch a pass that writes the scratch, so the compiler
orders a batch after the previous one's scratch accesses.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from rfw.units import align_up

from ..blocks import BlockAllocator
from ..consts import const, ffi, new, vk
from ..device import VkDevice
from .geometry import SceneGeometry
from .structure import AccelerationStructure, build_info, build_range, build_sizes


@dataclass
class BlasJob:
    """One mesh's BLAS build: its description, size and scratch bytes."""

    mesh: int
    geometry: Any  # VkAccelerationStructureGeometryKHR (kept alive with the job)
    info: Any  # VkAccelerationStructureBuildGeometryInfoKHR*
    range: Any  # VkAccelerationStructureBuildRangeInfoKHR*
    size: int
    scratch: int


def blas_jobs(device: VkDevice, geometry: SceneGeometry, flags: int) -> list[BlasJob]:
    """A build per mesh with triangles, with the sizes the driver asks for."""
    jobs = []
    for m in range(len(geometry.mesh_ranges)):
        tris = geometry.triangles(m)
        if tris == 0:
            continue
        g = geometry.geometry(m)
        info = build_info("bottom", g, flags)
        size, scratch, _ = build_sizes(device, info, [tris])
        rng, _ = build_range(tris)
        jobs.append(BlasJob(m, g, info, rng, size, scratch))
    return jobs


def batches(jobs: list[BlasJob], budget: int, align: int) -> list[list[BlasJob]]:
    """Consecutive jobs whose aligned scratch fits ``budget`` (one job larger than it goes
    alone)."""
    out: list[list[BlasJob]] = []
    used = budget + 1
    for job in jobs:
        need = align_up(job.scratch, align)
        if used + need > budget:
            out.append([])
            used = 0
        out[-1].append(job)
        used += need
    return out


def batch_scratch(batch: list[BlasJob], align: int) -> int:
    return sum(align_up(j.scratch, align) for j in batch)


def create_structures(device: VkDevice, jobs: list[BlasJob], meshes: int, *,
                      allocator: BlockAllocator | None, label: str,
                      names: list[str]) -> list[AccelerationStructure | None]:
    """The structures the jobs build, by mesh (None for meshes without triangles); without
    ``allocator`` each gets memory of its own (originals that die after compaction)."""
    out: list[AccelerationStructure | None] = [None] * meshes
    for j in jobs:
        out[j.mesh] = AccelerationStructure(device, "bottom", j.size, allocator=allocator,
                                            label=f"{label}.blas{j.mesh}:{names[j.mesh]}")
    return out


def record_batch(device: VkDevice, cmd: Any, batch: list[BlasJob],
                 blas: list[AccelerationStructure | None], base: int, align: int) -> list[Any]:
    """Record one batch's builds, each into its own range of the scratch at ``base``;
    returns the cffi structs that must live until the command buffer is submitted."""
    infos = ffi.new("VkAccelerationStructureBuildGeometryInfoKHR[]", len(batch))
    ranges = ffi.new("VkAccelerationStructureBuildRangeInfoKHR*[]", len(batch))
    offset = 0
    for i, job in enumerate(batch):
        job.info.dstAccelerationStructure = blas[job.mesh].handle
        job.info.scratchData.deviceAddress = base + offset
        infos[i] = job.info[0]
        ranges[i] = job.range
        offset += align_up(job.scratch, align)
    device.fn.vkCmdBuildAccelerationStructuresKHR(cmd, len(batch), infos, ranges)
    return [infos, ranges]


# compaction -----------------------------------------------------------------------------------

_COMPACTED = "VK_QUERY_TYPE_ACCELERATION_STRUCTURE_COMPACTED_SIZE_KHR"


def record_size_query(device: VkDevice, cmd: Any,
                      structures: list[AccelerationStructure]) -> Any:
    """Record queries of the structures' compacted sizes; returns the query pool (read it
    with :func:`compacted_sizes` once the command buffer finished)."""
    info = vk.VkQueryPoolCreateInfo(queryType=const(_COMPACTED), queryCount=len(structures))
    pool = vk.vkCreateQueryPool(device.device, info, None)
    vk.vkCmdResetQueryPool(cmd, pool, 0, len(structures))
    handles = ffi.new("VkAccelerationStructureKHR[]", [s.handle for s in structures])
    device.fn.vkCmdWriteAccelerationStructuresPropertiesKHR(
        cmd, len(structures), handles, const(_COMPACTED), pool, 0)
    return pool


def compacted_sizes(device: VkDevice, pool: Any, n: int) -> list[int]:
    """The ``n`` sizes the query pool holds; the pool is destroyed."""
    sizes = ffi.new("uint64_t[]", n)
    try:
        vk.vkGetQueryPoolResults(device.device, pool, 0, n, 8 * n, sizes, 8,
                                 vk.VK_QUERY_RESULT_64_BIT | vk.VK_QUERY_RESULT_WAIT_BIT)
    finally:
        vk.vkDestroyQueryPool(device.device, pool, None)
    return [int(s) for s in sizes]


def record_compaction(device: VkDevice, cmd: Any, originals: list[AccelerationStructure],
                      compacted: list[AccelerationStructure]) -> None:
    """Record compacting copies of ``originals`` into ``compacted``."""
    for old, new_ in zip(originals, compacted, strict=True):
        info = new("VkCopyAccelerationStructureInfoKHR", src=old.handle, dst=new_.handle,
                   mode=const("VK_COPY_ACCELERATION_STRUCTURE_MODE_COMPACT_KHR"))
        device.fn.vkCmdCopyAccelerationStructureKHR(cmd, info)
