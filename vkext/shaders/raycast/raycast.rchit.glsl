#version 460
#extension GL_EXT_ray_tracing : require
#include "raycast.glsl"

layout(location = 0) rayPayloadInEXT Hit payload;
hitAttributeEXT vec2 barycentrics;  // weights of the 2nd and 3rd vertices

void main() {
    payload = Hit(gl_HitTEXT, gl_PrimitiveID, gl_InstanceCustomIndexEXT, barycentrics.x,
                  barycentrics.y);
}
