#version 460
// ray-traced shadows by ray query: terminate on the first hit, no shader tables
#extension GL_EXT_ray_query : require
#extension GL_EXT_samplerless_texture_functions : require
#include "rt_shadows.glsl"

layout(local_size_x = 8, local_size_y = 8) in;

bool occluded(vec3 origin, float tmin, vec3 direction, float tmax) {
    rayQueryEXT q;
    rayQueryInitializeEXT(q, tlas, gl_RayFlagsOpaqueEXT | gl_RayFlagsTerminateOnFirstHitEXT,
                          RT_MASK_OCCLUDERS, origin, tmin, direction, tmax);
    while (rayQueryProceedEXT(q)) {
    }
    return rayQueryGetIntersectionTypeEXT(q, true) != gl_RayQueryCommittedIntersectionNoneEXT;
}

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = imageSize(o_visibility);
    if (px.x >= size.x || px.y >= size.y) {
        return;
    }
    imageStore(o_visibility, px, uvec4(visibility_bits(px, vec2(size))));
}
