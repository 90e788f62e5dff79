// the material model, one source for every shader that turns a material into a surface:
// the G-buffer and forward fragment shaders (mesh.glsl's surface(): implicit-lod lookups of
// the bound material) and the visibility buffer's resolve (vis_resolve: any material of the
// scene, looked up with explicit gradients).
//
// the includer says how a texture is read before including this file:
//   #define MATERIAL_TEXTURE(name, uv) ...
// where name is one of base_color_tex, metal_rough_tex, normal_tex, occlusion_tex,
// emissive_tex. Without it only the types are declared (vertex shaders).
#ifndef RFW_MATERIAL_GLSL
#define RFW_MATERIAL_GLSL

// MaterialBlock's fields by value (rfw/backends/scene_data.py material_bytes: 64 bytes, the
// same in std140 and std430, so a storage buffer of them reads as the uniform block does)
struct MaterialFactors {
    vec4 base_color;
    vec4 emissive;     // w: normal scale
    vec4 params;       // metallic, roughness, occlusion strength, cutoff
    uvec4 flags;       // x: alpha mode (0 opaque, 1 mask, 2 blend), y: double-sided,
                       // z: specular factor (float bits)
};

struct Surface {
    vec4 base_color;
    vec3 normal;
    float metallic;
    float roughness;
    float occlusion;
    vec3 emissive;
};

// an alpha-masked material's coverage test: true where the surface is cut away
bool material_cut(MaterialFactors m, float alpha) {
    return m.flags.x == 1u && alpha < m.params.w;
}

#ifdef MATERIAL_TEXTURE
// the material at a point, with the normal map applied in world space
Surface material_surface(MaterialFactors m, vec2 uv, vec3 n_in, vec4 t_in) {
    Surface s;
    s.base_color = m.base_color * MATERIAL_TEXTURE(base_color_tex, uv);
    vec4 mr = MATERIAL_TEXTURE(metal_rough_tex, uv);
    s.metallic = clamp(m.params.x * mr.b, 0.0, 1.0);
    s.roughness = clamp(m.params.y * mr.g, 0.045, 1.0);
    float ao = MATERIAL_TEXTURE(occlusion_tex, uv).r;
    s.occlusion = mix(1.0, ao, m.params.z);
    s.emissive = m.emissive.rgb * MATERIAL_TEXTURE(emissive_tex, uv).rgb;
    vec3 n = normalize(n_in);
    vec3 t = t_in.xyz - n * dot(n, t_in.xyz);
    if (dot(t, t) < 1e-12) {
        s.normal = n;
        return s;
    }
    t = normalize(t);
    vec3 b = cross(n, t) * t_in.w;
    vec3 tn = MATERIAL_TEXTURE(normal_tex, uv).xyz * 2.0 - 1.0;
    tn = vec3(tn.xy * m.emissive.w, tn.z);
    s.normal = normalize(tn.x * t + tn.y * b + tn.z * n);
    return s;
}
#endif

#endif
