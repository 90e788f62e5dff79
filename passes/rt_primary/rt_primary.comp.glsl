#version 460
// primary rays by ray query: the closest hit, read back from the committed intersection
#extension GL_EXT_ray_query : require
#include "rt_primary.glsl"

layout(local_size_x = 8, local_size_y = 8) in;

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 isize = imageSize(o_albedo);
    if (px.x >= isize.x || px.y >= isize.y) {
        return;
    }
    vec2 size = vec2(isize);
    vec3 o, d;
    camera_ray(px, size, o, d);
    rayQueryEXT q;
    rayQueryInitializeEXT(q, tlas, gl_RayFlagsOpaqueEXT, RT_MASK_OCCLUDERS, o,
                          camera.near_far.x, d, camera.near_far.y * 2.0);
    while (rayQueryProceedEXT(q)) {
    }
    PrimaryHit h;
    h.instance = -1;
    if (rayQueryGetIntersectionTypeEXT(q, true) == gl_RayQueryCommittedIntersectionTriangleEXT) {
        h = PrimaryHit(rayQueryGetIntersectionBarycentricsEXT(q, true),
                       rayQueryGetIntersectionInstanceCustomIndexEXT(q, true),
                       rayQueryGetIntersectionPrimitiveIndexEXT(q, true),
                       rayQueryGetIntersectionObjectToWorldEXT(q, true));
    }
    shade(px, size, h);
}
