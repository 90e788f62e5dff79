// pathtrace: the integrator, shared by the ray-query and ray-pipeline variants (include
// only). The stage file defines trace_closest() and occluded() and calls render_pixel().
#include "pathtrace_scene.glsl"
#include "pbr.glsl"
#include "color.glsl"

// the sums carried from frame to frame (history pairs) and what a frame shows of them
layout(set = 0, binding = 6) uniform texture2D t_sums_prev;  // rgb: radiance sum, a: samples
layout(set = 0, binding = 7) uniform texture2D t_half_prev;  // rgb: even samples' sum, a: hits
layout(set = 0, binding = 8, rgba32f) uniform writeonly image2D o_sums;
layout(set = 0, binding = 9, rgba32f) uniform writeonly image2D o_half;
layout(set = 0, binding = 10, rgba32f) uniform writeonly image2D o_hdr;
layout(set = 0, binding = 11, rgba32f) uniform writeonly image2D o_error;
layout(set = 0, binding = 12) readonly buffer SobolDirections { uint v[]; } sobol_directions;
// pathtrace.Params as Settings.pack() writes it (method and mode are host-side)
layout(set = 0, binding = 13, std140) uniform Params {
    int max_recursion;
    int spp;
    int max_bounces;
    int rr_start;
    int seed;
    float sky;
    float ao_radius;
    int light;
    uint jitter;
} u_params;
// what changes every frame: the first sample's index, and 1 where the sums restart
layout(push_constant) uniform Frame {
    uint sample_base;
    uint restart;
} u_frame;

Hit trace_closest(vec3 origin, vec3 direction, float tmax, uint seed);
bool occluded(vec3 origin, vec3 direction, float tmax, uint mask, uint seed);

// --- sampler: Sobol points, Owen-scrambled and shuffled per pixel and dimension set ---
// (Burley 2020, "Practical Hash-based Owen Scrambling"): four Sobol dimensions per set, a
// set per use along the path, each with its own seed, so the sets are decorrelated while
// each stays stratified over the samples of a pixel

uint sobol(uint index, uint dim) {
    uint x = 0u;
    for (uint bit = 0u; index != 0u; bit++, index >>= 1u) {
        if ((index & 1u) != 0u) {
            x ^= sobol_directions.v[dim * 32u + bit];
        }
    }
    return x;
}

uint laine_karras(uint x, uint seed) {
    x ^= x * 0x3d20adeau;
    x += seed;
    x *= (seed >> 16u) | 1u;
    x ^= x * 0x05526c56u;
    x ^= x * 0x53a22864u;
    return x;
}

uint nested_uniform_scramble(uint x, uint seed) {
    return bitfieldReverse(laine_karras(bitfieldReverse(x), seed));
}

uint g_pixel_seed;
uint g_sample;

// four dimensions of set `set` of the current sample, in [0, 1)
vec4 sample4(uint set) {
    uint seed = hash_combine(g_pixel_seed, set);
    uint index = nested_uniform_scramble(g_sample, seed);
    vec4 u;
    for (uint d = 0u; d < 4u; d++) {
        uint x = nested_uniform_scramble(sobol(index, d), hash_combine(seed, d + 1u));
        u[d] = float(x >> 8u) * (1.0 / 16777216.0);
    }
    return u;
}

// --- rays ---

// an origin off the surface by a few ulps along the normal (integer steps of the float
// bits where the coordinates are large, a fixed step near the origin): no self-hits at any
// distance from the world origin, without a t_min to tune
vec3 offset_origin(vec3 p, vec3 n) {
    ivec3 steps = ivec3(256.0 * n);
    vec3 stepped = intBitsToFloat(floatBitsToInt(p)
                                  + ivec3(p.x < 0.0 ? -steps.x : steps.x,
                                          p.y < 0.0 ? -steps.y : steps.y,
                                          p.z < 0.0 ? -steps.z : steps.z));
    vec3 small = p + n * (1.0 / 65536.0);
    return vec3(abs(p.x) < 1.0 / 32.0 ? small.x : stepped.x,
                abs(p.y) < 1.0 / 32.0 ? small.y : stepped.y,
                abs(p.z) < 1.0 / 32.0 ? small.z : stepped.z);
}

