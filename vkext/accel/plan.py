"""The builds of a scene's acceleration structures as tiny frame graphs, and their barriers.

Builds outside a frame (the BLAS and first TLAS at scene load, a host-side refit) are
declared as graphs and compiled by :func:`rfw.graph.compile`, like a frame: the BLAS builds,
the compaction query and copies, the TLAS build and the refit are passes; the BLAS of each
batch, the scratch the builds share, the compacted BLAS and the TLAS are acceleration-structure
resources. Batches of BLAS builds are steps of the ``blas`` pass (``rfw.graph.Step``): batch
``k`` writes its BLAS and the whole scratch, so the compiler plans a barrier between batches
as it plans those between passes. It plans every other barrier too: the TLAS build after the
BLAS writes, later readers after the TLAS. :class:`PlanRecorder` records them, pass by pass
and step by step, with :func:`vkext.commands.record_barriers`, as ``VkExecutor.record`` does;
the accel modules record only the work between them.

Not through ``VkExecutor`` itself: ``vkext.executor`` imports ``vkext.scene``, which builds
these structures (an import circle), and a build needs none of what the executor makes for
a frame (programs, descriptor pools, uniform ring, transient heaps).

The last pass, ``readers``, stands for every later user of the structures: ray queries and
ray-tracing pipelines in any stage, in later submits. Its barrier makes the builds visible to
them; a plan compiled again starts from how ``readers`` left the structures (a refit waits for
earlier traces).
"""

from __future__ import annotations

from typing import Any

from rfw.graph import (
    AccelStructure,
    CompiledGraph,
    Graph,
    GraphBuilder,
    Reference,
    Step,
    compile,
)

from ..commands import GLOBAL, record_barriers

BUILD_STAGE = frozenset({"ACCELERATION_STRUCTURE_BUILD_KHR"})
ANY_STAGE = frozenset({"ALL_COMMANDS"})

# reads of the build stage: the TLAS build reads the BLAS, the compaction query and copies
# read the originals
_BUILD_READ = AccelStructure(stages=BUILD_STAGE, desc="read by a build, query or copy")
_LATER_READ = AccelStructure(stages=ANY_STAGE, desc="read by any later trace or copy")


def build_graph(batches: int, *, compact: bool) -> Graph:
    """Pass ``blas`` with one step per batch (``batch0`` ..; batch ``k`` writes slot
    ``blas{k}`` and the shared ``scratch``), with ``compact`` then ``compact_query`` (reads
    the BLAS) and ``compact`` (copies them into ``compact.blas``), then ``tlas`` (reads the
    BLAS, writes ``tlas`` with the same scratch) and ``readers``. No batch: no ``blas``."""
    g = GraphBuilder("accel_build", size=(1, 1))
    blas = [f"blas.blas{k}" for k in range(batches)]
    if batches:
        steps = [Step(f"batch{k}", writes=(f"blas{k}", "scratch")) for k in range(batches)]
        p = g.add_pass("blas", "compute", steps=steps)
        for k in range(batches):
            p.output(f"blas{k}", AccelStructure(desc=f"the BLAS of batch {k}"))
        _write_scratch(p, first=True)
    if compact and blas:
        q = g.add_pass("compact_query", "compute", side_effect=True)
        c = g.add_pass("compact", "compute")
        for k, name in enumerate(blas):
            q.input(f"blas{k}", name, _BUILD_READ)
            c.input(f"blas{k}", name, _BUILD_READ)
        c.output("blas", AccelStructure(desc="the compacted BLAS"))
        blas = ["compact.blas"]
    t = g.add_pass("tlas", "compute")
    for k, name in enumerate(blas):
        t.input(f"blas{k}", name, _BUILD_READ)
    t.output("tlas", AccelStructure(desc="the TLAS"), name="tlas")
    _write_scratch(t, first=not batches)
    _readers(g, ["tlas", *blas])
    return g.build()


def refit_graph() -> Graph:
    """``refit`` updates ``tlas`` in place with its own scratch, then ``readers``."""
    g = GraphBuilder("accel_refit", size=(1, 1))
    p = g.add_pass("refit", "compute")
    p.output("tlas", AccelStructure(desc="the TLAS, refit in place"), name="tlas")
    p.output("scratch", AccelStructure(desc="scratch of refits"), name="scratch")
    _readers(g, ["tlas"])
    return g.build()


def _write_scratch(p: Any, *, first: bool) -> None:
    # the scratch's accesses are acceleration-structure accesses of the build stage: an
    # accel resource, written by every build that uses it
    if first:
        p.output("scratch", AccelStructure(desc="scratch shared by the builds"), name="scratch")
    else:
        p.output("scratch", Reference(), target="scratch")


def _readers(g: GraphBuilder, names: list[str]) -> None:
    r = g.add_pass("readers", "compute", side_effect=True)
    for k, name in enumerate(names):
        r.input(f"s{k}", name, _LATER_READ)


def compiled(graph: Graph) -> CompiledGraph:
    """The plan of a build graph (compiling the same graph again is a cache lookup)."""
    return compile(graph, (1, 1))


class PlanRecorder:
    """Records a compiled build plan's barriers into command buffers, pass by pass and step
    by step in the plan's order (out of order is a bug: it raises)."""

    def __init__(self, plan: CompiledGraph):
        self.plan = plan
        self._next = 0
        self._step = -1  # the step of the current pass it is in
        self._resources = {r.name: GLOBAL for r in plan.resources}
        self.recorded = 0  # barriers recorded so far

    def enter(self, cmd: Any, name: str) -> None:
        """Record the barriers pass ``name`` needs before its work."""
        order = self.plan.order
        if self._next >= len(order) or order[self._next] != name:
            expected = order[self._next] if self._next < len(order) else "nothing"
            raise RuntimeError(f"{self.plan.name}: pass '{name}' recorded where the plan has "
                               f"{expected}")
        self._next += 1
        self._step = -1
        self._record(cmd, [b for b in self.plan.barriers if b.pass_name == name])

    def step(self, cmd: Any, index: int) -> None:
        """Record the barriers step ``index`` of the current pass needs before its work."""
        name = self.plan.order[self._next - 1] if self._next else "-"
        self._record(cmd, self.plan.barriers_before_step(name, index, self._step))
        self._step = index

    def _record(self, cmd: Any, barriers: list | tuple) -> None:
        # every resource here is synchronized by global memory barriers: equal ones are one
        unique = {(b.src, b.dst): b for b in barriers}
        self.recorded += record_barriers(cmd, list(unique.values()), self._resources)

    def done(self) -> bool:
        return self._next == len(self.plan.order)
