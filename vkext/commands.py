"""Command pools, one-time submits, timestamps, barriers from rfw states, uploads and readbacks.

Barriers take the compiler's :class:`rfw.graph.sync.State` (synchronization2 names without
prefixes or ``_BIT``) and map them back: layout ``X`` -> ``VK_IMAGE_LAYOUT_X``, stage ``Y`` ->
``VK_PIPELINE_STAGE_2_Y_BIT`` (``TASK_SHADER_EXT`` -> ``..._TASK_SHADER_BIT_EXT``), access ``Z``
-> ``VK_ACCESS_2_Z_BIT``, ``NONE`` -> 0.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from rfw.graph.compile import Barrier
from rfw.graph.formats import format_info
from rfw.graph.sync import State

from .buffers import Buffer, staging_buffer
from .consts import const, ffi, flag_name, lib, vk
from .device import VkDevice
from .images import Image, aspect_flags, numpy_dtype

FENCE_TIMEOUT_NS = 60 * 10**9
NONE: frozenset[str] = frozenset()


# ---------------------------------------------------------------------------------------------
# synchronization2 names


@lru_cache(maxsize=512)
def _names(prefix: str, names: frozenset[str]) -> int:
    out = 0
    for n in names:
        if n != "NONE":
            out |= const(flag_name(prefix, n))
    return out


def stage_flags(names: Iterable[str] | str | int) -> int:
    """``{"COPY", "TASK_SHADER_EXT"}`` -> ``VkPipelineStageFlags2``."""
    if isinstance(names, int):
        return names
    return _names("VK_PIPELINE_STAGE_2_", frozenset({names} if isinstance(names, str) else names))


def access_flags(names: Iterable[str] | str | int) -> int:
    """``{"SHADER_SAMPLED_READ"}`` -> ``VkAccessFlags2``."""
    if isinstance(names, int):
        return names
    return _names("VK_ACCESS_2_", frozenset({names} if isinstance(names, str) else names))


@lru_cache(maxsize=64)
def image_layout(name: str | None) -> int:
    """``"COLOR_ATTACHMENT_OPTIMAL"`` -> ``VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL``."""
    return const(f"VK_IMAGE_LAYOUT_{name or 'UNDEFINED'}")


def as_state(x: State | str | None, *, source: bool) -> State:
    """A State from a State or a bare layout name: a bare layout waits for, or blocks,
    everything (ALL_COMMANDS with memory read/write), the safe choice when nothing better
    is known."""
    if isinstance(x, State):
        return x
    layout = x or "UNDEFINED"
    if layout == "UNDEFINED":
        return State("UNDEFINED", NONE, NONE)
    access = {"MEMORY_WRITE"} if source else {"MEMORY_READ", "MEMORY_WRITE"}
    return State(layout, frozenset({"ALL_COMMANDS"}), frozenset(access))


# ---------------------------------------------------------------------------------------------
# barriers


@dataclass(frozen=True)
class ImageBarrier:
    """One image transition; ``image`` is an :class:`Image` or a raw ``VkImage`` (then give
    ``aspect``). ``mips``/``layers`` are (first, count); default: all."""

    image: Any
    src: State | str | None
    dst: State | str | None
    aspect: int | None = None
    mips: tuple[int, int] | None = None
    layers: tuple[int, int] | None = None


@dataclass(frozen=True)
class BufferBarrier:
    buffer: Any
    src: State | str | None
    dst: State | str | None
    offset: int = 0
    size: int | None = None  # None: the whole buffer


@lru_cache(maxsize=1024)
def _masks(src: State | str | None, dst: State | str | None) -> tuple[int, ...]:
    # a transition's stage and access masks and layouts: the same each frame it is recorded
    s, d = as_state(src, source=True), as_state(dst, source=False)
    return (stage_flags(s.stages), access_flags(s.access), stage_flags(d.stages),
            access_flags(d.access), image_layout(s.layout), image_layout(d.layout))


def _image_barrier(out: Any, b: ImageBarrier) -> None:
    img = b.image
    handle = img.handle if isinstance(img, Image) else img
    aspect = b.aspect or (img.aspect if isinstance(img, Image) else vk.VK_IMAGE_ASPECT_COLOR_BIT)
    out.sType = const("VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER_2")
    (out.srcStageMask, out.srcAccessMask, out.dstStageMask, out.dstAccessMask,
     out.oldLayout, out.newLayout) = _masks(b.src, b.dst)
    out.srcQueueFamilyIndex = out.dstQueueFamilyIndex = vk.VK_QUEUE_FAMILY_IGNORED
    out.image = handle
    r = out.subresourceRange
    r.aspectMask = aspect
    r.baseMipLevel, r.levelCount = b.mips or (0, vk.VK_REMAINING_MIP_LEVELS)
    r.baseArrayLayer, r.layerCount = b.layers or (0, vk.VK_REMAINING_ARRAY_LAYERS)


def _buffer_barrier(out: Any, b: BufferBarrier) -> None:
    buf = b.buffer
    out.sType = const("VK_STRUCTURE_TYPE_BUFFER_MEMORY_BARRIER_2")
    (out.srcStageMask, out.srcAccessMask, out.dstStageMask,
     out.dstAccessMask) = _masks(b.src, b.dst)[:4]
    out.srcQueueFamilyIndex = out.dstQueueFamilyIndex = vk.VK_QUEUE_FAMILY_IGNORED
    out.buffer = buf.handle if isinstance(buf, Buffer) else buf
    out.offset = b.offset
    out.size = const("VK_WHOLE_SIZE") if b.size is None else b.size


def barrier(cmd: Any, image_barriers: Iterable[ImageBarrier | tuple] = (),
            buffer_barriers: Iterable[BufferBarrier | tuple] = (),
            memory_barriers: Iterable[tuple[State, State]] = ()) -> None:
    """Record one ``vkCmdPipelineBarrier2``; tuples are (resource, src, dst, ...)."""
    images = [b if isinstance(b, ImageBarrier) else ImageBarrier(*b) for b in image_barriers]
    buffers = [b if isinstance(b, BufferBarrier) else BufferBarrier(*b) for b in buffer_barriers]
    memory = list(memory_barriers)
    if not (images or buffers or memory):
        return
    # the structs are a function of the handles, states and ranges alone: a frame that
    # records the same barriers again (every frame, per pass) reuses the ones made first
    key = (tuple(map(_image_key, images)), tuple(map(_buffer_key, buffers)), tuple(memory))
    try:
        made = _DEPENDENCIES.get(key)
    except TypeError:  # e.g. ranges given as lists: made for this call only
        made = key = None
    if made is None:
        made = _dependency(images, buffers, memory)
        if key is not None:
            if len(_DEPENDENCIES) >= _MAX_DEPENDENCIES:
                _DEPENDENCIES.clear()
            _DEPENDENCIES[key] = made
    lib.vkCmdPipelineBarrier2(cmd, made[0])


# made VkDependencyInfo (with the arrays it points into) by what they hold
_DEPENDENCIES: dict[tuple, tuple[Any, list]] = {}
_MAX_DEPENDENCIES = 4096


def _image_key(b: ImageBarrier) -> tuple:
    img = b.image
    if isinstance(img, Image):
        return (img.handle, b.aspect or img.aspect, b.src, b.dst, b.mips, b.layers)
    return (img, b.aspect or vk.VK_IMAGE_ASPECT_COLOR_BIT, b.src, b.dst, b.mips, b.layers)


def _buffer_key(b: BufferBarrier) -> tuple:
    buf = b.buffer
    return (buf.handle if isinstance(buf, Buffer) else buf, b.src, b.dst, b.offset, b.size)


def _dependency(images: list[ImageBarrier], buffers: list[BufferBarrier],
                memory: list[tuple[State, State]]) -> tuple[Any, list]:
    dep = ffi.new("VkDependencyInfo*")
    dep.sType = const("VK_STRUCTURE_TYPE_DEPENDENCY_INFO")
    keep = []
    if images:
        arr = ffi.new("VkImageMemoryBarrier2[]", len(images))
        for i, b in enumerate(images):
            _image_barrier(arr[i], b)
        dep.imageMemoryBarrierCount, dep.pImageMemoryBarriers = len(images), arr
        keep.append(arr)
    if buffers:
        arr = ffi.new("VkBufferMemoryBarrier2[]", len(buffers))
        for i, b in enumerate(buffers):
            _buffer_barrier(arr[i], b)
        dep.bufferMemoryBarrierCount, dep.pBufferMemoryBarriers = len(buffers), arr
        keep.append(arr)
    if memory:
        arr = ffi.new("VkMemoryBarrier2[]", len(memory))
        for i, (s, d) in enumerate(memory):
            s, d = as_state(s, source=True), as_state(d, source=False)
            m = arr[i]
            m.sType = const("VK_STRUCTURE_TYPE_MEMORY_BARRIER_2")
            m.srcStageMask, m.srcAccessMask = stage_flags(s.stages), access_flags(s.access)
            m.dstStageMask, m.dstAccessMask = stage_flags(d.stages), access_flags(d.access)
        dep.memoryBarrierCount, dep.pMemoryBarriers = len(memory), arr
        keep.append(arr)
    return dep, keep


# a plan resource synchronized by memory barriers: acceleration structures (their accesses
# are acceleration-structure accesses of memory, not of a buffer range the plan owns)
class _GlobalMemory:
    def __repr__(self) -> str:
        return "GLOBAL"


GLOBAL = _GlobalMemory()


def record_barriers(cmd: Any, barriers: Iterable[Barrier],
                    resources: Mapping[str, Image | Buffer]) -> int:
    """Record a compiled plan's barriers (e.g. those of one pass) as one pipeline barrier.
    Returns how many were recorded. Every resource must be in ``resources``; one given as
    :data:`GLOBAL` (acceleration structures) gets a global memory barrier."""
    images, buffers, memory = [], [], []
    for b in barriers:
        res = resources.get(b.resource)
        if res is None:
            raise KeyError(f"barrier of pass '{b.pass_name}' names '{b.resource}', which is "
                           "not among the resources given (external? pass it in resources)")
        if res is GLOBAL:
            memory.append((b.src, b.dst))
        elif isinstance(res, Image):  # a barrier between steps may cover some mips only
            images.append(ImageBarrier(res, b.src, b.dst, mips=b.mips))
        else:
            buffers.append(BufferBarrier(res, b.src, b.dst, *(b.bytes or (0, None))))
    barrier(cmd, images, buffers, memory)
    return len(images) + len(buffers) + len(memory)


# ---------------------------------------------------------------------------------------------
# command pools and submission


class CommandPool:
    """A command pool on the device's queue family (resettable command buffers)."""

    def __init__(self, device: VkDevice, *, transient: bool = True, label: str = "commands"):
        self.device, self.label = device, label
        flags = vk.VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT
        if transient:
            flags |= vk.VK_COMMAND_POOL_CREATE_TRANSIENT_BIT
        info = vk.VkCommandPoolCreateInfo(flags=flags, queueFamilyIndex=device.queue_family)
        self.handle = vk.vkCreateCommandPool(device.device, info, None)
        device.register(self)
        device.set_name(self.handle, "COMMAND_POOL", label)

    def allocate(self, count: int = 1) -> list[Any]:
        info = vk.VkCommandBufferAllocateInfo(commandPool=self.handle,
                                              level=vk.VK_COMMAND_BUFFER_LEVEL_PRIMARY,
                                              commandBufferCount=count)
        return list(vk.vkAllocateCommandBuffers(self.device.device, info))

    def free(self, cmds: Sequence[Any]) -> None:
        if cmds and self.handle is not None:
            vk.vkFreeCommandBuffers(self.device.device, self.handle, len(cmds), list(cmds))

    def reset(self) -> None:
        vk.vkResetCommandPool(self.device.device, self.handle, 0)

    def destroy(self) -> None:
        if self.handle is not None and self.device.alive:
            vk.vkDestroyCommandPool(self.device.device, self.handle, None)
        self.handle = None
        self.device.unregister(self)


