"""GLSL to SPIR-V with glslang: cache, includes, defines, errors with file and line, and
layouts reflected from the binary (never hand-written)."""

import shutil
from pathlib import Path

import pytest

from rfw.spirv import ShaderCompileError, compile_glsl, reflect

from ..cli.warm import warm_cli

ROOT = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.skipif(shutil.which("glslangValidator") is None,
                                reason="needs glslangValidator (scripts/setup-system.sh)")


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    """A SPIR-V cache of the test's own: shaders compile afresh, nothing shared is touched."""
    monkeypatch.setenv("RFW_CACHE_SPIRV", str(tmp_path / "cache"))


def write(folder, name, text):
    p = folder / name
    p.write_text(text)
    return p


COMPUTE = """#version 460
#include "helpers.glsl"
layout(local_size_x = 8, local_size_y = 4) in;
layout(set = 0, binding = 0) uniform sampler2D t_src;
layout(set = 0, binding = 1, rgba16f) uniform writeonly image2D o_dst;
layout(set = 0, binding = 2) uniform Params { float gain; int mode; vec3 tint; } u_params;
layout(set = 1, binding = 0) readonly buffer Counts { uint counts[]; };
layout(set = 1, binding = 3) uniform texture2D t_many[4];
layout(set = 1, binding = 4) uniform sampler s_linear;
layout(push_constant) uniform Push { mat4 m; uint frame; } pc;
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    vec4 c = texelFetch(t_src, p, 0) * twice(u_params.gain) * float(counts[0] + pc.frame);
    c += texture(sampler2D(t_many[1], s_linear), vec2(0.5)) * SCALE;
    imageStore(o_dst, p, c + pc.m[0] * u_params.tint.x);
}
"""


def test_compile_reflect_and_cache(tmp_path):
    write(tmp_path, "helpers.glsl", "float twice(float x) { return 2.0 * x; }\n")
    src = write(tmp_path, "blit.comp.glsl", COMPUTE)
    a = compile_glsl(src, {"SCALE": "1.0"})
    r = reflect(a.code)
    assert (r.stage, r.entry, r.local_size) == ("comp", "main", (8, 4, 1))
    assert r.push_constant_size == 68  # mat4 (64) + uint
    kinds = {d.name: (d.set, d.binding, d.kind, d.count) for d in r.descriptors.values()}
    assert kinds["t_src"] == (0, 0, "combined_image_sampler", 1)
    assert kinds["o_dst"] == (0, 1, "storage_image", 1)
    assert kinds["u_params"] == (0, 2, "uniform_buffer", 1)
    assert kinds["t_many"] == (1, 3, "sampled_image", 4)
    assert kinds["s_linear"] == (1, 4, "sampler", 1)
    counts = next(d for d in r.descriptors.values() if d.set == 1 and d.binding == 0)
    assert counts.kind == "storage_buffer"
    assert [d.binding for d in r.sets()[1]] == [0, 3, 4]
    # the cache answers an unchanged compile; an edited include or another define recompiles
    assert compile_glsl(src, {"SCALE": "1.0"}).key == a.key
    assert compile_glsl(src, {"SCALE": "2.0"}).key != a.key
    write(tmp_path, "helpers.glsl", "float twice(float x) { return x + x; }\n")
    assert compile_glsl(src, {"SCALE": "1.0"}).key != a.key


def test_errors_name_file_and_line(tmp_path):
    write(tmp_path, "helpers.glsl", "float twice(float x) { return 2.0 * x; }\n")
    bad = write(tmp_path, "bad.comp.glsl", COMPUTE.replace("imageStore(", "imageStorre("))
    with pytest.raises(ShaderCompileError) as e:
        compile_glsl(bad, {"SCALE": "1.0"})
    assert f"{bad}:15" in str(e.value) and "imageStorre" in str(e.value)
    write(tmp_path, "helpers.glsl", "float twice(float x) { return 2.0 * y; }\n")
    good = write(tmp_path, "good.comp.glsl", COMPUTE)
    with pytest.raises(ShaderCompileError, match=r"helpers.glsl:1: 'y' : undeclared"):
        compile_glsl(good, {"SCALE": "1.0"})
    with pytest.raises(ShaderCompileError, match=r"named <name>\.<stage>\.glsl"):
        compile_glsl(write(tmp_path, "nostage.glsl", "#version 460\n"))


def test_mesh_task_and_ray_tracing_stages_compile(tmp_path):
    mesh = write(tmp_path, "m.mesh.glsl", """#version 460
#extension GL_EXT_mesh_shader : require
layout(local_size_x = 32) in;
layout(triangles, max_vertices = 64, max_primitives = 124) out;
layout(set = 0, binding = 0) readonly buffer Verts { vec4 v[]; };
void main() {
    SetMeshOutputsEXT(3, 1);
    if (gl_LocalInvocationIndex < 3) gl_MeshVerticesEXT[gl_LocalInvocationIndex].gl_Position = v[gl_LocalInvocationIndex];
    if (gl_LocalInvocationIndex == 0) gl_PrimitiveTriangleIndicesEXT[0] = uvec3(0, 1, 2);
}
""")
    r = reflect(compile_glsl(mesh).code)
    assert r.stage == "mesh" and r.local_size == (32, 1, 1)
    rgen = write(tmp_path, "r.rgen.glsl", """#version 460
#extension GL_EXT_ray_tracing : require
layout(set = 0, binding = 0) uniform accelerationStructureEXT tlas;
layout(set = 0, binding = 1, rgba8) uniform image2D o_img;
layout(location = 0) rayPayloadEXT vec3 payload;
void main() {
    traceRayEXT(tlas, gl_RayFlagsOpaqueEXT, 0xff, 0, 0, 0, vec3(0), 0.0, vec3(0, 0, 1), 10.0, 0);
    imageStore(o_img, ivec2(gl_LaunchIDEXT.xy), vec4(payload, 1));
}
""")
    r = reflect(compile_glsl(rgen).code)
    assert r.stage == "rgen"
    assert r.descriptors["tlas"].kind == "acceleration_structure"
    assert r.descriptors["o_img"].kind == "storage_image"


