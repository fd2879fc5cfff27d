// ---- lights (hybrid_core::shading) ----

fn spot_cone(cos_angle: f32, cos_inner: f32, cos_outer: f32) -> f32 {
    if cos_inner <= cos_outer {
        return select(0.0, 1.0, cos_angle >= cos_outer);
    }
    let t = clamp((cos_angle - cos_outer) / (cos_inner - cos_outer), 0.0, 1.0);
    return t * t * (3.0 - 2.0 * t);
}

fn attenuation_factor(a: vec4<f32>, d: f32) -> f32 {
    return 1.0 / max(a.x + a.y * d + a.z * d * d, 1e-12);
}

/// Direction towards the light from `p`, distance (a huge value for directional lights) and
/// the radiance arriving at `p` (unshadowed).
struct Incident {
    dir: vec3<f32>,
    distance: f32,
    radiance: vec3<f32>,
}

const FAR_AWAY: f32 = 3.0e38;

fn light_incident(light: Light, p: vec3<f32>) -> Incident {
    if light.kind.x == LIGHT_DIRECTIONAL {
        return Incident(light.direction.xyz, FAR_AWAY, light.power.xyz);
    }
    let d = light.position.xyz - p;
    let len = length(d);
    var dir = vec3<f32>(0.0, 1.0, 0.0);
    if len > 0.0 {
        dir = d / len;
    }
    var radiance = light.power.xyz * attenuation_factor(light.attenuation, len);
    if light.kind.x == LIGHT_SPOT {
        radiance = radiance * spot_cone(dot(-dir, light.direction.xyz), light.cone.x, light.cone.y);
    }
    return Incident(dir, len, radiance);
}

/// The normal flipped, if needed, to the viewer's side.
fn facing(n: vec3<f32>, view: vec3<f32>) -> vec3<f32> {
    if dot(n, view) < 0.0 {
        return -n;
    }
    return n;
}

/// Blinn–Phong contribution of light `i` to `s` seen along `view` (unshadowed).
fn blinn_phong(i: u32, s: Surface, view: vec3<f32>) -> vec3<f32> {
    let inc = light_incident(lights[i], s.position);
    if all(inc.radiance == vec3<f32>(0.0)) {
        return vec3<f32>(0.0);
    }
    let n = facing(s.normal, view);
    let n_dot_l = dot(n, inc.dir);
    if n_dot_l <= 0.0 {
        return vec3<f32>(0.0);
    }
    var spec = vec3<f32>(0.0);
    if any(s.specular != vec3<f32>(0.0)) {
        let h = normalize_or(inc.dir + view, vec3<f32>(0.0));
        spec = s.specular * pow(max(dot(n, h), 0.0), specular_exponent(s.shininess));
    }
    return (s.diffuse * n_dot_l + spec) * inc.radiance;
}

/// Listing 5: emission + env_ambient · ambient + Σ lights Blinn–Phong, unshadowed.
fn local_lighting(s: Surface, view: vec3<f32>) -> vec3<f32> {
    var c = s.emission + frame.env_ambient.xyz * s.ambient;
    for (var i = 0u; i < frame.counts.x; i++) {
        c += blinn_phong(i, s, view);
    }
    return c;
}

// ---- directions (listings 8a/8c) ----

fn reflect_dir(i: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    return i - 2.0 * dot(n, i) * n;
}

/// Refraction between the environment and the material (entering when `i` goes against `n`),
/// falling back to the reflection on total internal reflection. xyz direction, w = 1 on TIR.
fn refract_or_reflect(i: vec3<f32>, n_in: vec3<f32>, env_ior: f32, mat_ior: f32) -> vec4<f32> {
    var n = n_in;
    var eta = env_ior / mat_ior;
    if dot(i, n_in) >= 0.0 {
        n = -n_in;
        eta = mat_ior / env_ior;
    }
    let cos_i = -dot(n, i);
    let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
    if k < 0.0 {
        return vec4<f32>(reflect_dir(i, n_in), 1.0);
    }
    return vec4<f32>(normalize(eta * i + (eta * cos_i - sqrt(k)) * n), 0.0);
}

