#version 460
// TAA resolve of linear HDR color: last frame's result reprojected through the motion
// vectors, clipped to this frame's 3x3 neighbourhood in YCoCg, blended with this frame's
// jittered sample. CLAMP: 0 off, 1 min/max box (a clamp), 2 variance box (a clip toward
// the mean). Alpha is coverage (0 where nothing is drawn: tonemap paints the sky there)
// and color is premultiplied by it (0 there), so both resolve alike: an edge against the
// sky keeps a fractional coverage.
#extension GL_EXT_samplerless_texture_functions : require  // texelFetch on texture2D
#include "scene.glsl"   // set 1: this frame's (jittered) camera
#include "motion.glsl"  // set 0 binding 0: last frame's matrices, both frames' jitter
#include "color.glsl"

#ifndef CLAMP
#define CLAMP 2
#endif

layout(local_size_x = 8, local_size_y = 8) in;

layout(set = 0, binding = 1) uniform texture2D t_hdr;
layout(set = 0, binding = 2) uniform texture2D t_velocity;
layout(set = 0, binding = 3) uniform texture2D t_depth;
layout(set = 0, binding = 4) uniform texture2D t_history;
layout(set = 0, binding = 5) uniform texture2D t_history_depth;
layout(set = 0, binding = 6) uniform sampler s_linear;
layout(set = 0, binding = 7, rgba16f) uniform writeonly image2D o_color;
// taa.Params as Settings.pack() writes it (clamp is a define): four scalars, std140 offsets
layout(set = 0, binding = 8, std140) uniform Params {
    float feedback;
    int jitter;
    float variance_gamma;
    float depth_tolerance;
} u_params;
layout(set = 0, binding = 9, std140) uniform Frame {
    uint has_history;  // 0 on the executor's first frame
} u_frame;

// color as YCoCg, coverage as the fourth component
vec4 to_ycocg(vec4 c) {
    return vec4(0.25 * c.r + 0.5 * c.g + 0.25 * c.b, 0.5 * c.r - 0.5 * c.b,
                -0.25 * c.r + 0.5 * c.g - 0.25 * c.b, c.a);
}

vec4 from_ycocg(vec4 c) {
    float t = c.x - c.z;
    return vec4(t + c.y, c.x + c.z, t - c.y, c.w);
}

// h's color moved toward the box's centre until it is inside (a clip keeps its hue, a
// clamp not), its coverage clamped to the box's own. The box grows by the rounding of
// half floats, so a history equal to this frame's sample but for rounding stays as it is.
vec4 clip_to_box(vec4 h, vec4 lo, vec4 hi) {
    vec3 centre = 0.5 * (lo.xyz + hi.xyz);
    // (relative to luma: chroma near 0 carries the rounding of the luma's channels)
    float luma = max(abs(lo.x), abs(hi.x));
    vec3 extent = 0.5 * (hi.xyz - lo.xyz) + 2e-3 * luma + 1e-5;
    vec3 d = h.xyz - centre;
    vec3 r = abs(d / extent);
    float m = max(r.x, max(r.y, r.z));
    return vec4(m > 1.0 ? centre + d / m : h.xyz, clamp(h.w, lo.w, hi.w));
}

// last frame's result at pixel position p, Catmull-Rom filtered (sharper than bilinear:
// resampled every frame, bilinear history blurs under motion), as nine bilinear taps
vec4 history_at(vec2 p, vec2 size) {
    vec2 centre = floor(p - 0.5) + 0.5;
    vec2 f = p - centre;
    vec2 w0 = f * (-0.5 + f * (1.0 - 0.5 * f));
    vec2 w1 = 1.0 + f * f * (-2.5 + 1.5 * f);
    vec2 w2 = f * (0.5 + f * (2.0 - 1.5 * f));
    vec2 w3 = f * f * (-0.5 + 0.5 * f);
    vec2 w12 = w1 + w2;
    vec2 t0 = (centre - 1.0) / size;
    vec2 t3 = (centre + 2.0) / size;
    vec2 t12 = (centre + w2 / w12) / size;
    vec4 sum = vec4(0.0);
    vec2 ts[3] = vec2[3](t0, t12, t3);
    vec2 ws[3] = vec2[3](w0, w12, w3);
    for (int j = 0; j < 3; j++) {
        for (int i = 0; i < 3; i++) {
            sum += textureLod(sampler2D(t_history, s_linear), vec2(ts[i].x, ts[j].y), 0.0) *
                (ws[i].x * ws[j].y);
        }
    }
    return sum;
}

// view distance of a depth value (this projection: 0 at near, 1 at far)
float linear_depth(float d) {
    float n = camera.near_far.x, f = camera.near_far.y;
    return n * f / (f - d * (f - n));
}

