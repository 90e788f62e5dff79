#version 460
// ray-traced shadows by ray-tracing pipeline: the miss shader marks a ray visible, and no
// closest-hit shader runs (devices with pipelines but no ray query run this variant)
#extension GL_EXT_ray_tracing : require
#extension GL_EXT_samplerless_texture_functions : require
#include "rt_shadows.glsl"

layout(location = 0) rayPayloadEXT float visible;

bool occluded(vec3 origin, float tmin, vec3 direction, float tmax) {
    visible = 0.0;
    traceRayEXT(tlas, gl_RayFlagsOpaqueEXT | gl_RayFlagsTerminateOnFirstHitEXT
                | gl_RayFlagsSkipClosestHitShaderEXT, RT_MASK_OCCLUDERS, 0, 0, 0, origin, tmin,
                direction, tmax, 0);
    return visible == 0.0;
}

void main() {
    ivec2 px = ivec2(gl_LaunchIDEXT.xy);  // the launch is the image's size
    imageStore(o_visibility, px, uvec4(visibility_bits(px, vec2(gl_LaunchSizeEXT.xy))));
}