mat3 basis(vec3 n) {  // an orthonormal frame around n (Duff et al. 2017)
    float s = n.z >= 0.0 ? 1.0 : -1.0;
    float a = -1.0 / (s + n.z);
    float b = n.x * n.y * a;
    return mat3(vec3(1.0 + s * n.x * n.x * a, s * b, -s * n.x), vec3(b, s + n.y * n.y * a, -n.y), n);
}

vec3 cosine_sample(vec3 n, vec2 u) {
    float r = sqrt(u.x), phi = 2.0 * PI * u.y;
    return basis(n) * vec3(r * cos(phi), r * sin(phi), sqrt(max(0.0, 1.0 - u.x)));
}

// --- the BSDF: pbr.glsl's metallic-roughness model, with KHR_materials_specular's factor
// scaling the dielectric lobe (1: exactly brdf(), what the raster passes shade) ---

struct Bsdf {
    vec3 base;
    float metallic;
    float alpha;  // GGX alpha: roughness squared
    float specular;
    vec3 n;
};

vec3 fresnel(Bsdf m, float voh) {
    return mix(m.specular * f_schlick(vec3(0.04), voh), f_schlick(m.base, voh), m.metallic);
}

// f(v, l) * n.l
vec3 bsdf_eval(Bsdf m, vec3 v, vec3 l) {
    float nol = dot(m.n, l), nov = dot(m.n, v);
    if (nol <= 0.0 || nov <= 0.0) {
        return vec3(0.0);
    }
    vec3 h = normalize(v + l);
    float noh = clamp(dot(m.n, h), 0.0, 1.0), voh = clamp(dot(v, h), 0.0, 1.0);
    vec3 f = fresnel(m, voh);
    vec3 spec = d_ggx(noh, m.alpha) * v_smith(max(nov, 1e-4), nol, m.alpha) * f;
    vec3 diffuse = (1.0 - m.metallic) * (vec3(1.0) - f) * m.base / PI;
    return (diffuse + spec) * nol;
}

// the chance of sampling the specular lobe: its share of the Fresnel-weighted albedo
float specular_share(Bsdf m, float nov) {
    float spec = luminance(fresnel(m, nov));
    float diffuse = (1.0 - m.metallic) * luminance(m.base) * (1.0 - spec);
    float total = spec + diffuse;
    return total > 0.0 ? clamp(spec / total, 0.0, 1.0) : 0.5;
}

// Smith G1 of GGX, for the visible-normal density
float g1_ggx(float nov, float a) {
    float a2 = a * a;
    return 2.0 * nov / (nov + sqrt(a2 + (1.0 - a2) * nov * nov));
}

// a half vector from the GGX distribution of normals visible from v (Heitz 2018), in the
// frame where n is +z
vec3 sample_vndf(vec3 v, float a, vec2 u) {
    vec3 vh = normalize(vec3(a * v.x, a * v.y, v.z));
    float len2 = vh.x * vh.x + vh.y * vh.y;
    vec3 t1 = len2 > 0.0 ? vec3(-vh.y, vh.x, 0.0) * inversesqrt(len2) : vec3(1.0, 0.0, 0.0);
    vec3 t2 = cross(vh, t1);
    float r = sqrt(u.x), phi = 2.0 * PI * u.y;
    float p1 = r * cos(phi), p2 = r * sin(phi);
    float s = 0.5 * (1.0 + vh.z);
    p2 = (1.0 - s) * sqrt(max(0.0, 1.0 - p1 * p1)) + s * p2;
    vec3 nh = p1 * t1 + p2 * t2 + sqrt(max(0.0, 1.0 - p1 * p1 - p2 * p2)) * vh;
    return normalize(vec3(a * nh.x, a * nh.y, max(0.0, nh.z)));
}

