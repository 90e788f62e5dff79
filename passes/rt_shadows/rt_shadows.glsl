// rt_shadows: what the ray-query and ray-pipeline variants share (include only). occluded()
// comes from rt_occluded_query.glsl or rt_occluded_pipeline.glsl, included by the stage file.
#include "raytrace.glsl"

layout(set = 0, binding = 0) uniform texture2D t_depth;
layout(set = 0, binding = 1) uniform texture2D t_normal;
layout(set = 0, binding = 2) uniform accelerationStructureEXT tlas;
layout(set = 0, binding = 3, r32ui) uniform writeonly uimage2D o_visibility;
// rt_shadows.Params as Settings.pack() writes it (the method string is host-side)
layout(set = 0, binding = 4, std140) uniform Params {
    int max_recursion;
    float normal_bias;
    float t_min;
    uint point_lights;
} u_params;

bool occluded(vec3 origin, float tmin, vec3 direction, float tmax);

// one shadow ray per light that faces the point; bit i stays set where light i is unoccluded
uint visibility_bits(ivec2 px, vec2 size) {
    vec3 p, n;
    if (!gbuffer_point(t_depth, t_normal, px, size, p, n)) {
        return 0xffffffffu;
    }
    vec3 o = ray_origin(p, n, u_params.normal_bias);
    uint bits = 0xffffffffu;
    for (uint i = 0u; i < lights.count.x; i++) {
        Light li = lights.items[i];
        bool directional = uint(li.position.w) == 0u;
        if (!directional && u_params.point_lights == 0u) {
            continue;
        }
        vec3 d = directional ? -li.direction.xyz : li.position.xyz - o;
        float tmax = directional ? 1e5 : length(d);
        d = normalize(d);
        if (dot(d, n) <= 0.0) {
            continue;  // faces away: the BRDF gives it nothing anyway
        }
        if (occluded(o, u_params.t_min, d, tmax)) {
            bits &= ~(1u << i);
        }
    }
    return bits;
}
