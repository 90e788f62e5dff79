// one texture shown as display color; MODE picks how (0 color, 1 normals, 2 depth, 3 heatmap)
#include "color.wgsl"
#ifdef LINEAR_DEPTH
#include "scene.wgsl"
#endif

struct Params {
    channel: i32,
    range: vec2f,
};

#ifdef DEPTH_SOURCE
@group(0) @binding(0) var t_source: texture_depth_2d;
#else
@group(0) @binding(0) var t_source: texture_2d<f32>;
#endif
@group(0) @binding(1) var o_view: texture_storage_2d<rgba8unorm, write>;
@group(0) @binding(2) var<uniform> u_params: Params;

fn load_source(p: vec2i) -> vec4f {
#ifdef DEPTH_SOURCE
    let d = textureLoad(t_source, p, 0);
    return vec4f(d, d, d, 1.0);
#else
    return textureLoad(t_source, p, 0);
#endif
}

fn window(v: f32) -> f32 {
    return clamp((v - u_params.range.x) / (u_params.range.y - u_params.range.x), 0.0, 1.0);
}

// Mikhailov's polynomial fit of the turbo colour map
fn turbo(x: f32) -> vec3f {
    let v4 = vec4f(1.0, x, x * x, x * x * x);
    let v2 = v4.zw * v4.z;
    return vec3f(
        dot(v4, vec4f(0.13572138, 4.61539260, -42.66032258, 132.13108234)) +
            dot(v2, vec2f(-152.94239396, 59.28637943)),
        dot(v4, vec4f(0.09140261, 2.19418839, 4.84296658, -14.18503333)) +
            dot(v2, vec2f(4.27729857, 2.82956604)),
        dot(v4, vec4f(0.10667330, 12.64194608, -60.58204836, 110.36276771)) +
            dot(v2, vec2f(-89.90310912, 27.34824973)));
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3u) {
    let size = textureDimensions(o_view);
    if (id.x >= size.x || id.y >= size.y) {
        return;
    }
    let p = vec2i(id.xy);
    let s = load_source(p);
    var out = vec4f(0.0, 0.0, 0.0, 1.0);
    if (MODE == 0) {
#ifdef SRGB_SOURCE
        out = vec4f(srgb_encode(clamp(s.rgb, vec3f(0.0), vec3f(1.0))), s.a);
#else
        out = clamp(s, vec4f(0.0), vec4f(1.0));
#endif
    } else if (MODE == 1) {
        out = vec4f(s.xyz * 0.5 + 0.5, 1.0);
    } else if (MODE == 2) {
#ifdef LINEAR_DEPTH
        // perspective depth d = f (z - n) / (z (f - n)) inverted for view distance z
        let n = camera.near_far.x;
        let f = camera.near_far.y;
        let z = n * f / (f - s.x * (f - n));
        out = vec4f(vec3f(window((z - n) / (f - n))), 1.0);
#endif
    } else {
        out = vec4f(clamp(turbo(window(s[clamp(u_params.channel, 0, 3)])), vec3f(0.0),
                          vec3f(1.0)), 1.0);
    }
    textureStore(o_view, p, out);
}
