#version 460
// twin of gbuffer.wgsl (fs_main)
#include "mesh.glsl"

layout(location = 0) in vec3 i_normal;
layout(location = 1) in vec2 i_uv;
layout(location = 2) in vec4 i_tangent;

layout(location = 0) out vec4 g_albedo;
layout(location = 1) out vec4 g_normal;
layout(location = 2) out vec4 g_material;
layout(location = 3) out vec4 g_emissive;

void main() {
    Surface s = surface(i_uv, i_normal, i_tangent);
    if (material.flags.x == 1u && s.base_color.a < material.params.w) {
        discard;
    }
    g_albedo = vec4(s.base_color.rgb, 1.0);
    g_normal = vec4(s.normal, 1.0);
    g_material = vec4(s.occlusion, s.roughness, s.metallic, 1.0);
    g_emissive = vec4(s.emissive, 1.0);
}
