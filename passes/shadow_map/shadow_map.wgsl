#include "mesh.wgsl"

@vertex
fn vs_main(v: VertexIn) -> @builtin(position) vec4f {
    return camera.view_proj * (instance.model * vec4f(v.position, 1.0));
}
