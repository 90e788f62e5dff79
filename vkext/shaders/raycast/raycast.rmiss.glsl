#version 460
#extension GL_EXT_ray_tracing : require
#include "raycast.glsl"

layout(location = 0) rayPayloadInEXT Hit payload;

void main() {
    payload = miss_hit();
}
