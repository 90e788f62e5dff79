"""Command pools and submission: :class:`CommandPool`, :func:`submit` (``vkQueueSubmit2``, waiting
on a fence or handing it back) and :func:`one_time`, a command buffer recorded in a ``with``
block and submitted at its end."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any

from ..consts import const, ffi, vk
from ..device import VkDevice
from .labels import begin_label, end_label

FENCE_TIMEOUT_NS = 60 * 10**9


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
