"""``rfw new-pass NAME``: a working pass folder, its GLSL shader and its test, from templates;
``--package DIR`` makes it an installable distribution (the ``rfw.passes`` entry point, the
shaders as package data, the test beside it)."""

from __future__ import annotations

import keyword
import re
from pathlib import Path

from .fileio import atomic_write, inside
from .graph.errors import GraphError

_COMPUTE_PY = '''"""{title}: TODO say what it computes (this docstring is the catalogue entry)."""

from typing import Annotated

from rfw.authoring import ComputePass, Range, Settings, Tex2D, register_pass, storage_format


@register_pass("{name}")
class {cls}(ComputePass):
    """Scales the color of ``src`` by ``gain``: replace with your technique."""

    # its commands depend on nothing but its settings, slot resources and scene: recorded
    # once, then replayed where the backend can (say False if they depend on more)
    replay = "auto"
    shader = "{name}.comp.glsl"  # resolved next to this file
    inputs = {{"src": Tex2D(desc="input color")}}
    # the input's size and format (sRGB: its linear twin, as storage images cannot be sRGB)
    outputs = {{"dst": Tex2D(format_of="src", size_of="src", desc="output color")}}

    class Params(Settings):
        gain: Annotated[float, Range(0.0, 16.0)] = 1.0  # multiplies the input

    def record(self, ctx) -> None:
        # the shader's storage format is dst's: a define, so one file serves every format
        ctx.dispatch(threads=ctx.extent("dst"), t_src=ctx.sampled("src"),
                     o_dst=ctx.storage("dst"), u_params=self.params,
                     defines={{"DST_FORMAT": storage_format(ctx.format("dst"))}})
'''

_COMPUTE_GLSL = '''#version 460
// {title}: the color of t_src times u_params.gain (replace with your technique); the same
// SPIR-V runs on --backend wgpu and --backend vk, bindings matched by name
#extension GL_EXT_samplerless_texture_functions : require  // texelFetch on texture2D

#ifndef DST_FORMAT  // the pass defines dst's format (its input's)
#define DST_FORMAT rgba16f
#endif

layout(local_size_x = 8, local_size_y = 8) in;

layout(set = 0, binding = 0) uniform texture2D t_src;
layout(set = 0, binding = 1, DST_FORMAT) uniform writeonly image2D o_dst;
layout(set = 0, binding = 2, std140) uniform Params {{
    float gain;
}} u_params;  // Settings.pack() writes the std140 layout

void main() {{
    ivec2 id = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(id, imageSize(o_dst)))) {{
        return;  // threads are rounded up to whole workgroups
    }}
    vec4 c = texelFetch(t_src, id, 0);
    imageStore(o_dst, id, vec4(c.rgb * u_params.gain, c.a));
}}
'''

_RASTER_PY = '''"""{title}: TODO say what it draws (this docstring is the catalogue entry)."""

from rfw.authoring import Attachment, DepthAttachment, RenderPass, Settings, register_pass


@register_pass("{name}")
class {cls}(RenderPass):
    """Draws the scene's base color times ``gain``: replace with your technique."""

    replay = "auto"  # recorded once, then replayed while settings, slots and scene hold
    shader = "{name}"  # {name}.vert.glsl + {name}.frag.glsl, next to this file
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

_RASTER_VERT = '''#version 460
// {title}: the scene's transform (clip space is WebGPU's on both backends: scene.glsl)
#define MESH_VERTEX_INPUT
#include "mesh.glsl"

layout(location = 0) out vec2 o_uv;

void main() {{
    gl_Position = camera.view_proj * (instance.model * vec4(v_position, 1.0));
    o_uv = v_uv;
}}
'''

_RASTER_FRAG = '''#version 460
// {title}: the material's base color times u_params.gain
#include "mesh.glsl"

layout(set = 0, binding = 0, std140) uniform Params {{
    float gain;
}} u_params;

layout(location = 0) in vec2 i_uv;
layout(location = 0) out vec4 o_color;

