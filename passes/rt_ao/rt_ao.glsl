// rt_ao: what the ray-query and ray-pipeline variants share (include only). occluded() comes
// from rt_occluded_query.glsl or rt_occluded_pipeline.glsl, which the stage file includes after.
#include "raytrace.glsl"

layout(set = 0, binding = 0) uniform texture2D t_depth;
layout(set = 0, binding = 1) uniform texture2D t_normal;
layout(set = 0, binding = 2) uniform accelerationStructureEXT tlas;
layout(set = 0, binding = 3, rgba16f) uniform writeonly image2D o_ao;
// rt_ao.Params as Settings.pack() writes it (the method string is host-side)
layout(set = 0, binding = 4, std140) uniform Params {
    int max_recursion;
    float radius;
    int samples;
    float normal_bias;
    float t_min;
} u_params;

bool occluded(vec3 origin, float tmin, vec3 direction, float tmax);

// the fraction of `samples` cosine-weighted rays that leave the hemisphere's `radius`
// unoccluded (1: open sky, 0: fully enclosed)
float ambient_occlusion(ivec2 px, vec2 size) {
    vec3 p, n;
    if (!gbuffer_point(t_depth, t_normal, px, size, p, n)) {
        return 1.0;
    }
    vec3 o = ray_origin(p, n, u_params.normal_bias);
    uint count = uint(clamp(u_params.samples, 1, 256));
    uint open = 0u;
    for (uint s = 0u; s < count; s++) {
        vec3 d = cosine_direction(n, random2(px, s));
        if (!occluded(o, u_params.t_min, d, u_params.radius)) {
            open++;
        }
    }
    return float(open) / float(count);
}
