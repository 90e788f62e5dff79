#version 460
// raycast through a ray-tracing pipeline: one launch per ray; the closest-hit and miss
// shaders fill the payload, so nothing here needs GL_EXT_ray_query (devices with pipelines
// only, such as NVIDIA's drivers without it enabled, run this variant)
#extension GL_EXT_ray_tracing : require
#define RAYCAST_STREAMS
#include "raycast.glsl"

layout(set = 0, binding = 0) uniform accelerationStructureEXT tlas;

layout(location = 0) rayPayloadEXT Hit payload;

void main() {
    uint i = gl_LaunchIDEXT.x;  // the launch is exactly one batch wide
    vec3 origin, direction;
    vec2 interval;
    if (!load_ray(i, origin, direction, interval)) {
        return;
    }
    // sbt record offset 0, stride 0: every geometry uses hit record (instance offset + 0)
    traceRayEXT(tlas, gl_RayFlagsOpaqueEXT, 0xFF, 0, 0, 0, origin, interval.x, direction,
                interval.y, 0);
    store_hit(i, payload);
}
