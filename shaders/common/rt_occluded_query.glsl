// occluded() by ray query, for compute shaders (GL_EXT_ray_query): any opaque occluder
// (RT_MASK_OCCLUDERS) of `tlas` in [tmin, tmax] along the ray, terminating on the first hit.
// Include after the pass's bindings declare `tlas`.
#ifndef RFW_RT_OCCLUDED_GLSL
#define RFW_RT_OCCLUDED_GLSL

bool occluded(vec3 origin, float tmin, vec3 direction, float tmax) {
    rayQueryEXT q;
    rayQueryInitializeEXT(q, tlas, gl_RayFlagsOpaqueEXT | gl_RayFlagsTerminateOnFirstHitEXT,
                          RT_MASK_OCCLUDERS, origin, tmin, direction, tmax);
    while (rayQueryProceedEXT(q)) {
    }
    return rayQueryGetIntersectionTypeEXT(q, true) != gl_RayQueryCommittedIntersectionNoneEXT;
}

#endif
