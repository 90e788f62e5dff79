"""Buffers: usages to Vulkan flags (device addresses where the device has them), host
access, and staging buffers."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

from .allocation import DeviceMemory, Resource, flags_of
from .consts import const, vk
from .device import VkDevice

BUFFER_USAGE = {
    "storage": "VK_BUFFER_USAGE_STORAGE_BUFFER_BIT",
    "uniform": "VK_BUFFER_USAGE_UNIFORM_BUFFER_BIT",
    "indirect": "VK_BUFFER_USAGE_INDIRECT_BUFFER_BIT",
    "vertex": "VK_BUFFER_USAGE_VERTEX_BUFFER_BIT",
    "index": "VK_BUFFER_USAGE_INDEX_BUFFER_BIT",
    "transfer_src": "VK_BUFFER_USAGE_TRANSFER_SRC_BIT",
    "transfer_dst": "VK_BUFFER_USAGE_TRANSFER_DST_BIT",
    "device_address": "VK_BUFFER_USAGE_SHADER_DEVICE_ADDRESS_BIT",
    "acceleration_structure": "VK_BUFFER_USAGE_ACCELERATION_STRUCTURE_STORAGE_BIT_KHR",
    "acceleration_structure_input":
        "VK_BUFFER_USAGE_ACCELERATION_STRUCTURE_BUILD_INPUT_READ_ONLY_BIT_KHR",
    "shader_binding_table": "VK_BUFFER_USAGE_SHADER_BINDING_TABLE_BIT_KHR",
}


def buffer_usage_flags(usages: Iterable[str] | int) -> int:
    if isinstance(usages, int):
        return usages
    unknown = [u for u in usages if u not in BUFFER_USAGE]
    if unknown:
        raise ValueError(f"unknown buffer usage {', '.join(sorted(unknown))} "
                         f"(known: {', '.join(sorted(BUFFER_USAGE))})")
    return flags_of(BUFFER_USAGE[u] for u in usages)


def device_buffer_flags(device: VkDevice, usage: Iterable[str] | int) -> int:
    """``buffer_usage_flags`` on ``device``: with buffer device address, anything shaders
    touch also gets an address."""
    flags = buffer_usage_flags(usage)
    if not isinstance(usage, int) and "buffer_device_address" in device.caps \
            and set(usage) - {"transfer_src", "transfer_dst"}:
        flags |= const(BUFFER_USAGE["device_address"])
    return flags


def buffer_create_info(size: int, usage: int) -> Any:
    return vk.VkBufferCreateInfo(size=size, usage=usage,
                                 sharingMode=vk.VK_SHARING_MODE_EXCLUSIVE)


class Buffer(Resource):
    """A buffer (unbound until ``bind``/``allocate``). With buffer device address, any
    usage beyond transfers adds ``SHADER_DEVICE_ADDRESS`` so shaders can reach it."""

    kind = "buffer"

    def __init__(self, device: VkDevice, size: int, usage: Iterable[str] | int, *,
                 label: str = ""):
        self.device, self.label = device, label or "buffer"
        self.handle = None
        self.bytes = int(size)
        if self.bytes <= 0:
            raise ValueError(f"buffer '{self.label}': size must be positive, got {size}")
        self.usages = frozenset(usage) if not isinstance(usage, int) else frozenset()
        self.usage = device_buffer_flags(device, usage)
        self._init_binding()
        self.handle = vk.vkCreateBuffer(device.device, buffer_create_info(self.bytes, self.usage),
                                        None)
        device.register(self)
        device.set_name(self.handle, "BUFFER", self.label)
        req = vk.vkGetBufferMemoryRequirements(device.device, self.handle)
        self.size, self.alignment, self.type_bits = (int(req.size), int(req.alignment),
                                                     int(req.memoryTypeBits))

    def _bind(self, memory: DeviceMemory, offset: int) -> None:
        vk.vkBindBufferMemory(self.device.device, self.handle, memory.handle, offset)

    @property
    def address(self) -> int:
        """The buffer's device address (needs buffer device address)."""
        if not self.usage & const(BUFFER_USAGE["device_address"]):
            raise ValueError(f"buffer '{self.label}' was not created for device addresses")
        return self.device.buffer_address(self.handle)

    # host access (host-visible memory only)

    def map(self) -> np.ndarray:
        """The buffer's bytes as a writable uint8 array over mapped memory."""
        if self.memory is None:
            raise ValueError(f"buffer '{self.label}' is not bound to memory")
        return np.frombuffer(self.memory.map(), np.uint8, count=self.bytes, offset=self.offset)

    def unmap(self) -> None:
        """Unmap memory this buffer owns (shared blocks stay mapped)."""
        if self._owned is not None:
            self._owned.unmap()

    def write(self, array: Any, offset: int = 0) -> None:
        data = np.ascontiguousarray(array).reshape(-1).view(np.uint8)
        if offset + data.size > self.bytes:
            raise ValueError(f"buffer '{self.label}': writing {data.size} bytes at {offset} "
                             f"overruns its {self.bytes} bytes")
        self.map()[offset:offset + data.size] = data

    def read(self, dtype: Any = np.uint8, shape: int | tuple[int, ...] | None = None,
             offset: int = 0) -> np.ndarray:
        dtype = np.dtype(dtype)
        count = (self.bytes - offset) // dtype.itemsize if shape is None \
            else int(np.prod(shape))
        raw = self.map()[offset:offset + count * dtype.itemsize]
        out = raw.view(dtype).copy()
        return out if shape is None else out.reshape(shape)

    def destroy(self) -> None:
        if self.handle is not None and self.device.alive:
            vk.vkDestroyBuffer(self.device.device, self.handle, None)
        self.handle = None
        self._release_memory()
        self.device.unregister(self)

    def __repr__(self) -> str:
        return f"<Buffer '{self.label}' {self.bytes} B align {self.alignment}>"


def staging_buffer(device: VkDevice, size: int, *, readback: bool = False,
                   label: str = "staging") -> Buffer:
    """A host-visible, coherent transfer buffer with its own memory (cached for readback)."""
    buf = Buffer(device, size, ("transfer_src", "transfer_dst"), label=label)
    try:
        buf.allocate(host_visible=True, readback=readback)
    except BaseException:
        buf.destroy()
        raise
    return buf
