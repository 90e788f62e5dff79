"""Device memory: aliased heaps for a compiled graph, a block allocator, views, staging.

Images and buffers are created first, their real ``VkMemoryRequirements`` read, and only
then bound, at the offsets the frame-graph compiler planned: resources whose lifetimes do not
overlap share the bytes of one ``VkDeviceMemory``, so the aliasing is real.
"""

from __future__ import annotations

import bisect
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from rfw.errors import RfwError
from rfw.graph.compile import CompiledGraph, MemoryOptions, ResourcePlan
from rfw.graph.formats import FormatInfo, format_info
from rfw.units import GiB, KiB, MiB, align_up

from .consts import const, ffi, vk
from .device import VkDevice


class VkOutOfMemoryError(RfwError, MemoryError):
    """An allocation the device cannot satisfy (too large for its heap, or refused)."""


class PlanMismatchError(ValueError):
    """The driver needs more bytes or a stricter alignment than the compiled plan gives."""


class UnsupportedFormatError(RfwError):
    """The device cannot make an image of that format, usage and shape."""


# rfw usage names -> (image usage flag, format feature the usage needs)
_IMAGE_USAGE = {
    "sampled": ("VK_IMAGE_USAGE_SAMPLED_BIT", "VK_FORMAT_FEATURE_SAMPLED_IMAGE_BIT"),
    "storage": ("VK_IMAGE_USAGE_STORAGE_BIT", "VK_FORMAT_FEATURE_STORAGE_IMAGE_BIT"),
    "color": ("VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT", "VK_FORMAT_FEATURE_COLOR_ATTACHMENT_BIT"),
    "depth": ("VK_IMAGE_USAGE_DEPTH_STENCIL_ATTACHMENT_BIT",
              "VK_FORMAT_FEATURE_DEPTH_STENCIL_ATTACHMENT_BIT"),
    "depth_read": ("VK_IMAGE_USAGE_DEPTH_STENCIL_ATTACHMENT_BIT",
                   "VK_FORMAT_FEATURE_DEPTH_STENCIL_ATTACHMENT_BIT"),
    "transfer_src": ("VK_IMAGE_USAGE_TRANSFER_SRC_BIT", "VK_FORMAT_FEATURE_TRANSFER_SRC_BIT"),
    "transfer_dst": ("VK_IMAGE_USAGE_TRANSFER_DST_BIT", "VK_FORMAT_FEATURE_TRANSFER_DST_BIT"),
    "shading_rate": ("VK_IMAGE_USAGE_FRAGMENT_SHADING_RATE_ATTACHMENT_BIT_KHR",
                     "VK_FORMAT_FEATURE_FRAGMENT_SHADING_RATE_ATTACHMENT_BIT_KHR"),
}
_BUFFER_USAGE = {
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
# wgpu formats whose Vulkan format the device picks, in order of preference
_DEVICE_CHOSEN = {
    "depth24plus": ("VK_FORMAT_X8_D24_UNORM_PACK32", "VK_FORMAT_D32_SFLOAT"),
    "depth24plus-stencil8": ("VK_FORMAT_D24_UNORM_S8_UINT", "VK_FORMAT_D32_SFLOAT_S8_UINT"),
}

DEVICE_LOCAL = "VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT"
HOST_VISIBLE = "VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT"
HOST_COHERENT = "VK_MEMORY_PROPERTY_HOST_COHERENT_BIT"
HOST_CACHED = "VK_MEMORY_PROPERTY_HOST_CACHED_BIT"


def _flags(names: Iterable[str]) -> int:
    out = 0
    for n in names:
        out |= const(n)
    return out


def _size(n: int) -> str:
    for unit, scale in (("GiB", GiB), ("MiB", MiB), ("KiB", KiB)):
        if n >= scale:
            return f"{n / scale:.4g} {unit}"
    return f"{n} B"


# ---------------------------------------------------------------------------------------------
# formats and usages


def vk_format(name: str, device: VkDevice | None = None, *, usages: Iterable[str] = ()) -> int:
    """The ``VkFormat`` of an rfw format name (wgpu or Vulkan spelling).

    ``depth24plus``-style names have no fixed Vulkan format: the first candidate the device
    supports for ``usages`` is chosen (without a device, the first candidate).
    """
    info = format_info(name)
    if info.vk is not None:
        return const(info.vk)
    candidates = _DEVICE_CHOSEN.get(info.name, ())
    for c in candidates:
        if device is None or not _missing_features(device, const(c), usages):
            return const(c)
    raise UnsupportedFormatError(f"format '{name}': the device supports none of "
                                 f"{', '.join(candidates) or 'its Vulkan equivalents'}")


def aspect_flags(format: str | FormatInfo) -> int:
    """Every aspect of a format: color, or depth and/or stencil."""
    info = format if isinstance(format, FormatInfo) else format_info(format)
    if info.depth or info.stencil:
        return ((vk.VK_IMAGE_ASPECT_DEPTH_BIT if info.depth else 0)
                | (vk.VK_IMAGE_ASPECT_STENCIL_BIT if info.stencil else 0))
    return vk.VK_IMAGE_ASPECT_COLOR_BIT


_ASPECTS = {"color": "VK_IMAGE_ASPECT_COLOR_BIT", "depth": "VK_IMAGE_ASPECT_DEPTH_BIT",
            "stencil": "VK_IMAGE_ASPECT_STENCIL_BIT"}


def _aspect(aspect: str | int | None, default: int) -> int:
    if aspect is None:
        return default
    if isinstance(aspect, int):
        return aspect
    return _flags(_ASPECTS[a] for a in aspect.replace("_", "|").split("|"))


def image_usage_flags(usages: Iterable[str] | int) -> int:
    if isinstance(usages, int):
        return usages
    unknown = [u for u in usages if u not in _IMAGE_USAGE]
    if unknown:
        raise ValueError(f"unknown image usage {', '.join(sorted(unknown))} "
                         f"(known: {', '.join(sorted(_IMAGE_USAGE))})")
    return _flags(_IMAGE_USAGE[u][0] for u in usages)


def buffer_usage_flags(usages: Iterable[str] | int) -> int:
    if isinstance(usages, int):
        return usages
    unknown = [u for u in usages if u not in _BUFFER_USAGE]
    if unknown:
        raise ValueError(f"unknown buffer usage {', '.join(sorted(unknown))} "
                         f"(known: {', '.join(sorted(_BUFFER_USAGE))})")
    return _flags(_BUFFER_USAGE[u] for u in usages)


def _missing_features(device: VkDevice, fmt: int, usages: Iterable[str]) -> list[str]:
    props = vk.vkGetPhysicalDeviceFormatProperties(device.physical_device, fmt)
    have = props.optimalTilingFeatures
    return [u for u in sorted(set(usages)) if u in _IMAGE_USAGE
            and not have & const(_IMAGE_USAGE[u][1])]


def numpy_dtype(format: str) -> tuple[np.dtype, int]:
    """The numpy dtype of one channel and the channel count of a texel (for readback);
    packed and compressed formats read as raw bytes."""
    info = format_info(format)
    if info.compressed or info.block_bytes % info.components or (info.depth and info.stencil):
        return np.dtype(np.uint8), info.block_bytes
    size = info.block_bytes // info.components
    kind = {"float": "f", "depth": "f" if size == 4 else "u", "unorm": "u", "uint": "u",
            "uscaled": "u", "stencil": "u", "snorm": "i", "sint": "i", "sscaled": "i"}
    code = kind.get(info.kind)
    if code is None or size not in (1, 2, 4, 8) or (code == "f" and size == 1):
        return np.dtype(np.uint8), info.block_bytes
    return np.dtype(f"{code}{size}"), info.components


# ---------------------------------------------------------------------------------------------
# memory types and allocations


def find_memory_type(device: VkDevice, type_bits: int, required: Iterable[str] = (),
                     preferred: Iterable[str] = ()) -> int:
    """The first memory type allowed by ``type_bits`` with every ``required`` property,
    and, among those, the most ``preferred`` ones."""
    need = _flags(required)
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
            raise VkOutOfMemoryError(f"{label or 'memory'}: {_size(self.size)} is larger than "
                                     f"memory heap {heap} ({_size(heap_size)}) of {device.name}")
        if self.size > limit:
            raise VkOutOfMemoryError(f"{label or 'memory'}: {_size(self.size)} is over the "
                                     f"device's maxMemoryAllocationSize ({_size(limit)})")
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
                                     f"{_size(self.size)} ({type(e).__name__})") from None
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


