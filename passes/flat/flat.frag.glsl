#version 460
// the base colour factor only: no texture is read, and the value is stored unencoded
#include "mesh.glsl"

layout(location = 0) in float i_light;

layout(location = 0) out vec4 o_color;

void main() {
    o_color = vec4(material.base_color.rgb * i_light, 1.0);
}
