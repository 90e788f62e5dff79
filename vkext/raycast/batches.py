"""How a cast is cut into batches: :func:`batch_rays` (one batch unless overlap pays, with the
measurements that say when) and :func:`batch_graph`, the tiny frame graph of one batch whose
plan orders its copies and trace."""

from __future__ import annotations

from rfw.graph import Buffer as BufferSlot
from rfw.graph import Graph, GraphBuilder

DEFAULT_BATCH = 1 << 20
# Batches go SLOTS in flight: the host copies one batch's rays in and another's hits out
# while the GPU works. A cast of at most ``batch`` rays is one batch unless overlap pays
# (batch_rays): then OVERLAP_PARTS batches of at least OVERLAP_MIN rays. Overlap hides at
# most the smaller of the GPU's time and the host's copies, and each batch more costs a
# submit, a wait and smaller copies. Measured (benchmarks/bench_rt.py --sections cast,
# courtyard primary rays, medians, ms):
# - NVIDIA H200 (driver 580.159.04, 16-thread Xeon), 921,600 rays, staged: 4 batches 11.85
#   wall (into new arrays), 1 batch 5.92 (into out= arrays); mapped: 10.84 against 5.87.
#   The GPU's share is 1.3-1.7 ms (copies 0.6 + 0.35, trace 0.4), the host's copies 3-8
#   ms; 4 submits cost 1.68 ms against 0.48 for one, and the host's copies in four pieces
#   took 4.8 ms (in) and 3.0 (out, page faults of new arrays included) against 1.6 and 1.4:
#   about 2 ms a batch more (OVERLAP_BATCH_MS), for at most the GPU's 1.5 ms hidden.
# - lavapipe (2 cores; mapped, ray_query), 921,600 rays: 4 batches 348-350 ms wall (host
#   copies 14-19 in, 10-15 out; trace 340), 1 batch 313-325 (copies 5 in, 3-4 out; trace
#   303-311). The "GPU" is the host's own cores: the host's copies compete with the trace
#   instead of hiding behind it, so a CPU device never overlaps.
# So on a GPU a cast overlaps only when the last cast of at least OVERLAP_MIN rays through
# the same buffers measured GPU and host rates (timestamps; upload + readback) that put
# both over OVERLAP_PARTS * OVERLAP_BATCH_MS for this one; the first cast is one batch.
OVERLAP_PARTS, OVERLAP_MIN, SLOTS = 4, 1 << 16, 2
OVERLAP_BATCH_MS = 2.0

# the pass type that traces: its shader stages read the rays and write the hits
_PASS_TYPE = {"ray_query": "compute", "ray_pipeline": "ray_tracing"}


def batch_graph(method: str) -> Graph:
    """One batch of ``method``: ``rays`` copies the rays in (buffer ``rays``), ``trace``
    reads them and writes buffer ``hits``, ``hits`` copies those out. Both buffers are
    external (persistent): a plan compiled from this starts from how the last batch left
    them."""
    g = GraphBuilder("raycast", size=(1, 1))
    g.add_pass("rays", "transfer").output(
        "rays", BufferSlot(usage=("transfer_dst",), external=True), name="rays")
    t = g.add_pass("trace", _PASS_TYPE[method])
    t.input("rays", "rays", BufferSlot(usage=("storage",)))
    t.output("hits", BufferSlot(usage=("storage",), external=True), name="hits")
    g.add_pass("hits", "transfer", side_effect=True).input(
        "hits", "hits", BufferSlot(usage=("transfer_src",)))
    return g.build()


def batch_rays(n: int, batch: int, *, device_type: str = "discrete_gpu",
               rates: tuple[float, float] | None = None) -> int:
    """Rays per batch for a cast of ``n`` rays (``n > 0``) capped at ``batch``: all of them
    (at most ``batch``) in one, or OVERLAP_PARTS batches of at least OVERLAP_MIN where
    overlap pays (see OVERLAP_BATCH_MS): on a device that is not the host's CPU
    (``device_type``, :attr:`VkDevice.device_type`), with ``rates`` measured (the GPU's
    and the host's nanoseconds per ray, :attr:`RayBuffers.rates`) that put both the GPU's
    time and the host's copies for ``n`` rays at OVERLAP_PARTS * OVERLAP_BATCH_MS or more."""
    per = min(batch, n)
    if device_type == "cpu" or rates is None or n < 2 * OVERLAP_MIN:
        return per
    if min(rates) * n / 1e6 < OVERLAP_PARTS * OVERLAP_BATCH_MS:
        return per
    return min(per, max(OVERLAP_MIN, -(-n // OVERLAP_PARTS)))