def _shared_pool(device: VkDevice) -> CommandPool:
    pool = getattr(device, "_one_time_pool", None)
    if pool is None or pool.handle is None:
        pool = CommandPool(device, label="vkext:one_time")
        device._one_time_pool = pool  # type: ignore[attr-defined]
    return pool


def submit(device: VkDevice, cmds: Sequence[Any], *, wait: bool = True) -> Any:
    """Submit with ``vkQueueSubmit2``; with ``wait`` block on a fence and return None,
    otherwise return the fence (the caller waits and destroys it)."""
    fence = vk.vkCreateFence(device.device, vk.VkFenceCreateInfo(), None)
    try:
        infos = ffi.new("VkCommandBufferSubmitInfo[]", len(cmds))
        for i, c in enumerate(cmds):
            infos[i].sType = const("VK_STRUCTURE_TYPE_COMMAND_BUFFER_SUBMIT_INFO")
            infos[i].commandBuffer = c
        info = ffi.new("VkSubmitInfo2*")
        info.sType = const("VK_STRUCTURE_TYPE_SUBMIT_INFO_2")
        info.commandBufferInfoCount, info.pCommandBufferInfos = len(cmds), infos
        vk.vkQueueSubmit2(device.queue, 1, info, fence)
        if not wait:
            return fence
        vk.vkWaitForFences(device.device, 1, [fence], vk.VK_TRUE, FENCE_TIMEOUT_NS)
    except BaseException:
        vk.vkDeviceWaitIdle(device.device)
        vk.vkDestroyFence(device.device, fence, None)
        raise
    vk.vkDestroyFence(device.device, fence, None)
    return None


