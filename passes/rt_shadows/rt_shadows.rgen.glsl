#version 460
// ray-traced shadows by ray-tracing pipeline: the miss shader marks a ray visible, and no
// closest-hit shader runs (devices with pipelines but no ray query run this variant)
#extension GL_EXT_ray_tracing : require
#extension GL_EXT_samplerless_texture_functions : require
#include "rt_shadows.glsl"
#include "rt_occluded_pipeline.glsl"

void main() {
    ivec2 px = ivec2(gl_LaunchIDEXT.xy);  // the launch is the image's size
    imageStore(o_visibility, px, uvec4(visibility_bits(px, vec2(gl_LaunchSizeEXT.xy))));
}
