// sun shadow lookup with a 3x3 PCF kernel on a comparison sampler
fn sun_shadow(map: texture_depth_2d, cmp: sampler_comparison, p: vec3f, n: vec3f,
              l: vec3f, bias: f32) -> f32 {
    let texel = 1.0 / vec2f(textureDimensions(map));
    // normal offset keeps lit faces from shadowing themselves at grazing angles
    let offset = n * (1.0 - clamp(dot(n, l), 0.0, 1.0)) * 2.0 * texel.x * 40.0;
    let h = lights.sun_view_proj * vec4f(p + offset, 1.0);
    let c = h.xyz / h.w;
    let uv = vec2f(c.x * 0.5 + 0.5, 0.5 - c.y * 0.5);
    if (any(uv < vec2f(0.0)) || any(uv > vec2f(1.0)) || c.z > 1.0) {
        return 1.0;
    }
    var lit = 0.0;
    for (var y = -1; y <= 1; y++) {
        for (var x = -1; x <= 1; x++) {
            lit += textureSampleCompareLevel(map, cmp, uv + vec2f(f32(x), f32(y)) * texel,
                                             c.z - bias);
        }
    }
    return lit / 9.0;
}
