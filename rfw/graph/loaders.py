"""Graphs from files: rfw's TOML format and the Raptor engine's JSON frame graphs.

Both produce the same ``Graph`` the Python builder makes, so all three compile alike.
Errors name the file, the pass and the slot (and the line where it can be found).
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import rtoml
import tomli_w

from ..errors import check_identifier
from .errors import GraphError, did_you_mean
from .graph import Graph, GraphBuilder, PassBuilder, gc_paused, is_identifier
from .resources import BUFFER_USAGES, IMAGE_USAGES, LOAD_OPS, PASS_TYPES, SLOT_TYPES, SizeRule, Slot

# the Raptor engine's samples run in a 1280x800 window: its relative sizes scale that
RAPTOR_DEFAULT_SIZE = (1280, 800)


def load_graph(path: str | Path, *, strict: bool | None = None) -> Graph:
    """Load a ``.toml`` (rfw) or ``.json`` (Raptor) frame graph."""
    path = Path(path)
    if path.suffix.lower() == ".json":
        return load_raptor(path, strict=strict)
    if path.suffix.lower() == ".toml":
        return load_toml(path, strict=strict)
    raise GraphError(f"unknown graph file type '{path.suffix}' (expected .toml or .json)",
                     file=str(path))


def _read(path: Path) -> str:
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise GraphError("file not found", file=str(path)) from None
    except OSError as e:
        raise GraphError(f"cannot read: {e.strerror or e}", file=str(path)) from None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        line = data.count(b"\n", 0, e.start) + 1
        column = e.start - (data.rfind(b"\n", 0, e.start) + 1) + 1
        raise GraphError(f"not UTF-8 text: byte 0x{data[e.start]:02x} at line {line}, column "
                         f"{column}", file=str(path)) from None


class _Lines:
    """Where each pass name first appears in a file, indexed in one sweep.

    A regex per pass made loading quadratic in the file size; the sweep records the first
    ``key = "value"`` (TOML) or ``"key": "value"`` (JSON) line of every quote-free value.
    """

    def __init__(self, text: str, pattern: str, value: Callable[[str], str]):
        self.text, self.value = text, value
        self.first: dict[str, int] = {}
        line, pos = 1, 0
        for m in re.finditer(pattern, text):
            line += text.count("\n", pos, m.start())
            pos = m.start()
            self.first.setdefault(m.group(1), line)

    def of(self, name: str) -> int | None:
        if name in self.first:
            return self.first[name]
        if not any(c in name for c in "\"'\\\n"):
            return None  # the sweep saw every quote-free value
        # names with quotes or escapes are rare: search for them one by one
        m = re.search(self.value(re.escape(name)), self.text)
        return None if m is None else self.text.count("\n", 0, m.start()) + 1


def _toml_lines(text: str) -> _Lines:
    return _Lines(text, r'name\s*=\s*["\']([^"\'\n]*)["\']',
                  lambda name: r'name\s*=\s*["\']' + name + r'["\']')


def _raptor_lines(text: str) -> _Lines:
    return _Lines(text, r'"name"\s*:\s*"([^"\\\n]*)"',
                  lambda name: r'"name"\s*:\s*"' + name + '"')


class _Checker:
    """Unknown keys and bad values: errors in strict mode, warnings in lenient mode."""

    def __init__(self, source: str, strict: bool):
        self.source, self.strict = source, strict
        self.warnings: list[tuple[str, str]] = []

    def fail(self, message: str) -> None:
        raise GraphError(message, file=self.source)

    def keys(self, table: Mapping[str, Any], known: tuple[str, ...], where: str) -> None:
        for key in table:
            if key not in known:
                msg = f"{where}: unknown key '{key}'" + did_you_mean(key, known)
                if self.strict:
                    self.fail(msg)
                self.warnings.append(("warning", msg))

    def strings(self, value: Any, where: str) -> list[str]:
        """A string or a list of strings."""
        items = [value] if isinstance(value, str) else value
        if not isinstance(items, list) or not all(isinstance(v, str) for v in items):
            self.fail(f"{where}: expected a string or a list of strings, got "
                      f"{json.dumps(value)}")
        return items

    def number(self, value: Any, where: str, *, positive: bool = False) -> float:
        if value.__class__ is float and math.isfinite(value) and (value > 0 or not positive):
            return value  # the common case, before any message is made
        if isinstance(value, bool) or not isinstance(value, int | float) \
                or not math.isfinite(value) or (positive and value <= 0):
            what = "a positive finite number" if positive else "a finite number"
            self.fail(f"{where}: expected {what}, got {json.dumps(value)}")
        return float(value)

    def type(self, value: Any, types: type | tuple[type, ...], where: str,
             key: str | None = None) -> Any:
        """``value`` if it has one of ``types``; the error names ``where`` (and ``key``)."""
        if value.__class__ is types:
            return value  # the common case: big graphs check millions of values
        if key is not None:
            where = f"{where}: '{key}'"
        if not isinstance(value, types) or (isinstance(value, bool) and bool not in (
                types if isinstance(types, tuple) else (types,))):
            names = "/".join(t.__name__ for t in (types if isinstance(types, tuple) else
                                                  (types,)))
            self.fail(f"{where}: expected {names}, got {json.dumps(value)}")
        return value


# ---------------------------------------------------------------------------------------------
# TOML

_GRAPH_KEYS = ("name", "size", "strict", "outputs", "pass", "external")
_PASS_KEYS = ("name", "type", "enabled", "side_effect", "requires", "settings", "inputs",
              "outputs", "backend")
_OUT_KEYS = ("type", "format", "size", "scale", "size_of", "mips", "layers", "samples", "bytes",
             "usage", "load", "clear", "external", "read_only", "stages", "desc", "name",
             "target")
_IN_KEYS = ("from", "type", "format", "usage", "read_only", "stages", "desc", "load")
_EXTERNAL_KEYS = ("name", *(k for k in _OUT_KEYS if k not in ("name", "target", "external")))


def load_toml(path: str | Path, *, strict: bool | None = None) -> Graph:
    path = Path(path)
    return loads_toml(_read(path), source=str(path), strict=strict)


@gc_paused
def loads_toml(text: str, *, source: str = "<toml>", strict: bool | None = None) -> Graph:
    try:
        # rtoml (compiled) parses a 10k-pass graph three times faster than tomllib
        data = rtoml.loads(text)
    except rtoml.TomlParsingError as e:
        message = " ".join(str(e).split())
        if "recursion" in message or "recurse" in message:
            message = "nested too deeply"
        raise GraphError(f"malformed TOML: {message}", file=source) from None
    if strict is None:
        strict = data.get("strict", True) is not False
    check = _Checker(source, strict)
    check.keys(data, _GRAPH_KEYS, "graph")
    size = _size_pair(data.get("size"), "graph 'size'", check) if "size" in data else None
    g = GraphBuilder(str(data.get("name", Path(source).stem)), size=size, strict=strict,
                     source=source)
    for i, ext in enumerate(check.type(data.get("external", []), list, "[[external]]")):
        where = f"[[external]] #{i + 1}"
        check.type(ext, dict, where)
        check.keys(ext, _EXTERNAL_KEYS, where)
        if "name" not in ext:
            check.fail(f"{where}: missing 'name'")
        g.external(ext["name"], _toml_slot(ext, f"external '{ext['name']}'", check, out=True))
    passes = check.type(data.get("pass", []), list, "[[pass]]")
    if not passes:
        check.fail("the graph has no [[pass]] tables")
    lines = _toml_lines(text)
    for i, table in enumerate(passes):
        _toml_pass(g, table, i, lines, check)
    if "outputs" in data:
        g.output(*check.strings(check.type(data["outputs"], list, "graph 'outputs'"),
                                "graph 'outputs'"))
    graph = g.build()
    return _with_warnings(graph, check.warnings)


def _with_warnings(graph: Graph, warnings: list[tuple[str, str]]) -> Graph:
    from dataclasses import replace

    return replace(graph, diagnostics=tuple(warnings)) if warnings else graph


def _toml_pass(g: GraphBuilder, table: Any, i: int, lines: _Lines, check: _Checker) -> None:
    check.type(table, dict, f"[[pass]] #{i + 1}")
    if "name" not in table:
        check.fail(f"[[pass]] #{i + 1}: missing 'name'")
    name = check.type(table["name"], str, f"[[pass]] #{i + 1} 'name'")
    where = f"pass '{name}'"
    line = lines.of(name)
    origin = f"line {line}" if line else None
    if origin:
        where += f" ({origin})"
    if not is_identifier(name):
        check_identifier("pass", name, file=check.source,
                         element=f"[[pass]] #{i + 1}" + (f" ({origin})" if origin else ""))
    check.keys(table, _PASS_KEYS, where)
    ptype = check.type(table.get("type", "graphics"), str, where, "type")
    if ptype not in PASS_TYPES:
        check.fail(f"{where}: unknown pass type '{ptype}'" + did_you_mean(str(ptype), PASS_TYPES))
    p = g.add_pass(name, ptype,
                   enabled=check.type(table.get("enabled", True), bool, where, "enabled"),
                   side_effect=check.type(table.get("side_effect", False), bool, where,
                                          "side_effect"),
                   requires=check.strings(table.get("requires", []), f"{where}: 'requires'")
                   if "requires" in table else [],
                   settings=check.type(table.get("settings", {}), dict, where, "settings"),
                   origin=origin, backend=_backend(table.get("backend"), where, check))
    for slot, spec in check.type(table.get("inputs", {}), dict, where, "inputs").items():
        _toml_input(p, slot, spec, f"{where}, input '{slot}'", check)
    for slot, spec in check.type(table.get("outputs", {}), dict, where, "outputs").items():
        _toml_output(p, slot, spec, f"{where}, output '{slot}'", check)


BACKENDS = ("wgpu", "vk")


def _backend(value: Any, where: str, check: _Checker) -> str | None:
    if value is None:
        return None
    if value not in BACKENDS:
        check.fail(f"{where}: unknown backend {json.dumps(value)}"
                   + did_you_mean(str(value), BACKENDS))
    return value


def _toml_input(p: PassBuilder, slot: str, spec: Any, where: str, check: _Checker) -> None:
    if isinstance(spec, str):
        spec = {"from": spec}
    check.type(spec, dict, where)
    check.keys(spec, _IN_KEYS, where)
    if "from" not in spec:
        check.fail(f"{where}: missing 'from' (the resource it reads, e.g. \"gbuffer.albedo\")")
    p.input(slot, check.type(spec["from"], str, where, "from"),
            _toml_slot(spec, where, check, out=False))


def _toml_output(p: PassBuilder, slot: str, spec: Any, where: str, check: _Checker) -> None:
    check.type(spec, dict, where)
    check.keys(spec, _OUT_KEYS, where)
    s = _toml_slot(spec, where, check, out=True)
    if s.type == "reference":
        if "target" not in spec:
            check.fail(f"{where}: a reference output needs 'target' (the resource written "
                       "in place)")
        p.output(slot, s, target=check.type(spec["target"], str, f"{where}: 'target'"))
    else:
        name = spec.get("name")
        p.output(slot, s, name=None if name is None else check.type(name, str,
                                                                    f"{where}: 'name'"))


def _toml_slot(spec: Mapping[str, Any], where: str, check: _Checker, *, out: bool) -> Slot:
    stype = check.type(spec.get("type", "texture"), str, where, "type")
    if stype not in SLOT_TYPES:
        check.fail(f"{where}: unknown slot type '{stype}'" + did_you_mean(str(stype), SLOT_TYPES))
    kw: dict[str, Any] = {}
    for key in ("format", "desc"):
        if key in spec:
            kw[key] = check.type(spec[key], str, where, key)
    for key in ("mips", "layers", "samples", "bytes"):
        if key in spec:
            kw[key] = check.type(spec[key], int, where, key)
    for key in ("external", "read_only"):
        if key in spec:
            kw[key] = check.type(spec[key], bool, where, key)
    if "usage" in spec:
        kw["usage"] = frozenset(check.strings(spec["usage"], f"{where}: 'usage'"))
        for u in sorted(kw["usage"] - BUFFER_USAGES - IMAGE_USAGES):
            check.fail(f"{where}: 'usage': unknown usage '{u}'"
                       + did_you_mean(u, BUFFER_USAGES | IMAGE_USAGES))
    if "stages" in spec:
        kw["stages"] = frozenset(check.strings(spec["stages"], f"{where}: 'stages'"))
    if "load" in spec:
        if not isinstance(spec["load"], str) or spec["load"] not in LOAD_OPS:
            check.fail(f"{where}: unknown load op '{spec['load']}'"
                       + did_you_mean(str(spec["load"]), LOAD_OPS))
        kw["load"] = spec["load"]
    if "clear" in spec:
        clear = check.type(spec["clear"], list, f"{where}: 'clear'")
        kw["clear"] = tuple(check.number(c, f"{where}: 'clear'") for c in clear)
    if out:
        kw["size"] = _toml_size(spec, where, check)
    if stype == "buffer" and "usage" not in kw:
        kw["usage"] = frozenset({"storage"})
    return Slot(stype, **kw)


def _toml_size(spec: Mapping[str, Any], where: str, check: _Checker) -> SizeRule | None:
    scale = spec.get("scale", 1.0)
    if isinstance(scale, (int, float)) and not isinstance(scale, bool):
        sx = sy = check.number(scale, f"{where}: 'scale'", positive=True)
    else:
        sx, sy = _pair(scale, f"{where}: 'scale'", check, float)
        check.number(sx, f"{where}: 'scale'", positive=True)
        check.number(sy, f"{where}: 'scale'", positive=True)
    if "size" in spec:
        if "size_of" in spec or "scale" in spec:
            check.fail(f"{where}: 'size' is fixed; it cannot be combined with 'scale' or "
                       "'size_of'")
        return SizeRule.fixed(*_size_pair(spec["size"], f"{where}: 'size'", check))
    if "size_of" in spec:
        return SizeRule.like(check.type(spec["size_of"], str, f"{where}: 'size_of'"), sx, sy)
    if "scale" in spec:
        return SizeRule.output(sx, sy)
    return None


def _pair(value: Any, where: str, check: _Checker, kind: Callable[[Any], Any]) -> tuple:
    if not isinstance(value, list | tuple) or len(value) != 2 or not all(
            isinstance(v, int | float) and not isinstance(v, bool) for v in value):
        check.fail(f"{where}: expected [x, y], got {json.dumps(value)}")
    return kind(value[0]), kind(value[1])


def _size_pair(value: Any, where: str, check: _Checker) -> tuple[int, int]:
    w, h = _pair(value, where, check, lambda v: v)
    if not (math.isfinite(w) and math.isfinite(h)) or w != int(w) or h != int(h) \
            or w < 1 or h < 1:
        check.fail(f"{where}: a size must be two positive integers, got {json.dumps(value)}")
    return int(w), int(h)


def to_toml(graph: Graph) -> str:
    """The graph as rfw TOML (``rfw graph convert``); loading it gives an equal graph."""
    data: dict[str, Any] = {"name": graph.name}
    if graph.size:
        data["size"] = list(graph.size)
    data["strict"] = graph.strict
    if graph.outputs is not None:
        data["outputs"] = list(graph.outputs)
    if graph.imports:
        data["external"] = [{"name": n, **_slot_table(s, out=True, external=False)}
                            for n, s in graph.imports]
    data["pass"] = []
    for p in graph.passes:
        table: dict[str, Any] = {"name": p.name, "type": p.type}
        if not p.enabled:
            table["enabled"] = False
        if p.side_effect:
            table["side_effect"] = True
        if p.requires:
            table["requires"] = list(p.requires)
        if p.backend:
            table["backend"] = p.backend
        if p.settings:
            table["settings"] = _thaw(p.settings)
        ins = {b.slot: {"from": b.resource, **_slot_table(b.spec, out=False)} for b in p.inputs}
        outs = {}
        for b in p.outputs:
            t = _slot_table(b.spec, out=True)
            if b.spec.type == "reference":
                t["target"] = b.resource
            elif b.resource != f"{p.name}.{b.slot}":
                t["name"] = b.resource
            outs[b.slot] = t
        if len(ins) != len(p.inputs) or len(outs) != len(p.outputs):
            raise GraphError(f"pass '{p.name}' uses one slot name twice; TOML keys are unique",
                             file=graph.source)
        if ins:
            table["inputs"] = ins
        if outs:
            table["outputs"] = outs
        data["pass"].append(table)
    return tomli_w.dumps(data)


def _thaw(settings: tuple) -> dict[str, Any]:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in settings}


def _slot_table(s: Slot, *, out: bool, external: bool = True) -> dict[str, Any]:
    t: dict[str, Any] = {"type": s.type}
    if s.format:
        t["format"] = s.format
    if out and s.size is not None:
        if s.size.mode == "fixed":
            t["size"] = [s.size.width, s.size.height]
        else:
            if s.size.mode == "relative":
                t["size_of"] = s.size.of
            if s.size.scale != (1.0, 1.0) or s.size.mode == "output":
                t["scale"] = list(s.size.scale)
    for key in ("mips", "layers", "samples"):
        if getattr(s, key) != 1:
            t[key] = getattr(s, key)
    if s.bytes is not None:
        t["bytes"] = s.bytes
    if s.usage:
        t["usage"] = sorted(s.usage)
    if s.stages:
        t["stages"] = sorted(s.stages)
    if s.load:
        t["load"] = s.load
    if s.clear is not None:
        t["clear"] = list(s.clear)
    if s.external and external:
        t["external"] = True
    if s.read_only:
        t["read_only"] = True
    if s.desc:
        t["desc"] = s.desc
    return t


# ---------------------------------------------------------------------------------------------
# Raptor JSON (Mastering Graphics Programming with Vulkan)

_R_GRAPH_KEYS = ("name", "passes")
_R_PASS_KEYS = ("name", "type", "enabled", "inputs", "outputs")
_R_IN_KEYS = ("type", "name")
_R_OUT_KEYS = ("type", "name", "external", "format", "load_operation", "op", "clear_color",
               "clear_depth", "clear_stencil", "resolution", "resolution_scale")
_R_TYPES = ("texture", "attachment", "buffer", "reference", "shading_rate")
_R_PASS_TYPES = {"": "graphics", "graphics": "graphics", "compute": "compute",
                 "ray_tracing": "ray_tracing"}
_R_LOAD = {"clear": "clear", "load": "load", "VK_ATTACHMENT_LOAD_OP_CLEAR": "clear",
           "VK_ATTACHMENT_LOAD_OP_LOAD": "load", "VK_ATTACHMENT_LOAD_OP_DONT_CARE": "dont_care"}


def load_raptor(path: str | Path, *, strict: bool | None = None) -> Graph:
    path = Path(path)
    return loads_raptor(_read(path), source=str(path), strict=strict)


@gc_paused
def loads_raptor(text: str, *, source: str = "<json>", strict: bool | None = None) -> Graph:
    """A Raptor frame graph. Lenient by default, as Raptor only warns about inputs that no
    pass produces; texture and buffer outputs without a description stay application-owned,
    as in Raptor."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError as e:
        raise GraphError(f"malformed JSON: {e.msg} (line {e.lineno}, column {e.colno})",
                         file=source) from None
    except RecursionError:
        raise GraphError("malformed JSON: nested too deeply", file=source) from None
    strict = False if strict is None else strict
    check = _Checker(source, strict)
    check.type(data, dict, "graph")
    check.keys(data, _R_GRAPH_KEYS, "graph")
    passes = check.type(data.get("passes"), list, "graph 'passes'")
    if not passes:
        check.fail("graph 'passes': the graph has no passes")
    g = GraphBuilder(str(data.get("name", Path(source).stem)), size=RAPTOR_DEFAULT_SIZE,
                     strict=strict, source=source)
    lines = _raptor_lines(text)
    kinds = _raptor_kinds(passes)
    for i, p in enumerate(passes):
        _raptor_pass(g, p, i, lines, check, kinds)
    return _with_warnings(g.build(), check.warnings)


