#include "scene.wgsl"
#include "pbr.wgsl"
#include "shadow.wgsl"

struct Params {
    shadow_bias: f32,
    ambient: f32,
};

@group(0) @binding(0) var t_albedo: texture_2d<f32>;
@group(0) @binding(1) var t_normal: texture_2d<f32>;
@group(0) @binding(2) var t_material: texture_2d<f32>;
@group(0) @binding(3) var t_emissive: texture_2d<f32>;
@group(0) @binding(4) var t_depth: texture_depth_2d;
@group(0) @binding(5) var o_hdr: texture_storage_2d<rgba16float, write>;
@group(0) @binding(6) var<uniform> u_params: Params;
#ifdef HAS_SHADOW
@group(0) @binding(7) var t_shadow: texture_depth_2d;
@group(0) @binding(8) var s_shadow: sampler_comparison;
#endif
#ifdef HAS_AO
@group(0) @binding(9) var t_ao: texture_2d<f32>;
@group(0) @binding(10) var s_linear: sampler;
#endif
#ifdef HAS_VISIBILITY
// screen-space shadows (rt_shadows): bit i set where light i reaches the pixel
@group(0) @binding(11) var t_visibility: texture_2d<u32>;
#endif

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3u) {
    let size = textureDimensions(o_hdr);
    if (id.x >= size.x || id.y >= size.y) {
        return;
    }
    let px = vec2i(id.xy);
    let depth = textureLoad(t_depth, px, 0);
    if (depth >= 1.0) {
        // background: alpha 0, painted by tonemap as in the forward path
        textureStore(o_hdr, px, vec4f(0.0));
        return;
    }
    let base = textureLoad(t_albedo, px, 0).rgb;
    let n = normalize(textureLoad(t_normal, px, 0).xyz);
    let m = textureLoad(t_material, px, 0);
    let emissive = textureLoad(t_emissive, px, 0).rgb;
    let p = world_from_depth(vec2f(id.xy) + 0.5, vec2f(size), depth);
    let v = normalize(camera.position.xyz - p);
    var ao = m.r;
#ifdef HAS_AO
    ao *= textureSampleLevel(t_ao, s_linear, (vec2f(id.xy) + 0.5) / vec2f(size), 0.0).r;
#endif
    var color = emissive + base * lights.ambient.rgb * u_params.ambient * ao;
#ifdef HAS_VISIBILITY
    let visible = textureLoad(t_visibility, px, 0).r;
#endif
    for (var i = 0u; i < lights.count.x; i++) {
        var l: vec3f;
        var e = light_at(i, p, &l);
#ifdef HAS_VISIBILITY
        e *= f32((visible >> i) & 1u);
#endif
#ifdef HAS_SHADOW
        if (i == lights.count.y) {
            e *= sun_shadow(t_shadow, s_shadow, p, n, l, u_params.shadow_bias);
        }
#endif
        color += brdf(base, m.b, m.g, n, v, l, e);
    }
    textureStore(o_hdr, px, vec4f(color, 1.0));
}
