#include "mesh.wgsl"

// the same expression as gbuffer.wgsl and forward.wgsl, so depths compare equal; invariant
// asks the compiler to evaluate it identically in every pipeline
@vertex
fn vs_main(v: VertexIn) -> @builtin(position) @invariant vec4f {
    return camera.view_proj * (instance.model * vec4f(v.position, 1.0));
}