class Heap(DeviceMemory):
    """One ``VkDeviceMemory`` that resources are bound into at chosen offsets (aliasing)."""

    @classmethod
    def for_resources(cls, device: VkDevice, resources: Iterable[Image | Buffer],
                      size: int | None = None, *, label: str = "") -> Heap:
        """A heap of a memory type every resource accepts (device-local preferred)."""
        resources = list(resources)
        bits = ~0
        for r in resources:
            bits &= r.type_bits
        if not bits:
            names = ", ".join(f"{r.label} ({r.type_bits:#x})" for r in resources)
            raise VkOutOfMemoryError(f"{label or 'heap'}: no memory type suits all of {names}")
        if size is None:
            size = max(r.size for r in resources)
        return cls(device, size, bits, label=label)

    def bind(self, resource: Image | Buffer, offset: int) -> None:
        resource.bind(self, offset)


# ---------------------------------------------------------------------------------------------
# images, buffers, views


class _Resource:
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
        self._allocation: SubAllocation | None = None  # from a BlockAllocator

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
        if self._allocation is not None:
            self._allocation.free()
            self._allocation = None
        if self._owned is not None:
            self._owned.destroy()
            self._owned = None
        self.memory = None


class Image(_Resource):
    """A 2D optimal-tiling image (unbound until ``bind``/``allocate``)."""

    kind = "image"

    def __init__(self, device: VkDevice, width: int, height: int, format: str,
                 usage: Iterable[str] | int, *, mips: int = 1, layers: int = 1,
                 samples: int = 1, label: str = "", flags: int = 0):
        self.device, self.label = device, label or "image"
        self.handle = None
        self.views: list[ImageView] = []
        self.format, self.info = format, format_info(format)
        self.usages = frozenset(usage) if not isinstance(usage, int) else frozenset()
        if "shading_rate" in self.usages:  # vkext does not enable the extension (yet)
            device.require("VK_KHR_fragment_shading_rate")
        self.vk_format = vk_format(format, device, usages=self.usages)
        self.width, self.height = int(width), int(height)
        self.mips, self.layers, self.samples = int(mips), int(layers), int(samples)
        self.usage = image_usage_flags(usage)
        self.aspect = aspect_flags(self.info)
        self._init_binding()
        self._check_support()
        info = image_create_info(self.vk_format, self.width, self.height, self.usage,
                                 self.mips, self.layers, self.samples, flags)
        self.handle = vk.vkCreateImage(device.device, info, None)
        device.register(self)
        device.set_name(self.handle, "IMAGE", self.label)
        req = vk.vkGetImageMemoryRequirements(device.device, self.handle)
        self.size, self.alignment, self.type_bits = (int(req.size), int(req.alignment),
                                                     int(req.memoryTypeBits))

    def _check_support(self) -> None:
        what = (f"image '{self.label}' ({self.format}, {self.width}x{self.height}, "
                f"usage {'|'.join(sorted(self.usages)) or hex(self.usage)})")
        missing = _missing_features(self.device, self.vk_format, self.usages)
        if missing:
            raise UnsupportedFormatError(f"{what}: {self.device.name} does not support "
                                         f"{', '.join(missing)} for this format")
        try:
            props = vk.vkGetPhysicalDeviceImageFormatProperties(
                self.device.physical_device, self.vk_format, vk.VK_IMAGE_TYPE_2D,
                vk.VK_IMAGE_TILING_OPTIMAL, self.usage, 0)
        except vk.VkErrorFormatNotSupported:
            raise UnsupportedFormatError(f"{what}: not supported by {self.device.name}") from None
        problems = []
        if max(self.width, self.height) > min(props.maxExtent.width, props.maxExtent.height):
            problems.append(f"larger than {props.maxExtent.width}x{props.maxExtent.height}")
        if self.mips > props.maxMipLevels:
            problems.append(f"{self.mips} mips (max {props.maxMipLevels})")
        if self.layers > props.maxArrayLayers:
            problems.append(f"{self.layers} layers (max {props.maxArrayLayers})")
        if not props.sampleCounts & self.samples:
            problems.append(f"{self.samples} samples (supported mask {props.sampleCounts:#x})")
        if problems:
            raise UnsupportedFormatError(f"{what}: {'; '.join(problems)}")

    def _bind(self, memory: DeviceMemory, offset: int) -> None:
        vk.vkBindImageMemory(self.device.device, self.handle, memory.handle, offset)

    def view(self, *, format: str | None = None, aspect: str | int | None = None,
             mips: tuple[int, int] | None = None, layers: tuple[int, int] | None = None,
             label: str = "") -> ImageView:
        return ImageView(self, format=format, aspect=aspect, mips=mips, layers=layers,
                         label=label)

    def subresource_range(self, aspect: int | None = None) -> Any:
        return vk.VkImageSubresourceRange(aspectMask=aspect or self.aspect, baseMipLevel=0,
                                          levelCount=self.mips, baseArrayLayer=0,
                                          layerCount=self.layers)

    def destroy(self) -> None:
        for v in list(self.views):
            v.destroy()
        if self.handle is not None and self.device.alive:
            vk.vkDestroyImage(self.device.device, self.handle, None)
        self.handle = None
        self._release_memory()
        self.device.unregister(self)

    def __repr__(self) -> str:
        return (f"<Image '{self.label}' {self.format} {self.width}x{self.height} "
                f"{self.size} B align {self.alignment}>")


