// metallic-roughness BRDF (GGX, Smith height-correlated, Schlick) and punctual lights
// (needs scene.glsl for `lights`)
#ifndef RFW_PBR_GLSL
#define RFW_PBR_GLSL

#include "scene.glsl"

const float PI = 3.14159265358979;

float d_ggx(float noh, float a) {
    float a2 = a * a;
    float d = noh * noh * (a2 - 1.0) + 1.0;
    return a2 / (PI * d * d);
}

float v_smith(float nov, float nol, float a) {
    float a2 = a * a;
    float gv = nol * sqrt(nov * nov * (1.0 - a2) + a2);
    float gl = nov * sqrt(nol * nol * (1.0 - a2) + a2);
    return 0.5 / max(gv + gl, 1e-5);
}

vec3 f_schlick(vec3 f0, float voh) {
    return f0 + (vec3(1.0) - f0) * pow(1.0 - voh, 5.0);
}

// radiance reflected toward v from light arriving along l with irradiance e (n.l applied here)
vec3 brdf(vec3 base, float metallic, float roughness, vec3 n, vec3 v, vec3 l, vec3 e) {
    vec3 h = normalize(v + l);
    float nol = clamp(dot(n, l), 0.0, 1.0);
    float nov = clamp(abs(dot(n, v)), 1e-4, 1.0);
    float noh = clamp(dot(n, h), 0.0, 1.0);
    float voh = clamp(dot(v, h), 0.0, 1.0);
    float a = roughness * roughness;
    vec3 f0 = mix(vec3(0.04), base, metallic);
    vec3 f = f_schlick(f0, voh);
    vec3 spec = d_ggx(noh, a) * v_smith(nov, nol, a) * f;
    vec3 diffuse = (1.0 - metallic) * (vec3(1.0) - f) * base / PI;
    return (diffuse + spec) * e * nol;
}

// direction toward light i and the irradiance it delivers at p (before n.l and shadowing)
vec3 light_at(uint i, vec3 p, out vec3 l_out) {
    Light li = lights.items[i];
    uint kind = uint(li.position.w);
    vec3 power = li.color.rgb * li.color.w;
    if (kind == 0u) {
        l_out = -normalize(li.direction.xyz);
        return power;
    }
    vec3 d = li.position.xyz - p;
    float dist2 = max(dot(d, d), 1e-4);
    vec3 l = d * inversesqrt(dist2);
    l_out = l;
    float atten = 1.0 / dist2;
    float range = li.direction.w;
    if (range > 0.0) {
        float r = dist2 / (range * range);
        atten *= clamp(1.0 - r * r, 0.0, 1.0);
    }
    if (kind == 2u) {
        float cd = dot(normalize(li.direction.xyz), -l);
        atten *= smoothstep(li.cone.y, li.cone.x, cd);
    }
    return power * atten;
}

#endif
