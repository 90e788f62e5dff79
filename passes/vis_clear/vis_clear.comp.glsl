#version 460
// all ones in every word: larger than any (depth, ~id) a surface writes
layout(local_size_x = 256) in;

layout(set = 0, binding = 0, std430) writeonly buffer Ids { uvec2 v[]; } ids;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i < uint(ids.v.length())) {
        ids.v[i] = uvec2(0xffffffffu);
    }
}
