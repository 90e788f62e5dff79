"""Cross-API graphs: bridges where a resource crosses from one backend to another."""

import pytest

from rfw.graph import Attachment, Buffer, GraphBuilder, GraphError, Storage, Texture, compile
from rfw.graph.bridges import insert_bridges


def mixed(gbuffer_backend="vk"):
    g = GraphBuilder("mixed", size=(64, 48))
    g.add_pass("gbuffer", "graphics", backend=gbuffer_backend) \
        .output("albedo", Attachment("rgba8unorm")).output("ids", Buffer(1024))
    g.add_pass("light", "compute").input("a", "gbuffer.albedo") \
        .input("i", "gbuffer.ids", Buffer()).output("hdr", Texture("rgba16float"))
    g.add_pass("blur", "compute").input("a", "gbuffer.albedo").output("o", Texture("r32float"))
    g.add_pass("tone", "compute").input("h", "light.hdr").input("b", "blur.o") \
        .output("ldr", Texture("rgba8unorm"))
    return g.output("tone.ldr").build()


def test_a_bridge_per_resource_and_backend_pair():
    c = compile(mixed(), backend="wgpu")
    assert c.order == ("gbuffer", "bridge.gbuffer.albedo.vk-wgpu",
                       "bridge.gbuffer.ids.vk-wgpu", "light", "blur", "tone")
    copy = c.resource("gbuffer.albedo@wgpu")
    assert (copy.format, copy.width, copy.height) == ("rgba8unorm", 64, 48)
    assert c.resource("gbuffer.ids@wgpu").raw_bytes == 1024
    # both readers share one copy; the original is read only by the bridge
    assert {a.resource for a in c.accesses["light"]} >= {"gbuffer.albedo@wgpu",
                                                         "gbuffer.ids@wgpu"}
    assert c.resource("gbuffer.albedo").last == "bridge.gbuffer.albedo.vk-wgpu"
    b = {(x.pass_name, x.resource): x for x in c.barriers}
    src = b[("bridge.gbuffer.albedo.vk-wgpu", "gbuffer.albedo")]
    assert src.dst.layout == "TRANSFER_SRC_OPTIMAL" and src.dst.stages == {"COPY"}
    dst = b[("light", "gbuffer.albedo@wgpu")]
    assert dst.src.access == {"TRANSFER_WRITE"} and dst.dst.layout == "SHADER_READ_ONLY_OPTIMAL"


def test_one_backend_needs_no_bridge():
    graph = mixed(None)
    assert insert_bridges(graph, "vk") is graph  # nothing pinned: nothing to bridge
    assert not any(n.startswith("bridge.") for n in compile(mixed("vk"), backend="vk").order)
    assert not any(n.startswith("bridge.") for n in compile(mixed(None), backend="vk").order)
    assert not any(n.startswith("bridge.") for n in compile(mixed(None)).order)


def test_in_place_writes_across_backends_are_refused():
    g = GraphBuilder("bad", size=(8, 8))
    g.add_pass("a", "compute", backend="vk").output("img", Texture("rgba8unorm"))
    g.add_pass("b", "compute").input("x", "a.img", Storage()).output("o", Texture("r8unorm"))
    with pytest.raises(GraphError, match=r"pass 'b' \(wgpu\) writes 'a.img' in place, but pass "
                                         r"'a' made it on vk"):
        compile(g.output("b.o").build(), backend="wgpu")