def image_create_info(fmt: int, width: int, height: int, usage: int, mips: int = 1,
                      layers: int = 1, samples: int = 1, flags: int = 0) -> Any:
    return vk.VkImageCreateInfo(
        flags=flags, imageType=vk.VK_IMAGE_TYPE_2D, format=fmt,
        extent=vk.VkExtent3D(width=width, height=height, depth=1), mipLevels=mips,
        arrayLayers=layers, samples=samples, tiling=vk.VK_IMAGE_TILING_OPTIMAL, usage=usage,
        sharingMode=vk.VK_SHARING_MODE_EXCLUSIVE, initialLayout=vk.VK_IMAGE_LAYOUT_UNDEFINED)


def buffer_create_info(size: int, usage: int) -> Any:
    return vk.VkBufferCreateInfo(size=size, usage=usage,
                                 sharingMode=vk.VK_SHARING_MODE_EXCLUSIVE)


class ImageView:
    """A view of an image; destroyed with it."""

    def __init__(self, image: Image, *, format: str | None = None,
                 aspect: str | int | None = None, mips: tuple[int, int] | None = None,
                 layers: tuple[int, int] | None = None, label: str = ""):
        self.image, self.device = image, image.device
        self.handle = None
        base_mip, mip_count = mips or (0, image.mips)
        base_layer, layer_count = layers or (0, image.layers)
        self.format = format or image.format
        self.aspect = _aspect(aspect, image.aspect)
        view_type = vk.VK_IMAGE_VIEW_TYPE_2D if layers is None and image.layers == 1 \
            else vk.VK_IMAGE_VIEW_TYPE_2D_ARRAY
        info = vk.VkImageViewCreateInfo(
            image=image.handle, viewType=view_type,
            format=vk_format(self.format, image.device, usages=image.usages),
            subresourceRange=vk.VkImageSubresourceRange(
                aspectMask=self.aspect, baseMipLevel=base_mip, levelCount=mip_count,
                baseArrayLayer=base_layer, layerCount=layer_count))
        self.handle = vk.vkCreateImageView(image.device.device, info, None)
        self.label = label or f"{image.label}:view"
        image.views.append(self)
        self.device.register(self)
        self.device.set_name(self.handle, "IMAGE_VIEW", self.label)

    def destroy(self) -> None:
        if self.handle is not None and self.device.alive:
            vk.vkDestroyImageView(self.device.device, self.handle, None)
        self.handle = None
        if self in self.image.views:
            self.image.views.remove(self)
        self.device.unregister(self)


