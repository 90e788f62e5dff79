#version 460
// ray-traced ambient occlusion by ray-tracing pipeline: the miss shader marks a ray open,
// no closest-hit shader runs
#extension GL_EXT_ray_tracing : require
#extension GL_EXT_samplerless_texture_functions : require
#include "rt_ao.glsl"
#include "rt_occluded_pipeline.glsl"

void main() {
    ivec2 px = ivec2(gl_LaunchIDEXT.xy);  // the launch is the image's size
    float ao = ambient_occlusion(px, vec2(gl_LaunchSizeEXT.xy));
    imageStore(o_ao, px, vec4(ao, ao, ao, 1.0));
}
