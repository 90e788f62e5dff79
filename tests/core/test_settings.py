"""Typed pass settings: conversion, suggestions and the WGSL uniform layout."""

import struct
from typing import Annotated

import pytest

from rfw import Settings, SettingsError
from rfw.passes import Range


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
    with pytest.raises(SettingsError, match=r"setting 'curve': expected an integer, got 'fast'"):
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


# every bad value is refused where it enters, naming the setting; the good ones beside them
# show the check is not simply refusing everything
BAD = [
    ("curve", 99999999999999, "does not fit a 32-bit integer"),
    ("curve", -(1 << 31) - 1, "does not fit a 32-bit integer"),
    ("curve", 2.5, "expected an integer"),
    ("curve", True, "expected an integer"),
    ("exposure", float("nan"), "must be finite"),
    ("exposure", "inf", "must be finite"),
    ("exposure", "-Infinity", "must be finite"),
    ("exposure", 1e39, "does not fit a 32-bit float"),
    ("exposure", 10 ** 40, "does not fit a 32-bit float"),
    ("exposure", "two", "expected a number"),
    ("exposure", [1.0], "expected a number"),
    ("enabled", 5, "expected true or false"),
    ("enabled", "maybe", "expected true or false"),
    ("tint", "1,nan,0", "must be finite"),
    ("tint", (1.0, 2.0), "expected 3 numbers"),
    ("tint", 5, "expected 3 numbers"),
    ("label", 2.5, "expected a string"),
    ("label", True, "expected a string"),
    ("label", ["a"], "expected a string"),
]
GOOD = [
    ("curve", (1 << 31) - 1, (1 << 31) - 1),
    ("curve", -(1 << 31), -(1 << 31)),
    ("curve", " 7 ", 7),
    ("exposure", 3, 3.0),
    ("exposure", "-1e38", -1e38),
    ("enabled", "ON", True),
    ("tint", [0, 1, 2], (0.0, 1.0, 2.0)),
    ("label", "y", "y"),
    ("label", 3, "3"),
]


@pytest.mark.parametrize("key,value,needle", BAD, ids=[f"{k}={v!r}" for k, v, _ in BAD])
def test_bad_values_are_refused_naming_the_setting(key, value, needle):
    with pytest.raises(SettingsError) as e:
        Params("pass 'tm'", **{key: value})
    assert f"pass 'tm': setting '{key}'" in str(e.value) and needle in str(e.value)


@pytest.mark.parametrize("key,value,expected", GOOD, ids=[f"{k}={v!r}" for k, v, _ in GOOD])
def test_values_at_the_bounds_are_kept(key, value, expected):
    assert getattr(Params(**{key: value}), key) == expected


class Bounded(Settings):
    size: Annotated[int, Range(1, 16)] = 4
    gain: Annotated[float, Range(lo=0.0)] = 1.0


@pytest.mark.parametrize("key,value", [("size", 0), ("size", 17), ("size", "-4"),
                                       ("gain", -0.001)])
def test_declared_bounds_refuse_values_outside(key, value):
    with pytest.raises(SettingsError, match=rf"pass 'p': setting '{key}': .* is outside"):
        Bounded("pass 'p'", **{key: value})


def test_declared_bounds_keep_values_inside_and_pack_as_their_type():
    b = Bounded(size="16", gain=0)
    assert (b.size, b.gain) == (16, 0.0) and Bounded(size=1).size == 1
    assert struct.unpack_from("<if", b.pack(), 0) == (16, 0.0)
    assert Bounded.fields()["size"] == (int, 4)
