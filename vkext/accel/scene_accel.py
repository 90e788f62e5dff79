"""``SceneAccel``: the BLAS and TLAS of one scene, built, refit and reported.

It joins the seams of :mod:`vkext.accel`: geometry input (:mod:`.geometry`), BLAS batches and
compaction (:mod:`.blas`), instances and the TLAS (:mod:`.tlas`), the plans that order the
builds (:mod:`.plan`) and the statistics (:mod:`.stats`). No barrier is written here: the
one-time build and host-side refits record their compiled plan's barriers, and a frame's TLAS
build (:meth:`SceneAccel.record_tlas`) gets its barriers from the frame graph.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from rfw.scene.model import Scene
from rfw.units import MiB, align_up

from ..blocks import BlockAllocator
from ..buffers import Buffer
from ..commands import one_time
from ..consts import vk
from ..device import VkDevice
from .blas import (
    BlasJob,
    batch_scratch,
    batches,
    blas_jobs,
    compacted_sizes,
    create_structures,
    record_batch,
    record_compaction,
    record_size_query,
)
from .geometry import SceneGeometry
from .plan import PlanRecorder, build_graph, compiled, refit_graph
from .stats import BuildTimer, accel_stats
from .structure import PREFER, AccelerationStructure, build_flags, scratch_buffer, scratch_multiple
from .tlas import ALPHA_MASK, TopLevel, instance_records


class SceneAccel:
    """BLAS per mesh and a TLAS over the instances of an :class:`rfw.scene.model.Scene`.

    Parameters
    ----------
    prefer
        ``"fast_trace"`` (default: a better tree, a slower build), ``"fast_build"`` or None.
    allow_update
        Build the TLAS so :meth:`update` can refit it for moved instances instead of
        rebuilding (an update keeps the tree's topology, so traversal slows as instances
        drift far from where they were built).
    compact
        Compact every BLAS after its build (query the compacted size, copy, free the
        original); ``stats()`` reports the bytes before and after.
    hit_groups
        Shader-binding-table record offset per alpha mode (default 0 for all), for pipelines
        with several hit groups (an any-hit alpha test for MASK); ``hit_records`` is then the
        number of hit records a table must hold.
    scratch_budget
        The most scratch memory BLAS builds use at once; more BLAS are built in batches.
    moves
        The scene's animations move its instances: :meth:`move` sets each frame's
        transforms, and a frame's TLAS build records its instance records in its own
        commands (not a host write a frame in flight could still be reading).

    ``blas[m]`` is mesh ``m``'s structure (None for a mesh without triangles), shared by
    every instance of the mesh; ``tlas`` the top level; ``transforms`` the instances' current
    (N, 4, 4) world matrices; ``geometry`` the triangles' buffers (:mod:`.geometry`).
    ``build_plan`` is the compiled plan of the one-time build, ``refit_plan`` that of the
    last :meth:`update`.
    """

    def __init__(self, device: VkDevice, scene: Scene, *, prefer: str | None = "fast_trace",
                 allow_update: bool = False, compact: bool = False,
                 hit_groups: Mapping[str, int] | None = None, scratch_budget: int = 64 * MiB,
                 label: str = "accel", moves: bool = False):
        device.require("VK_KHR_acceleration_structure", "buffer_device_address")
        if prefer not in PREFER:
            raise ValueError(f"prefer is one of {', '.join(map(repr, PREFER))}, not {prefer!r}")
        unknown = sorted(set(hit_groups or {}) - set(ALPHA_MASK))
        if unknown:
            raise ValueError(f"hit_groups: unknown alpha mode(s) {', '.join(unknown)} "
                             f"(known: {', '.join(ALPHA_MASK)})")
        self.device, self.scene, self.label = device, scene, label
        self.prefer, self.allow_update, self.compact = prefer, allow_update, compact
        self.moves = moves
        self.hit_groups = {m: int((hit_groups or {}).get(m, 0)) for m in ALPHA_MASK}
        self.hit_records = max(self.hit_groups.values()) + 1
        self.scratch_budget = int(scratch_budget)
        self.transforms = np.array([np.asarray(i.transform, np.float32)
                                    for i in scene.instances], np.float32).reshape(-1, 4, 4)
        self.blas: list[AccelerationStructure | None] = []
        self.geometry: SceneGeometry | None = None
        self.top: TopLevel | None = None
        self.timer: BuildTimer | None = None
        self.build_plan = self.refit_plan = None
        self.tlas_instances: list[int] = []  # scene instance index of each TLAS record
        self.triangles = self.blas_bytes_built = self.scratch_bytes = self.blas_batches = 0
        self.build_ms: dict[str, float] = {}
        self.frame_builds = {"build": 0, "update": 0}
        self._frame_scratch: Buffer | None = None  # record_tlas's, made on first use
        self._query_pool: Any = None
        self.allocator: BlockAllocator | None = BlockAllocator(device, block_size=32 * MiB,
                                                               label=f"{label}:blocks")
        device.register(self)
        try:
            self.timer = BuildTimer(device, 3, label)
            self.geometry = SceneGeometry(device, scene, self.allocator, label)
            self._build()
        except BaseException:
            self.destroy()
            raise

    # what shaders and callers read -----------------------------------------------------------

    @property
    def tlas(self) -> AccelerationStructure | None:
        return self.top.tlas if self.top is not None else None

    @property
    def instance_buffer(self) -> Buffer:
        return self.top.instance_buffer

    def _instance_records(self) -> np.ndarray:
        records, self.tlas_instances = instance_records(self.scene, self.blas, self.transforms,
                                                        self.hit_groups)
        return records

    # the one-time build ----------------------------------------------------------------------

    def _build(self) -> None:
        dev, scene = self.device, self.scene
        if len(scene.instances) >= 1 << 24:
            raise ValueError(f"{len(scene.instances)} instances: instanceCustomIndex holds 24 "
                             "bits")
        align = scratch_multiple(dev)
        compact_flag = ("VK_BUILD_ACCELERATION_STRUCTURE_ALLOW_COMPACTION_BIT_KHR",) \
            if self.compact else ()
        jobs = blas_jobs(dev, self.geometry, build_flags(self.prefer, *compact_flag))
        self.triangles = sum(j.range.primitiveCount for j in jobs)
        # compacted copies live in the block allocator; the originals die after the copy
        self.blas = create_structures(dev, jobs, len(scene.meshes),
                                      allocator=None if self.compact else self.allocator,
                                      label=self.label, names=[m.name for m in scene.meshes])
        self.blas_bytes_built = sum(j.size for j in jobs)
        groups = batches(jobs, self.scratch_budget, align)
        self.blas_batches = len(groups)
        self.top = TopLevel(dev, scene, self.blas, self.allocator, prefer=self.prefer,
                            allow_update=self.allow_update, align=align, label=self.label,
                            moves=self.moves)
        compact = self.compact and bool(jobs)
        self.build_plan = compiled(build_graph(len(groups), compact=compact))
        plan = PlanRecorder(self.build_plan)
        need = max(max((batch_scratch(b, align) for b in groups), default=0),
                   self.top.scratch[0])
        scratch = scratch_buffer(dev, need, align, f"{self.label}:build scratch")
        try:
            self._record_builds(plan, groups, jobs, scratch, align, compact)
            self.scratch_bytes = scratch.bytes
        finally:
            scratch.destroy()
        if not plan.done():
            raise RuntimeError(f"'{self.label}': the build plan has passes nobody recorded")

    def _record_builds(self, plan: PlanRecorder, groups: list[list[BlasJob]],
                       jobs: list[BlasJob], scratch: Buffer, align: int, compact: bool) -> None:
        """BLAS batches, then (after compaction, in a submit of its own) the TLAS; the
        timer's mark 1 ends the BLAS, mark 2 the TLAS."""
        dev, timer = self.device, self.timer
        base = align_up(scratch.address, align)
        keep: list[Any] = []  # cffi structs that must live until the commands are submitted
        with one_time(dev, label=f"{self.label}: build") as cmd:
            timer.start(cmd)
            timer.mark(cmd, 0)
            if groups:
                plan.enter(cmd, "blas")
            for k, batch in enumerate(groups):
                plan.step(cmd, k)
                keep += record_batch(dev, cmd, batch, self.blas, base, align)
            timer.mark(cmd, 1)
            if compact:
                plan.enter(cmd, "compact_query")
                self._query_pool = record_size_query(dev, cmd,
                                                     [self.blas[j.mesh] for j in jobs])
            else:
                self._record_first_tlas(cmd, plan, scratch)
        self.build_ms["blas"] = timer.span(0, 1)
        if compact:
            self._compact(plan, jobs)
            with one_time(dev, label=f"{self.label}: tlas") as cmd:
                timer.start(cmd)
                timer.mark(cmd, 1)
                self._record_first_tlas(cmd, plan, scratch)
        self.build_ms["tlas"] = timer.span(1, 2)
        del keep

    def _record_first_tlas(self, cmd: Any, plan: PlanRecorder, scratch: Buffer) -> None:
        # the TLAS build reuses the BLAS builds' scratch; timer mark 2 after it
        plan.enter(cmd, "tlas")
        self.top.record(cmd, self._instance_records(), scratch)
        self.timer.mark(cmd, 2)
        plan.enter(cmd, "readers")

    def _compact(self, plan: PlanRecorder, jobs: list[BlasJob]) -> None:
        """Compacted sizes back to the host, structures of that size, copies into them."""
        dev = self.device
        pool, self._query_pool = self._query_pool, None
        sizes = compacted_sizes(dev, pool, len(jobs))
        originals = [self.blas[j.mesh] for j in jobs]
        compacted: list[AccelerationStructure] = []
        try:
            for old, size in zip(originals, sizes, strict=True):
                compacted.append(AccelerationStructure(dev, "bottom", size,
                                                       allocator=self.allocator,
                                                       label=old.label))
            with one_time(dev, label=f"{self.label}: compact") as cmd:
                self.timer.start(cmd)
                self.timer.mark(cmd, 0)
                plan.enter(cmd, "compact")
                record_compaction(dev, cmd, originals, compacted)
                self.timer.mark(cmd, 1)
            self.build_ms["compact"] = self.timer.span(0, 1)
        except BaseException:
            for c in compacted:
                c.destroy()
            raise
        for job, old, c in zip(jobs, originals, compacted, strict=True):
            old.destroy()
            self.blas[job.mesh] = c

    # per frame ---------------------------------------------------------------------------------

    def record_tlas(self, cmd: Any, *, update: bool = False) -> str:
        """Record a TLAS build from the current ``transforms`` into ``cmd`` (a frame's
        command buffer), or with ``update`` (needs ``allow_update``) a refit of it in place.

        No barrier is recorded: the frame graph plans them. ``accel_build`` declares the
        TLAS and this object's frame scratch as its outputs, so the executor orders this
        build after the last frame's (the scratch: write after write) and after its traces
        (the TLAS: write after read), and the traces after it. The instance records are
        written from the host now, so the previous user of the TLAS must be done (frames
        are waited for). Returns ``"build"`` or ``"update"``."""
        if update and not self.allow_update:
            raise ValueError(f"'{self.label}' was built without allow_update=True: it can "
                             "only be rebuilt")
        if self._frame_scratch is None:
            self._frame_scratch = scratch_buffer(self.device, self.top.frame_scratch,
                                                 self.top.align, f"{self.label}:frame scratch")
        self.top.record(cmd, self._instance_records(), self._frame_scratch, update=update,
                        inline=self.moves)
        mode = "update" if update else "build"
        self.frame_builds[mode] += 1
        return mode

    def move(self, transforms: Any) -> None:
        """The instances' (N, 4, 4) transforms of the frame to come (``moves``: the
        scene's animations): the next :meth:`record_tlas` builds from them."""
        if not self.moves:
            raise ValueError(f"'{self.label}' was made for a still scene (moves=False)")
        self.transforms = np.asarray(transforms, np.float32).reshape(-1, 4, 4).copy()

    # refit -------------------------------------------------------------------------------------

    def update(self, transforms: Mapping[int, Any] | Any) -> None:
        """Refit the TLAS for moved instances: ``transforms`` is (N, 4, 4) for every scene
        instance, or ``{instance index: 4x4}`` for some. Needs ``allow_update=True``.

        The instance records are rewritten in place and the TLAS updated from itself
        (``VK_BUILD_ACCELERATION_STRUCTURE_MODE_UPDATE_KHR``) through the refit plan, whose
        barriers order it after earlier traces and later traces after it; the call waits
        for the GPU, so no trace still reads the records it overwrites."""
        if not self.allow_update:
            raise ValueError(f"'{self.label}' was built without allow_update=True: rebuild it "
                             "to move instances")
        self.transforms = _moved(self.transforms, transforms)
        self.refit_plan = compiled(refit_graph())
        plan = PlanRecorder(self.refit_plan)
        with one_time(self.device, label=f"{self.label}: update") as cmd:
            plan.enter(cmd, "refit")
            self.timer.start(cmd)
            self.timer.mark(cmd, 0)
            self.top.record(cmd, self._instance_records(), self.top.update_scratch,
                            update=True)
            self.timer.mark(cmd, 1)
            plan.enter(cmd, "readers")
        self.build_ms["update"] = self.timer.span(0, 1)

    # reporting and teardown --------------------------------------------------------------------

    def stats(self) -> dict[str, Any]:
        """What was built and what it cost (see :func:`vkext.accel.stats.accel_stats`)."""
        return accel_stats(self)

    def destroy(self) -> None:
        """Destroy the structures, buffers and pools (safe to call twice)."""
        if self._query_pool is not None and self.device.alive:
            vk.vkDestroyQueryPool(self.device.device, self._query_pool, None)
        self._query_pool = None
        if self.top is not None:
            self.top.destroy()
            self.top = None
        for b in self.blas:
            if b is not None:
                b.destroy()
        self.blas = []
        if self._frame_scratch is not None:
            self._frame_scratch.destroy()
            self._frame_scratch = None
        if self.timer is not None:
            self.timer.destroy()
            self.timer = None
        if self.allocator is not None:
            self.allocator.destroy()
            self.allocator = None
        self.device.unregister(self)

    def __enter__(self) -> SceneAccel:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.destroy()


def _moved(current: np.ndarray, transforms: Mapping[int, Any] | Any) -> np.ndarray:
    """``current`` with ``transforms`` applied: all (N, 4, 4) of them or ``{index: 4x4}``."""
    n = len(current)
    out = current.copy()
    if isinstance(transforms, Mapping):
        for k, t in transforms.items():
            if not 0 <= int(k) < n:
                raise ValueError(f"update: instance {k} is not among the scene's {n}")
            out[int(k)] = _matrix(t, f"transforms[{k}]")
    else:
        arr = np.asarray(transforms, np.float32)
        if arr.shape != (n, 4, 4):
            raise ValueError(f"update: transforms has shape {arr.shape}, expected "
                             f"({n}, 4, 4) or a dict of 4x4 matrices")
        out = arr.copy()
    if not np.isfinite(out).all():
        raise ValueError("update: transforms must be finite")
    return out


def _matrix(t: Any, what: str) -> np.ndarray:
    m = np.asarray(t, np.float32)
    if m.shape != (4, 4):
        raise ValueError(f"update: {what} has shape {m.shape}, expected (4, 4)")
    return m
