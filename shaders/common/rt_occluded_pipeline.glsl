// occluded() by traceRayEXT, for raygen shaders (GL_EXT_ray_tracing): the same test as
// rt_occluded_query.glsl. No closest-hit shader runs; the pass's miss shader sets the
// payload to 1 (the ray got through). Include after the pass's bindings declare `tlas`.
#ifndef RFW_RT_OCCLUDED_GLSL
#define RFW_RT_OCCLUDED_GLSL

layout(location = 0) rayPayloadEXT float visible;

bool occluded(vec3 origin, float tmin, vec3 direction, float tmax) {
    visible = 0.0;
    traceRayEXT(tlas, gl_RayFlagsOpaqueEXT | gl_RayFlagsTerminateOnFirstHitEXT
                | gl_RayFlagsSkipClosestHitShaderEXT, RT_MASK_OCCLUDERS, 0, 0, 0, origin, tmin,
                direction, tmax, 0);
    return visible == 0.0;
}

#endif