def image_view(image: Image, format: str | None = None, aspect: str | int | None = None,
               mips: tuple[int, int] | None = None, *, layers: tuple[int, int] | None = None,
               label: str = "") -> ImageView:
    """A view of ``image``: ``aspect`` "color", "depth", "stencil" or "depth|stencil"
    (default: all of the format's aspects; sample depth through ``aspect="depth"``),
    ``mips`` and ``layers`` as (first, count)."""
    return ImageView(image, format=format, aspect=aspect, mips=mips, layers=layers, label=label)


class Buffer(_Resource):
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
        self.usage = _buffer_flags(device, usage)
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
        if not self.usage & const(_BUFFER_USAGE["device_address"]):
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


# ---------------------------------------------------------------------------------------------
# transient memory of a compiled graph


@dataclass(frozen=True)
class Placement:
    """Where one transient resource went, and what the driver asked for."""

    name: str
    heap: int
    offset: int
    size: int  # bytes the driver requires
    alignment: int
    planned: int  # bytes the plan reserved


def _image_usages(r: ResourcePlan, readback: bool) -> set[str]:
    return set(r.usages) | ({"transfer_src"} if readback else set())


def _buffer_usages(r: ResourcePlan, readback: bool) -> set[str]:
    usages = set(r.usages) & set(_BUFFER_USAGE) or {"storage"}
    return usages | ({"transfer_src"} if readback else set())


