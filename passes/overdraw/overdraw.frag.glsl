#version 460
// every fragment adds 1 (the pipeline blends one + one)

layout(location = 0) out vec4 o_count;

void main() {
    o_count = vec4(1.0);
}
