"""Access states: the (layout, stages, access) a usage needs, in Vulkan synchronization2 terms.

Names drop the ``VK_IMAGE_LAYOUT_``, ``VK_PIPELINE_STAGE_2_`` and ``VK_ACCESS_2_`` prefixes and
the ``_BIT`` suffix; vkext maps them back, the wgpu backend only needs the usages.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache, cached_property

# shader stages a pass of each type reads and writes resources in
SHADER_STAGES = {
    "graphics": frozenset({"VERTEX_SHADER", "FRAGMENT_SHADER"}),
    "mesh": frozenset({"TASK_SHADER_EXT", "MESH_SHADER_EXT", "FRAGMENT_SHADER"}),
    "compute": frozenset({"COMPUTE_SHADER"}),
    "ray_tracing": frozenset({"RAY_TRACING_SHADER_KHR"}),
    "transfer": frozenset({"COPY"}),
}

NONE: frozenset[str] = frozenset()


@dataclass(frozen=True)
class State:
    """How a resource is touched: image layout (None for buffers), stages and access."""

    layout: str | None
    stages: frozenset[str]
    access: frozenset[str]

    # cached: the barrier planner asks these of every access, twice
    @cached_property
    def writes(self) -> bool:
        return bool(write_access(self.access))

    @cached_property
    def write_access(self) -> frozenset[str]:
        return write_access(self.access)

    def merge(self, other: State) -> State:
        key = (self, other)
        merged = _MERGED.get(key)
        if merged is None:
            merged = _MERGED[key] = State(self.layout, self.stages | other.stages,
                                          self.access | other.access)
        return merged

    def to_json(self) -> dict[str, str]:
        return {"layout": self.layout or "-", "stages": "|".join(sorted(self.stages)) or "NONE",
                "access": "|".join(sorted(self.access)) or "NONE"}


# a graph merges the same few states again and again: each merge is made once
_MERGED: dict[tuple[State, State], State] = {}

UNDEFINED = State("UNDEFINED", NONE, NONE)


@cache
def is_write(access: str) -> bool:
    """Whether an access name writes (extension accesses end in _KHR/_EXT)."""
    return access.removesuffix("_KHR").removesuffix("_EXT").endswith("WRITE")


# the barrier planner asks this of the same few access sets again and again
_WRITE_ACCESS: dict[frozenset[str], frozenset[str]] = {}


def write_access(access: frozenset[str]) -> frozenset[str]:
    """The writing part of a set of accesses."""
    w = _WRITE_ACCESS.get(access)
    if w is None:
        w = _WRITE_ACCESS[access] = frozenset(a for a in access if is_write(a))
    return w


def _depth_layout(depth: bool, stencil: bool, read_only: bool) -> str:
    # depth-only formats use the 1.2 core depth layouts, combined formats the 1.0 ones
    aspect = "DEPTH_STENCIL" if stencil else "DEPTH"
    return f"{aspect}_{'READ_ONLY' if read_only else 'ATTACHMENT'}_OPTIMAL"


def state_for(usage: str, *, pass_type: str, write: bool, read: bool = True,
              depth: bool = False, stencil: bool = False, image: bool = True,
              stages: frozenset[str] = NONE) -> State:
    """The state one usage of a resource needs inside a pass of ``pass_type``."""
    shader = stages or SHADER_STAGES[pass_type]
    fragment_tests = frozenset({"EARLY_FRAGMENT_TESTS", "LATE_FRAGMENT_TESTS"})
    if usage == "sampled":
        layout = _depth_layout(depth, stencil, True) if depth else "SHADER_READ_ONLY_OPTIMAL"
        return State(layout if image else None, shader, frozenset({"SHADER_SAMPLED_READ"}))
    if usage == "storage":
        acc = ({"SHADER_STORAGE_READ"} if read else set()) | \
            ({"SHADER_STORAGE_WRITE"} if write else set())
        return State("GENERAL" if image else None, shader, frozenset(acc))
    if usage == "color":
        acc = {"COLOR_ATTACHMENT_WRITE"} | ({"COLOR_ATTACHMENT_READ"} if read else set())
        return State("COLOR_ATTACHMENT_OPTIMAL", frozenset({"COLOR_ATTACHMENT_OUTPUT"}),
                     frozenset(acc))
    if usage == "depth":
        return State(_depth_layout(True, stencil, False), fragment_tests,
                     frozenset({"DEPTH_STENCIL_ATTACHMENT_READ",
                                "DEPTH_STENCIL_ATTACHMENT_WRITE"}))
    if usage == "depth_read":
        return State(_depth_layout(True, stencil, True), fragment_tests,
                     frozenset({"DEPTH_STENCIL_ATTACHMENT_READ"}))
    if usage == "shading_rate":
        return State("FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR",
                     frozenset({"FRAGMENT_SHADING_RATE_ATTACHMENT_KHR"}),
                     frozenset({"FRAGMENT_SHADING_RATE_ATTACHMENT_READ_KHR"}))
    if usage == "uniform":
        return State(None, shader, frozenset({"UNIFORM_READ"}))
    if usage == "indirect":
        return State(None, frozenset({"DRAW_INDIRECT"}), frozenset({"INDIRECT_COMMAND_READ"}))
    if usage == "vertex":
        return State(None, frozenset({"VERTEX_ATTRIBUTE_INPUT"}),
                     frozenset({"VERTEX_ATTRIBUTE_READ"}))
    if usage == "index":
        return State(None, frozenset({"INDEX_INPUT"}), frozenset({"INDEX_READ"}))
    if usage == "accel_build":
        # a refit reads the structure it updates; a build only writes it
        return State(None, frozenset({"ACCELERATION_STRUCTURE_BUILD_KHR"}),
                     frozenset({"ACCELERATION_STRUCTURE_READ_KHR",
                                "ACCELERATION_STRUCTURE_WRITE_KHR"}))
    if usage == "accel_read":  # ray queries in any shader stage, ray-tracing pipelines
        return State(None, shader, frozenset({"ACCELERATION_STRUCTURE_READ_KHR"}))
    if usage == "transfer_src":
        return State("TRANSFER_SRC_OPTIMAL" if image else None, frozenset({"COPY"}),
                     frozenset({"TRANSFER_READ"}))
    if usage == "transfer_dst":
        return State("TRANSFER_DST_OPTIMAL" if image else None, frozenset({"COPY"}),
                     frozenset({"TRANSFER_WRITE"}))
    raise ValueError(f"unknown usage '{usage}'")


def merge_states(a: State, b: State) -> State | None:
    """One state covering both usages in the same pass, or None if they cannot coexist
    (an image in two layouts at once: a feedback loop)."""
    if a.layout == b.layout:
        return a.merge(b)
    read_only = not a.writes and not b.writes
    depth_ro = {"DEPTH_READ_ONLY_OPTIMAL", "DEPTH_STENCIL_READ_ONLY_OPTIMAL"}
    if read_only and (a.layout in depth_ro or b.layout in depth_ro):
        # sampling a depth buffer while depth-testing against it read-only is legal
        layout = a.layout if a.layout in depth_ro else b.layout
        return State(layout, a.stages | b.stages, a.access | b.access)
    return None
