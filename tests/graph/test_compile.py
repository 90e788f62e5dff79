"""Compiler steps on small hand-made graphs with exact expected results."""

from __future__ import annotations

from dataclasses import replace

import pytest

from rfw.graph import (
    Attachment,
    Buffer,
    DepthAttachment,
    GraphBuilder,
    GraphError,
    History,
    MemoryOptions,
    Reference,
    SizeRule,
    Storage,
    Texture,
    compile,
)
from rfw.graph.compile import _CACHE, _MEMORY_CACHE, STATS

MIB = 1 << 20
KIB64 = 64 * 1024


def chain(*names, fmt="rgba8unorm", size=(256, 256), out=True):
    """p0 -> p1 -> ... each reading the previous one's output."""
    g = GraphBuilder("chain", size=size)
    prev = None
    for name in names:
        p = g.add_pass(name, "compute")
        if prev:
            p.input("src", f"{prev}.out")
        p.output("out", Texture(fmt))
        prev = name
    if out:
        g.output(f"{prev}.out")
    return g


# ---------------------------------------------------------------------------------------------
# order


def test_order_follows_producers_not_declaration():
    g = GraphBuilder("o", size=(64, 64))
    g.add_pass("c", "compute").input("b", "b.out").output("out", Texture("r8unorm"))
    g.add_pass("b", "compute").input("a", "a.out").output("out", Texture("r8unorm"))
    g.add_pass("a", "compute").output("out", Texture("r8unorm"))
    g.output("c.out")
    assert compile(g.build()).order == ("a", "b", "c")


def test_independent_passes_keep_declaration_order():
    g = GraphBuilder("o", size=(64, 64))
    for name in ("z", "y", "x"):
        g.add_pass(name, "compute", side_effect=True).output("out", Texture("r8unorm"))
    c = compile(g.build())
    assert c.order == ("z", "y", "x")
    assert c.parallel_levels == (("z", "y", "x"),)


def test_readers_see_in_place_writes_declared_before_them():
    def graph(modifier_first: bool):
        g = GraphBuilder("v", size=(64, 64))
        g.add_pass("make", "compute").output("img", Texture("rgba8unorm"))
        reader = lambda: g.add_pass("read", "compute").input("x", "make.img") \
            .output("out", Texture("rgba8unorm"))  # noqa: E731
        modifier = lambda: g.add_pass("blend", "compute").input(  # noqa: E731
            "x", "make.img", Storage())
        (modifier(), reader()) if modifier_first else (reader(), modifier())
        g.output("read.out", "make.img")
        return g.build()

    after = compile(graph(True))
    assert after.order == ("make", "blend", "read")
    assert ("blend", "read", "data") in after.edges
    before = compile(graph(False))
    assert before.order == ("make", "read", "blend")
    assert ("read", "blend", "order") in before.edges  # write after read


def test_cycle_is_reported_with_its_full_path():
    g = GraphBuilder("cyc", size=(64, 64))
    g.add_pass("a", "compute").input("x", "c.out").output("out", Texture("r8unorm"))
    g.add_pass("b", "compute").input("x", "a.out").output("out", Texture("r8unorm"))
    g.add_pass("c", "compute").input("x", "b.out").output("out", Texture("r8unorm"))
    with pytest.raises(GraphError, match=r"cycle between passes: a -> b -> c -> a"):
        compile(g.build())


# ---------------------------------------------------------------------------------------------
# validation errors


def test_duplicate_producer_names_both_passes():
    g = GraphBuilder("d", size=(64, 64))
    g.add_pass("a", "compute").output("x", Texture("r8unorm"), name="shared")
    g.add_pass("b", "compute").output("x", Texture("r8unorm"), name="shared")
    with pytest.raises(GraphError, match=r"pass 'b', slot 'x': resource 'shared' is already "
                                         r"produced by pass 'a'"):
        compile(g.build())


def test_unproduced_input_strict_error_lenient_warning():
    def build(strict):
        g = GraphBuilder("u", size=(64, 64), strict=strict)
        g.add_pass("a", "compute").output("color", Texture("r8unorm"))
        g.add_pass("b", "compute").input("x", "colour").output("y", Texture("r8unorm"))
        return g.build()

    with pytest.raises(GraphError, match=r"pass 'b', slot 'x': no enabled pass produces "
                                         r"'colour' and it is not external"):
        compile(build(True))
    c = compile(build(False))
    assert [d.level for d in c.diagnostics] == ["warning"]
    assert "'colour'" in c.diagnostics[0].message


