#version 460
// the G-buffer from the visibility buffer: per pixel, the triangle's three vertices from
// the scene's own buffers (device addresses), perspective-correct barycentrics solved from
// the three clip-space corners (also at the pixel's 2x2 quad, for texture gradients), the
// attributes interpolated as the rasteriser interpolates gbuffer.vert.glsl's outputs, and
// the material evaluated by the G-buffer's own code (material.glsl) with those gradients
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_EXT_nonuniform_qualifier : require
#extension GL_EXT_samplerless_texture_functions : require
#include "scene.glsl"
#include "color.glsl"

#ifndef MAX_TEXTURES
#define MAX_TEXTURES 1
#endif
#ifndef TRIANGLE_BITS
#define TRIANGLE_BITS 16
#endif
#ifndef MAX_SAMPLERS
#define MAX_SAMPLERS 1
#endif

layout(local_size_x = 8, local_size_y = 8) in;

#include "streams.glsl"

#ifdef ATOMIC
// visbuffer.py's write = "atomic": per pixel (depth bits << 32 | ~id)
layout(set = 0, binding = 0, std430) readonly buffer Ids { uvec2 v[]; } ids;
#else
layout(set = 0, binding = 0) uniform utexture2D t_ids;
#endif
layout(set = 0, binding = 1) uniform texture2D t_depth;
layout(set = 0, binding = 5) uniform texture2D textures[MAX_TEXTURES];
layout(set = 0, binding = 6) uniform sampler samplers[MAX_SAMPLERS];
layout(set = 0, binding = 7, rgba16f) uniform writeonly image2D o_albedo;
layout(set = 0, binding = 8, rgba16f) uniform writeonly image2D o_normal;
layout(set = 0, binding = 9, rgba8) uniform writeonly image2D o_material;
layout(set = 0, binding = 10, rgba16f) uniform writeonly image2D o_emissive;

// what MATERIAL_TEXTURE reads: the pixel's material's texture slots and its uv gradients
struct Slots {
    int base_color_tex, metal_rough_tex, normal_tex, occlusion_tex, emissive_tex, sampler_;
};
Slots g_slots;
vec2 g_duv_dx, g_duv_dy;
#define MATERIAL_TEXTURE(name, uv) textureGrad(sampler2D(textures[nonuniformEXT(g_slots.name)], \
    samplers[nonuniformEXT(g_slots.sampler_)]), uv, g_duv_dx, g_duv_dy)
#include "material.glsl"

#include "scene_tables.glsl"
layout(set = 0, binding = 2, std430) readonly buffer Meshes { SceneMesh m[]; } meshes;
layout(set = 0, binding = 3, std430) readonly buffer Instances { SceneInstance i[]; } instances;
layout(set = 0, binding = 4, std430) readonly buffer Materials { SceneMaterial m[]; } materials;

// the albedo as the G-buffer's rgba8unorm-srgb attachment holds it: 8-bit sRGB levels,
// decoded (storage images cannot be sRGB, so lighting reads this linear value instead)
vec3 srgb_quantized(vec3 c) {
    vec3 level = floor(srgb_encode(clamp(c, 0.0, 1.0)) * 255.0 + 0.5) / 255.0;
    return srgb_decode(level);
}

// perspective-correct barycentrics of pixel px's centre: the weights b with
// sum(b_i * c_i.xyw) parallel to (ndc.x, ndc.y, 1). The rows r of the adjugate of the matrix
// of corners (cross products of c.xyw) solve it up to a scale, which the normalisation
// removes: no division by w, so corners behind the camera need no clipping.
vec3 weights(vec3 r0, vec3 r1, vec3 r2, ivec2 px, vec2 size) {
    vec2 ndc = (vec2(px) + 0.5) / size * 2.0 - 1.0;
    vec3 q = vec3(ndc.x, -ndc.y, 1.0);  // ndc y is up, rows go down
    vec3 u = vec3(dot(r0, q), dot(r1, q), dot(r2, q));
    return u / (u.x + u.y + u.z);
}

