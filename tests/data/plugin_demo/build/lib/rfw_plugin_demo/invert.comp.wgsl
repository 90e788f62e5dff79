@group(0) @binding(0) var t_src: texture_2d<f32>;
@group(0) @binding(1) var o_dst: texture_storage_2d<rgba8unorm, write>;

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3u) {
    let size = textureDimensions(o_dst);
    if (id.x >= size.x || id.y >= size.y) {
        return;
    }
    let c = textureLoad(t_src, vec2i(id.xy), 0);
    textureStore(o_dst, vec2i(id.xy), vec4f(1.0 - c.rgb, 1.0 - c.a));
}
