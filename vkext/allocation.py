"""Device memory: memory types, ``VkDeviceMemory`` allocations, and what images and
buffers share to be bound into them."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from rfw.errors import RfwError
from rfw.units import GiB, KiB, MiB

from .consts import const, ffi, vk
from .device import VkDevice


class VkOutOfMemoryError(RfwError, MemoryError):
    """An allocation the device cannot satisfy (too large for its heap, or refused)."""


class PlanMismatchError(ValueError):
    """The driver needs more bytes or a stricter alignment than the compiled plan gives."""


DEVICE_LOCAL = "VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT"
HOST_VISIBLE = "VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT"
HOST_COHERENT = "VK_MEMORY_PROPERTY_HOST_COHERENT_BIT"
HOST_CACHED = "VK_MEMORY_PROPERTY_HOST_CACHED_BIT"


def flags_of(names: Iterable[str]) -> int:
    """The OR of Vulkan constants given by name."""
    out = 0
    for n in names:
        out |= const(n)
    return out


def byte_text(n: int) -> str:
    """A byte count for messages: ``1.5 MiB``, ``300 B``."""
    for unit, scale in (("GiB", GiB), ("MiB", MiB), ("KiB", KiB)):
        if n >= scale:
            return f"{n / scale:.4g} {unit}"
    return f"{n} B"


def find_memory_type(device: VkDevice, type_bits: int, required: Iterable[str] = (),
                     preferred: Iterable[str] = ()) -> int:
    """The first memory type allowed by ``type_bits`` with every ``required`` property,
    and, among those, the most ``preferred`` ones."""
    need = flags_of(required)
    want = [const(p) for p in preferred]
    best: tuple[int, int] | None = None
    for i, (props, _) in enumerate(device.memory_types):
        if not type_bits & (1 << i) or props & need != need:
            continue
        score = sum(1 for w in want if props & w)
        if best is None or score > best[0]:
            best = (score, i)
    if best is None:
        raise VkOutOfMemoryError(f"no memory type in bits {type_bits:#x} has "
                                 f"{' | '.join(required) or 'any properties'}")
    return best[1]


class DeviceMemory:
    """One ``VkDeviceMemory``. Allocated with the device-address flag when the device has
    buffer device address, so any buffer bound to it may use it."""

    def __init__(self, device: VkDevice, size: int, type_bits: int = ~0, *,
                 host_visible: bool = False, readback: bool = False, label: str = ""):
        self.device, self.size, self.label = device, int(size), label
        self.handle: Any = None
        self._mapped: Any = None
        required = [HOST_VISIBLE, HOST_COHERENT] if host_visible else []
        preferred = [HOST_CACHED] if readback else [] if host_visible else [DEVICE_LOCAL]
        self.type_index = find_memory_type(device, type_bits, required, preferred)
        self.properties, heap = device.memory_types[self.type_index]
        heap_size = device.memory_heaps[heap][0]
        limit = device.limits["maxMemoryAllocationSize"]
        if self.size <= 0:
            raise ValueError(f"{label or 'memory'}: size must be positive, got {self.size}")
        if self.size > heap_size:
            raise VkOutOfMemoryError(f"{label or 'memory'}: {byte_text(self.size)} is larger "
                                     f"than memory heap {heap} ({byte_text(heap_size)}) of "
                                     f"{device.name}")
        if self.size > limit:
            raise VkOutOfMemoryError(f"{label or 'memory'}: {byte_text(self.size)} is over the "
                                     f"device's maxMemoryAllocationSize ({byte_text(limit)})")
        info = ffi.new("VkMemoryAllocateInfo*")
        info.sType = const("VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO")
        info.allocationSize, info.memoryTypeIndex = self.size, self.type_index
        flags = None
        if "buffer_device_address" in device.caps:
            flags = ffi.new("VkMemoryAllocateFlagsInfo*")
            flags.sType = const("VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_FLAGS_INFO")
            flags.flags = const("VK_MEMORY_ALLOCATE_DEVICE_ADDRESS_BIT")
            info.pNext = flags
        try:
            self.handle = vk.vkAllocateMemory(device.device, info, None)
        except (vk.VkErrorOutOfDeviceMemory, vk.VkErrorOutOfHostMemory) as e:
            raise VkOutOfMemoryError(f"{label or 'memory'}: the driver refused "
                                     f"{byte_text(self.size)} ({type(e).__name__})") from None
        device.register(self)
        device.set_name(self.handle, "DEVICE_MEMORY", label)

    @property
    def host_visible(self) -> bool:
        return bool(self.properties & const(HOST_VISIBLE))

    def map(self) -> Any:
        """The whole allocation as a writable buffer (mapped once, kept until unmap)."""
        if not self.host_visible:
            raise ValueError(f"{self.label or 'memory'} is not host-visible")
        if self._mapped is None:
            self._mapped = vk.vkMapMemory(self.device.device, self.handle, 0, self.size, 0)
        return self._mapped

    def unmap(self) -> None:
        if self._mapped is not None:
            vk.vkUnmapMemory(self.device.device, self.handle)
            self._mapped = None

    def destroy(self) -> None:
        if self.handle is not None and self.device.alive:
            self.unmap()
            vk.vkFreeMemory(self.device.device, self.handle, None)
        self.handle = None
        self.device.unregister(self)


class Resource:
    """What images and buffers share: requirements, binding, the memory they own."""

    kind = "resource"
    device: VkDevice
    handle: Any
    label: str
    size: int  # bytes the driver requires
    alignment: int
    type_bits: int

    def _init_binding(self) -> None:
        self.memory: DeviceMemory | None = None
        self.offset = 0
        self._owned: DeviceMemory | None = None  # dedicated memory freed with the resource
        self.sub_allocation: Any = None  # a blocks.SubAllocation, from a BlockAllocator

    def bind(self, memory: DeviceMemory, offset: int = 0) -> None:
        if self.memory is not None:
            raise ValueError(f"{self.kind} '{self.label}' is already bound")
        if offset % self.alignment:
            raise PlanMismatchError(f"{self.kind} '{self.label}': offset {offset} is not a "
                                    f"multiple of the required alignment {self.alignment}")
        if offset + self.size > memory.size:
            raise PlanMismatchError(f"{self.kind} '{self.label}': {self.size} bytes at offset "
                                    f"{offset} overrun '{memory.label}' ({memory.size} bytes)")
        if not self.type_bits & (1 << memory.type_index):
            raise PlanMismatchError(f"{self.kind} '{self.label}' cannot live in memory type "
                                    f"{memory.type_index} (allowed bits {self.type_bits:#x})")
        self._bind(memory, offset)
        self.memory, self.offset = memory, offset

    def _bind(self, memory: DeviceMemory, offset: int) -> None:
        raise NotImplementedError

    def allocate(self, *, host_visible: bool = False, readback: bool = False) -> None:
        """Bind to a dedicated allocation of exactly the required size."""
        mem = DeviceMemory(self.device, self.size, self.type_bits, host_visible=host_visible,
                           readback=readback, label=f"{self.label}:memory")
        self._owned = mem
        self.bind(mem, 0)

    def _release_memory(self) -> None:
        if self.sub_allocation is not None:
            self.sub_allocation.free()
            self.sub_allocation = None
        if self._owned is not None:
            self._owned.destroy()
            self._owned = None
        self.memory = None
