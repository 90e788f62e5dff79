#version 460
// one meshlet per invocation: cone (backface), frustum and occlusion culling, the survivors
// compacted into the payload with a subgroup ballot inside each subgroup and a prefix over
// subgroups in shared memory, so the indices are dense for any subgroup size (8 on
// lavapipe, 32 on NVIDIA, 64 elsewhere). Culling is conservative: a meshlet that has a
// visible front face is kept.
//
// The draw is m_draws[m_push.draw_base + gl_DrawIDARB] (one indirect command per instance).
// Phases (meshlet.glsl): PHASE_SINGLE runs the cone and frustum tests; two-phase occlusion
// culling runs PHASE_EARLY (the meshlets visible last frame, by m_visibility) and, after
// the depth pyramid of what it drew is built, PHASE_LATE (every meshlet against that
// pyramid; records visibility for the next frame; draws what was not drawn early).
// Counting: every meshlet lands in exactly one of drawn / culled by cone, frustum or
// occlusion; the single and late phases count the tests, the early phase only what it draws.
#extension GL_EXT_mesh_shader : require
#extension GL_ARB_shader_draw_parameters : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_ballot : require
#ifdef OCCLUSION
#extension GL_EXT_samplerless_texture_functions : require  // texelFetch on texture2D
#endif
#include "meshlet.glsl"

layout(local_size_x = TASK_GROUP) in;

// vertex_offset, triangle_offset (words), vertex_count, triangle_count
layout(set = 0, binding = 2, std430) readonly buffer meshlets { uvec4 m_meshlets[]; };
layout(set = 0, binding = 5, std430) readonly buffer spheres { vec4 m_spheres[]; };
layout(set = 0, binding = 6, std430) readonly buffer cones { uint m_cones[]; };
layout(set = 0, binding = 7, std430) readonly buffer cone_apex { vec4 m_cone_apex[]; };
// one word per (draw, meshlet): 1 if the meshlet was visible at the end of the last frame
// (a persistent graph buffer, made by passes/meshlet_cull)
layout(set = 0, binding = 16, std430) buffer visibility { uint m_visibility[]; };

#ifdef OCCLUSION
// this frame's max-depth pyramid (passes/depth_pyramid) of what the early phase drew:
// level 0 at the render size, level L's texel min(p >> L, size_L - 1) holds the farthest
// depth of level-0 pixel p
layout(set = 4, binding = 0) uniform texture2D t_pyramid;
#endif

taskPayloadSharedEXT MPayload payload;

shared uint s_count[TASK_GROUP];   // survivors per subgroup (at most TASK_GROUP subgroups)
shared uint s_stats[C_COUNT];

bool cone_culled(uint row, MInstance inst) {
    uint packed = m_cones[row];
    int cutoff_s8 = bitfieldExtract(int(packed), 24, 8);
    if (cutoff_s8 >= 127 || inst.bounds.y == 0.0) {
        return false;  // a cone that covers every direction (or a non-uniform scale)
    }
    vec3 axis = vec3(bitfieldExtract(int(packed), 0, 8), bitfieldExtract(int(packed), 8, 8),
                     bitfieldExtract(int(packed), 16, 8)) / 127.0;
    // rotation, mirroring and uniform scale keep angles: the cone moves with the model
    // matrix (a mirrored instance's triangles are emitted rewound, so its front faces
    // are the mirrored ones)
    vec3 apex = (inst.model * vec4(m_cone_apex[row].xyz, 1.0)).xyz;
    vec3 axis_w = mat3(inst.model) * axis / inst.bounds.x;
    return dot(normalize(apex - m_cull.position.xyz), axis_w) >= float(cutoff_s8) / 127.0;
}

#ifdef OCCLUSION
// the sphere's bounds along one view axis (a = x or y, z forward > r): the tangent directions
// from the eye (Mara and McGuire 2013, niagara's form), as a / z of the two tangents
vec2 tangent_bounds(vec2 c, float r) {
    float t = sqrt(dot(c, c) - r * r);
    return vec2((t * c.x - r * c.y) / (r * c.x + t * c.y), (t * c.x + r * c.y) / (t * c.y - r * c.x));
}

