#version 460
// twin of shadow_map.wgsl (vs_main); depth only, so no fragment shader
//
// the vertex is flipped to Vulkan's y-down ndc (vk_clip in scene.glsl): the map's texels land
// where WebGPU puts them, so shadow.glsl's uv mapping is shared. front faces stay WebGPU's
// (VK_FRONT_FACE_COUNTER_CLOCKWISE); this pass culls VK_CULL_MODE_FRONT_BIT like the WGSL one.
#define MESH_VERTEX_INPUT
#include "mesh.glsl"

void main() {
    gl_Position = vk_clip(camera.view_proj * (instance.model * vec4(v_position, 1.0)));
}
