"""``rfw new-pass NAME``: a working pass folder, its shader and its test, from templates."""

from __future__ import annotations

import keyword
import re
from pathlib import Path

from .fileio import atomic_write, inside
from .graph.errors import GraphError

_COMPUTE_PY = '''"""{title}: TODO say what it computes (this docstring is the catalogue entry)."""

from rfw import ComputePass, Settings, Tex2D, register_pass


@register_pass("{name}")
class {cls}(ComputePass):
    """Scales the color of ``src`` by ``gain``: replace with your technique."""

    shader = "{name}.comp.wgsl"
    inputs = {{"src": Tex2D(desc="input color")}}
    outputs = {{"dst": Tex2D("rgba16float", size_of="src", desc="output color")}}

    class Params(Settings):
        gain: float = 1.0  # multiplies the input

    def record(self, ctx) -> None:
        ctx.dispatch(threads=ctx.extent("dst"), t_src=ctx.sampled("src"),
                     o_dst=ctx.storage("dst"), u_params=self.params)
'''

_COMPUTE_WGSL = '''struct Params {{
    gain: f32,
}};

@group(0) @binding(0) var t_src: texture_2d<f32>;
@group(0) @binding(1) var o_dst: texture_storage_2d<rgba16float, write>;
@group(0) @binding(2) var<uniform> u_params: Params;

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3u) {{
    let size = textureDimensions(o_dst);
    if (id.x >= size.x || id.y >= size.y) {{
        return;  // threads are rounded up to whole workgroups
    }}
    let c = textureLoad(t_src, vec2i(id.xy), 0);
    textureStore(o_dst, vec2i(id.xy), vec4f(c.rgb * u_params.gain, c.a));
}}
'''

_RASTER_PY = '''"""{title}: TODO say what it draws (this docstring is the catalogue entry)."""

from rfw import RenderPass, Settings, register_pass
from rfw.graph import Attachment, DepthAttachment


@register_pass("{name}")
class {cls}(RenderPass):
    """Draws the scene's base color times ``gain``: replace with your technique."""

    shader = "{name}.wgsl"
    outputs = {{
        "color": Attachment("rgba16float", desc="shaded color"),
        "depth": DepthAttachment("depth32float", desc="scene depth"),
    }}

    class Params(Settings):
        gain: float = 1.0

    def record(self, ctx) -> None:
        ctx.draw_scene(color=[("color", (0.0, 0.0, 0.0, 0.0))], depth=("depth", 1.0),
                       u_params=self.params)
'''

_RASTER_WGSL = '''#include "mesh.wgsl"

struct Params {{
    gain: f32,
}};

@group(0) @binding(0) var<uniform> u_params: Params;

struct VertexOut {{
    @builtin(position) clip: vec4f,
    @location(0) uv: vec2f,
}};

@vertex
fn vs_main(v: VertexIn) -> VertexOut {{
    var o: VertexOut;
    o.clip = camera.view_proj * (instance.model * vec4f(v.position, 1.0));
    o.uv = v.uv;
    return o;
}}

@fragment
fn fs_main(i: VertexOut) -> @location(0) vec4f {{
    let base = material.base_color * textureSample(base_color_tex, material_sampler, i.uv);
    return vec4f(base.rgb * u_params.gain, 1.0);
}}
'''

_COMPUTE_TEST = '''"""{title}: analytic test (exact expected values; avoid rounding ties)."""

import numpy as np

from {module} import {cls}
from rfw.testing import run_pass


def test_gain_scales_the_input():
    src = np.full((4, 6, 4), 0.25, np.float16)
    out = run_pass({cls}, {{"src": ("rgba16float", src)}}, settings={{"gain": 2.0}})["dst"]
    assert out.shape == (4, 6, 4)
    assert np.all(out[..., :3] == np.float16(0.5))
'''

_RASTER_TEST = '''"""{title}: renders a one-triangle scene and checks its color."""

import numpy as np

from {module} import {cls}
from rfw.scene.model import Camera, Instance, Material, Mesh, Scene
from rfw.testing import run_pass


def test_draws_the_base_color():
    tri = Mesh("tri", np.array([[-1, -1, 0], [1, -1, 0], [0, 1, 0]], np.float32),
               np.tile(np.float32([0, 0, 1]), (3, 1)), np.zeros((3, 2), np.float32),
               np.tile(np.float32([1, 0, 0, 1]), (3, 1)), np.arange(3, dtype=np.uint32))
    scene = Scene("one", [tri], [Material(base_color=(0.25, 0.5, 1.0, 1.0))],
                  instances=[Instance(0, np.identity(4, np.float32))],
                  cameras=[Camera((0, 0, 3), (0, 0, 0))])
    out = run_pass({cls}, {{}}, settings={{"gain": 2.0}}, scene=scene, size=(32, 32))["color"]
    centre = out[16, 16, :3].astype(np.float32)
    assert np.allclose(centre, [0.5, 1.0, 2.0])
    assert out[0, 0, 3] == 0  # background untouched
'''


def new_pass(name: str, folder: Path, *, kind: str = "compute",
             tests: Path | None = None) -> list[Path]:
    """Write ``folder/<name>/`` (module, shader, ``__init__``) and a test; returns the files."""
    if not re.fullmatch(r"[a-z][a-z0-9_]*", name) or keyword.iskeyword(name):
        raise GraphError(f"pass name '{name}' must be a snake_case identifier",
                         element="new-pass")
    target = inside(folder, name)  # every file below is checked to stay in its folder
    if target.exists():
        raise GraphError("already exists: not overwritten", file=str(target))
    cls = "".join(w.upper() if w in ("ssao", "fxaa", "taa") else w.capitalize()
                  for w in name.split("_")) + "Pass"
    title = name.replace("_", " ").capitalize()
    module = f"{folder.name}.{name}.{name}" if (folder / "__init__.py").exists() \
        else f"{name}.{name}"
    fields = {"name": name, "cls": cls, "title": title, "module": module}
    py, wgsl, test = ((_COMPUTE_PY, _COMPUTE_WGSL, _COMPUTE_TEST) if kind == "compute" else
                      (_RASTER_PY, _RASTER_WGSL, _RASTER_TEST))
    shader = f"{name}.comp.wgsl" if kind == "compute" else f"{name}.wgsl"
    files = {inside(target, "__init__.py"): "", inside(target, f"{name}.py"): py.format(**fields),
             inside(target, shader): wgsl.format(**fields)}
    test_path = inside(tests if tests is not None else target, f"test_{name}.py")
    if test_path.exists():
        raise GraphError("already exists: not overwritten", file=str(test_path))
    files[test_path] = test.format(**fields)
    for path, text in files.items():
        atomic_write(path, lambda f, t=text: f.write(t.encode("utf-8")))
    return list(files)
