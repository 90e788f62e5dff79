"""The ``wgpu`` backend as the frame driver sees it (registered in the ``rfw.backends``
entry-point group): the device (:mod:`.device`) and executor (:mod:`.executor`) behind
:class:`rfw.backend.Backend`."""

from __future__ import annotations

from typing import Any

import numpy as np

from ...backend import BackendBase
from ...errors import RfwError
from ...graph import CompiledGraph, compile
from ...graph.graph import Graph
from ...options import DEFAULT, RunOptions
from ...passes import Pass
from .device import Device
from .executor import Executor
from .scene import GpuScene


class WgpuBackend(BackendBase):
    name = "wgpu"
    auto_variants = False  # without Vulkan's capabilities, auto stands for its last option
    host_writes_depth = False  # WebGPU refuses write_texture and copies into depth textures

    def make_device(self, *, label: str | None = None,
                    options: RunOptions = DEFAULT) -> Device:
        return Device(gpu=options.gpu)

    def owns(self, device: Any) -> bool:
        return isinstance(device, Device)

    def describe(self, device: Device) -> dict[str, str]:
        return device.describe()

    def caps(self, device: Device) -> frozenset[str]:
        return frozenset(device.caps)

    def timestamps(self, device: Device) -> bool:
        return "timestamp-query" in device.features

    def fit(self, graph: Graph, device: Device, *, readback: bool = True,
            options: RunOptions = DEFAULT) -> tuple[CompiledGraph, Any]:
        plan = compile(graph)
        check_extents(plan, device.device.limits.get("max-texture-dimension-2d"), graph.source)
        return plan, None

    def scene(self, device: Device, scene: Any, camera: Any, size: tuple[int, int]) -> GpuScene:
        gpu_scene = GpuScene(device.device, scene, camera)
        gpu_scene.set_viewport(size)
        return gpu_scene

    def executor(self, device: Device, plan: CompiledGraph, passes: dict[str, Pass],
                 slots: dict[str, dict[str, str]], scene: Any, *, readback: tuple[str, ...],
                 fitted: Any, options: RunOptions = DEFAULT) -> Executor:
        return Executor(device, plan, passes, slots, scene, readback=readback, options=options)

    def read_bridge(self, executor: Executor, bridge: str, resource: str) -> np.ndarray:
        if executor.plan.resource(resource).kind == "buffer":
            raw = executor.device.device.queue.read_buffer(executor.buffer(resource))
            return np.frombuffer(raw, np.uint8)
        return executor.read(resource)

    def write_bridge(self, executor: Executor, bridge: str, resource: str,
                     data: np.ndarray) -> None:
        r = executor.plan.resource(resource)
        if r.kind == "buffer":
            executor.device.device.queue.write_buffer(executor.buffer(resource), 0,
                                                      np.ascontiguousarray(data).tobytes())
            return
        if r.format == "r32float" and data.dtype == np.uint16:  # depth16unorm's words
            data = data.astype(np.float32) / np.float32(65535)
        executor.upload(resource, data)


def check_extents(plan: Any, limit: int | None, source: str | None) -> None:
    """Every image of ``plan`` within the device's 2D limit: a clear error, not a GPU one."""
    for r in plan.resources:
        if limit and r.kind == "image" and max(r.width, r.height) > limit:
            raise RfwError(f"'{r.name}' would be {r.width}x{r.height}, over the device's "
                           f"limit of {limit} pixels per side (use a smaller --size)",
                           file=source, element="size")
