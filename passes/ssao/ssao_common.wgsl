// what both ssao dispatches share: settings and view-space positions from the depth buffer
#include "scene.wgsl"

struct Params {
    radius: f32,
    samples: i32,
    intensity: f32,
    power: f32,
    bias: f32,
    blur_radius: i32,
    blur_depth: f32,
};

#ifdef DEPTH_TEXTURE
@group(0) @binding(0) var t_depth: texture_depth_2d;
#else
@group(0) @binding(0) var t_depth: texture_2d<f32>;
#endif
@group(0) @binding(3) var<uniform> u_params: Params;

fn load_depth(px: vec2i) -> f32 {
#ifdef DEPTH_TEXTURE
    return textureLoad(t_depth, px, 0);
#else
    return textureLoad(t_depth, px, 0).r;
#endif
}

// view-space position of the centre of full-resolution pixel px at depth d
fn view_position(px: vec2i, d: f32) -> vec3f {
    let size = vec2f(textureDimensions(t_depth));
    let world = world_from_depth(vec2f(px) + 0.5, size, d);
    return (camera.view * vec4f(world, 1.0)).xyz;
}

// the full-resolution pixel a half-resolution texel stands for
fn source_pixel(id: vec2u) -> vec2i {
    return min(vec2i(id * 2u), vec2i(textureDimensions(t_depth)) - 1);
}
