// rt_primary: what the ray-pipeline and ray-query variants share (include only), after the
// talk's barycentrics and albedo example: mesh data is read through buffer references
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_EXT_nonuniform_qualifier : require
#extension GL_EXT_samplerless_texture_functions : require
#include "raytrace.glsl"

#ifndef MAX_TEXTURES
#define MAX_TEXTURES 1
#endif

#include "streams.glsl"

// rt_primary.py's MESH_DTYPE and MATERIAL_DTYPE
struct GpuMesh {
    uint64_t positions;  // device addresses of the scene's own vertex and index buffers
    uint64_t uvs;
    uint64_t indices;
    uint material;
    uint pad;
};
struct GpuMaterial {
    vec4 base_color;
    int texture;  // index into textures, -1: none
    int pad0, pad1, pad2;
};

// what a primary ray found (the talk's payload): -1 instance on a miss
struct PrimaryHit {
    vec2 barycentrics;  // weights of the triangle's 2nd and 3rd vertices
    int instance;  // the scene's instance index (instanceCustomIndex)
    int primitive;  // triangle of the mesh
    mat4x3 object_to_world;
};

layout(set = 0, binding = 0) uniform accelerationStructureEXT tlas;
layout(set = 0, binding = 1, std430) readonly buffer Meshes { GpuMesh mesh[]; } meshes;
layout(set = 0, binding = 2, std430) readonly buffer Instances { uint mesh[]; } instances;
layout(set = 0, binding = 3, std430) readonly buffer Materials { GpuMaterial m[]; } materials;
layout(set = 0, binding = 4) uniform texture2D textures[MAX_TEXTURES];
layout(set = 0, binding = 5) uniform sampler s_texture;
layout(set = 0, binding = 6, rgba16f) uniform writeonly image2D o_barycentrics;
layout(set = 0, binding = 7, rgba16f) uniform writeonly image2D o_albedo;

// the camera ray through a pixel centre (the talk's compute_ray_dir, from the camera)
void camera_ray(ivec2 px, vec2 size, out vec3 origin, out vec3 direction) {
    vec2 ndc = vec2((float(px.x) + 0.5) / size.x * 2.0 - 1.0,
                    1.0 - (float(px.y) + 0.5) / size.y * 2.0);
    vec4 far = camera.inv_view_proj * vec4(ndc, 1.0, 1.0);
    origin = camera.position.xyz;
    direction = normalize(far.xyz / far.w - origin);
}

vec2 to_pixels(vec3 world, vec2 size) {
    vec4 clip = camera.view_proj * vec4(world, 1.0);
    return clip.xy / clip.w * 0.5 * size;
}

void shade(ivec2 px, vec2 size, PrimaryHit h) {
    if (h.instance < 0) {
        imageStore(o_barycentrics, px, vec4(0.0));
        imageStore(o_albedo, px, vec4(0.0));
        return;
    }
    GpuMesh mesh = meshes.mesh[instances.mesh[h.instance]];
    Uints index = Uints(mesh.indices);
    uint i0 = index.v[3 * h.primitive], i1 = index.v[3 * h.primitive + 1];
    uint i2 = index.v[3 * h.primitive + 2];
    Floats pos = Floats(mesh.positions);
    vec3 p0 = vec3(pos.v[3 * i0], pos.v[3 * i0 + 1], pos.v[3 * i0 + 2]);
    vec3 p1 = vec3(pos.v[3 * i1], pos.v[3 * i1 + 1], pos.v[3 * i1 + 2]);
    vec3 p2 = vec3(pos.v[3 * i2], pos.v[3 * i2 + 1], pos.v[3 * i2 + 2]);
    Vec2s uv = Vec2s(mesh.uvs);
    vec2 uv0 = uv.v[i0], uv1 = uv.v[i1], uv2 = uv.v[i2];
    float b = h.barycentrics.x, c = h.barycentrics.y, a = 1.0 - b - c;
    GpuMaterial mat = materials.m[mesh.material];
    vec4 albedo = mat.base_color;
    if (mat.texture >= 0) {
        // the talk's LOD: half the log2 of texels per screen pixel over the triangle
        vec2 s0 = to_pixels(h.object_to_world * vec4(p0, 1.0), size);
        vec2 s1 = to_pixels(h.object_to_world * vec4(p1, 1.0), size);
        vec2 s2 = to_pixels(h.object_to_world * vec4(p2, 1.0), size);
        vec2 tsize = vec2(textureSize(textures[nonuniformEXT(mat.texture)], 0));
        float texel_area = tsize.x * tsize.y * abs((uv1.x - uv0.x) * (uv2.y - uv0.y)
                                                  - (uv2.x - uv0.x) * (uv1.y - uv0.y));
        float screen_area = abs((s1.x - s0.x) * (s2.y - s0.y) - (s2.x - s0.x) * (s1.y - s0.y));
        float lod = max(0.0, 0.5 * log2(texel_area / max(screen_area, 1e-12)));
        albedo *= textureLod(sampler2D(textures[nonuniformEXT(mat.texture)], s_texture),
                             a * uv0 + b * uv1 + c * uv2, lod);
    }
    imageStore(o_barycentrics, px, vec4(b, c, a, 1.0));
    imageStore(o_albedo, px, vec4(albedo.rgb, 1.0));
}
