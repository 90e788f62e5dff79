// raycast: what the ray-query and the ray-pipeline variants share (include only)
// the host side is vkext.raycast (RAY_STREAMS, HIT_STREAMS, INVALID)

// std430 scalars: t, primitive, instance, then the barycentric weights of the triangle's
// 2nd and 3rd vertices
struct Hit {
    float t;  // +inf on a miss
    int primitive;  // triangle of the mesh, -1 on a miss
    int instance;  // gl_InstanceCustomIndexEXT: the scene's instance index, -1 on a miss
    float u;
    float v;
};

Hit miss_hit() {
    return Hit(uintBitsToFloat(0x7f800000u), -1, -1, 0.0, 0.0);
}

#ifdef RAYCAST_STREAMS
// a batch of `count` rays as streams, so the host fills and reads each with one contiguous
// copy: rays are origins (3 floats each), directions (3), and with per_ray tmin and tmax (1
// each; else the push constants' values); hits are t, primitive, instance (1 word each) and
// the barycentrics (2)
layout(set = 0, binding = 1, std430) readonly buffer Rays { float ray[]; } rays;
layout(set = 0, binding = 2, std430) writeonly buffer Hits { uint word[]; } hits;

layout(push_constant) uniform Push {
    uint count;  // rays in this batch: threads are rounded up to whole groups
    uint per_ray;  // 1: tmin and tmax are streams after the directions
    float tmin;
    float tmax;
} pc;

vec3 ray_vec3(uint stream, uint i) {
    uint at = stream * pc.count + 3u * i;
    return vec3(rays.ray[at], rays.ray[at + 1u], rays.ray[at + 2u]);
}

vec2 ray_interval(uint i) {
    if (pc.per_ray == 0u) {
        return vec2(pc.tmin, pc.tmax);
    }
    return vec2(rays.ray[6u * pc.count + i], rays.ray[7u * pc.count + i]);
}

// the checks work on bits, which no fast-math assumption can remove
bool finite3(vec3 x) {
    uvec3 e = floatBitsToUint(x) & 0x7f800000u;
    return all(notEqual(e, uvec3(0x7f800000u)));
}

bool zero3(vec3 x) {
    uvec3 b = floatBitsToUint(x) & 0x7fffffffu;
    return (b.x | b.y | b.z) == 0u;
}

// 0 for a ray that can be traced, else the code the host reports (vkext.raycast.INVALID):
// such a ray is never traced, and its hit gets t = NaN
int invalid_ray(vec3 origin, vec3 direction) {
    if (!finite3(origin)) {
        return -2;
    }
    if (!finite3(direction)) {
        return -3;
    }
    if (zero3(direction)) {
        return -4;
    }
    return 0;
}

void store_hit(uint i, Hit h) {
    uint n = pc.count;
    hits.word[i] = floatBitsToUint(h.t);
    hits.word[n + i] = uint(h.primitive);
    hits.word[2u * n + i] = uint(h.instance);
    hits.word[3u * n + 2u * i] = floatBitsToUint(h.u);
    hits.word[3u * n + 2u * i + 1u] = floatBitsToUint(h.v);
}

void store_invalid(uint i, int code) {
    store_hit(i, Hit(uintBitsToFloat(0x7fc00000u), code, -1, 0.0, 0.0));
}

// ray i's origin, direction and [t_min, t_max]; false (its hit marked invalid) when the
// ray cannot be traced
bool load_ray(uint i, out vec3 origin, out vec3 direction, out vec2 interval) {
    origin = ray_vec3(0u, i);
    direction = ray_vec3(3u, i);
    int bad = invalid_ray(origin, direction);
    if (bad != 0) {
        store_invalid(i, bad);
        return false;
    }
    interval = ray_interval(i);
    return true;
}
#endif
