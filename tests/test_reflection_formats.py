"""A storage image's declared format must be the bound resource's, on both backends.

A tiny third-party pass (found through the ``rfw.passes`` entry points of a dist-info written
into a temporary folder) declares its storage output ``rgba8`` in GLSL (one source for both
backends) or, wgpu only, in WGSL; the config gives the slot another format. Run through the
real CLI: the mismatch is one error line naming pass, binding, shader file and both formats;
the matching format renders; vk refuses the WGSL pass in one line naming pass and file.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from .cli.warm import warm_cli

ROOT = Path(__file__).resolve().parents[1]

PASS = '''"""Fill: a constant colour into a storage image."""

from rfw import ComputePass, Tex2D, register_pass


@register_pass("fmt_fill")
class FillPass(ComputePass):
    """Writes (0.2, 0.4, 0.6, 1.0) everywhere."""

    shader = "{shader}"
    outputs = {{"dst": Tex2D("{fmt}", desc="filled image")}}

    def record(self, ctx) -> None:
        ctx.dispatch(threads=ctx.extent("dst"), o_dst=ctx.storage("dst"))
'''

WGSL = """@group(0) @binding(0) var o_dst: texture_storage_2d<rgba8unorm, write>;

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3u) {
    let size = textureDimensions(o_dst);
    if (id.x >= size.x || id.y >= size.y) {
        return;
    }
    textureStore(o_dst, vec2i(id.xy), vec4f(0.2, 0.4, 0.6, 1.0));
}
"""

GLSL = """#version 460
layout(local_size_x = 8, local_size_y = 8) in;
layout(set = 0, binding = 0, rgba8) uniform writeonly image2D o_dst;

void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(p, imageSize(o_dst)))) {
        return;
    }
    imageStore(o_dst, p, vec4(0.2, 0.4, 0.6, 1.0));
}
"""

CONFIG = """name = "fmt"
size = [16, 8]
outputs = ["fill.dst"]

[[pass]]
name = "fill"
use = "fmt_fill"
"""


def plugin(tmp: Path, fmt: str, shader: str) -> Path:
    """A site folder holding the pass package and its entry point."""
    site = tmp / "site"
    pkg = site / "rfw_fmt_demo"
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "fmt_fill.py").write_text(PASS.format(fmt=fmt, shader=shader))
    (pkg / "fmt_fill.comp.wgsl").write_text(WGSL)
    (pkg / "fmt_fill.comp.glsl").write_text(GLSL)
    info = site / "rfw_fmt_demo-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: rfw-fmt-demo\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[rfw.passes]\nfmt_fill = rfw_fmt_demo.fmt_fill\n")
    return site


def run(tmp: Path, fmt: str, backend: str,
        shader: str = "fmt_fill.comp.glsl") -> subprocess.CompletedProcess:
    site = plugin(tmp, fmt, shader)
    config = tmp / "fmt.toml"
    config.write_text(CONFIG)
    # extended, not replaced: on the GPU machine rfw's dependencies come through PYTHONPATH
    path = [str(site), str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]
    env = {"PYTHONPATH": os.pathsep.join(path), "RFW_CACHE_SPIRV": str(tmp / "spirv")}
    return warm_cli("run", config, "--backend", backend, "--frames", "1", "--out", tmp / "out",
                    env=env, cwd=tmp)


CASES = [("wgpu", "fmt_fill.comp.glsl"), ("vk", "fmt_fill.comp.glsl"),
         ("wgpu", "fmt_fill.comp.wgsl")]


@pytest.mark.parametrize(("backend", "shader"), CASES)
def test_mismatched_storage_format_is_one_line(tmp_path, backend, shader):
    done = run(tmp_path, "rgba16float", backend, shader)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("rfw: error: "), done.stderr
    line = lines[0]
    for part in ("pass 'fill'", "'o_dst'", shader, "rgba8unorm", "rgba16float"):
        assert part in line, line
    assert not (tmp_path / "out" / "timings.json").exists()


@pytest.mark.parametrize(("backend", "shader"), CASES)
def test_matching_storage_format_renders(tmp_path, backend, shader):
    # negative control: the same pass with the declared format runs and writes its colour
    done = run(tmp_path, "rgba8unorm", backend, shader)
    assert done.returncode == 0, done.stderr
    img = np.asarray(Image.open(tmp_path / "out" / "fill.dst.png").convert("RGBA"))
    assert img.shape == (8, 16, 4)
    expected = np.round(np.array([0.2, 0.4, 0.6, 1.0]) * 255)
    assert np.abs(img.reshape(-1, 4) - expected).max() <= 1


def test_vk_refuses_a_wgsl_pass_in_one_line(tmp_path):
    done = run(tmp_path, "rgba8unorm", "vk", "fmt_fill.comp.wgsl")
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1, done.stderr
    assert lines[0].startswith("rfw: error: pass 'fill' (fmt_fill): ")
    assert "fmt_fill.comp.wgsl is WGSL, which only --backend wgpu runs" in lines[0]