def test_reflect_refuses_garbage():
    with pytest.raises(ShaderCompileError, match="bad magic"):
        reflect(b"\0" * 64)


def test_reflect_reads_storage_image_formats(tmp_path):
    write(tmp_path, "helpers.glsl", "float twice(float x) { return 2.0 * x; }\n")
    r = reflect(compile_glsl(write(tmp_path, "f.comp.glsl", COMPUTE), {"SCALE": "1.0"}).code)
    assert r.descriptors["o_dst"].format == "VK_FORMAT_R16G16B16A16_SFLOAT"
    assert r.descriptors["t_src"].format is None  # sampled: any format
    rgba8 = COMPUTE.replace("rgba16f)", "rgba8)")
    r = reflect(compile_glsl(write(tmp_path, "g.comp.glsl", rgba8), {"SCALE": "1.0"}).code)
    assert r.descriptors["o_dst"].format == "VK_FORMAT_R8G8B8A8_UNORM"


@pytest.mark.parametrize("damage", ["truncated", "not whole words", "bad magic",
                                    "zero-length instruction", "cut at an instruction"])
def test_reflect_refuses_damaged_modules(tmp_path, damage):
    write(tmp_path, "helpers.glsl", "float twice(float x) { return 2.0 * x; }\n")
    code = compile_glsl(write(tmp_path, "f.comp.glsl", COMPUTE), {"SCALE": "1.0"}).code
    reflect(code)  # negative control: the undamaged module reflects
    with pytest.raises(ShaderCompileError, match="SPIR-V"):
        reflect(damaged(code, damage))


def damaged(code: bytes, how: str) -> bytes:
    words = len(code) // 4
    if how == "truncated":
        return code[:len(code) // 2 // 4 * 4]
    if how == "not whole words":
        return code[:-3]
    if how == "bad magic":
        return b"\x00\x00\x00\x00" + code[4:]
    if how == "zero-length instruction":
        return code[:20] + b"\x00\x00\x00\x00" + code[24:]
    # the last instruction (OpFunctionEnd, one word) removed: still whole instructions
    assert how == "cut at an instruction" and words > 6
    return code[:-4]


VK_RUN = ["run", "configs/deferred.toml", "--backend", "vk", "--size", "64x36", "--frames", "1"]


def rfw_vk(tmp_path, cache):
    return warm_cli(*VK_RUN, "--out", tmp_path / "out", cwd=ROOT,
                    env={"RFW_CACHE_SPIRV": str(cache)})


def test_corrupt_cache_entries_heal_through_the_cli(tmp_path):
    cache = tmp_path / "spirv"
    first = rfw_vk(tmp_path, cache)
    assert first.returncode == 0, first.stderr
    entries = sorted(cache.glob("*.spv"))
    assert len(entries) >= 4, entries
    good = {p.name: p.read_bytes() for p in entries}
    # negative control: a sound cache is used silently
    again = rfw_vk(tmp_path, cache)
    assert again.returncode == 0 and "warning" not in again.stderr, again.stderr
    hows = ["truncated", "not whole words", "bad magic", "cut at an instruction"]
    for p, how in zip(entries, hows, strict=False):
        p.write_bytes(damaged(good[p.name], how))
    healed = rfw_vk(tmp_path, cache)
    assert healed.returncode == 0, healed.stderr
    warnings = [line for line in healed.stderr.splitlines() if line.startswith("rfw: warning:")]
    assert len(warnings) == len(hows), healed.stderr
    assert all("corrupt SPIR-V cache entry" in w for w in warnings), warnings
    assert {p.name for p in entries[:len(hows)]} == {
        next(n for n in good if n in w) for w in warnings}
    # rebuilt whole, the same bytes glslang gave the first time, and no temporary left behind
    assert {p.name: p.read_bytes() for p in cache.glob("*.spv")} == good
    assert not [p for p in cache.iterdir() if p.suffix != ".spv"]


def test_shader_that_is_not_utf8_is_one_error(tmp_path):
    bad = tmp_path / "latin.comp.glsl"
    bad.write_bytes(b"#version 460\n// caf\xe9\nlayout(local_size_x = 1) in;\nvoid main() {}\n")
    with pytest.raises(ShaderCompileError, match=r"latin\.comp\.glsl:2: not UTF-8 text \(byte 0xe9"):
        compile_glsl(bad)
    bad.write_bytes(bad.read_bytes().replace(b"\xe9", b"e"))  # negative control
    assert reflect(compile_glsl(bad).code).stage == "comp"


def test_unwritable_cache_warns_and_still_compiles(tmp_path, monkeypatch, capsys):
    (tmp_path / "a-file").write_text("")
    monkeypatch.setenv("RFW_CACHE_SPIRV", str(tmp_path / "a-file" / "spirv"))
    src = write(tmp_path, "plain.comp.glsl",
                "#version 460\nlayout(local_size_x = 2) in;\nvoid main() {}\n")
    assert reflect(compile_glsl(src).code).local_size == (2, 1, 1)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("rfw: warning: ") and "SPIR-V cache" in err[0]
