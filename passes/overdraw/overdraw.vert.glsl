#version 460
// twin of overdraw.wgsl (vs_main): the scene's transform, y flipped to Vulkan's ndc (vk_clip
// in scene.glsl) so culling and coverage are WebGPU's
#define MESH_VERTEX_INPUT
#include "mesh.glsl"

void main() {
    gl_Position = vk_clip(camera.view_proj * (instance.model * vec4(v_position, 1.0)));
}
