#version 460
// FXAA 3.11 quality (Lottes), preset 39 step sizes, on
// display-encoded color
#extension GL_EXT_samplerless_texture_functions : require  // texelFetch on texture2D
#include "color.glsl"

layout(local_size_x = 8, local_size_y = 8) in;

layout(set = 0, binding = 0) uniform texture2D t_ldr;
layout(set = 0, binding = 1) uniform sampler s_linear;
layout(set = 0, binding = 2, rgba8) uniform writeonly image2D o_color;
// fxaa.Params as Settings.pack() writes it: four scalars, the same offsets in std140
layout(set = 0, binding = 3, std140) uniform Params {
    float edge_threshold;
    float edge_threshold_min;
    float subpixel;
    int search_steps;
} u_params;

const float STEPS[12] = float[12](1.0, 1.0, 1.0, 1.0, 1.0, 1.5, 2.0, 2.0, 2.0, 2.0, 4.0, 8.0);

float luma_at(ivec2 p) {
    ivec2 size = textureSize(t_ldr, 0);
    return luminance(texelFetch(t_ldr, clamp(p, ivec2(0), size - 1), 0).rgb);
}

float luma_uv(vec2 uv) {
    return luminance(textureLod(sampler2D(t_ldr, s_linear), uv, 0.0).rgb);
}

void main() {
    uvec2 size = uvec2(imageSize(o_color));
    if (gl_GlobalInvocationID.x >= size.x || gl_GlobalInvocationID.y >= size.y) {
        return;
    }
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    vec4 center = texelFetch(t_ldr, px, 0);
    float lc = luminance(center.rgb);
    // the 3x3 neighbourhood: n s w e are -y +y -x +x in texel rows
    float ln = luma_at(px + ivec2(0, -1));
    float ls = luma_at(px + ivec2(0, 1));
    float lw = luma_at(px + ivec2(-1, 0));
    float le = luma_at(px + ivec2(1, 0));
    float lmin = min(lc, min(min(ln, ls), min(lw, le)));
    float lmax = max(lc, max(max(ln, ls), max(lw, le)));
    float range = lmax - lmin;
    if (range < max(u_params.edge_threshold_min, lmax * u_params.edge_threshold)) {
        imageStore(o_color, px, center);
        return;
    }
    float lnw = luma_at(px + ivec2(-1, -1));
    float lne = luma_at(px + ivec2(1, -1));
    float lsw = luma_at(px + ivec2(-1, 1));
    float lse = luma_at(px + ivec2(1, 1));

    // is the edge horizontal (luma changes along y) or vertical (along x)?
    float horizontal_edge = abs(-2.0 * lw + lnw + lsw) + 2.0 * abs(-2.0 * lc + ln + ls) +
        abs(-2.0 * le + lne + lse);
    float vertical_edge = abs(-2.0 * ln + lnw + lne) + 2.0 * abs(-2.0 * lc + lw + le) +
        abs(-2.0 * ls + lsw + lse);
    bool horizontal = horizontal_edge >= vertical_edge;

    // which side of the pixel the edge lies on: the neighbour with the steeper gradient
    vec2 texel = 1.0 / vec2(size);
    float l1 = horizontal ? ln : lw;
    float l2 = horizontal ? ls : le;
    float g1 = l1 - lc;
    float g2 = l2 - lc;
    bool first = abs(g1) >= abs(g2);
    float gradient = 0.25 * max(abs(g1), abs(g2));
    float across = horizontal ? texel.y : texel.x;
    float edge_luma = 0.5 * (l2 + lc);
    if (first) {
        across = -across;
        edge_luma = 0.5 * (l1 + lc);
    }

    // walk both ways along the edge, on the seam between the two sides, until luma leaves it
    vec2 uv = (vec2(px) + 0.5) * texel;
    vec2 seam = uv + (horizontal ? vec2(0.0, 0.5 * across) : vec2(0.5 * across, 0.0));
    vec2 along = horizontal ? vec2(texel.x, 0.0) : vec2(0.0, texel.y);
    vec2 uv1 = seam - along;
    vec2 uv2 = seam + along;
    float end1 = luma_uv(uv1) - edge_luma;
    float end2 = luma_uv(uv2) - edge_luma;
    bool done1 = abs(end1) >= gradient;
    bool done2 = abs(end2) >= gradient;
    int steps = clamp(u_params.search_steps, 1, 12);
    for (int i = 1; i < steps && !(done1 && done2); i++) {
        if (!done1) {
            uv1 -= along * STEPS[i];
            end1 = luma_uv(uv1) - edge_luma;
            done1 = abs(end1) >= gradient;
        }
        if (!done2) {
            uv2 += along * STEPS[i];
            end2 = luma_uv(uv2) - edge_luma;
            done2 = abs(end2) >= gradient;
        }
    }

    // blend across the edge by how close the pixel is to the nearer end, if the luma
    // there varies the way the centre's does (else the pixel is on the far side of a corner)
    float d1 = horizontal ? uv.x - uv1.x : uv.y - uv1.y;
    float d2 = horizontal ? uv2.x - uv.x : uv2.y - uv.y;
    bool nearer1 = d1 < d2;
    float edge_offset = 0.5 - min(d1, d2) / (d1 + d2);
    float near_end = nearer1 ? end1 : end2;
    bool valid = (near_end < 0.0) != (lc < edge_luma);
    float offset = valid ? edge_offset : 0.0;

    // subpixel aliasing: the 3x3 low-pass's difference from the centre, eased
    float average = (2.0 * (ln + ls + lw + le) + lnw + lne + lsw + lse) / 12.0;
    float sub = clamp(abs(average - lc) / range, 0.0, 1.0);
    float eased = (-2.0 * sub + 3.0) * sub * sub;
    offset = max(offset, eased * eased * u_params.subpixel);

    vec2 at = uv + (horizontal ? vec2(0.0, offset * across) : vec2(offset * across, 0.0));
    imageStore(o_color, px,
               vec4(textureLod(sampler2D(t_ldr, s_linear), at, 0.0).rgb, center.a));
}