// the density of bsdf_sample's directions
float bsdf_pdf(Bsdf m, vec3 v, vec3 l) {
    float nol = dot(m.n, l), nov = dot(m.n, v);
    if (nol <= 0.0 || nov <= 0.0) {
        return 0.0;
    }
    vec3 h = normalize(v + l);
    float noh = clamp(dot(m.n, h), 0.0, 1.0), voh = max(dot(v, h), 1e-6);
    float spec = g1_ggx(nov, m.alpha) * voh * d_ggx(noh, m.alpha) / nov / (4.0 * voh);
    float p = specular_share(m, nov);
    return p * spec + (1.0 - p) * nol / PI;
}

// a direction from the BSDF (lobe chosen by specular_share), or false below the surface
bool bsdf_sample(Bsdf m, vec3 v, vec3 u, out vec3 l) {
    float nov = dot(m.n, v);
    if (u.x < specular_share(m, nov)) {
        mat3 frame = basis(m.n);
        vec3 h = frame * sample_vndf(transpose(frame) * v, m.alpha, u.yz);
        l = reflect(-v, h);
    } else {
        l = cosine_sample(m.n, u.yz);
    }
    return dot(m.n, l) > 0.0;
}

// --- the integrator ---

vec3 sky_radiance() {
    return lights.ambient.rgb * u_params.sky;
}

float power_heuristic(float a, float b) {
    return a * a / max(a * a + b * b, 1e-30);
}

// the camera ray through a point of pixel px (u: where in the pixel), and the cone's spread
// per unit distance of one pixel there
void camera_ray(vec2 px, vec2 size, out vec3 origin, out vec3 direction) {
    vec2 ndc = vec2(px.x / size.x * 2.0 - 1.0, 1.0 - px.y / size.y * 2.0);
    vec4 far = camera.inv_view_proj * vec4(ndc, 1.0, 1.0);
    origin = camera.position.xyz;
    direction = normalize(far.xyz / far.w - origin);
}

struct PathSample {
    vec3 radiance;
    float hit;  // 1: the camera ray hit the scene
};

