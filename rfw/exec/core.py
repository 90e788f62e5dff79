"""The executor core: what every backend's executor does the same way, written once.

:class:`ExecutorCore` owns the frame protocol (``begin_frame``, ``record``, ``flush``,
``end_frame``, ``frame``, ``run``), the ring of frames in flight (``keep_in_flight``,
``drain``), per-pass timings (:class:`rfw.exec.timing.PassTiming`), history ping-pong
(``x@prev`` is last frame's ``x``: the objects behind the two swap each frame), the sampler
memo, the setup context passes get, replay keys (:mod:`rfw.exec.replay`) and the order of
teardown. A backend subclasses it and supplies primitives only:

* ``_make_slot(k)`` / ``_destroy_slot(slot)``: what one frame in flight owns (command
  buffers, timestamp queries, fences);
* ``_open(slot)``: begin the frame's commands in the slot; ``_context(name, p)``: the pass
  context ``record`` gets; ``_recorded(name, ctx)``: after it (end a debug label, a
  timestamp); ``_bridge(name)``: a bridge's side of a mixed plan (the copy itself goes
  through the host, :mod:`rfw.frame`);
* ``_submit(slot, last)``: submit what was recorded (``last``: the frame's end) and return
  ``finish(append)``, which waits for it and hands the frame's GPU ms per pass to
  ``append`` (None: no timestamps); ``flush`` waits at once;
* ``_swap(a, b)``: exchange the objects behind two resources (history);
* ``_make_sampler(filter, address, compare)``, ``_make_buffer(label, data, usage)``;
* ``_release()``: destroy the backend's own objects (after every frame is finished).

A pass context takes part in replay through ``can_replay()``, ``slot_objects()``,
``replayed(key)`` and ``finish()`` (:class:`rfw.exec.context.ContextCore` gives the
defaults of a backend that never replays).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from ..backends.base import FrameExecutor
from ..errors import naming
from ..frame import InFlight, frames_in_flight, run_frames
from ..graph import CompiledGraph
from ..options import DEFAULT, RunOptions
from ..passes import Pass
from .replay import replay_key
from .samplers import Samplers
from .timing import PassTiming, pass_timings

# a frame's GPU ms per pass (None: the device has no timestamps)
Times = dict[str, float] | None
Finish = Callable[[Callable[[Times], None]], None]


def history_pairs(plan: CompiledGraph) -> list[tuple[str, str]]:
    """(``x@prev``, ``x``) for every history resource of the plan: the two whose objects
    swap at the start of every frame after the first."""
    return [(r.name, r.name.removesuffix("@prev")) for r in plan.resources
            if r.history and r.name.endswith("@prev")]


class SetupContext:
    """What ``Pass.setup(ctx)`` sees (:class:`rfw.authoring.SetupContext`): the scene, the
    device's capabilities and buffers made from arrays, kept by the executor."""

    def __init__(self, executor: ExecutorCore, caps: frozenset[str]):
        self._executor = executor
        self.scene = executor.scene
        self.caps = caps

    def buffer(self, label: str, data: np.ndarray, *,
               usage: tuple[str, ...] = ("storage",)) -> Any:
        """A buffer holding ``data`` (its bytes), kept until the executor is destroyed."""
        return self._executor._make_buffer(label, np.ascontiguousarray(data), tuple(usage))


