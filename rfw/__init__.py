"""rfw: a frame-graph framework for real-time graphics research.

The Python API (:mod:`rfw.api`, docs/python-api.md): ``rfw.load``/``rfw.make_config`` make a
config, ``rfw.override`` applies ``--set`` strings, ``rfw.run`` renders once and
``rfw.Session`` keeps devices and scenes across renders; results are ``rfw.Result``;
``rfw.RunOptions`` say how frames run (frames, validation, vk's switches: :mod:`rfw.options`).
Every public function and class checks its arguments: a bad one is an ``rfw.RfwError``
naming it (``rfw.RfwTypeError``, also a TypeError, for a wrong type).
"""

from . import signals as _signals

_signals.early()  # the rfw command: a signal while it still imports ends it in one line too
from .errors import RfwError, RfwTypeError, RfwValueError  # noqa: E402
from .options import RunOptions  # noqa: E402
from .passes import ComputePass, Pass, RenderPass, Settings, SettingsError, Tex2D  # noqa: E402
from .registry import available, get_pass, register_pass  # noqa: E402

__version__ = "0.1.0"

# loaded on first use (PEP 562): importing rfw stays light and never imports vulkan
_API = ("Config", "PassEntry", "Result", "Session", "load", "make_config", "override", "run")

__all__ = ["ComputePass", "Config", "Pass", "PassEntry", "RayScene", "RenderPass", "Result",
           "RfwError", "RfwTypeError", "RfwValueError", "RunOptions", "Session", "Settings",
           "SettingsError", "Tex2D", "available", "get_pass", "load", "make_config",
           "override", "raycast", "register_pass", "run"]


def __getattr__(name: str):
    # rfw.raycast and rfw.RayScene on first use: importing rfw must not import vulkan (PEP
    # 562); the module is rfw.raycasting, so importing it never rebinds rfw.raycast to a module
    if name in ("raycast", "RayScene"):
        from . import raycasting

        return getattr(raycasting, name)
    if name in _API:  # rfw.api's names; rfw.run is a function, rfw.render stays the module
        from . import api

        return getattr(api, name)
    raise AttributeError(f"module 'rfw' has no attribute {name!r}")


def __dir__() -> list[str]:
    # the lazy names too: tab completion and dir(rfw) find rfw.run, rfw.Session, ...
    return sorted(set(globals()) | set(__all__))
