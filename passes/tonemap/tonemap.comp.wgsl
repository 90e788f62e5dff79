#include "color.wgsl"

struct Params {
    exposure: f32,
    curve: i32,
    sky: vec3f,
};

@group(0) @binding(0) var t_hdr: texture_2d<f32>;
@group(0) @binding(1) var o_ldr: texture_storage_2d<rgba8unorm, write>;
@group(0) @binding(2) var<uniform> u_params: Params;

// Narkowicz's fit of the ACES reference rendering transform
fn aces(x: vec3f) -> vec3f {
    return clamp((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), vec3f(0.0), vec3f(1.0));
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3u) {
    let size = textureDimensions(o_ldr);
    if (id.x >= size.x || id.y >= size.y) {
        return;
    }
    let texel = textureLoad(t_hdr, vec2i(id.xy), 0);
    // passes that leave the background empty (alpha 0) get the sky color
    let hdr = select(u_params.sky, texel.rgb, texel.a > 0.0) * u_params.exposure;
    var c = clamp(hdr, vec3f(0.0), vec3f(1.0));
    if (u_params.curve == 1) {
        c = aces(hdr);
    }
    textureStore(o_ldr, vec2i(id.xy), vec4f(srgb_encode(c), 1.0));
}
