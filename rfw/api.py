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

import operator
import os
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
from .errors import (
    RfwError,
    RfwTypeError,
    RfwValueError,
    check_bool,
    check_identifier,
    check_number,
    check_path,
    check_type,
    type_name,
)
from .frame import Result, load_scene_for
from .options import RunOptions, check_options
from .render import backend_for, render

ConfigLike = Config | str | Path


def load(path: str | Path, *sets: str, scene: str | None = None,
         size: tuple[int, int] | None = None) -> Config:
    """The config in ``path`` (TOML, as ``rfw run`` reads it) with ``sets`` applied, then
    ``scene`` and ``size`` (as ``--scene`` and ``--size`` apply them)."""
    return override(_load(check_path(path, "path", element="rfw.load")), *sets,
                    scene=scene, size=size)


def override(cfg: Config, *sets: str | Mapping[str, Any], scene: str | None = None,
             size: tuple[int, int] | None = None) -> Config:
    """A copy of ``cfg`` with ``sets`` applied in order: ``"key=value"`` strings as
    ``--set`` takes them, or mappings ``{key: value}`` (each item one ``key=value``)."""
    if not isinstance(cfg, Config):
        hint = " (rfw.load reads a config file)" if isinstance(cfg, str | os.PathLike) else ""
        raise RfwTypeError(f"'cfg' must be an rfw.Config{hint}, not {type_name(cfg)}",
                           element="rfw.override")
    _check_config(cfg, "cfg", "rfw.override")
    items: list[str] = []
    for s in sets:
        if isinstance(s, Mapping):
            for k, v in s.items():
                check_type(k, "sets", str, "a mapping with str keys ('pass.setting')",
                           file=cfg.source, element="rfw.override")
                items.append(f"{k}={_text(v)}")
        elif isinstance(s, str):
            items.append(s)
        else:
            raise RfwTypeError(f"'sets' must be 'key=value' strings or mappings, not "
                               f"{type_name(s)}", file=cfg.source, element="rfw.override")
    if scene is not None:
        items.append(f"scene={_scene_arg(scene, cfg.source)}")
    if size is not None:
        w, h = _pair(size, cfg.source)
        items.append(f"size={w}x{h}")
    out = apply_overrides(cfg, items)
    for entry in out.passes:  # a bad setting fails here, as rfw run refuses it
        if entry.enabled:
            try:
                pass_class(out, entry).Params(f"pass '{entry.name}'", **entry.settings)
            except RfwError as e:
                raise e.in_file(out.source) from None
    return out


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
    where = "rfw.make_config"
    if source is not None:
        check_type(source, "source", str, "a str naming the config in errors", element=where)
    check_type(name, "name", str, "a config name (str)", element=where)
    src = source or f"<python: {name}>"
    check_identifier("config", name, file=src, element="name")
    tables = []
    for p in _items(passes, "passes", "PassEntry objects or mappings", src):
        if isinstance(p, PassEntry):
            p = {"name": p.name, "use": p.use, "enabled": p.enabled, "inputs": dict(p.inputs),
                 "settings": dict(p.settings), **({"backend": p.backend} if p.backend else {})}
        elif not isinstance(p, Mapping):
            raise RfwTypeError(f"'passes' must hold PassEntry objects or mappings, not "
                               f"{type_name(p)}", file=src, element=where)
        tables.append(dict(p))
    if not tables:
        raise RfwError("the config has no passes", file=src, element="passes")
    outs = _items(outputs, "outputs", "output names ('pass.slot')", src)
    for o in outs:
        check_type(o, "outputs", str, "output names ('pass.slot') as str", file=src,
                   element=where)
    scene = _scene_arg(scene, src)
    for key, value in (("camera", camera), ("variants", variants)):
        if value is not None:
            check_type(value, key, Mapping, "a mapping", file=src, element=where)
    for key, value in (variants or {}).items():
        check_type(value, "variants", Mapping, f"a mapping of mappings (variant {key!r})",
                   file=src, element=where)
    data = {"name": name, "pass": tables, "outputs": outs, "scene": scene,
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
    ``timings["validation"]`` then counts the device's messages so far. ``options``
    (:class:`rfw.options.RunOptions`; default: read from the environment once, here) say
    how every render of the session runs and which devices it makes. Close the session
    (or use it in ``with``) to destroy its devices."""

    def __init__(self, backend: str | None = None, *, validation: bool = False,
                 options: RunOptions | None = None):
        if backend is not None:  # an unknown name: one line naming the installed ones
            get_backend(_backend_arg(backend, "rfw.Session"))
        self.backend = backend
        asked = check_bool(validation, "validation", element="rfw.Session") or None
        self.options = RunOptions.from_env(validation=asked) if options is None else \
            check_options(options).replace(validation=asked)
        self.validation = self.options.validation
        self.devices: dict[str, Any] = {}
        self.scenes: dict[str, Any] = {}
        self.devices_made = 0
        self.scenes_loaded = 0
        self.closed = False

    def device(self, backend: str) -> Any:
        """This session's device of ``backend``, made on first use."""
        self._check_open()
        backend = _backend_arg(backend, "Session.device")
        if backend not in self.devices:
            self.devices[backend] = get_backend(backend).make_device(options=self.options)
            self.devices_made += 1
        return self.devices[backend]

    def scene(self, cfg: Config) -> Any:
        """The scene ``cfg`` names (``default``, ``stress:N``, a file), loaded on first use."""
        self._check_open()
        check_type(cfg, "cfg", Config, "an rfw.Config", element="Session.scene")
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
        cfg = override(_config_arg(config, "Session.render"), *sets, scene=scene, size=size)
        if backend is not None:
            _backend_arg(backend, "Session.render")
        name = backend or self.backend or backend_for(cfg)
        get_backend(name, file=cfg.source)
        if frames is not None:
            check_number(frames, "frames", kind=int, lo=1, hi=MAX_FRAMES, file=cfg.source)
        check_number(warmup, "warmup", kind=int, lo=0, hi=MAX_FRAMES, file=cfg.source)
        needed = {name} | {e.backend or pass_class(cfg, e).backend
                           for e in cfg.passes if e.enabled} - {None}
        for b in sorted(needed):  # every backend the run mixes in: its device
            get_backend(b, file=cfg.source, element=None)
        devices = [self.device(b) for b in sorted(needed)]
        return render(cfg, scene=self.scene(cfg), devices=devices, backend=name,
                      options=self.options.replace(frames=frames, warmup=warmup))

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
        validation: bool = False, options: RunOptions | None = None) -> Result:
    """One render in a :class:`Session` of its own (its device destroyed after): the
    Python face of ``rfw run``; ``options`` as :class:`Session` takes them.
    ``result.save(folder)`` writes what ``rfw run`` writes."""
    cfg = _config_arg(config, "rfw.run")
    with Session(backend, validation=validation, options=options) as s:
        return s.render(cfg, *sets, frames=frames, scene=scene, size=size, warmup=warmup)