// conservative: true only if every point of the sphere (world center c, radius r) is farther
// than the pyramid's farthest depth over the sphere's screen rectangle
bool occlusion_culled(vec3 c, float r) {
    r = r * 1.01 + 1e-4;  // margin for float error (keeps the test conservative)
    vec3 v = (m_cull.view * vec4(c, 1.0)).xyz;
    vec3 cv = vec3(v.xy, -v.z);  // right-handed view: the camera looks down -z
    mat4 P = m_cull.proj;
    float znear = cv.z - r;
    if (znear <= 1e-3 * r || r * r >= dot(cv, cv)) {
        return false;  // the sphere reaches the eye plane: don't cull
    }
    // the nearest depth of the sphere (perspective depth depends on view z only)
    float d_sphere = (P[2][2] * -znear + P[3][2]) / znear;
    if (d_sphere <= 0.0) {
        return false;  // in front of the near plane
    }
    vec2 bx = tangent_bounds(cv.xz, r) * P[0][0];  // NDC x, left to right
    vec2 by = tangent_bounds(cv.yz, r) * P[1][1];  // NDC y, up
    // NDC to pixels (WebGPU NDC y up, row 0 at the top)
    ivec2 size = textureSize(t_pyramid, 0);
    vec2 lo = vec2(bx.x * 0.5 + 0.5, 0.5 - by.y * 0.5) * vec2(size) - 0.5;
    vec2 hi = vec2(bx.y * 0.5 + 0.5, 0.5 - by.x * 0.5) * vec2(size) + 0.5;
    ivec2 p0 = clamp(ivec2(floor(lo)), ivec2(0), size - 1);
    ivec2 p1 = clamp(ivec2(floor(hi)), ivec2(0), size - 1);
    int levels = textureQueryLevels(t_pyramid);
    for (int l = 0; l < levels; ++l) {
        ivec2 s = max(size >> l, ivec2(1));
        ivec2 a = min(p0 >> l, s - 1), b = min(p1 >> l, s - 1);
        if (b.x - a.x <= 1 && b.y - a.y <= 1) {  // at most 2x2 texels
            float d = max(max(texelFetch(t_pyramid, a, l).r, texelFetch(t_pyramid, ivec2(b.x, a.y), l).r),
                          max(texelFetch(t_pyramid, ivec2(a.x, b.y), l).r, texelFetch(t_pyramid, b, l).r));
            return d_sphere > d;
        }
    }
    return false;  // larger than the top level's 2x2: not tested
}
#endif

void count(int counter, uint meshlets, int tri_counter, uint triangles) {
    atomicAdd(s_stats[counter], meshlets);
    atomicAdd(s_stats[tri_counter], triangles);
}

void main() {
    if (gl_LocalInvocationIndex < uint(C_COUNT)) {
        s_stats[gl_LocalInvocationIndex] = 0u;
    }
    barrier();
    MDraw draw = m_draws[m_push.draw_base + gl_DrawIDARB];
    uint i = gl_GlobalInvocationID.x;
    uint phase = m_push.phase, flags = m_push.flags;
    bool valid = i < draw.ids.z;
    uint row = draw.ids.y + i;
    uint triangles = valid ? m_meshlets[row].w : 0u;
    bool last = valid && phase != PHASE_SINGLE && m_visibility[draw.ids.w + i] != 0u;
    bool counting = phase != PHASE_EARLY;
    // the early phase looks only at what was visible last frame
    bool visible = valid && (phase != PHASE_EARLY || last);
    if (visible) {
        MInstance inst = m_instances[draw.ids.x];
        vec4 s = m_spheres[row];
        vec3 c = (inst.model * vec4(s.xyz, 1.0)).xyz;
        float r = s.w * inst.bounds.x;
        if (counting) {
            count(C_CONSIDERED, 1u, C_TRIANGLES, triangles);
        }
        if ((flags & F_FRUSTUM) != 0u && frustum_culled(c, r)) {
            visible = false;
            if (counting) {
                count(C_FRUSTUM, 1u, C_TRIANGLES_FRUSTUM, triangles);
            }
        } else if ((flags & F_CONE) != 0u && cone_culled(row, inst)) {
            visible = false;
            if (counting) {
                count(C_CONE, 1u, C_TRIANGLES_CONE, triangles);
            }
        }
#ifdef OCCLUSION
        else if (phase == PHASE_LATE && (flags & F_OCCLUSION) != 0u && occlusion_culled(c, r)) {
            visible = false;
            if (!last) {  // one visible last frame was drawn by the early phase
                count(C_OCCLUSION, 1u, C_TRIANGLES_OCCLUSION, triangles);
            }
        }
#endif
    }
    // the late phase records visibility for the next frame's early phase; the single phase
    // records it too (MeshletScene.visibility() reads it back, and an early phase may follow)
    if (valid && phase != PHASE_EARLY) {
        m_visibility[draw.ids.w + i] = visible ? 1u : 0u;
    }
    // the late phase draws only the newly visible: the early phase drew the rest
    bool emit = visible && !(phase == PHASE_LATE && last);
    if (emit) {
        atomicAdd(s_stats[C_TRIANGLES_DRAWN], triangles);
    }
    uvec4 ballot = subgroupBallot(emit);
    uint local = subgroupBallotExclusiveBitCount(ballot);
    if (subgroupElect()) {
        s_count[gl_SubgroupID] = subgroupBallotBitCount(ballot);
    }
    barrier();
    uint base = 0u, total = 0u;
    for (uint k = 0u; k < gl_NumSubgroups; ++k) {
        base += k < gl_SubgroupID ? s_count[k] : 0u;
        total += s_count[k];
    }
    if (emit) {
        payload.meshlets[base + local] = row;
    }
    if (gl_LocalInvocationIndex == 0u) {
        payload.instance = draw.ids.x;
        s_stats[C_DRAWN] = total;
        s_stats[C_DRAWN_LATE] = phase == PHASE_LATE ? total : 0u;
    }
    barrier();
    if (gl_LocalInvocationIndex < uint(C_COUNT) && s_stats[gl_LocalInvocationIndex] != 0u) {
        atomicAdd(m_counters[gl_LocalInvocationIndex], s_stats[gl_LocalInvocationIndex]);
    }
    EmitMeshTasksEXT(total, 1, 1);
}
