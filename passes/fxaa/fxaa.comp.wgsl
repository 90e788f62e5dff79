// FXAA 3.11 quality (Lottes), preset 39 step sizes, on display-encoded color
#include "color.wgsl"

struct Params {
    edge_threshold: f32,
    edge_threshold_min: f32,
    subpixel: f32,
    search_steps: i32,
};

@group(0) @binding(0) var t_ldr: texture_2d<f32>;
@group(0) @binding(1) var s_linear: sampler;
@group(0) @binding(2) var o_color: texture_storage_2d<rgba8unorm, write>;
@group(0) @binding(3) var<uniform> u_params: Params;

const STEPS: array<f32, 12> = array<f32, 12>(1.0, 1.0, 1.0, 1.0, 1.0, 1.5, 2.0, 2.0, 2.0, 2.0,
                                             4.0, 8.0);

fn luma_at(p: vec2i) -> f32 {
    let size = vec2i(textureDimensions(t_ldr));
    return luminance(textureLoad(t_ldr, clamp(p, vec2i(0), size - 1), 0).rgb);
}

fn luma_uv(uv: vec2f) -> f32 {
    return luminance(textureSampleLevel(t_ldr, s_linear, uv, 0.0).rgb);
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3u) {
    let size = textureDimensions(o_color);
    if (id.x >= size.x || id.y >= size.y) {
        return;
    }
    let px = vec2i(id.xy);
    let center = textureLoad(t_ldr, px, 0);
    let lc = luminance(center.rgb);
    // the 3x3 neighbourhood: n s w e are -y +y -x +x in texel rows
    let ln = luma_at(px + vec2i(0, -1));
    let ls = luma_at(px + vec2i(0, 1));
    let lw = luma_at(px + vec2i(-1, 0));
    let le = luma_at(px + vec2i(1, 0));
    let lmin = min(lc, min(min(ln, ls), min(lw, le)));
    let lmax = max(lc, max(max(ln, ls), max(lw, le)));
    let range = lmax - lmin;
    if (range < max(u_params.edge_threshold_min, lmax * u_params.edge_threshold)) {
        textureStore(o_color, px, center);
        return;
    }
    let lnw = luma_at(px + vec2i(-1, -1));
    let lne = luma_at(px + vec2i(1, -1));
    let lsw = luma_at(px + vec2i(-1, 1));
    let lse = luma_at(px + vec2i(1, 1));

    // is the edge horizontal (luma changes along y) or vertical (along x)?
    let horizontal_edge = abs(-2.0 * lw + lnw + lsw) + 2.0 * abs(-2.0 * lc + ln + ls) +
        abs(-2.0 * le + lne + lse);
    let vertical_edge = abs(-2.0 * ln + lnw + lne) + 2.0 * abs(-2.0 * lc + lw + le) +
        abs(-2.0 * ls + lsw + lse);
    let horizontal = horizontal_edge >= vertical_edge;

    // which side of the pixel the edge lies on: the neighbour with the steeper gradient
    let texel = 1.0 / vec2f(size);
    let l1 = select(lw, ln, horizontal);
    let l2 = select(le, ls, horizontal);
    let g1 = l1 - lc;
    let g2 = l2 - lc;
    let first = abs(g1) >= abs(g2);
    let gradient = 0.25 * max(abs(g1), abs(g2));
    var across = select(texel.x, texel.y, horizontal);
    var edge_luma = 0.5 * (l2 + lc);
    if (first) {
        across = -across;
        edge_luma = 0.5 * (l1 + lc);
    }

    // walk both ways along the edge, on the seam between the two sides, until luma leaves it
    let uv = (vec2f(px) + 0.5) * texel;
    let seam = uv + select(vec2f(0.5 * across, 0.0), vec2f(0.0, 0.5 * across), horizontal);
    let along = select(vec2f(0.0, texel.y), vec2f(texel.x, 0.0), horizontal);
    var uv1 = seam - along;
    var uv2 = seam + along;
    var end1 = luma_uv(uv1) - edge_luma;
    var end2 = luma_uv(uv2) - edge_luma;
    var done1 = abs(end1) >= gradient;
    var done2 = abs(end2) >= gradient;
    let steps = clamp(u_params.search_steps, 1, 12);
    for (var i = 1; i < steps && !(done1 && done2); i++) {
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
    let d1 = select(uv.y - uv1.y, uv.x - uv1.x, horizontal);
    let d2 = select(uv2.y - uv.y, uv2.x - uv.x, horizontal);
    let nearer1 = d1 < d2;
    let edge_offset = 0.5 - min(d1, d2) / (d1 + d2);
    let near_end = select(end2, end1, nearer1);
    let valid = (near_end < 0.0) != (lc < edge_luma);
    var offset = select(0.0, edge_offset, valid);

    // subpixel aliasing: the 3x3 low-pass's difference from the centre, eased
    let average = (2.0 * (ln + ls + lw + le) + lnw + lne + lsw + lse) / 12.0;
    let sub = clamp(abs(average - lc) / range, 0.0, 1.0);
    let eased = (-2.0 * sub + 3.0) * sub * sub;
    offset = max(offset, eased * eased * u_params.subpixel);

    let at = uv + select(vec2f(offset * across, 0.0), vec2f(0.0, offset * across), horizontal);
    textureStore(o_color, px, vec4f(textureSampleLevel(t_ldr, s_linear, at, 0.0).rgb, center.a));
}