def test_unknown_slot_suggests_the_close_one():
    g = GraphBuilder("s", size=(64, 64))
    g.add_pass("gbuffer", "graphics").output("normal", Attachment("rgba16float"))
    g.add_pass("light", "compute").input("n", "gbuffer.nromal").output("o", Texture("r8unorm"))
    with pytest.raises(GraphError, match=r"pass 'gbuffer' has no output slot 'nromal' "
                                         r"\(did you mean 'normal'\?\)"):
        compile(g.build())


def test_input_from_disabled_pass_says_so():
    g = GraphBuilder("s", size=(64, 64))
    g.add_pass("a", "compute", enabled=False).output("o", Texture("r8unorm"))
    g.add_pass("b", "compute").input("x", "a.o").output("o", Texture("r8unorm"))
    with pytest.raises(GraphError, match=r"'a.o' comes from pass 'a', which is disabled"):
        compile(g.build())


def test_unknown_format_and_setting_suggest_close_matches():
    g = GraphBuilder("f", size=(64, 64))
    g.add_pass("a", "compute").output("o", Texture("rgba8unrom"))
    with pytest.raises(GraphError, match=r"pass 'a', slot 'o': unknown format 'rgba8unrom' "
                                         r"\(did you mean 'rgba8unorm'"):
        compile(g.build())
    g = GraphBuilder("s", size=(64, 64))
    g.add_pass("a", "compute", settings={"exposre": 2.0}, schema=("exposure", "gamma")) \
        .output("o", Texture("r8unorm"))
    with pytest.raises(GraphError, match=r"unknown setting 'exposre' \(did you mean "
                                         r"'exposure'\?\)"):
        compile(g.build())


def test_capabilities_refuse_passes_at_compile_time():
    g = GraphBuilder("caps", size=(64, 64))
    g.add_pass("cull", "mesh").output("o", Attachment("rgba8unorm"))
    g.add_pass("rt", "compute", requires=["VK_KHR_ray_query"]).output("s", Texture("r8unorm"))
    graph = g.build()
    compile(graph)  # no device given: plans for any device
    compile(graph, caps={"VK_EXT_mesh_shader", "VK_KHR_ray_query"})
    with pytest.raises(GraphError, match=r"pass 'cull' needs VK_EXT_mesh_shader, which the "
                                         r"device lacks"):
        compile(graph, caps={"VK_KHR_ray_query"})


def test_attachments_of_one_render_pass_must_agree_in_size():
    g = GraphBuilder("fb", size=(128, 128))
    (g.add_pass("draw", "graphics").output("color", Attachment("rgba8unorm"))
     .output("depth", DepthAttachment(size=SizeRule.output(0.5))))
    with pytest.raises(GraphError, match=r"pass 'draw': attachments differ in size: "
                                         r"draw.color 128x128, draw.depth 64x64"):
        compile(g.build())


@pytest.mark.parametrize("rule", [SizeRule.fixed(0, 4), SizeRule.output(0.001),
                                  SizeRule.output(-1.0)])
def test_empty_images_are_refused(rule):
    g = GraphBuilder("z", size=(256, 256))
    g.add_pass("a", "compute").output("o", Texture("r8unorm", size=rule))
    with pytest.raises(GraphError, match=r"pass 'a', slot 'o': 'a.o' resolves to"):
        compile(g.build())


def test_size_rule_cycle_and_unknown_size_source():
    g = GraphBuilder("z", size=(64, 64))
    g.add_pass("a", "compute").output("x", Texture("r8unorm", size=SizeRule.like("a.y"))) \
        .output("y", Texture("r8unorm", size=SizeRule.like("a.x")))
    with pytest.raises(GraphError, match=r"size rules form a cycle: a.x -> a.y -> a.x"):
        compile(g.build())
    g = GraphBuilder("z", size=(64, 64))
    g.add_pass("a", "compute").output("x", Texture("r8unorm", size=SizeRule.like("a.xx")))
    with pytest.raises(GraphError, match=r"sized like 'a.xx', which is not an image"):
        compile(g.build())


