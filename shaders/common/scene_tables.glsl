// The scene tables of rfw.authoring.scene_tables (include only): per mesh the device
// addresses of its parts of the scene's streams, per instance its matrices, per material
// its factors and texture slots; any shader reaches any triangle and its material through
// them. Needs GL_EXT_buffer_reference, GL_EXT_shader_explicit_arithmetic_types_int64,
// streams.glsl and material.glsl (MaterialFactors), included first.
#ifndef RFW_SCENE_TABLES_GLSL
#define RFW_SCENE_TABLES_GLSL

// rfw.authoring's MESH_DTYPE, INSTANCE_DTYPE and MATERIAL_DTYPE
struct SceneMesh {
    uint64_t positions;
    uint64_t normals;
    uint64_t uvs;
    uint64_t tangents;
    uint64_t indices;
    uint material;
    uint pad;
};
struct SceneInstance {
    mat4 model;
    mat4 normal;  // inverse transpose of the model matrix
    uvec4 mesh;  // x: mesh, y: 1 where the transform mirrors (the tangent's w flips)
};
struct SceneMaterial {
    MaterialFactors factors;
    ivec4 textures;  // base color, metallic-roughness, normal, occlusion (texture_lists)
    ivec4 more;  // x: emissive texture, y: sampler (into the sampler list)
};

vec3 vec3_at(uint64_t address, uint i) {
    Floats f = Floats(address);
    return vec3(f.v[3 * i], f.v[3 * i + 1], f.v[3 * i + 2]);
}

#endif
