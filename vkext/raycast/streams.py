"""Rays and hits as ``raycast.glsl`` lays them out (streams of 4-byte words) and as records,
the hit arrays a cast fills, and the checks of rays the shaders refuse."""

from __future__ import annotations

from typing import Any

import numpy as np

from rfw.errors import RfwError

# raycast.glsl's streams: 4-byte words per ray, in this order
RAY_STREAMS = (("origin", 3), ("direction", 3), ("tmin", 1), ("tmax", 1))
HIT_STREAMS = (("t", 1), ("primitive", 1), ("instance", 1), ("barycentrics", 2))
RAY_WORDS, HIT_WORDS = 8, 5
# what the shaders write as the primitive of a ray they refuse (t is NaN), by argument
INVALID = {-2: ("origins", "non-finite values"), -3: ("directions", "non-finite values"),
           -4: ("directions", "zero-length rows")}

# rays and hits as records, for callers of Raycaster.trace
RAY_DTYPE = np.dtype([("origin", "<f4", 3), ("tmin", "<f4"), ("direction", "<f4", 3),
                      ("tmax", "<f4")])
HIT_DTYPE = np.dtype([("t", "<f4"), ("primitive", "<i4"), ("instance", "<i4"), ("u", "<f4"),
                      ("v", "<f4")])


def hit_arrays(n: int, names: Any, out: dict[str, np.ndarray] | None = None,
               ) -> dict[str, np.ndarray]:
    """Arrays for ``n`` hits of the streams in ``names``: those in ``out`` (checked:
    C-contiguous and writable, of the stream's dtype and shape), new ones for the rest."""
    arrays = {}
    for name, width in HIT_STREAMS:
        if name not in names:
            continue
        shape = (n, width) if width > 1 else (n,)
        dtype = np.dtype(np.float32 if name in ("t", "barycentrics") else np.int32)
        given = (out or {}).get(name)
        if given is None:
            arrays[name] = np.empty(shape, dtype)
            continue
        if not (isinstance(given, np.ndarray) and given.dtype == dtype and given.shape == shape
                and given.flags.c_contiguous and given.flags.writeable):
            raise RfwError(f"out['{name}'] must be a writable C-contiguous {dtype} array of "
                           f"shape {shape}, got {_describe(given)}")
        arrays[name] = given
    return arrays


def fill_misses(arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """``arrays`` (of :func:`hit_arrays`) written as every ray missed: ``t`` inf, no
    primitive or instance (-1), zero barycentrics."""
    for name, value in (("t", np.inf), ("primitive", -1), ("instance", -1),
                        ("barycentrics", 0.0)):
        if name in arrays:
            arrays[name][...] = value
    return arrays


def _describe(a: Any) -> str:
    if not isinstance(a, np.ndarray):
        return type(a).__name__
    layout = "" if a.flags.c_contiguous else " not C-contiguous"
    return f"{a.dtype} {a.shape}{layout}{'' if a.flags.writeable else ' read-only'}"


def check_rays(origins: np.ndarray, directions: np.ndarray) -> None:
    """On the host what the shaders check per ray (for casts that trace nothing)."""
    for name, arr in (("origins", origins), ("directions", directions)):
        bad = ~np.isfinite(arr).all(axis=1)
        if bad.any():
            raise RfwError(f"{name} has non-finite values (first in row {int(np.argmax(bad))})")
    zero = ~directions.any(axis=1)
    if zero.any():
        raise RfwError(f"directions has zero-length rows (first: {int(np.argmax(zero))})")


def _check_traced(t: np.ndarray, primitive: np.ndarray) -> None:
    # a refused ray is the only NaN t, and min() propagates NaN: one pass over t
    if len(t) and np.isnan(t.min()):
        first = int(np.argmax(np.isnan(t)))
        name, what = INVALID.get(int(primitive[first]), ("rays", "a ray the GPU refused"))
        where = "first: " if what == "zero-length rows" else "first in row "
        raise RfwError(f"{name} has {what} ({where}{first})")
