"""A backend with no GPU: each graph output is painted one color, from its pass's name.

Enough of :class:`rfw.backend.Backend` for ``rfw run --backend paint`` to write images and
timings through rfw's own frame driver. ``RFW_BACKEND_DEMO_LOG`` names a file it appends
each call to the frame driver to.
"""

from __future__ import annotations

import os
import zlib
from dataclasses import dataclass, field

import numpy as np

from rfw.backend import BackendBase
from rfw.backends.base import FrameExecutor
from rfw.graph import compile


def _log(what):
    path = os.environ.get("RFW_BACKEND_DEMO_LOG")
    if path:
        with open(path, "a", encoding="utf-8") as f:
            f.write(what + "\n")


@dataclass
class Timing:
    gpu_ms: list = field(default_factory=list)
    cpu_ms: list = field(default_factory=list)


class Canvas:
    default_light = False

    def destroy(self):
        _log("scene.destroy")


class PaintExecutor(FrameExecutor):
    def __init__(self, plan, passes):
        self.plan, self.passes = plan, passes
        self.timings = {name: Timing() for name in plan.order}

    def begin_frame(self):
        self._recorded = []

    def record(self, name):
        self._recorded.append(name)

    def flush(self):
        pass

    def end_frame(self):
        for name in self._recorded:
            self.timings[name].gpu_ms.append(1.0)
            self.timings[name].cpu_ms.append(0.5)

    def read(self, resource):
        r = self.plan.resource(resource)
        value = zlib.crc32(r.producer.encode()) % 256
        return np.full((r.height, r.width, 4), value, np.uint8)

    def destroy(self):
        _log("executor.destroy")


class PaintBackend(BackendBase):
    name = "paint"

    def make_device(self, *, label=None, options=None):
        _log("make_device")
        return {"paint": True}

    def owns(self, device):
        return isinstance(device, dict) and device.get("paint", False)

    def describe(self, device):
        return {"device": "canvas", "driver": "brush", "api": "none", "backend": "paint"}

    def caps(self, device):
        return frozenset()

    def fit(self, graph, device, *, readback=True, options=None):
        _log("fit")
        return compile(graph), None

    def scene(self, device, scene, camera, size):
        return Canvas()

    def executor(self, device, plan, passes, slots, scene, *, readback, fitted, options):
        _log("executor")
        return PaintExecutor(plan, passes)

    def read_bridge(self, executor, bridge, resource):
        return executor.read(resource)

    def write_bridge(self, executor, bridge, resource, data):
        raise NotImplementedError

    def destroy_device(self, device):
        _log("destroy_device")


class Broken(BackendBase):
    """Registered, but with no way to run a frame."""

    name = "broken"
