"""rfw.backends.cffi_types: its fast answers are the cffi parser's own, type by type, on
wgpu-py's FFI (every shape it answers, for a spread of wgpu's typedefs), and a shape it does
not answer goes to the parser."""

from __future__ import annotations

import pytest
from cffi import model

from rfw.backends.cffi_types import fast_parse, slow_parse


@pytest.fixture(scope="module")
def parser():
    from wgpu.backends.wgpu_native._ffi import ffi

    from rfw.backends import cffi_types

    assert cffi_types._SLOW is not None  # installed by importing rfw.backends
    return ffi._parser


def _slow(parser, cdecl):
    return slow_parse(parser, cdecl)


def test_fast_answers_are_the_parsers(parser):
    names = sorted(k.split(" ", 1)[1] for k in parser._declarations if k.startswith("typedef "))
    assert len(names) > 400  # wgpu-native's header (432 typedefs in 0.32)
    sample = [*names[:: max(1, len(names) // 20)], "uint8_t", "uint32_t", "char", "intptr_t",
              "float", "void"]
    checked = 0
    for name in sample:
        forms = [f"{name} *", f"{name} const *", f"{name}[]", f"{name} [4]"]
        if name != "void":
            forms.append(name)
        for cdecl in forms:
            fast = fast_parse(parser, cdecl)
            assert fast is not None, cdecl
            assert fast == _slow(parser, cdecl), cdecl
            checked += 1
    # function types as wgpu-py's callbacks spell them
    for cdecl in ("void(WGPULogLevel, WGPUStringView, void *)",
                  "void(WGPUDevice const *, WGPUErrorType, WGPUStringView, void *, void *)",
                  "void(WGPUMapAsyncStatus, WGPUStringView, void *, void *)",
                  "int(void)", "void(uint32_t[], float)"):
        assert fast_parse(parser, cdecl) == _slow(parser, cdecl), cdecl
        checked += 1
    assert checked > 100
    # the control: the comparison tells a different answer apart
    assert fast_parse(parser, "uint32_t [4]") != _slow(parser, "uint32_t [5]")
    assert fast_parse(parser, "WGPUBuffer *") != _slow(parser, "WGPUBuffer const *")


@pytest.mark.parametrize("cdecl", ["struct WGPUColor *", "int(*)(int)", "void(int, ...)",
                                   "WGPUBuffer const", "not_a_type *", "uint32_t[2][3]"])
def test_other_shapes_go_to_the_parser(parser, cdecl):
    assert fast_parse(parser, cdecl) is None


def test_a_struct_made_through_the_fast_path_works():
    from wgpu.backends.wgpu_native._ffi import ffi

    color = ffi.new("WGPUColor *")
    color.r, color.a = 0.25, 1.0
    assert (color.r, color.g, color.a) == (0.25, 0.0, 1.0)
    assert ffi.sizeof("WGPUColor") == 4 * 8
    assert isinstance(model.void_type, model.VoidType)