def test_format_conflict_and_feedback_loop():
    g = GraphBuilder("c", size=(64, 64))
    g.add_pass("a", "compute").output("x", Texture("rgba8unorm"))
    g.add_pass("b", "compute").input("x", "a.x", Texture("rgba16float")) \
        .output("y", Texture("r8unorm"))
    with pytest.raises(GraphError, match=r"declares format rgba16float but 'a.x' is rgba8unorm"):
        compile(g.build())
    # the same format under its Vulkan name is no conflict
    g = GraphBuilder("c", size=(64, 64))
    g.add_pass("a", "compute").output("x", Texture("rgba8unorm"))
    g.add_pass("b", "compute").input("x", "a.x", Texture("VK_FORMAT_R8G8B8A8_UNORM")) \
        .output("y", Texture("r8unorm"))
    compile(g.build())
    g = GraphBuilder("f", size=(64, 64))
    g.add_pass("a", "graphics").output("x", Attachment("rgba8unorm"))
    g.add_pass("b", "graphics").input("t", "a.x").input("c", "a.x", Attachment())
    with pytest.raises(GraphError, match=r"'a.x' is used as sampled and color in the same pass"):
        compile(g.build())


def test_a_pass_cannot_read_what_it_produces():
    g = GraphBuilder("self", size=(64, 64))
    g.add_pass("a", "compute").input("x", "a.o").output("o", Texture("r8unorm"))
    with pytest.raises(GraphError, match=r"the pass reads 'a.o', which it produces itself"):
        compile(g.build())


def test_output_size_must_be_given_and_positive():
    g = GraphBuilder("nosize")
    g.add_pass("a", "compute").output("o", Texture("r8unorm"))
    with pytest.raises(GraphError, match="no output size given"):
        compile(g.build())
    with pytest.raises(GraphError, match="output size 0x5 is not positive"):
        compile(g.build(), (0, 5))


def test_several_problems_are_counted_in_one_line():
    g = GraphBuilder("many", size=(64, 64))
    g.add_pass("a", "compute").input("x", "nope1").input("y", "nope2").output("o", Texture("r8unorm"))
    with pytest.raises(GraphError) as e:
        compile(g.build())
    assert str(e.value).endswith("(and 1 more problem)")
    assert "\n" not in str(e.value)


# ---------------------------------------------------------------------------------------------
# culling, lifetimes, memory


def test_culling_keeps_what_outputs_need():
    g = chain("a", "b", "c")
    g.add_pass("unused", "compute").input("x", "a.out").output("o", Texture("r8unorm"))
    g.add_pass("readback", "transfer", side_effect=True).input("x", "a.out",
                                                              Texture(usage={"transfer_src"}))
    graph = g.build()
    c = compile(graph)
    assert c.order == ("a", "b", "c", "readback")
    assert c.culled == ("unused",)
    assert compile(graph, cull_passes=False).culled == ()


def test_lifetimes_and_aliasing_of_a_chain():
    # 256x256 rgba8 = 256 KiB each; a chain needs two alive at a time
    c = compile(chain("a", "b", "c", "d").build())
    spans = {r.name: (r.first, r.last) for r in c.resources}
    assert spans == {"a.out": ("a", "b"), "b.out": ("b", "c"), "c.out": ("c", "d"),
                     "d.out": ("d", "d")}
    size = 256 * 256 * 4
    assert all(r.bytes == size for r in c.resources)
    assert c.unaliased_bytes == 4 * size
    assert c.lower_bound_bytes == 2 * size
    assert c.transient_bytes == 2 * size
    offsets = {r.name: r.offset for r in c.resources}
    assert offsets["a.out"] == offsets["c.out"] != offsets["b.out"] == offsets["d.out"]
    # Raptor reuses a released texture of the same size and format: also two
    assert c.raptor_reuse_bytes == 2 * size