def _text(value: Any) -> str:
    # a Python value as --set spells it: a tuple or list of numbers as "1,2,3"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, tuple | list):
        return ",".join(_text(v) for v in value)
    return str(value)


def _pair(size: Any, source: str) -> tuple[int, int]:
    if not isinstance(size, tuple | list) or len(size) != 2:
        raise RfwTypeError(f"'size' must be (width, height), not {type_name(size)}",
                           file=source, element="size")
    return tuple(check_number(_integer(v), "size", kind=int, lo=1, file=source,
                              element="size") for v in size)  # type: ignore[return-value]


def _integer(value: Any) -> Any:
    # numpy's integers count as integers; anything else is left for check_number to refuse
    if isinstance(value, int):  # bool included: check_number refuses it
        return value
    try:
        return operator.index(value)
    except TypeError:
        return value


def _items(value: Any, name: str, what: str, source: str) -> list[Any]:
    # a list, tuple or other iterable of items, never a str (whose characters would do)
    if isinstance(value, str | bytes | Mapping) or not isinstance(value, Iterable):
        raise RfwTypeError(f"'{name}' must be a list of {what}, not {type_name(value)}",
                           file=source, element="rfw.make_config")
    return list(value)


def _scene_arg(scene: Any, source: str) -> str:
    # a scene name or path; as --scene takes it
    check_type(scene, "scene", (str, os.PathLike), "a scene name or path", file=source,
               element="scene")
    text = os.fspath(scene)
    if not isinstance(text, str) or not text:
        raise RfwValueError(f"'scene' must be a scene name or path, not {scene!r}",
                            file=source, element="scene")
    return text


def _backend_arg(backend: Any, where: str) -> str:
    return check_type(backend, "backend", str, "a backend name ('wgpu', 'vk')",
                      element=where)


def _load(path: Path) -> Config:
    # a config file as rfw run reads it; what the file system refuses is one line too
    if path.exists() and not (path.is_file() or path.is_dir()):
        raise RfwValueError("is not a regular file (a device, FIFO or socket?)",
                            file=str(path))
    try:
        return load_config(path)
    except OSError as e:
        raise RfwError(f"cannot read the config: {e.strerror or e}", file=str(path)) from None


def _config_arg(config: Any, where: str) -> Config:
    # a Config, or the path of a config file
    if isinstance(config, Config):
        return _check_config(config, "config", where)
    if isinstance(config, str | os.PathLike):
        return _load(check_path(config, "config", element=where))
    raise RfwTypeError(f"'config' must be an rfw.Config or a config file path, not "
                       f"{type_name(config)}", element=where)


def _check_config(cfg: Config, name: str, where: str) -> Config:
    # a Config made by hand (rfw.Config(...)) gets the shape checks a loaded one passed
    fields = (("name", str), ("passes", list), ("outputs", list), ("scene", str),
              ("size", tuple | list), ("source", str))
    for key, kind in fields:
        if not isinstance(getattr(cfg, key), kind):
            raise RfwTypeError(f"'{name}' has a bad {key}: {type_name(getattr(cfg, key))} "
                               "(make configs with rfw.load or rfw.make_config)",
                               element=where)
    for entry in cfg.passes:
        if not isinstance(entry, PassEntry):
            raise RfwTypeError(f"'{name}' has a pass that is no rfw.PassEntry: "
                               f"{type_name(entry)}", element=where)
    return cfg


__all__ = ["Config", "PassEntry", "Result", "Session", "load", "make_config", "override", "run"]
