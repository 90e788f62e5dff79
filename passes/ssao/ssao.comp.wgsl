// occlusion of a normal-oriented hemisphere, tested against the depth buffer in view space
#include "ssao_common.wgsl"

@group(0) @binding(1) var t_normal: texture_2d<f32>;
@group(0) @binding(2) var o_ao: texture_storage_2d<r32float, write>;

const GOLDEN_ANGLE: f32 = 2.39996323;
const TAU: f32 = 6.28318531;
const MAX_SAMPLES: i32 = 64;

// Jimenez's interleaved gradient noise: a per-pixel rotation with little low-frequency content
fn ign(p: vec2f) -> f32 {
    return fract(52.9829189 * fract(dot(p, vec2f(0.06711056, 0.00583715))));
}

// an orthonormal basis around unit n (Duff et al. 2017, branchless)
fn basis(n: vec3f) -> mat3x3f {
    let s = select(-1.0, 1.0, n.z >= 0.0);
    let a = -1.0 / (s + n.z);
    let b = n.x * n.y * a;
    return mat3x3f(vec3f(1.0 + s * n.x * n.x * a, s * b, -s * n.x),
                   vec3f(b, s + n.y * n.y * a, -n.y), n);
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3u) {
    let size = textureDimensions(o_ao);
    if (id.x >= size.x || id.y >= size.y) {
        return;
    }
    let px = source_pixel(id.xy);
    let d = load_depth(px);
    if (d >= 1.0) {
        textureStore(o_ao, vec2i(id.xy), vec4f(1.0));
        return;
    }
    let p = view_position(px, d);
    let n = normalize((camera.view * vec4f(textureLoad(t_normal, px, 0).xyz, 0.0)).xyz);
    let tbn = basis(n);
    let full = vec2f(textureDimensions(t_depth));
    let count = clamp(u_params.samples, 1, MAX_SAMPLES);
    let rotation = TAU * ign(vec2f(px));
    var occlusion = 0.0;
    for (var k = 0; k < count; k++) {
        // cosine-weighted hemisphere: a golden-angle spiral on the disc, lifted onto it;
        // lengths follow a radical inverse so they do not correlate with elevation
        let u = (f32(k) + 0.5) / f32(count);
        let phi = f32(k) * GOLDEN_ANGLE + rotation;
        let rho = sqrt(u);
        let dir = vec3f(rho * cos(phi), rho * sin(phi), sqrt(1.0 - u));
        let t = f32(reverseBits(u32(k))) * 2.3283064e-10;
        let reach = mix(0.1, 1.0, t * t);
        let s = p + tbn * dir * (u_params.radius * reach);
        // where the sample lands on screen, and the surface the camera sees there
        let clip = camera.proj * vec4f(s, 1.0);
        let ndc = clip.xy / clip.w;
        let at = vec2f(ndc.x * 0.5 + 0.5, 0.5 - ndc.y * 0.5) * full;
        if (clip.w <= 0.0 || any(at < vec2f(0.0)) || any(at >= full)) {
            continue;
        }
        let q = vec2i(at);
        let sd = load_depth(q);
        if (sd >= 1.0) {
            continue;
        }
        let scene_z = view_position(q, sd).z;
        // view space looks down -z: a surface in front of the sample has the larger z;
        // one more than a radius nearer than p is outside the hemisphere, so it fades out
        let r = u_params.radius;
        let range = 1.0 - smoothstep(r, 2.0 * r, abs(p.z - scene_z));
        occlusion += select(0.0, range, scene_z >= s.z + u_params.bias);
    }
    let open = clamp(1.0 - u_params.intensity * occlusion / f32(count), 0.0, 1.0);
    textureStore(o_ao, vec2i(id.xy), vec4f(pow(open, u_params.power)));
}
