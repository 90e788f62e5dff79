#version 460
// the deferred lighting model, per fragment
#include "mesh.glsl"
#include "pbr.glsl"

// forward.Params as Settings.pack() writes it; prepass is the host's switch, declared so the
// block matches the WGSL struct
layout(set = 0, binding = 0, std140) uniform Params {
    float shadow_bias;
    float ambient;
    uint prepass;
} u_params;
#ifdef HAS_SHADOW
layout(set = 0, binding = 1) uniform texture2D t_shadow;  // WGSL texture_depth_2d
layout(set = 0, binding = 2) uniform samplerShadow s_shadow;
#endif
#include "shadow.glsl"

layout(location = 0) in vec3 i_world;
layout(location = 1) in vec3 i_normal;
layout(location = 2) in vec2 i_uv;
layout(location = 3) in vec4 i_tangent;

layout(location = 0) out vec4 o_hdr;

void main() {
    Surface s = surface(i_uv, i_normal, i_tangent);
    if (material.flags.x == 1u && s.base_color.a < material.params.w) {
        discard;
    }
    vec3 v = normalize(camera.position.xyz - i_world);
    vec3 color = s.emissive + s.base_color.rgb * lights.ambient.rgb * u_params.ambient *
        s.occlusion;
    for (uint k = 0u; k < lights.count.x; k++) {
        vec3 l;
        vec3 e = light_at(k, i_world, l);
#ifdef HAS_SHADOW
        if (k == lights.count.y) {
            e *= sun_shadow(i_world, s.normal, l, u_params.shadow_bias);
        }
#endif
        color += brdf(s.base_color.rgb, s.metallic, s.roughness, s.normal, v, l, e);
    }
    o_hdr = vec4(color, 1.0);
}
