#version 460
// occlusion of a normal-oriented hemisphere, tested against the depth
// buffer in view space
#extension GL_EXT_samplerless_texture_functions : require  // texelFetch on texture2D
#include "ssao_common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;

layout(set = 0, binding = 1) uniform texture2D t_normal;
layout(set = 0, binding = 2, r32f) uniform writeonly image2D o_ao;

const float GOLDEN_ANGLE = 2.39996323;
const float TAU = 6.28318531;
const int MAX_SAMPLES = 64;

// Jimenez's interleaved gradient noise: a per-pixel rotation with little low-frequency content
float ign(vec2 p) {
    return fract(52.9829189 * fract(dot(p, vec2(0.06711056, 0.00583715))));
}

// an orthonormal basis around unit n (Duff et al. 2017, branchless)
mat3 basis(vec3 n) {
    float s = n.z >= 0.0 ? 1.0 : -1.0;
    float a = -1.0 / (s + n.z);
    float b = n.x * n.y * a;
    return mat3(vec3(1.0 + s * n.x * n.x * a, s * b, -s * n.x),
                vec3(b, s + n.y * n.y * a, -n.y), n);
}

void main() {
    uvec2 id = gl_GlobalInvocationID.xy;
    uvec2 size = uvec2(imageSize(o_ao));
    if (id.x >= size.x || id.y >= size.y) {
        return;
    }
    ivec2 px = source_pixel(id);
    float d = load_depth(px);
    if (d >= 1.0) {
        imageStore(o_ao, ivec2(id), vec4(1.0));
        return;
    }
    vec3 p = view_position(px, d);
    vec3 n = normalize((camera.view * vec4(texelFetch(t_normal, px, 0).xyz, 0.0)).xyz);
    mat3 tbn = basis(n);
    vec2 full = vec2(textureSize(t_depth, 0));
    int count = clamp(u_params.samples, 1, MAX_SAMPLES);
    float rotation = TAU * ign(vec2(px));
    float occlusion = 0.0;
    for (int k = 0; k < count; k++) {
        // cosine-weighted hemisphere: a golden-angle spiral on the disc, lifted onto it;
        // lengths follow a radical inverse so they do not correlate with elevation
        float u = (float(k) + 0.5) / float(count);
        float phi = float(k) * GOLDEN_ANGLE + rotation;
        float rho = sqrt(u);
        vec3 dir = vec3(rho * cos(phi), rho * sin(phi), sqrt(1.0 - u));
        float t = float(bitfieldReverse(uint(k))) * 2.3283064e-10;
        float reach = mix(0.1, 1.0, t * t);
        vec3 s = p + tbn * dir * (u_params.radius * reach);
        // where the sample lands on screen, and the surface the camera sees there
        vec4 clip = camera.proj * vec4(s, 1.0);
        vec2 ndc = clip.xy / clip.w;
        vec2 at = vec2(ndc.x * 0.5 + 0.5, 0.5 - ndc.y * 0.5) * full;
        if (clip.w <= 0.0 || any(lessThan(at, vec2(0.0))) || any(greaterThanEqual(at, full))) {
            continue;
        }
        ivec2 q = ivec2(at);
        float sd = load_depth(q);
        if (sd >= 1.0) {
            continue;
        }
        float scene_z = view_position(q, sd).z;
        // view space looks down -z: a surface in front of the sample has the larger z;
        // one more than a radius nearer than p is outside the hemisphere, so it fades out
        float r = u_params.radius;
        float range = 1.0 - smoothstep(r, 2.0 * r, abs(p.z - scene_z));
        occlusion += scene_z >= s.z + u_params.bias ? range : 0.0;
    }
    float open = clamp(1.0 - u_params.intensity * occlusion / float(count), 0.0, 1.0);
    imageStore(o_ao, ivec2(id), vec4(pow(open, u_params.power)));
}
