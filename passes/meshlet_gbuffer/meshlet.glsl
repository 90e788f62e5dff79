// meshlet data shared by meshlet_gbuffer.task.glsl and meshlet_gbuffer.mesh.glsl (set 0,
// written by vkext/meshlet.py). every mesh of the scene lives in one set of arrays: meshlet
// rows are rebased so that vertex_offset / triangle_offset index the global `meshlet_vertices`
// / `meshlet_triangles` arrays and meshlet vertices index the global attribute arrays.
#ifndef RFW_MESHLET_GLSL
#define RFW_MESHLET_GLSL

#define TASK_GROUP 32

layout(set = 0, binding = 0, std140) uniform MCameraBlock {
    layout(offset = 0) mat4 view;
    layout(offset = 64) mat4 proj;
    layout(offset = 128) mat4 view_proj;
    layout(offset = 192) mat4 inv_view_proj;
    layout(offset = 256) vec4 position;
} m_camera;  // the scene's CameraBlock (scene.glsl), bound here for the task/mesh stages

struct MInstance {
    mat4 model;
    mat4 normal;     // inverse transpose of model
    vec4 bounds;     // x: largest column scale of model, y: 1 if the cone test is valid
};
layout(set = 0, binding = 1, std430) readonly buffer MInstances { MInstance m_instances[]; };
// vertex_offset, triangle_offset (words), vertex_count, triangle_count
layout(set = 0, binding = 2, std430) readonly buffer MMeshlets { uvec4 m_meshlets[]; };
layout(set = 0, binding = 3, std430) readonly buffer MVertices { uint m_vertices[]; };
layout(set = 0, binding = 4, std430) readonly buffer MTriangles { uint m_triangles[]; };
layout(set = 0, binding = 5, std430) readonly buffer MSpheres { vec4 m_spheres[]; };
layout(set = 0, binding = 6, std430) readonly buffer MCones { uint m_cones[]; };
layout(set = 0, binding = 7, std430) readonly buffer MConeApex { vec4 m_cone_apex[]; };

// per draw (one instance): what vkext.meshlet.draw_meshlets pushes
layout(push_constant) uniform MDraw {
    uint instance;        // index into m_instances
    uint first_meshlet;   // the mesh's first row of m_meshlets
    uint meshlet_count;
    uint flags;           // bit 0: cone, bit 1: frustum, bit 2: occlusion culling
} m_draw;

struct MPayload {
    uint meshlets[TASK_GROUP];  // surviving meshlet rows (absolute), dense
};

#endif
