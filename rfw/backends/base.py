"""The frame protocol every backend's executor implements (rfw.exec.core.ExecutorCore is
rfw's own half of it; a plug-in backend may implement it directly)."""

from __future__ import annotations


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
