// metallic-roughness BRDF (GGX, Smith height-correlated, Schlick) and punctual lights
const PI: f32 = 3.14159265358979;

fn d_ggx(noh: f32, a: f32) -> f32 {
    let a2 = a * a;
    let d = noh * noh * (a2 - 1.0) + 1.0;
    return a2 / (PI * d * d);
}

fn v_smith(nov: f32, nol: f32, a: f32) -> f32 {
    let a2 = a * a;
    let gv = nol * sqrt(nov * nov * (1.0 - a2) + a2);
    let gl = nov * sqrt(nol * nol * (1.0 - a2) + a2);
    return 0.5 / max(gv + gl, 1e-5);
}

fn f_schlick(f0: vec3f, voh: f32) -> vec3f {
    return f0 + (vec3f(1.0) - f0) * pow(1.0 - voh, 5.0);
}

// radiance reflected toward v from light arriving along l with irradiance e (n.l applied here)
fn brdf(base: vec3f, metallic: f32, roughness: f32, n: vec3f, v: vec3f, l: vec3f,
        e: vec3f) -> vec3f {
    let h = normalize(v + l);
    let nol = clamp(dot(n, l), 0.0, 1.0);
    let nov = clamp(abs(dot(n, v)), 1e-4, 1.0);
    let noh = clamp(dot(n, h), 0.0, 1.0);
    let voh = clamp(dot(v, h), 0.0, 1.0);
    let a = roughness * roughness;
    let f0 = mix(vec3f(0.04), base, metallic);
    let f = f_schlick(f0, voh);
    let spec = d_ggx(noh, a) * v_smith(nov, nol, a) * f;
    let diffuse = (1.0 - metallic) * (vec3f(1.0) - f) * base / PI;
    return (diffuse + spec) * e * nol;
}

// direction toward light i and the irradiance it delivers at p (before n.l and shadowing)
fn light_at(i: u32, p: vec3f, l_out: ptr<function, vec3f>) -> vec3f {
    let li = lights.items[i];
    let kind = u32(li.position.w);
    let power = li.color.rgb * li.color.w;
    if (kind == 0u) {
        *l_out = -normalize(li.direction.xyz);
        return power;
    }
    let d = li.position.xyz - p;
    let dist2 = max(dot(d, d), 1e-4);
    let l = d * inverseSqrt(dist2);
    *l_out = l;
    var atten = 1.0 / dist2;
    let range = li.direction.w;
    if (range > 0.0) {
        let r = dist2 / (range * range);
        atten *= clamp(1.0 - r * r, 0.0, 1.0);
    }
    if (kind == 2u) {
        let cd = dot(normalize(li.direction.xyz), -l);
        atten *= smoothstep(li.cone.y, li.cone.x, cd);
    }
    return power * atten;
}
