"""Test-only recording helpers: stand-ins for pass work that needs no pipeline."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from rfw.graph import Attachment, DepthAttachment, GraphBuilder, Texture
from rfw.graph.graph import Graph
from vkext.consts import const, ffi, vk
from vkext.images import Image, ImageView


def unorm_codes(value: float, bits: int = 8) -> set[int]:
    """The codes Vulkan lets a driver store for ``value`` in a UNORM format: either of the
    two nearest to ``value * (2**bits - 1)`` (round to nearest is only recommended: for 0.5
    lavapipe stores 128, NVIDIA 127), or that value alone when it is a whole number."""
    r = float(np.float32(value)) * ((1 << bits) - 1)  # clear colours travel as float32
    return {math.floor(r), math.ceil(r)}


def chain_graph(n: int = 4, size: int = 256, fmt: str = "rgba8unorm") -> Graph:
    """``n`` graphics passes, each writing a ``size``² image read by the next."""
    g = GraphBuilder(f"chain{n}", size=(size, size))
    prev = None
    for i in range(n):
        p = g.add_pass(f"p{i}", "graphics")
        if prev:
            p.input("src", prev, Texture())
        p.output("color", Attachment(fmt))
        prev = f"p{i}.color"
    g.output(prev)
    return g.build()


def depth_chain_graph(size: int = 64) -> Graph:
    """Like ``chain_graph(4)``, with a depth buffer in p0 that p1 samples."""
    g = GraphBuilder("depth_chain", size=(size, size))
    g.add_pass("p0", "graphics").output("color", Attachment("rgba8unorm")) \
        .output("depth", DepthAttachment("depth32float"))
    g.add_pass("p1", "graphics").input("src", "p0.color").input("z", "p0.depth") \
        .output("color", Attachment("rgba8unorm"))
    g.add_pass("p2", "graphics").input("src", "p1.color").output("color", Attachment("rgba8unorm"))
    g.add_pass("p3", "graphics").input("src", "p2.color").output("color", Attachment("rgba8unorm"))
    g.output("p3.color")
    return g.build()


def copy_chain_graph(n: int = 4, size: int = 32) -> Graph:
    """``n`` transfer passes copying an external image along a chain of transients: copies
    are what sync validation 1.3.239 tracks best (it ignores dynamic rendering)."""
    g = GraphBuilder(f"copies{n}", size=(size, size))
    g.external("src", Texture("rgba8unorm", usage=("transfer_src",)))
    prev = "src"
    for i in range(n):
        g.add_pass(f"t{i}", "transfer").input("src", prev, Texture(usage=("transfer_src",))) \
            .output("dst", Texture("rgba8unorm", usage=("transfer_dst",)))
        prev = f"t{i}.dst"
    g.output(prev)
    return g.build()


def copy_pass(cmd, src: Image, dst: Image) -> None:
    """The whole of ``src`` into ``dst`` (TRANSFER_SRC_OPTIMAL to TRANSFER_DST_OPTIMAL)."""
    layers = vk.VkImageSubresourceLayers(aspectMask=vk.VK_IMAGE_ASPECT_COLOR_BIT, layerCount=1)
    region = vk.VkImageCopy(srcSubresource=layers, dstSubresource=layers,
                            extent=vk.VkExtent3D(width=src.width, height=src.height, depth=1))
    vk.vkCmdCopyImage(cmd, src.handle, vk.VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, dst.handle,
                      vk.VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, 1, [region])


def clear_pass(cmd, extent: tuple[int, int], colors: Sequence[tuple[ImageView, tuple]],
               depth: tuple[ImageView, float] | None = None) -> None:
    """Dynamic rendering that only clears its attachments: a real attachment write at
    COLOR_ATTACHMENT_OUTPUT / fragment tests, without a pipeline."""
    atts = ffi.new("VkRenderingAttachmentInfo[]", max(1, len(colors)))
    for i, (view, color) in enumerate(colors):
        a = atts[i]
        a.sType = const("VK_STRUCTURE_TYPE_RENDERING_ATTACHMENT_INFO")
        a.imageView = view.handle
        a.imageLayout = vk.VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL
        a.loadOp = vk.VK_ATTACHMENT_LOAD_OP_CLEAR
        a.storeOp = vk.VK_ATTACHMENT_STORE_OP_STORE
        for k in range(4):
            a.clearValue.color.float32[k] = color[k]
    info = ffi.new("VkRenderingInfo*")
    info.sType = const("VK_STRUCTURE_TYPE_RENDERING_INFO")
    info.renderArea.extent.width, info.renderArea.extent.height = extent
    info.layerCount = 1
    info.colorAttachmentCount, info.pColorAttachments = len(colors), atts
    if depth is not None:
        d = ffi.new("VkRenderingAttachmentInfo*")
        d.sType = const("VK_STRUCTURE_TYPE_RENDERING_ATTACHMENT_INFO")
        d.imageView = depth[0].handle
        d.imageLayout = const("VK_IMAGE_LAYOUT_DEPTH_ATTACHMENT_OPTIMAL")
        d.loadOp = vk.VK_ATTACHMENT_LOAD_OP_CLEAR
        d.storeOp = vk.VK_ATTACHMENT_STORE_OP_STORE
        d.clearValue.depthStencil.depth = depth[1]
        info.pDepthAttachment = d
    vk.vkCmdBeginRendering(cmd, info)
    vk.vkCmdEndRendering(cmd)
