#version 460
#extension GL_EXT_ray_tracing : require

struct PrimaryHit {
    vec2 barycentrics;
    int instance;
    int primitive;
    mat4x3 object_to_world;
};

layout(location = 0) rayPayloadInEXT PrimaryHit payload;

void main() {
    payload.instance = -1;
    payload.primitive = -1;
}
