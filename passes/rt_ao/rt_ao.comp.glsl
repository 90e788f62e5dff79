#version 460
// ray-traced ambient occlusion by ray query: any hit within the radius occludes
#extension GL_EXT_ray_query : require
#extension GL_EXT_samplerless_texture_functions : require
#include "rt_ao.glsl"
#include "rt_occluded_query.glsl"

layout(local_size_x = 8, local_size_y = 8) in;

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = imageSize(o_ao);
    if (px.x >= size.x || px.y >= size.y) {
        return;
    }
    float ao = ambient_occlusion(px, vec2(size));
    imageStore(o_ao, px, vec4(ao, ao, ao, 1.0));
}
