// camera motion for temporal passes: last frame's view-projection beside this frame's
//
// a block of the pass's own set 0 (no other pass's layout changes), at binding
// MOTION_BINDING (default 0); the scene fills it (scene bindings "motion", byte layout
// rfw/backends/scene_data.py's CameraFrames). Matrices are unjittered: a motion vector made
// from them carries the motion alone, and `jitter` says how this frame's image is shifted.
#ifndef RFW_MOTION_GLSL
#define RFW_MOTION_GLSL

#ifndef MOTION_BINDING
#define MOTION_BINDING 0
#endif

layout(set = 0, binding = MOTION_BINDING, std140) uniform MotionBlock {
    layout(offset = 0) mat4 prev_view_proj;      // last frame's (this frame's on the first)
    layout(offset = 64) mat4 prev_inv_view_proj;
    layout(offset = 128) mat4 view_proj;         // this frame's, without the jitter
    layout(offset = 192) vec4 jitter;            // pixels (x right, y down): xy this frame's, zw last's
} motion;                                        // 208 bytes

// pixel position (y down) of a clip-space point on a `size` target
vec2 pixel_of_clip(vec4 clip, vec2 size) {
    vec2 ndc = clip.xy / clip.w;
    return vec2(ndc.x * 0.5 + 0.5, 0.5 - ndc.y * 0.5) * size;
}

#endif
