"""Which files make a pass's program; WGSL preprocessing and reflection (for wgpu-only
plugins); errors that point at the user's file and line, GLSL and WGSL alike."""

from pathlib import Path

import pytest

from rfw.shaders import ShaderError, explain, preprocess, program_files, reflect


def write(tmp: Path, name: str, text: str) -> Path:
    p = tmp / name
    p.write_text(text)
    return p


def test_includes_defines_and_line_map(tmp_path):
    write(tmp_path, "common.wgsl", "const K: f32 = SCALE;\n")
    main = write(tmp_path, "main.wgsl", '#include "common.wgsl"\n#define SCALE 2.0\n'
                 "#ifdef FAST\nfn f() -> f32 { return K; }\n#else\nfn f() -> f32 { return 0.0; }\n"
                 "#endif\n")
    slow = preprocess(main)
    assert "return 0.0" in slow.text and "return K" not in slow.text
    # the include came before the define: the host define wins everywhere
    fast = preprocess(main, {"FAST": 1, "SCALE": "3.0"})
    assert "const K: f32 = 3.0;" in fast.text and "return K" in fast.text
    assert fast.where(1) == f"{tmp_path / 'common.wgsl'}:1"
    assert fast.where(2) == f"{main}:4"
    assert fast.hash != slow.hash


@pytest.mark.parametrize("text, message", [
    ('#include "nope.wgsl"\n', "include 'nope.wgsl' not found"),
    ("#ifdef A\n", "#ifdef without #endif"),
    ("#endif\n", "#endif without #ifdef"),
])
def test_preprocess_errors_name_file_and_line(tmp_path, text, message):
    with pytest.raises(ShaderError, match=message):
        preprocess(write(tmp_path, "bad.wgsl", text))


def test_includes_are_once_only_so_cycles_cannot_loop(tmp_path):
    write(tmp_path, "a.wgsl", '#include "b.wgsl"\nconst A: i32 = 1;\n')
    write(tmp_path, "b.wgsl", '#include "a.wgsl"\nconst B: i32 = 2;\n')
    text = preprocess(tmp_path / "a.wgsl").text
    assert text.count("const A") == 1 and text.count("const B") == 1
    assert text.index("const B") < text.index("const A")


def test_reflect_bindings(tmp_path):
    src = preprocess(write(tmp_path, "r.wgsl", """
@group(0) @binding(0) var t_hdr: texture_2d<f32>;
@group(0) @binding(1) var o_ldr: texture_storage_2d<rgba8unorm, write>;
@group(0) @binding(2) var<uniform> u_params: Params;
@group(1) @binding(0) var<storage, read_write> counts: array<u32>;
@group(1) @binding(1) var<storage> items: array<f32>;
@group(2) @binding(3) var s: sampler_comparison;
// @group(3) @binding(0) var commented: texture_2d<f32>;
"""))
    b = reflect(src)
    assert set(b) == {"t_hdr", "o_ldr", "u_params", "counts", "items", "s"}
    assert (b["o_ldr"].kind, b["o_ldr"].access) == ("storage-texture", "write")
    assert b["counts"].kind == "storage" and b["items"].kind == "read-only-storage"
    assert (b["s"].group, b["s"].binding, b["s"].kind) == (2, 3, "sampler")


def test_compile_errors_point_at_the_original_file(tmp_path, device):
    from rfw.backends.wgpu.programs import ShaderCache

    write(tmp_path, "inc.wgsl", "fn helper() -> f32 { return 1.0; }\n")
    bad = write(tmp_path, "bad.comp.wgsl", '#include "inc.wgsl"\n\n@compute @workgroup_size(1)\n'
                "fn main() {\n    let x: f32 = undefined_thing;\n}\n")
    with pytest.raises(ShaderError) as e:
        ShaderCache(device).program([bad], {}, "compute", {})
    assert f"{bad}:5" in str(e.value)
    assert "undefined_thing" in str(e.value)


def test_glsl_compile_errors_point_at_the_original_file(tmp_path, device, monkeypatch):
    from rfw.backends.wgpu.programs import ShaderCache

    monkeypatch.setenv("RFW_CACHE_SPIRV", str(tmp_path / "cache"))
    write(tmp_path, "inc.glsl", "float helper() { return 1.0; }\n")
    bad = write(tmp_path, "bad.comp.glsl", '#version 460\n#include "inc.glsl"\n'
                "layout(local_size_x = 1) in;\nvoid main() {\n    float x = undefined_thing;\n}\n")
    with pytest.raises(ShaderError) as e:
        ShaderCache(device).program([bad], {}, "compute", {}, owner="p")
    assert str(e.value).startswith(f"pass 'p': {bad}:5: ")
    assert "undefined_thing" in str(e.value) and "\n" not in str(e.value)


def test_program_files_is_one_rule(tmp_path):
    for name in ("fwd.vert.glsl", "fwd.frag.glsl", "post.comp.glsl", "old.wgsl"):
        write(tmp_path, name, "")
    # a bare name: every <name>.<stage>.glsl beside the pass, in stage order
    assert program_files(tmp_path, "fwd") == [tmp_path / "fwd.vert.glsl",
                                              tmp_path / "fwd.frag.glsl"]
    assert program_files(tmp_path, "post") == [tmp_path / "post.comp.glsl"]
    assert program_files(tmp_path, "post.comp.glsl") == [tmp_path / "post.comp.glsl"]
    assert program_files(tmp_path, "old.wgsl") == [tmp_path / "old.wgsl"]
    with pytest.raises(ShaderError, match=r"pass 'p': no shader nope\.<stage>\.glsl in "):
        program_files(tmp_path, "nope", owner="p")
    with pytest.raises(ShaderError, match=r"pass 'p': shader .*gone\.comp\.glsl not found"):
        program_files(tmp_path, "gone.comp.glsl", owner="p")


