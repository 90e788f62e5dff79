#version 460
// twin of gbuffer.wgsl (fs_main). MESHLET_COLORS (the meshlet G-buffer's debug view): the
// albedo is a color per meshlet, from the mesh shader's per-primitive meshlet row.
// VELOCITY: a fifth target, the motion vector in pixels (gbuffer.vert.glsl's clip positions).
#ifdef MESHLET_COLORS
#extension GL_EXT_mesh_shader : require
#endif
#include "mesh.glsl"
#ifdef VELOCITY
#include "motion.glsl"
#endif

layout(location = 0) in vec3 i_normal;
layout(location = 1) in vec2 i_uv;
layout(location = 2) in vec4 i_tangent;
#ifdef MESHLET_COLORS
layout(location = 3) perprimitiveEXT flat in uint i_meshlet;

vec3 meshlet_color(uint id) {
    uint h = id * 2654435761u;  // Knuth's multiplicative hash: neighbours get far-apart hues
    h ^= h >> 15;
    return vec3(uvec3(h, h >> 8, h >> 16) & 255u) / 255.0 * 0.8 + 0.2;
}
#endif
#ifdef VELOCITY
layout(location = 4) in vec4 i_clip;
layout(location = 5) in vec4 i_prev_clip;
#endif

layout(location = 0) out vec4 g_albedo;
layout(location = 1) out vec4 g_normal;
layout(location = 2) out vec4 g_material;
layout(location = 3) out vec4 g_emissive;
#ifdef VELOCITY
layout(location = 4) out vec2 g_velocity;
#endif

void main() {
    Surface s = surface(i_uv, i_normal, i_tangent);
    if (material.flags.x == 1u && s.base_color.a < material.params.w) {
        discard;
    }
#ifdef MESHLET_COLORS
    g_albedo = vec4(meshlet_color(i_meshlet), 1.0);
#else
    g_albedo = vec4(s.base_color.rgb, 1.0);
#endif
    g_normal = vec4(s.normal, 1.0);
    g_material = vec4(s.occlusion, s.roughness, s.metallic, 1.0);
    g_emissive = vec4(s.emissive, 1.0);
#ifdef VELOCITY
    // interpolated clip positions, divided here: the surface point under this fragment
    g_velocity = pixel_of_clip(i_prev_clip, camera.viewport.xy) -
        pixel_of_clip(i_clip, camera.viewport.xy);
#endif
}
