"""Golden images keyed by adapter: compare 8-bit renders, write failure artefacts, regenerate.

Goldens live in ``tests/golden/<adapter>/<name>.png``, where ``<adapter>`` names the device
and driver (``adapter_key``). Another adapter rasterises and filters differently, so a
golden is only compared on the adapter that made it; elsewhere the test renders and skips.
``RFW_REGEN_GOLDEN=1`` writes the current renders as goldens instead of comparing.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

GOLDEN = Path(__file__).resolve().parent / "golden"
REGEN_ENV = "RFW_REGEN_GOLDEN"
DIFF_BOOST = 16  # diff.png shows |actual - expected| times this


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


def compare(actual: np.ndarray, expected: np.ndarray, *, atol: int = 1) -> tuple[int, int]:
    """(largest channel difference, pixels with a channel over ``atol``) of two RGBA8 images."""
    d = np.abs(actual.astype(np.int16) - expected.astype(np.int16))
    return int(d.max()), int((d > atol).any(axis=-1).sum())


def check_golden(actual: np.ndarray, name: str, device: Any, artefacts: Path, *,
                 atol: int = 1) -> None:
    """Compare ``actual`` (H, W, 4 uint8) with this adapter's golden ``name``.

    Regenerating writes it; a missing golden skips; a mismatch writes actual.png,
    expected.png and diff.png to ``artefacts`` and fails naming that folder.
    """
    assert actual.dtype == np.uint8 and actual.ndim == 3 and actual.shape[2] == 4
    key = adapter_key(device)
    path = GOLDEN / key / f"{name}.png"
    if regenerating():
        write_png(path, actual)
        return
    if not path.exists():
        pytest.skip(f"no golden {path.relative_to(GOLDEN.parents[1])} for adapter '{key}' "
                    f"({device.name}, {device.driver}); rendered fine. Create this adapter's "
                    f"goldens with: {REGEN_ENV}=1 python -m pytest tests/test_golden.py")
    expected = read_png(path)
    if expected.shape != actual.shape:
        worst, over = 255, actual.shape[0] * actual.shape[1]
    else:
        worst, over = compare(actual, expected, atol=atol)
    if over == 0:
        return
    artefacts.mkdir(parents=True, exist_ok=True)
    write_png(artefacts / "actual.png", actual)
    write_png(artefacts / "expected.png", expected)
    if expected.shape == actual.shape:
        write_png(artefacts / "diff.png", diff_image(actual, expected))
    raise AssertionError(f"{name} on '{key}': {over} pixels differ by more than {atol} "
                         f"(largest difference {worst}; shapes {actual.shape} vs "
                         f"{expected.shape}); actual, expected and diff (x{DIFF_BOOST}) "
                         f"in {artefacts}")
