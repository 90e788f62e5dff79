"""rfw's user-facing errors: one line, ``FILE: ELEMENT: message``, exit code 2 at the CLI.

Every error a user can cause (a bad config, scene, graph, shader, cache or command-line value)
is an ``RfwError``; the CLI prints ``rfw: error: <line>`` and exits 2. Any other exception is
a bug in rfw and may show its traceback. Values are validated where they enter (``check_*``
below), so the message can name the file and the key.
"""

from __future__ import annotations

import difflib
import math
import os
import re
import sys
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

# pass, resource, output and variant names: they become file names and labels
IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_.-]*")


def close_matches(word: str, choices: Iterable[str], n: int = 3) -> list[str]:
    return difflib.get_close_matches(word, list(choices), n=n, cutoff=0.6)


def did_you_mean(word: str, choices: Iterable[str]) -> str:
    found = close_matches(word, choices)
    if not found:
        return ""
    return " (did you mean " + " or ".join(f"'{m}'" for m in found) + "?)"


def _one_line(text: str) -> str:
    # control characters (newlines included) never reach the terminal raw
    return re.sub(r"[\x00-\x1f\x7f]", lambda m: repr(m[0])[1:-1], text)


class RfwError(ValueError):
    """An error the user can fix. ``str()`` is one line: ``FILE: ELEMENT: message``.

    ``element`` names the pass, slot, key or line (``pass 'ssao': setting 'radius'``);
    ``more`` holds the other problems found in the same run."""

    def __init__(self, message: str, *, file: str | None = None, element: str | None = None,
                 suggest: tuple[str, Iterable[str]] | None = None,
                 more: Iterable[str] = ()):
        if suggest is not None:
            message += did_you_mean(*suggest)
        self.message = _one_line(message)
        self.file = None if file is None else _one_line(str(file))
        self.element = None if element is None else _one_line(element)
        self.more = list(more)
        super().__init__(self.line())

    def line(self) -> str:
        extra = f" (and {len(self.more)} more problem{'s' * (len(self.more) > 1)})" \
            if self.more else ""
        head = "".join(f"{p}: " for p in (self.file, self.element) if p)
        return head + self.message + extra

    def in_file(self, file: str | None) -> RfwError:
        """Name ``file`` unless a file is already named (the innermost one wins)."""
        if file and not self.file:
            self.file = _one_line(str(file))
            self.args = (self.line(),)
        return self

    def about(self, element: str) -> RfwError:
        """Name ``element`` (``pass 'ssao'``) unless the error names one or mentions it."""
        if not self.element and element not in self.message:
            self.element = _one_line(element)
            self.args = (self.line(),)
        return self


class RfwTypeError(RfwError, TypeError):
    """An argument of the wrong type (``rfw.load(5)``): an RfwError that is a TypeError too."""


class RfwValueError(RfwError):
    """An argument of the right type but a bad value (an RfwError, so a ValueError)."""


def type_name(value: Any) -> str:
    """``int 5``, ``str 'x'``: what an argument was, for "expected ..., not ..." messages."""
    text = repr(value)
    return f"{type(value).__name__} {text if len(text) <= 60 else text[:57] + '...'}"


def check_type(value: Any, name: str, types: type | tuple[type, ...], expected: str, *,
               element: str | None = None, file: str | None = None) -> Any:
    """``value`` if it is one of ``types`` (booleans only where ``bool`` is named), else an
    RfwTypeError: ``'name' must be EXPECTED, not int 5``."""
    kinds = types if isinstance(types, tuple) else (types,)
    if not isinstance(value, kinds) or (isinstance(value, bool) and bool not in kinds):
        raise RfwTypeError(f"'{name}' must be {expected}, not {type_name(value)}",
                           file=file, element=element)
    return value


def check_bool(value: Any, name: str, *, element: str | None = None) -> bool:
    """``value`` if it is True or False (numpy's too); ``'yes'`` or 1 are refused."""
    if type(value).__module__ == "numpy" and type(value).__name__ in ("bool", "bool_"):
        return bool(value)
    return check_type(value, name, bool, "True or False", element=element)


def check_path(value: Any, name: str, *, element: str | None = None) -> Path:
    """``value`` (a str or os.PathLike naming a file or folder) as a Path; bytes, empty
    names and NUL characters are refused."""
    check_type(value, name, (str, os.PathLike), "a path (str or os.PathLike)",
               element=element)
    text = os.fspath(value)
    if not isinstance(text, str):
        raise RfwTypeError(f"'{name}' must be a path (str or os.PathLike), not "
                           f"{type_name(value)}", element=element)
    if not text or "\0" in text:
        raise RfwValueError(f"'{name}' must name a file or folder, not {text!r}",
                            element=element)
    return Path(text)


@contextmanager
def naming(element: str) -> Iterator[None]:
    """RfwErrors raised inside name ``element`` (see ``RfwError.about``)."""
    try:
        yield
    except RfwError as e:
        e.about(element)
        raise


def is_identifier(name: Any) -> bool:
    """What ``check_identifier`` accepts, without making its message."""
    return isinstance(name, str) and IDENTIFIER.fullmatch(name) is not None and ".." not in name


def check_identifier(kind: str, name: Any, *, file: str | None = None,
                     element: str | None = None) -> str:
    """``name`` if it is an identifier (``[A-Za-z_][A-Za-z0-9_.-]*``), else an RfwError:
    names become file names, so ``../x``, ``/abs`` and control characters are refused."""
    if not is_identifier(name):
        raise RfwError(f"{kind} name {name!r} is not an identifier (letters, digits, '_', "
                       f"'.', '-'; starting with a letter or '_')", file=file, element=element)
    return name


def check_number(value: Any, key: str, *, kind: type = float, lo: float | None = None,
                 hi: float | None = None, file: str | None = None,
                 element: str | None = None) -> Any:
    """``value`` as ``kind`` (int or float) if it is one, finite and within [lo, hi]; booleans
    and strings are refused. The error names ``key`` (and ``file``/``element``)."""
    ok_types = (int,) if kind is int else (int, float)
    if isinstance(value, bool) or not isinstance(value, ok_types):
        raise RfwTypeError(f"'{key}' must be {'an integer' if kind is int else 'a number'}, "
                       f"not {value!r}", file=file, element=element)
    if kind is float and not math.isfinite(value):
        raise RfwError(f"'{key}' must be finite, not {value!r}", file=file, element=element)
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        bounds = (f"between {lo} and {hi}" if lo is not None and hi is not None
                  else f"at least {lo}" if lo is not None else f"at most {hi}")
        raise RfwError(f"'{key}' must be {bounds}, not {value!r}", file=file, element=element)
    return kind(value)


_warned: set[str] = set()


def warn(message: str) -> None:
    """One line on stderr, ``rfw: warning: ...``, once per message per process."""
    line = _one_line(message)
    if line not in _warned:
        _warned.add(line)
        print(f"rfw: warning: {line}", file=sys.stderr)
