#include "mesh.wgsl"
#include "pbr.wgsl"
#include "shadow.wgsl"

struct Params {
    shadow_bias: f32,
    ambient: f32,
    prepass: u32,  // host-side switch, here so the struct matches Settings.pack()
};

@group(0) @binding(0) var<uniform> u_params: Params;
#ifdef HAS_SHADOW
@group(0) @binding(1) var t_shadow: texture_depth_2d;
@group(0) @binding(2) var s_shadow: sampler_comparison;
#endif

struct VertexOut {
    // invariant: the same expression as depth_prepass.wgsl, evaluated identically, so
    // less-equal against the prepass depth passes exactly where this surface is nearest
    @builtin(position) @invariant clip: vec4f,
    @location(0) world: vec3f,
    @location(1) normal: vec3f,
    @location(2) uv: vec2f,
    @location(3) tangent: vec4f,
};

@vertex
fn vs_main(v: VertexIn) -> VertexOut {
    var o: VertexOut;
    let w = instance.model * vec4f(v.position, 1.0);
    o.clip = camera.view_proj * w;
    o.world = w.xyz;
    o.normal = (instance.normal * vec4f(v.normal, 0.0)).xyz;
    o.tangent = vec4f((instance.model * vec4f(v.tangent.xyz, 0.0)).xyz, v.tangent.w);
    o.uv = v.uv;
    return o;
}

@fragment
fn fs_main(i: VertexOut) -> @location(0) vec4f {
    let s = surface(i.uv, i.normal, i.tangent);
    if (material.flags.x == 1u && s.base_color.a < material.params.w) {
        discard;
    }
    let v = normalize(camera.position.xyz - i.world);
    var color = s.emissive + s.base_color.rgb * lights.ambient.rgb * u_params.ambient * s.occlusion;
    for (var k = 0u; k < lights.count.x; k++) {
        var l: vec3f;
        var e = light_at(k, i.world, &l);
#ifdef HAS_SHADOW
        if (k == lights.count.y) {
            e *= sun_shadow(t_shadow, s_shadow, i.world, s.normal, l, u_params.shadow_bias);
        }
#endif
        color += brdf(s.base_color.rgb, s.metallic, s.roughness, s.normal, v, l, e);
    }
    return vec4f(color, 1.0);
}
