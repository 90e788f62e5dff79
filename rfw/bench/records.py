"""Reading ``results.jsonl``: whole records only, every timing a finite number of ms.

A file that is not UTF-8, a line cut short (a bench interrupted mid-write), a line that is
not JSON or nests past any record's depth is refused naming the file and the line. So is a
timing that is not a finite number of ms at least 0 (a string, a bool, NaN, ``Infinity``,
``1e400``, which JSON reads as inf) or that sits where a list of them belongs, naming the
field: a comparison of what is left after dropping such values would judge other runs than
the ones measured."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from ..errors import RfwError

SAMPLE_LISTS = ("gpu_ms", "cpu_ms", "wall_ms")  # per frame in a record's "frame"
PEER_LISTS = ("frame_ms", "gpu_ms")  # per frame in a peer's record
KINDS = ("rfw", "peer")


def read_results(path: Path) -> list[dict[str, Any]]:
    """The checked records of the ``results.jsonl`` at ``path`` (RfwError: ``FILE: line N:``)."""
    try:
        data = path.read_bytes()
    except OSError as e:
        raise RfwError(f"cannot read: {e.strerror or e}", file=str(path)) from None
    return parse_results(data, path)


def parse_results(data: bytes, path: str | Path) -> list[dict[str, Any]]:
    """The checked records of ``data``, a ``results.jsonl``'s bytes already read; errors
    name ``path`` as :func:`read_results` does."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        line = data.count(b"\n", 0, e.start) + 1
        raise RfwError(f"not UTF-8 (byte {e.start}: {data[e.start:e.end].hex()})",
                       file=str(path), element=f"line {line}") from None
    lines = text.split("\n")
    records = []
    for n, line in enumerate(lines, 1):
        if not line.strip():
            continue
        where = f"line {n}"
        try:
            record = json.loads(line)
        except RecursionError:
            raise RfwError("nested too deeply to be a run record", file=str(path),
                           element=where) from None
        except ValueError as e:
            last = n == len(lines)  # no newline after it: the writer stopped mid-line
            why = "cut short (no end of line: the bench that wrote it was interrupted?)" \
                if last else f"not JSON ({getattr(e, 'msg', e)})"
            raise RfwError(why, file=str(path), element=where) from None
        try:
            check_record(record)
        except RfwError as e:
            raise RfwError(e.message, file=str(path),
                           element=where + (f": {e.element}" if e.element else "")) from None
        records.append(record)
    return records


def check_record(record: Any) -> None:
    """Refuse a record compare or the report cannot judge (RfwError naming the field)."""
    if not isinstance(record, dict):
        raise RfwError(f"expected a run record (a JSON object), not {_kind(record)}")
    variant = record.get("variant")
    if not isinstance(variant, str) or not variant:
        raise RfwError("not a run record (no 'variant')" if variant is None else
                       f"expected a variant name, not {_kind(variant)}", element="variant")
    kind = record.get("kind", "rfw")
    if kind not in KINDS:
        raise RfwError(f"expected 'rfw' or 'peer', not {_kind(kind)}", element="kind")
    for key in ("image",):
        if record.get(key) is not None and not isinstance(record[key], str):
            raise RfwError(f"expected a file name, not {_kind(record[key])}", element=key)
    for key in ("ray", "inputs", "shader_files", "spirv", "camera_path"):
        if record.get(key) is not None and not isinstance(record[key], dict):
            raise RfwError(f"expected an object, not {_kind(record[key])}", element=key)
    _check_inputs(record)
    if record.get("error"):
        return  # a failed run: its times are not read
    if kind == "peer":
        for key in PEER_LISTS:
            _samples(record.get(key), key)
        if record.get("rays") is not None:
            _number(record["rays"], "rays")
        return
    passes = record.get("passes")
    if not isinstance(passes, list):
        raise RfwError("expected a list of passes, not "
                       f"{'nothing' if passes is None else _kind(passes)}", element="passes")
    names = set()
    for i, p in enumerate(passes):
        if not isinstance(p, dict) or not isinstance(p.get("name"), str) or not p["name"]:
            raise RfwError(f"expected {{name, gpu_ms, cpu_ms}}, not {_kind(p)}",
                           element=f"passes[{i}]")
        if p["name"] in names:
            raise RfwError(f"pass '{p['name']}' is listed twice", element=f"passes[{i}]")
        names.add(p["name"])
        for key in ("gpu_ms", "cpu_ms"):
            _samples(p.get(key), f"pass '{p['name']}': {key}")
    frame = record.get("frame")
    if not isinstance(frame, dict):
        raise RfwError("expected {gpu_ms, cpu_ms, wall_ms}, not "
                       f"{'nothing' if frame is None else _kind(frame)}", element="frame")
    for key in SAMPLE_LISTS:
        _samples(frame.get(key), f"frame.{key}")
    frames = (record.get("camera_path") or {}).get("frames")
    if frames is not None:
        _camera_frames(frames)


