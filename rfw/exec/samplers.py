"""The sampler memo every executor keeps: one sampler per (filter, address, compare)."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

from ..context import check_sampler

# (filter, address, compare) -> the backend's sampler
Maker = Callable[[str, str, str | None], Any]


class Samplers:
    """Samplers made by the backend's ``make(filter, address, compare)`` once per key, after
    :func:`rfw.context.check_sampler` refused any value it has no sampler for; kept until
    the executor drops them (``clear``; iterating gives them, to destroy first)."""

    def __init__(self, make: Maker) -> None:
        self._make = make
        self._made: dict[tuple[str, str, str | None], Any] = {}

    def get(self, filter: str, address: str, compare: str | None) -> Any:
        key = (filter, address, compare)
        found = self._made.get(key)
        if found is None:
            check_sampler(filter, address, compare)
            found = self._made[key] = self._make(filter, address, compare)
        return found

    def __iter__(self) -> Iterator[Any]:
        return iter(list(self._made.values()))

    def __len__(self) -> int:
        return len(self._made)

    def clear(self) -> None:
        self._made.clear()
