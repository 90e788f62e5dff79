#version 460
// one meshlet per invocation: cone (backface) and frustum culling, the survivors compacted
// into the payload with a subgroup ballot inside each subgroup and a prefix over subgroups
// in shared memory, so the indices are dense for any subgroup size (8 on lavapipe, 32/64 on
// desktop GPUs). Culling is conservative (a meshlet that has a visible front face is kept).
#extension GL_EXT_mesh_shader : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_ballot : require
#include "meshlet.glsl"

layout(local_size_x = TASK_GROUP) in;

// meshlets considered, culled by the cone test, culled by the frustum test, drawn
layout(set = 0, binding = 8, std430) buffer MCounters { uint m_counters[4]; };

taskPayloadSharedEXT MPayload payload;

shared uint s_count[TASK_GROUP];   // survivors per subgroup (at most TASK_GROUP subgroups)
shared uint s_stats[3];            // considered, cone, frustum

bool frustum_culled(vec3 c, float r) {
    // Gribb-Hartmann planes of WebGPU clip space (-w <= x, y <= w, 0 <= z <= w)
    mat4 m = transpose(m_camera.view_proj);  // rows of view_proj
    vec4 planes[6] = vec4[6](m[3] + m[0], m[3] - m[0], m[3] + m[1], m[3] - m[1], m[2],
                             m[3] - m[2]);
    for (int k = 0; k < 6; ++k) {
        vec4 p = planes[k];
        if (dot(p.xyz, c) + p.w < -r * length(p.xyz)) {
            return true;
        }
    }
    return false;
}

bool cone_culled(uint row, MInstance inst) {
    uint packed = m_cones[row];
    int cutoff_s8 = bitfieldExtract(int(packed), 24, 8);
    if (cutoff_s8 >= 127 || inst.bounds.y == 0.0) {
        return false;  // a cone that covers every direction (or a mirrored instance)
    }
    vec3 axis = vec3(bitfieldExtract(int(packed), 0, 8), bitfieldExtract(int(packed), 8, 8),
                     bitfieldExtract(int(packed), 16, 8)) / 127.0;
    // rotation and uniform scale keep angles: the cone moves with the model matrix
    vec3 apex = (inst.model * vec4(m_cone_apex[row].xyz, 1.0)).xyz;
    vec3 axis_w = mat3(inst.model) * axis / inst.bounds.x;
    return dot(normalize(apex - m_camera.position.xyz), axis_w) >= float(cutoff_s8) / 127.0;
}

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (gl_LocalInvocationIndex < 3u) {
        s_stats[gl_LocalInvocationIndex] = 0u;
    }
    barrier();
    bool valid = i < m_draw.meshlet_count;
    bool visible = valid;
    uint row = m_draw.first_meshlet + i;
    if (valid) {
        MInstance inst = m_instances[m_draw.instance];
        atomicAdd(s_stats[0], 1u);
        if ((m_draw.flags & 2u) != 0u) {
            vec4 s = m_spheres[row];
            vec3 c = (inst.model * vec4(s.xyz, 1.0)).xyz;
            if (frustum_culled(c, s.w * inst.bounds.x)) {
                visible = false;
                atomicAdd(s_stats[2], 1u);
            }
        }
        if (visible && (m_draw.flags & 1u) != 0u && cone_culled(row, inst)) {
            visible = false;
            atomicAdd(s_stats[1], 1u);
        }
    }
    uvec4 ballot = subgroupBallot(visible);
    uint local = subgroupBallotExclusiveBitCount(ballot);
    if (subgroupElect()) {
        s_count[gl_SubgroupID] = subgroupBallotBitCount(ballot);
    }
    barrier();
    uint base = 0u, total = 0u;
    for (uint s = 0u; s < gl_NumSubgroups; ++s) {
        base += s < gl_SubgroupID ? s_count[s] : 0u;
        total += s_count[s];
    }
    if (visible) {
        payload.meshlets[base + local] = row;
    }
    if (gl_LocalInvocationIndex == 0u) {
        atomicAdd(m_counters[0], s_stats[0]);
        atomicAdd(m_counters[1], s_stats[1]);
        atomicAdd(m_counters[2], s_stats[2]);
        atomicAdd(m_counters[3], total);
    }
    EmitMeshTasksEXT(total, 1, 1);
}
