#version 460
// linear HDR to display-encoded LDR (tonemap.py)
#extension GL_EXT_samplerless_texture_functions : require  // texelFetch on texture2D
#include "color.glsl"

layout(local_size_x = 8, local_size_y = 8) in;

layout(set = 0, binding = 0) uniform texture2D t_hdr;
layout(set = 0, binding = 1, rgba8) uniform writeonly image2D o_ldr;
// tonemap.Params as Settings.pack() writes it: sky is a vec3, 16-aligned in both layouts;
// std140 ends the block at 28, WGSL rounds the struct to 32 (the uploaded size)
layout(set = 0, binding = 2, std140) uniform Params {
    float exposure;
    int curve;
    vec3 sky;
} u_params;

// Narkowicz's fit of the ACES reference rendering transform
vec3 aces(vec3 x) {
    return clamp((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), vec3(0.0), vec3(1.0));
}

void main() {
    uvec2 id = gl_GlobalInvocationID.xy;
    uvec2 size = uvec2(imageSize(o_ldr));
    if (id.x >= size.x || id.y >= size.y) {
        return;
    }
    vec4 texel = texelFetch(t_hdr, ivec2(id), 0);
    // passes that leave the background empty (alpha 0) get the sky color; a coverage
    // between (a temporal resolve's edge against the background) is color premultiplied
    // by it, over the sky
    vec3 under = texel.a >= 1.0 ? texel.rgb : texel.rgb + (1.0 - texel.a) * u_params.sky;
    vec3 hdr = (texel.a > 0.0 ? under : u_params.sky) * u_params.exposure;
    vec3 c = clamp(hdr, vec3(0.0), vec3(1.0));
    if (u_params.curve == 1) {
        c = aces(hdr);
    }
    imageStore(o_ldr, ivec2(id), vec4(srgb_encode(c), 1.0));
}
