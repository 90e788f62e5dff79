"""glTF JSON to pygltflib's document classes, every value checked against their type hints.

pygltflib's own ``from_json`` (dataclasses_json) takes seconds on large files and fails on
wrong types with messages that name no element, so the JSON is decoded here instead.
"""

from __future__ import annotations

import dataclasses
import json
import typing
from typing import Any, NoReturn

import pygltflib


class ShapeError(Exception):
    """A JSON value of the wrong type; the message names the element."""


def _shape_error(where: str, expected: str, value: Any) -> ShapeError:
    text = json.dumps(value)
    if len(text) > 40:
        text = text[:37] + "..."
    return ShapeError(f"{where.removeprefix('gltf.')}: expected {expected}, got {text}")


def decode_json(value: Any, hint: Any, where: str) -> Any:
    """One JSON value as the type ``hint`` says, or ShapeError naming the element."""
    if value is None:
        return None  # required fields are checked where they are used
    origin = typing.get_origin(hint)
    if origin is typing.Union:
        inner = [a for a in typing.get_args(hint) if a is not type(None)]
        return decode_json(value, inner[0], where)
    if hint is typing.Any:
        return value
    if origin is list:
        if not isinstance(value, list):
            raise _shape_error(where, "an array", value)
        (item,) = typing.get_args(hint)
        for i, v in enumerate(value):
            if v is None:  # a field set to null reads as absent, a list item cannot
                raise _shape_error(f"{where}[{i}]", "a value", v)
        return [decode_json(v, item, f"{where}[{i}]") for i, v in enumerate(value)]
    if hint is pygltflib.Attributes:
        if not isinstance(value, dict):
            raise _shape_error(where, "an object", value)
        for k, v in value.items():
            if isinstance(v, bool) or not isinstance(v, int):
                raise _shape_error(f"{where}.{k}", "an accessor index", v)
        return pygltflib.Attributes(**value)
    if origin is dict:
        if not isinstance(value, dict):
            raise _shape_error(where, "an object", value)
        return value
    if dataclasses.is_dataclass(hint):
        if not isinstance(value, dict):
            raise _shape_error(where, "an object", value)
        hints = _hints(hint)
        # unknown keys are dropped; extras may hold any JSON value and nothing reads them
        return hint(**{k: decode_json(v, hints[k], f"{where}.{k}") for k, v in value.items()
                       if k in hints and k != "extras"})
    if hint is bool:
        if not isinstance(value, bool):
            raise _shape_error(where, "true or false", value)
        return value
    if hint is int:
        if isinstance(value, float) and value.is_integer():
            value = int(value)  # some exporters write 0.0 for offsets
        if isinstance(value, bool) or not isinstance(value, int):
            raise _shape_error(where, "an integer", value)
        return value
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise _shape_error(where, "a number", value)
        return value
    if hint is str:
        if not isinstance(value, str):
            raise _shape_error(where, "a string", value)
        return value
    return value


_HINTS: dict[type, dict[str, Any]] = {}


def _hints(cls: type) -> dict[str, Any]:
    if cls not in _HINTS:
        _HINTS[cls] = typing.get_type_hints(cls)
    return _HINTS[cls]


def reject_constant(name: str) -> NoReturn:
    """``json.loads``' ``parse_constant``: NaN and Infinity are not JSON."""
    raise ValueError(f"{name} is not valid JSON")
