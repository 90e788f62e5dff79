"""The wgpu executor end to end on small images: forward against deferred, timings, errors."""

import json

import numpy as np
import pytest

from rfw import ComputePass, Tex2D, get_pass
from rfw.config import apply_overrides, build, load_config
from rfw.graph import compile
from rfw.render import render, write_outputs
from rfw.shaders import ShaderError
from rfw.testing import run_pass

from ..conftest import ROOT

SIZE = ["size=160x90"]


def cfg(name, *sets):
    return apply_overrides(load_config(ROOT / "configs" / f"{name}.toml"), [*SIZE, *sets])


def test_forward_and_deferred_agree(device, scene):
    # the same BRDF, lights and shadow lookup: differences come only from interpolation order
    fwd = render(cfg("forward", "shadow.enabled=true"), scene=scene, device=device)
    dfr = render(cfg("deferred", "shadow.enabled=true"), scene=scene, device=device)
    a = fwd.images["tonemap.ldr"][..., :3].astype(int)
    b = dfr.images["tonemap.ldr"][..., :3].astype(int)
    diff = np.abs(a - b)
    assert diff.max() <= 3  # 8-bit levels
    assert (diff > 1).mean() < 0.001  # fewer than 0.1% of pixels differ by more than one level
    assert a.std() > 10  # not a flat image: the cube, its shadow and the sky are there


def test_shadows_darken_the_floor_behind_the_cube(device, scene):
    lit = render(cfg("deferred"), scene=scene, device=device).images["tonemap.ldr"]
    shadowed = render(cfg("deferred", "shadow.enabled=true"), scene=scene,
                      device=device).images["tonemap.ldr"]
    darker = lit[..., :3].astype(int).sum(-1) - shadowed[..., :3].astype(int).sum(-1)
    assert (darker > 30).sum() > 50  # a shadow of at least 50 pixels appears
    assert (darker < -3).sum() == 0  # and nothing gets brighter


def test_timings_and_files(device, scene, tmp_path):
    r = render(cfg("deferred", "shadow.enabled=true"), scene=scene, device=device, frames=3)
    t = r.timings
    assert [p["name"] for p in t["passes"]] == ["shadow", "gbuffer", "lighting", "tonemap"]
    assert t["size"] == [160, 90] and t["frames"] == 3 and t["backend"] == "wgpu"
    assert t["device"] and "driver" in t
    if t["timestamps"]:
        assert all(p["gpu_ms"] > 0 for p in t["passes"])
        assert t["gpu_ms_total"] == pytest.approx(sum(p["gpu_ms"] for p in t["passes"]))
    formats = {x.name: x.format for x in r.frame.plan.resources}
    written = write_outputs(r, tmp_path, formats)
    assert sorted(p.name for p in written) == ["timings.json", "tonemap.ldr.png"]
    assert json.loads((tmp_path / "timings.json").read_text())["passes"] == t["passes"]
    from PIL import Image

    png = np.asarray(Image.open(tmp_path / "tonemap.ldr.png"))
    assert png.shape == (90, 160, 4)
    assert np.array_equal(png[..., :3], r.images["tonemap.ldr"][..., :3])


def test_identical_transients_share_textures(device, scene):
    # the deferred graph with shadows: no two transients match, so none share
    built = build(cfg("deferred", "shadow.enabled=true"))
    plan = compile(built.graph)
    from rfw.backends.wgpu.resources import share_textures

    names = list(plan.order)
    spans = {r.name: (names.index(r.first), names.index(r.last)) for r in plan.resources}
    owners = share_textures(list(plan.resources), set(plan.outputs), spans)
    assert all(owners[k] == k for k in owners)


