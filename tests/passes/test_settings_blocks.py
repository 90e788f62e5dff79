"""Every settings block a shader declares matches its pass's ``Settings`` member by member
(name, offset, type), checked statically for the built-in passes and where a backend binds
the settings; the negative controls (fields swapped, renamed, retyped, a member too many)
fail naming pass, member and file, on the real run path of both backends too."""

from __future__ import annotations

import inspect
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import rfw.settings_layout as settings_layout
from rfw import registry
from rfw.passes import Settings
from rfw.settings_layout import check_bound_settings, check_settings_block
from rfw.shaders import STAGES, ShaderError
from rfw.spirv import compile_glsl, uniform_blocks

ROOT = Path(__file__).resolve().parents[2]

# the defines without which a pass's shader does not compile, one set per variant it uses
DEFINES = {"debug_view": [{"MODE": m} for m in range(4)]}


def _bound_names(cls: type) -> set[str]:
    """The binding names the pass gives its settings to in record(): ``u_params=self.params``."""
    return set(re.findall(r"(\w+)=self\.params(?![\w.])", inspect.getsource(cls)))


def _entry_files(cls: type) -> list[Path]:
    return sorted(p for p in cls.folder().glob("*.glsl") if p.name.split(".")[-2] in STAGES)


BINDING = sorted(pid for pid in registry.available() if _bound_names(registry.get_pass(pid)))


def test_the_passes_that_bind_settings_are_found():
    # the scan finds the passes it should (a regex that found none would check nothing)
    assert {"tonemap", "fxaa", "ssao", "forward", "flat", "debug_view", "deferred_lighting",
            "rt_ao", "rt_shadows"} <= set(BINDING)


@pytest.mark.parametrize("pass_id", BINDING)
def test_every_builtin_settings_block_matches_its_settings(pass_id):
    cls = registry.get_pass(pass_id)
    checked = 0
    for path in _entry_files(cls):
        for defines in DEFINES.get(pass_id, [{}]):
            blocks = uniform_blocks(compile_glsl(path, defines).code)
            for name in _bound_names(cls):
                if name in blocks:
                    check_settings_block(pass_id, cls.Params, blocks[name], path)
                    assert blocks[name], f"{path}: an empty settings block"
                    checked += 1
    assert checked, f"pass '{pass_id}' binds its settings, but no shader declares the block"


# ---------------------------------------------------------------------------------------------
# negative controls, against tonemap's real block: exposure float 0, curve int 4, sky vec3 16

TONEMAP = ROOT / "passes" / "tonemap" / "tonemap.comp.glsl"


@pytest.fixture(scope="module")
def tonemap_block():
    return uniform_blocks(compile_glsl(TONEMAP).code)["u_params"]


class Swapped(Settings):
    curve: int = 1
    exposure: float = 1.0
    sky: tuple[float, float, float] = (0.5, 0.5, 0.5)


class Renamed(Settings):
    exposure_ev: float = 1.0
    curve: int = 1
    sky: tuple[float, float, float] = (0.5, 0.5, 0.5)


class Retyped(Settings):
    exposure: int = 1
    curve: int = 1
    sky: tuple[float, float, float] = (0.5, 0.5, 0.5)


class Fewer(Settings):  # the block's sky is a member too many
    exposure: float = 1.0
    curve: int = 1
    mode: str = "aces"  # host-side: packs nothing


def test_the_real_settings_pass(tonemap_block):
    from passes.tonemap.tonemap import TonemapPass

    assert [(m.name, m.offset, m.type) for m in tonemap_block] == [
        ("exposure", 0, "float"), ("curve", 4, "int"), ("sky", 16, "vec3")]
    check_settings_block("tonemap", TonemapPass.Params, tonemap_block, TONEMAP)