@contextmanager
def one_time(device: VkDevice, *, label: str | None = None) -> Iterator[Any]:
    """Record a command buffer in the ``with`` block, then submit it and wait.
    An exception in the block discards the commands."""
    pool = _shared_pool(device)
    cmd = pool.allocate(1)[0]
    try:
        vk.vkBeginCommandBuffer(cmd, vk.VkCommandBufferBeginInfo(
            flags=vk.VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT))
        if label:
            begin_label(device, cmd, label)
        yield cmd
        if label:
            end_label(device, cmd)
        vk.vkEndCommandBuffer(cmd)
        submit(device, [cmd])
    finally:
        pool.free([cmd])


# ---------------------------------------------------------------------------------------------
# debug labels


def begin_label(device: VkDevice, cmd: Any, text: str,
                color: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)) -> None:
    if device.debug_utils:
        device.fn.vkCmdBeginDebugUtilsLabelEXT(cmd, vk.VkDebugUtilsLabelEXT(
            pLabelName=text, color=list(color)))


def end_label(device: VkDevice, cmd: Any) -> None:
    if device.debug_utils:
        device.fn.vkCmdEndDebugUtilsLabelEXT(cmd)


@contextmanager
def label(device: VkDevice, cmd: Any, text: str,
          color: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)) -> Iterator[None]:
    """A debug label around the commands recorded in the block (no-op without debug utils)."""
    begin_label(device, cmd, text, color)
    try:
        yield
    finally:
        end_label(device, cmd)


