#version 460
// examples/plugin_pass.py's pass: mix(color, 1 - color, amount), alpha kept
#extension GL_EXT_samplerless_texture_functions : require  // texelFetch on texture2D

layout(local_size_x = 8, local_size_y = 8) in;

layout(set = 0, binding = 0) uniform texture2D t_color;
layout(set = 0, binding = 1, rgba8) uniform writeonly image2D o_inverted;
layout(set = 0, binding = 2, std140) uniform Params {
    float amount;
} u_params;

void main() {
    ivec2 id = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(id, imageSize(o_inverted)))) {
        return;  // threads are rounded up to whole workgroups
    }
    vec4 c = texelFetch(t_color, id, 0);
    imageStore(o_inverted, id, vec4(mix(c.rgb, 1.0 - c.rgb, u_params.amount), c.a));
}
