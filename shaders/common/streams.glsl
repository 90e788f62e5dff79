// Typed views of the scene's vertex and index streams through device addresses (a mesh's
// part of a stream starts at the address its pass hands the shader). Needs
// GL_EXT_buffer_reference.
#ifndef RFW_STREAMS_GLSL
#define RFW_STREAMS_GLSL

layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer Floats {
    float v[];
};
layout(buffer_reference, std430, buffer_reference_align = 8) readonly buffer Vec2s {
    vec2 v[];
};
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer Vec4s {
    vec4 v[];
};
layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer Uints {
    uint v[];
};

#endif
