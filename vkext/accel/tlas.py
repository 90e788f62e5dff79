"""The top level: instance records over the BLAS, and the TLAS built (or refit) from them.

Instances carry ``instanceCustomIndex`` = the scene's instance index (instances of empty
meshes are left out of the TLAS, so ``gl_InstanceID`` is not that index; the custom index
is), a mask bit per alpha mode (:data:`ALPHA_MASK`: shadow rays may skip blended surfaces),
an SBT record offset per alpha mode (``hit_groups``: alpha-tested geometry can get a hit group
with an any-hit shader) and ``TRIANGLE_FACING_CULL_DISABLE``: a ray query answers for both
faces, as a rasteriser with culling off would.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from rfw.graph.sync import State
from rfw.scene.model import Scene
from rfw.units import align_up

from ..blocks import BlockAllocator
from ..buffers import Buffer
from ..commands.transfers import record_update
from ..consts import const, new
from ..device import VkDevice
from .structure import (
    AccelerationStructure,
    build_flags,
    build_info,
    build_range,
    build_sizes,
    scratch_buffer,
)

# TLAS instance mask bits by material alpha mode (cull masks of rays test against them)
MASK_OPAQUE, MASK_ALPHA_TEST, MASK_BLEND = 0x1, 0x2, 0x4
ALPHA_MASK = {"OPAQUE": MASK_OPAQUE, "MASK": MASK_ALPHA_TEST, "BLEND": MASK_BLEND}

# VkAccelerationStructureInstanceKHR: a row-major 3x4 transform, then two words of 24 + 8
# bitfields (custom index | mask << 24, SBT record offset | flags << 24), then the BLAS address
INSTANCE_DTYPE = np.dtype([("transform", "<f4", (3, 4)), ("index_mask", "<u4"),
                           ("sbt_flags", "<u4"), ("reference", "<u8")])
assert INSTANCE_DTYPE.itemsize == 64


def instance_records(scene: Scene, blas: Sequence[AccelerationStructure | None],
                     transforms: np.ndarray, hit_groups: Mapping[str, int]
                     ) -> tuple[np.ndarray, list[int]]:
    """The TLAS's instance records and, for each, the scene instance it stands for."""
    rows, kept = [], []
    cull_off = const("VK_GEOMETRY_INSTANCE_TRIANGLE_FACING_CULL_DISABLE_BIT_KHR")
    # no TRIANGLE_FLIP_FACING for mirrored instances: ray tracing decides facing in
    # object space, where an instance transform cannot change the winding, so a mirrored
    # instance faces out where its mesh does (and facing culling is off anyway)
    for k, inst in enumerate(scene.instances):
        b = blas[inst.mesh]
        if b is None:
            continue
        alpha = scene.materials[scene.meshes[inst.mesh].material].alpha_mode
        rows.append((np.zeros((3, 4), np.float32), k | ALPHA_MASK.get(alpha, 1) << 24,
                     hit_groups.get(alpha, 0) | cull_off << 24, b.address))
        kept.append(k)
    records = np.array(rows, INSTANCE_DTYPE)
    if len(records):
        records["transform"] = transforms[kept, :3, :]
    return records, kept


# a TLAS build reads its instance records as VK_ACCESS_2_SHADER_READ in the build stage
RECORDS_READ = State(None, frozenset({"ACCELERATION_STRUCTURE_BUILD_KHR"}),
                     frozenset({"SHADER_READ"}))


class TopLevel:
    """The TLAS of a scene: a host-visible buffer of instance records, the geometry that
    points at it, the structure, and with ``allow_update`` the scratch of refits.

    ``records`` is how many instances the TLAS holds (instances of meshes with a BLAS);
    ``scratch`` the (build, refit) scratch bytes, ``frame_scratch`` what builds and refits
    in frames need.
    """

    def __init__(self, device: VkDevice, scene: Scene, blas: Sequence[AccelerationStructure | None],
                 allocator: BlockAllocator, *, prefer: str | None, allow_update: bool,
                 align: int, label: str, moves: bool = False):
        self.device, self.allow_update, self.label = device, allow_update, label
        self.flags = build_flags(prefer, *(("VK_BUILD_ACCELERATION_STRUCTURE_ALLOW_UPDATE_BIT_KHR",)
                                           if allow_update else ()))
        # host-visible: records are written from the host before each build; where
        # instances move (``moves``), a frame's build writes them in its own commands
        self.moves = moves
        self.instance_buffer = allocator.create_buffer(
            max(64, 64 * len(scene.instances)),
            ("acceleration_structure_input", *(("transfer_dst",) if moves else ())),
            host_visible=True, label=f"{label}.instances")
        g = self.geometry = new("VkAccelerationStructureGeometryKHR")
        g.geometryType = const("VK_GEOMETRY_TYPE_INSTANCES_KHR")
        g.geometry.instances.sType = const(
            "VK_STRUCTURE_TYPE_ACCELERATION_STRUCTURE_GEOMETRY_INSTANCES_DATA_KHR")
        g.geometry.instances.arrayOfPointers = 0
        g.geometry.instances.data.deviceAddress = self.instance_buffer.address
        # records need the BLAS addresses, which compaction changes: count them now, write
        # them once the BLAS are final
        self.records = sum(1 for i in scene.instances if blas[i.mesh] is not None)
        size, scratch, update = build_sizes(device, build_info("top", g, self.flags),
                                            [self.records])
        self.scratch = (scratch, update)
        self.frame_scratch = max(scratch, update if allow_update else 0)
        self.align = align
        self.tlas = AccelerationStructure(device, "top", size, allocator=allocator,
                                          label=f"{label}.tlas")
        self.update_scratch: Buffer | None = None
        if allow_update:
            self.update_scratch = scratch_buffer(device, update, align, f"{label}:update scratch")

    def record(self, cmd: Any, records: np.ndarray, scratch: Buffer, *,
               update: bool = False, inline: bool = False) -> None:
        """Write ``records`` from the host and record a build (or refit in place) of the
        TLAS with ``scratch``. Records no barrier: the caller's plan orders it. The host
        write needs the TLAS's last build to be done with the records (frames and one-time
        submits are waited for). ``inline`` (a frame's build where instances move): the
        records travel in ``cmd`` itself (``vkCmdUpdateBuffer``), so a frame in flight
        keeps the ones its build reads; the update's own barriers order it after the last
        build's reads and before this one."""
        if len(records) and inline:
            record_update(cmd, self.instance_buffer, records, reader=RECORDS_READ)
        elif len(records):
            self.instance_buffer.write(records)  # host writes: the submit makes them visible
        _rng, ranges = build_range(len(records))  # ranges points into _rng
        info = build_info("top", self.geometry, self.flags, update=update)
        if update:
            info.srcAccelerationStructure = self.tlas.handle
        info.dstAccelerationStructure = self.tlas.handle
        info.scratchData.deviceAddress = align_up(scratch.address, self.align)
        self.device.fn.vkCmdBuildAccelerationStructuresKHR(cmd, 1, info, ranges)

    def destroy(self) -> None:
        if self.update_scratch is not None:
            self.update_scratch.destroy()
            self.update_scratch = None
        self.tlas.destroy()
