#version 460
// the scene's transform; clip space is WebGPU's on both backends (scene.glsl)
#define MESH_VERTEX_INPUT
#include "mesh.glsl"

void main() {
    gl_Position = camera.view_proj * (instance.model * vec4(v_position, 1.0));
}
