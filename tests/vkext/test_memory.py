"""Aliased transient heaps from a compiled graph, requirements, block allocation, staging."""

from __future__ import annotations

import numpy as np
import pytest

from rfw.graph import GraphBuilder, MemoryOptions, Texture, compile
from rfw.graph.synthetic import synthetic_graph
from vkext import (
    BlockAllocator,
    Buffer,
    DeviceMemory,
    Heap,
    Image,
    PlanMismatchError,
    UnsupportedFormatError,
    VkMissingFeatureError,
    VkOutOfMemoryError,
    image_view,
    memory_options,
    plan_heaps,
    requirements,
    staging_buffer,
)
from vkext.consts import vk
from vkext.images import vk_format

from .helpers import chain_graph

KiB, MiB, TiB = 1 << 10, 1 << 20, 1 << 40


def _overlap(a, b) -> bool:
    return a.offset < b.offset + b.size and b.offset < a.offset + a.size


def test_heap_aliasing_is_real(vk_device):
    plan = compile(chain_graph(4, 256))
    tm = plan_heaps(plan, vk_device)
    separate = plan_heaps(plan, vk_device, no_alias=True)
    try:
        assert tm.allocated_bytes == plan.transient_bytes == 2 * 256 * KiB
        assert separate.allocated_bytes == 4 * 256 * KiB
        assert tm.allocated_bytes < separate.allocated_bytes
        assert len(tm.heaps) == 1 and len(separate.heaps) == 4
        img = tm.images
        # p0 is dead when p2 is born: same VkDeviceMemory, overlapping bytes
        assert img["p0.color"].memory is img["p2.color"].memory
        assert _overlap(img["p0.color"], img["p2.color"])
        assert _overlap(img["p1.color"], img["p3.color"])
        # p0 and p1 are alive together (p1 reads p0): disjoint
        assert img["p0.color"].memory is img["p1.color"].memory
        assert not _overlap(img["p0.color"], img["p1.color"])
        for name, p in tm.placements.items():
            assert p.offset == plan.resource(name).offset and p.size <= p.planned
        assert "p2.color" in tm.report()
    finally:
        tm.destroy()
        separate.destroy()


def _odd_graph(size: tuple[int, int]):
    g = GraphBuilder("odd", size=size)
    g.add_pass("a", "compute").output("r8", Texture("r8unorm"))
    g.add_pass("b", "compute").input("src", "a.r8").output("hdr", Texture("rgba16float"))
    g.output("b.hdr")
    return g.build()


def _short(plan, reqs) -> list[str]:
    """Resources whose driver size or alignment the plan does not give."""
    return [n for n, (size, align) in reqs.items()
            if size > plan.resource(n).bytes or plan.resource(n).offset % align]


def test_requirements_against_the_64k_default(vk_device):
    # 1920x1080: lavapipe's sizes are the texel bytes and 64 bytes of alignment would do;
    # NVIDIA rounds image sizes to 80 KiB, past the 64 KiB default: what the driver reports
    # (vkGetImageMemoryRequirements) decides whether the default plan binds
    plan = compile(_odd_graph((1920, 1080)))
    reqs = requirements(plan, vk_device)
    short = _short(plan, reqs)
    if short:
        with pytest.raises(PlanMismatchError, match=f"'{short[0]}': the driver needs "
                                                    f"{reqs[short[0]][0]} bytes"):
            plan_heaps(plan, vk_device)
    else:
        plan_heaps(plan, vk_device).destroy()
    fitted = memory_options(plan, vk_device)
    replan = compile(_odd_graph((1920, 1080)), memory=fitted)
    assert not _short(replan, reqs)
    tm = plan_heaps(replan, vk_device)
    try:
        for name, (size, align) in reqs.items():
            assert (size, align) == (tm.images[name].size, tm.images[name].alignment)
    finally:
        tm.destroy()
    if vk_device.driver_name == "llvmpipe":
        assert not short and {a for _, a in reqs.values()} == {64}
        assert fitted.image_alignment == 64 and replan.transient_bytes < plan.transient_bytes


def test_odd_sizes_need_more_than_the_texels(vk_device):
    # 1281x721: lavapipe pads rows, so even 64 KiB rounding can fall short of the driver
    plan = compile(_odd_graph((1281, 721)))
    reqs = requirements(plan, vk_device)
    short = [n for n, (size, _) in reqs.items() if size > plan.resource(n).bytes]
    if short:
        with pytest.raises(PlanMismatchError, match=f"'{short[0]}': the driver needs "
                                                    f"{reqs[short[0]][0]} bytes"):
            plan_heaps(plan, vk_device)
    if vk_device.driver_name == "llvmpipe":
        assert short == ["b.hdr"] and reqs["a.r8"][0] > plan.resource("a.r8").raw_bytes
    # compiled again with options fitted to the device, it binds
    fitted = memory_options(plan, vk_device)
    replan = compile(_odd_graph((1281, 721)), memory=fitted)
    tm = plan_heaps(replan, vk_device)
    try:
        assert tm.allocated_bytes == replan.transient_bytes
    finally:
        tm.destroy()


