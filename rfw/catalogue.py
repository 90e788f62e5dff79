"""``rfw passes``: every registered pass (built-in and installed) with its docstring, slots
and settings. Apart from rfw.plugins, which the registry imports to find entry points."""

from __future__ import annotations

import inspect
import sys

from .errors import RfwError
from .registry import available


def catalogue(names: list[str] | None = None) -> list[dict]:
    """Every registered pass (built-in and installed), or those named: id, module, the first
    line of its docstring, its slots with formats and its settings with types, defaults and
    ranges, as ``rfw passes`` prints them."""
    passes = available()
    for name in names or ():
        if name not in passes:
            raise RfwError(f"unknown pass '{name}'", element="passes",
                           suggest=(name, passes))
    out = []
    for pass_id, cls in passes.items():
        if names and pass_id not in names:
            continue
        doc = cls.describe() or inspect.getdoc(sys.modules.get(cls.__module__)) or ""
        bounds = cls.Params.bounds()
        settings = []
        for key, (kind, default) in cls.Params.fields().items():
            lo, hi = (bounds[key].lo, bounds[key].hi) if key in bounds else (None, None)
            settings.append({"name": key, "type": kind.__name__ if isinstance(kind, type)
                             else str(kind),
                             "default": default, "min": lo, "max": hi})
        out.append({"id": pass_id, "module": cls.__module__,
                    "doc": " ".join(doc.strip().split("\n\n")[0].split()),
                    "type": cls.type, "backend": cls.backend,
                    "inputs": [_slot_info(k, s) for k, s in cls.inputs.items()],
                    "outputs": [_slot_info(k, s) for k, s in cls.outputs.items()],
                    "settings": settings})
    return out


def _slot_info(name: str, spec: object) -> dict:
    size = getattr(spec, "size", None)
    return {"name": name, "type": spec.type, "format": spec.format,  # type: ignore[attr-defined]
            "format_of": getattr(spec, "format_of", None),
            "size": None if size is None else size.describe(),
            "optional": getattr(spec, "optional", False),
            "desc": getattr(spec, "desc", "")}


def format_catalogue(entries: list[dict]) -> str:
    """``rfw passes`` as text: a header line per pass, then its slots and settings."""
    lines = []
    for e in entries:
        where = f"{e['type']}" + (f", {e['backend']} only" if e["backend"] else "")
        lines.append(f"{e['id']}  ({where}; {e['module']})")
        lines.append(f"    {e['doc'] or '(no docstring)'}")
        for direction, slots in (("in ", e["inputs"]), ("out", e["outputs"])):
            for s in slots:
                fmt = s["format"] or (f"format of {s['format_of']}" if s.get("format_of")
                                      else "any" if direction == "in " else "-")
                size = f", {s['size']}" if s["size"] else ""
                opt = ", optional" if s["optional"] else ""
                desc = f": {s['desc']}" if s["desc"] else ""
                lines.append(f"    {direction} {s['name']} ({s['type']} {fmt}{size}{opt}){desc}")
        for s in e["settings"]:
            rng = ""
            if s["min"] is not None or s["max"] is not None:
                lo = "" if s["min"] is None else f"{s['min']:g}"
                hi = "" if s["max"] is None else f"{s['max']:g}"
                rng = f" in {lo}..{hi}"
            lines.append(f"    set {s['name']}: {s['type']} = {s['default']!r}{rng}")
        lines.append("")
    return "\n".join(lines).rstrip() + "\n"