// one path: next-event estimation of the punctual lights (every light, one shadow ray
// each) and of the sky (a cosine-distributed direction), BSDF sampling for the next bounce;
// the sky, reached both ways, is weighted by the power heuristic; emission is added where
// a path hits it. Russian roulette from bounce rr_start on.
PathSample trace_path(vec3 o, vec3 d, float spread) {
    PathSample out_;
    out_.radiance = vec3(0.0);
    out_.hit = 0.0;
    vec3 throughput = vec3(1.0);
    float cone = 0.0;
    float sky_weight = 1.0;  // the MIS weight of the sky if this ray escapes
    int bounces = clamp(u_params.max_bounces, 0, 64);
    for (int depth = 0; depth <= bounces; depth++) {
        uint path_seed = hash_combine(g_pixel_seed, uint(depth) * 977u + g_sample);
        Hit h = trace_closest(o, d, 1e30, path_seed);
        if (h.instance < 0) {
            if (depth > 0) {
                // the sky reached by BSDF sampling, weighted against its NEE
                out_.radiance += throughput * sky_radiance() * sky_weight;
            }
            break;
        }
        if (depth == 0) {
            out_.hit = 1.0;
        }
        cone += spread * h.t;
        Shading sh = shade_hit(h, d, cone);
        vec3 v = -d;
        out_.radiance += throughput * sh.s.emissive;
        if (depth == bounces) {
            break;
        }
        Bsdf m = Bsdf(sh.s.base_color.rgb, sh.s.metallic, sh.s.roughness * sh.s.roughness,
                      specular_factor(h.instance), sh.s.normal);
        if (dot(m.n, v) <= 0.0) {  // the shading normal turned away from the viewer
            m.n = sh.ng;
        }
        vec3 origin = offset_origin(sh.p, sh.ng);
        // punctual lights: delta distributions, which BSDF sampling never hits
        for (uint i = 0u; i < lights.count.x; i++) {
            vec3 l;
            vec3 e = light_at(i, sh.p, l);
            if (dot(l, sh.ng) <= 0.0 || dot(e, e) == 0.0) {
                continue;
            }
            vec3 f = bsdf_eval(m, v, l);
            if (dot(f, f) == 0.0) {
                continue;
            }
            bool directional = uint(lights.items[i].position.w) == 0u;
            float tmax = directional ? 1e30 : length(lights.items[i].position.xyz - origin);
            if (!occluded(origin, l, tmax, MASK_ALL, path_seed + i)) {
                out_.radiance += throughput * f * e;
            }
        }
        vec4 u0 = sample4(uint(depth) * 2u);
        vec4 u1 = sample4(uint(depth) * 2u + 1u);
        // the sky: a cosine-distributed direction about the geometric normal
        if (dot(sky_radiance(), sky_radiance()) > 0.0) {
            vec3 l = cosine_sample(sh.ng, u1.xy);
            float light_pdf = max(dot(l, sh.ng), 0.0) / PI;
            vec3 f = bsdf_eval(m, v, l);
            if (light_pdf > 0.0 && dot(f, f) > 0.0
                    && !occluded(origin, l, 1e30, MASK_ALL, path_seed + 101u)) {
                float w = power_heuristic(light_pdf, bsdf_pdf(m, v, l));
                out_.radiance += throughput * f * sky_radiance() * (w / light_pdf);
            }
        }
        vec3 l;
        if (!bsdf_sample(m, v, u0.xyz, l) || dot(l, sh.ng) <= 0.0) {
            break;
        }
        float pdf = bsdf_pdf(m, v, l);
        if (pdf <= 0.0) {
            break;
        }
        throughput *= bsdf_eval(m, v, l) / pdf;
        // the sky's weight if this ray escapes: the power heuristic against the cosine NEE
        // density about the geometric normal
        sky_weight = power_heuristic(pdf, max(dot(l, sh.ng), 0.0) / PI);
        if (depth + 1 >= u_params.rr_start) {
            float q = clamp(max(throughput.r, max(throughput.g, throughput.b)), 0.05, 0.95);
            if (u0.w >= q) {
                break;
            }
            throughput /= q;
        }
        // the cone widens by the lobe it left through
        spread += min(2.0 * m.alpha, 1.0) * (1.0 - m.metallic) + m.alpha * m.metallic;
        o = origin;
        d = l;
    }
    return out_;
}

#if defined(MODE_AO) || defined(MODE_VISIBILITY)
// the point a camera ray sees, for the per-effect modes: false on the sky
bool camera_point(vec3 o, vec3 d, float spread, uint seed, out Shading sh) {
    Hit h = trace_closest(o, d, 1e30, seed);
    if (h.instance < 0) {
        return false;
    }
    sh = shade_hit(h, d, spread * h.t);
    return true;
}
#endif

#if defined(MODE_AO)
// ambient occlusion at the point a camera ray sees, as rt_ao defines it: the fraction of
// cosine-distributed rays about the shading normal that travel ao_radius unoccluded by
// opaque and masked surfaces (one ray per sample)
PathSample trace_ao(vec3 o, vec3 d, float spread) {
    PathSample out_ = PathSample(vec3(0.0), 0.0);
    uint seed = hash_combine(g_pixel_seed, g_sample);
    Shading sh;
    if (!camera_point(o, d, spread, seed, sh)) {
        return out_;
    }
    vec3 l = cosine_sample(sh.s.normal, sample4(1u).xy);
    vec3 origin = offset_origin(sh.p, sh.ng);
    bool open = dot(l, sh.ng) <= 0.0 ? false :
        !occluded(origin, l, u_params.ao_radius, MASK_OCCLUDERS, seed + 1u);
    out_.radiance = vec3(open ? 1.0 : 0.0);
    out_.hit = 1.0;
    return out_;
}
#endif

