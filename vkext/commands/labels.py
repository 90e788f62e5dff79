"""Debug labels around recorded commands (``VK_EXT_debug_utils``); without debug utils on the
device they record nothing."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from ..consts import vk
from ..device import VkDevice


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
