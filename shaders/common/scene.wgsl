// camera and lights: group 1, shared by every pass that shades or projects
struct Camera {
    view: mat4x4f,
    proj: mat4x4f,
    view_proj: mat4x4f,
    inv_view_proj: mat4x4f,
    position: vec4f,   // world position, w unused
    viewport: vec4f,   // width, height, 1/width, 1/height
    near_far: vec4f,   // near, far
};

struct Light {
    position: vec4f,   // w: kind (0 directional, 1 point, 2 spot)
    direction: vec4f,  // direction the light travels; w: range (0 = infinite)
    color: vec4f,      // linear rgb; w: intensity
    cone: vec4f,       // cos(inner), cos(outer)
};

const MAX_LIGHTS: u32 = 16u;

struct Lights {
    count: vec4u,          // x: number of lights, y: index of the sun (or MAX_LIGHTS)
    sun_view_proj: mat4x4f,
    ambient: vec4f,        // linear rgb sky ambient
    items: array<Light, 16>,
};

@group(1) @binding(0) var<uniform> camera: Camera;
@group(1) @binding(1) var<uniform> lights: Lights;

// world position from a depth value (0..1) at pixel centre `p` of a `size` target
fn world_from_depth(p: vec2f, size: vec2f, depth: f32) -> vec3f {
    let ndc = vec2f(p.x / size.x * 2.0 - 1.0, 1.0 - p.y / size.y * 2.0);
    let h = camera.inv_view_proj * vec4f(ndc, depth, 1.0);
    return h.xyz / h.w;
}
