"""rfw: a frame-graph framework for real-time graphics research."""

from .passes import ComputePass, Pass, RenderPass, Settings, SettingsError, Tex2D
from .registry import available, get_pass, register_pass

__version__ = "0.1.0"

__all__ = ["ComputePass", "Pass", "RayScene", "RenderPass", "Settings", "SettingsError", "Tex2D",
           "available", "get_pass", "raycast", "register_pass"]


def __getattr__(name: str):
    # rfw.raycast and rfw.RayScene on first use: importing rfw must not import vulkan (PEP
    # 562); the module is rfw.raycasting, so importing it never rebinds rfw.raycast to a module
    if name in ("raycast", "RayScene"):
        from . import raycasting

        return getattr(raycasting, name)
    raise AttributeError(f"module 'rfw' has no attribute {name!r}")
