"""Renderer configs: scene, camera, size, passes with settings, and technique variants.

```toml
name = "deferred"
scene = "default"                 # or a path (.gltf .glb .obj .ply ...)
size = [1280, 720]
outputs = ["tonemap.ldr"]

[[pass]]
name = "lighting"                 # the instance name; "use" picks the pass id (default: name)
use = "deferred_lighting"
inputs = { albedo = "gbuffer.albedo", shadow = "shadow.depth" }
settings = { ambient = 0.5 }

[animation]                       # the scene's node animations (rfw.timeline)
fps = 60                          # frame k at start + k / fps seconds

[variants.shadows]                # --set shadows=off applies these overrides
default = "on"
on = {}
off = { "shadow.enabled" = false }
```

An option may instead list other options, best first (``auto = ["ray_query", "shadow_map"]``):
a device resolves it to the first whose passes it can run (``resolve_auto``); until then it
stands for its last option, the most portable one.

One module of ~650 lines: the config's keys, their checks and the messages naming file and
key are one schema, read top to bottom as the TOML is.
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from .errors import RfwError, check_identifier, check_number
from .graph import Graph, GraphBuilder, GraphError
from .graph.errors import did_you_mean
from .graph.resources import SizeRule
from .options import MAX_FRAMES_IN_FLIGHT
from .passes import SCENE_NEEDS, Pass
from .registry import get_pass

_KEYS = ("name", "scene", "size", "camera", "outputs", "pass", "variants", "frames",
         "async_compute", "frames_in_flight", "animation")
_PASS_KEYS = ("name", "use", "enabled", "inputs", "settings", "backend")
_CAMERA_KEYS = ("position", "target", "up", "yfov", "znear", "zfar", "gltf", "path")
MAX_FRAMES = 100_000  # timed frames of one run; more is a typo, not an experiment
MAX_SIZE = 16384  # pixels per side: beyond any device's 2D image limit we know of


@dataclass
class PassEntry:
    name: str
    use: str
    enabled: bool = True
    inputs: dict[str, str] = field(default_factory=dict)
    settings: dict[str, Any] = field(default_factory=dict)
    backend: str | None = None  # pin this pass to "wgpu" or "vk"


@dataclass
class Config:
    name: str
    passes: list[PassEntry]
    outputs: list[str]
    scene: str = "default"
    size: tuple[int, int] = (1280, 720)
    camera: dict[str, Any] | None = None
    variants: dict[str, dict[str, Any]] = field(default_factory=dict)
    frames: int = 1
    source: str = "<config>"
    chosen: dict[str, str] = field(default_factory=dict)  # variant -> option in force
    base: list[PassEntry] = field(default_factory=list)  # the passes as the file declares
    explicit: list[tuple[str, Any]] = field(default_factory=list)  # --set pass.key=value
    async_compute: str = "auto"  # compute beside raster on a second queue (rfw.graph.queues)
    frames_in_flight: int | None = None  # None: RunOptions.default_in_flight (rfw.options)
    # [animation]: the timeline the scene's node animations play on (rfw.timeline)
    animation: dict[str, Any] | None = None

    def entry(self, name: str) -> PassEntry:
        for p in self.passes:
            if p.name == name:
                return p
        raise GraphError(f"no pass named '{name}'" + did_you_mean(name, [p.name for p in
                                                                          self.passes]),
                         file=self.source)


def _fail(source: str, message: str, element: str | None = None) -> GraphError:
    return GraphError(message, file=source, element=element)


def _check_keys(table: dict, known: tuple[str, ...], where: str, source: str) -> None:
    for key in table:
        if key not in known:
            raise _fail(source, f"{where}: unknown key '{key}'" + did_you_mean(key, known))


def _read_toml(path: Path) -> dict[str, Any]:
    """The TOML table in ``path``; a missing file, bad UTF-8 or bad TOML is one error naming
    the file and the line."""
    source = str(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise _fail(source, "file not found") from None
    except IsADirectoryError:
        raise _fail(source, "is a directory, not a config file") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        line = raw[:e.start].count(b"\n") + 1
        raise _fail(source, f"not a TOML file: not valid UTF-8 (byte {raw[e.start]:#04x})",
                    f"line {line}") from None
    try:
        return tomllib.loads(text)
    except RecursionError:
        # tomllib cannot say where: the line with the most brackets is the one
        no, line = max(enumerate(text.splitlines() or [""], 1),
                       key=lambda t: t[1].count("[") + t[1].count("{"))
        key = line.partition("=")[0].strip()[:40] if "=" in line else "a value"
        raise _fail(source, f"malformed TOML: {key} is nested too deeply", f"line {no}") \
            from None
    except tomllib.TOMLDecodeError as e:
        # tomllib ends its message with "(at line L, column C)": that becomes the element
        m = re.search(r"\s*\(at line (\d+), column (\d+)\)$", str(e))
        message = str(e)[:m.start()] if m else str(e)
        element = f"line {m[1]}, column {m[2]}" if m else None
        raise _fail(source, f"malformed TOML: {message}", element) from None


def _table(value: Any, key: str, source: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise _fail(source, f"must be a table, not {value!r}", key)
    return value


def _string(value: Any, key: str, source: str) -> str:
    if not isinstance(value, str):
        raise _fail(source, f"must be a string, not {value!r}", key)
    return value


def _size_of(value: Any, source: str) -> tuple[int, int]:
    if not (isinstance(value, list) and len(value) == 2):
        raise _fail(source, f"must be two integers [width, height], not {value!r}", "size")
    w, h = (check_number(v, "size", kind=int, lo=1, hi=MAX_SIZE, file=source, element="size")
            for v in value)
    return w, h


def _camera(value: Any, source: str, prefix: str = "") -> dict[str, Any]:
    """The ``camera`` table checked: vectors, yfov in degrees, near and far, ``gltf`` (a
    scene camera's name or index) and ``path`` (:mod:`rfw.camera_path`). ``prefix``
    (``"--set "``) goes before the key an error names."""
    from .camera_path import check_path, check_vector

    camera = _table(value, "camera", source)
    _check_keys(camera, _CAMERA_KEYS, "camera", source)
    out: dict[str, Any] = {}
    for key, v in camera.items():
        where = f"{prefix}camera.{key}"
        if key in ("position", "target", "up"):
            try:
                out[key] = check_vector(v, where, source)
            except RfwError as e:
                raise _fail(source, e.message, where) from None
        elif key == "yfov":
            out[key] = check_number(v, where, lo=0.01, hi=179.0, file=source, element=where)
        elif key == "gltf":
            if isinstance(v, bool) or not isinstance(v, str | int):
                raise _fail(source, f"must be a camera's name or index, not {v!r}", where)
            out[key] = v if isinstance(v, str) else check_number(
                v, where, kind=int, lo=0, file=source, element=where)
        elif key == "path":
            out[key] = check_path(v, source, where)
        else:
            out[key] = check_number(v, where, lo=1e-6, hi=1e9, file=source, element=where)
    if out.get("znear", 0.0) >= out.get("zfar", math.inf):
        raise _fail(source, "'znear' must be smaller than 'zfar'", f"{prefix}camera")
    if "up" in out:
        _check_up(out, source, f"{prefix}camera.up")
    if "position" in out and "target" in out:  # the view is the config's: checked now
        _check_matrices(out, source, prefix)
    return out


def _check_matrices(camera: dict[str, Any], source: str, prefix: str) -> None:
    """The camera's float32 matrices keep a picture (:func:`rfw.camera_path.check_camera`),
    with the scene camera's defaults for keys the table leaves out (rfw.frame.camera_for
    checks again with the scene's own)."""
    from .camera_path import check_camera
    from .scene.model import Camera

    values = {k: tuple(v) if isinstance(v, list) else v for k, v in camera.items()
              if k in ("position", "target", "up", "znear", "zfar")}
    if "yfov" in camera:
        values["yfov"] = math.radians(camera["yfov"])
    try:
        check_camera(Camera(**values), file=source, element=f"{prefix}camera.position")
    except RfwError as e:
        raise _fail(source, e.message, e.element) from None


def _check_up(camera: dict[str, Any], source: str, where: str) -> None:
    """An up vector gives the image its top: zero, or along the view direction, it gives
    none (the renderer would pick another axis without a word)."""
    up = [float(v) for v in camera["up"]]
    if not math.hypot(*up) > 1e-9:
        raise _fail(source, f"must not be zero, not {camera['up']!r}", where)
    if "position" in camera and "target" in camera:
        view = [float(t) - float(p) for t, p in zip(camera["target"], camera["position"],
                                                    strict=True)]
        cross = (view[1] * up[2] - view[2] * up[1], view[2] * up[0] - view[0] * up[2],
                 view[0] * up[1] - view[1] * up[0])
        if math.hypot(*cross) <= 1e-6 * math.hypot(*view) * math.hypot(*up):
            raise _fail(source, f"{camera['up']!r} is parallel to the view direction (target "
                        f"- position = {view!r}): it gives the image no top", where)


def _camera_value(text: str) -> Any:
    """A ``--set camera.KEY=VALUE`` value: TOML (``[0, 1, 5]``, ``60``, ``"name"``,
    ``{...}``), else numbers separated by commas (``0,1,5``), else the text."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        pass
    parts = text.split(",")
    if len(parts) > 1:
        try:
            return [float(p) for p in parts]
        except ValueError:
            pass
    return text


def _set_camera(cfg: Config, key: str, text: str) -> Config:
    """``--set camera.KEY=VALUE`` (``camera.path=orbit``, ``camera.path.turns=0.5``,
    ``camera.path=off`` to drop a path), checked with the whole camera table."""
    camera = dict(cfg.camera or {})
    parts = key.split(".")
    value = _camera_value(text)
    if len(parts) == 2 and parts[1] == "path" and str(value).lower() in ("off", "none"):
        camera.pop("path", None)
    elif len(parts) == 2:
        camera[parts[1]] = value
    elif len(parts) == 3 and parts[1] == "path":
        path = camera.get("path") or {}
        # no kind here: check_path infers it from all the path's keys, in any order
        path = {"kind": path} if isinstance(path, str) else dict(path)
        path[parts[2]] = value
        camera["path"] = path
    else:
        raise _fail(cfg.source, f"cannot set '{key}': use camera.<key> or camera.path.<key> "
                    f"(camera keys: {', '.join(_CAMERA_KEYS)})", f"--set {key}")
    if parts[1] not in _CAMERA_KEYS:
        raise _fail(cfg.source, f"unknown key '{parts[1]}'" + did_you_mean(parts[1],
                                                                        _CAMERA_KEYS),
                    f"--set {key}")
    return replace(cfg, camera=camera)  # checked once all --set are in: apply_overrides


def _pass_entry(t: Any, i: int, source: str) -> PassEntry:
    if not isinstance(t, dict) or "name" not in t:
        raise _fail(source, "needs a 'name'", f"[[pass]] #{i + 1}")
    name = check_identifier("pass", t["name"], file=source, element=f"[[pass]] #{i + 1}")
    where = f"pass '{name}'"
    _check_keys(t, _PASS_KEYS, where, source)
    use = check_identifier("pass id", t.get("use", name), file=source,
                           element=f"{where}: 'use'")
    inputs = _table(t.get("inputs", {}), f"{where}: 'inputs'", source)
    for slot, feed in inputs.items():
        check_identifier("input slot", slot, file=source, element=f"{where}: inputs")
        check_identifier("resource", _string(feed, f"{where}: inputs.{slot}", source),
                         file=source, element=f"{where}: inputs.{slot}")
    settings = _table(t.get("settings", {}), f"{where}: 'settings'", source)
    if not isinstance(t.get("enabled", True), bool):
        raise _fail(source, f"{where}: 'enabled' must be true or false")
    if t.get("backend") not in (None, "wgpu", "vk"):
        raise _fail(source, f"{where}: unknown backend {t['backend']!r}"
                    + did_you_mean(str(t["backend"]), ("wgpu", "vk")))
    return PassEntry(name, use, t.get("enabled", True), dict(inputs), dict(settings),
                     t.get("backend"))


def _check_variant(vname: str, v: Any, source: str) -> None:
    check_identifier("variant", vname, file=source, element="variants")
    v = _table(v, f"variants.{vname}", source)
    for option, value in v.items():
        if option == "default":
            continue
        where = f"variants.{vname}.{option}"
        check_identifier("variant option", option, file=source, element=f"variants.{vname}")
        if isinstance(value, list) and not (value and all(
                isinstance(o, str) and o in v and isinstance(v[o], dict) for o in value)):
            raise _fail(source, f"{where}: a list must name options of "
                                f"the variant ({', '.join(k for k in v if k != 'default')})")
        if not isinstance(value, dict | list):
            raise _fail(source, f"{where}: expected a table of overrides "
                                "or a list of options")


_RUN_ONLY_KEYS = ("scene", "camera", "variants", "frames", "animation")


def is_run_config(path: str | Path) -> bool:
    """Whether ``path`` is a run config (passes by pass id, with ``use``, a scene...) rather
    than a graph TOML (passes with typed slots); unreadable files are left to the loader."""
    try:
        data = _read_toml(Path(path))
    except GraphError:
        return False
    tables = data.get("pass")
    tables = [t for t in tables if isinstance(t, dict)] if isinstance(tables, list) else []
    if any(k in data for k in _RUN_ONLY_KEYS) or any("use" in t for t in tables):
        return True
    return bool(tables) and not any("type" in t or "outputs" in t for t in tables)


def load_config(path: str | Path) -> Config:
    path = Path(path)
    return _config_from({"name": path.stem, **_read_toml(path)}, str(path), path.parent)


def _config_from(data: dict[str, Any], source: str, base_dir: Path | None) -> Config:
    """The config of a TOML file's table (``rfw.make_config`` builds one): checked, each
    variant's default in force. ``base_dir``: the folder a scene path is relative to (None:
    as given)."""
    _check_keys(data, _KEYS, "config", source)
    tables = data.get("pass", [])
    if not isinstance(tables, list):
        raise _fail(source, "must be an array of tables ([[pass]])", "pass")
    passes = [_pass_entry(t, i, source) for i, t in enumerate(tables)]
    if not passes:
        raise _fail(source, "the config has no [[pass]] tables")
    camera = None if data.get("camera") is None else _camera(data["camera"], source)
    outputs = data.get("outputs", [])
    if not isinstance(outputs, list):
        raise _fail(source, f"must be a list of resource names, not {outputs!r}", "outputs")
    for o in outputs:
        check_identifier("output", o, file=source, element="outputs")
    variants = _table(data.get("variants", {}), "variants", source)
    for vname, v in variants.items():
        _check_variant(vname, v, source)
    scene = _string(data.get("scene", "default"), "scene", source)
    if scene != "default" and base_dir is not None:
        scene = str(base_dir / scene)  # a config's scene is relative to the config
    frames = check_number(data.get("frames", 1), "frames", kind=int, lo=1, hi=MAX_FRAMES,
                          file=source, element="frames")
    cfg = Config(_string(data["name"], "name", source), passes, list(outputs),
                 scene, _size_of(data.get("size", [1280, 720]), source), camera, variants,
                 frames, source, base=list(passes),
                 async_compute=_async_compute(data.get("async_compute", "auto"), source,
                                              "async_compute"),
                 frames_in_flight=None if "frames_in_flight" not in data else check_number(
                     data["frames_in_flight"], "frames_in_flight", kind=int, lo=1,
                     hi=MAX_FRAMES_IN_FLIGHT, file=source, element="frames_in_flight"))
    if data.get("animation") is not None:
        from .timeline import check_animation

        cfg = replace(cfg, animation=check_animation(data["animation"], source))
    for vname, v in variants.items():
        default = v.get("default")
        if isinstance(default, bool):  # a switch: default = true
            default = _boolean_option(str(default).lower(), [k for k in v if k != "default"])
        if not isinstance(default, str) or default not in v:
            raise _fail(source, f"variants.{vname}: 'default' must name one of its options "
                                f"({', '.join(k for k in v if k != 'default')})")
        cfg = _apply_variant(cfg, vname, default)
    return cfg


def _apply_variant(cfg: Config, vname: str, option: str) -> Config:
    """Choose ``option`` of variant ``vname`` and recompute the passes: the file's passes,
    then every variant's chosen overrides in the order the file declares the variants (so a
    later variant wins where two set one key, whatever the order of ``--set``), then the
    explicit ``--set pass.key`` overrides in their order."""
    v = cfg.variants[vname]
    options = [k for k in v if k != "default"]
    option = _boolean_option(option, options)
    if option not in options:
        raise _fail(cfg.source, f"variant '{vname}' has no option '{option}'"
                    + did_you_mean(option, options))
    return _recompute(replace(cfg, chosen={**cfg.chosen, vname: option}))


def _recompute(cfg: Config) -> Config:
    out = replace(cfg, passes=list(cfg.base))
    for name, v in cfg.variants.items():
        if name in cfg.chosen:
            for key, value in _overrides(v, cfg.chosen[name]).items():
                out = _set(out, key, value)
    for key, value in cfg.explicit:
        out = _set(out, key, value)
    return out


def _overrides(v: dict[str, Any], option: str) -> dict[str, Any]:
    """An option's overrides; an auto option (a list) stands for its last option until a
    device resolves it."""
    value = v[option]
    return v[value[-1]] if isinstance(value, list) else value


def pass_class(cfg: Config, entry: PassEntry) -> type[Pass]:
    """The class of ``entry``'s pass id; an unknown id names the config and the pass."""
    return get_pass(entry.use, file=cfg.source, element=f"pass '{entry.name}'")