def test_raptor_reuse_needs_identical_descriptions():
    g = GraphBuilder("r", size=(256, 256))
    fmts = ["rgba8unorm", "r32float", "rgba8unorm", "r32float"]
    prev = None
    for i, fmt in enumerate(fmts):  # same byte size, alternating formats
        p = g.add_pass(f"p{i}", "compute")
        if prev:
            p.input("src", prev)
        p.output("out", Texture(fmt))
        prev = f"p{i}.out"
    g.output(prev)
    c = compile(g.build())
    size = 256 * 256 * 4
    assert c.transient_bytes == 2 * size  # byte-level aliasing does not care about format
    assert c.raptor_reuse_bytes == 2 * size  # p2 reuses p0's, p3 reuses p1's
    g2 = GraphBuilder("r2", size=(256, 256))
    g2.add_pass("a", "compute").output("out", Texture("rgba8unorm"))
    g2.add_pass("b", "compute").input("s", "a.out").output("out", Texture("r32float"))
    g2.add_pass("c", "compute").input("s", "b.out").output("out", Texture("rg16float"))
    g2.output("c.out")
    c2 = compile(g2.build())
    assert c2.transient_bytes == 2 * size
    assert c2.raptor_reuse_bytes == 3 * size  # nothing matches a freed texture exactly


def test_alignment_and_no_alias_option():
    g = GraphBuilder("a", size=(100, 100))
    g.add_pass("a", "compute").output("img", Texture("r8unorm")).output("buf", Buffer(1000))
    g.add_pass("b", "compute").input("i", "a.img").input("b", "a.buf", Buffer()) \
        .output("o", Texture("r8unorm"))
    g.output("b.o")
    c = compile(g.build())
    img, buf = c.resource("a.img"), c.resource("a.buf")
    assert (img.bytes, buf.bytes) == (KIB64, 1024)  # 10,000 texels -> 64 KiB; 1000 -> 1024 B
    assert img.heap != buf.heap  # images and buffers never share a heap
    assert [r.offset % KIB64 for r in c.resources if r.kind == "image"] == [0, 0]
    c_no = compile(g.build(), memory=MemoryOptions(alias=False))
    assert c_no.transient_bytes == c_no.unaliased_bytes == c.unaliased_bytes


def test_outputs_live_to_the_end_of_the_frame():
    g = chain("a", "b")
    g.add_pass("late", "compute", side_effect=True).output("o", Texture("rgba8unorm"))
    c = compile(g.output("a.out").build())
    assert c.resource("a.out").last == "late"  # read back after the frame: never aliased
    assert c.resource("late.o").offset != c.resource("a.out").offset


def test_history_and_external_resources_are_persistent():
    g = GraphBuilder("h", size=(64, 64))
    g.external("swapchain", Attachment("bgra8unorm"))
    g.add_pass("taa", "compute").input("prev", "taa.color", History()) \
        .output("color", Texture("rgba16float"))
    g.add_pass("present", "graphics").input("c", "taa.color") \
        .input("target", "swapchain", Attachment())
    c = compile(g.build())
    assert not c.resource("taa.color").transient and c.resource("taa.color").heap is None
    assert not c.resource("taa.color@prev").transient
    assert not c.resource("swapchain").transient
    assert c.transient_bytes == 0
    assert c.order == ("taa", "present")


# ---------------------------------------------------------------------------------------------
# barriers


def _barriers(c):
    return {(b.pass_name, b.resource): b for b in c.barriers}


def test_barriers_for_write_read_and_read_read():
    g = GraphBuilder("b", size=(64, 64))
    g.add_pass("draw", "graphics").output("color", Attachment("rgba8unorm"))
    g.add_pass("blur", "compute").input("c", "draw.color").output("o", Texture("rgba8unorm"))
    g.add_pass("blur2", "compute").input("c", "draw.color").output("o", Texture("rgba8unorm"))
    g.add_pass("comp", "graphics").input("c", "draw.color").input("a", "blur.o") \
        .input("b", "blur2.o").output("o", Attachment("rgba8unorm"))
    c = compile(g.output("comp.o").build())
    b = _barriers(c)
    first = b[("draw", "draw.color")]
    assert first.src.layout == "UNDEFINED" and first.dst.layout == "COLOR_ATTACHMENT_OPTIMAL"
    raw = b[("blur", "draw.color")]
    assert raw.src.stages == {"COLOR_ATTACHMENT_OUTPUT"}
    assert raw.src.access == {"COLOR_ATTACHMENT_WRITE"}
    assert raw.dst.layout == "SHADER_READ_ONLY_OPTIMAL" and raw.dst.stages == {"COMPUTE_SHADER"}
    assert ("blur2", "draw.color") not in b  # read after read, same layout and stages
    late = b[("comp", "draw.color")]  # new stages must see the write too
    # ... and the layout transition made for blur: ordered only before blur's stages, so the
    # barrier waits for those too (sync validation reports a read-after-write otherwise)
    assert late.src.stages == {"COLOR_ATTACHMENT_OUTPUT", "COMPUTE_SHADER"}
    assert late.dst.stages == {"VERTEX_SHADER", "FRAGMENT_SHADER"}


