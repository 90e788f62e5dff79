"""argparse value types of rfw's commands: bad values become usage errors, not tracebacks.
Below :mod:`rfw.cli` and the subcommands that add their own arguments (``rfw bench``)."""

from __future__ import annotations

import argparse
import typing

from .config import parse_size


def size(text: str) -> tuple[int, int]:
    try:
        return parse_size(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def backend(text: str) -> str:
    """``--backend NAME``: an empty name is refused here (``args.backend or default`` would
    take it for no --backend); an unknown one by :func:`rfw.backend.get_backend`."""
    if not text.strip():
        from .backend import installed

        raise argparse.ArgumentTypeError(f"names no backend; installed: "
                                         f"{', '.join(installed()) or 'none'}")
    return text


def count(lo: int, hi: int) -> typing.Callable[[str], int]:
    """An argparse type: an integer in [lo, hi] (``--frames 0`` is an error, not 1)."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"must be between {lo} and {hi}, got {value}")
        return value

    return parse


def triangles(text: str) -> int:
    """``--max-triangles``: meshoptimizer pads triangle runs to 4 bytes."""
    value = count(4, 512)(text)
    if value % 4:
        raise argparse.ArgumentTypeError(f"max_triangles must be a multiple of 4, got {value}")
    return value


def real(lo: float, hi: float) -> typing.Callable[[str], float]:
    """An argparse type: a finite number in [lo, hi]."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if not lo <= value <= hi:  # nan fails both comparisons
            raise argparse.ArgumentTypeError(f"must be between {lo} and {hi}, got {text}")
        return value

    return parse