def missing_caps(cfg: Config, caps: frozenset[str]) -> dict[str, list[str]]:
    """The capabilities each enabled pass of ``cfg`` needs and ``caps`` lacks (by pass)."""
    from .graph.compile import IMPLIED_CAPS

    out: dict[str, list[str]] = {}
    for entry in cfg.passes:
        if not entry.enabled:
            continue
        try:
            inst = pass_class(cfg, entry)(entry.name, **entry.settings)
        except GraphError as e:
            raise e.in_file(cfg.source) from None
        need = [c for c in (*IMPLIED_CAPS.get(inst.type, ()), *inst.requires) if c not in caps]
        if need:
            out[entry.name] = need
    return out


def resolve_auto(cfg: Config, caps: Any) -> tuple[Config, dict[str, str]]:
    """Resolve auto options for a device with capabilities ``caps``: each variant left at
    an option that lists others takes the first of them whose enabled passes the device can
    run. Returns the config and, for every variant that has an auto option, the option in
    force (``{"shadows": "ray_query"}``; explicit choices are reported as they are)."""
    caps = frozenset(caps)
    techniques: dict[str, str] = {}
    for name, v in cfg.variants.items():
        if not any(isinstance(value, list) for value in v.values()):
            continue
        chosen = cfg.chosen.get(name, "")
        if not isinstance(v.get(chosen), list):
            techniques[name] = chosen
            continue
        why = []
        for option in v[chosen]:
            trial = _apply_variant(cfg, name, option)
            missing = missing_caps(trial, caps)
            if not missing:
                cfg, techniques[name] = trial, option
                break
            why.append(f"{option} (" + "; ".join(f"pass '{p}' needs {', '.join(c)}"
                                                  for p, c in missing.items()) + ")")
        else:
            raise _fail(cfg.source, f"variant '{name}': the device can run none of its "
                                    f"'{chosen}' options: " + ", ".join(why))
    return cfg, techniques