void write_background(ivec2 px) {
    imageStore(o_albedo, px, vec4(0.0));
    imageStore(o_normal, px, vec4(0.0));
    imageStore(o_material, px, vec4(0.0));
    imageStore(o_emissive, px, vec4(0.0));
}

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 isize = imageSize(o_albedo);
    if (px.x >= isize.x || px.y >= isize.y) {
        return;
    }
    if (texelFetch(t_depth, px, 0).r >= 1.0) {
        write_background(px);
        return;
    }
#ifdef ATOMIC
    uint id = ~ids.v[px.y * isize.x + px.x].x;  // the low word (little-endian) holds ~id
#else
    uint id = texelFetch(t_ids, px, 0).r;
#endif
    // visbuffer.py's triangle_bits: the instance in the high bits, the triangle below
    uvec2 ids = uvec2(id >> TRIANGLE_BITS, id & ((1u << TRIANGLE_BITS) - 1u));
    SceneInstance inst = instances.i[ids.x];
    SceneMesh mesh = meshes.m[inst.mesh.x];
    Uints index = Uints(mesh.indices);
    uint i0 = index.v[3 * ids.y], i1 = index.v[3 * ids.y + 1], i2 = index.v[3 * ids.y + 2];

    // the corners in clip space, as gbuffer.vert.glsl computes gl_Position
    vec3 p0 = vec3_at(mesh.positions, i0), p1 = vec3_at(mesh.positions, i1);
    vec3 p2 = vec3_at(mesh.positions, i2);
    vec4 c0 = camera.view_proj * (inst.model * vec4(p0, 1.0));
    vec4 c1 = camera.view_proj * (inst.model * vec4(p1, 1.0));
    vec4 c2 = camera.view_proj * (inst.model * vec4(p2, 1.0));
    vec3 r0 = cross(c1.xyw, c2.xyw), r1 = cross(c2.xyw, c0.xyw), r2 = cross(c0.xyw, c1.xyw);
    vec2 size = vec2(isize);
    vec3 b = weights(r0, r1, r2, px, size);
    // the texture gradients a fragment shader's implicit lookup takes: differences across
    // the pixel's 2x2 quad, from its top-left pixel (coarse), on this triangle's plane as
    // the rasteriser's helper pixels extend it
    ivec2 corner = px & ~1;
    vec3 b00 = weights(r0, r1, r2, corner, size);
    vec3 bx = weights(r0, r1, r2, corner + ivec2(1, 0), size) - b00;
    vec3 by = weights(r0, r1, r2, corner + ivec2(0, 1), size) - b00;

    Vec2s uvs = Vec2s(mesh.uvs);
    vec2 t0 = uvs.v[i0], t1 = uvs.v[i1], t2 = uvs.v[i2];
    vec2 uv = b.x * t0 + b.y * t1 + b.z * t2;
    g_duv_dx = bx.x * t0 + bx.y * t1 + bx.z * t2;
    g_duv_dy = by.x * t0 + by.y * t1 + by.z * t2;
    vec3 n_obj = b.x * vec3_at(mesh.normals, i0) + b.y * vec3_at(mesh.normals, i1)
        + b.z * vec3_at(mesh.normals, i2);
    Vec4s tans = Vec4s(mesh.tangents);
    vec4 t_obj = b.x * tans.v[i0] + b.y * tans.v[i1] + b.z * tans.v[i2];
    vec3 n = (inst.normal * vec4(n_obj, 0.0)).xyz;
    vec4 t = vec4((inst.model * vec4(t_obj.xyz, 0.0)).xyz,
                  inst.mesh.y == 1u ? -t_obj.w : t_obj.w);

    SceneMaterial mat = materials.m[mesh.material];
    g_slots = Slots(mat.textures.x, mat.textures.y, mat.textures.z, mat.textures.w,
                    mat.more.x, mat.more.y);
    Surface s = material_surface(mat.factors, uv, n, t);
    // what gbuffer.frag.glsl writes, through the formats of its attachments
    imageStore(o_albedo, px, vec4(srgb_quantized(s.base_color.rgb), 1.0));
    imageStore(o_normal, px, vec4(s.normal, 1.0));
    imageStore(o_material, px, vec4(s.occlusion, s.roughness, s.metallic, 1.0));
    imageStore(o_emissive, px, vec4(s.emissive, 1.0));
}
