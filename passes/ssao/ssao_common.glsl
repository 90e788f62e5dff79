// what both ssao dispatches share: settings and view-space
// positions from the depth buffer
#ifndef RFW_SSAO_COMMON_GLSL
#define RFW_SSAO_COMMON_GLSL
#include "scene.glsl"

// WGSL binds a depth format as texture_depth_2d (DEPTH_TEXTURE), a copy as texture_2d<f32>:
// both are a sampled image here, whose depth is .r
layout(set = 0, binding = 0) uniform texture2D t_depth;
// ssao.Params as Settings.pack() writes it: 28 bytes of scalars, the same offsets in std140
layout(set = 0, binding = 3, std140) uniform Params {
    float radius;
    int samples;
    float intensity;
    float power;
    float bias;
    int blur_radius;
    float blur_depth;
} u_params;

float load_depth(ivec2 px) {
    return texelFetch(t_depth, px, 0).r;
}

// view-space position of the centre of full-resolution pixel px at depth d
vec3 view_position(ivec2 px, float d) {
    vec2 size = vec2(textureSize(t_depth, 0));
    vec3 world = world_from_depth(vec2(px) + 0.5, size, d);
    return (camera.view * vec4(world, 1.0)).xyz;
}

// the full-resolution pixel a half-resolution texel stands for
ivec2 source_pixel(uvec2 id) {
    return min(ivec2(id * 2u), textureSize(t_depth, 0) - 1);
}

#endif
