#version 460
// raycast through ray queries: one invocation per ray, closest hit, no shader tables
#extension GL_EXT_ray_query : require
#include "raycast.glsl"

layout(local_size_x = 64) in;

layout(set = 0, binding = 0) uniform accelerationStructureEXT tlas;
layout(set = 0, binding = 1, std430) readonly buffer Rays { Ray ray[]; } rays;
layout(set = 0, binding = 2, std430) writeonly buffer Hits { Hit hit[]; } hits;

layout(push_constant) uniform Push {
    uint count;  // rays in this batch: threads are rounded up to whole groups
} pc;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= pc.count) {
        return;
    }
    Ray r = rays.ray[i];
    rayQueryEXT q;
    // opaque: a geometric query ignores alpha, so no candidate needs confirming
    rayQueryInitializeEXT(q, tlas, gl_RayFlagsOpaqueEXT, 0xFF, r.origin_tmin.xyz,
                          r.origin_tmin.w, r.direction_tmax.xyz, r.direction_tmax.w);
    while (rayQueryProceedEXT(q)) {
    }
    Hit h = miss_hit();
    if (rayQueryGetIntersectionTypeEXT(q, true) == gl_RayQueryCommittedIntersectionTriangleEXT) {
        vec2 b = rayQueryGetIntersectionBarycentricsEXT(q, true);
        h = Hit(rayQueryGetIntersectionTEXT(q, true),
                rayQueryGetIntersectionPrimitiveIndexEXT(q, true),
                rayQueryGetIntersectionInstanceCustomIndexEXT(q, true), b.x, b.y);
    }
    hits.hit[i] = h;
}
