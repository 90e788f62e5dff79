"""rfw: a frame-graph framework for real-time graphics research."""

from .passes import ComputePass, Pass, RenderPass, Settings, SettingsError, Tex2D
from .registry import available, get_pass, register_pass

__version__ = "0.1.0"

__all__ = ["ComputePass", "Pass", "RenderPass", "Settings", "SettingsError", "Tex2D",
           "available", "get_pass", "register_pass"]
