#version 460
// masked and blended surfaces (non-opaque geometry): ignored where surface_blocks says the
// ray passes
#extension GL_EXT_ray_tracing : require
#include "pathtrace_scene.glsl"

layout(location = 0) rayPayloadInEXT Payload payload;
hitAttributeEXT vec2 barycentrics;

void main() {
    if (!surface_blocks(gl_InstanceCustomIndexEXT, gl_PrimitiveID, barycentrics, payload.seed)) {
        ignoreIntersectionEXT;
    }
}
