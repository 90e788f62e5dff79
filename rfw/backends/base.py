"""The backend interface both executors implement (wgpu here, raw Vulkan in vkext)."""

from __future__ import annotations

from ..shaders import ShaderError


class SlotContext:
    """What both pass contexts share: a pass's resources reached by slot name."""

    pass_: object
    slots: dict[str, str]  # slot -> resource

    def resource(self, slot: str) -> str:
        try:
            return self.slots[slot]
        except KeyError:
            raise ShaderError(f"pass '{self.pass_.name}' has no slot '{slot}' "  # type: ignore
                              f"(slots: {', '.join(self.slots)})") from None

    def has(self, slot: str) -> bool:
        return slot in self.slots

    # replay (rfw.exec.replay): a backend that keeps recorded commands overrides these
    def can_replay(self) -> bool:
        """Whether the executor may build the pass's replay key: never by default."""
        return False

    def slot_objects(self) -> list[object]:
        """The objects behind the pass's slots, for its replay key."""
        return []

    def replayed(self, key: tuple) -> bool:
        """Execute again what was recorded for ``key``: nothing kept by default."""
        return False

    def finish(self) -> None:
        """After ``record``: nothing to close by default."""


class FrameExecutor:
    """Runs a compiled graph frame by frame; a frame can also be driven pass by pass
    (``begin_frame``, ``record``, ``flush``, ``end_frame``), as mixed-backend frames do."""

    def begin_frame(self) -> None:
        raise NotImplementedError

    def record(self, name: str) -> None:
        raise NotImplementedError

    def flush(self) -> None:
        raise NotImplementedError

    def end_frame(self) -> None:
        raise NotImplementedError

    def drain(self) -> None:
        """Wait until every frame in flight is done (a backend without frames in flight
        has none)."""

    def frame(self, drain: bool = False) -> None:
        """Record and submit one frame; timings per pass are appended. ``drain`` also waits
        for the frames in flight, this one included (the last frame of a run does, so a
        clock around ``frame()`` counts the wait)."""
        self.begin_frame()
        for name in self.plan.order:  # type: ignore[attr-defined]
            self.record(name)
        self.end_frame()
        if drain:
            self.drain()

    def run(self, frames: int = 1) -> None:
        for k in range(frames):
            self.frame(drain=k == frames - 1)