def _buffer_flags(device: VkDevice, usage: Iterable[str] | int) -> int:
    # with buffer device address, anything shaders touch also gets an address
    flags = buffer_usage_flags(usage)
    if not isinstance(usage, int) and "buffer_device_address" in device.caps \
            and set(usage) - {"transfer_src", "transfer_dst"}:
        flags |= const(_BUFFER_USAGE["device_address"])
    return flags


def _transients(plan: CompiledGraph) -> list[ResourcePlan]:
    return [r for r in plan.resources if r.transient and r.heap is not None]


def _requirements2() -> Any:
    # the package's wrapper would pass an output struct with sType 0 (a validation error)
    out = ffi.new("VkMemoryRequirements2*")
    out.sType = const("VK_STRUCTURE_TYPE_MEMORY_REQUIREMENTS_2")
    return out


def requirements(plan: CompiledGraph, device: VkDevice, *,
                 readback: bool = False) -> dict[str, tuple[int, int]]:
    """The driver's (size, alignment) for each transient resource of ``plan``, without
    creating anything (``vkGetDevice*MemoryRequirements``)."""
    out: dict[str, tuple[int, int]] = {}
    for r in _transients(plan):
        if r.kind == "image":
            usages = _image_usages(r, readback)
            info = image_create_info(vk_format(r.format, device, usages=usages), r.width,
                                     r.height, image_usage_flags(usages), r.mips, r.layers,
                                     r.samples)
            query = vk.VkDeviceImageMemoryRequirements(pCreateInfo=info, planeAspect=0)
            req = _requirements2()
            vk.vkGetDeviceImageMemoryRequirements(device.device, query, req)
        else:
            usage = _buffer_flags(device, _buffer_usages(r, readback))
            query = vk.VkDeviceBufferMemoryRequirements(
                pCreateInfo=buffer_create_info(r.raw_bytes, usage))
            req = _requirements2()
            vk.vkGetDeviceBufferMemoryRequirements(device.device, query, req)
        mr = req.memoryRequirements
        out[r.name] = (int(mr.size), int(mr.alignment))
    return out