// whether last frame's depth around pixel position p (unjittered) shows a surface at
// view distance `expected` (relative tolerance), or background where `expected` is < 0:
// any of the 3x3 texels around it (an edge's jittered samples fall either side of it)
bool history_matches(vec2 p, float expected, ivec2 size) {
    // texel centre c of last frame's depth was sampled at c - jitter there
    ivec2 base = ivec2(floor(p + motion.jitter.zw)) - 1;
    for (int k = 0; k < 9; k++) {
        ivec2 t = clamp(base + ivec2(k % 3, k / 3), ivec2(0), size - 1);
        float d = texelFetch(t_history_depth, t, 0).r;
        bool match = expected < 0.0 ? d >= 1.0 : d < 1.0 &&
            abs(linear_depth(d) - expected) <= u_params.depth_tolerance * expected;
        if (match) {
            return true;
        }
    }
    return false;
}

void main() {
    ivec2 size = imageSize(o_color);
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (px.x >= size.x || px.y >= size.y) {
        return;
    }
    vec4 current = texelFetch(t_hdr, px, 0);
    vec4 result = current;
    if (u_frame.has_history != 0u && u_params.feedback > 0.0) {
        // the neighbourhood's colors, and its nearest surface (whose motion an edge takes)
        vec4 m1 = vec4(0.0), m2 = vec4(0.0);
        vec4 lo = vec4(1e30), hi = vec4(-1e30);
        float nearest = 2.0;
        ivec2 nearest_px = px;
        for (int dy = -1; dy <= 1; dy++) {
            for (int dx = -1; dx <= 1; dx++) {
                ivec2 q = clamp(px + ivec2(dx, dy), ivec2(0), size - 1);
                vec4 c = to_ycocg(texelFetch(t_hdr, q, 0));
                m1 += c;
                m2 += c * c;
                lo = min(lo, c);
                hi = max(hi, c);
                float z = texelFetch(t_depth, q, 0).r;
                if (z < nearest) {
                    nearest = z;
                    nearest_px = q;
                }
            }
        }
        vec2 fsize = vec2(size);
        vec2 centre = vec2(px) + 0.5;
        float depth = texelFetch(t_depth, px, 0).r;
        // this pixel's surface (the jittered inverse finds it at the jittered centre)
        vec3 here = world_from_depth(centre, fsize, min(depth, 1.0));
        vec4 prev_clip = motion.prev_view_proj * vec4(here, 1.0);
        vec2 velocity = texelFetch(t_velocity, nearest_px, 0).xy;
        if (nearest >= 1.0) {  // nothing drawn: the camera's motion of the far plane
            velocity = pixel_of_clip(prev_clip, fsize) -
                pixel_of_clip(motion.view_proj * vec4(here, 1.0), fsize);
        }
        // unjittered positions: this pixel's centre is where the jitter took its sample from
        vec2 prev = centre + velocity;
        vec2 own = centre + (depth >= 1.0 ? velocity : texelFetch(t_velocity, px, 0).xy);
        bool valid = all(greaterThanEqual(prev, vec2(0.0))) && all(lessThan(prev, fsize)) &&
            prev_clip.w > 0.0;
        if (valid && u_params.depth_tolerance > 0.0) {
            float expected = depth >= 1.0 ? -1.0 : prev_clip.w;  // view distance last frame
            valid = history_matches(own, expected, size);
        }
        if (valid) {
            vec4 history = to_ycocg(history_at(prev, fsize));
#if CLAMP == 1
            history = clamp(history, lo, hi);
#elif CLAMP == 2
            // the box around the mean, stretched to hold this frame's sample: a pixel
            // unlike its neighbours (a highlight) is not pulled toward them
            vec4 mean = m1 / 9.0;
            vec4 sigma = sqrt(max(m2 / 9.0 - mean * mean, 0.0));
            vec4 here_c = to_ycocg(current);
            history = clip_to_box(history, min(mean - u_params.variance_gamma * sigma, here_c),
                                  max(mean + u_params.variance_gamma * sigma, here_c));
#endif
            vec4 h = from_ycocg(history);
            if (!any(isnan(h)) && !any(isinf(h))) {
                h = vec4(max(h.rgb, vec3(0.0)), clamp(h.a, 0.0, 1.0));
                float wc = (1.0 - u_params.feedback) / (1.0 + luminance(current.rgb));
                float wh = u_params.feedback / (1.0 + luminance(h.rgb));
                result = (current * wc + h * wh) / (wc + wh);
            }
        }
    }
    imageStore(o_color, px, result);
}
