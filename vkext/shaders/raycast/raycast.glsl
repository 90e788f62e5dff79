// raycast: what the ray-query and the ray-pipeline variants share (include only)
// the host's numpy twins are vkext.raycast.RAY_DTYPE and HIT_DTYPE

// one ray: origin and tmin, direction and tmax (direction need not be unit length: t is in
// its units, as Embree's and Vulkan's are)
struct Ray {
    vec4 origin_tmin;
    vec4 direction_tmax;
};

// std430: five scalars, stride 20 bytes
struct Hit {
    float t;  // +inf on a miss
    int primitive;  // triangle of the mesh, -1 on a miss
    int instance;  // gl_InstanceCustomIndexEXT: the scene's instance index, -1 on a miss
    float u;  // barycentric weights of the triangle's 2nd and 3rd vertices
    float v;
};

Hit miss_hit() {
    return Hit(uintBitsToFloat(0x7f800000u), -1, -1, 0.0, 0.0);
}
