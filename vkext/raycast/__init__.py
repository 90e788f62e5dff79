"""Closest-hit ray casting against a :class:`SceneAccel`, by ray query or ray-tracing pipeline.

Two ways to the same answer, so either can be checked against the other and against a CPU
reference (``rfw.RayScene`` and ``rfw.raycast`` are the numpy front end):

- ``"ray_query"``: a compute shader with ``GL_EXT_ray_query`` (``raycast.comp.glsl``);
- ``"ray_pipeline"``: raygen + miss + closest hit through a shader binding table and
  ``vkCmdTraceRaysKHR``; it needs no ray-query support (NVIDIA drivers may offer pipelines
  only).

A :class:`RayScene` keeps what casting needs from call to call: the scene's acceleration
structures (built once), the device's pipeline (:func:`raycaster`) and the ray and hit
buffers (:class:`RayBuffers`, grown when a batch is larger, never shrunk). Rays and hits are
*streams* (origins, directions, optional per-ray tmin and tmax; t, primitive, instance,
barycentrics), so the host fills and reads each with one copy of the caller's arrays, the
rays converted to float32 in that same copy whatever their dtype and layout (split among
threads when large: :func:`parallel_copy`); hits go into new arrays or the caller's
(``out``). The shaders check every ray as they read it (finite origin and direction, a
direction that is not zero): such a ray is not traced, and :meth:`Raycaster.cast` raises
naming the argument and the first bad row.

Rays go through in batches of at most ``batch`` rays, :data:`SLOTS` in flight, so the host
fills one batch's rays and reads another's hits while the GPU works; memory stays bounded
for any ray count. A cast of at most ``batch`` rays is one batch unless overlap pays
(:func:`batch_rays`: a GPU that is not the host's CPU, with measured GPU and host times both
large enough to hide behind each other; then :data:`OVERLAP_PARTS` batches): on the
H200 and on lavapipe a batch more cost more than it hid. Every batch reuses its slot's
fence and, for a cast like the last, its command buffer: a cast only submits. Where
the buffers live (:func:`mapped_streams`, per stream): on a discrete GPU, per batch one
submit copies the rays from a staging buffer to device-local memory, traces, and copies the
hits back (about 160 bytes a ray of the batch, staging included); where memory is
device-local and host-cached at once (lavapipe, integrated GPUs) the trace reads and writes
mapped buffers, one pair per slot, and nothing is copied. Timestamps around each copy and each trace give
``last``'s GPU parts, read once after the last batch; ``last`` also has the host's.

A batch is a tiny frame graph (:func:`batch_graph`: copy the rays in, trace, copy the hits
out), compiled once; its barriers are recorded by ``vkext.accel.plan.PlanRecorder``, as the
acceleration-structure builds record theirs. Both buffers persist from batch to batch, so
the plan also orders a batch's copy of the rays after the last batch's trace read them, and
its trace after the last batch's hits were copied out. A mapped stream skips its copy, and
mapped hits are made visible to the host (``commands.written_for_host``).

Modules: :mod:`.streams` (the rays' and hits' layout, the checks), :mod:`.copies` (the host's
copies), :mod:`.placement` (staged or mapped streams), :mod:`.batches` (batch sizes, the
batch plan), :mod:`.caster` (:class:`Raycaster`, :class:`RayBuffers`), :mod:`.ray_scene`
(:func:`raycaster`, :class:`RayScene`), :mod:`.shared` (casts whose rays and hits stay on the
GPU, in memory exported to CUDA: ``RayScene.cast_device``).
"""

from .batches import (
    DEFAULT_BATCH,
    OVERLAP_BATCH_MS,
    OVERLAP_MIN,
    OVERLAP_PARTS,
    SLOTS,
    batch_graph,
    batch_rays,
)
from .caster import (
    GPU_PARTS,
    HOST_PARTS,
    METHODS,
    SHADERS,
    STAMPS,
    RayBuffers,
    Raycaster,
    device_lock,
    pick_method,
)
from .copies import COPY_SPLIT, COPY_THREADS, parallel_copy
from .placement import PLACEMENTS, mapped_streams, mapped_type_bits, rays_in_host_memory
from .ray_scene import RayScene, check_device, raycaster
from .streams import (
    HIT_DTYPE,
    HIT_STREAMS,
    HIT_WORDS,
    INVALID,
    RAY_DTYPE,
    RAY_STREAMS,
    RAY_WORDS,
    check_rays,
    hit_arrays,
)

__all__ = [
    "COPY_SPLIT",
    "COPY_THREADS",
    "DEFAULT_BATCH",
    "GPU_PARTS",
    "HIT_DTYPE",
    "HIT_STREAMS",
    "HIT_WORDS",
    "HOST_PARTS",
    "INVALID",
    "METHODS",
    "OVERLAP_BATCH_MS",
    "OVERLAP_MIN",
    "OVERLAP_PARTS",
    "PLACEMENTS",
    "RAY_DTYPE",
    "RAY_STREAMS",
    "RAY_WORDS",
    "SHADERS",
    "SLOTS",
    "STAMPS",
    "RayBuffers",
    "RayScene",
    "Raycaster",
    "batch_graph",
    "batch_rays",
    "check_device",
    "check_rays",
    "device_lock",
    "hit_arrays",
    "mapped_streams",
    "mapped_type_bits",
    "parallel_copy",
    "pick_method",
    "raycaster",
    "rays_in_host_memory",
]
