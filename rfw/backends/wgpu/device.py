"""The wgpu adapter and device rfw runs on: the features it asks for, what it can do
(``caps``) and the period of its timestamps."""

from __future__ import annotations

from typing import Any

import wgpu

from ...backend import pick_gpu

# wgpu features rfw asks for when the adapter has them
WANTED_FEATURES = ("timestamp-query", "float32-filterable", "rg11b10ufloat-renderable",
                   "bgra8unorm-storage", "texture-adapter-specific-format-features")


class Device:
    """A wgpu adapter and device with what rfw needs to know about them."""

    def __init__(self, *, gpu: int | None = None, power_preference: str = "high-performance"):
        """``gpu``: the device index among the machine's GPUs (``RunOptions.gpu``); None:
        the driver's default adapter."""
        index = gpu
        if index is None:
            self.adapter = wgpu.gpu.request_adapter_sync(power_preference=power_preference)
        else:  # that GPU among the Vulkan adapters, in the driver's order
            adapters = [a for a in wgpu.gpu.enumerate_adapters_sync()
                        if a.info.get("backend_type") == "Vulkan"]
            self.adapter = pick_gpu(
                [("cpu" if a.info.get("adapter_type") == "CPU" else "gpu", a) for a in adapters],
                index, ", ".join(a.info.get("device", "?") for a in adapters) or "none")
        if self.adapter is None:
            raise RuntimeError("no wgpu adapter found (is a Vulkan driver installed?)")
        self.features = tuple(f for f in WANTED_FEATURES if f in self.adapter.features)
        self.device = self.adapter.request_device_sync(required_features=list(self.features),
                                                       label="rfw")
        info = self.adapter.info
        self.name = info.get("device", "?")
        self.driver = info.get("description", "") or info.get("driver", "")
        self.backend = info.get("backend_type", "")
        self.timestamp_period = _timestamp_period(self.device)
        self.caps = frozenset(self.features) | frozenset(self.adapter.features)

    def describe(self) -> dict[str, str]:
        return {"device": self.name, "driver": self.driver, "api": self.backend,
                "backend": "wgpu"}


def _timestamp_period(device: Any) -> float:
    # wgpu-native resolves raw ticks; the period converts them to nanoseconds
    try:
        from wgpu.backends.wgpu_native._ffi import lib

        return float(lib.wgpuQueueGetTimestampPeriod(device.queue._internal)) or 1.0
    except Exception:
        return 1.0
