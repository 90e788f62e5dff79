#version 460
// ray-traced shadows by ray query: terminate on the first hit, no shader tables
#extension GL_EXT_ray_query : require
#extension GL_EXT_samplerless_texture_functions : require
#include "rt_shadows.glsl"
#include "rt_occluded_query.glsl"

layout(local_size_x = 8, local_size_y = 8) in;

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = imageSize(o_visibility);
    if (px.x >= size.x || px.y >= size.y) {
        return;
    }
    imageStore(o_visibility, px, uvec4(visibility_bits(px, vec2(size))));
}
