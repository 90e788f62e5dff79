"""Uploads and readbacks through staging buffers: recorded copies (buffers, images, images in
bands streamed through one staging buffer, uniforms a frame rewrites, bytes for the host) with
their barriers, and one-shot ``upload_*`` / ``read_*`` that submit and wait."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from rfw.graph.formats import format_info
from rfw.graph.sync import State

from ..buffers import Buffer, staging_buffer
from ..consts import const, ffi, lib, vk
from ..device import VkDevice
from ..images import Image, aspect_flags, numpy_dtype
from .barriers import BufferBarrier, ImageBarrier, as_state, barrier, image_layout
from .pools import one_time

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


def copy_image_out(cmd: Any, image: Image, buffer: Buffer, now: State,
                   after: State | None) -> None:
    """Record ``image`` (in state ``now``) copied into ``buffer`` at offset 0, with its
    barriers: into TRANSFER_SRC, and back to ``after`` (None or TRANSFER_SRC: it stays)."""
    barrier(cmd, [ImageBarrier(image, now, TRANSFER_SRC)])
    copy_image_to_buffer(cmd, image, buffer)
    if after is not None and after != TRANSFER_SRC:
        barrier(cmd, [ImageBarrier(image, TRANSFER_SRC, after)])


def copy_into_uniforms(cmd: Any, source: Buffer, dst: Buffer, region: Any,
                       readers: State) -> None:
    """Record the copy of ``region`` (a ``VkBufferCopy*``) of ``source`` into ``dst``, a
    uniform range ``readers`` read every frame: after their reads recorded or submitted
    before it on the queue, before theirs after it."""
    rng = (region.dstOffset, region.size)
    barrier(cmd, buffer_barriers=[BufferBarrier(dst, readers, COPY_WRITE, *rng)])
    lib.vkCmdCopyBuffer(cmd, source.handle, dst.handle, 1, region)
    barrier(cmd, buffer_barriers=[BufferBarrier(dst, COPY_WRITE, readers, *rng)])


def copy_into_buffers(cmd: Any, source: Buffer, copies: Sequence[tuple[Buffer, Any]], *,
                      before: State, after: State) -> None:
    """Record the copies ``(dst, region)`` (each region a ``VkBufferCopy*``) of ``source``
    into their buffers: after ``before``'s accesses to the ranges written, before
    ``after``'s (a frame's instance rows into every buffer that binds them)."""
    spans = [(dst, region.dstOffset, region.size) for dst, region in copies]
    barrier(cmd, buffer_barriers=[BufferBarrier(d, before, COPY_WRITE, o, n)
                                  for d, o, n in spans])
    for dst, region in copies:
        lib.vkCmdCopyBuffer(cmd, source.handle, dst.handle, 1, region)
    barrier(cmd, buffer_barriers=[BufferBarrier(d, COPY_WRITE, after, o, n)
                                  for d, o, n in spans])


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


def texel_layout(image: Image, *, mip: int = 0, aspect: str | int | None = None,
                 ) -> tuple[tuple[int, int, int], np.dtype]:
    """The (h, w, channels) shape and channel dtype :func:`texels` gives ``image``'s bytes
    (depth-stencil: uint32 depth words or uint8 stencil)."""
    w, h = max(1, image.width >> mip), max(1, image.height >> mip)
    info = format_info(image.format)
    if info.depth and info.stencil:
        stencil = _copy_aspect(image.format, aspect) == vk.VK_IMAGE_ASPECT_STENCIL_BIT
        dtype, channels = np.dtype(np.uint8 if stencil else np.uint32), 1
    else:
        dtype, channels = numpy_dtype(image.format)
    return (h, w, channels), np.dtype(dtype)


def texels(raw: np.ndarray, image: Image, *, mip: int = 0,
           aspect: str | int | None = None) -> np.ndarray:
    """Bytes from ``copy_image_to_buffer`` as an (h, w, channels) array of the format's
    channel type (:func:`texel_layout`)."""
    shape, dtype = texel_layout(image, mip=mip, aspect=aspect)
    return raw.view(dtype).reshape(shape)


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


UPDATE_LIMIT = 65536  # bytes one vkCmdUpdateBuffer may write


def record_update(cmd: Any, buffer: Buffer, data: np.ndarray, *, reader: State) -> None:
    """Record ``data`` into ``buffer`` from ``cmd`` by vkCmdUpdateBuffer (in pieces of
    ``UPDATE_LIMIT`` bytes): after ``reader``'s earlier reads of the buffer, before its next
    ones (a TLAS's instance records between the builds of two frames)."""
    raw = np.ascontiguousarray(data).reshape(-1).view(np.uint8)
    barrier(cmd, buffer_barriers=[BufferBarrier(buffer, reader, COPY_WRITE, 0, raw.size)])
    for start in range(0, raw.size, UPDATE_LIMIT):
        piece = raw[start:start + UPDATE_LIMIT]
        lib.vkCmdUpdateBuffer(cmd, buffer.handle, start, piece.size,
                              ffi.from_buffer("char[]", piece))
    barrier(cmd, buffer_barriers=[BufferBarrier(buffer, COPY_WRITE, reader, 0, raw.size)])