# ---------------------------------------------------------------------------------------------
# timestamps


class TimestampPool:
    """A ``VK_QUERY_TYPE_TIMESTAMP`` pool; results in nanoseconds."""

    def __init__(self, device: VkDevice, count: int, *, label: str = "timestamps"):
        device.require("timestamp")
        self.device, self.count, self.label = device, int(count), label
        info = vk.VkQueryPoolCreateInfo(queryType=vk.VK_QUERY_TYPE_TIMESTAMP,
                                        queryCount=self.count)
        self.handle = vk.vkCreateQueryPool(device.device, info, None)
        device.register(self)
        device.set_name(self.handle, "QUERY_POOL", label)
        bits = device.timestamp_bits
        self.mask = (1 << bits) - 1 if bits < 64 else (1 << 64) - 1
        if "host_query_reset" in device.caps:
            self.reset()

    def reset(self, cmd: Any = None) -> None:
        """Reset every query: on the host (host query reset) or recorded into ``cmd``."""
        if cmd is None:
            self.device.require("host_query_reset")
            vk.vkResetQueryPool(self.device.device, self.handle, 0, self.count)
        else:
            vk.vkCmdResetQueryPool(cmd, self.handle, 0, self.count)

    def write(self, cmd: Any, stage: Iterable[str] | str | int, index: int) -> None:
        """``vkCmdWriteTimestamp2`` after the work of ``stage`` (e.g. ``"ALL_COMMANDS"``)."""
        if not 0 <= index < self.count:
            raise IndexError(f"timestamp {index} outside pool '{self.label}' of {self.count}")
        flags = stage_flags(stage)
        if flags & (flags - 1):
            raise ValueError(f"a timestamp is written after one stage, not {stage}")
        vk.vkCmdWriteTimestamp2(cmd, flags, self.handle, index)

    def results(self, first: int = 0, count: int | None = None) -> list[int]:
        """Nanoseconds on the device clock, waiting until every query is available."""
        count = self.count - first if count is None else count
        data = ffi.new("uint64_t[]", count)
        vk.vkGetQueryPoolResults(self.device.device, self.handle, first, count, 8 * count, data,
                                 8, vk.VK_QUERY_RESULT_64_BIT | vk.VK_QUERY_RESULT_WAIT_BIT)
        period = self.device.timestamp_period
        return [round((data[i] & self.mask) * period) for i in range(count)]

    def destroy(self) -> None:
        if self.handle is not None and self.device.alive:
            vk.vkDestroyQueryPool(self.device.device, self.handle, None)
        self.handle = None
        self.device.unregister(self)


