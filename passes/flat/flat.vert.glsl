#version 460
// lambert per vertex from the scene's sun; the fragment stage multiplies the base colour in
#define MESH_VERTEX_INPUT
#include "mesh.glsl"

layout(set = 0, binding = 0, std140) uniform Params {
    float ambient;
} u_params;

layout(location = 0) out float o_light;

// towards the sun; rfw.backends.scene_data's shadow default where no light is directional
vec3 to_sun() {
    if (lights.count.y < MAX_LIGHTS) {
        return -normalize(lights.items[lights.count.y].direction.xyz);
    }
    return -normalize(vec3(-0.3, -1.0, -0.2));
}

void main() {
    vec4 w = instance.model * vec4(v_position, 1.0);
    gl_Position = camera.view_proj * w;
    vec3 n = normalize((instance.normal * vec4(v_normal, 0.0)).xyz);
    o_light = u_params.ambient + (1.0 - u_params.ambient) * max(dot(n, to_sun()), 0.0);
}
