"""The wgpu backend, by concern: ``device``, ``resources`` (textures and buffers from the
plan), ``programs`` (shaders, layouts, their cache), ``context`` (what a pass records
through), ``timestamps``, ``executor``, ``calls`` (wgpu-native calls made with descriptors
built once), ``scene`` (a scene on the GPU) and ``backend`` (the ``rfw.backends`` entry point)."""

from .context import PassContext
from .device import Device
from .executor import Executor

__all__ = ["Device", "Executor", "PassContext"]