# ---------------------------------------------------------------------------------------------
# uploads and readbacks through staging buffers

TRANSFER_DST = State("TRANSFER_DST_OPTIMAL", frozenset({"COPY"}), frozenset({"TRANSFER_WRITE"}))
TRANSFER_SRC = State("TRANSFER_SRC_OPTIMAL", frozenset({"COPY"}), frozenset({"TRANSFER_READ"}))
HOST_READ = State(None, frozenset({"HOST"}), frozenset({"HOST_READ"}))
COPY_WRITE = State(None, frozenset({"COPY"}), frozenset({"TRANSFER_WRITE"}))
COPY_READ = State(None, frozenset({"COPY"}), frozenset({"TRANSFER_READ"}))
# the default reader of uploaded bytes: every stage, any access
ANY_ACCESS = State(None, frozenset({"ALL_COMMANDS"}), frozenset({"MEMORY_READ", "MEMORY_WRITE"}))


def copy_image_to_buffer(cmd: Any, image: Image, buffer: Buffer, *, mip: int = 0,
                         layer: int = 0, aspect: str | int | None = None,
                         layout: str = "TRANSFER_SRC_OPTIMAL") -> None:
    """Record a tightly packed copy of one mip/layer (and aspect) of ``image`` into
    ``buffer`` at offset 0; the image must be in ``layout`` by then."""
    w, h = max(1, image.width >> mip), max(1, image.height >> mip)
    vk.vkCmdCopyImageToBuffer(cmd, image.handle, image_layout(layout), buffer.handle, 1,
                              [_copy_region(_copy_aspect(image.format, aspect), w, h, mip,
                                            layer)])


def copy_into_uniforms(cmd: Any, source: Buffer, dst: Buffer, region: Any,
                       readers: State) -> None:
    """Record the copy of ``region`` (a ``VkBufferCopy*``) of ``source`` into ``dst``, a
    uniform range ``readers`` read every frame: after their reads recorded or submitted
    before it on the queue, before theirs after it."""
    rng = (region.dstOffset, region.size)
    barrier(cmd, buffer_barriers=[BufferBarrier(dst, readers, COPY_WRITE, *rng)])
    lib.vkCmdCopyBuffer(cmd, source.handle, dst.handle, 1, region)
    barrier(cmd, buffer_barriers=[BufferBarrier(dst, COPY_WRITE, readers, *rng)])


def copy_buffer_to_image(cmd: Any, buffer: Buffer, image: Image, *, mip: int = 0,
                         layer: int = 0, aspect: str | int | None = None,
                         layout: str = "TRANSFER_DST_OPTIMAL") -> None:
    """Record a copy of tightly packed texels at offset 0 of ``buffer`` into one mip/layer
    of ``image``, which must be in ``layout`` by then."""
    w, h = max(1, image.width >> mip), max(1, image.height >> mip)
    vk.vkCmdCopyBufferToImage(cmd, buffer.handle, image.handle, image_layout(layout), 1,
                              [_copy_region(_copy_aspect(image.format, aspect), w, h, mip,
                                            layer)])


