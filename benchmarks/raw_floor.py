"""The raw-Vulkan floor of bench_scaling.py: the same geometry drawn depth-only outside the
frame graph, with nothing but what drawing needs.

One pipeline (``raw_floor.vert.glsl``: position in, the instance's transform from an
instance-rate vertex buffer, view-projection pushed; no fragment shader, no descriptor set),
one depth32float attachment cleared to 1, ``less`` test, back faces culled, WebGPU's clip space
through a negative-height viewport as rfw's vk backend draws. Two ways to draw ``k`` copies:

- ``instanced``: one ``vkCmdDrawIndexed`` of ``k`` instances;
- ``draws``: ``k`` ``vkCmdDrawIndexed`` of one instance each (``firstInstance`` picks the
  transform): rfw's draw count without its per-draw descriptor-set binds.

Each mode's command buffer is recorded once and submitted every frame (one submit and wait
a frame); GPU ms from two timestamps around the rendering.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
MODES = ("instanced", "draws")


def _pipeline(dev: Any, keep: list[Any]) -> tuple[Any, Any, Any]:
    """(module, layout, pipeline) of the depth-only program."""
    from rfw.spirv import compile_glsl
    from vkext.consts import const, ffi, new, vk

    spv = compile_glsl(HERE / "raw_floor.vert.glsl")
    words = ffi.new("uint32_t[]", len(spv.code) // 4)
    ffi.memmove(words, spv.code, len(spv.code))
    module = vk.vkCreateShaderModule(dev.device, new("VkShaderModuleCreateInfo",
                                                     codeSize=len(spv.code), pCode=words), None)
    push = ffi.new("VkPushConstantRange*")
    push.stageFlags, push.offset, push.size = const("VK_SHADER_STAGE_VERTEX_BIT"), 0, 64
    layout = vk.vkCreatePipelineLayout(dev.device, new(
        "VkPipelineLayoutCreateInfo", pushConstantRangeCount=1, pPushConstantRanges=push), None)
    stage = new("VkPipelineShaderStageCreateInfo", 1)
    entry = ffi.new("char[]", b"main")
    stage[0].stage, stage[0].module, stage[0].pName = const("VK_SHADER_STAGE_VERTEX_BIT"), \
        module, entry
    bindings = ffi.new("VkVertexInputBindingDescription[2]")
    bindings[0].binding, bindings[0].stride = 0, 12
    bindings[0].inputRate = const("VK_VERTEX_INPUT_RATE_VERTEX")
    bindings[1].binding, bindings[1].stride = 1, 64
    bindings[1].inputRate = const("VK_VERTEX_INPUT_RATE_INSTANCE")
    attrs = ffi.new("VkVertexInputAttributeDescription[5]")
    attrs[0].location, attrs[0].binding = 0, 0
    attrs[0].format, attrs[0].offset = const("VK_FORMAT_R32G32B32_SFLOAT"), 0
    for i in range(4):
        attrs[i + 1].location, attrs[i + 1].binding = i + 1, 1
        attrs[i + 1].format = const("VK_FORMAT_R32G32B32A32_SFLOAT")
        attrs[i + 1].offset = 16 * i
    vertex = new("VkPipelineVertexInputStateCreateInfo", vertexBindingDescriptionCount=2,
                 pVertexBindingDescriptions=bindings, vertexAttributeDescriptionCount=5,
                 pVertexAttributeDescriptions=attrs)
    assembly = new("VkPipelineInputAssemblyStateCreateInfo",
                   topology=const("VK_PRIMITIVE_TOPOLOGY_TRIANGLE_LIST"))
    viewport = new("VkPipelineViewportStateCreateInfo", viewportCount=1, scissorCount=1)
    raster = new("VkPipelineRasterizationStateCreateInfo",
                 polygonMode=const("VK_POLYGON_MODE_FILL"),
                 cullMode=const("VK_CULL_MODE_BACK_BIT"),
                 frontFace=const("VK_FRONT_FACE_COUNTER_CLOCKWISE"), lineWidth=1.0)
    multisample = new("VkPipelineMultisampleStateCreateInfo",
                      rasterizationSamples=const("VK_SAMPLE_COUNT_1_BIT"))
    ds = new("VkPipelineDepthStencilStateCreateInfo", depthTestEnable=1, depthWriteEnable=1,
             depthCompareOp=const("VK_COMPARE_OP_LESS"))
    blend = new("VkPipelineColorBlendStateCreateInfo", attachmentCount=0)
    dyn = ffi.new("VkDynamicState[2]", [const("VK_DYNAMIC_STATE_VIEWPORT"),
                                        const("VK_DYNAMIC_STATE_SCISSOR")])
    dynamic = new("VkPipelineDynamicStateCreateInfo", dynamicStateCount=2, pDynamicStates=dyn)
    rendering = new("VkPipelineRenderingCreateInfo", colorAttachmentCount=0,
                    depthAttachmentFormat=const("VK_FORMAT_D32_SFLOAT"))
    info = new("VkGraphicsPipelineCreateInfo", pNext=rendering, stageCount=1, pStages=stage,
               pVertexInputState=vertex, pInputAssemblyState=assembly,
               pViewportState=viewport, pRasterizationState=raster,
               pMultisampleState=multisample, pDepthStencilState=ds, pColorBlendState=blend,
               pDynamicState=dynamic, layout=layout, basePipelineIndex=-1)
    keep += [words, push, stage, entry, bindings, attrs, vertex, assembly, viewport, raster,
             multisample, ds, blend, dyn, dynamic, rendering, info]
    pipe = vk.vkCreateGraphicsPipelines(dev.device, ffi.NULL, 1, info, None)[0]
    return module, layout, pipe


def _record(cmd: Any, *, pipe: Any, layout: Any, view: Any, size: tuple[int, int],
            view_proj: np.ndarray, buffers: tuple[Any, Any, Any], count: int, instances: int,
            mode: str, stamps: Any) -> None:
    from vkext.consts import const, ffi, new, vk

    w, h = size
    stamps.reset(cmd)
    stamps.write(cmd, "ALL_COMMANDS", 0)
    depth = new("VkRenderingAttachmentInfo", imageView=view,
                imageLayout=const("VK_IMAGE_LAYOUT_DEPTH_ATTACHMENT_OPTIMAL"),
                loadOp=const("VK_ATTACHMENT_LOAD_OP_CLEAR"),
                storeOp=const("VK_ATTACHMENT_STORE_OP_STORE"))
    depth.clearValue.depthStencil.depth = 1.0
    area = ffi.new("VkRect2D*")
    area.extent.width, area.extent.height = w, h
    info = new("VkRenderingInfo", renderArea=area[0], layerCount=1, pDepthAttachment=depth)
    vk.vkCmdBeginRendering(cmd, info)
    vk.vkCmdBindPipeline(cmd, const("VK_PIPELINE_BIND_POINT_GRAPHICS"), pipe)
    # negative height: WebGPU's y-up clip space, as rfw's vk backend draws
    vk.vkCmdSetViewport(cmd, 0, 1, [vk.VkViewport(x=0, y=h, width=w, height=-h, minDepth=0,
                                                  maxDepth=1)])
    vk.vkCmdSetScissor(cmd, 0, 1, [area[0]])
    data = np.ascontiguousarray(view_proj.T, dtype=np.float32).tobytes()
    vk.vkCmdPushConstants(cmd, layout, const("VK_SHADER_STAGE_VERTEX_BIT"), 0, 64,
                          ffi.from_buffer(data))
    positions, transforms, index = buffers
    vk.vkCmdBindVertexBuffers(cmd, 0, 2, [positions.handle, transforms.handle], [0, 0])
    vk.vkCmdBindIndexBuffer(cmd, index.handle, 0, const("VK_INDEX_TYPE_UINT32"))
    if mode == "instanced":
        vk.vkCmdDrawIndexed(cmd, count, instances, 0, 0, 0)
    else:
        draw = vk.vkCmdDrawIndexed  # one call per instance, as a draw loop records them
        for k in range(instances):
            draw(cmd, count, 1, 0, 0, k)
    vk.vkCmdEndRendering(cmd)
    stamps.write(cmd, "ALL_COMMANDS", 1)


def measure(mesh: Any, transforms: np.ndarray, view_proj: np.ndarray, size: tuple[int, int],
            *, frames: int, warmup: int, modes: tuple[str, ...] = MODES,
            depth_out: dict[str, np.ndarray] | None = None) -> dict[str, list[float]]:
    """GPU ms per timed frame of each mode; ``depth_out`` (when given) receives each mode's
    last depth image as float32 (H, W)."""
    from vkext.buffers import Buffer
    from vkext.commands import (
        CommandPool,
        ImageBarrier,
        TimestampPool,
        barrier,
        read_image,
        submit,
        upload_buffer,
    )
    from vkext.consts import vk
    from vkext.device import VkDevice
    from vkext.images import Image, image_view

    dev = VkDevice(label="raw_floor")
    keep: list[Any] = []
    owned: list[Any] = []
    module = layout = pipe = None
    try:
        positions = np.ascontiguousarray(mesh.positions, dtype=np.float32)
        columns = np.ascontiguousarray(np.transpose(transforms, (0, 2, 1)), dtype=np.float32)
        indices = np.ascontiguousarray(mesh.indices, dtype=np.uint32)
        bufs = []
        for name, arr, usage in (("positions", positions, "vertex"),
                                 ("transforms", columns, "vertex"),
                                 ("indices", indices, "index")):
            b = Buffer(dev, arr.nbytes, {usage, "transfer_dst"}, label=f"raw_floor.{name}")
            owned.append(b)
            b.allocate()
            upload_buffer(dev, b, arr)
            bufs.append(b)
        w, h = size
        image = Image(dev, w, h, "depth32float", {"depth", "transfer_src"},
                      label="raw_floor.depth")
        owned.append(image)
        image.allocate()
        view = image_view(image)
        module, layout, pipe = _pipeline(dev, keep)
        stamps = TimestampPool(dev, 2, label="raw_floor.timestamps")
        owned.append(stamps)
        pool = CommandPool(dev, transient=False, label="raw_floor.commands")
        owned.append(pool)
        out: dict[str, list[float]] = {}
        for mode in modes:
            # recorded once and submitted every frame: no host work per draw or per frame
            (cmd,) = pool.allocate(1)
            vk.vkBeginCommandBuffer(cmd, vk.VkCommandBufferBeginInfo())
            barrier(cmd, [ImageBarrier(image, None, "DEPTH_ATTACHMENT_OPTIMAL")])
            _record(cmd, pipe=pipe, layout=layout, view=view.handle, size=size,
                    view_proj=view_proj, buffers=tuple(bufs), count=len(indices),
                    instances=len(transforms), mode=mode, stamps=stamps)
            vk.vkEndCommandBuffer(cmd)
            times = []
            for f in range(warmup + frames):
                submit(dev, [cmd])
                t0, t1 = stamps.results()
                if f >= warmup:
                    times.append((t1 - t0) / 1e6)
            pool.free([cmd])
            out[mode] = times
            if depth_out is not None:
                depth_out[mode] = read_image(dev, image, layout_now="DEPTH_ATTACHMENT_OPTIMAL",
                                             aspect="depth")[..., 0]
        return out
    finally:
        vk.vkDeviceWaitIdle(dev.device)
        if pipe is not None:
            vk.vkDestroyPipeline(dev.device, pipe, None)
            vk.vkDestroyPipelineLayout(dev.device, layout, None)
            vk.vkDestroyShaderModule(dev.device, module, None)
        for obj in reversed(owned):
            obj.destroy()
        dev.destroy()
