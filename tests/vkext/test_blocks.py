"""The block allocator: placements are sound under any sequence, and the work per
allocation stays bounded as allocations pile up (counted, never timed)."""

from __future__ import annotations

import itertools

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vkext import BlockAllocator
from vkext.blocks import PROBES

KiB, MiB = 1 << 10, 1 << 20

# alignments as drivers ask for them: lavapipe's small ones, NVIDIA's larger ones (up to
# 64 KiB for some images), and one beyond that, since no alignment may be assumed
ALIGNMENTS = [1, 4, 16, 64, 256, 1024, 4096, 64 * KiB, 256 * KiB]


def _any_type(device) -> int:
    return (1 << len(device.memory_types)) - 1


def placement_problems(allocs, granularity: int) -> list[str]:
    """What is wrong with a set of live sub-allocations: overlap, misalignment, a range
    past its block, or a linear and a non-linear range sharing a granularity page."""
    problems = []
    by_memory: dict[int, list] = {}
    for a, alignment in allocs:
        if a.offset % alignment:
            problems.append(f"{a.label}: offset {a.offset} misses alignment {alignment}")
        if a.end > a.memory.size:
            problems.append(f"{a.label}: ends at {a.end}, past its block ({a.memory.size})")
        by_memory.setdefault(id(a.memory), []).append(a)
    for group in by_memory.values():
        group.sort(key=lambda a: a.offset)
        for x, y in itertools.pairwise(group):
            if y.offset < x.end:
                problems.append(f"{x.label} [{x.offset}, {x.end}) overlaps {y.label} "
                                f"[{y.offset}, {y.end})")
            elif x.linear != y.linear and (x.end - 1) // granularity == y.offset // granularity:
                problems.append(f"{x.label} and {y.label} share a granularity page")
    return problems


# one step: allocate (size, alignment index, linear) or free the k-th live allocation
_steps = st.lists(st.one_of(
    st.tuples(st.just("alloc"), st.integers(1, 3 * MiB), st.integers(0, len(ALIGNMENTS) - 1),
              st.booleans()),
    st.tuples(st.just("free"), st.integers(0, 10_000))), min_size=1, max_size=60)


@pytest.mark.parametrize("strategy", ["good-fit", "first-fit"])
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                 HealthCheck.function_scoped_fixture])
@given(steps=_steps, granularity=st.sampled_from([1, 64, 1024, 4096]))
def test_placements_never_overlap_and_keep_alignment(vk_device, strategy, steps, granularity):
    blocks = BlockAllocator(vk_device, block_size=2 * MiB, label="prop", strategy=strategy)
    blocks.granularity = granularity  # exaggerated past lavapipe's 64 too
    live = []
    try:
        for step in steps:
            if step[0] == "alloc":
                _, size, k, linear = step
                a = blocks.allocate(size, ALIGNMENTS[k], _any_type(vk_device), linear=linear,
                                    label=f"a{len(live)}")
                live.append((a, ALIGNMENTS[k]))
            elif live:
                live.pop(step[1] % len(live))[0].free()
            assert placement_problems(live, granularity) == []
            s = blocks.stats()
            assert s["allocations"] == len(live)
            assert s["used_bytes"] == sum(a.size for a, _ in live)
            free = sum(e - b for bs in blocks.blocks.values() for blk in bs
                       for b, e in blk.gaps())
            assert free == s["free_bytes"]  # free ranges and allocations tile every block
    finally:
        blocks.destroy()


