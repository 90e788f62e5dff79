// what ray-traced screen-space passes share (include only; needs scene.glsl's camera)
#ifndef RFW_RAYTRACE_GLSL
#define RFW_RAYTRACE_GLSL

#include "scene.glsl"

// instance mask bits of vkext.accel.ALPHA_MASK: opaque and alpha-tested surfaces occlude,
// blended ones (water, glass) do not, as the shadow map leaves them out
const uint RT_MASK_OCCLUDERS = 0x3u;

// a ray tracer's view of a G-buffer pixel: the world point it sees and its normal, turned
// toward the camera (thin double-sided surfaces store either side). false: background
bool gbuffer_point(texture2D depth_tex, texture2D normal_tex, ivec2 px, vec2 size,
                   out vec3 p, out vec3 n) {
    float depth = texelFetch(depth_tex, px, 0).r;
    if (depth >= 1.0) {
        return false;
    }
    p = world_from_depth(vec2(px) + 0.5, size, depth);
    n = normalize(texelFetch(normal_tex, px, 0).xyz);
    if (dot(n, camera.position.xyz - p) < 0.0) {
        n = -n;
    }
    return true;
}

// where rays leave the surface: along the normal, further for distant points, whose
// reconstructed depth carries more error
vec3 ray_origin(vec3 p, vec3 n, float bias) {
    return p + n * bias * (1.0 + 0.02 * length(camera.position.xyz - p));
}

// pcg3d (Jarzynski and Olano 2020): a deterministic hash per pixel and sample
uvec3 pcg3d(uvec3 v) {
    v = v * 1664525u + 1013904223u;
    v.x += v.y * v.z;
    v.y += v.z * v.x;
    v.z += v.x * v.y;
    v ^= v >> 16u;
    v.x += v.y * v.z;
    v.y += v.z * v.x;
    v.z += v.x * v.y;
    return v;
}

vec2 random2(ivec2 px, uint i) {
    return vec2(pcg3d(uvec3(uvec2(px), i)).xy) * (1.0 / 4294967296.0);
}

// a direction of the hemisphere around n with density cos(theta) / pi
vec3 cosine_direction(vec3 n, vec2 u) {
    float r = sqrt(u.x);
    float phi = 6.28318530718 * u.y;
    vec3 t = normalize(abs(n.x) > 0.5 ? cross(n, vec3(0.0, 1.0, 0.0)) : cross(n, vec3(1.0, 0.0, 0.0)));
    vec3 b = cross(n, t);
    return normalize(t * (r * cos(phi)) + b * (r * sin(phi)) + n * sqrt(max(0.0, 1.0 - u.x)));
}

#endif
