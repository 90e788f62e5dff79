#version 460
// invariant: the same expression as depth_prepass.vert.glsl, so less-equal against the
// prepass depth passes exactly where this surface is nearest.
// VELOCITY: also the surface's unjittered clip position this frame and last frame, from
// motion.glsl's matrices and last frame's instance rows (set 0), for the motion vector
#define MESH_VERTEX_INPUT
#include "mesh.glsl"
#ifdef VELOCITY
#include "motion.glsl"

layout(set = 0, binding = 1, std430) readonly buffer PrevInstanceBlock {
    InstanceData items[];
} prev_instances;
#endif

invariant gl_Position;

layout(location = 0) out vec3 o_normal;
layout(location = 1) out vec2 o_uv;
layout(location = 2) out vec4 o_tangent;
#ifdef VELOCITY
layout(location = 4) out vec4 o_clip;
layout(location = 5) out vec4 o_prev_clip;
#endif

void main() {
    gl_Position = camera.view_proj * (instance.model * vec4(v_position, 1.0));
    o_normal = (instance.normal * vec4(v_normal, 0.0)).xyz;
    o_tangent = vec4((instance.model * vec4(v_tangent.xyz, 0.0)).xyz, v_tangent.w);
    o_uv = v_uv;
#ifdef VELOCITY
    o_clip = motion.view_proj * (instance.model * vec4(v_position, 1.0));
    o_prev_clip = motion.prev_view_proj *
        (prev_instances.items[gl_InstanceIndex].model * vec4(v_position, 1.0));
#endif
}