def test_placement_check_rejects_bad_placements(vk_device):
    # negative control: the check above sees overlap, misalignment and a shared page
    blocks = BlockAllocator(vk_device, block_size=MiB, label="control")
    try:
        a = blocks.allocate(1000, 16, _any_type(vk_device), linear=True, label="a")
        b = blocks.allocate(1000, 256, _any_type(vk_device), linear=False, label="b")
        assert placement_problems([(a, 16), (b, 256)], 64) == []
        b.offset = 512  # overlaps a
        assert "overlaps" in placement_problems([(a, 16), (b, 256)], 64)[0]
        b.offset = 1008  # after a, misaligned for 256
        assert "alignment" in placement_problems([(a, 16), (b, 256)], 64)[0]
        b.offset = 1024  # aligned, but on a's 4 KiB page
        assert "granularity" in placement_problems([(a, 16), (b, 256)], 4096)[0]
        assert placement_problems([(a, 16), (b, 256)], 64) == []
    finally:
        blocks.destroy()


def _visits_per_allocation(device, strategy: str, count: int) -> float:
    """Allocate ``count`` scene-like buffers (vertex streams and indices of small meshes,
    every fourth a 256-byte-aligned uniform, every ninth freed again) and return the free
    ranges (or gaps) looked at per allocation over the last quarter."""
    blocks = BlockAllocator(device, block_size=64 * MiB, label="scale", strategy=strategy)
    try:
        live = []
        marks = []
        for k in range(count):
            if k == count * 3 // 4:
                marks.append(blocks.visits)
            size = 48 + (k * 97) % 4000
            live.append(blocks.allocate(size, 256 if k % 4 == 0 else 16, _any_type(device),
                                        linear=True, label=f"b{k}"))
            if k % 9 == 8:
                live.pop(k % len(live)).free()
        return (blocks.visits - marks[0]) / (count - count * 3 // 4)
    finally:
        blocks.destroy()


def test_allocation_work_stays_bounded_as_allocations_grow(vk_device):
    # work per allocation at 400 and at 4,000 allocations: the same bound for both
    small = _visits_per_allocation(vk_device, "good-fit", 400)
    large = _visits_per_allocation(vk_device, "good-fit", 4000)
    assert small <= PROBES + 1 and large <= PROBES + 1
    assert large <= 2 * small + 1


def test_first_fit_work_grows_with_allocations(vk_device):
    # negative control: the old first-fit scan fails the bound, and ten times the
    # allocations cost several times the work per allocation
    small = _visits_per_allocation(vk_device, "first-fit", 400)
    large = _visits_per_allocation(vk_device, "first-fit", 4000)
    assert large > PROBES + 1
    assert large > 5 * small


def test_unknown_strategy_is_one_line(vk_device):
    from rfw.errors import RfwError

    with pytest.raises(RfwError, match="unknown allocation strategy 'best'"):
        BlockAllocator(vk_device, strategy="best")


def _cubes(meshes: int, mirrored: bool = False):
    import numpy as np

    from rfw.scene import Instance, Scene
    from rfw.scene.stress import _cube

    scene = Scene("cubes", [_cube(f"cube{k}", 0) for k in range(meshes)])
    for k in range(meshes):
        t = np.identity(4, np.float32)
        t[0, 3] = 2.0 * k
        if mirrored and k == 0:
            t[0, 0] = -1.0
        scene.instances.append(Instance(k, t, f"cube {k}"))
    return scene


def _scene_buffers(device, scene) -> tuple[int, int]:
    """Live buffers a VkScene of ``scene`` adds, and its allocator's allocations."""
    from vkext.scene import VkScene

    before = device.live_objects()["Buffer"]
    vs = VkScene(device, scene)
    try:
        return device.live_objects()["Buffer"] - before, vs.allocator.stats()["allocations"]
    finally:
        vs.destroy()


def test_scene_buffers_do_not_grow_with_meshes(vk_device):
    # every mesh's streams share a few packed buffers: 6 meshes or 60, the same count
    few, many = _scene_buffers(vk_device, _cubes(6)), _scene_buffers(vk_device, _cubes(60))
    assert few == many
    assert few[0] <= 8
    # negative control: the count sees buffers the scene adds (a mirrored instance's
    # flipped tangents and indices are two more)
    mirrored = _scene_buffers(vk_device, _cubes(60, mirrored=True))
    assert mirrored[0] == many[0] + 2
