#version 460
// unlit (glTF 2.0 section 3.7.2.1): base colour factor times COLOR_0, plus emissive
#include "mesh.glsl"

layout(location = 0) in vec4 i_color;

layout(location = 0) out vec4 o_color;

void main() {
    vec4 base = material.base_color * i_color;
    if (material.flags.x == 1u && base.a < material.params.w) {
        discard;
    }
    // alpha 1 marks a covered pixel (tonemap paints the sky where it is 0)
    o_color = vec4(base.rgb + material.emissive.rgb, 1.0);
}
