#version 460
// raycast through ray queries: one invocation per ray, closest hit, no shader tables
#extension GL_EXT_ray_query : require
#define RAYCAST_STREAMS
#include "raycast.glsl"

layout(local_size_x = 64) in;

layout(set = 0, binding = 0) uniform accelerationStructureEXT tlas;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= pc.count) {
        return;
    }
    vec3 origin, direction;
    vec2 interval;
    if (!load_ray(i, origin, direction, interval)) {
        return;
    }
    rayQueryEXT q;
    // opaque: a geometric query ignores alpha, so no candidate needs confirming
    rayQueryInitializeEXT(q, tlas, gl_RayFlagsOpaqueEXT, 0xFF, origin, interval.x, direction,
                          interval.y);
    while (rayQueryProceedEXT(q)) {
    }
    Hit h = miss_hit();
    if (rayQueryGetIntersectionTypeEXT(q, true) == gl_RayQueryCommittedIntersectionTriangleEXT) {
        vec2 b = rayQueryGetIntersectionBarycentricsEXT(q, true);
        h = Hit(rayQueryGetIntersectionTEXT(q, true),
                rayQueryGetIntersectionPrimitiveIndexEXT(q, true),
                rayQueryGetIntersectionInstanceCustomIndexEXT(q, true), b.x, b.y);
    }
    store_hit(i, h);
}