def test_tonemap_is_exact_on_analytic_input(device):
    hdr = np.zeros((4, 8, 4), np.float16)
    hdr[..., 0], hdr[..., 1], hdr[..., 2], hdr[..., 3] = 0.499, 0.0031, 2.0, 1.0
    out = run_pass(get_pass("tonemap"), {"hdr": ("rgba16float", hdr)},
                   settings={"curve": 0}, device=device)["ldr"]
    # sRGB encode: 1.055 * 0.499^(1/2.4) - 0.055 = 0.7348 -> 187; 12.92 * 0.0031 -> 10
    assert out.shape == (4, 8, 4)
    assert np.all(out[..., 0] == 187) and np.all(out[..., 1] == 10) and np.all(out[..., 2] == 255)
    empty = np.zeros((2, 2, 4), np.float16)  # alpha 0: background takes the sky color
    sky = run_pass(get_pass("tonemap"), {"hdr": ("rgba16float", empty)},
                   settings={"curve": 0, "sky": (0.499, 0.0, 1.0)}, device=device)["ldr"]
    assert tuple(sky[0, 0]) == (187, 0, 255, 255)


class _Mismatch(ComputePass):
    """A pass whose record() names a binding its shader does not declare."""

    shader = "tonemap.comp.glsl"
    inputs = {"hdr": Tex2D()}
    outputs = {"ldr": Tex2D("rgba8unorm", size_of="hdr")}

    def record(self, ctx):
        ctx.dispatch(threads=ctx.extent("ldr"), t_hdr=ctx.sampled("hdr"),
                     o_ldr=ctx.storage("ldr"), u_params=self.params, t_extra=ctx.sampled("hdr"))

    @classmethod
    def folder(cls):
        return ROOT / "passes" / "tonemap"


def test_binding_mismatch_names_pass_binding_and_file(device):
    hdr = np.ones((2, 2, 4), np.float16)
    with pytest.raises(ShaderError, match=r"pass '_Mismatch': \S*tonemap.comp.glsl has no "
                                          r"binding named t_extra"):
        run_pass(_Mismatch, {"hdr": ("rgba16float", hdr)}, device=device)


class _Count(ComputePass):
    """Writes, per pixel, 1 into a storage buffer of counters; tests buffer slots."""

    shader = "count.comp.wgsl"
    inputs = {"src": Tex2D()}

    def declare(self):
        from rfw.graph import Buffer

        return dict(self.inputs), {"counts": Buffer(4 * 64, usage={"storage"},
                                                    desc="one u32 per pixel")}

    def record(self, ctx):
        ctx.dispatch(threads=ctx.extent("src"), t_src=ctx.sampled("src"),
                     counts=ctx.buffer("counts"))


def test_buffer_slots_are_allocated_with_their_usages(device, tmp_path, monkeypatch):
    (tmp_path / "count.comp.wgsl").write_text("""
@group(0) @binding(0) var t_src: texture_2d<f32>;
@group(0) @binding(1) var<storage, read_write> counts: array<u32>;

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3u) {
    let size = textureDimensions(t_src);
    if (id.x >= size.x || id.y >= size.y) { return; }
    counts[id.y * size.x + id.x] = u32(textureLoad(t_src, vec2i(id.xy), 0).r * 255.0 + 0.5);
}
""")
    monkeypatch.setattr(_Count, "folder", classmethod(lambda cls: tmp_path))
    img = np.arange(64, dtype=np.uint8).reshape(8, 8, 1).repeat(4, axis=2)
    from rfw.backends.wgpu import Executor
    from rfw.graph import GraphBuilder, Texture
    from rfw.graph.resources import SizeRule

    g = GraphBuilder("b", size=(8, 8))
    g.external("img", Texture("rgba8unorm", size=SizeRule.fixed(8, 8)))
    inst = _Count("count")
    b = g.add_pass("count", "compute")
    b.input("src", "img")
    b.output("counts", inst.declare()[1]["counts"])
    plan = compile(g.output("count.counts").build())
    ex = Executor(device, plan, {"count": inst}, {"count": {"src": "img",
                                                            "counts": "count.counts"}})
    try:
        ex.upload("img", img)
        ex.run(1)
        data = np.frombuffer(device.device.queue.read_buffer(ex.buffer("count.counts")),
                             np.uint32)
        assert np.array_equal(data, np.arange(64))
    finally:
        ex.destroy()
