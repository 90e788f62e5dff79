#include "mesh.wgsl"

@vertex
fn vs_main(v: VertexIn) -> @builtin(position) vec4f {
    return camera.view_proj * (instance.model * vec4f(v.position, 1.0));
}

@fragment
fn fs_main() -> @location(0) vec4f {
    return vec4f(1.0);
}
