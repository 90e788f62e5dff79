#version 460
// ray-traced ambient occlusion by ray query: any hit within the radius occludes
#extension GL_EXT_ray_query : require
#extension GL_EXT_samplerless_texture_functions : require
#include "rt_ao.glsl"

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
    ivec2 size = imageSize(o_ao);
    if (px.x >= size.x || px.y >= size.y) {
        return;
    }
    float ao = ambient_occlusion(px, vec2(size));
    imageStore(o_ao, px, vec4(ao, ao, ao, 1.0));
}