def test_write_after_read_waits_for_the_readers():
    g = GraphBuilder("war", size=(64, 64))
    g.add_pass("make", "compute").output("img", Texture("rgba8unorm"))
    g.add_pass("read", "graphics").input("x", "make.img").output("o", Attachment("rgba8unorm"))
    g.add_pass("blend", "compute").input("x", "make.img", Storage())
    c = compile(g.output("read.o", "make.img").build())
    war = _barriers(c)[("blend", "make.img")]
    assert war.src.layout == "SHADER_READ_ONLY_OPTIMAL" and war.dst.layout == "GENERAL"
    assert {"VERTEX_SHADER", "FRAGMENT_SHADER", "COMPUTE_SHADER"} <= war.src.stages


def test_aliasing_barrier_waits_for_the_previous_occupant():
    c = compile(chain("a", "b", "c").build())
    alias = _barriers(c)[("c", "c.out")]
    assert alias.aliased == ("a.out",)
    assert alias.src.layout == "UNDEFINED"
    assert alias.src.stages == {"COMPUTE_SHADER"}  # a.out's last read and its write
    assert "aliased" in alias.to_json()["from"]


def test_buffers_have_no_layouts_and_indirect_reads():
    g = GraphBuilder("buf", size=(64, 64))
    g.add_pass("cull", "compute").output("draws", Buffer(4096))
    g.add_pass("draw", "graphics").input("d", "cull.draws", Buffer(usage={"indirect"})) \
        .output("o", Attachment("rgba8unorm"))
    c = compile(g.output("draw.o").build())
    b = _barriers(c)
    assert ("cull", "cull.draws") not in b  # nothing before it, nothing to transition
    ind = b[("draw", "cull.draws")]
    assert ind.dst.layout is None and ind.dst.stages == {"DRAW_INDIRECT"}
    assert ind.dst.access == {"INDIRECT_COMMAND_READ"}
    assert ind.src.access == {"SHADER_STORAGE_WRITE"}


def test_history_pairs_hand_over_between_frames():
    g = GraphBuilder("h", size=(64, 64))
    g.add_pass("taa", "compute").input("prev", "taa.color", History()) \
        .output("color", Texture("rgba16float"))
    g.add_pass("show", "compute").input("c", "taa.color").output("o", Texture("rgba8unorm"))
    c = compile(g.output("show.o").build())
    b = _barriers(c)
    # last frame's color was left sampled by compute: reading it as history needs nothing
    assert ("taa", "taa.color@prev") not in b
    # this frame writes the other image of the pair, last sampled as history
    w = b[("taa", "taa.color")]
    assert w.src.layout == "SHADER_READ_ONLY_OPTIMAL" and w.dst.layout == "GENERAL"
    assert w.src.stages == {"COMPUTE_SHADER"}


def test_depth_read_only_and_sampling_share_a_layout():
    g = GraphBuilder("d", size=(64, 64))
    g.add_pass("z", "graphics").output("depth", DepthAttachment())
    g.add_pass("decal", "graphics").input("zt", "z.depth", DepthAttachment(None, read_only=True)) \
        .input("zs", "z.depth").output("o", Attachment("rgba8unorm"))
    c = compile(g.output("decal.o").build())
    acc = {a.resource: a for a in c.accesses["decal"]}["z.depth"]
    assert acc.state.layout == "DEPTH_READ_ONLY_OPTIMAL" and acc.role == "read"


def test_reference_input_orders_without_touching_memory():
    g = GraphBuilder("ref", size=(64, 64))
    g.add_pass("a", "compute").output("o", Texture("r8unorm"))
    g.add_pass("b", "compute").input("after", "a.o", Reference()).output("o", Texture("r8unorm"))
    c = compile(g.output("b.o", "a.o").build())
    assert c.order == ("a", "b")
    assert ("a", "b", "order") in c.edges
    assert ("b", "a.o") not in _barriers(c)
    assert c.resource("a.o").last == "b"  # a graph output lives to the end, not via the ref


