// sun shadow lookup with a 3x3 PCF kernel on a comparison sampler (needs scene.glsl for `lights`)
//
// with HAS_SHADOW, include it after the pass declares t_shadow (texture2D) and s_shadow
// (samplerShadow): the lookups name those globals, not function parameters, because naga
// (the wgpu backend) makes a texture a depth texture and a sampler a comparison one only
// where a depth-reference lookup samples the globals themselves
#ifndef RFW_SHADOW_GLSL
#define RFW_SHADOW_GLSL
#ifdef HAS_SHADOW

#include "scene.glsl"

// separate texture and comparison sampler, as WebGPU binds them; combined at each lookup
float sun_shadow(vec3 p, vec3 n, vec3 l, float bias) {
    vec2 texel = 1.0 / vec2(textureSize(sampler2DShadow(t_shadow, s_shadow), 0));
    // normal offset keeps lit faces from shadowing themselves at grazing angles
    vec3 offset = n * (1.0 - clamp(dot(n, l), 0.0, 1.0)) * 2.0 * texel.x * 40.0;
    vec4 h = lights.sun_view_proj * vec4(p + offset, 1.0);
    vec3 c = h.xyz / h.w;
    // WebGPU's ndc-to-uv (y up in ndc): the map is drawn in WebGPU's clip space on both
    // backends (scene.glsl)
    vec2 uv = vec2(c.x * 0.5 + 0.5, 0.5 - c.y * 0.5);
    if (any(lessThan(uv, vec2(0.0))) || any(greaterThan(uv, vec2(1.0))) || c.z > 1.0) {
        return 1.0;
    }
    float lit = 0.0;
    for (int y = -1; y <= 1; y++) {
        for (int x = -1; x <= 1; x++) {
            lit += textureLod(sampler2DShadow(t_shadow, s_shadow),
                              vec3(uv + vec2(float(x), float(y)) * texel, c.z - bias), 0.0);
        }
    }
    return lit / 9.0;
}

#endif
#endif