_TRUE, _FALSE = ("true", "on", "1", "yes"), ("false", "off", "0", "no")


def _boolean_option(option: str, options: list[str]) -> str:
    """A switch variant (options spelled true/false or on/off) takes any boolean spelling:
    ``--set culling.cone=off`` picks the option ``false``."""
    if option in options:
        return option
    word = str(option).lower()
    for group in (_TRUE, _FALSE):
        if word in group:
            match = [o for o in options if o.lower() in group]
            if len(match) == 1:
                return match[0]
    return option


def _set(cfg: Config, key: str, value: Any) -> Config:
    """Set one pass key: ``<pass>.enabled``, ``<pass>.inputs.<slot>`` or
    ``<pass>.<setting>``."""
    head, _, tail = key.partition(".")
    if not tail:
        raise _fail(cfg.source, f"cannot set '{key}': use <pass>.<setting>, <pass>.enabled, "
                                "size, scene, frames or a variant name")
    entry = cfg.entry(head)
    passes = []
    for p in cfg.passes:
        if p is not entry:
            passes.append(p)
        elif tail == "enabled":
            passes.append(replace(p, enabled=_bool(value, key, cfg.source)))
        elif tail.startswith("inputs."):
            slot = check_identifier("input slot", tail[7:], file=cfg.source, element=key)
            feed = check_identifier("resource", value, file=cfg.source, element=key)
            passes.append(replace(p, inputs={**p.inputs, slot: feed}))
        else:
            passes.append(replace(p, settings={**p.settings, tail: value}))
    return replace(cfg, passes=passes)


