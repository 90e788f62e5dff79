#version 460
// twin of depth_prepass.wgsl (vs_main); depth only, so no fragment shader
//
// invariant, and the same expression (vk_clip included) as gbuffer.vert.glsl and
// forward.vert.glsl, so a later less-equal test against this depth passes exactly where that
// surface is nearest. y is flipped to Vulkan's ndc (vk_clip in scene.glsl); the pipeline keeps
// WebGPU's front face, VK_FRONT_FACE_COUNTER_CLOCKWISE.
#define MESH_VERTEX_INPUT
#include "mesh.glsl"

invariant gl_Position;

void main() {
    gl_Position = vk_clip(camera.view_proj * (instance.model * vec4(v_position, 1.0)));
}