def _raptor_kinds(passes: list[Any]) -> dict[str, str]:
    """``"image"`` or ``"buffer"`` per resource a Raptor output creates (any pass, enabled or
    not, declared before or after its readers): what a ``reference`` input reads."""
    kinds: dict[str, str] = {}
    for p in passes:
        outputs = p.get("outputs", []) if isinstance(p, dict) else []
        for r in outputs if isinstance(outputs, list) else []:
            if isinstance(r, dict) and isinstance(r.get("name"), str) \
                    and r.get("type") in ("attachment", "texture", "buffer"):
                kinds.setdefault(r["name"], "buffer" if r["type"] == "buffer" else "image")
    return kinds


def _raptor_pass(g: GraphBuilder, p: Any, i: int, lines: _Lines, check: _Checker,
                 kinds: dict[str, str]) -> None:
    check.type(p, dict, f"passes[{i}]")
    name = check.type(p.get("name"), str, f"passes[{i}] 'name'")
    line = lines.of(name)
    origin = f"line {line}" if line else None
    where = f"pass '{name}'" + (f" ({origin})" if origin else "")
    if not is_identifier(name):
        check_identifier("pass", name, file=check.source,
                         element=f"passes[{i}]" + (f" ({origin})" if origin else ""))
    check.keys(p, _R_PASS_KEYS, where)
    rtype = check.type(p.get("type", ""), str, where, "type")
    if rtype not in _R_PASS_TYPES:
        check.fail(f"{where}: unknown pass type '{rtype}'" + did_you_mean(str(rtype),
                                                                        _R_PASS_TYPES))
    ptype = _R_PASS_TYPES[rtype]
    b = g.add_pass(name, ptype, enabled=check.type(p.get("enabled", True), bool, where,
                                                     "enabled"), origin=origin)
    ins = check.type(p.get("inputs", []), list, f"{where}: 'inputs'")
    outs = check.type(p.get("outputs", []), list, f"{where}: 'outputs'")
    # names the pass also binds for real: a reference input on one of them only orders
    bound = {str(r.get("name")) for r in ins
             if isinstance(r, dict) and r.get("type") != "reference"}
    bound |= {str(r.get("name")) for r in outs if isinstance(r, dict)}
    for k, r in enumerate(ins):
        check.type(r, dict, f"{where}, inputs[{k}]")
        rname, rtype_ = _raptor_io(r, f"{where}, inputs[{k}]", check, _R_IN_KEYS)
        if rtype_ == "reference" and rname not in bound:
            # Raptor's reference input is an edge to a resource the pass reads by itself
            # (depth of field copies 'lighting', samples 'depth'): a real read, so its
            # producer is never culled, it lives until here and gets a barrier
            rtype_ = "buffer" if kinds.get(rname) == "buffer" else "texture"
        b.input(rname, rname, _raptor_input_slot(rtype_, ptype))
    for k, r in enumerate(outs):
        check.type(r, dict, f"{where}, outputs[{k}]")
        rname, rtype_ = _raptor_io(r, f"{where}, outputs[{k}]", check, _R_OUT_KEYS)
        _raptor_output(b, r, rname, rtype_, f"{where}, output '{rname}'", check)


