// pathtrace: the scene as every stage of the path tracer reads it (include only): the
// tables, textures and samplers of rfw.authoring.scene_tables, a hit turned into a shading
// point with its material (material.glsl, as the raster passes evaluate it; textures at the
// LOD of the hit's ray cone), and the alpha test of masked and blended surfaces.
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_EXT_nonuniform_qualifier : require
#extension GL_EXT_samplerless_texture_functions : require
#include "scene.glsl"
#include "streams.glsl"

#ifndef MAX_TEXTURES
#define MAX_TEXTURES 1
#endif
#ifndef MAX_SAMPLERS
#define MAX_SAMPLERS 1
#endif

layout(set = 0, binding = 0) uniform accelerationStructureEXT tlas;
layout(set = 0, binding = 4) uniform texture2D textures[MAX_TEXTURES];
layout(set = 0, binding = 5) uniform sampler samplers[MAX_SAMPLERS];

// what MATERIAL_TEXTURE reads: the material's texture slots, and the texture-independent
// part of the LOD (the ray cone's footprint over the triangle's uv density, in log2); each
// texture adds half the log2 of its texel count
struct Slots {
    int base_color_tex, metal_rough_tex, normal_tex, occlusion_tex, emissive_tex, sampler_;
};
Slots g_slots;
float g_lod;
float texture_lod(int t) {
    ivec2 size = textureSize(textures[nonuniformEXT(t)], 0);
    return max(0.0, g_lod + 0.5 * log2(float(size.x) * float(size.y)));
}
#define MATERIAL_TEXTURE(name, uv) textureLod(sampler2D(textures[nonuniformEXT(g_slots.name)], \
    samplers[nonuniformEXT(g_slots.sampler_)]), uv, texture_lod(g_slots.name))
#include "material.glsl"
#include "scene_tables.glsl"

layout(set = 0, binding = 1, std430) readonly buffer Meshes { SceneMesh m[]; } meshes;
layout(set = 0, binding = 2, std430) readonly buffer Instances { SceneInstance i[]; } instances;
layout(set = 0, binding = 3, std430) readonly buffer Materials { SceneMaterial m[]; } materials;

// the TLAS instance masks of vkext.accel.ALPHA_MASK
const uint MASK_ALL = 0xffu;  // what camera and bounce rays see: blended surfaces too
const uint MASK_OCCLUDERS = 0x3u;  // what AO and visibility rays test, as rt_ao/rt_shadows

// a ray's closest hit: -1 instance on a miss
struct Hit {
    vec2 barycentrics;  // weights of the triangle's 2nd and 3rd vertices
    int instance;  // the scene's instance (instanceCustomIndex)
    int primitive;  // triangle of the mesh
    float t;
};

uint hash_u32(uint x) {  // a 32-bit integer finaliser (lowbias32)
    x ^= x >> 16u;
    x *= 0x7feb352du;
    x ^= x >> 15u;
    x *= 0x846ca68bu;
    x ^= x >> 16u;
    return x;
}

uint hash_combine(uint seed, uint v) {
    return hash_u32(seed ^ (v + 0x9e3779b9u + (seed << 6u) + (seed >> 2u)));
}

void material_slots(SceneMaterial mat) {
    g_slots = Slots(mat.textures.x, mat.textures.y, mat.textures.z, mat.textures.w,
                    mat.more.x, mat.more.y);
}

// whether a candidate hit of a masked or blended surface stops the ray: a masked one where
// its coverage passes the cutoff, a blended one with the probability of its coverage
// (stochastic transparency, from `seed`); coverage read at the texture's finest level
bool surface_blocks(int instance, int primitive, vec2 bc, uint seed) {
    SceneInstance inst = instances.i[instance];
    SceneMesh mesh = meshes.m[inst.mesh.x];
    SceneMaterial mat = materials.m[mesh.material];
    uint mode = mat.factors.flags.x;
    if (mode == 0u) {
        return true;
    }
    Uints index = Uints(mesh.indices);
    uint i0 = index.v[3 * primitive], i1 = index.v[3 * primitive + 1];
    uint i2 = index.v[3 * primitive + 2];
    Vec2s uvs = Vec2s(mesh.uvs);
    vec2 uv = (1.0 - bc.x - bc.y) * uvs.v[i0] + bc.x * uvs.v[i1] + bc.y * uvs.v[i2];
    material_slots(mat);
    float alpha = mat.factors.base_color.a * textureLod(sampler2D(
        textures[nonuniformEXT(g_slots.base_color_tex)],
        samplers[nonuniformEXT(g_slots.sampler_)]), uv, 0.0).a;
    if (mode == 1u) {
        return !material_cut(mat.factors, alpha);
    }
    uint h = hash_combine(hash_combine(seed, uint(instance)), uint(primitive));
    return float(hash_u32(h ^ floatBitsToUint(bc.x)) >> 8u) * (1.0 / 16777216.0) < alpha;
}