def test_plan_that_does_not_fit_names_resource_and_numbers(vk_device):
    g = GraphBuilder("tight", size=(1281, 721))
    g.add_pass("a", "compute").output("r8", Texture("r8unorm"))
    g.add_pass("b", "compute").input("src", "a.r8").output("x", Texture("r8unorm"))
    g.output("b.x")
    plan = compile(g.build(), memory=MemoryOptions(image_alignment=16))
    before = vk_device.live_objects()
    size, align = requirements(plan, vk_device)["a.r8"]
    if size <= plan.resource("a.r8").bytes and plan.resource("b.x").offset % align == 0:
        pytest.skip("this driver fits even a 16-byte plan")
    with pytest.raises(PlanMismatchError, match=r"'a.r8': the driver needs \d+ bytes, the plan "
                                                r"reserves \d+") as e:
        plan_heaps(plan, vk_device)
    assert "memory_options" in str(e.value)
    assert vk_device.live_objects()["Image"] == before["Image"]  # nothing left behind


def test_synthetic_graph_binds(vk_device):
    # fitted to the driver's sizes and alignments (the 64 KiB default is too small on NVIDIA)
    first = compile(synthetic_graph(40, seed=3), size=(320, 180))
    plan = compile(synthetic_graph(40, seed=3), size=(320, 180),
                   memory=memory_options(first, vk_device, readback=True))
    tm = plan_heaps(plan, vk_device, readback=True)
    try:
        assert tm.allocated_bytes == plan.transient_bytes < plan.unaliased_bytes
        assert set(tm.resources) == {r.name for r in plan.resources if r.transient}
        assert tm.buffers, "the synthetic graph should have transient buffers"
        for b in tm.buffers.values():
            assert b.address > 0  # device-address memory
        real = {n: (r.size, r.alignment) for n, r in tm.resources.items()}
        assert requirements(plan, vk_device, readback=True) == real
    finally:
        tm.destroy()


def test_absurd_heap_is_a_clear_error(vk_device):
    with pytest.raises(VkOutOfMemoryError, match="larger than memory heap"):
        DeviceMemory(vk_device, TiB, label="absurd")
    limit = vk_device.limits["maxMemoryAllocationSize"]
    heap = vk_device.memory_heaps[0][0]
    if limit < heap:
        with pytest.raises(VkOutOfMemoryError, match="maxMemoryAllocationSize"):
            DeviceMemory(vk_device, limit + 1, label="too big")
    assert vk_device.live_objects()["DeviceMemory"] == 0


# formats a device may refuse as storage images, most likely first: depth and sRGB formats
# (lavapipe refuses depth32float storage, NVIDIA accepts it but refuses sRGB storage)
_STORAGE_CANDIDATES = ("depth32float", "depth16unorm", "rgba8unorm-srgb", "bgra8unorm-srgb",
                       "rgb9e5ufloat")


def _refused_storage_format(device) -> str | None:
    """The first candidate whose optimal-tiling features lack storage on this device."""
    for name in _STORAGE_CANDIDATES:
        props = vk.vkGetPhysicalDeviceFormatProperties(device.physical_device, vk_format(name))
        if not props.optimalTilingFeatures & vk.VK_FORMAT_FEATURE_STORAGE_IMAGE_BIT:
            return name
    return None


def _must_refuse(error: type[Exception], match: str, *args, **kwargs) -> None:
    """``Image(*args)`` raises ``error``; an image made anyway is destroyed, not leaked into
    the module's device (where it would fail the leak checks of later tests)."""
    with pytest.raises(error, match=match):
        Image(*args, **kwargs).destroy()


def test_unsupported_image_is_a_clear_error(vk_device):
    before = vk_device.live_objects()
    with pytest.raises(UnsupportedFormatError, match="larger than"):
        Image(vk_device, 1 << 20, 8, "rgba8unorm", {"sampled"}, label="huge")
    if "VK_KHR_fragment_shading_rate" not in vk_device.caps:
        _must_refuse(VkMissingFeatureError, "VK_KHR_fragment_shading_rate",
                     vk_device, 8, 8, "r8uint", {"shading_rate"}, label="rate")
    refused = _refused_storage_format(vk_device)
    if refused is not None:
        _must_refuse(UnsupportedFormatError, "does not support storage",
                     vk_device, 8, 8, refused, {"storage"}, label="bad")
    assert vk_device.live_objects()["Image"] == before["Image"]
    if refused is None:
        pytest.skip(f"{vk_device.name} supports storage images of every candidate format "
                    f"({', '.join(_STORAGE_CANDIDATES)})")


def test_supported_storage_format_is_not_refused(vk_device):
    # negative control for the query above: a format the device lists with storage binds
    props = vk.vkGetPhysicalDeviceFormatProperties(vk_device.physical_device,
                                                   vk_format("rgba8unorm"))
    assert props.optimalTilingFeatures & vk.VK_FORMAT_FEATURE_STORAGE_IMAGE_BIT  # required
    Image(vk_device, 8, 8, "rgba8unorm", {"storage"}, label="fine").destroy()


