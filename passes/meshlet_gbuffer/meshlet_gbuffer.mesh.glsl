#version 460
// one meshlet per workgroup: the twin of gbuffer.vert.glsl for the meshlet's vertices (the
// same expressions, the same y flip, invariant position), and its packed 8-bit triangles.
// passes/gbuffer/gbuffer.frag.glsl shades the result unchanged.
#extension GL_EXT_mesh_shader : require
#include "meshlet.glsl"

layout(local_size_x = 32) in;
layout(triangles, max_vertices = 64, max_primitives = 124) out;

layout(set = 0, binding = 9, std430) readonly buffer MPositions { vec4 m_positions[]; };
layout(set = 0, binding = 10, std430) readonly buffer MNormals { vec4 m_normals[]; };
layout(set = 0, binding = 11, std430) readonly buffer MUvs { vec4 m_uvs[]; };
layout(set = 0, binding = 12, std430) readonly buffer MTangents { vec4 m_tangents[]; };

taskPayloadSharedEXT MPayload payload;

out gl_MeshPerVertexEXT {
    invariant vec4 gl_Position;
} gl_MeshVerticesEXT[];

layout(location = 0) out vec3 o_normal[];
layout(location = 1) out vec2 o_uv[];
layout(location = 2) out vec4 o_tangent[];

// WebGPU clip space to Vulkan's (scene.glsl's vk_clip)
vec4 vk_clip(vec4 clip) {
    return vec4(clip.x, -clip.y, clip.z, clip.w);
}

void main() {
    uint row = payload.meshlets[gl_WorkGroupID.x];
    uvec4 m = m_meshlets[row];
    uint vcount = m.z, tcount = m.w;
    SetMeshOutputsEXT(vcount, tcount);
    mat4 model = m_instances[m_draw.instance].model;
    mat4 normal = m_instances[m_draw.instance].normal;
    for (uint v = gl_LocalInvocationIndex; v < vcount; v += 32u) {
        uint k = m_vertices[m.x + v];
        gl_MeshVerticesEXT[v].gl_Position =
            vk_clip(m_camera.view_proj * (model * vec4(m_positions[k].xyz, 1.0)));
        o_normal[v] = (normal * vec4(m_normals[k].xyz, 0.0)).xyz;
        vec4 t = m_tangents[k];
        o_tangent[v] = vec4((model * vec4(t.xyz, 0.0)).xyz, t.w);
        o_uv[v] = m_uvs[k].xy;
    }
    for (uint t = gl_LocalInvocationIndex; t < tcount; t += 32u) {
        uvec3 idx;
        for (uint c = 0u; c < 3u; ++c) {
            uint b = 3u * t + c;
            idx[c] = (m_triangles[m.y + (b >> 2u)] >> (8u * (b & 3u))) & 0xffu;
        }
        gl_PrimitiveTriangleIndicesEXT[t] = idx;
    }
}
