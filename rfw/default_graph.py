"""A deferred renderer's frame graph declared with the builder (a compiler example).

``tests/data/default_graph.toml`` declares the same graph in TOML; a test keeps the two identical.
"""

from __future__ import annotations

from .graph import (
    Attachment,
    DepthAttachment,
    Graph,
    GraphBuilder,
    History,
    SizeRule,
    Texture,
)


def default_graph() -> Graph:
    g = GraphBuilder("deferred", size=(1280, 720))
    g.add_pass("shadow_map", "graphics").output(
        "depth", DepthAttachment("depth32float", size=SizeRule.fixed(2048, 2048), clear=(1.0, 0.0),
                                 desc="sun shadow map"))
    (g.add_pass("gbuffer", "graphics")
     .output("albedo", Attachment("rgba8unorm-srgb", clear=(0, 0, 0, 1), desc="base color"))
     .output("normal", Attachment("rgba16float", clear=(0, 0, 0, 0), desc="world normal"))
     .output("material", Attachment("rgba8unorm", clear=(0, 0, 0, 0),
                                    desc="occlusion, roughness, metalness"))
     .output("depth", DepthAttachment("depth32float", clear=(1.0, 0.0))))
    (g.add_pass("ssao", "compute")
     .input("normal", "gbuffer.normal")
     .input("depth", "gbuffer.depth")
     .output("ao", Texture("r8unorm", size=SizeRule.output(0.5), desc="raw ambient occlusion")))
    (g.add_pass("ssao_blur", "compute")
     .input("ao", "ssao.ao")
     .output("ao", Texture("r8unorm", size=SizeRule.like("ssao.ao"), desc="blurred occlusion")))
    (g.add_pass("lighting", "compute")
     .input("albedo", "gbuffer.albedo")
     .input("normal", "gbuffer.normal")
     .input("material", "gbuffer.material")
     .input("depth", "gbuffer.depth")
     .input("shadow", "shadow_map.depth")
     .input("ao", "ssao_blur.ao")
     .output("hdr", Texture("rgba16float", desc="linear scene color")))
    (g.add_pass("sky", "graphics")
     .input("color", "lighting.hdr", Attachment())
     .input("depth", "gbuffer.depth", DepthAttachment(None, read_only=True)))
    (g.add_pass("taa", "compute")
     .input("color", "lighting.hdr")
     .input("depth", "gbuffer.depth")
     .input("history", "taa.resolved", History())
     .output("resolved", Texture("rgba16float", desc="temporally resolved color")))
    (g.add_pass("tonemap", "compute")
     .input("hdr", "taa.resolved")
     .output("ldr", Texture("rgba8unorm", desc="display color")))
    (g.add_pass("debug_normals", "compute", enabled=False)
     .input("normal", "gbuffer.normal")
     .output("view", Texture("rgba8unorm")))
    g.output("tonemap.ldr")
    return g.build()
