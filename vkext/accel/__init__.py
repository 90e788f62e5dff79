"""Acceleration structures of a scene: one BLAS per mesh, one TLAS over the instances.

A BLAS holds a mesh's triangles in the mesh's own space and is built once, however many
instances place it: the TLAS refers to it by device address with each instance's transform
(the talk's sofas and chairs). Triangles come from device buffers through their buffer
device addresses: all meshes' positions in one buffer, all indices in another, kept after the
build and readable by shaders (``SceneAccel.geometry``: ``positions``, ``indices``, offsets in
``mesh_ranges``).

Building follows the talk's order, each step a pass of the build plan (:mod:`.plan`), whose
barriers the graph compiler plans:

1. size queries (``vkGetAccelerationStructureBuildSizesKHR``) for every BLAS and the TLAS;
2. BLAS builds, each with its own range of one scratch buffer whose ranges are aligned to
   ``minAccelerationStructureScratchOffsetAlignment``; when the scratch of all of them would
   exceed ``scratch_budget`` they are built in batches reusing the scratch (steps
   ``batch0``, ``batch1``, ... of the ``blas`` pass that all write it);
3. with ``compact``: the compacted sizes are queried (``compact_query``), the BLAS copied
   into structures of that size (``compact``, ``VK_COPY_ACCELERATION_STRUCTURE_MODE_COMPACT_KHR``)
   and the originals freed;
4. the TLAS build (``tlas``) reads the BLAS, so it waits for their writes;
5. ``readers`` stands for every later reader (ray queries in any stage, ray-tracing
   pipelines): its barrier makes the builds visible to them.

Per frame, ``passes/accel_build`` records the TLAS build (or refit) into the frame and the
frame graph plans its barriers. Geometry of OPAQUE materials is flagged opaque (any-hit
shaders never run for it); MASK and BLEND geometry is not, with
``NO_DUPLICATE_ANY_HIT_INVOCATION`` so an alpha test runs once per triangle. Instances are
described in :mod:`.tlas`.

Modules: :mod:`.structure` (one structure, sizes, build descriptions, scratch),
:mod:`.geometry` (the triangles' buffers), :mod:`.blas` (batches, compaction), :mod:`.tlas`
(instance records, the TLAS), :mod:`.plan` (the build plans and their barriers),
:mod:`.stats` (timings and the summary), :mod:`.scene_accel` (``SceneAccel``).
"""

from .plan import PlanRecorder, build_graph, refit_graph
from .scene_accel import SceneAccel
from .structure import PREFER, AccelerationStructure, build_sizes
from .tlas import ALPHA_MASK, INSTANCE_DTYPE, MASK_ALPHA_TEST, MASK_BLEND, MASK_OPAQUE

__all__ = [
    "ALPHA_MASK",
    "INSTANCE_DTYPE",
    "MASK_ALPHA_TEST",
    "MASK_BLEND",
    "MASK_OPAQUE",
    "PREFER",
    "AccelerationStructure",
    "PlanRecorder",
    "SceneAccel",
    "build_graph",
    "build_sizes",
    "refit_graph",
]
