// depth-aware box blur of the raw occlusion: neighbours on other surfaces get no weight
#include "ssao_common.wgsl"

@group(0) @binding(1) var t_ao: texture_storage_2d<r32float, read>;
@group(0) @binding(2) var o_ao: texture_storage_2d<rgba16float, write>;

const MAX_RADIUS: i32 = 8;

fn view_depth(id: vec2i) -> f32 {
    let px = source_pixel(vec2u(id));
    let d = load_depth(px);
    return select(-view_position(px, d).z, -1.0, d >= 1.0);  // -1: background
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3u) {
    let size = vec2i(textureDimensions(o_ao));
    let c = vec2i(id.xy);
    if (c.x >= size.x || c.y >= size.y) {
        return;
    }
    let zc = view_depth(c);
    let r = clamp(u_params.blur_radius, 0, MAX_RADIUS);
    if (zc < 0.0 || r == 0) {
        textureStore(o_ao, c, vec4f(textureLoad(t_ao, c).r));
        return;
    }
    let tolerance = max(u_params.blur_depth, 1e-6) * zc;
    var sum = 0.0;
    var weight = 0.0;
    for (var y = -r; y <= r; y++) {
        for (var x = -r; x <= r; x++) {
            let q = c + vec2i(x, y);
            if (any(q < vec2i(0)) || any(q >= size)) {
                continue;
            }
            let zq = view_depth(q);
            let w = select(max(0.0, 1.0 - abs(zq - zc) / tolerance), 0.0, zq < 0.0);
            sum += w * textureLoad(t_ao, q).r;
            weight += w;
        }
    }
    // the centre always has weight 1, so weight > 0
    textureStore(o_ao, c, vec4f(sum / weight));
}
