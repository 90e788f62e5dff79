#version 460
// depth only, so no fragment shader
//
// invariant, and the same expression as gbuffer.vert.glsl and forward.vert.glsl, so a later
// less-equal test against this depth passes exactly where that surface is nearest
#define MESH_VERTEX_INPUT
#include "mesh.glsl"

invariant gl_Position;

void main() {
    gl_Position = camera.view_proj * (instance.model * vec4(v_position, 1.0));
}
