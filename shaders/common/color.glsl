// display encoding
#ifndef RFW_COLOR_GLSL
#define RFW_COLOR_GLSL

vec3 srgb_encode(vec3 c) {
    vec3 lo = c * 12.92;
    vec3 hi = 1.055 * pow(max(c, vec3(0.0)), vec3(1.0 / 2.4)) - 0.055;
    // bvec mix picks per component, as WGSL's select(hi, lo, cond)
    return mix(hi, lo, lessThanEqual(c, vec3(0.0031308)));
}

// the inverse of srgb_encode: display levels back to linear, as an sRGB format's reads give
vec3 srgb_decode(vec3 c) {
    vec3 lo = c / 12.92;
    vec3 hi = pow((max(c, vec3(0.0)) + 0.055) / 1.055, vec3(2.4));
    return mix(hi, lo, lessThanEqual(c, vec3(0.04045)));
}

float luminance(vec3 c) {
    return dot(c, vec3(0.2126, 0.7152, 0.0722));
}

#endif