#if defined(MODE_VISIBILITY)
// the visibility of one light (u_params.light, -1: the sun) at the point a camera ray sees,
// as rt_shadows defines it: 1 where a ray toward it is unoccluded by opaque and masked
// surfaces, and where the surface faces away from it (the BSDF gives it nothing there)
PathSample trace_visibility(vec3 o, vec3 d, float spread) {
    PathSample out_ = PathSample(vec3(0.0), 0.0);
    uint seed = hash_combine(g_pixel_seed, g_sample);
    Shading sh;
    if (!camera_point(o, d, spread, seed, sh)) {
        return out_;
    }
    out_.hit = 1.0;
    uint i = u_params.light < 0 ? lights.count.y : uint(u_params.light);
    if (i >= lights.count.x) {
        out_.radiance = vec3(1.0);
        return out_;
    }
    vec3 l;
    light_at(i, sh.p, l);
    vec3 origin = offset_origin(sh.p, sh.ng);
    bool directional = uint(lights.items[i].position.w) == 0u;
    float tmax = directional ? 1e30 : length(lights.items[i].position.xyz - origin);
    bool lit = dot(l, sh.ng) <= 0.0 || !occluded(origin, l, tmax, MASK_OCCLUDERS, seed + 1u);
    out_.radiance = vec3(lit ? 1.0 : 0.0);
    return out_;
}
#endif

// this frame's samples of pixel px, added to the sums of the frames before (restarted on
// u_frame.restart); the mean, and the convergence estimate: half the difference of the
// means of the even and the odd samples
void render_pixel(ivec2 px, ivec2 isize) {
    vec2 size = vec2(isize);
    vec4 sums = u_frame.restart != 0u ? vec4(0.0) : texelFetch(t_sums_prev, px, 0);
    vec4 half_ = u_frame.restart != 0u ? vec4(0.0) : texelFetch(t_half_prev, px, 0);
    g_pixel_seed = hash_combine(hash_combine(uint(u_params.seed), uint(px.x)), uint(px.y));
    // a pixel's angle from the camera: the cone every camera ray starts with
    float spread = 2.0 / (camera.proj[1][1] * size.y);
    uint count = uint(clamp(u_params.spp, 1, 4096));
    for (uint s = 0u; s < count; s++) {
        g_sample = u_frame.sample_base + s;
        vec2 jitter = u_params.jitter != 0u ? sample4(0x7fffu).xy : vec2(0.5);
        vec3 o, d;
        camera_ray(vec2(px) + jitter, size, o, d);
#if defined(MODE_AO)
        PathSample r = trace_ao(o, d, spread);
#elif defined(MODE_VISIBILITY)
        PathSample r = trace_visibility(o, d, spread);
#else
        PathSample r = trace_path(o, d, spread);
#endif
        vec3 value = all(lessThan(abs(r.radiance), vec3(1e30))) ? r.radiance : vec3(0.0);
        sums += vec4(value, 1.0);
        if ((g_sample & 1u) == 0u) {
            half_.rgb += value;
        }
        half_.a += r.hit;
    }
    imageStore(o_sums, px, sums);
    imageStore(o_half, px, half_);
    float n = max(sums.a, 1.0);
    float even = floor((sums.a + 1.0) * 0.5), odd = sums.a - even;
    vec3 mean_even = half_.rgb / max(even, 1.0);
    vec3 mean_odd = (sums.rgb - half_.rgb) / max(odd, 1.0);
    imageStore(o_hdr, px, vec4(sums.rgb / n, half_.a / n));
    imageStore(o_error, px, vec4(odd > 0.0 ? 0.5 * abs(mean_even - mean_odd) : vec3(0.0),
                                 sums.a));
}