void main() {{
    vec4 base = material.base_color *
        texture(sampler2D(base_color_tex, material_sampler), i_uv);
    o_color = vec4(base.rgb * u_params.gain, 1.0);
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


_PYPROJECT = '''[build-system]
requires = ["setuptools>=61"]
build-backend = "setuptools.build_meta"

[project]
name = "{dist}"
version = "0.1.0"
description = "{title}: an rfw pass"
requires-python = ">=3.11"
# rfw itself is not listed: install this into the environment that has rfw

[project.entry-points."rfw.passes"]
# rfw imports this module to find the pass; @register_pass("{name}") does the rest
{name} = "{package}.{name}"

[tool.setuptools]
packages = ["{package}"]

[tool.setuptools.package-data]
# the shaders are found next to the module, so they must be installed with it
{package} = ["*.glsl", "*.wgsl"]

[tool.pytest.ini_options]
testpaths = ["tests"]
'''

_README = '''# {dist}

{title}: an rfw pass, `use = "{name}"` in a config.

    pip install --no-build-isolation .   # into the environment that has rfw
    rfw passes {name}                    # its slots and settings
    python -m pytest tests               # its test
'''


def _check_name(name: str) -> None:
    if not re.fullmatch(r"[a-z][a-z0-9_]*", name) or keyword.iskeyword(name):
        raise GraphError(f"pass name '{name}' must be a snake_case identifier",
                         element="new-pass")


def _check_free(name: str) -> None:
    # a second class under a registered id breaks every later rfw command ("registered twice")
    from .registry import available

    if name in available():
        raise GraphError(f"pass id '{name}' is already registered (built-in or installed): "
                         "choose another name", element="new-pass")


def _title(name: str) -> str:
    return name.replace("_", " ").capitalize()


def new_package(name: str, root: Path, *, kind: str = "compute") -> list[Path]:
    """Write an installable distribution in ``root``: ``pyproject.toml`` (entry point
    ``rfw.passes``, shaders as package data), ``rfw_<name>/`` with the pass, ``tests/`` with
    its test and a README; returns the files. ``root`` must not exist or be empty (checked
    first; new_pass checks the name before it writes anything)."""
    if root.exists() and (not root.is_dir() or any(root.iterdir())):
        raise GraphError("already exists and is not an empty folder: not overwritten",
                         file=str(root), element="--package")
    package = f"rfw_{name}"
    fields = {"name": name, "package": package, "dist": f"rfw-{name.replace('_', '-')}",
              "title": _title(name)}
    files = new_pass(name, root, kind=kind, tests=root / "tests", package=package)
    extra = {inside(root, "pyproject.toml"): _PYPROJECT.format(**fields),
             inside(root, "README.md"): _README.format(**fields)}
    for path, text in extra.items():
        atomic_write(path, lambda f, t=text: f.write(t.encode("utf-8")))
    return [*extra, *files]


def new_pass(name: str, folder: Path, *, kind: str = "compute",
             tests: Path | None = None, package: str | None = None) -> list[Path]:
    """Write ``folder/<name>/`` (module, shader, ``__init__``) and a test; returns the files.
    ``package`` names the folder (an import package) instead of ``<name>``."""
    _check_name(name)
    _check_free(name)
    target = inside(folder, package or name)  # every file below is checked to stay in it
    if target.exists():
        raise GraphError("already exists: not overwritten", file=str(target))
    cls = "".join(w.upper() if w in ("ssao", "fxaa", "taa") else w.capitalize()
                  for w in name.split("_")) + "Pass"
    title = _title(name)
    if package is not None:
        module = f"{package}.{name}"
    else:
        module = f"{folder.name}.{name}.{name}" if (folder / "__init__.py").exists() \
            else f"{name}.{name}"
    fields = {"name": name, "cls": cls, "title": title, "module": module}
    py, test = (_COMPUTE_PY, _COMPUTE_TEST) if kind == "compute" else (_RASTER_PY, _RASTER_TEST)
    shaders = {f"{name}.comp.glsl": _COMPUTE_GLSL} if kind == "compute" else \
        {f"{name}.vert.glsl": _RASTER_VERT, f"{name}.frag.glsl": _RASTER_FRAG}
    files = {inside(target, "__init__.py"): "", inside(target, f"{name}.py"): py.format(**fields),
             **{inside(target, f): text.format(**fields) for f, text in shaders.items()}}
    test_path = inside(tests if tests is not None else target, f"test_{name}.py")
    if test_path.exists():
        raise GraphError("already exists: not overwritten", file=str(test_path))
    files[test_path] = test.format(**fields)
    for path, text in files.items():
        atomic_write(path, lambda f, t=text: f.write(t.encode("utf-8")))
    return list(files)