def memory_options(plan: CompiledGraph, device: VkDevice, *,
                   base: MemoryOptions | None = None, readback: bool = False) -> MemoryOptions:
    """Placement rules that fit this device: per kind, the largest alignment the driver asks
    for, and each resource's exact size from the driver (rows and tiles padded).
    Compile again with these to get a plan ``plan_heaps`` accepts without waste."""
    base = base or MemoryOptions()
    reqs = requirements(plan, device, readback=readback)
    chosen = {"image": base.image_alignment, "buffer": base.buffer_alignment}
    for kind in chosen:
        aligns = [reqs[r.name][1] for r in _transients(plan) if r.kind == kind]
        if aligns:
            chosen[kind] = max(aligns)
    sizes = tuple(sorted((name, size) for name, (size, _) in reqs.items()))
    return replace(base, image_alignment=chosen["image"], buffer_alignment=chosen["buffer"],
                   sizes=sizes)


class TransientMemory:
    """The transient images and buffers of a compiled graph, bound into aliased heaps.

    ``images``/``buffers`` map resource names to :class:`Image`/:class:`Buffer`; ``heaps``
    lists ``(VkDeviceMemory, size)``; ``allocated_bytes`` is the sum of what was allocated.
    """

    def __init__(self, device: VkDevice, plan: CompiledGraph, *, no_alias: bool):
        self.device, self.plan, self.no_alias = device, plan, no_alias
        self.images: dict[str, Image] = {}
        self.buffers: dict[str, Buffer] = {}
        self.memories: list[DeviceMemory] = []
        self.placements: dict[str, Placement] = {}
        device.register(self)

    @property
    def resources(self) -> dict[str, Image | Buffer]:
        return {**self.images, **self.buffers}

    @property
    def heaps(self) -> list[tuple[Any, int]]:
        return [(m.handle, m.size) for m in self.memories]

    @property
    def allocated_bytes(self) -> int:
        return sum(m.size for m in self.memories)

    def report(self) -> str:
        """One line per resource: heap, offset, driver size and alignment against the plan."""
        mode = "separate allocations" if self.no_alias else "aliased heaps"
        lines = [f"{self.plan.name}: {_size(self.allocated_bytes)} in {len(self.memories)} "
                 f"{mode} (plan: {_size(self.plan.transient_bytes)} aliased, "
                 f"{_size(self.plan.unaliased_bytes)} unaliased)"]
        for p in self.placements.values():
            lines.append(f"  {p.name:<28} heap {p.heap} @ {p.offset:>10}  size {p.size:>10}  "
                         f"align {p.alignment:>6}  planned {p.planned:>10}")
        return "\n".join(lines)

    def destroy(self) -> None:
        for r in [*self.images.values(), *self.buffers.values()]:
            r.destroy()
        for m in self.memories:
            m.destroy()
        self.images.clear()
        self.buffers.clear()
        self.memories.clear()
        self.device.unregister(self)


def plan_heaps(plan: CompiledGraph, device: VkDevice, *, no_alias: bool = False,
               readback: bool = False) -> TransientMemory:
    """Create the transient resources of ``plan`` and bind them where the plan says.

    Every resource's real requirements are checked against the plan: a driver that needs
    more bytes than planned, or an alignment the planned offset misses, raises
    :class:`PlanMismatchError` naming the resource and both numbers (compile with
    ``memory=memory_options(plan, device)`` to fit the device). ``no_alias=True`` gives each
    resource its own allocation of the driver's size instead, for comparison.
    ``readback=True`` adds transfer-source usage to every resource.
    """
    tm = TransientMemory(device, plan, no_alias=no_alias)
    try:
        members: dict[int, list[tuple[ResourcePlan, Image | Buffer]]] = {}
        for r in _transients(plan):
            if r.kind == "image":
                res: Image | Buffer = Image(device, r.width, r.height, r.format,
                                            _image_usages(r, readback), mips=r.mips,
                                            layers=r.layers, samples=r.samples, label=r.name)
                tm.images[r.name] = res
            else:
                res = Buffer(device, r.raw_bytes, _buffer_usages(r, readback), label=r.name)
                tm.buffers[r.name] = res
            members.setdefault(r.heap, []).append((r, res))
        if no_alias:
            for k, (r, res) in enumerate(pair for group in members.values() for pair in group):
                mem = DeviceMemory(device, res.size, res.type_bits, label=f"{r.name}:memory")
                tm.memories.append(mem)
                res.bind(mem, 0)
                tm.placements[r.name] = Placement(r.name, k, 0, res.size, res.alignment, r.bytes)
            return tm
        _check_plan(plan, device, members)
        for h, heap_bytes in enumerate(plan.heaps):
            group = members.get(h, [])
            if not group:
                continue
            heap = Heap.for_resources(device, [res for _, res in group], heap_bytes,
                                      label=f"{plan.name}:heap{h}")
            tm.memories.append(heap)
            for r, res in group:
                heap.bind(res, r.offset)
                tm.placements[r.name] = Placement(r.name, len(tm.memories) - 1, r.offset,
                                                  res.size, res.alignment, r.bytes)
    except BaseException:
        tm.destroy()
        raise
    return tm


