"""Per-pass timings as every executor keeps them: one sample per timed frame."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class PassTiming:
    """A pass's GPU time (timestamp queries) and CPU record time per frame, in ms."""

    name: str
    gpu_ms: list[float] = field(default_factory=list)
    cpu_ms: list[float] = field(default_factory=list)


def pass_timings(order: tuple[str, ...] | list[str]) -> dict[str, PassTiming]:
    """An empty :class:`PassTiming` per pass, in the plan's order."""
    return {name: PassTiming(name) for name in order}
