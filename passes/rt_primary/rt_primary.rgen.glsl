#version 460
// primary rays by ray-tracing pipeline: the closest-hit shader fills the payload
#extension GL_EXT_ray_tracing : require
#include "rt_primary.glsl"

layout(location = 0) rayPayloadEXT PrimaryHit payload;

void main() {
    ivec2 px = ivec2(gl_LaunchIDEXT.xy);
    vec2 size = vec2(gl_LaunchSizeEXT.xy);
    vec3 o, d;
    camera_ray(px, size, o, d);
    traceRayEXT(tlas, gl_RayFlagsOpaqueEXT, RT_MASK_OCCLUDERS, 0, 0, 0, o, camera.near_far.x,
                d, camera.near_far.y * 2.0, 0);
    shade(px, size, payload);
}
