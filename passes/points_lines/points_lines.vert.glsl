#version 460
// a stroke (Scene.strokes: points or line segments), placed by its instance row; a stroke's
// fourth vertex stream is its COLOR_0, which mesh.glsl declares as v_tangent
#define MESH_VERTEX_INPUT
#include "mesh.glsl"

layout(location = 0) out vec4 o_color;

void main() {
    gl_Position = camera.view_proj * (instance.model * vec4(v_position, 1.0));
    // Vulkan leaves a point's size undefined unless the last vertex stage writes it
    gl_PointSize = 1.0;
    o_color = v_tangent;
}
