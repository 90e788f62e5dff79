#version 460
// the indirect draws of the meshlet passes: one VkDrawMeshTasksIndirectCommandEXT per mesh
// instance (m_draws' order), with the instance culled as a whole against the culling
// camera's frustum (its mesh's bounding sphere) before any of its meshlets is looked at. A
// culled instance launches no task workgroup; its meshlets and triangles are counted as
// frustum-culled (in the single and late phases, which count; the early phase does not).
#include "meshlet.glsl"

layout(local_size_x = 64) in;

// x, y, z task workgroups (the indirect command), w unused (16-byte stride)
layout(set = 0, binding = 15, std430) writeonly buffer MCommands { uvec4 m_commands[]; };

void main() {
    uint d = gl_GlobalInvocationID.x;
    if (d >= m_push.draw_count) {
        return;
    }
    MDraw draw = m_draws[d];
    MInstance inst = m_instances[draw.ids.x];
    bool visible = true;
    if ((m_push.flags & F_FRUSTUM) != 0u) {
        vec3 c = (inst.model * vec4(draw.sphere.xyz, 1.0)).xyz;
        visible = !frustum_culled(c, draw.sphere.w * inst.bounds.x);
    }
    uint groups = (draw.ids.z + TASK_GROUP - 1u) / TASK_GROUP;
    m_commands[d] = uvec4(visible ? groups : 0u, 1u, 1u, 0u);
    if (!visible && m_push.phase != PHASE_EARLY) {
        atomicAdd(m_counters[C_CONSIDERED], draw.ids.z);
        atomicAdd(m_counters[C_FRUSTUM], draw.ids.z);
        atomicAdd(m_counters[C_TRIANGLES], draw.info.x);
        atomicAdd(m_counters[C_TRIANGLES_FRUSTUM], draw.info.x);
        atomicAdd(m_counters[C_INSTANCES_CULLED], 1u);
    }
}
