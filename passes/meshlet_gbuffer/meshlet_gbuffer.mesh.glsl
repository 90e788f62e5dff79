#version 460
// one meshlet per workgroup: the twin of gbuffer.vert.glsl for the meshlet's vertices (the
// same expressions, WebGPU clip space flipped by the render pass's viewport, invariant
// position), and its packed 8-bit triangles.
// passes/gbuffer/gbuffer.frag.glsl shades the result unchanged.
//
// F_TRIANGLES culls back-facing triangles here (gl_CullPrimitiveEXT) before the rasterizer
// would: only triangles whose three vertices are in front of the eye and whose signed
// pixel area is negative by more than the rasterizer's snapping could change (1/256 pixel
// per vertex), so the image cannot change. F_COLORS writes each triangle's meshlet (per
// primitive) for the debug colors of gbuffer.frag.glsl's MESHLET_COLORS.
#extension GL_EXT_mesh_shader : require
#include "meshlet.glsl"

layout(local_size_x = 32) in;
layout(triangles, max_vertices = 64, max_primitives = 124) out;

// the scene's CameraBlock (scene.glsl): the camera the mesh shader projects with
layout(set = 0, binding = 0, std140) uniform view_camera { MCamera m_camera; };
layout(set = 0, binding = 2, std430) readonly buffer meshlets { uvec4 m_meshlets[]; };
layout(set = 0, binding = 3, std430) readonly buffer vertices { uint m_vertices[]; };
layout(set = 0, binding = 4, std430) readonly buffer triangles { uint m_triangles[]; };
layout(set = 0, binding = 9, std430) readonly buffer positions { vec4 m_positions[]; };
layout(set = 0, binding = 10, std430) readonly buffer normals { vec4 m_normals[]; };
layout(set = 0, binding = 11, std430) readonly buffer uvs { vec4 m_uvs[]; };
layout(set = 0, binding = 12, std430) readonly buffer tangents { vec4 m_tangents[]; };

taskPayloadSharedEXT MPayload payload;

out gl_MeshPerVertexEXT {
    invariant vec4 gl_Position;
} gl_MeshVerticesEXT[];

layout(location = 0) out vec3 o_normal[];
layout(location = 1) out vec2 o_uv[];
layout(location = 2) out vec4 o_tangent[];
#ifdef MESHLET_COLORS
layout(location = 3) perprimitiveEXT flat out uint o_meshlet[];
#endif
// only the culling flag of the per-primitive built-ins (the full block would declare the
// shading-rate capability too)
perprimitiveEXT out gl_MeshPerPrimitiveEXT {
    bool gl_CullPrimitiveEXT;
} gl_MeshPrimitivesEXT[];

shared vec3 s_screen[64];  // pixels (x right, y up) and w of each vertex
shared uint s_backface;

void main() {
    uint row = payload.meshlets[gl_WorkGroupID.x];
    uvec4 m = m_meshlets[row];
    uint vcount = m.z, tcount = m.w;
    SetMeshOutputsEXT(vcount, tcount);
    mat4 model = m_instances[payload.instance].model;
    mat4 normal = m_instances[payload.instance].normal;
    // a mirroring model reverses the winding on screen and the tangent frame's handedness
    bool mirrored = m_instances[payload.instance].bounds.z < 0.0;
    bool cull_triangles = (m_push.flags & F_TRIANGLES) != 0u;
    if (gl_LocalInvocationIndex == 0u) {
        s_backface = 0u;
    }
    for (uint v = gl_LocalInvocationIndex; v < vcount; v += 32u) {
        uint k = m_vertices[m.x + v];
        vec4 clip = m_camera.view_proj * (model * vec4(m_positions[k].xyz, 1.0));
        gl_MeshVerticesEXT[v].gl_Position = clip;  // WebGPU's clip space (scene.glsl)
        o_normal[v] = (normal * vec4(m_normals[k].xyz, 0.0)).xyz;
        vec4 t = m_tangents[k];
        o_tangent[v] = vec4((model * vec4(t.xyz, 0.0)).xyz, mirrored ? -t.w : t.w);
        o_uv[v] = m_uvs[k].xy;
        s_screen[v] = vec3(clip.xy / clip.w * 0.5 * m_push.viewport, clip.w);
    }
    barrier();
    for (uint t = gl_LocalInvocationIndex; t < tcount; t += 32u) {
        uvec3 idx;
        for (uint c = 0u; c < 3u; ++c) {
            uint b = 3u * t + c;
            idx[c] = (m_triangles[m.y + (b >> 2u)] >> (8u * (b & 3u))) & 0xffu;
        }
        if (mirrored) {
            idx = idx.xzy;  // counter-clockwise on screen again: the pipeline culls back faces
        }
        gl_PrimitiveTriangleIndicesEXT[t] = idx;
#ifdef MESHLET_COLORS
        o_meshlet[t] = row;
#endif
        bool cull = false;
        if (cull_triangles) {
            vec3 a = s_screen[idx.x], b = s_screen[idx.y], c = s_screen[idx.z];
            if (a.z > 0.0 && b.z > 0.0 && c.z > 0.0) {
                vec2 e1 = b.xy - a.xy, e2 = c.xy - a.xy;
                float area2 = e1.x * e2.y - e1.y * e2.x;  // > 0: counter-clockwise, front
                // a vertex moved by up to 1/256 pixel changes area2 by at most this much
                float margin = (length(e1) + length(e2) + length(c.xy - b.xy)) / 64.0 + 1e-3;
                cull = area2 < -margin;
            }
            if (cull) {
                atomicAdd(s_backface, 1u);
            }
        }
        gl_MeshPrimitivesEXT[t].gl_CullPrimitiveEXT = cull;
    }
    barrier();
    if (gl_LocalInvocationIndex == 0u && s_backface != 0u) {
        atomicAdd(m_counters[C_TRIANGLES_BACKFACE], s_backface);
    }
}
