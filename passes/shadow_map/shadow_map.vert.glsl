#version 460
// depth only, so no fragment shader. clip space is WebGPU's on both backends (scene.glsl): the
// map's texels land where shadow.glsl's uv mapping looks for them; the pass culls front faces
#define MESH_VERTEX_INPUT
#include "mesh.glsl"

void main() {
    gl_Position = camera.view_proj * (instance.model * vec4(v_position, 1.0));
}
