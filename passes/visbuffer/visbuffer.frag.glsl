#version 460
// the visibility buffer's one word; an alpha-masked material's test is gbuffer.frag.glsl's
// (material_cut on the same product), so both cut the same pixels
#include "mesh.glsl"

layout(location = 0) in vec2 i_uv;
layout(location = 1) flat in uint i_instance;

layout(location = 0) out uint o_id;

void main() {
    MaterialFactors m = MaterialFactors(material.base_color, material.emissive,
                                        material.params, material.flags);
    if (m.flags.x == 1u) {
        vec4 base = m.base_color * texture(sampler2D(base_color_tex, material_sampler), i_uv);
        if (material_cut(m, base.a)) {
            discard;
        }
    }
    // visbuffer.py's triangle_bits: the instance in the high bits, the triangle below
    o_id = (i_instance << TRIANGLE_BITS) | uint(gl_PrimitiveID);
}