@pytest.mark.parametrize(("settings", "message"), [
    (Swapped, "'exposure' of FILE is at offset 0, Swapped.pack() puts it at 4 (and 1 more "
              "problem)"),
    (Renamed, "'exposure' of FILE is no field Renamed.pack() writes (did you mean "
              "'exposure_ev'?)"),
    (Retyped, "'exposure' of FILE is declared float, Retyped.pack() writes it as int"),
    (Fewer, "'sky' of FILE is no field Fewer.pack() writes"),
])
def test_a_block_that_disagrees_fails_naming_pass_member_and_file(tonemap_block, settings,
                                                                  message):
    with pytest.raises(ShaderError) as e:
        check_settings_block("tonemap", settings, tonemap_block, TONEMAP)
    assert str(e.value) == "pass 'tonemap': settings block member " + message.replace(
        "FILE", str(TONEMAP))


def _block(tmp_path: Path, members: str) -> tuple:
    path = tmp_path / "b.comp.glsl"
    path.write_text("#version 460\nlayout(local_size_x = 1) in;\n"
                    f"layout(set = 0, binding = 0, std140) uniform Params {{ {members} }} u_p;\n"
                    "layout(set = 0, binding = 1) buffer Out { float o; };\n"
                    "void main() { o = 0.0; }\n")
    return uniform_blocks(compile_glsl(path).code)["u_p"], path


class Mixed(Settings):
    scale: float = 1.0
    label: str = "x"  # host-side: packs nothing, takes no bytes
    flip: bool = False  # a u32: GLSL uint or bool
    range: tuple[float, float] = (0.0, 1.0)  # 8-aligned: 8
    count: int = 3


def test_bools_vectors_and_left_out_fields(tmp_path):
    block, path = _block(tmp_path, "float scale; bool flip; vec2 range; int count;")
    check_settings_block("p", Mixed, block, path)
    block, path = _block(tmp_path, "float scale; uint flip; vec2 range; int count;")
    check_settings_block("p", Mixed, block, path)
    # fields left out (at the end, or in between with an explicit offset) read what they
    # would read declared: allowed
    block, path = _block(tmp_path, "float scale;")
    check_settings_block("p", Mixed, block, path)
    block, path = _block(tmp_path, "float scale; layout(offset = 16) int count;")
    check_settings_block("p", Mixed, block, path)
    block, path = _block(tmp_path, "float scale; vec2 range;")  # range is 8-aligned anyway
    check_settings_block("p", Mixed, block, path)
    # left out in between without an offset, the next member moves: refused
    block, path = _block(tmp_path, "float scale; int count;")
    with pytest.raises(ShaderError, match=r"'count' of .* is at offset 4, Mixed\.pack\(\) "
                                          "puts it at 16"):
        check_settings_block("p", Mixed, block, path)
    # padding is a member too many (std140 never needs one where pack() would not pad)
    block, path = _block(tmp_path, "float scale; float _pad0; vec2 range;")
    with pytest.raises(ShaderError, match=r"member '_pad0' .* is no field Mixed"):
        check_settings_block("p", Mixed, block, path)
    # a vector read as another vector, a matrix where a field is
    block, path = _block(tmp_path, "float scale; uint flip; ivec2 range;")
    with pytest.raises(ShaderError, match=r"'range' .* is declared ivec2, .* writes it as vec2"):
        check_settings_block("p", Mixed, block, path)
    block, path = _block(tmp_path, "mat4 scale;")
    with pytest.raises(ShaderError, match=r"'scale' .* is declared mat4, .* as float"):
        check_settings_block("p", Mixed, block, path)


def test_the_layout_is_where_pack_writes():
    m = Mixed(scale=0.25, flip=True, range=(0.5, 2.0), count=-7)
    fields = Mixed.layout()
    assert [(f.name, f.offset, f.type) for f in fields] == [
        ("scale", 0, "float"), ("flip", 4, "uint"), ("range", 8, "vec2"), ("count", 16, "int")]
    raw = m.pack()
    assert len(raw) == 32
    assert np.frombuffer(raw, "<f4", 1, 0)[0] == 0.25
    assert np.frombuffer(raw, "<u4", 1, 4)[0] == 1
    assert tuple(np.frombuffer(raw, "<f4", 2, 8)) == (0.5, 2.0)
    assert np.frombuffer(raw, "<i4", 1, 16)[0] == -7


class _Program:
    """What check_bound_settings reads of either backend's program."""

    def __init__(self, spirvs):
        self.spirvs = spirvs
        self.settings_checked = set()


