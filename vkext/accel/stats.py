"""What building a scene's acceleration structures cost: build times and a stats summary."""

from __future__ import annotations

import time
from typing import Any

from ..commands import TimestampPool
from ..device import VkDevice


class BuildTimer:
    """Times between marks in ms: GPU timestamps written after everything recorded before
    each mark, where the device has them, else the host's clock around submit-and-wait
    (which then includes the submit)."""

    def __init__(self, device: VkDevice, marks: int, label: str):
        self.pool = TimestampPool(device, marks, label=f"{label}:timestamps") \
            if "timestamp" in device.caps else None
        self.kind = "gpu" if self.pool is not None else "cpu"
        self._host: list[float] = []

    def start(self, cmd: Any) -> None:
        """Before the first mark of a command buffer."""
        if self.pool is not None:
            self.pool.reset(cmd)
        self._host = [time.perf_counter()]

    def mark(self, cmd: Any, index: int) -> None:
        if self.pool is not None:
            self.pool.write(cmd, "ALL_COMMANDS", index)

    def span(self, a: int, b: int) -> float:
        """ms from mark ``a`` to mark ``b`` of the last command buffer, once its submit was
        waited for; on the host clock, the whole submit (each phase of it reports that)."""
        if self.pool is None:
            return (time.perf_counter() - self._host[0]) * 1e3
        t = self.pool.results(a, b - a + 1)
        return (t[-1] - t[0]) / 1e6

    def destroy(self) -> None:
        if self.pool is not None:
            self.pool.destroy()
            self.pool = None


def accel_stats(acc: Any) -> dict[str, Any]:
    """A :class:`vkext.accel.SceneAccel`'s structure counts and bytes (BLAS bytes as built
    and now, after any compaction), build times in ms per phase and how they were measured
    (``"gpu"`` timestamps or the ``"cpu"`` clock), and the TLAS builds frames recorded."""
    built = [b for b in acc.blas if b is not None]
    ranges = acc.geometry.mesh_ranges if acc.geometry is not None else []
    return {
        "blas": len(built),
        "instances": len(acc.tlas_instances),
        "triangles": int(acc.triangles),
        "instance_triangles": sum(ranges[i.mesh][3] // 3 for i in acc.scene.instances)
        if ranges else 0,
        "blas_bytes_built": int(acc.blas_bytes_built),
        "blas_bytes": sum(b.size for b in built),
        "tlas_bytes": acc.tlas.size if acc.tlas is not None else 0,
        "scratch_bytes": int(acc.scratch_bytes),
        "blas_batches": int(acc.blas_batches),
        "build_ms": dict(acc.build_ms),
        "timer": acc.timer.kind if acc.timer is not None else "cpu",
        "prefer": acc.prefer, "allow_update": acc.allow_update, "compact": acc.compact,
        "frame_builds": dict(acc.frame_builds),
    }