def test_heap_bind_checks(vk_device):
    a = Image(vk_device, 64, 64, "rgba8unorm", {"color"}, label="a")
    b = Buffer(vk_device, 1000, {"storage"}, label="b")
    heap = Heap.for_resources(vk_device, [a, b], a.size + 4096, label="h")
    try:
        if a.alignment > 1:
            with pytest.raises(PlanMismatchError, match="alignment"):
                heap.bind(a, a.alignment // 2)
        with pytest.raises(PlanMismatchError, match="overrun"):
            heap.bind(b, _up(a.size + 4096 - 512, b.alignment))
        heap.bind(a, 0)
        heap.bind(b, _up(a.size, 4096))
        with pytest.raises(ValueError, match="already bound"):
            heap.bind(a, 0)
    finally:
        a.destroy()
        b.destroy()
        heap.destroy()


def _up(x: int, a: int) -> int:
    return -(-x // a) * a


def test_block_allocator_alignment_granularity_reuse(vk_device):
    blocks = BlockAllocator(vk_device, block_size=MiB, label="test")
    blocks.granularity = 4096  # lavapipe's is 64: exaggerate to see the rule work
    try:
        bits = (1 << len(vk_device.memory_types)) - 1  # any type: sub-allocation is the point
        a = blocks.allocate(100, 16, bits, linear=True, label="buf a")
        img = blocks.allocate(1000, 256, bits, linear=False, label="img")
        b = blocks.allocate(100, 16, bits, linear=True, label="buf b")
        assert a.offset == 0
        assert img.offset == 4096  # a buffer's page may not hold an optimal image
        assert b.offset == 112  # same kind: packs into a's page, aligned
        c = blocks.allocate(4000, 64, bits, linear=True, label="buf c")
        assert c.offset == 8192  # too big for page 0's rest; the image's page is off limits
        assert blocks.stats()["blocks"] == 1
        # reuse after free: first fit finds the hole
        img.free()
        d = blocks.allocate(900, 256, bits, linear=False, label="img again")
        assert d.offset == 4096
        # a request bigger than a block gets its own block, freed when empty
        big = blocks.allocate(3 * MiB, 4096, bits, linear=True, label="big")
        assert big.memory is not a.memory and big.memory.size >= 3 * MiB
        s = blocks.stats()
        assert s["blocks"] == 2 and s["allocations"] == 5
        big.free()
        assert blocks.stats()["blocks"] == 1
        for x in (a, b, c, d):
            x.free()
        s = blocks.stats()
        assert s["allocations"] == 0 and s["used_bytes"] == 0 and s["blocks"] == 1  # kept
    finally:
        blocks.destroy()


def test_block_allocator_resources(vk_device):
    before = vk_device.live_objects()
    blocks = BlockAllocator(vk_device, block_size=4 * MiB)
    try:
        tex = blocks.create_image(128, 128, "rgba8unorm", {"sampled", "transfer_dst"}, mips=8,
                                  label="albedo")
        mesh = blocks.create_buffer(3000, {"vertex", "storage"}, label="mesh")
        upload = blocks.create_buffer(4096, {"transfer_src"}, host_visible=True, label="up")
        if len(vk_device.memory_types) == 1:  # lavapipe: one type, so one block for all
            assert tex.memory is mesh.memory is upload.memory
        assert tex.offset % tex.alignment == 0 and mesh.offset % mesh.alignment == 0
        assert mesh.address > 0
        upload.write(np.arange(1024, dtype=np.uint32))
        assert np.array_equal(upload.read(np.uint32), np.arange(1024, dtype=np.uint32))
        view = image_view(tex, aspect="color", mips=(2, 3))
        assert view in tex.views
        mesh.destroy()
        assert blocks.stats()["allocations"] == 2
    finally:
        blocks.destroy()
    after = vk_device.live_objects()
    for kind in ("Image", "Buffer", "DeviceMemory", "ImageView"):
        assert after[kind] == before[kind], kind


def test_staging_buffer_round_trip(vk_device):
    buf = staging_buffer(vk_device, 4096, readback=True)
    try:
        data = np.linspace(0, 1, 1024, dtype=np.float32)
        buf.write(data)
        assert np.array_equal(buf.read(np.float32), data)
        buf.unmap()
        assert np.array_equal(buf.read(np.float32, (32, 32)), data.reshape(32, 32))
        with pytest.raises(ValueError, match="overruns"):
            buf.write(np.zeros(2000, np.float32))
    finally:
        buf.destroy()


def test_create_and_drop_returns_to_baseline(vk_device):
    plan = compile(chain_graph(4, 64))
    baseline = vk_device.live_objects()
    for _ in range(5):
        tm = plan_heaps(plan, vk_device)
        tm.images["p1.color"].view()
        tm.destroy()
    assert vk_device.live_objects() == baseline