def _check_plan(plan: CompiledGraph, device: VkDevice,
                members: Mapping[int, list[tuple[ResourcePlan, Image | Buffer]]]) -> None:
    problems = []
    granularity = device.limits["bufferImageGranularity"]
    for h, group in members.items():
        kinds = {r.kind for r, _ in group}
        for r, res in group:
            if res.size > r.bytes:
                problems.append(f"'{r.name}': the driver needs {res.size} bytes, the plan "
                                f"reserves {r.bytes}")
            if r.offset % res.alignment:
                problems.append(f"'{r.name}': planned offset {r.offset} is not a multiple of "
                                f"the driver's alignment {res.alignment}")
            if len(kinds) > 1 and (r.offset % granularity or r.bytes % granularity):
                problems.append(f"'{r.name}': heap {h} mixes images and buffers, so offsets "
                                f"and sizes must be multiples of bufferImageGranularity "
                                f"({granularity})")
    if problems:
        raise PlanMismatchError(
            f"the memory plan of '{plan.name}' does not fit {device.name}:\n  "
            + "\n  ".join(problems)
            + "\ncompile with memory=vkext.memory.memory_options(plan, device)")


# ---------------------------------------------------------------------------------------------
# persistent resources: blocks with first-fit sub-allocation


@dataclass(eq=False)
class SubAllocation:
    """A range of a block; ``linear`` is True for buffers (and linear images)."""

    block: _Block
    offset: int
    size: int
    linear: bool
    label: str = ""

    @property
    def memory(self) -> DeviceMemory:
        return self.block.memory

    @property
    def end(self) -> int:
        return self.offset + self.size

    def free(self) -> None:
        self.block.owner.free(self)


class _Block:
    def __init__(self, owner: BlockAllocator, memory: DeviceMemory):
        self.owner, self.memory = owner, memory
        self.allocs: list[SubAllocation] = []  # sorted by offset

    @property
    def used(self) -> int:
        return sum(a.size for a in self.allocs)

    def gaps(self) -> list[tuple[int, int]]:
        out, cursor = [], 0
        for a in self.allocs:
            if a.offset > cursor:
                out.append((cursor, a.offset))
            cursor = max(cursor, a.end)
        if cursor < self.memory.size:
            out.append((cursor, self.memory.size))
        return out

    def fit(self, size: int, alignment: int, linear: bool, granularity: int) -> int | None:
        """First fit: the lowest offset where the range fits, aligned, and shares no
        bufferImageGranularity page with a neighbour of the other kind."""
        def page(x: int) -> int:
            return x // granularity

        prev: SubAllocation | None = None
        for i in range(len(self.allocs) + 1):
            nxt = self.allocs[i] if i < len(self.allocs) else None
            start = prev.end if prev else 0
            stop = nxt.offset if nxt else self.memory.size
            o = align_up(start, alignment)
            if prev and prev.linear != linear and page(prev.end - 1) == page(o):
                o = align_up(o, max(alignment, granularity))
            fits = o + size <= stop
            if fits and nxt and nxt.linear != linear and page(o + size - 1) == page(nxt.offset):
                fits = False
            if fits:
                return o
            prev = nxt
        return None

    def insert(self, a: SubAllocation) -> None:
        bisect.insort(self.allocs, a, key=lambda x: x.offset)


