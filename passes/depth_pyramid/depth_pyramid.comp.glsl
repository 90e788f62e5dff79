#version 460
// one level of the max-depth pyramid (depth_pyramid.py): FROM_DEPTH copies the depth buffer
// into level 0, otherwise each texel is the max of its 2x2 source texels, plus the third
// row/column where the source size is odd and this is the last texel (conservative).
#extension GL_EXT_samplerless_texture_functions : require  // texelFetch on texture2D

layout(local_size_x = 8, local_size_y = 8) in;

#ifdef FROM_DEPTH
layout(set = 0, binding = 0) uniform texture2D t_depth;
#else
layout(set = 0, binding = 0, r32f) uniform readonly image2D i_src;
#endif
layout(set = 0, binding = 1, r32f) uniform writeonly image2D o_dst;

void main() {
    ivec2 id = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = imageSize(o_dst);
    if (id.x >= size.x || id.y >= size.y) {
        return;
    }
#ifdef FROM_DEPTH
    float d = texelFetch(t_depth, id, 0).r;
#else
    ivec2 src = imageSize(i_src);
    ivec2 lo = 2 * id;
    ivec2 hi = min(2 * id + 1, src - 1);
    if (id.x == size.x - 1) {
        hi.x = src.x - 1;
    }
    if (id.y == size.y - 1) {
        hi.y = src.y - 1;
    }
    float d = 0.0;
    for (int y = lo.y; y <= hi.y; ++y) {
        for (int x = lo.x; x <= hi.x; ++x) {
            d = max(d, imageLoad(i_src, ivec2(x, y)).r);
        }
    }
#endif
    imageStore(o_dst, id, vec4(d));
}
