#version 460
// the path tracer by ray-tracing pipeline: closest-hit and miss shaders fill the payload,
// the any-hit shader runs surface_blocks on masked and blended surfaces
#extension GL_EXT_ray_tracing : require
#include "pathtrace.glsl"

layout(location = 0) rayPayloadEXT Payload payload;

Hit trace_closest(vec3 origin, vec3 direction, float tmax, uint seed) {
    payload.seed = seed;
    traceRayEXT(tlas, gl_RayFlagsNoneEXT, MASK_ALL, 0, 0, 0, origin, 0.0, direction, tmax, 0);
    return payload.hit;
}

bool occluded(vec3 origin, vec3 direction, float tmax, uint mask, uint seed) {
    payload.seed = seed;
    payload.hit.instance = 0;  // the miss shader sets -1: the ray got through
    traceRayEXT(tlas, gl_RayFlagsTerminateOnFirstHitEXT | gl_RayFlagsSkipClosestHitShaderEXT,
                mask, 0, 0, 0, origin, 0.0, direction, tmax, 0);
    return payload.hit.instance != -1;
}

void main() {
    render_pixel(ivec2(gl_LaunchIDEXT.xy), ivec2(gl_LaunchSizeEXT.xy));
}