# ---------------------------------------------------------------------------------------------
# parallel levels and incremental recompiles


def test_parallel_levels_of_a_diamond():
    g = GraphBuilder("dia", size=(64, 64))
    g.add_pass("top", "compute").output("o", Texture("r8unorm"))
    g.add_pass("left", "compute").input("x", "top.o").output("o", Texture("r8unorm"))
    g.add_pass("right", "compute").input("x", "top.o").output("o", Texture("r8unorm"))
    g.add_pass("bottom", "compute").input("l", "left.o").input("r", "right.o") \
        .output("o", Texture("r8unorm"))
    c = compile(g.output("bottom.o").build())
    assert c.parallel_levels == (("top",), ("left", "right"), ("bottom",))


def test_recompiling_is_incremental():
    _CACHE.clear()
    _MEMORY_CACHE.clear()
    g = chain("a", "b", "c")
    g.add_pass("extra", "compute").input("x", "a.out").output("o", Texture("r8unorm"))
    graph = g.build()
    before = dict(STATS)
    first = compile(graph)
    assert compile(graph) is first  # unchanged graph: a lookup
    assert STATS["compile"] == before.get("compile", 0) + 1
    # switching off a pass that was culled anyway changes nothing downstream of validation
    off = compile(graph.with_enabled("extra", False))
    assert off.order == first.order and off.resources == first.resources
    assert STATS["assign_memory"] == before.get("assign_memory", 0) + 1
    # a technique variant with the same slots but another pass type reuses the memory plan
    variant = graph.with_pass(replace(graph.pass_("b"), type="ray_tracing"))
    v = compile(variant)
    assert v.resources == first.resources
    assert STATS["assign_memory"] == before.get("assign_memory", 0) + 1
    assert _barriers(v)[("b", "a.out")].dst.stages == {"RAY_TRACING_SHADER_KHR"}


def test_a_history_reader_keeps_the_producer_alive():
    # the previous frame's value exists only if its producer runs every frame
    g = GraphBuilder("h", size=(64, 64))
    g.add_pass("P", "compute").output("r", Texture("rgba8unorm"))
    g.add_pass("H", "compute").input("prev", "P.r", History()).output("o", Texture("rgba8unorm"))
    c = compile(g.output("H.o").build())
    assert c.order == ("P", "H") or c.order == ("H", "P")
    assert c.culled == ()
    assert not c.resource("P.r").transient
    # a culled history reader makes no pair: P.r is an ordinary transient again
    g2 = GraphBuilder("h2", size=(64, 64))
    g2.add_pass("P", "compute").output("r", Texture("rgba8unorm"))
    g2.add_pass("K", "compute").input("r", "P.r").output("o", Texture("rgba8unorm"))
    g2.add_pass("C", "compute").input("prev", "P.r", History()).output("x", Texture("r8unorm"))
    c2 = compile(g2.output("K.o").build())
    assert c2.culled == ("C",) and c2.resource("P.r").transient


def test_reads_after_an_in_place_write_get_a_barrier():
    g = GraphBuilder("a", size=(64, 64))
    g.add_pass("make", "compute").output("buf", Buffer(4096))
    g.add_pass("bump", "compute").output("buf", Reference(), target="make.buf")
    g.add_pass("use", "compute").input("buf", "make.buf", Buffer()).output("out", Buffer(256))
    c = compile(g.output("use.out").build())
    use = _barriers(c)[("use", "make.buf")]
    assert use.src.access == {"SHADER_STORAGE_WRITE"} and use.src.stages == {"COMPUTE_SHADER"}


def test_device_sizes_replace_the_texel_estimate():
    # a driver that pads an odd-sized image: the plan holds what it will really bind
    g = chain("a", "b", size=(1281, 721), fmt="rgba16float")
    plain = compile(g.build())
    padded = compile(g.build(), memory=MemoryOptions(image_alignment=64,
                                                     sizes=(("a.out", 7_460_096),)))
    assert plain.resource("a.out").raw_bytes == 1281 * 721 * 8
    assert padded.resource("a.out").bytes == 7_460_096
    texels = 1281 * 721 * 8  # 7,388,808, rounded up to 64-byte alignment below
    assert padded.resource("b.out").bytes == -(-texels // 64) * 64 == 7_388_864
    assert padded.transient_bytes == 7_460_096 + 7_388_864
