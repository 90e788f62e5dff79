"""The ``vk`` backend (registered in the ``rfw.backends`` entry-point group): raw Vulkan's
device, fitted plans, executor and host copies behind :class:`rfw.backend.Backend`, so that
:func:`rfw.render.render` drives it as it drives wgpu. Also the Vulkan half of
``rfw.RayScene`` and ``rfw.raycast`` (``VkBackend.ray_scene``).

``render_vk(cfg, ...)`` is ``rfw.render.render(cfg, backend="vk", ...)``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from rfw.backend import BackendBase
from rfw.config import Config
from rfw.frame import Result
from rfw.graph import CompiledGraph
from rfw.graph.graph import Graph
from rfw.options import DEFAULT, RunOptions
from rfw.passes import Pass
from rfw.render import render
from rfw.scene.model import Scene

from .commands import read_buffer, read_image, upload_buffer, upload_image
from .device import VkDevice, list_devices
from .executor import VkExecutor
from .fitting import check_passes, fit_graph
from .frame_stats import accel_stats, culling_counters
from .scene import VkScene


class VkBackend(BackendBase):
    name = "vk"
    auto_variants = True  # ray queries, ray pipelines and mesh shaders are per device
    host_writes_depth = True

    def make_device(self, *, label: str | None = None,
                    options: RunOptions = DEFAULT) -> VkDevice:
        return VkDevice(validation=options.validation, gpu=options.gpu,
                        async_queue=options.async_queue, **({"label": label} if label else {}))

    def owns(self, device: Any) -> bool:
        return isinstance(device, VkDevice)

    def list_devices(self) -> list[dict[str, Any]]:
        return list_devices()

    def describe(self, device: VkDevice) -> dict[str, Any]:
        return device.describe()

    def caps(self, device: VkDevice) -> frozenset[str]:
        return frozenset(device.caps)

    def timestamps(self, device: VkDevice) -> bool:
        return "timestamp" in device.caps

    def fit(self, graph: Graph, device: VkDevice, *, readback: bool = True,
            options: RunOptions = DEFAULT) -> tuple[CompiledGraph, Any]:
        # the plan's transients placed with the driver's exact sizes and alignments
        return fit_graph(graph, device, alias=options.alias, readback=readback,
                         order_seed=options.order_seed)

    def check(self, plan: CompiledGraph, passes: dict[str, Pass]) -> None:
        check_passes(plan, passes)

    def scene(self, device: VkDevice, scene: Scene, camera: Any,
              size: tuple[int, int]) -> VkScene:
        vscene = VkScene(device, scene, camera)
        try:
            vscene.set_viewport(size)
        except BaseException:
            vscene.destroy()
            raise
        return vscene

    def executor(self, device: VkDevice, plan: CompiledGraph, passes: dict[str, Pass],
                 slots: dict[str, dict[str, str]], scene: Any, *, readback: tuple[str, ...],
                 fitted: Any, options: RunOptions = DEFAULT) -> VkExecutor:
        return VkExecutor(device, plan, passes, slots, scene, readback=readback,
                          alias=options.alias, memory_info=fitted, options=options)

    def read_bridge(self, executor: VkExecutor, bridge: str, resource: str) -> np.ndarray:
        state = executor.state_in(bridge, resource)  # the plan's transfer-src state there
        if resource in executor.buffers:
            return read_buffer(executor.device, executor.buffers[resource], state)
        return read_image(executor.device, executor.image(resource), layout_now=state,
                          layout_after=state)

    def write_bridge(self, executor: VkExecutor, bridge: str, resource: str,
                     data: np.ndarray) -> None:
        state = executor.state_in(bridge, resource)  # transfer dst: the consumer's from
        if resource in executor.buffers:
            upload_buffer(executor.device, executor.buffers[resource], data, dst=state)
        else:
            upload_image(executor.device, executor.image(resource), data, layout_after=state,
                         layout_before=state)

    def read_device(self, executor: VkExecutor, resource: str, *, wrap: Any = None) -> Any:
        """A graph output as an ``rfw.interop.DeviceArray`` (or as ``wrap`` makes it):
        zero-copy where the device shares memory with CUDA, else a host copy
        (:func:`vkext.external.read_output`)."""
        from .external import read_output

        return read_output(executor, resource, wrap=wrap)

    def export_outputs(self, executor: VkExecutor, names: Any) -> str | None:
        """From the next frame on, the frames copy the images ``names`` into exported memory
        themselves (:func:`vkext.external.export_outputs`): None, or why they do not."""
        from .external import export_outputs

        return export_outputs(executor, names)

    def collect(self, executor: VkExecutor) -> dict[str, Any]:
        # before the scene, which owns the acceleration structures, goes; the culling
        # counters come back through the executor's readback, before the executor goes
        return {"memory": executor.memory(), "accel": accel_stats(executor),
                "culling": culling_counters(executor)}

    def report(self, executor: VkExecutor, device: VkDevice, *,
               validation: bool) -> dict[str, Any]:
        out: dict[str, Any] = {}
        if validation or device.validation:
            out["validation"] = {"messages": len(device.messages),
                                 "texts": [m.text for m in device.messages[:20]]}
        return out

    def destroy_device(self, device: VkDevice) -> None:
        device.destroy()

    def ray_scene(self, device: VkDevice, scene: Scene, *, method: str = "auto",
                  batch: int | None = None) -> Any:
        """A :class:`vkext.raycast.RayScene` of every instance of ``scene``: acceleration
        structures built once, then ``cast(origins, directions, tmin, tmax, hits=...)``
        (float32 (R, 3) arrays; numbers or (R,) float32 arrays) as often as wanted, reusing
        them and the ray buffers; ``destroy()`` frees it."""
        from .raycast import DEFAULT_BATCH, RayScene

        return RayScene(device, scene, method=method, batch=batch or DEFAULT_BATCH)


def render_vk(cfg: Config, *, scene: Any = None, frames: int | None = None,
              device: VkDevice | None = None, validation: bool | None = None,
              alias: bool | None = None, warmup: int | None = None,
              options: RunOptions | None = None) -> Result:
    """``rfw.render.render`` on raw Vulkan: images of the graph outputs and timings.json's
    fields, plus ``memory`` (transient bytes allocated against the plan's numbers),
    ``techniques`` (what auto variants chose for the device) and, where the frame has
    them, ``culling`` and ``accel``. A config that pins passes to wgpu runs mixed.
    ``options`` and the keywords as ``render`` takes them."""
    return render(cfg, scene=scene, frames=frames, warmup=warmup, device=device,
                  backend="vk", validation=validation, alias=alias, options=options)
