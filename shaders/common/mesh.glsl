// scene geometry: vertex layout, material (set 2) and instances (set 3)
//
// a vertex shader defines MESH_VERTEX_INPUT before including this file to declare the
// vertex attributes (WGSL's VertexIn): one buffer per attribute, see wgpu.scene.VERTEX_BUFFERS
#ifndef RFW_MESH_GLSL
#define RFW_MESH_GLSL

#include "scene.glsl"

#ifdef MESH_VERTEX_INPUT
layout(location = 0) in vec3 v_position;   // float32x3, stride 12
layout(location = 1) in vec3 v_normal;     // float32x3, stride 12
layout(location = 2) in vec2 v_uv;         // float32x2, stride 8
layout(location = 3) in vec4 v_tangent;    // float32x4, stride 16
#endif

layout(set = 2, binding = 0, std140) uniform MaterialBlock {
    layout(offset = 0) vec4 base_color;
    layout(offset = 16) vec4 emissive;     // w: normal scale
    layout(offset = 32) vec4 params;       // metallic, roughness, occlusion strength, cutoff
    layout(offset = 48) uvec4 flags;       // x: alpha mode (0 opaque, 1 mask, 2 blend)
} material;                                // 64 bytes
layout(set = 2, binding = 1) uniform texture2D base_color_tex;
layout(set = 2, binding = 2) uniform texture2D metal_rough_tex;
layout(set = 2, binding = 3) uniform texture2D normal_tex;
layout(set = 2, binding = 4) uniform texture2D occlusion_tex;
layout(set = 2, binding = 5) uniform texture2D emissive_tex;
layout(set = 2, binding = 6) uniform sampler material_sampler;

// every instance's matrices in one storage buffer, indexed by the draw's instance: a scene
// draw's firstInstance is the instance's index (one set for the whole scene, however many
// instances; scene_data.instance_blocks writes the rows)
struct InstanceData {
    mat4 model;
    mat4 normal;                           // inverse transpose of the model matrix
};                                         // 128 bytes, std430 array stride 128

layout(set = 3, binding = 0, std430) readonly buffer InstanceBlock {
    InstanceData items[];
} scene_instances;

#ifdef MESH_VERTEX_INPUT
// the drawn instance's block, as `instance.model` and `instance.normal` (vertex stage: a
// fragment shader gets what it needs through its inputs)
#define instance (scene_instances.items[gl_InstanceIndex])
#endif

#ifndef MESH_VERTEX_INPUT
// implicit-lod sampling of the bound material: fragment stage only (WGSL leaves it out of
// vertex entry points by reachability)
#define MATERIAL_TEXTURE(name, uv) texture(sampler2D(name, material_sampler), uv)
#endif
#include "material.glsl"

#ifndef MESH_VERTEX_INPUT
// the bound material at a point, with the normal map applied in world space
Surface surface(vec2 uv, vec3 n_in, vec4 t_in) {
    MaterialFactors m = MaterialFactors(material.base_color, material.emissive,
                                        material.params, material.flags);
    return material_surface(m, uv, n_in, t_in);
}
#endif

#endif
