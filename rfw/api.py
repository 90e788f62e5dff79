"""rfw from Python: load or build a config, override settings, render, read images and timings.

```python
import rfw

cfg = rfw.load("configs/deferred.toml", "lighting.ambient=0.5", size=(64, 36))
with rfw.Session(backend="wgpu") as s:       # one device, scenes loaded once
    a = s.render(cfg, frames=5)
    b = s.render(cfg, "tonemap.exposure=2", frames=5)
print(a.gpu_ms, b.images["tonemap.ldr"].shape)   # per-pass medians; (H, W, 4) uint8
```

Overrides are the strings of ``rfw run --set`` (a variant, ``size``, ``scene``, ``frames``,
``<pass>.enabled``, ``<pass>.<setting>``, ``<pass>.inputs.<slot>``). Every error a user can
cause is an :class:`rfw.errors.RfwError` whose ``str()`` is the line ``rfw run`` prints
after ``rfw: error:``. ``rfw.run`` is a one-off :class:`Session`.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from .backend import get_backend
from .config import (
    MAX_FRAMES,
    Config,
    PassEntry,
    _config_from,
    apply_overrides,
    load_config,
    pass_class,
)
from .errors import RfwError, check_identifier, check_number
from .frame import Result, load_scene_for
from .render import backend_for, render

ConfigLike = Config | str | Path


def load(path: str | Path, *sets: str, scene: str | None = None,
         size: tuple[int, int] | None = None) -> Config:
    """The config in ``path`` (TOML, as ``rfw run`` reads it) with ``sets`` applied, then
    ``scene`` and ``size`` (as ``--scene`` and ``--size`` apply them)."""
    return override(load_config(path), *sets, scene=scene, size=size)


def override(cfg: Config, *sets: str | Mapping[str, Any], scene: str | None = None,
             size: tuple[int, int] | None = None) -> Config:
    """A copy of ``cfg`` with ``sets`` applied in order: ``"key=value"`` strings as
    ``--set`` takes them, or mappings ``{key: value}`` (each item one ``key=value``)."""
    items: list[str] = []
    for s in sets:
        if isinstance(s, Mapping):
            items += [f"{k}={_text(v)}" for k, v in s.items()]
        elif isinstance(s, str):
            items.append(s)
        else:
            raise RfwError(f"an override is a 'key=value' string or a mapping, not {s!r}",
                           file=cfg.source, element="--set")
    if scene is not None:
        items.append(f"scene={scene}")
    if size is not None:
        w, h = _pair(size, cfg.source)
        items.append(f"size={w}x{h}")
    return apply_overrides(cfg, items)


def make_config(name: str, passes: Iterable[PassEntry | Mapping[str, Any]], outputs: Iterable[str],
           *, scene: str = "default", size: tuple[int, int] = (1280, 720), frames: int = 1,
           camera: Mapping[str, Any] | None = None,
           variants: Mapping[str, Mapping[str, Any]] | None = None,
           source: str | None = None) -> Config:
    """A config built in code, checked as a TOML file's would be. ``passes`` are
    :class:`PassEntry` objects or tables with a config's ``[[pass]]`` keys (``name``,
    ``use``, ``enabled``, ``inputs``, ``settings``, ``backend``); ``variants`` as a config's
    ``[variants.NAME]`` tables (each with its ``default``). ``source`` names the config in
    error messages (default ``<python: NAME>``)."""
    src = source or f"<python: {name}>"
    check_identifier("config", name, file=src, element="name")
    tables = []
    for p in passes:
        if isinstance(p, PassEntry):
            p = {"name": p.name, "use": p.use, "enabled": p.enabled, "inputs": dict(p.inputs),
                 "settings": dict(p.settings), **({"backend": p.backend} if p.backend else {})}
        tables.append(dict(p))
    if not tables:
        raise RfwError("the config has no passes", file=src, element="passes")
    if not isinstance(scene, str) or not scene:
        raise RfwError(f"must be a scene name or path, not {scene!r}", file=src,
                       element="scene")
    data = {"name": name, "pass": tables, "outputs": list(outputs), "scene": scene,
            "size": list(_pair(size, src)), "frames": frames,
            "variants": {k: dict(v) for k, v in (variants or {}).items()},
            **({} if camera is None else {"camera": dict(camera)})}
    cfg = _config_from(data, src, None)  # checked and built as load_config does
    for entry in cfg.passes:  # an unknown pass id fails here, not at the first render
        pass_class(cfg, entry)
    return cfg


class Session:
    """Devices and loaded scenes kept across renders: the first render that needs a
    backend makes its device, the first that names a scene loads it; later renders reuse
    both (``devices_made`` and ``scenes_loaded`` count what was made). Each render uploads
    its scene to the device and builds its graph anew (a config may change anything).

    ``backend`` is the default for :meth:`render` (``None``: as ``rfw run`` picks it);
    ``validation`` makes devices with the API's validation layer (vk), and a result's
    ``timings["validation"]`` then counts the device's messages so far. Close the session
    (or use it in ``with``) to destroy its devices."""

    def __init__(self, backend: str | None = None, *, validation: bool = False):
        if backend is not None:
            get_backend(backend)  # an unknown name: one line naming the installed ones
        self.backend = backend
        self.validation = validation
        self.devices: dict[str, Any] = {}
        self.scenes: dict[str, Any] = {}
        self.devices_made = 0
        self.scenes_loaded = 0
        self.closed = False

    def device(self, backend: str) -> Any:
        """This session's device of ``backend``, made on first use."""
        self._check_open()
        if backend not in self.devices:
            self.devices[backend] = get_backend(backend).make_device(
                validation=self.validation)
            self.devices_made += 1
        return self.devices[backend]

    def scene(self, cfg: Config) -> Any:
        """The scene ``cfg`` names (``default``, ``stress:N``, a file), loaded on first use."""
        self._check_open()
        key = cfg.scene if cfg.scene in ("default",) or not Path(cfg.scene).exists() \
            else str(Path(cfg.scene).resolve())
        if key not in self.scenes:
            self.scenes[key] = load_scene_for(cfg)
            self.scenes_loaded += 1
        return self.scenes[key]

    def render(self, config: ConfigLike, *sets: str | Mapping[str, Any],
               frames: int | None = None, backend: str | None = None,
               scene: str | None = None, size: tuple[int, int] | None = None,
               warmup: int = 1) -> Result:
        """Render ``config`` (a :class:`Config` or a TOML path) with ``sets`` applied:
        ``warmup`` frames, then ``frames`` timed ones (default: the config's)."""
        self._check_open()
        cfg = config if isinstance(config, Config) else load_config(config)
        cfg = override(cfg, *sets, scene=scene, size=size)
        name = backend or self.backend or backend_for(cfg)
        get_backend(name, file=cfg.source)
        check_number(warmup, "warmup", kind=int, lo=0, hi=MAX_FRAMES, file=cfg.source)
        needed = {name} | {e.backend or pass_class(cfg, e).backend
                           for e in cfg.passes if e.enabled} - {None}
        for b in sorted(needed):  # every backend the run mixes in: its device
            get_backend(b, file=cfg.source, element=None)
        devices = [self.device(b) for b in sorted(needed)]
        return render(cfg, scene=self.scene(cfg), frames=frames, warmup=warmup,
                      devices=devices, backend=name, validation=self.validation)

    def close(self) -> None:
        """Destroy the devices this session made (scenes are host data: just dropped)."""
        while self.devices:
            name, device = self.devices.popitem()
            get_backend(name).destroy_device(device)
        self.scenes.clear()
        self.closed = True

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _check_open(self) -> None:
        if self.closed:
            raise RfwError("this session is closed: make a new rfw.Session",
                           element="rfw.Session")


def run(config: ConfigLike, *sets: str | Mapping[str, Any], frames: int | None = None,
        backend: str | None = None, scene: str | None = None,
        size: tuple[int, int] | None = None, warmup: int = 1,
        validation: bool = False) -> Result:
    """One render in a :class:`Session` of its own (its device destroyed after): the
    Python face of ``rfw run``. ``result.save(folder)`` writes what ``rfw run`` writes."""
    with Session(backend, validation=validation) as s:
        return s.render(config, *sets, frames=frames, scene=scene, size=size, warmup=warmup)


def _text(value: Any) -> str:
    # a Python value as --set spells it
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def _pair(size: Any, source: str) -> tuple[int, int]:
    if not isinstance(size, (tuple, list)) or len(size) != 2:
        raise RfwError(f"must be (width, height), not {size!r}", file=source, element="size")
    return (check_number(size[0], "size", kind=int, lo=1, file=source, element="size"),
            check_number(size[1], "size", kind=int, lo=1, file=source, element="size"))


__all__ = ["Config", "PassEntry", "Result", "Session", "load", "make_config", "override", "run"]
