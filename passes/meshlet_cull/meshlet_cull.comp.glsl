#version 460
// the indirect draws of a meshlet G-buffer pass: one VkDrawMeshTasksIndirectCommandEXT per
// mesh instance (m_draws' order), with the instance culled as a whole against the culling
// camera's frustum (its mesh's bounding sphere) before any of its meshlets is looked at. A
// culled instance launches no task workgroup; its meshlets and triangles are counted as
// frustum-culled and its visibility words are cleared (in the single and late phases, which
// count and record visibility; the early phase does neither).
//
// CLEAR: the dispatch before, in the single and early phases: zero the frame's counters and
// the first m_push.draw_count visibility words (all of them on an executor's first frame:
// nothing was visible before it, so its early phase draws nothing).
#include "meshlet.glsl"

layout(local_size_x = 64) in;

// x, y, z task workgroups (the indirect command), w unused (16-byte stride)
layout(set = 0, binding = 15, std430) writeonly buffer commands { uvec4 m_commands[]; };
// one word per (draw, meshlet): 1 if the meshlet was visible at the end of the last frame
layout(set = 0, binding = 16, std430) buffer visibility { uint m_visibility[]; };

#ifdef CLEAR
void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i < uint(C_COUNT)) {
        m_counters[i] = 0u;
    }
    if (i < m_push.draw_count) {
        m_visibility[i] = 0u;
    }
}
#else
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
        // no task shader runs for it: its meshlets were not visible this frame
        for (uint i = 0u; i < draw.ids.z; ++i) {
            m_visibility[draw.ids.w + i] = 0u;
        }
    }
}
#endif
