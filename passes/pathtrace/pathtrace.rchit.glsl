#version 460
#extension GL_EXT_ray_tracing : require
#include "pathtrace_scene.glsl"

layout(location = 0) rayPayloadInEXT Payload payload;
hitAttributeEXT vec2 barycentrics;

void main() {
    payload.hit = Hit(barycentrics, gl_InstanceCustomIndexEXT, gl_PrimitiveID, gl_HitTEXT);
}
