#version 460
// invariant and the same expression as gbuffer.vert.glsl: the same depth and coverage
#define MESH_VERTEX_INPUT
#include "mesh.glsl"

invariant gl_Position;

layout(location = 0) out vec2 o_uv;
layout(location = 1) flat out uint o_instance;

void main() {
    gl_Position = camera.view_proj * (instance.model * vec4(v_position, 1.0));
    o_uv = v_uv;
    o_instance = uint(gl_InstanceIndex);  // a scene draw's firstInstance: its instance
}