def _raptor_io(r: Mapping[str, Any], where: str, check: _Checker,
               known: tuple[str, ...]) -> tuple[str, str]:
    check.keys(r, known, where)
    rtype = r.get("type")
    if not isinstance(rtype, str) or rtype not in _R_TYPES:
        check.fail(f"{where}: unknown resource type {json.dumps(rtype)}"
                   + did_you_mean(str(rtype), _R_TYPES))
    name = r.get("name")
    if not isinstance(name, str) or not name:
        check.fail(f"{where}: missing resource 'name'")
    return name, rtype


def _raptor_input_slot(rtype: str, ptype: str) -> Slot:
    if rtype == "buffer":  # Raptor's buffers are indirect draw lists read by draws and shaders
        usage = {"indirect", "storage"} if ptype == "graphics" else {"storage"}
        return Slot("buffer", usage=frozenset(usage))
    return Slot(rtype)


def _raptor_output(b: PassBuilder, r: Mapping[str, Any], name: str, rtype: str, where: str,
                   check: _Checker) -> None:
    if rtype == "reference":
        b.output(name, Slot("reference"), target=name)
        return
    if rtype == "shading_rate":
        check.fail(f"{where}: a shading_rate resource can only be an input")
    external = check.type(r.get("external", False), bool, where, "external")
    fmt = r.get("format")
    if rtype == "buffer" or (rtype == "texture" and fmt is None):
        # Raptor creates these outside the graph; they order passes but are not allocated
        if not external:
            check.warnings.append(("info", f"{where}: {rtype} without a description is "
                                           "application-owned, as in Raptor"))
        usage = frozenset({"storage"}) if rtype == "buffer" else frozenset()
        b.output(name, Slot(rtype, usage=usage, external=True), name=name)
        return
    if fmt is None:
        check.fail(f"{where}: an attachment needs a 'format'")
    check.type(fmt, str, where, "format")
    load = r.get("load_operation", r.get("op"))
    if load is not None and (not isinstance(load, str) or load not in _R_LOAD):
        check.fail(f"{where}: unknown load operation '{load}'" + did_you_mean(str(load), _R_LOAD))
    if "resolution" in r:
        size = SizeRule.fixed(*_size_pair(r["resolution"], f"{where}: 'resolution'", check))
    elif "resolution_scale" in r:
        sx, sy = _pair(r["resolution_scale"], f"{where}: 'resolution_scale'", check, float)
        if not (math.isfinite(sx) and math.isfinite(sy)) or sx <= 0 or sy <= 0:
            check.fail(f"{where}: 'resolution_scale' must be positive, got {[sx, sy]}")
        size = SizeRule.output(sx, sy)
    else:
        size = SizeRule.output()
    clear = None
    if "clear_color" in r:
        clear = tuple(check.number(c, f"{where}: 'clear_color'")
                      for c in check.type(r["clear_color"], list, f"{where}: 'clear_color'"))
    elif "clear_depth" in r:
        clear = (check.number(r["clear_depth"], f"{where}: 'clear_depth'"),
                 check.number(r.get("clear_stencil", 0), f"{where}: 'clear_stencil'"))
    b.output(name, Slot(rtype, fmt, size=size, load=_R_LOAD.get(load) if load else None,
                        clear=clear, external=external), name=name)
