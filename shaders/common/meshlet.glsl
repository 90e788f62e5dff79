// what the meshlet passes share (passes/meshlet_cull, passes/meshlet_gbuffer): flags,
// phases, counters, and the set 0 buffers every one of their shaders reads. the buffers are
// bound by name (the block names): the scene's meshlet data from vkext/meshlet.py, the
// counters, commands and visibility from the frame graph. every mesh of the scene lives in
// one set of arrays: meshlet rows are rebased so that vertex_offset / triangle_offset index
// the global `m_vertices` / `m_triangles` arrays and meshlet vertices index the global
// attribute arrays.
#ifndef RFW_MESHLET_GLSL
#define RFW_MESHLET_GLSL

#define TASK_GROUP 32

// flags (push constants): which tests run, and the debug outputs
#define F_CONE 1u
#define F_FRUSTUM 2u
#define F_OCCLUSION 4u
#define F_TRIANGLES 8u      // per-triangle backface culling in the mesh shader
#define F_COLORS 16u        // meshlet colors (the mesh shader's o_meshlet)

// phases: one pass with every test but occlusion, or two-phase occlusion culling
#define PHASE_SINGLE 0u
#define PHASE_EARLY 1u      // what was visible last frame (m_visibility), no occlusion test
#define PHASE_LATE 2u       // everything against this frame's pyramid; draws the newly visible

// counters (m_counters), the names vkext.meshlet.COUNTERS gives them
#define C_CONSIDERED 0
#define C_CONE 1
#define C_FRUSTUM 2
#define C_OCCLUSION 3
#define C_DRAWN 4
#define C_TRIANGLES 5
#define C_TRIANGLES_CONE 6
#define C_TRIANGLES_FRUSTUM 7
#define C_TRIANGLES_OCCLUSION 8
#define C_TRIANGLES_DRAWN 9
#define C_TRIANGLES_BACKFACE 10
#define C_INSTANCES_CULLED 11
#define C_DRAWN_LATE 12
#define C_COUNT 13

struct MCamera {
    mat4 view;
    mat4 proj;
    mat4 view_proj;
    mat4 inv_view_proj;
    vec4 position;
};

// the camera the culling tests use: the main camera, or the one kept while culling is frozen
layout(set = 0, binding = 13, std140) uniform cull_camera { MCamera m_cull; };

struct MInstance {
    mat4 model;
    mat4 normal;     // inverse transpose of model
    vec4 bounds;     // x: largest column scale of model, y: 1 if the cone test is valid,
                     // z: -1 if model mirrors (negative determinant), else 1
};
layout(set = 0, binding = 1, std430) readonly buffer instances { MInstance m_instances[]; };
// the frame's counters (a graph buffer: the culling pass clears it, every pass adds to it)
layout(set = 0, binding = 8, std430) buffer counters { uint m_counters[C_COUNT]; };

// one per draw (a mesh instance), sorted by material: a material's draws are one
// vkCmdDrawMeshTasksIndirectEXT whose gl_DrawIDARB counts from m_push.draw_base
struct MDraw {
    uvec4 ids;       // instance, first meshlet row, meshlet count, first visibility word
    uvec4 info;      // x: triangles of the mesh
    vec4 sphere;     // the mesh's bounding sphere (object space)
};
layout(set = 0, binding = 14, std430) readonly buffer draws { MDraw m_draws[]; };

layout(push_constant) uniform MPush {
    uint draw_base;  // the first draw of this vkCmdDrawMeshTasksIndirectEXT
    uint flags;      // F_*
    uint phase;      // PHASE_*
    uint draw_count; // draws (the culling compute pass)
    vec2 viewport;   // pixels (per-triangle culling's margin)
} m_push;

struct MPayload {
    uint instance;
    uint meshlets[TASK_GROUP];  // surviving meshlet rows (absolute), dense
};

// Gribb-Hartmann planes of WebGPU clip space (-w <= x, y <= w, 0 <= z <= w) of the culling
// camera; true if the sphere (world center c, radius r) is entirely outside one of them
bool frustum_culled(vec3 c, float r) {
    mat4 m = transpose(m_cull.view_proj);  // rows of view_proj
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

#endif
