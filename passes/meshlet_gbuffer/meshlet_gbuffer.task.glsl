#version 460
// one meshlet per invocation: cone (backface) and frustum culling, the survivors compacted
// into the payload with a subgroup ballot inside each subgroup and a prefix over subgroups
// in shared memory, so the indices are dense for any subgroup size (8 on lavapipe, 32/64 on
// desktop GPUs). Culling is conservative (a meshlet that has a visible front face is kept).
#extension GL_EXT_mesh_shader : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_ballot : require
#ifdef OCCLUSION
#extension GL_EXT_samplerless_texture_functions : require  // texelFetch on texture2D
#endif
#include "meshlet.glsl"

layout(local_size_x = TASK_GROUP) in;

// meshlets considered, culled by the cone test, culled by the frustum test, drawn, culled by
// the occlusion test
layout(set = 0, binding = 8, std430) buffer MCounters { uint m_counters[5]; };

#ifdef OCCLUSION
// the previous frame's max-depth pyramid (passes/depth_pyramid): level 0 at the render size,
// level L's texel min(p >> L, size_L - 1) holds the farthest depth of level-0 pixel p
layout(set = 4, binding = 0) uniform texture2D t_pyramid;
#endif

taskPayloadSharedEXT MPayload payload;

shared uint s_count[TASK_GROUP];   // survivors per subgroup (at most TASK_GROUP subgroups)
shared uint s_stats[4];            // considered, cone, frustum, occlusion

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
    vec3 v = (m_camera.view * vec4(c, 1.0)).xyz;
    vec3 cv = vec3(v.xy, -v.z);  // right-handed view: the camera looks down -z
    mat4 P = m_camera.proj;
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

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (gl_LocalInvocationIndex < 4u) {
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
#ifdef OCCLUSION
        if (visible && (m_draw.flags & 4u) != 0u) {
            vec4 s = m_spheres[row];
            if (occlusion_culled((inst.model * vec4(s.xyz, 1.0)).xyz, s.w * inst.bounds.x)) {
                visible = false;
                atomicAdd(s_stats[3], 1u);
            }
        }
#endif
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
        atomicAdd(m_counters[4], s_stats[3]);
    }
    EmitMeshTasksEXT(total, 1, 1);
}
