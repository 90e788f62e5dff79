#version 460
// depth-aware box blur of the raw occlusion, neighbours on other
// surfaces get no weight
#extension GL_EXT_samplerless_texture_functions : require  // texelFetch on texture2D
#include "ssao_common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;

layout(set = 0, binding = 1, r32f) uniform readonly image2D t_ao;
layout(set = 0, binding = 2, rgba16f) uniform writeonly image2D o_ao;

const int MAX_RADIUS = 8;

float view_depth(ivec2 id) {
    ivec2 px = source_pixel(uvec2(id));
    float d = load_depth(px);
    return d >= 1.0 ? -1.0 : -view_position(px, d).z;  // -1: background
}

void main() {
    ivec2 size = imageSize(o_ao);
    ivec2 c = ivec2(gl_GlobalInvocationID.xy);
    if (c.x >= size.x || c.y >= size.y) {
        return;
    }
    float zc = view_depth(c);
    int r = clamp(u_params.blur_radius, 0, MAX_RADIUS);
    if (zc < 0.0 || r == 0) {
        imageStore(o_ao, c, vec4(imageLoad(t_ao, c).r));
        return;
    }
    float tolerance = max(u_params.blur_depth, 1e-6) * zc;
    float sum = 0.0;
    float weight = 0.0;
    for (int y = -r; y <= r; y++) {
        for (int x = -r; x <= r; x++) {
            ivec2 q = c + ivec2(x, y);
            if (any(lessThan(q, ivec2(0))) || any(greaterThanEqual(q, size))) {
                continue;
            }
            float zq = view_depth(q);
            float w = zq < 0.0 ? 0.0 : max(0.0, 1.0 - abs(zq - zc) / tolerance);
            sum += w * imageLoad(t_ao, q).r;
            weight += w;
        }
    }
    // the centre always has weight 1, so weight > 0
    imageStore(o_ao, c, vec4(sum / weight));
}
