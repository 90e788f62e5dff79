"""Images and image views: formats and usages to Vulkan flags, creation with the device's
support checked, views of chosen aspects, mips and layers."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

from rfw.errors import RfwError
from rfw.graph.formats import FormatInfo, format_info

from .allocation import DeviceMemory, Resource, flags_of
from .consts import const, vk
from .device import VkDevice


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


# wgpu formats whose Vulkan format the device picks, in order of preference
_DEVICE_CHOSEN = {
    "depth24plus": ("VK_FORMAT_X8_D24_UNORM_PACK32", "VK_FORMAT_D32_SFLOAT"),
    "depth24plus-stencil8": ("VK_FORMAT_D24_UNORM_S8_UINT", "VK_FORMAT_D32_SFLOAT_S8_UINT"),
}


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
    return flags_of(_ASPECTS[a] for a in aspect.replace("_", "|").split("|"))


def image_usage_flags(usages: Iterable[str] | int) -> int:
    if isinstance(usages, int):
        return usages
    unknown = [u for u in usages if u not in _IMAGE_USAGE]
    if unknown:
        raise ValueError(f"unknown image usage {', '.join(sorted(unknown))} "
                         f"(known: {', '.join(sorted(_IMAGE_USAGE))})")
    return flags_of(_IMAGE_USAGE[u][0] for u in usages)


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


class Image(Resource):
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
