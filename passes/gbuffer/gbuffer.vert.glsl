#version 460
// invariant: the same expression as depth_prepass.vert.glsl, so less-equal against the
// prepass depth passes exactly where this surface is nearest
#define MESH_VERTEX_INPUT
#include "mesh.glsl"

invariant gl_Position;

layout(location = 0) out vec3 o_normal;
layout(location = 1) out vec2 o_uv;
layout(location = 2) out vec4 o_tangent;

void main() {
    gl_Position = camera.view_proj * (instance.model * vec4(v_position, 1.0));
    o_normal = (instance.normal * vec4(v_normal, 0.0)).xyz;
    o_tangent = vec4((instance.model * vec4(v_tangent.xyz, 0.0)).xyz, v_tangent.w);
    o_uv = v_uv;
}