def readback_bytes(image: Image, *, mip: int = 0, aspect: str | int | None = None) -> int:
    """Bytes ``copy_image_to_buffer`` writes for one mip/layer."""
    w, h = max(1, image.width >> mip), max(1, image.height >> mip)
    return w * h * _texel_bytes(image.format, _copy_aspect(image.format, aspect))


def texels(raw: np.ndarray, image: Image, *, mip: int = 0,
           aspect: str | int | None = None) -> np.ndarray:
    """Bytes from ``copy_image_to_buffer`` as an (h, w, channels) array of the format's
    channel type (depth-stencil: uint32 depth words or uint8 stencil)."""
    w, h = max(1, image.width >> mip), max(1, image.height >> mip)
    info = format_info(image.format)
    if info.depth and info.stencil:
        stencil = _copy_aspect(image.format, aspect) == vk.VK_IMAGE_ASPECT_STENCIL_BIT
        dtype, channels = np.dtype(np.uint8 if stencil else np.uint32), 1
    else:
        dtype, channels = numpy_dtype(image.format)
    return raw.view(dtype).reshape(h, w, channels)


def _copy_region(aspect: int, w: int, h: int, mip: int, layer: int) -> Any:
    return vk.VkBufferImageCopy(
        bufferOffset=0, bufferRowLength=0, bufferImageHeight=0,
        imageSubresource=vk.VkImageSubresourceLayers(aspectMask=aspect, mipLevel=mip,
                                                     baseArrayLayer=layer, layerCount=1),
        imageOffset=vk.VkOffset3D(x=0, y=0, z=0), imageExtent=vk.VkExtent3D(width=w, height=h,
                                                                           depth=1))


def _copy_aspect(fmt: str, aspect: str | int | None) -> int:
    if isinstance(aspect, int):
        return aspect
    if aspect is not None:
        return const(f"VK_IMAGE_ASPECT_{aspect.upper()}_BIT")
    flags = aspect_flags(fmt)
    # a copy moves one aspect: depth first for depth-stencil formats
    return flags & vk.VK_IMAGE_ASPECT_DEPTH_BIT or flags


def _texel_bytes(fmt: str, aspect: int) -> int:
    info = format_info(fmt)
    if info.depth and info.stencil:  # packed: depth copies out as 4 bytes, stencil as 1
        return 1 if aspect == vk.VK_IMAGE_ASPECT_STENCIL_BIT else 4
    return info.block_bytes


def record_upload(cmd: Any, staging: Buffer, *,
                  buffers: Sequence[tuple[Buffer, int, int]] = (),
                  images: Sequence[tuple[Image, Sequence[tuple[int, int, int, int]]]] = (),
                  buffers_to: State | None = None,
                  images_to: State | str = "SHADER_READ_ONLY_OPTIMAL") -> None:
    """Record copies out of ``staging`` (written by the host before the submit) and their
    barriers: ``buffers`` are (dst, staging offset, bytes) into offset 0 of dst, ``images``
    (image, [(staging offset, mip, width, height)]) of fresh images (their old contents are
    discarded). Afterwards the images are in ``images_to`` and the buffers' bytes are
    visible to ``buffers_to`` (default: every stage)."""
    barrier(cmd, [ImageBarrier(img, "UNDEFINED", TRANSFER_DST) for img, _ in images])
    for dst, offset, size in buffers:
        vk.vkCmdCopyBuffer(cmd, staging.handle, dst.handle, 1,
                           [vk.VkBufferCopy(srcOffset=offset, dstOffset=0, size=size)])
    for img, regions in images:
        _copy_bands(cmd, staging, img, [(offset, mip, 0, w, h) for offset, mip, w, h in regions])
    after = buffers_to or ANY_ACCESS
    # one memory barrier covers every buffer copied
    barrier(cmd, [ImageBarrier(img, TRANSFER_DST, images_to) for img, _ in images],
            memory_barriers=[(COPY_WRITE, after)] if buffers else ())


