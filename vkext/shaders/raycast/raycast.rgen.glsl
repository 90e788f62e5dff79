#version 460
// raycast through a ray-tracing pipeline: one launch per ray; the closest-hit and miss
// shaders fill the payload, so nothing here needs GL_EXT_ray_query (devices with pipelines
// only, such as NVIDIA's drivers without it enabled, run this variant)
#extension GL_EXT_ray_tracing : require
#include "raycast.glsl"

layout(set = 0, binding = 0) uniform accelerationStructureEXT tlas;
layout(set = 0, binding = 1, std430) readonly buffer Rays { Ray ray[]; } rays;
layout(set = 0, binding = 2, std430) writeonly buffer Hits { Hit hit[]; } hits;

layout(location = 0) rayPayloadEXT Hit payload;

void main() {
    uint i = gl_LaunchIDEXT.x;  // the launch is exactly one batch wide
    Ray r = rays.ray[i];
    // sbt record offset 0, stride 0: every geometry uses hit record (instance offset + 0)
    traceRayEXT(tlas, gl_RayFlagsOpaqueEXT, 0xFF, 0, 0, 0, r.origin_tmin.xyz, r.origin_tmin.w,
                r.direction_tmax.xyz, r.direction_tmax.w, 0);
    hits.hit[i] = payload;
}
