"""Typed pass settings: conversion, suggestions and the WGSL uniform layout."""

import struct

import pytest

from rfw import Settings, SettingsError


class Params(Settings):
    exposure: float = 1.0
    curve: int = 1
    enabled: bool = True
    tint: tuple[float, float, float] = (1.0, 0.5, 0.25)
    label: str = "x"  # host-side only


def test_defaults_conversion_and_unknown_keys():
    p = Params("pass 'tm'", exposure="2.5", enabled="off")
    assert (p.exposure, p.curve, p.enabled, p.tint) == (2.5, 1, False, (1.0, 0.5, 0.25))
    assert Params(tint="0.1,0.2,0.3").tint == (0.1, 0.2, 0.3)
    with pytest.raises(SettingsError, match=r"pass 'tm': unknown setting 'exposre' \(did you "
                                            r"mean 'exposure'\?\)"):
        Params("pass 'tm'", exposre=2)
    with pytest.raises(SettingsError, match=r"setting 'curve': expected int, got 'fast'"):
        Params("pass 'tm'", curve="fast")


def test_pack_follows_wgsl_alignment():
    # f32 @0, i32 @4, u32 @8, vec3f aligned to 16 -> @16..28, struct size rounded to 32
    data = Params(exposure=0.499, curve=3, enabled=True, tint=(1.0, 2.0, 3.0)).pack()
    assert len(data) == 32
    assert struct.unpack_from("<fiI", data, 0) == (pytest.approx(0.499), 3, 1)
    assert struct.unpack_from("<3f", data, 16) == (1.0, 2.0, 3.0)
    assert data[12:16] == b"\0" * 4


def test_replace_and_equality():
    p = Params()
    q = p.replace(curve=0)
    assert q.curve == 0 and p.curve == 1 and q != p and q == Params(curve=0)
