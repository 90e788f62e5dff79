"""The basic Vulkan object wrappers every module above the device shares: ``VkObject`` (a
handle registered with the device, destroyed once), samplers, descriptor set layouts and pools,
and descriptor writes (:func:`update_descriptors`).

Every wrapper registers with the device, so ``live_objects()`` counts it and
``VkDevice.destroy()`` reaches anything left behind.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from .consts import const, ffi, new, vk
from .device import VkDevice

# descriptor kinds as rfw.spirv.reflect names them
DESCRIPTOR_TYPES = {
    "uniform_buffer": "VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER",
    "storage_buffer": "VK_DESCRIPTOR_TYPE_STORAGE_BUFFER",
    "sampled_image": "VK_DESCRIPTOR_TYPE_SAMPLED_IMAGE",
    "storage_image": "VK_DESCRIPTOR_TYPE_STORAGE_IMAGE",
    "combined_image_sampler": "VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER",
    "sampler": "VK_DESCRIPTOR_TYPE_SAMPLER",
    "acceleration_structure": "VK_DESCRIPTOR_TYPE_ACCELERATION_STRUCTURE_KHR",
}

_FILTER = {"linear": "VK_FILTER_LINEAR", "nearest": "VK_FILTER_NEAREST"}
_MIPMAP = {"linear": "VK_SAMPLER_MIPMAP_MODE_LINEAR", "nearest": "VK_SAMPLER_MIPMAP_MODE_NEAREST"}
_ADDRESS = {"repeat": "VK_SAMPLER_ADDRESS_MODE_REPEAT",
            "mirror-repeat": "VK_SAMPLER_ADDRESS_MODE_MIRRORED_REPEAT",
            "clamp-to-edge": "VK_SAMPLER_ADDRESS_MODE_CLAMP_TO_EDGE"}
COMPARE = {"never": "VK_COMPARE_OP_NEVER", "less": "VK_COMPARE_OP_LESS",
           "equal": "VK_COMPARE_OP_EQUAL", "less-equal": "VK_COMPARE_OP_LESS_OR_EQUAL",
           "greater": "VK_COMPARE_OP_GREATER", "not-equal": "VK_COMPARE_OP_NOT_EQUAL",
           "greater-equal": "VK_COMPARE_OP_GREATER_OR_EQUAL", "always": "VK_COMPARE_OP_ALWAYS"}


# ---------------------------------------------------------------------------------------------
# owned Vulkan objects


class VkObject:
    """A Vulkan handle this package created: registered with the device, destroyed once."""

    destroy_fn = ""
    object_type = ""

    def __init__(self, device: VkDevice, handle: Any, label: str = ""):
        self.device, self.handle, self.label = device, handle, label
        device.register(self)
        device.set_name(handle, self.object_type, label)

    def destroy(self) -> None:
        if self.handle is not None and self.device.alive:
            getattr(vk, self.destroy_fn)(self.device.device, self.handle, None)
        self.handle = None
        self.device.unregister(self)

    def __repr__(self) -> str:
        return f"<{type(self).__name__} '{self.label}'>"


class Sampler(VkObject):
    destroy_fn, object_type = "vkDestroySampler", "SAMPLER"


class DescriptorSetLayout(VkObject):
    destroy_fn, object_type = "vkDestroyDescriptorSetLayout", "DESCRIPTOR_SET_LAYOUT"

    def __init__(self, device: VkDevice, entries: Sequence[tuple[int, str, int]], stages: int,
                 label: str = ""):
        """``entries``: (binding, kind, count) with kinds as :data:`DESCRIPTOR_TYPES` keys."""
        self.entries = tuple(sorted(entries))
        arr = ffi.new("VkDescriptorSetLayoutBinding[]", max(1, len(self.entries)))
        for i, (binding, kind, count) in enumerate(self.entries):
            arr[i].binding = binding
            arr[i].descriptorType = const(DESCRIPTOR_TYPES[kind])
            arr[i].descriptorCount = count
            arr[i].stageFlags = stages
        info = new("VkDescriptorSetLayoutCreateInfo", bindingCount=len(self.entries),
                   pBindings=arr)
        super().__init__(device, vk.vkCreateDescriptorSetLayout(device.device, info, None),
                         label)


class DescriptorPool(VkObject):
    """A pool sized for ``sets`` sets and ``per_kind`` descriptors of each kind (or the
    counts given in ``sizes``)."""

    destroy_fn, object_type = "vkDestroyDescriptorPool", "DESCRIPTOR_POOL"

    def __init__(self, device: VkDevice, sets: int, sizes: dict[str, int], label: str = ""):
        sizes = {k: n for k, n in sizes.items() if n > 0}
        arr = ffi.new("VkDescriptorPoolSize[]", max(1, len(sizes)))
        for i, (kind, n) in enumerate(sizes.items()):
            arr[i].type = const(DESCRIPTOR_TYPES[kind])
            arr[i].descriptorCount = n
        info = new("VkDescriptorPoolCreateInfo", maxSets=max(1, sets), poolSizeCount=len(sizes),
                   pPoolSizes=arr)
        super().__init__(device, vk.vkCreateDescriptorPool(device.device, info, None), label)

    def allocate(self, layouts: Sequence[Any]) -> Any:
        """``VkDescriptorSet[n]`` for the layout handles (raises ``vk.VkError`` when full)."""
        handles = ffi.new("VkDescriptorSetLayout[]", list(layouts))
        info = new("VkDescriptorSetAllocateInfo", descriptorPool=self.handle,
                   descriptorSetCount=len(layouts), pSetLayouts=handles)
        return vk.vkAllocateDescriptorSets(self.device.device, info)

    def reset(self) -> None:
        vk.vkResetDescriptorPool(self.device.device, self.handle, 0)


def make_sampler(device: VkDevice, *, mag: str = "linear", min: str = "linear",
                 mip: str = "nearest", address_u: str = "clamp-to-edge",
                 address_v: str = "clamp-to-edge", address_w: str = "clamp-to-edge",
                 compare: str | None = None, label: str = "") -> Sampler:
    """A sampler in WebGPU terms (wgpu's defaults: lod clamp 0..32, no anisotropy)."""
    info = new("VkSamplerCreateInfo")
    info.magFilter, info.minFilter = const(_FILTER[mag]), const(_FILTER[min])
    info.mipmapMode = const(_MIPMAP[mip])
    info.addressModeU = const(_ADDRESS[address_u])
    info.addressModeV = const(_ADDRESS[address_v])
    info.addressModeW = const(_ADDRESS[address_w])
    info.compareEnable = int(compare is not None)
    info.compareOp = const(COMPARE[compare or "never"])
    info.minLod, info.maxLod = 0.0, 32.0
    info.borderColor = const("VK_BORDER_COLOR_FLOAT_TRANSPARENT_BLACK")
    return Sampler(device, vk.vkCreateSampler(device.device, info, None), label)


# ---------------------------------------------------------------------------------------------
# descriptor writes


@dataclass(frozen=True)
class BufferRange:
    """A range of a buffer bound as one uniform or storage descriptor."""

    buffer: Any  # VkBuffer handle
    offset: int
    size: int


def update_descriptors(device: VkDevice, writes: Sequence[tuple[Any, int, str, tuple]]) -> None:
    """One ``vkUpdateDescriptorSets``. Each write is (set, binding, kind, payload) with
    payload (buffer, offset, range) for buffers, (view, layout) for images, (sampler,) for
    samplers, (view, layout, sampler) for combined image samplers and (handle,) for
    acceleration structures. A list of payloads fills an array binding from element 0."""
    if not writes:
        return
    arr = new("VkWriteDescriptorSet", len(writes))
    infos = []
    for i, (dst, binding, kind, payload) in enumerate(writes):
        items = payload if isinstance(payload, list) else [payload]
        w = arr[i]
        w.dstSet, w.dstBinding, w.dstArrayElement = dst, binding, 0
        w.descriptorCount = len(items)
        w.descriptorType = const(DESCRIPTOR_TYPES[kind])
        if kind in ("uniform_buffer", "storage_buffer"):
            info = ffi.new("VkDescriptorBufferInfo[]", len(items))
            for k, item in enumerate(items):
                info[k].buffer, info[k].offset, info[k].range = item
            w.pBufferInfo = info
        elif kind == "acceleration_structure":
            handles = ffi.new("VkAccelerationStructureKHR[]", [item[0] for item in items])
            info = new("VkWriteDescriptorSetAccelerationStructureKHR",
                       accelerationStructureCount=len(items), pAccelerationStructures=handles)
            w.pNext = info
            infos.append(handles)
        else:
            info = ffi.new("VkDescriptorImageInfo[]", len(items))
            for k, item in enumerate(items):
                if kind == "sampler":
                    info[k].sampler = item[0]
                else:
                    info[k].imageView, info[k].imageLayout = item[0], item[1]
                    if kind == "combined_image_sampler":
                        info[k].sampler = item[2]
            w.pImageInfo = info
        infos.append(info)
    vk.vkUpdateDescriptorSets(device.device, len(writes), arr, 0, ffi.NULL)