def _copy_bands(cmd: Any, staging: Buffer, image: Image,
                bands: Sequence[tuple[int, int, int, int, int]]) -> None:
    """One ``vkCmdCopyBufferToImage`` of (staging offset, mip, first row, width, rows)
    regions into ``image``, which is in TRANSFER_DST."""
    arr = ffi.new("VkBufferImageCopy[]", len(bands))
    for i, (offset, mip, y, w, rows) in enumerate(bands):
        r = arr[i]
        r.bufferOffset = offset
        r.imageSubresource.aspectMask = image.aspect
        r.imageSubresource.mipLevel = mip
        r.imageSubresource.layerCount = 1
        r.imageOffset.y = y
        r.imageExtent.width, r.imageExtent.height, r.imageExtent.depth = w, rows, 1
    lib.vkCmdCopyBufferToImage(cmd, staging.handle, image.handle,
                               image_layout(TRANSFER_DST.layout), len(bands), arr)


def record_image_bands(cmd: Any, staging: Buffer, image: Image,
                       bands: Sequence[tuple[int, int, int, int, int]], *, first: bool,
                       last: bool, to: State | str = "SHADER_READ_ONLY_OPTIMAL") -> None:
    """Record one chunk of an image upload streamed through ``staging``: ``bands`` are
    (staging offset, mip, first row, width, rows). The ``first`` chunk discards the image's
    old contents (every mip), a later one waits for the chunk before it (the same image's
    copies), and the ``last`` leaves the image in ``to``."""
    barrier(cmd, [ImageBarrier(image, "UNDEFINED" if first else TRANSFER_DST, TRANSFER_DST)])
    _copy_bands(cmd, staging, image, bands)
    if last:
        barrier(cmd, [ImageBarrier(image, TRANSFER_DST, to)])


