#version 460
// G-buffer in, linear HDR radiance out (deferred_lighting.py)
#extension GL_EXT_samplerless_texture_functions : require  // texelFetch on texture2D
#include "scene.glsl"
#include "pbr.glsl"

layout(local_size_x = 8, local_size_y = 8) in;

layout(set = 0, binding = 0) uniform texture2D t_albedo;
layout(set = 0, binding = 1) uniform texture2D t_normal;
layout(set = 0, binding = 2) uniform texture2D t_material;
layout(set = 0, binding = 3) uniform texture2D t_emissive;
layout(set = 0, binding = 4) uniform texture2D t_depth;  // WGSL texture_depth_2d: read .r
layout(set = 0, binding = 5, rgba16f) uniform writeonly image2D o_hdr;
// deferred_lighting.Params as Settings.pack() writes it: 8 bytes used, 16 uploaded
layout(set = 0, binding = 6, std140) uniform Params {
    float shadow_bias;
    float ambient;
} u_params;
#ifdef HAS_SHADOW
layout(set = 0, binding = 7) uniform texture2D t_shadow;  // WGSL texture_depth_2d
layout(set = 0, binding = 8) uniform samplerShadow s_shadow;
#endif
#include "shadow.glsl"
#ifdef HAS_AO
layout(set = 0, binding = 9) uniform texture2D t_ao;
layout(set = 0, binding = 10) uniform sampler s_linear;
#endif
#ifdef HAS_VISIBILITY
// screen-space shadows (rt_shadows): bit i set where light i reaches the pixel
layout(set = 0, binding = 11) uniform utexture2D t_visibility;
#endif

void main() {
    uvec2 id = gl_GlobalInvocationID.xy;
    uvec2 size = uvec2(imageSize(o_hdr));
    if (id.x >= size.x || id.y >= size.y) {
        return;
    }
    ivec2 px = ivec2(id);
    float depth = texelFetch(t_depth, px, 0).r;
    if (depth >= 1.0) {
        // background: alpha 0, painted by tonemap as in the forward path
        imageStore(o_hdr, px, vec4(0.0));
        return;
    }
    vec3 base = texelFetch(t_albedo, px, 0).rgb;
    vec3 n = normalize(texelFetch(t_normal, px, 0).xyz);
    vec4 m = texelFetch(t_material, px, 0);
    vec3 emissive = texelFetch(t_emissive, px, 0).rgb;
    vec3 p = world_from_depth(vec2(id) + 0.5, vec2(size), depth);
    vec3 v = normalize(camera.position.xyz - p);
    float ao = m.r;
#ifdef HAS_AO
    ao *= textureLod(sampler2D(t_ao, s_linear), (vec2(id) + 0.5) / vec2(size), 0.0).r;
#endif
    vec3 color = emissive + base * lights.ambient.rgb * u_params.ambient * ao;
#ifdef HAS_VISIBILITY
    uint visible = texelFetch(t_visibility, px, 0).r;
#endif
    for (uint i = 0u; i < lights.count.x; i++) {
        vec3 l;
        vec3 e = light_at(i, p, l);
#ifdef HAS_VISIBILITY
        e *= float((visible >> i) & 1u);
#endif
#ifdef HAS_SHADOW
        if (i == lights.count.y) {
            e *= sun_shadow(p, n, l, u_params.shadow_bias);
        }
#endif
        color += brdf(base, m.b, m.g, n, v, l, e);
    }
    imageStore(o_hdr, px, vec4(color, 1.0));
}
