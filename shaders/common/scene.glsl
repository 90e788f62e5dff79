// camera and lights: set 1, shared by every pass that shades or projects
//
// byte layouts are rfw/backends/scene_data.py's; std140 gives them, and the explicit offsets
// make glslang reject any drift.
// matrices are column-major in both languages.
#ifndef RFW_SCENE_GLSL
#define RFW_SCENE_GLSL

layout(set = 1, binding = 0, std140) uniform CameraBlock {
    layout(offset = 0) mat4 view;
    layout(offset = 64) mat4 proj;
    layout(offset = 128) mat4 view_proj;
    layout(offset = 192) mat4 inv_view_proj;
    layout(offset = 256) vec4 position;   // world position, w unused
    layout(offset = 272) vec4 viewport;   // width, height, 1/width, 1/height
    layout(offset = 288) vec4 near_far;   // near, far
} camera;                                 // 304 bytes

struct Light {           // 64 bytes, array stride 64 in both layouts
    vec4 position;       // 0   w: kind (0 directional, 1 point, 2 spot)
    vec4 direction;      // 16  direction the light travels; w: range (0 = infinite)
    vec4 color;          // 32  linear rgb; w: intensity
    vec4 cone;           // 48  cos(inner), cos(outer)
};

const uint MAX_LIGHTS = 16u;

layout(set = 1, binding = 1, std140) uniform LightsBlock {
    layout(offset = 0) uvec4 count;          // x: number of lights, y: index of the sun
    layout(offset = 16) mat4 sun_view_proj;
    layout(offset = 80) vec4 ambient;        // linear rgb sky ambient
    layout(offset = 96) Light items[16];
} lights;                                    // 1120 bytes

// world position from a depth value (0..1) at pixel centre `p` of a `size` target; ndc y is
// WebGPU's (up): the vk vertex shaders flip y, so camera matrices and images are shared
vec3 world_from_depth(vec2 p, vec2 size, float depth) {
    vec2 ndc = vec2(p.x / size.x * 2.0 - 1.0, 1.0 - p.y / size.y * 2.0);
    vec4 h = camera.inv_view_proj * vec4(ndc, depth, 1.0);
    return h.xyz / h.w;
}

// clip space is WebGPU's (ndc +y up) on both backends: wgpu reads the SPIR-V as is, and the
// vk backend draws with a negative-height viewport, which puts every vertex at the
// framebuffer position WebGPU gives it; images, depth and the framebuffer-space winding (so
// the front face, ccw) are the same on both.

#endif
