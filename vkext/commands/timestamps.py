"""GPU timestamps: :class:`TimestampPool`, a ``VK_QUERY_TYPE_TIMESTAMP`` pool written after a
stage and read back in nanoseconds."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from ..consts import ffi, vk
from ..device import VkDevice
from .barriers import stage_flags


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
