"""Golden images keyed by adapter: compare 8-bit renders, write failure artefacts, regenerate.

Goldens live in ``tests/golden/<adapter>/<name>.png``, where ``<adapter>`` names the device
and driver (``adapter_key``). Another adapter rasterises and filters differently, so a
golden is only compared on the adapter that made it. On an adapter without goldens the
test fails under CI (the ``CI`` environment variable, set by ``.ci/run``) and skips
elsewhere, both with the command that creates them (``REGEN_COMMAND``), which writes the
current renders as goldens instead of comparing.

Every image comparison of the suite (goldens, vertex against meshlet path, Vulkan against
wgpu) goes through ``image_diff`` and ``BOUNDS`` (see ``Bounds`` for the measurements); a
check that a change reached a picture bounds ``changed_share`` from below.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

# the comparison itself lives in rfw (rfw bench replay judges images with it too)
from rfw.golden import (  # noqa: F401  (re-exported: the suite imports them from here)
    BOUNDS,
    Bounds,
    ImageDiff,
    flip_mean,
    image_diff,
    mismatch,
)

GOLDEN = Path(__file__).resolve().parent / "golden"
REGEN_ENV = "RFW_REGEN_GOLDEN"
REGEN_COMMAND = f"{REGEN_ENV}=1 .venv/bin/python -m pytest tests/test_golden.py"
DIFF_BOOST = 16  # diff.png shows |actual - expected| times this


def assert_similar(actual: np.ndarray, expected: np.ndarray, what: str) -> None:
    """Fails naming ``what`` and every exceeded bound unless the images match."""
    why = mismatch(actual, expected)
    assert not why, f"{what}: {why}"


def changed_share(actual: np.ndarray, expected: np.ndarray, over: float = 2) -> float:
    """The share of pixels that differ by more than ``over`` (levels of an 8-bit image,
    the values' own units otherwise) in some channel: how much of a picture a change
    reached. The same picture gives 0, and one changed pixel ``1 / pixels`` (0.0017 at
    32x18), so "the change reached the image" is a bound well above that, set from what
    the change measures; (H, W, C) arrays count pixels, others count elements."""
    a, b = np.asarray(actual), np.asarray(expected)
    if a.shape != b.shape:
        raise ValueError(f"arrays differ in shape: {a.shape} vs {b.shape}")
    d = np.abs(a.astype(np.float64) - b.astype(np.float64))
    per_pixel = d.max(axis=-1) if d.ndim == 3 else d
    return float((per_pixel > over).mean())


def adapter_key(device: Any) -> str:
    """``<device>-<driver>-<major.minor>`` in [a-z0-9.-], e.g.
    ``llvmpipe-llvm15-256bit-mesa-25.0``.

    The device name keeps llvmpipe's LLVM major version and SIMD width (both change its
    arithmetic) and drops other parenthesised details; the driver keeps its name and
    major.minor version, where rendering changes are expected.
    """
    # llvmpipe's code generation depends on its LLVM and SIMD width: keep both in the key
    simd = re.search(r"LLVM (\d+)[^,)]*,\s*(\d+) bits", device.name)
    name = re.sub(r"\(.*?\)", "", device.name)
    if simd:
        name += f"-llvm{simd[1]}-{simd[2]}bit"
    driver = re.match(r"\s*([A-Za-z][\w ]*?)\s*v?(\d+)\.(\d+)", device.driver or "")
    parts = [name]
    if driver:
        parts.append(f"{driver[1]}-{driver[2]}.{driver[3]}")
    elif device.driver:
        parts.append(device.driver)
    key = re.sub(r"[^a-z0-9.]+", "-", "-".join(parts).lower())
    return re.sub(r"-{2,}", "-", key).strip("-.") or "unknown"


def regenerating() -> bool:
    return os.environ.get(REGEN_ENV, "") not in ("", "0")


def in_ci() -> bool:
    """True under CI (``.ci/run`` runs with CI=true); "", "0" and "false" count as unset."""
    return os.environ.get("CI", "").strip().lower() not in ("", "0", "false", "no")


def read_png(path: Path) -> np.ndarray:
    from PIL import Image

    with Image.open(path) as im:
        return np.asarray(im.convert("RGBA"))


def write_png(path: Path, rgba: np.ndarray) -> None:
    from PIL import Image

    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.ascontiguousarray(rgba), "RGBA").save(path, format="PNG", optimize=True)


def diff_image(actual: np.ndarray, expected: np.ndarray, boost: int = DIFF_BOOST) -> np.ndarray:
    """|actual - expected| per channel times ``boost``, opaque, so small errors show."""
    d = np.abs(actual.astype(np.int16) - expected.astype(np.int16)) * boost
    out = np.clip(d, 0, 255).astype(np.uint8)
    out[..., 3] = 255
    return out


def missing_golden(path: Path, key: str, device: Any) -> None:
    """No golden for this adapter: fail under CI (a comparison nobody made is not a pass),
    skip elsewhere; both say how to create them."""
    message = (f"no golden {path.relative_to(GOLDEN.parents[1])} for adapter '{key}' "
               f"({device.name}, {device.driver}); rendered fine. Create this adapter's "
               f"goldens with: {REGEN_COMMAND}")
    if in_ci():
        pytest.fail(message, pytrace=False)
    pytest.skip(message)


def check_golden(actual: np.ndarray, name: str, device: Any, artefacts: Path) -> None:
    """Compare ``actual`` (H, W, 4 uint8) with this adapter's golden ``name`` (``BOUNDS``).

    Regenerating writes it; a missing golden fails under CI and skips elsewhere
    (``missing_golden``); a mismatch writes actual.png, expected.png and diff.png to
    ``artefacts`` and fails naming that folder and the exceeded bounds.
    """
    assert actual.dtype == np.uint8 and actual.ndim == 3 and actual.shape[2] == 4
    key = adapter_key(device)
    path = GOLDEN / key / f"{name}.png"
    if regenerating():
        write_png(path, actual)
        return
    if not path.exists():
        missing_golden(path, key, device)
    expected = read_png(path)
    why = mismatch(actual, expected)
    if not why:
        return
    artefacts.mkdir(parents=True, exist_ok=True)
    write_png(artefacts / "actual.png", actual)
    write_png(artefacts / "expected.png", expected)
    if expected.shape == actual.shape:
        write_png(artefacts / "diff.png", diff_image(actual, expected))
    raise AssertionError(f"{name} on '{key}': {why}; actual, expected and diff "
                         f"(x{DIFF_BOOST}) in {artefacts}")
