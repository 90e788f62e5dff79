"""Byte units and alignment, defined once: rfw and vkext (which depends on rfw, never the
reverse) both import them from here."""

from __future__ import annotations

KiB = 1 << 10
MiB = 1 << 20
GiB = 1 << 30


def align_up(x: int, a: int) -> int:
    """``x`` rounded up to a multiple of ``a`` (``a`` > 0; not only powers of two)."""
    return -(-x // a) * a