def _bool(value: Any, key: str, source: str) -> bool:
    if isinstance(value, bool):
        return value
    if isinstance(value, str) and value.lower() in ("true", "false", "on", "off", "1", "0"):
        return value.lower() in ("true", "on", "1")
    raise _fail(source, f"'{key}' must be true or false, got {value!r}")


def parse_size(text: str) -> tuple[int, int]:
    """``"WxH"`` -> ``(W, H)``, both positive; ValueError saying what was expected."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise ValueError(f"expected WxH (e.g. 1920x1080), got '{text}'") from None
    if w < 1 or h < 1:
        raise ValueError(f"size must be positive, got {w}x{h}")
    if w > MAX_SIZE or h > MAX_SIZE:
        raise ValueError(f"size {w}x{h} is over {MAX_SIZE} pixels per side")
    return w, h


def apply_overrides(cfg: Config, sets: list[str]) -> Config:
    """``--set key=value``: a variant, size/scene/frames, pass.enabled or pass.setting."""
    camera_set = False
    for item in sets:
        key, eq, value = item.partition("=")
        key = key.strip()
        if not eq or not key:
            raise _fail(cfg.source, f"--set '{item}': expected key=value")
        value = value.strip()
        if key in cfg.variants:
            cfg = _apply_variant(cfg, key, value)
        elif key == "size":
            try:
                cfg = replace(cfg, size=parse_size(value))
            except ValueError as e:
                raise _fail(cfg.source, f"--set size={value}: {e}") from None
        elif key == "scene":
            cfg = replace(cfg, scene=value)
        elif key == "frames":
            cfg = replace(cfg, frames=_frames(value, cfg.source))
        elif key == "async_compute":
            cfg = replace(cfg, async_compute=_async_compute(value, cfg.source,
                                                            "--set async_compute"))
        elif key == "frames_in_flight":
            cfg = replace(cfg, frames_in_flight=_frames(
                value, cfg.source, key="frames_in_flight", hi=MAX_FRAMES_IN_FLIGHT))
        elif key == "camera" or key.startswith("camera."):
            cfg = _set_camera(cfg, key, value)
            camera_set = True
        elif key.startswith("animation."):
            cfg = _set_animation(cfg, key, value)
        else:
            head = key.partition(".")[0]
            if head not in [p.name for p in cfg.passes]:
                known = [p.name for p in cfg.passes] + list(cfg.variants) + [
                    "size", "scene", "frames", "async_compute", "frames_in_flight", "camera",
                    "animation"]
                raise _fail(cfg.source, f"--set '{key}': no pass or variant '{head}'"
                            + did_you_mean(head, known))
            cfg = _set(cfg, key, value)  # fails here on a bad key, before it is kept
            cfg = replace(cfg, explicit=[*cfg.explicit, (key, value)])
    if camera_set:  # the whole camera table: a path's keys may come in any order
        cfg = replace(cfg, camera=_camera(cfg.camera, cfg.source, "--set "))
    return cfg


def _set_animation(cfg: Config, key: str, text: str) -> Config:
    """``--set animation.KEY=VALUE`` (``animation.fps=30``, ``animation.clip=walk``),
    checked with the whole ``[animation]`` table."""
    from .timeline import ANIMATION_KEYS, check_animation

    name = key.partition(".")[2]
    if name not in ANIMATION_KEYS:
        raise _fail(cfg.source, f"unknown key '{name}'" + did_you_mean(name, ANIMATION_KEYS),
                    f"--set {key}")
    value = _camera_value(text)
    table = {**(cfg.animation or {}), name: value}
    try:
        return replace(cfg, animation=check_animation(table, cfg.source, "--set animation"))
    except RfwError as e:
        raise _fail(cfg.source, e.message, e.element) from None


def _async_compute(value: Any, source: str, element: str) -> str:
    """``auto``, or any boolean spelling (TOML true/false, on/off, ...) as ``on``/``off``."""
    word = str(value).lower() if isinstance(value, bool | str) else None
    if word == "auto":
        return word
    if word in _TRUE or word in _FALSE:
        return "on" if word in _TRUE else "off"
    raise _fail(source, f"must be true, false or \"auto\", not {value!r}", element)


def _frames(text: str, source: str, *, key: str = "frames", hi: int = MAX_FRAMES) -> int:
    try:
        value = int(text)
    except ValueError:
        raise _fail(source, f"must be an integer, not {text!r}", f"--set {key}") from None
    return check_number(value, key, kind=int, lo=1, hi=hi, file=source,
                        element=f"--set {key}")


def _has_work(cfg: Config, entry: PassEntry, scene: Any) -> bool:
    need = pass_class(cfg, entry).scene_needs
    if need is None:
        return True
    if need not in SCENE_NEEDS:
        raise _fail(cfg.source, f"pass '{entry.name}' ({entry.use}): scene_needs must be one "
                                f"of {', '.join(SCENE_NEEDS)}, not {need!r}")
    return SCENE_NEEDS[need](scene)


@dataclass
class Built:
    graph: Graph
    passes: dict[str, Pass]  # enabled passes by name
    slots: dict[str, dict[str, str]]  # pass -> slot -> resource


def for_scene(cfg: Config, scene: Any) -> Config:
    """``cfg`` without the enabled passes whose ``scene_needs`` ``scene`` lacks (a
    points_lines pass on a scene without points or lines): not listed as disabled either.
    ``cfg`` itself where every pass has work."""
    passes = [p for p in cfg.passes if not p.enabled or _has_work(cfg, p, scene)]
    return cfg if len(passes) == len(cfg.passes) else replace(cfg, passes=passes)


def build(cfg: Config, scene: Any = None) -> Built:
    """Instantiate the passes and wire their slots into a frame graph; with ``scene``, for
    that scene (:func:`for_scene`)."""
    if scene is not None:
        cfg = for_scene(cfg, scene)
    enabled = {p.name for p in cfg.passes if p.enabled}
    g = GraphBuilder(cfg.name, size=cfg.size, source=cfg.source)
    instances: dict[str, Pass] = {}
    slots: dict[str, dict[str, str]] = {}
    for entry in cfg.passes:
        cls = pass_class(cfg, entry)
        try:
            inst = cls(entry.name, **entry.settings)
        except GraphError as e:
            raise e.in_file(cfg.source) from None
        ins, outs = inst.declare()
        for key in entry.inputs:
            if key not in ins:
                raise _fail(cfg.source, f"pass '{entry.name}' ({entry.use}): no input slot "
                                        f"'{key}'" + did_you_mean(key, ins))
        # the instance's type and requirements: a setting may choose them (ray methods)
        b = g.add_pass(entry.name, inst.type, enabled=entry.enabled,
                       side_effect=cls.side_effect, requires=inst.requires,
                       settings=inst.params.as_dict(), schema=tuple(inst.params.fields()),
                       backend=entry.backend or cls.backend, steps=inst.steps())
        mapping: dict[str, str] = {}
        for slot, spec in ins.items():
            source = entry.inputs.get(slot)
            feeder = None if source is None else source.partition(".")[0]
            if source is None or (feeder in [p.name for p in cfg.passes]
                                  and feeder not in enabled):
                if spec.optional:
                    continue  # unfed: the pass runs without it
                if entry.enabled:
                    why = "is not connected" if source is None else \
                        f"reads '{source}', whose pass is disabled"
                    raise _fail(cfg.source, f"pass '{entry.name}' ({entry.use}): input "
                                            f"'{slot}' {why}")
                continue
            b.input(slot, source, spec)
            # a history slot reads last frame's value: the plan's "<resource>@prev" copy
            mapping[slot] = f"{source}@prev" if spec.type == "history" else source
        for slot, spec in outs.items():
            if spec.size is not None and spec.size.mode == "relative" and spec.size.of in mapping:
                spec = spec.with_(size=SizeRule.like(mapping[spec.size.of], *spec.size.scale))
            elif spec.size is not None and spec.size.mode == "relative" and spec.size.of in outs:
                spec = spec.with_(size=SizeRule.like(f"{entry.name}.{spec.size.of}",
                                                     *spec.size.scale))
            b.output(slot, spec)
            mapping[slot] = f"{entry.name}.{slot}"
        if entry.enabled:
            instances[entry.name] = inst
            slots[entry.name] = mapping
    g.output(*cfg.outputs)
    return Built(replace(g.build(), async_compute=cfg.async_compute), instances, slots)