def upload_image(device: VkDevice, image: Image, array: Any,
                 layout_after: State | str = "SHADER_READ_ONLY_OPTIMAL", *,
                 layout_before: State | str = "UNDEFINED", mip: int = 0, layer: int = 0,
                 aspect: str | int | None = None) -> None:
    """Copy ``array`` (h x w x channels, the format's texel layout) into one mip/layer of
    ``image``, then transition it to ``layout_after`` (a State says which stages wait)."""
    info = format_info(image.format)
    expected = readback_bytes(image, mip=mip, aspect=aspect)
    if info.compressed:
        w, h = max(1, image.width >> mip), max(1, image.height >> mip)
        expected = -(-w // info.block_width) * -(-h // info.block_height) * info.block_bytes
    data = np.ascontiguousarray(array)
    if data.nbytes != expected:
        raise ValueError(f"upload to '{image.label}' ({image.format}, mip {mip}): expected "
                         f"{expected} bytes, the array has {data.nbytes} (shape {data.shape}, "
                         f"{data.dtype})")
    one = {"mips": (mip, 1), "layers": (layer, 1)}
    staging = staging_buffer(device, expected, label=f"{image.label}:upload")
    try:
        staging.write(data)
        with one_time(device, label=f"upload {image.label}") as cmd:
            barrier(cmd, [ImageBarrier(image, layout_before, TRANSFER_DST, **one)])
            copy_buffer_to_image(cmd, staging, image, mip=mip, layer=layer, aspect=aspect)
            barrier(cmd, [ImageBarrier(image, TRANSFER_DST, layout_after, **one)])
    finally:
        staging.destroy()


def read_image(device: VkDevice, image: Image, format: str | None = None,
               w: int | None = None, h: int | None = None,
               layout_now: State | str | None = None, *,
               layout_after: State | str | None = None, mip: int = 0, layer: int = 0,
               aspect: str | int | None = None) -> np.ndarray:
    """Read one mip/layer back as an (h, w, channels) array of the format's channel type.

    ``layout_now`` is how the image was last used (a State makes the copy wait for exactly
    those stages); afterwards the image is returned to ``layout_after`` (default: the layout
    it was in; an UNDEFINED image stays TRANSFER_SRC_OPTIMAL). ``format``, ``w`` and ``h``
    default to the image's own and must agree with them.
    """
    if layout_now is None:
        raise ValueError("read_image needs layout_now: the layout (or State) the image is in")
    want = (format or image.format, w or max(1, image.width >> mip),
            h or max(1, image.height >> mip))
    have = (image.format, max(1, image.width >> mip), max(1, image.height >> mip))
    if want != have:
        raise ValueError(f"read_image of '{image.label}': asked for {want}, it is {have}")
    now = as_state(layout_now, source=True)
    if layout_after is None:
        layout_after = layout_now if now.layout != "UNDEFINED" else TRANSFER_SRC
    after = as_state(layout_after, source=False)
    one = {"mips": (mip, 1), "layers": (layer, 1)}
    size = readback_bytes(image, mip=mip, aspect=aspect)
    staging = staging_buffer(device, size, readback=True, label=f"{image.label}:read")
    try:
        with one_time(device, label=f"read {image.label}") as cmd:
            barrier(cmd, [ImageBarrier(image, now, TRANSFER_SRC, **one)])
            copy_image_to_buffer(cmd, image, staging, mip=mip, layer=layer, aspect=aspect)
            images = [] if after == TRANSFER_SRC else \
                [ImageBarrier(image, TRANSFER_SRC, after, **one)]
            barrier(cmd, images, [BufferBarrier(staging, COPY_WRITE, HOST_READ)])
        raw = staging.read()
    finally:
        staging.destroy()
    return texels(raw, image, mip=mip, aspect=aspect)


def upload_buffer(device: VkDevice, buffer: Buffer, array: Any,
                  dst: State | str | None = None, *, offset: int = 0) -> None:
    """Copy ``array`` into ``buffer`` at ``offset``; ``dst`` says who reads it next
    (default: every stage)."""
    data = np.ascontiguousarray(array).reshape(-1).view(np.uint8)
    staging = staging_buffer(device, data.size, label=f"{buffer.label}:upload")
    try:
        staging.write(data)
        after = dst if isinstance(dst, State) else ANY_ACCESS
        with one_time(device, label=f"upload {buffer.label}") as cmd:
            vk.vkCmdCopyBuffer(cmd, staging.handle, buffer.handle, 1,
                               [vk.VkBufferCopy(srcOffset=0, dstOffset=offset, size=data.size)])
            barrier(cmd, buffer_barriers=[BufferBarrier(buffer, COPY_WRITE, after, offset,
                                                        data.size)])
    finally:
        staging.destroy()


def copy_to_host(cmd: Any, buffer: Buffer, staging: Buffer, size: int, *,
                 offset: int = 0) -> None:
    """Record a copy of ``size`` bytes at ``offset`` of ``buffer`` into offset 0 of the
    host-visible ``staging`` and make them visible to the host (read them after the submit
    has finished). The copy must already wait for the buffer's writers (a barrier to
    ``COPY_READ``)."""
    vk.vkCmdCopyBuffer(cmd, buffer.handle, staging.handle, 1,
                       [vk.VkBufferCopy(srcOffset=offset, dstOffset=0, size=size)])
    barrier(cmd, buffer_barriers=[BufferBarrier(staging, COPY_WRITE, HOST_READ, 0, size)])


def written_for_host(cmd: Any, buffer: Buffer, src: State, size: int) -> None:
    """Record that ``size`` bytes of the host-visible ``buffer``, written as ``src`` says
    (a shader writing mapped memory, no copy), are made visible to the host (read them
    after the submit has finished)."""
    barrier(cmd, buffer_barriers=[BufferBarrier(buffer, src, HOST_READ, 0, size)])


def read_buffer(device: VkDevice, buffer: Buffer, src: State | str | None = None, *,
                dtype: Any = np.uint8, offset: int = 0, size: int | None = None) -> np.ndarray:
    """Read ``buffer`` back; ``src`` is how it was last written (default: any stage)."""
    size = buffer.bytes - offset if size is None else size
    before = src if isinstance(src, State) else \
        State(None, frozenset({"ALL_COMMANDS"}), frozenset({"MEMORY_WRITE"}))
    staging = staging_buffer(device, size, readback=True, label=f"{buffer.label}:read")
    try:
        with one_time(device, label=f"read {buffer.label}") as cmd:
            barrier(cmd, buffer_barriers=[BufferBarrier(buffer, before, COPY_READ, offset,
                                                        size)])
            copy_to_host(cmd, buffer, staging, size, offset=offset)
        return staging.read(dtype)
    finally:
        staging.destroy()