def _check_inputs(record: dict[str, Any]) -> None:
    for key in ("inputs", "shader_files", "spirv"):
        for name, digest in (record.get(key) or {}).items():
            if not isinstance(digest, str):
                raise RfwError(f"expected a sha256, not {_kind(digest)}",
                               element=f"{key}.{name}")


def _camera_frames(frames: Any) -> None:
    if not isinstance(frames, list):
        raise RfwError(f"expected a list, not {_kind(frames)}", element="camera_path.frames")
    for i, f in enumerate(frames):
        where = f"camera_path.frames[{i}]"
        if not isinstance(f, dict):
            raise RfwError(f"expected an object, not {_kind(f)}", element=where)
        for key in ("position", "target"):
            v = f.get(key)
            if v is not None and (not isinstance(v, list) or len(v) != 3):
                raise RfwError(f"expected 3 numbers, not {_kind(v)}", element=f"{where}.{key}")
            for j, x in enumerate(v or []):
                _finite(x, f"{where}.{key}[{j}]")
        for key in ("yfov", "t", "write_ms"):
            if f.get(key) is not None:
                _finite(f[key], f"{where}.{key}")


def _samples(value: Any, where: str) -> None:
    """A list of per-frame times (``null`` for a frame without one), or absent."""
    if value is None:
        return
    if not isinstance(value, list):
        raise RfwError(f"expected a list of times in ms, not {_kind(value)}", element=where)
    for i, x in enumerate(value):
        if x is not None:
            _number(x, f"{where}[{i}]")


def _number(x: Any, where: str) -> None:
    _finite(x, where)
    if x < 0:
        raise RfwError(f"expected a time in ms, at least 0, not {x!r}", element=where)


def _finite(x: Any, where: str) -> None:
    if isinstance(x, bool) or not isinstance(x, int | float):
        raise RfwError(f"expected a number, not {_kind(x)}", element=where)
    if isinstance(x, int) and abs(x) > 1e300:  # math.isfinite of a huge int overflows
        raise RfwError("expected a finite number, not an integer of "
                       f"{len(str(abs(x)))} digits", element=where)
    if not math.isfinite(x):
        raise RfwError(f"expected a finite number, not {x!r}"
                       + (" (JSON's Infinity, or a number too large for a double)"
                          if math.isinf(x) else ""), element=where)


def _kind(value: Any) -> str:
    """A value as the error shows it: JSON's words, cut to a few characters."""
    if isinstance(value, dict | list):  # not printed: it may nest deeply
        n = len(value)
        return (f"an object of {n} key{'s' * (n != 1)}" if isinstance(value, dict) else
                f"a list of {n} item{'s' * (n != 1)}")
    if isinstance(value, bool) or value is None:
        return json.dumps(value)
    if isinstance(value, str):
        return repr(value[:40] + ("..." if len(value) > 40 else ""))
    return repr(value)
