"""A fast path for cffi's type strings, for wgpu-py's in-line (ABI mode) FFI.

wgpu-py makes every struct with ``ffi.new("WGPUSomething *")``. cffi parses each new type
string once per process, but each parse runs pycparser over a preamble that declares every
typedef name of the cdef (432 for wgpu-native in wgpu-py 0.32): some 30 ms a string, so a short
``rfw run`` on wgpu spent 2.5 of its 5 seconds there (cProfile, lavapipe). Nearly all of
the strings are a typedef or primitive name, a pointer to one (``const`` or not), an array
of one, or a function type over such arguments; their cffi types are built here from the
parser's declarations by the parser's own helpers, without parsing. Anything else goes to
cffi's parser. ``tests/core/test_cffi_types.py`` checks the fast answers against the
parser's for every typedef of wgpu's header.
"""

from __future__ import annotations

import re
from typing import Any

_ONE = re.compile(r"([A-Za-z_]\w*)(\s+const)?\s*(?:(\*)|\[\s*(\d*)\s*\])?")
_FUNCTION = re.compile(r"([A-Za-z_]\w*)\s*\(([^()]*)\)")


def _named(parser: Any, name: str) -> tuple[Any, int] | None:
    from cffi import model

    found = parser._declarations.get("typedef " + name)
    if found is not None:
        return found
    if name == "void":
        return model.void_type, 0
    if name in model.PrimitiveType.ALL_PRIMITIVE_TYPES:
        return model.PrimitiveType(name), 0
    return None


def _one(parser: Any, text: str) -> tuple[Any, int] | None:
    from cffi import model

    m = _ONE.fullmatch(text.strip())
    if m is None:
        return None
    found = _named(parser, m.group(1))
    if found is None:
        return None
    tp, quals = found
    if m.group(2):  # "T const *": a pointer to const T (a const T alone goes to the parser)
        if not m.group(3):
            return None
        quals |= model.Q_CONST
    if m.group(3):  # the parser's PtrDecl case, without a declarator name
        return parser._get_type_pointer(tp, quals), 0
    if m.group(4) is not None:  # its ArrayDecl case: the item's qualifiers kept
        return model.ArrayType(tp, int(m.group(4)) if m.group(4) else None), quals
    return tp, quals


def fast_parse(parser: Any, cdecl: str) -> tuple[Any, int] | None:
    """cffi's ``(type, quals)`` of ``cdecl`` where it is one of the simple shapes above;
    None where the parser must decide."""
    from cffi import model

    simple = _one(parser, cdecl)
    if simple is not None:
        return simple
    m = _FUNCTION.fullmatch(cdecl.strip())
    if m is None:
        return None
    result = _named(parser, m.group(1))
    texts = m.group(2).split(",") if m.group(2).strip() else []
    args = [_one(parser, a) for a in texts]
    if result is None or any(a is None for a in args) or "..." in m.group(2):
        return None
    types = [parser._as_func_arg(*a) for a in args]  # type: ignore[misc]
    if types == [model.void_type]:
        types = []
    return model.RawFunctionType(tuple(types), result[0], False, None), 0


_SLOW: Any = None  # cffi's own parse_type_and_quals, once install() has put the fast path first


def install() -> None:
    """Route every cffi parser's type strings through :func:`fast_parse` first (once)."""
    global _SLOW
    from cffi import cparser

    if _SLOW is not None:
        return
    _SLOW = slow = cparser.Parser.parse_type_and_quals

    def parse_type_and_quals(self: Any, cdecl: str) -> tuple[Any, int]:
        return fast_parse(self, cdecl) or slow(self, cdecl)

    cparser.Parser.parse_type_and_quals = parse_type_and_quals


def slow_parse(parser: Any, cdecl: str) -> tuple[Any, int]:
    """cffi's own answer for ``cdecl`` (what :func:`fast_parse` is checked against)."""
    return (_SLOW or type(parser).parse_type_and_quals)(parser, cdecl)