def test_the_bound_check_runs_once_per_program_and_settings_type(monkeypatch):
    from passes.tonemap.tonemap import TonemapPass

    calls = []
    real = settings_layout.uniform_blocks
    monkeypatch.setattr(settings_layout, "uniform_blocks",
                        lambda code: calls.append(1) or real(code))
    prog = _Program((compile_glsl(TONEMAP),))
    for _ in range(3):
        check_bound_settings(prog, "u_params", TonemapPass.Params(exposure=2.0), "tonemap")
        check_bound_settings(prog, "u_params", b"\0" * 32, "tonemap")  # bytes: not checked
    assert len(calls) == 1
    with pytest.raises(ShaderError, match="pass 'tonemap': settings block member 'exposure'"):
        check_bound_settings(prog, "u_params", Swapped(), "tonemap")
    with pytest.raises(ShaderError):  # a failed check is no pass: it fails again
        check_bound_settings(prog, "u_params", Swapped(), "tonemap")
    assert len(calls) == 3


# ---------------------------------------------------------------------------------------------
# the real run path: a pass with its shader as text, its block right or fields swapped

PLUGIN = '''
from rfw.authoring import ComputePass, Settings, Tex2D, register_pass

GLSL = """#version 460
layout(local_size_x = 8, local_size_y = 8) in;
layout(set = 0, binding = 0, rgba8) uniform writeonly image2D o_color;
layout(set = 0, binding = 1, std140) uniform Params { MEMBERS } u_params;
void main() {
    ivec2 id = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(id, imageSize(o_color)))) {
        return;
    }
    imageStore(o_color, id, vec4(u_params.tint, u_params.alpha));
}
"""


@register_pass("settings_fill")
class SettingsFillPass(ComputePass):
    """Fills its output with the colour its settings give."""

    shader = "settings_fill.comp.glsl"
    shader_source = GLSL
    outputs = {"color": Tex2D("rgba8unorm", desc="tint and alpha everywhere")}

    class Params(Settings):
        alpha: float = 1.0
        tint: tuple[float, float, float] = (0.2, 0.4, 0.6)

    def record(self, ctx):
        ctx.dispatch(threads=ctx.extent("color"), o_color=ctx.storage("color"),
                     u_params=self.params)
'''

CONFIG = """name = "settings_fill"
size = [16, 8]
outputs = ["fill.color"]

[[pass]]
name = "fill"
use = "settings_fill"
"""

RUN = """import sys
sys.path.insert(0, sys.argv.pop(1))
__import__("settings_fill")
from rfw.cli import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.parametrize("backend", ["wgpu", "vk"])
@pytest.mark.parametrize(("members", "ok"), [("float alpha; vec3 tint;", True),
                                              ("vec3 tint; float alpha;", False)])
def test_the_run_refuses_a_block_that_disagrees(tmp_path, backend, members, ok):
    if backend == "vk":
        pytest.importorskip("vulkan")
    (tmp_path / "settings_fill.py").write_text(PLUGIN.replace("MEMBERS", members))
    (tmp_path / "fill.toml").write_text(CONFIG)
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, "-c", RUN, str(tmp_path), "run",
                           str(tmp_path / "fill.toml"), "--backend", backend, "--frames", "1",
                           "--out", str(out)], cwd=ROOT, capture_output=True, text=True,
                          timeout=300, check=False)
    if ok:
        assert done.returncode == 0, done.stdout + done.stderr
        with Image.open(out / "fill.color.png") as im:
            image = np.asarray(im.convert("RGBA"))
        assert image.shape[:2] == (8, 16)
        assert (image.reshape(-1, 4) == (51, 102, 153, 255)).all()  # tint, alpha exactly
        return
    lines = done.stderr.splitlines()
    assert done.returncode == 2 and len(lines) == 1, done.stdout + done.stderr
    assert "Traceback" not in done.stderr
    assert lines[0].startswith("rfw: error: pass 'fill': settings block member 'tint' of ")
    assert "settings_fill.comp.glsl is at offset 0, SettingsFillPass.Params.pack() puts it " \
        "at 16 (and 1 more problem)" in lines[0]
    assert not (out / "fill.color.png").exists()
