"""The wgpu adapter and device rfw runs on: the features it asks for, what it can do
(``caps``) and the period of its timestamps."""

from __future__ import annotations

from typing import Any

import wgpu

from ... import env
from ...backend import GPU_ENV, get_backend, pick_gpu
from ...errors import RfwError
from ...options import UUID_PREFIX

NO_UUID = "wgpu 0.32's adapter info has no device UUID"

# wgpu features rfw asks for when the adapter has them
WANTED_FEATURES = ("timestamp-query", "float32-filterable", "rg11b10ufloat-renderable",
                   "bgra8unorm-storage", "texture-adapter-specific-format-features")


class Device:
    """A wgpu adapter and device with what rfw needs to know about them."""

    def __init__(self, *, gpu: int | str | None = None,
                 power_preference: str = "high-performance"):
        """``gpu``: the device index among the machine's GPUs or ``uuid:<hex>``
        (``RunOptions.gpu``); None: the driver's default adapter."""
        self.index: int | None = None
        self.uuid_via: str | None = None  # the Vulkan UUID a uuid: choice was resolved by
        fakes = env.get("RFW_FAKE_GPUS")
        if gpu is None and not fakes:
            self.adapter = wgpu.gpu.request_adapter_sync(power_preference=power_preference)
        else:  # that GPU among the Vulkan adapters, in the driver's order
            adapters = [a for a in wgpu.gpu.enumerate_adapters_sync()
                        if a.info.get("backend_type") == "Vulkan"]
            if fakes and adapters:  # a test aid: the first adapter, listed N times
                adapters = adapters[:1] * fakes
            listed = [("cpu" if a.info.get("adapter_type") == "CPU" else "gpu", i)
                      for i, a in enumerate(adapters)]
            found = ", ".join(a.info.get("device", "?") for a in adapters) or "none"
            if isinstance(gpu, str):  # the UUID's place among the Vulkan devices of its kind
                kind, nth = self._place_of_uuid(gpu)
                pool = [i for k, i in listed if k == kind]
                if nth >= len(pool):
                    raise RfwError(f"asks for device {gpu}, Vulkan's {kind.upper()} device "
                                   f"{nth}, and wgpu lists {len(pool)}: {found}",
                                   element=GPU_ENV)
                self.index = pool[nth]
            else:
                self.index = pick_gpu(listed, 0 if gpu is None else gpu, found)
            self.adapter = adapters[self.index]
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

    def describe(self) -> dict[str, Any]:
        # wgpu 0.32's adapter info has no device UUID: the record says so rather than guess
        return {"device": self.name, "driver": self.driver, "api": self.backend,
                "backend": "wgpu", "uuid": None, "uuid_note": NO_UUID, "index": self.index,
                "uuid_via": self.uuid_via}

    def _place_of_uuid(self, choice: str) -> tuple[str, int]:
        """The kind (``gpu``, ``cpu``) of the device ``uuid:<hex>`` names and its index among
        that kind's Vulkan devices, as the vk backend lists them; wgpu lists its Vulkan
        adapters in the same driver order (assumed, docs/multi-gpu.md)."""
        try:
            listed = get_backend("vk").list_devices()
        except RfwError as e:
            raise RfwError(f"asks for device {choice}: {NO_UUID}, and the vk backend that "
                           f"would find its index is not usable ({e.message})",
                           element=GPU_ENV) from None
        pick = pick_gpu([(d["kind"], d) for d in listed], choice,
                        ", ".join(d["name"] for d in listed), uuid_of=lambda d: d["uuid"])
        self.uuid_via = choice.removeprefix(UUID_PREFIX)
        same = [d["index"] for d in listed if d["kind"] == pick["kind"]]
        return pick["kind"], same.index(pick["index"])


def _timestamp_period(device: Any) -> float:
    # wgpu-native resolves raw ticks; the period converts them to nanoseconds
    try:
        from wgpu.backends.wgpu_native._ffi import lib

        return float(lib.wgpuQueueGetTimestampPeriod(device.queue._internal)) or 1.0
    except Exception:
        return 1.0
