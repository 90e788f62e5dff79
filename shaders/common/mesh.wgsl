// scene geometry: vertex layout, material (group 2) and instance (group 3)
#include "scene.wgsl"

struct VertexIn {
    @location(0) position: vec3f,
    @location(1) normal: vec3f,
    @location(2) uv: vec2f,
    @location(3) tangent: vec4f,
};

struct Material {
    base_color: vec4f,
    emissive: vec4f,   // w: normal scale
    params: vec4f,     // metallic, roughness, occlusion strength, alpha cutoff
    flags: vec4u,      // x: alpha mode (0 opaque, 1 mask, 2 blend)
};

struct Instance {
    model: mat4x4f,
    normal: mat4x4f,   // inverse transpose of the model matrix
};

@group(2) @binding(0) var<uniform> material: Material;
@group(2) @binding(1) var base_color_tex: texture_2d<f32>;
@group(2) @binding(2) var metal_rough_tex: texture_2d<f32>;
@group(2) @binding(3) var normal_tex: texture_2d<f32>;
@group(2) @binding(4) var occlusion_tex: texture_2d<f32>;
@group(2) @binding(5) var emissive_tex: texture_2d<f32>;
@group(2) @binding(6) var material_sampler: sampler;
@group(3) @binding(0) var<uniform> instance: Instance;

struct Surface {
    base_color: vec4f,
    normal: vec3f,
    metallic: f32,
    roughness: f32,
    occlusion: f32,
    emissive: vec3f,
};

// the material at a point, with the normal map applied in world space
fn surface(uv: vec2f, n_in: vec3f, t_in: vec4f) -> Surface {
    var s: Surface;
    s.base_color = material.base_color * textureSample(base_color_tex, material_sampler, uv);
    let mr = textureSample(metal_rough_tex, material_sampler, uv);
    s.metallic = clamp(material.params.x * mr.b, 0.0, 1.0);
    s.roughness = clamp(material.params.y * mr.g, 0.045, 1.0);
    let ao = textureSample(occlusion_tex, material_sampler, uv).r;
    s.occlusion = mix(1.0, ao, material.params.z);
    s.emissive = material.emissive.rgb * textureSample(emissive_tex, material_sampler, uv).rgb;
    let n = normalize(n_in);
    var t = t_in.xyz - n * dot(n, t_in.xyz);
    if (dot(t, t) < 1e-12) {
        s.normal = n;
        return s;
    }
    t = normalize(t);
    let b = cross(n, t) * t_in.w;
    var m = textureSample(normal_tex, material_sampler, uv).xyz * 2.0 - 1.0;
    m = vec3f(m.xy * material.emissive.w, m.z);
    s.normal = normalize(m.x * t + m.y * b + m.z * n);
    return s;
}
