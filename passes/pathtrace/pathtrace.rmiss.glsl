#version 460
#extension GL_EXT_ray_tracing : require
#include "pathtrace_scene.glsl"

layout(location = 0) rayPayloadInEXT Payload payload;

void main() {
    payload.hit.instance = -1;
}
