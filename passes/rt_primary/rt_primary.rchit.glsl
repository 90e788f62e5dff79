#version 460
#extension GL_EXT_ray_tracing : require
#extension GL_EXT_scalar_block_layout : enable

struct PrimaryHit {
    vec2 barycentrics;
    int instance;
    int primitive;
    mat4x3 object_to_world;
};

layout(location = 0) rayPayloadInEXT PrimaryHit payload;
hitAttributeEXT vec2 barycentrics;

void main() {
    payload = PrimaryHit(barycentrics, gl_InstanceCustomIndexEXT, gl_PrimitiveID,
                         gl_ObjectToWorldEXT);
}