class BlockAllocator:
    """Persistent resources (meshes, textures, history images) sub-allocated from large
    blocks, one list of blocks per memory type; a request larger than a block gets a block
    of its own. First fit, alignment and ``bufferImageGranularity`` respected."""

    def __init__(self, device: VkDevice, *, block_size: int = 64 * MiB,
                 label: str = "blocks"):
        self.device, self.block_size, self.label = device, int(block_size), label
        self.granularity = max(1, int(device.limits["bufferImageGranularity"]))
        self.blocks: dict[int, list[_Block]] = {}
        self.resources: list[Image | Buffer] = []  # what create_* made, destroyed with it
        device.register(self)

    def allocate(self, size: int, alignment: int, type_bits: int, *, linear: bool,
                 host_visible: bool = False, label: str = "") -> SubAllocation:
        required = [HOST_VISIBLE, HOST_COHERENT] if host_visible else []
        type_index = find_memory_type(self.device, type_bits, required,
                                      [] if host_visible else [DEVICE_LOCAL])
        blocks = self.blocks.setdefault(type_index, [])
        for block in blocks:
            o = block.fit(size, alignment, linear, self.granularity)
            if o is not None:
                break
        else:
            block_bytes = max(self.block_size, align_up(size, self.granularity))
            mem = DeviceMemory(self.device, block_bytes, 1 << type_index,
                               host_visible=host_visible,
                               label=f"{self.label}:block{sum(map(len, self.blocks.values()))}")
            block = _Block(self, mem)
            blocks.append(block)
            o = 0
        a = SubAllocation(block, o, int(size), linear, label)
        block.insert(a)
        return a

    def free(self, a: SubAllocation) -> None:
        block = a.block
        if a not in block.allocs:
            return
        block.allocs.remove(a)
        self.resources = [r for r in self.resources if r._allocation is not a]
        blocks = self.blocks.get(block.memory.type_index, [])
        # an empty block goes back unless it is the last regular one of its type
        if not block.allocs and (len(blocks) > 1 or block.memory.size > self.block_size):
            blocks.remove(block)
            block.memory.destroy()

    def _bind(self, res: Image | Buffer, *, host_visible: bool) -> Image | Buffer:
        try:
            a = self.allocate(res.size, res.alignment, res.type_bits,
                              linear=isinstance(res, Buffer), host_visible=host_visible,
                              label=res.label)
            res._allocation = a
            res.bind(a.memory, a.offset)
        except BaseException:
            res.destroy()
            raise
        self.resources.append(res)
        return res

    def create_image(self, width: int, height: int, format: str, usage: Iterable[str] | int,
                     *, mips: int = 1, layers: int = 1, samples: int = 1,
                     label: str = "") -> Image:
        img = Image(self.device, width, height, format, usage, mips=mips, layers=layers,
                    samples=samples, label=label)
        return self._bind(img, host_visible=False)  # type: ignore[return-value]

    def create_buffer(self, size: int, usage: Iterable[str] | int, *,
                      host_visible: bool = False, label: str = "") -> Buffer:
        buf = Buffer(self.device, size, usage, label=label)
        return self._bind(buf, host_visible=host_visible)  # type: ignore[return-value]

    def stats(self) -> dict[str, int]:
        blocks = [b for bs in self.blocks.values() for b in bs]
        block_bytes = sum(b.memory.size for b in blocks)
        used = sum(b.used for b in blocks)
        gaps = [e - s for b in blocks for s, e in b.gaps()]
        return {"blocks": len(blocks), "block_bytes": block_bytes, "used_bytes": used,
                "free_bytes": block_bytes - used,
                "allocations": sum(len(b.allocs) for b in blocks),
                "largest_free": max(gaps, default=0)}

    def destroy(self) -> None:
        for res in self.resources:
            res.destroy()
        self.resources.clear()
        for blocks in self.blocks.values():
            for b in blocks:
                b.memory.destroy()
        self.blocks.clear()
        self.device.unregister(self)