// a hit as a shading point
struct Shading {
    vec3 p;  // world position
    vec3 ng;  // geometric normal, facing the incoming ray
    Surface s;  // the material there (s.normal: shading normal, same side as ng)
    float area_lod;  // 0.5 log2(uv area / world area) of the triangle
};

// the point a ray of direction `d` hit, its material at the LOD a cone of width `cone_width`
// there gives (ray cones: the footprint over the triangle's uv density, widened by the
// angle it meets the surface at)
Shading shade_hit(Hit h, vec3 d, float cone_width) {
    SceneInstance inst = instances.i[h.instance];
    SceneMesh mesh = meshes.m[inst.mesh.x];
    Uints index = Uints(mesh.indices);
    uint i0 = index.v[3 * h.primitive], i1 = index.v[3 * h.primitive + 1];
    uint i2 = index.v[3 * h.primitive + 2];
    float b = h.barycentrics.x, c = h.barycentrics.y, a = 1.0 - b - c;
    vec3 p0 = (inst.model * vec4(vec3_at(mesh.positions, i0), 1.0)).xyz;
    vec3 p1 = (inst.model * vec4(vec3_at(mesh.positions, i1), 1.0)).xyz;
    vec3 p2 = (inst.model * vec4(vec3_at(mesh.positions, i2), 1.0)).xyz;
    Shading sh;
    sh.p = a * p0 + b * p1 + c * p2;
    vec3 e = cross(p1 - p0, p2 - p0);
    float world_area = length(e);
    sh.ng = world_area > 0.0 ? e / world_area : -d;
    Vec2s uvs = Vec2s(mesh.uvs);
    vec2 t0 = uvs.v[i0], t1 = uvs.v[i1], t2 = uvs.v[i2];
    vec2 uv = a * t0 + b * t1 + c * t2;
    float uv_area = abs((t1.x - t0.x) * (t2.y - t0.y) - (t2.x - t0.x) * (t1.y - t0.y));
    sh.area_lod = 0.5 * log2(max(uv_area, 1e-20) / max(world_area, 1e-20));
    float cosine = max(abs(dot(sh.ng, d)), 1e-4);
    g_lod = sh.area_lod + log2(max(cone_width, 1e-20) / cosine);
    vec3 n_obj = a * vec3_at(mesh.normals, i0) + b * vec3_at(mesh.normals, i1)
        + c * vec3_at(mesh.normals, i2);
    Vec4s tans = Vec4s(mesh.tangents);
    vec4 t_obj = a * tans.v[i0] + b * tans.v[i1] + c * tans.v[i2];
    vec3 n = (inst.normal * vec4(n_obj, 0.0)).xyz;
    if (dot(n, n) < 1e-20) {
        n = sh.ng;
    }
    vec4 t = vec4((inst.model * vec4(t_obj.xyz, 0.0)).xyz,
                  inst.mesh.y == 1u ? -t_obj.w : t_obj.w);
    SceneMaterial mat = materials.m[mesh.material];
    material_slots(mat);
    sh.s = material_surface(mat.factors, uv, n, t);
    // every surface is seen from the side the ray came from (thin and double-sided ones,
    // and rays that reach the inside of closed meshes)
    if (dot(sh.ng, d) > 0.0) {
        sh.ng = -sh.ng;
    }
    if (dot(sh.s.normal, sh.ng) < 0.0) {
        sh.s.normal = -sh.s.normal;
    }
    return sh;
}

float specular_factor(int instance) {
    SceneMesh mesh = meshes.m[instances.i[instance].mesh.x];
    return uintBitsToFloat(materials.m[mesh.material].factors.flags.z);
}

// the ray pipeline's payload: the hit, and the seed an any-hit shader draws from
struct Payload {
    Hit hit;
    uint seed;
};
