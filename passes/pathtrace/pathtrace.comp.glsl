#version 460
// the path tracer by ray query: candidate hits of masked and blended surfaces are confirmed
// where surface_blocks says so (what the pipeline variant's any-hit shader decides)
#extension GL_EXT_ray_query : require
#include "pathtrace.glsl"

layout(local_size_x = 8, local_size_y = 8) in;

void resolve_candidates(rayQueryEXT q, uint seed) {
    while (rayQueryProceedEXT(q)) {
        if (rayQueryGetIntersectionTypeEXT(q, false) == gl_RayQueryCandidateIntersectionTriangleEXT
                && surface_blocks(rayQueryGetIntersectionInstanceCustomIndexEXT(q, false),
                                  rayQueryGetIntersectionPrimitiveIndexEXT(q, false),
                                  rayQueryGetIntersectionBarycentricsEXT(q, false), seed)) {
            rayQueryConfirmIntersectionEXT(q);
        }
    }
}

Hit trace_closest(vec3 origin, vec3 direction, float tmax, uint seed) {
    rayQueryEXT q;
    rayQueryInitializeEXT(q, tlas, gl_RayFlagsNoneEXT, MASK_ALL, origin, 0.0, direction, tmax);
    resolve_candidates(q, seed);
    Hit h;
    h.instance = -1;
    if (rayQueryGetIntersectionTypeEXT(q, true) == gl_RayQueryCommittedIntersectionTriangleEXT) {
        h = Hit(rayQueryGetIntersectionBarycentricsEXT(q, true),
                rayQueryGetIntersectionInstanceCustomIndexEXT(q, true),
                rayQueryGetIntersectionPrimitiveIndexEXT(q, true),
                rayQueryGetIntersectionTEXT(q, true));
    }
    return h;
}

bool occluded(vec3 origin, vec3 direction, float tmax, uint mask, uint seed) {
    rayQueryEXT q;
    rayQueryInitializeEXT(q, tlas, gl_RayFlagsTerminateOnFirstHitEXT, mask, origin, 0.0,
                          direction, tmax);
    resolve_candidates(q, seed);
    return rayQueryGetIntersectionTypeEXT(q, true) != gl_RayQueryCommittedIntersectionNoneEXT;
}

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 isize = imageSize(o_hdr);
    if (px.x < isize.x && px.y < isize.y) {
        render_pixel(px, isize);
    }
}
