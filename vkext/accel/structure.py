"""One acceleration structure, its size query and the build descriptions both levels share."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from ..blocks import BlockAllocator
from ..buffers import Buffer
from ..consts import const, ffi, new
from ..device import VkDevice

PREFER = {"fast_trace": "VK_BUILD_ACCELERATION_STRUCTURE_PREFER_FAST_TRACE_BIT_KHR",
          "fast_build": "VK_BUILD_ACCELERATION_STRUCTURE_PREFER_FAST_BUILD_BIT_KHR",
          None: None}


class AccelerationStructure:
    """One ``VkAccelerationStructureKHR`` at offset 0 of a buffer it owns.

    ``allocator`` sub-allocates the buffer from a :class:`BlockAllocator`; without one it gets
    memory of its own (for structures that live only until compaction).
    """

    def __init__(self, device: VkDevice, level: str, size: int, *,
                 allocator: BlockAllocator | None = None, label: str = ""):
        if level not in ("bottom", "top"):
            raise ValueError(f"level is 'bottom' or 'top', not {level!r}")
        self.device, self.level, self.size = device, level, int(size)
        self.label = label or f"{level}-level"
        self.handle = None
        usage = ("acceleration_structure",)
        if allocator is not None:
            self.buffer = allocator.create_buffer(self.size, usage, label=f"{self.label}:buffer")
        else:
            self.buffer = Buffer(device, self.size, usage, label=f"{self.label}:buffer")
            try:
                self.buffer.allocate()
            except BaseException:
                self.buffer.destroy()
                raise
        info = new("VkAccelerationStructureCreateInfoKHR", buffer=self.buffer.handle, offset=0,
                   size=self.size,
                   type=const(f"VK_ACCELERATION_STRUCTURE_TYPE_{level.upper()}_LEVEL_KHR"))
        try:
            self.handle = device.fn.vkCreateAccelerationStructureKHR(device.device, info, ffi.NULL)
        except BaseException:
            self.buffer.destroy()
            raise
        device.register(self)
        device.set_name(self.handle, "ACCELERATION_STRUCTURE_KHR", self.label)
        addr = new("VkAccelerationStructureDeviceAddressInfoKHR",
                   accelerationStructure=self.handle)
        self.address = int(device.fn.vkGetAccelerationStructureDeviceAddressKHR(device.device,
                                                                                addr))

    def destroy(self) -> None:
        if self.handle is not None and self.device.alive:
            self.device.fn.vkDestroyAccelerationStructureKHR(self.device.device, self.handle,
                                                             ffi.NULL)
        self.handle = None
        self.buffer.destroy()
        self.device.unregister(self)

    def __repr__(self) -> str:
        return f"<AccelerationStructure '{self.label}' {self.level} {self.size} B>"


def build_sizes(device: VkDevice, info: Any, counts: Sequence[int]) -> tuple[int, int, int]:
    """(structure, build scratch, update scratch) bytes for a build described by ``info``
    (a ``VkAccelerationStructureBuildGeometryInfoKHR*``) with ``counts`` primitives per
    geometry."""
    out = new("VkAccelerationStructureBuildSizesInfoKHR")
    prims = ffi.new("uint32_t[]", [int(c) for c in counts] or [0])
    device.fn.vkGetAccelerationStructureBuildSizesKHR(
        device.device, const("VK_ACCELERATION_STRUCTURE_BUILD_TYPE_DEVICE_KHR"), info, prims, out)
    return (int(out.accelerationStructureSize), int(out.buildScratchSize),
            int(out.updateScratchSize))


def build_info(level: str, geometry: Any, flags: int, *, update: bool = False) -> Any:
    """A one-geometry build (or, with ``update``, refit) description of a ``level`` structure;
    the caller sets its destination, source and scratch."""
    info = new("VkAccelerationStructureBuildGeometryInfoKHR")
    info.type = const(f"VK_ACCELERATION_STRUCTURE_TYPE_{level.upper()}_LEVEL_KHR")
    info.flags = flags
    info.mode = const("VK_BUILD_ACCELERATION_STRUCTURE_MODE_UPDATE_KHR" if update
                      else "VK_BUILD_ACCELERATION_STRUCTURE_MODE_BUILD_KHR")
    info.geometryCount, info.pGeometries = 1, geometry
    return info


def build_flags(prefer: str | None, *extra: str) -> int:
    """The build flags of a ``prefer`` choice (see :data:`PREFER`) plus ``extra`` ones."""
    out = const(PREFER[prefer]) if prefer else 0
    for name in extra:
        out |= const(name)
    return out


def build_range(count: int) -> tuple[Any, Any]:
    """(range, array of one pointer to it) for a one-geometry build of ``count`` primitives;
    both must live until the build is recorded."""
    rng = ffi.new("VkAccelerationStructureBuildRangeInfoKHR*")
    rng.primitiveCount = count
    return rng, ffi.new("VkAccelerationStructureBuildRangeInfoKHR*[1]", [rng])


def scratch_multiple(device: VkDevice) -> int:
    """Scratch addresses of builds are multiples of this."""
    return int(device.extension_properties["VK_KHR_acceleration_structure"]
               ["minAccelerationStructureScratchOffsetAlignment"])


def scratch_buffer(device: VkDevice, size: int, align: int, label: str) -> Buffer:
    """Scratch memory of builds: a buffer of its own, with room to align its address up."""
    buf = Buffer(device, max(16, size + align), ("storage",), label=label)
    try:
        buf.allocate()
    except BaseException:
        buf.destroy()
        raise
    return buf
