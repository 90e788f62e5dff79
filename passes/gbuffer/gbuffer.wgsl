#include "mesh.wgsl"

struct VertexOut {
    // invariant: the same expression as depth_prepass.wgsl, evaluated identically, so
    // less-equal against the prepass depth passes exactly where this surface is nearest
    @builtin(position) @invariant clip: vec4f,
    @location(0) normal: vec3f,
    @location(1) uv: vec2f,
    @location(2) tangent: vec4f,
};

struct GBuffer {
    @location(0) albedo: vec4f,
    @location(1) normal: vec4f,
    @location(2) material: vec4f,
    @location(3) emissive: vec4f,
};

@vertex
fn vs_main(v: VertexIn) -> VertexOut {
    var o: VertexOut;
    o.clip = camera.view_proj * (instance.model * vec4f(v.position, 1.0));
    o.normal = (instance.normal * vec4f(v.normal, 0.0)).xyz;
    o.tangent = vec4f((instance.model * vec4f(v.tangent.xyz, 0.0)).xyz, v.tangent.w);
    o.uv = v.uv;
    return o;
}

@fragment
fn fs_main(i: VertexOut) -> GBuffer {
    let s = surface(i.uv, i.normal, i.tangent);
    if (material.flags.x == 1u && s.base_color.a < material.params.w) {
        discard;
    }
    var g: GBuffer;
    g.albedo = vec4f(s.base_color.rgb, 1.0);
    g.normal = vec4f(s.normal, 1.0);
    g.material = vec4f(s.occlusion, s.roughness, s.metallic, 1.0);
    g.emissive = vec4f(s.emissive, 1.0);
    return g;
}