class ExecutorCore(FrameExecutor):
    """The backend-independent half of an executor (module docstring); a backend's
    executor calls ``_init_core`` first in its ``__init__`` and ``_setup_passes`` once its
    resources exist."""

    plan: CompiledGraph
    passes: dict[str, Pass]
    slots: dict[str, dict[str, str]]
    scene: Any
    options: RunOptions
    timings: dict[str, PassTiming]
    in_flight: InFlight

    def _init_core(self, plan: CompiledGraph, passes: dict[str, Pass],
                   slots: dict[str, dict[str, str]], scene: Any, readback: tuple[str, ...],
                   options: RunOptions | None) -> None:
        self.plan, self.passes, self.slots, self.scene = plan, passes, slots, scene
        self.readback = tuple(readback)
        self.options = options if options is not None else DEFAULT
        self.frame_index = 0
        self.timings = pass_timings(plan.order)
        self.history = history_pairs(plan)
        self._samplers = Samplers(self._make_sampler)
        self.in_flight = InFlight([])
        self._frame_slot: Any = None
        self._cpu: dict[str, float] = {}
        self._recorded: list[str] = []
        self._flushed: dict[str, float] = {}  # GPU ms of the frame's flushed submits

    def _setup_passes(self, caps: frozenset[str]) -> None:
        """Every pass's ``setup`` with one setup context, before the first frame."""
        ctx = SetupContext(self, caps)
        for p in self.passes.values():
            with naming(f"pass '{p.name}'"):
                p.setup(ctx)

    # primitives (module docstring) ---------------------------------------------------------
    def _make_slot(self, k: int) -> Any:
        raise NotImplementedError

    def _destroy_slot(self, slot: Any) -> None:
        raise NotImplementedError

    def _open(self, slot: Any) -> None:
        raise NotImplementedError

    def _context(self, name: str, p: Pass) -> Any:
        raise NotImplementedError

    def _recorded_pass(self, name: str, ctx: Any) -> None:
        """After a pass's ``record``: nothing by default."""

    def _bridge(self, name: str) -> None:
        raise NotImplementedError

    def _abandon(self) -> None:
        """A pass's ``record`` (or the backend around it) raised: drop what the frame
        recorded so far. Nothing by default."""

    def _submit(self, slot: Any, *, last: bool) -> Finish | None:
        raise NotImplementedError

    def _swap(self, a: str, b: str) -> None:
        raise NotImplementedError

    def _make_sampler(self, filter: str, address: str, compare: str | None) -> Any:
        raise NotImplementedError

    def _make_buffer(self, label: str, data: np.ndarray, usage: tuple[str, ...]) -> Any:
        raise NotImplementedError

    def _slots_made(self, frames: int) -> None:
        """After ``keep_in_flight`` made the ring: nothing by default."""

    def _drained(self) -> None:
        """After ``drain`` finished every frame in flight: nothing by default."""

    def _before_frame(self) -> None:
        """First in ``begin_frame``, before the frame takes its slot: nothing by default."""

    def _can_drain(self) -> bool:
        """Whether ``destroy`` can wait for the frames in flight (the device is alive)."""
        return True

    def _idle(self) -> None:
        """In ``destroy``, once the frames in flight are finished or dropped."""

    def _release(self) -> None:
        raise NotImplementedError

    # shared ------------------------------------------------------------------------------
    def sampler(self, *, filter: str = "linear", address: str = "clamp-to-edge",
                compare: str | None = None) -> Any:
        """A sampler made once per (filter, address, compare) and kept until ``destroy``."""
        return self._samplers.get(filter, address, compare)

    def scene_bindings(self) -> dict[str, Any]:
        return self.scene.bindings() if self.scene is not None else {}

    def keep_in_flight(self, frames: int) -> None:
        """Keep up to ``frames`` frames in flight (:func:`rfw.frame.frames_in_flight`): one
        slot each. Frames in flight now are finished first."""
        frames = frames_in_flight(frames)
        self.drain()
        for slot in self.in_flight.slots:
            self._destroy_slot(slot)
        self.in_flight = InFlight([])
        for k in range(frames):
            self.in_flight.slots.append(self._make_slot(k))
        self._slots_made(frames)

    def run(self, frames: int = 1) -> None:
        """``frames`` frames; returns once they are done (the last one drains)."""
        run_frames(self, frames)

    def drain(self) -> None:
        """Wait for every frame in flight; their timings are appended, oldest first."""
        self.in_flight.drain()
        self._drained()

    # the frame protocol ------------------------------------------------------------------
    def begin_frame(self) -> None:
        """Start a frame: ``record`` passes into it, ``flush`` to submit what was recorded
        and wait, ``end_frame`` to submit the rest without waiting. The frame takes the
        next slot once the frame that used it last is finished; from the second frame on,
        history resources swap (last frame's ``x`` is this one's ``x@prev``). The scene
        learns which frame begins (``begin_frame``: its jittered camera and last frame's
        matrices, written so that frames in flight keep theirs)."""
        self._before_frame()
        begin = getattr(self.scene, "begin_frame", None)  # a third-party scene may have none
        if begin is not None:
            begin(self.frame_index)
        slot = self._frame_slot = self.in_flight.slot(self.frame_index)
        if self.frame_index:
            for copy, name in self.history:
                self._swap(copy, name)
        self._cpu, self._recorded, self._flushed = {}, [], {}
        self._open(slot)

    def record(self, name: str) -> None:
        """Record pass ``name``: ``record(ctx)``, unless the backend executes again what
        it recorded for the same replay key (:mod:`rfw.exec.replay`); the CPU time is the
        pass's. A bridge's side (no pass instance here) records what the backend needs."""
        p = self.passes.get(name)
        if p is None:
            self._bridge(name)
            return
        try:
            ctx = self._context(name, p)
            t = time.perf_counter()
            with naming(f"pass '{name}'"):
                key = replay_key(p, ctx, ctx.slot_objects()) if ctx.can_replay() else None
                if key is None or not ctx.replayed(key):
                    p.record(ctx)
                ctx.finish()
            self._cpu[name] = self._cpu.get(name, 0.0) + (time.perf_counter() - t) * 1e3
            self._recorded.append(name)
            self._recorded_pass(name, ctx)
        except BaseException:
            self._abandon()
            raise

    def flush(self) -> None:
        """Submit what was recorded since the last flush and wait for it, its timestamps
        added to the frame's (a bridge then copies what it wrote). Nothing recorded:
        nothing happens."""
        finish = self._submit(self._frame_slot, last=False)
        if finish is not None:
            finish(self._add_flushed)

    def _add_flushed(self, gpu: Times) -> None:
        if gpu is not None:
            for name, ms in gpu.items():
                self._flushed[name] = self._flushed.get(name, 0.0) + ms

    def end_frame(self) -> None:
        """Submit what is left without waiting: the frame's timings are appended when it
        is finished (its slot comes round again, or a drain). One frame in flight waits
        here, as every frame did before frames in flight."""
        slot = self._frame_slot
        finish = self._submit(slot, last=True)
        cpu, recorded = self._cpu, self._recorded
        flushed, self._flushed = self._flushed, {}

        def done() -> None:
            def append(gpu: Times) -> None:
                if flushed:  # the frame's earlier submits, then its last one
                    merged = dict(flushed)
                    for name, ms in (gpu or {}).items():
                        merged[name] = merged.get(name, 0.0) + ms
                    gpu = merged
                self._append(cpu, gpu, recorded)

            if finish is None:
                append(None)
            else:
                finish(append)

        self.in_flight.submitted(slot, done)
        self.frame_index += 1
        if len(self.in_flight) == 1:
            self.drain()

    def _append(self, cpu: dict[str, float], gpu: Times, recorded: list[str]) -> None:
        for name in dict.fromkeys(recorded):
            self.timings[name].cpu_ms.append(cpu[name])
            if gpu is not None:
                self.timings[name].gpu_ms.append(gpu.get(name, 0.0))

    # teardown ----------------------------------------------------------------------------
    def destroy(self) -> None:
        """Destroy everything the executor made (safe to call twice); frames in flight
        are finished first (or dropped, if that fails, and the failure raised after)."""
        in_flight = getattr(self, "in_flight", InFlight([]))
        failed = None
        try:
            if self._can_drain():
                self.drain()
        except Exception as e:  # destroy everything still, then say what went wrong
            failed = e
        in_flight.forget()
        self._idle()
        for slot in in_flight.slots:
            self._destroy_slot(slot)
        in_flight.slots.clear()
        self._release()
        self._samplers.clear()
        if failed is not None:
            raise failed