def test_explain_maps_lines(tmp_path):
    src = preprocess(write(tmp_path, "m.wgsl", "a\nb\n"))
    assert explain(src, "error at wgsl:2:3 oops").startswith(f"{tmp_path / 'm.wgsl'}:2: ")


@pytest.mark.parametrize("where", ["main", "include"])
def test_invalid_utf8_names_file_and_line(tmp_path, where):
    good = "fn g() -> f32 { return 1.0; }\n"
    bad = b"// ok\nfn h() -> f32 { return 2.0; } // \xff\xfe latin-1?\n"
    inc = tmp_path / "inc.wgsl"
    main = tmp_path / "main.wgsl"
    if where == "main":
        inc.write_text(good)
        main.write_bytes(b'#include "inc.wgsl"\n' + bad)
        bad_file, line = main, 3
    else:
        inc.write_bytes(bad)
        main.write_text('#include "inc.wgsl"\n' + good)
        bad_file, line = inc, 2
    with pytest.raises(ShaderError) as e:
        preprocess(main)
    text = str(e.value)
    assert text.startswith(f"{bad_file}:{line}: not UTF-8") and "\n" not in text
    # negative control: the same bytes, valid UTF-8, preprocess
    bad_file.write_text(bad.decode("latin-1"))
    assert "return 2.0" in preprocess(main).text


def test_an_edited_include_recompiles(tmp_path, device, monkeypatch):
    # the wgpu program cache skips hashing on a hit, but not past a changed include
    from rfw.backends.wgpu.programs import ShaderCache

    monkeypatch.setenv("RFW_CACHE_SPIRV", str(tmp_path / "cache"))
    inc = write(tmp_path, "k.glsl", "const uint K = 1u;\n")
    main = write(tmp_path, "m.comp.glsl", '#version 460\n#include "k.glsl"\n'
                 "layout(local_size_x = 1) in;\n"
                 "layout(set = 0, binding = 0) buffer B { uint v; } b_out;\n"
                 "void main() { b_out.v = K; }\n")
    cache = ShaderCache(device)
    first = cache.program([main], {}, "compute", {})
    assert cache.program([main], {}, "compute", {}) is first
    inc.write_text("const uint K = 22u;  // longer, so the size changes too\n")
    assert cache.program([main], {}, "compute", {}) is not first


RASTER_VERT = """#version 460
#define MESH_VERTEX_INPUT
#include "mesh.glsl"
void main() { gl_Position = camera.view_proj * (instance.model * vec4(v_position, 1.0)); }
"""


@pytest.mark.parametrize(("files", "kind", "message"), [
    # a stage only the vk backend runs
    ({"m.mesh.glsl": "#version 460\n#extension GL_EXT_mesh_shader : require\n"
                     "layout(local_size_x = 1) in;\n"
                     "layout(triangles, max_vertices = 3, max_primitives = 1) out;\n"
                     "void main() { SetMeshOutputsEXT(0, 0); }\n"},
     "render", r"m\.mesh\.glsl is a mesh shader: the wgpu backend runs comp, vert and frag"),
    # WebGPU has no combined image samplers
    ({"c.comp.glsl": "#version 460\nlayout(local_size_x = 1) in;\n"
                     "layout(set = 0, binding = 0) uniform sampler2D t_src;\n"
                     "layout(set = 0, binding = 1, rgba8) uniform writeonly image2D o_dst;\n"
                     "void main() { imageStore(o_dst, ivec2(0), texture(t_src, vec2(0.5))); }\n"},
     "compute", r"binding 't_src' is a combined image sampler .*WebGPU has none"),
    # group 1 of a raster program is the scene's
    ({"s.vert.glsl": RASTER_VERT.replace(
        "void main", "layout(set = 1, binding = 5) uniform Extra { vec4 x; } u_extra;\nvoid main"
    ).replace("vec4(v_position, 1.0)", "vec4(v_position, 1.0) + u_extra.x")},
     "render", r"declares u_extra in group 1, which the scene owns \(camera, lights\)"),
])
def test_wgpu_refuses_what_it_cannot_run(tmp_path, device, monkeypatch, files, kind, message):
    from rfw.backends.wgpu.programs import ShaderCache

    monkeypatch.setenv("RFW_CACHE_SPIRV", str(tmp_path / "cache"))
    paths = [write(tmp_path, name, text) for name, text in files.items()]
    with pytest.raises(ShaderError, match=message):
        ShaderCache(device).program(paths, {}, kind, {}, owner="p")


def test_wgpu_takes_a_scene_raster_program(tmp_path, device, monkeypatch):
    # negative control of the scene-group refusal: the plain vertex shader is accepted, and
    # its groups 1-3 are the scene's shared layouts
    from rfw.backends.wgpu.programs import ShaderCache

    monkeypatch.setenv("RFW_CACHE_SPIRV", str(tmp_path / "cache"))
    cache = ShaderCache(device)
    prog = cache.program([write(tmp_path, "ok.vert.glsl", RASTER_VERT)], {}, "render", {})
    assert prog.layouts[1:] == [cache.scene_layouts[g] for g in (1, 2, 3)]
