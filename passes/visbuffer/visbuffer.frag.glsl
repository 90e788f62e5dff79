#version 460
// the visibility buffer's one id; an alpha-masked material's test is gbuffer.frag.glsl's
// (material_cut on the same product), so both cut the same pixels.
// ATOMIC (visbuffer.py's write = "atomic"): no color target; the id goes into the pixel's
// 64-bit word of `ids` by atomic min of (depth bits << 32 | ~id): the nearest surface wins,
// at equal depth the larger id (drawn later, as less-equal gives). EARLY_TESTS: the opaque
// draw, whose hidden fragments never reach the shader.
#ifdef ATOMIC
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_EXT_shader_atomic_int64 : require
#endif
#include "mesh.glsl"

#ifdef EARLY_TESTS
layout(early_fragment_tests) in;
#endif

layout(location = 0) in vec2 i_uv;
layout(location = 1) flat in uint i_instance;

#ifdef ATOMIC
layout(set = 0, binding = 0, std430) buffer Ids { uint64_t v[]; } ids;
#else
layout(location = 0) out uint o_id;
#endif

void main() {
#ifndef EARLY_TESTS
    MaterialFactors m = MaterialFactors(material.base_color, material.emissive,
                                        material.params, material.flags);
    if (m.flags.x == 1u) {
        vec4 base = m.base_color * texture(sampler2D(base_color_tex, material_sampler), i_uv);
        if (material_cut(m, base.a)) {
            discard;
        }
    }
#endif
    // visbuffer.py's triangle_bits: the instance in the high bits, the triangle below
    uint id = (i_instance << TRIANGLE_BITS) | uint(gl_PrimitiveID);
#ifdef ATOMIC
    uvec2 px = uvec2(gl_FragCoord.xy);
    uint64_t word = (uint64_t(floatBitsToUint(gl_FragCoord.z)) << 32) | uint64_t(~id);
    atomicMin(ids.v[px.y * uint(camera.viewport.x) + px.x], word);
#else
    o_id = id;
#endif
}
