"""GLSL to SPIR-V with glslang: cache, includes, defines, errors with file and line, and
layouts reflected from the binary (never hand-written)."""

import shutil

import pytest

from vkext.spirv import ShaderCompileError, compile_glsl, reflect

pytestmark = pytest.mark.skipif(shutil.which("glslangValidator") is None,
                                reason="needs glslangValidator (scripts/setup-system.sh)")


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
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
