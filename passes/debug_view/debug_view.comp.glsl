#version 460
// one texture shown as display color; MODE picks how
// (0 color, 1 normals, 2 depth, 3 heatmap)
#extension GL_EXT_samplerless_texture_functions : require  // texelFetch on texture2D
#include "color.glsl"
#ifdef LINEAR_DEPTH
#include "scene.glsl"
#endif

layout(local_size_x = 8, local_size_y = 8) in;

// WGSL binds a depth format as texture_depth_2d (DEPTH_SOURCE): a sampled image here too
layout(set = 0, binding = 0) uniform texture2D t_source;
layout(set = 0, binding = 1, rgba8) uniform writeonly image2D o_view;
// debug_view.Params as Settings.pack() writes it: range is a vec2, 8-aligned in both layouts
layout(set = 0, binding = 2, std140) uniform Params {
    int channel;
    vec2 range;
} u_params;

vec4 load_source(ivec2 p) {
#ifdef DEPTH_SOURCE
    float d = texelFetch(t_source, p, 0).r;
    return vec4(d, d, d, 1.0);
#else
    return texelFetch(t_source, p, 0);
#endif
}

float window(float v) {
    return clamp((v - u_params.range.x) / (u_params.range.y - u_params.range.x), 0.0, 1.0);
}

// Mikhailov's polynomial fit of the turbo colour map
vec3 turbo(float x) {
    vec4 v4 = vec4(1.0, x, x * x, x * x * x);
    vec2 v2 = v4.zw * v4.z;
    return vec3(
        dot(v4, vec4(0.13572138, 4.61539260, -42.66032258, 132.13108234)) +
            dot(v2, vec2(-152.94239396, 59.28637943)),
        dot(v4, vec4(0.09140261, 2.19418839, 4.84296658, -14.18503333)) +
            dot(v2, vec2(4.27729857, 2.82956604)),
        dot(v4, vec4(0.10667330, 12.64194608, -60.58204836, 110.36276771)) +
            dot(v2, vec2(-89.90310912, 27.34824973)));
}

void main() {
    uvec2 size = uvec2(imageSize(o_view));
    if (gl_GlobalInvocationID.x >= size.x || gl_GlobalInvocationID.y >= size.y) {
        return;
    }
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    vec4 s = load_source(p);
    vec4 o = vec4(0.0, 0.0, 0.0, 1.0);
    if (MODE == 0) {
#ifdef SRGB_SOURCE
        o = vec4(srgb_encode(clamp(s.rgb, vec3(0.0), vec3(1.0))), s.a);
#else
        o = clamp(s, vec4(0.0), vec4(1.0));
#endif
    } else if (MODE == 1) {
        o = vec4(s.xyz * 0.5 + 0.5, 1.0);
    } else if (MODE == 2) {
#ifdef LINEAR_DEPTH
        // perspective depth d = f (z - n) / (z (f - n)) inverted for view distance z
        float n = camera.near_far.x;
        float f = camera.near_far.y;
        float z = n * f / (f - s.x * (f - n));
        o = vec4(vec3(window((z - n) / (f - n))), 1.0);
#endif
    } else {
        o = vec4(clamp(turbo(window(s[clamp(u_params.channel, 0, 3)])), vec3(0.0), vec3(1.0)),
                 1.0);
    }
    imageStore(o_view, p, o);
}
