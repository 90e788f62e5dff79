"""Barriers from rfw states: :func:`barrier` records one ``vkCmdPipelineBarrier2`` (its structs
made once and reused when the same barrier is recorded again), :func:`record_barriers` a compiled
plan's barriers.

Barriers take the compiler's :class:`rfw.graph.sync.State` (synchronization2 names without
prefixes or ``_BIT``) and map them back: layout ``X`` -> ``VK_IMAGE_LAYOUT_X``, stage ``Y`` ->
``VK_PIPELINE_STAGE_2_Y_BIT`` (``TASK_SHADER_EXT`` -> ``..._TASK_SHADER_BIT_EXT``), access ``Z``
-> ``VK_ACCESS_2_Z_BIT``, ``NONE`` -> 0.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

from rfw.graph.compile import Barrier
from rfw.graph.sync import State

from ..buffers import Buffer
from ..consts import const, ffi, flag_name, lib, vk
from ..images import Image

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
