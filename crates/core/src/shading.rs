//! Shading shared by every stage and backend: Blinn–Phong for the three light kinds (paper
//! listing 5), the skybox, and the reflection/refraction directions (listing 8a/8c).

use glam::{Vec2, Vec3, Vec4};
use hybrid_scene::texture::Texture;
use hybrid_scene::{DirectionalLight, Environment, Lights, PointLight, Skybox, SpotLight, specular_exponent};

use crate::buffers::Surface;
use crate::lanes::{V3, aos, dot3, normalize_or_zero3, soa, splat3};

/// Rec. 709 luminance of a linear colour.
pub fn luminance(c: Vec3) -> f32 {
    c.dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

/// One light of any kind.
#[derive(Debug, Clone, Copy)]
pub enum Light<'a> {
    Directional(&'a DirectionalLight),
    Point(&'a PointLight),
    Spot(&'a SpotLight),
}

/// Every light in the order directional, point, spot (the order of listings 5 and 8a).
pub fn lights(l: &Lights) -> impl Iterator<Item = Light<'_>> {
    l.directional.iter().map(Light::Directional).chain(l.point.iter().map(Light::Point)).chain(l.spot.iter().map(Light::Spot))
}

impl Light<'_> {
    pub fn casts_shadows(&self) -> bool {
        match self {
            Light::Directional(l) => l.casts_shadows,
            Light::Point(l) => l.casts_shadows,
            Light::Spot(l) => l.casts_shadows,
        }
    }

    /// Unit direction from `p` towards the light and the distance to it (∞ for directional):
    /// a shadow ray from `p` along the direction up to that distance.
    #[inline]
    pub fn direction_from(&self, p: Vec3) -> (Vec3, f32) {
        match self {
            Light::Directional(l) => (-l.direction, f32::INFINITY),
            Light::Point(l) => to_position(p, l.position),
            Light::Spot(l) => to_position(p, l.position),
        }
    }

    /// Radiance arriving at `p` from this light (colour × intensity × attenuation × cone),
    /// with the direction towards the light.
    #[inline]
    pub fn incident(&self, p: Vec3) -> (Vec3, Vec3) {
        match self {
            Light::Directional(l) => (-l.direction, l.color * l.intensity),
            Light::Point(l) => {
                let (dir, d) = to_position(p, l.position);
                (dir, l.color * l.intensity * l.attenuation.factor(d))
            }
            Light::Spot(l) => {
                let (dir, d) = to_position(p, l.position);
                let cos = (-dir).dot(l.direction);
                let cone = spot_cone(cos, l.inner_angle.cos(), l.outer_angle.cos());
                (dir, l.color * l.intensity * l.attenuation.factor(d) * cone)
            }
        }
    }

    /// Blinn–Phong contribution of this light to `s` seen along `view` (unit, from the surface
    /// towards the viewer). Unshadowed.
    #[inline]
    pub fn blinn_phong(&self, s: &Surface, view: Vec3) -> Vec3 {
        blinn_phong_from(self.incident(s.position), s, view)
    }
}

/// Blinn–Phong of one light arriving as `(direction towards the light, radiance)` at `s`.
#[inline]
fn blinn_phong_from((l, radiance): (Vec3, Vec3), s: &Surface, view: Vec3) -> Vec3 {
    if radiance == Vec3::ZERO {
        return Vec3::ZERO;
    }
    let n = facing(s.normal, view);
    let n_dot_l = n.dot(l);
    if n_dot_l <= 0.0 {
        return Vec3::ZERO;
    }
    let h = (l + view).normalize_or_zero();
    let spec = if s.specular == Vec3::ZERO { Vec3::ZERO } else { s.specular * n.dot(h).max(0.0).powf(specular_exponent(s.shininess)) };
    (s.diffuse * n_dot_l + spec) * radiance
}

fn to_position(p: Vec3, light: Vec3) -> (Vec3, f32) {
    let d = light - p;
    let len = d.length();
    if len > 0.0 { (d / len, len) } else { (Vec3::Y, 0.0) }
}

/// Spot cone falloff: 1 inside the inner cone, 0 outside the outer, smoothstep in between.
pub fn spot_cone(cos_angle: f32, cos_inner: f32, cos_outer: f32) -> f32 {
    if cos_inner <= cos_outer {
        return if cos_angle >= cos_outer { 1.0 } else { 0.0 };
    }
    let t = ((cos_angle - cos_outer) / (cos_inner - cos_outer)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// The normal flipped, if needed, to the viewer's side (so open surfaces light from both sides).
#[inline]
pub fn facing(n: Vec3, view: Vec3) -> Vec3 {
    if n.dot(view) < 0.0 { -n } else { n }
}

/// Listing 5: `emission + env_ambient · ambient + Σ lights Blinn–Phong`, unshadowed.
pub fn local_lighting(s: &Surface, view: Vec3, all: &Lights, env: &Environment) -> Vec3 {
    let mut c = s.emission + env.ambient * s.ambient;
    for light in lights(all) {
        c += light.blinn_phong(s, view);
    }
    c
}

/// The scene's lights with their per-frame constants precomputed (colour × intensity, the
/// cosines of spot cones), for shading many points: [`FrameLights::local_lighting`] gives exactly
/// (bit for bit) what [`local_lighting`] gives, faster.
#[derive(Debug, Clone)]
pub struct FrameLights {
    lights: Vec<FrameLight>,
    env_ambient: Vec3,
}

#[derive(Debug, Clone, Copy)]
enum FrameLight {
    /// Direction towards the light and radiance.
    Directional {
        to_light: Vec3,
        radiance: Vec3,
    },
    Point {
        position: Vec3,
        power: Vec3,
        attenuation: hybrid_scene::Attenuation,
    },
    Spot {
        position: Vec3,
        direction: Vec3,
        power: Vec3,
        attenuation: hybrid_scene::Attenuation,
        cos_inner: f32,
        cos_outer: f32,
    },
}

impl FrameLight {
    /// As [`Light::incident`], bit for bit.
    #[inline]
    fn incident(&self, p: Vec3) -> (Vec3, Vec3) {
        let (dir, _, radiance) = self.incident_and_distance(p);
        (dir, radiance)
    }

    /// [`Self::incident`] with the distance to the light ([`Light::direction_from`]'s: ∞ for a
    /// directional light), all from one `to_position`.
    #[inline]
    fn incident_and_distance(&self, p: Vec3) -> (Vec3, f32, Vec3) {
        match *self {
            FrameLight::Directional { to_light, radiance } => (to_light, f32::INFINITY, radiance),
            FrameLight::Point { position, power, attenuation } => {
                let (dir, d) = to_position(p, position);
                (dir, d, power * attenuation.factor(d))
            }
            FrameLight::Spot { position, direction, power, attenuation, cos_inner, cos_outer } => {
                let (dir, d) = to_position(p, position);
                let cone = spot_cone((-dir).dot(direction), cos_inner, cos_outer);
                (dir, d, power * attenuation.factor(d) * cone)
            }
        }
    }
}

impl FrameLights {
    /// Number of lights.
    pub fn len(&self) -> usize {
        self.lights.len()
    }

    /// Whether there are no lights.
    pub fn is_empty(&self) -> bool {
        self.lights.is_empty()
    }

    /// Light `k` (in [`lights`] order) at `p`: `(direction, distance, radiance)`, where
    /// direction and radiance are [`Light::incident`]'s and direction and distance
    /// [`Light::direction_from`]'s, bit for bit (a shadow ray and its light's term from one
    /// evaluation).
    #[inline]
    pub fn incident_and_distance(&self, k: usize, p: Vec3) -> (Vec3, f32, Vec3) {
        self.lights[k].incident_and_distance(p)
    }

    /// [`Self::incident_and_distance`]'s direction and radiance of light `k` at four points
    /// (lanes), each lane bit for bit the one-point value.
    #[inline]
    pub fn incident4(&self, k: usize, p: V3) -> (V3, V3) {
        self.lights[k].incident4(p)
    }

    /// [`Light::blinn_phong`], bit for bit, for light arriving as `(direction, radiance)` already
    /// evaluated (by [`Self::incident_and_distance`]) at `s.position`.
    #[inline]
    pub fn blinn_phong_incident(&self, (l, radiance): (Vec3, Vec3), s: &Surface, view: Vec3) -> Vec3 {
        blinn_phong_from((l, radiance), s, view)
    }

    pub fn new(all: &Lights, env: &Environment) -> Self {
        let lights = lights(all)
            .map(|l| match l {
                Light::Directional(l) => FrameLight::Directional { to_light: -l.direction, radiance: l.color * l.intensity },
                Light::Point(l) => FrameLight::Point { position: l.position, power: l.color * l.intensity, attenuation: l.attenuation },
                Light::Spot(l) => FrameLight::Spot {
                    position: l.position,
                    direction: l.direction,
                    power: l.color * l.intensity,
                    attenuation: l.attenuation,
                    cos_inner: l.inner_angle.cos(),
                    cos_outer: l.outer_angle.cos(),
                },
            })
            .collect();
        Self { lights, env_ambient: env.ambient }
    }

    /// Listing 5 for one surface, as [`local_lighting`] (same result, bit for bit).
    #[inline]
    pub fn local_lighting(&self, s: &Surface, view: Vec3) -> Vec3 {
        let mut c = s.emission + self.env_ambient * s.ambient;
        if self.lights.is_empty() {
            return c;
        }
        let n = facing(s.normal, view);
        let exponent = specular_exponent(s.shininess);
        let has_specular = s.specular != Vec3::ZERO;
        for light in &self.lights {
            let (l, radiance) = light.incident(s.position);
            // Lights that contribute nothing still add +0 (as `local_lighting` does: −0 + 0 = +0).
            if radiance == Vec3::ZERO {
                c += Vec3::ZERO;
                continue;
            }
            let n_dot_l = n.dot(l);
            if n_dot_l <= 0.0 {
                c += Vec3::ZERO;
                continue;
            }
            let spec = if has_specular {
                let h = (l + view).normalize_or_zero();
                s.specular * n.dot(h).max(0.0).powf(exponent)
            } else {
                Vec3::ZERO
            };
            c += (s.diffuse * n_dot_l + spec) * radiance;
        }
        c
    }

    /// [`Self::local_lighting`] of four surfaces at once (SIMD lanes = surfaces), bit for bit:
    /// each lane does that function's operations in the same order (the same sums, the same
    /// square roots and divisions, `+0` added for a light that contributes nothing), and the
    /// specular power is the same `powf` call per lane. Deferred lighting shades the G-buffer's
    /// pixels four at a time with it.
    pub fn local_lighting4(&self, s: &[Surface; 4], view: [Vec3; 4]) -> [Vec3; 4] {
        let lanes = |f: &dyn Fn(&Surface) -> Vec3| -> V3 { soa(s.map(|s| f(&s))) };
        let (emission, ambient) = (lanes(&|s| s.emission), lanes(&|s| s.ambient));
        let env = splat3(self.env_ambient);
        let mut c: V3 = [0, 1, 2].map(|k| emission[k] + env[k] * ambient[k]);
        if self.lights.is_empty() {
            return aos(c);
        }
        let (position, normal, diffuse, specular) =
            (lanes(&|s| s.position), lanes(&|s| s.normal), lanes(&|s| s.diffuse), lanes(&|s| s.specular));
        let view = soa(view);
        // `facing`: the normal flipped where n · view < 0.
        let flip = dot3(normal, view).cmplt(Vec4::ZERO);
        let n = normal.map(|v| Vec4::select(flip, -v, v));
        let exponent = s.map(|s| specular_exponent(s.shininess));
        let has_specular = s.map(|s| s.specular != Vec3::ZERO);
        let any_specular = has_specular.contains(&true);
        for light in &self.lights {
            let (l, radiance) = light.incident4(position);
            let n_dot_l = dot3(n, l);
            // Lit unless the radiance is zero or n · l ≤ 0 (NaN is lit, as in the scalar test).
            let dark =
                (radiance[0].cmpeq(Vec4::ZERO) & radiance[1].cmpeq(Vec4::ZERO) & radiance[2].cmpeq(Vec4::ZERO)) | n_dot_l.cmple(Vec4::ZERO);
            let mut spec = [Vec4::ZERO; 3];
            if any_specular {
                let lit = (!dark).bitmask();
                // h = (l + view).normalize_or_zero(), then n · h.
                let h = normalize_or_zero3([0, 1, 2].map(|k| l[k] + view[k]));
                let n_dot_h = dot3(n, h).to_array();
                let mut power = [0.0f32; 4];
                for lane in 0..4 {
                    if has_specular[lane] && lit >> lane & 1 != 0 {
                        power[lane] = n_dot_h[lane].max(0.0).powf(exponent[lane]);
                    }
                }
                let power = Vec4::from_array(power);
                // Lanes without specular colour add +0, as the scalar path's `Vec3::ZERO` does
                // (not `specular · 0`, which is −0 for a −0 component).
                let with = glam::BVec4A::new(has_specular[0], has_specular[1], has_specular[2], has_specular[3]);
                spec = specular.map(|v| Vec4::select(with, v * power, Vec4::ZERO));
            }
            for k in 0..3 {
                let term = (diffuse[k] * n_dot_l + spec[k]) * radiance[k];
                c[k] += Vec4::select(dark, Vec4::ZERO, term);
            }
        }
        aos(c)
    }
}

impl FrameLight {
    /// [`FrameLight::incident`] at four points, lane by lane.
    #[inline]
    fn incident4(&self, p: V3) -> (V3, V3) {
        match *self {
            FrameLight::Directional { to_light, radiance } => (splat3(to_light), splat3(radiance)),
            FrameLight::Point { position, power, attenuation } => {
                let (dir, d) = to_position4(p, position);
                let f = attenuation_factor4(attenuation, d);
                (dir, splat3(power).map(|v| v * f))
            }
            FrameLight::Spot { position, direction, power, attenuation, cos_inner, cos_outer } => {
                let (dir, d) = to_position4(p, position);
                let neg = dir.map(|v| -v);
                let cos = dot3(neg, splat3(direction)).to_array();
                let cone = Vec4::from_array(cos.map(|c| spot_cone(c, cos_inner, cos_outer)));
                let f = attenuation_factor4(attenuation, d);
                (dir, splat3(power).map(|v| v * f * cone))
            }
        }
    }
}

/// `to_position` lane by lane: the unit direction `(light − p) / |light − p|` and the distance,
/// or (+Y, 0) where the distance is not > 0.
#[inline]
fn to_position4(p: V3, light: Vec3) -> (V3, Vec4) {
    let d = [0, 1, 2].map(|k| Vec4::splat(light[k]) - p[k]);
    let len = dot3(d, d).sqrt();
    let ok = len.cmpgt(Vec4::ZERO);
    let y = [Vec4::ZERO, Vec4::ONE, Vec4::ZERO];
    ([0, 1, 2].map(|k| Vec4::select(ok, d[k] / len, y[k])), Vec4::select(ok, len, Vec4::ZERO))
}

/// `Attenuation::factor` lane by lane: `1 / max(c + l·d + q·d·d, 1e-12)` (a NaN sum gives
/// 1e-12, as `f32::max` does).
#[inline]
fn attenuation_factor4(a: hybrid_scene::Attenuation, d: Vec4) -> Vec4 {
    let sum = Vec4::splat(a.constant) + Vec4::splat(a.linear) * d + Vec4::splat(a.quadratic) * d * d;
    Vec4::ONE / sum.max(Vec4::splat(1e-12))
}

/// Mirror reflection of incident direction `i` about normal `n` (GLSL `reflect`).
#[inline]
pub fn reflect(i: Vec3, n: Vec3) -> Vec3 {
    i - 2.0 * n.dot(i) * n
}

/// Refraction of unit incident direction `i` at a surface with normal `n` (either side),
/// between the environment (`env_ior`) and the material (`mat_ior`): entering when `i` goes
/// against `n`, leaving otherwise. `None` on total internal reflection.
#[inline]
pub fn refract(i: Vec3, n: Vec3, env_ior: f32, mat_ior: f32) -> Option<Vec3> {
    let (n, eta) = if i.dot(n) < 0.0 { (n, env_ior / mat_ior) } else { (-n, mat_ior / env_ior) };
    let cos_i = -n.dot(i);
    let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
    if k < 0.0 { None } else { Some((eta * i + (eta * cos_i - k.sqrt()) * n).normalize()) }
}

/// Refraction direction with the paper's fallback: the reflected direction on total internal
/// reflection (listing 8a/8c). Returns the direction and whether TIR happened.
#[inline]
pub fn refract_or_reflect(i: Vec3, n: Vec3, env_ior: f32, mat_ior: f32) -> (Vec3, bool) {
    match refract(i, n, env_ior, mat_ior) {
        Some(t) => (t, false),
        None => (reflect(i, n), true),
    }
}

/// Linear skybox radiance seen along unit direction `dir` (listing 8d).
pub fn sky(env: &Environment, textures: &[Texture], dir: Vec3) -> Vec3 {
    match &env.skybox {
        Skybox::Color(c) => *c,
        Skybox::Gradient { zenith, horizon, ground } => {
            let y = dir.normalize_or_zero().y.clamp(-1.0, 1.0);
            if y >= 0.0 { horizon.lerp(*zenith, y) } else { horizon.lerp(*ground, -y) }
        }
        Skybox::Cube { faces } => {
            let (face, uv) = cube_face_uv(dir);
            textures[faces[face]].sample(uv, 0.0).truncate()
        }
    }
}

/// Cube-map face (+X, −X, +Y, −Y, +Z, −Z) and its UV ((0,0) top-left) for a direction, in the
/// OpenGL cube-map convention.
pub fn cube_face_uv(d: Vec3) -> (usize, Vec2) {
    let a = d.abs();
    let (face, sc, tc, ma) = if a.x >= a.y && a.x >= a.z {
        if d.x > 0.0 { (0, -d.z, -d.y, a.x) } else { (1, d.z, -d.y, a.x) }
    } else if a.y >= a.z {
        if d.y > 0.0 { (2, d.x, d.z, a.y) } else { (3, d.x, -d.z, a.y) }
    } else if d.z > 0.0 {
        (4, d.x, -d.y, a.z)
    } else {
        (5, -d.x, -d.y, a.z)
    };
    let ma = if ma > 0.0 { ma } else { 1.0 };
    (face, Vec2::new(0.5 * (sc / ma + 1.0), 0.5 * (tc / ma + 1.0)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use hybrid_scene::Attenuation;

    fn surface() -> Surface {
        Surface { position: Vec3::ZERO, normal: Vec3::Y, diffuse: Vec3::splat(0.5), opacity: 1.0, ior: 1.0, ..Default::default() }
    }

    #[test]
    fn point_light_diffuse_hand_value() {
        // Light 2 m straight above, intensity 4, attenuation 1/d² → radiance 1.
        // Lambert: 0.5 · cos 0 · 1 = 0.5.
        let l = PointLight {
            position: Vec3::new(0.0, 2.0, 0.0),
            color: Vec3::ONE,
            intensity: 4.0,
            attenuation: Attenuation { constant: 0.0, linear: 0.0, quadratic: 1.0 },
            casts_shadows: true,
        };
        let c = Light::Point(&l).blinn_phong(&surface(), Vec3::Y);
        assert!((c - Vec3::splat(0.5)).abs().max_element() < 1e-6, "{c}");
        // At 60° incidence from 2 m away: 0.5 · 0.5 · 1 = 0.25.
        let l2 = PointLight { position: Vec3::new(3f32.sqrt(), 1.0, 0.0), ..l };
        let c = Light::Point(&l2).blinn_phong(&surface(), Vec3::Y);
        assert!((c.x - 0.25).abs() < 1e-6, "{c}");
    }

    #[test]
    fn specular_hand_value() {
        // Light and viewer both along the normal: H = N, n·h = 1 → spec = specular colour.
        let l = DirectionalLight { direction: -Vec3::Y, color: Vec3::ONE, intensity: 1.0, casts_shadows: true };
        let s = Surface { diffuse: Vec3::ZERO, specular: Vec3::splat(0.3), shininess: 1.0, ..surface() };
        let c = Light::Directional(&l).blinn_phong(&s, Vec3::Y);
        assert!((c.x - 0.3).abs() < 1e-6);
        // Viewer at 90° from the light in the plane: h at 45°, cos 45° ^ 255 ≈ 0.
        let v = Vec3::X;
        let c = Light::Directional(&l).blinn_phong(&s, v);
        assert!(c.x < 1e-6);
        // Exponent 1 (shininess 0): (cos 45°)^1 · 0.3.
        let s1 = Surface { shininess: 0.0, ..s };
        let c = Light::Directional(&l).blinn_phong(&s1, (Vec3::X + Vec3::Y).normalize());
        let h = (Vec3::Y + (Vec3::X + Vec3::Y).normalize()).normalize();
        assert!((c.x - 0.3 * h.y).abs() < 1e-6);
    }

    /// Uniform numbers in [−1, 1) from a xorshift generator (fixed seeds: every run tests the
    /// same points).
    fn uniform(mut seed: u64) -> impl FnMut() -> f32 {
        move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
        }
    }

    /// One light of each kind and a black directional one (attenuated point and spot lights).
    fn every_kind_of_light() -> Lights {
        let att = Attenuation { constant: 1.0, linear: 0.1, quadratic: 0.05 };
        Lights {
            directional: vec![
                DirectionalLight {
                    direction: Vec3::new(-0.3, -1.0, -0.5).normalize(),
                    color: Vec3::ONE,
                    intensity: 1.2,
                    casts_shadows: true,
                },
                DirectionalLight { direction: Vec3::Y, color: Vec3::ZERO, intensity: 1.0, casts_shadows: false },
            ],
            point: vec![PointLight {
                position: Vec3::new(0.5, 3.0, 1.0),
                color: Vec3::new(1.0, 0.8, 0.6),
                intensity: 7.0,
                attenuation: att,
                casts_shadows: true,
            }],
            spot: vec![SpotLight {
                position: Vec3::new(-1.0, 2.0, 0.0),
                direction: Vec3::new(0.3, -1.0, 0.0).normalize(),
                color: Vec3::ONE,
                intensity: 5.0,
                attenuation: att,
                inner_angle: 0.3,
                outer_angle: 0.6,
                casts_shadows: true,
            }],
        }
    }

    #[test]
    fn frame_lights_match_local_lighting_bit_for_bit() {
        let all = every_kind_of_light();
        let env = Environment { ambient: Vec3::splat(0.1), ..Default::default() };
        let fast = FrameLights::new(&all, &env);
        let mut r = uniform(0x2545_f491_4f6c_dd1d);
        let bits = |v: Vec3| v.to_array().map(f32::to_bits);
        for k in 0..5000 {
            let s = Surface {
                position: Vec3::new(r(), r(), r()) * 2.0,
                normal: Vec3::new(r(), r(), r()).normalize_or(Vec3::Y),
                emission: Vec3::new(r(), 0.0, -0.0).abs() * 0.1,
                ambient: Vec3::splat(r().abs()),
                diffuse: Vec3::new(r(), r(), r()).abs(),
                opacity: 1.0,
                specular: if k % 3 == 0 { Vec3::ZERO } else { Vec3::splat(r().abs()) },
                shininess: r().abs(),
                reflectivity: 0.0,
                ior: 1.0,
            };
            let view = Vec3::new(r(), r(), r()).normalize_or(Vec3::Z);
            assert_eq!(bits(fast.local_lighting(&s, view)), bits(local_lighting(&s, view, &all, &env)), "{s:?} {view}");
            for (i, light) in lights(&all).enumerate() {
                let (l1, r1) = light.incident(s.position);
                let ((l2, d2, r2), (l3, d3)) = (fast.incident_and_distance(i, s.position), light.direction_from(s.position));
                assert_eq!((bits(l2), bits(r2)), (bits(l1), bits(r1)), "light {i}: {s:?}");
                assert_eq!((bits(l2), d2.to_bits()), (bits(l3), d3.to_bits()), "light {i}: {s:?}");
                let blinn_phong = fast.blinn_phong_incident((l2, r2), &s, view);
                assert_eq!(bits(blinn_phong), bits(light.blinn_phong(&s, view)), "light {i}: {s:?} {view}");
            }
        }
        // No lights: emission + ambient only.
        let none = FrameLights::new(&Lights::default(), &env);
        let s = surface();
        assert_eq!(bits(none.local_lighting(&s, Vec3::Y)), bits(local_lighting(&s, Vec3::Y, &Lights::default(), &env)));
    }

    #[test]
    fn four_lane_lighting_matches_local_lighting_bit_for_bit() {
        let mut all = every_kind_of_light();
        // A light at a shaded point below (distance 0: the +Y fallback), a black one.
        let point = |position: Vec3, color: Vec3| PointLight { position, color, ..all.point[0] };
        all.point.extend([point(Vec3::ZERO, Vec3::ONE), point(Vec3::X, Vec3::ZERO)]);
        let env = Environment { ambient: Vec3::new(0.1, -0.0, 0.2), ..Default::default() };
        let mut r = uniform(0x9e37_79b9_7f4a_7c15);
        let bits = |v: Vec3| v.to_array().map(f32::to_bits);
        for (name, lights) in [("all kinds", all.clone()), ("none", Lights::default())] {
            let fast = FrameLights::new(&lights, &env);
            for k in 0..4000 {
                let s: [Surface; 4] = std::array::from_fn(|lane| Surface {
                    position: if (k + lane) % 11 == 0 { Vec3::ZERO } else { Vec3::new(r(), r(), r()) * 2.0 },
                    normal: match (k + lane) % 13 {
                        0 => Vec3::ZERO,
                        1 => -Vec3::Y,
                        _ => Vec3::new(r(), r(), r()).normalize_or(Vec3::Y),
                    },
                    // y: −0 + (−0 · 0) stays −0 until a light adds +0 to it.
                    emission: Vec3::new(r().abs() * 0.1, -0.0, 0.0),
                    ambient: Vec3::new(r().abs(), 0.0, 0.0),
                    diffuse: if (k + lane) % 7 == 0 { Vec3::new(-0.0, -0.0, 0.3) } else { Vec3::new(r(), r(), r()).abs() },
                    opacity: 1.0,
                    specular: match (k + lane) % 3 {
                        0 => Vec3::ZERO,
                        1 => Vec3::splat(-0.0),
                        _ => Vec3::splat(r().abs()),
                    },
                    shininess: r().abs() * 1.2 - 0.1,
                    reflectivity: 0.0,
                    ior: 1.0,
                });
                // Unit views, and the degenerate −n and zero.
                let view: [Vec3; 4] = std::array::from_fn(|lane| match (k + lane) % 17 {
                    0 => Vec3::ZERO,
                    1 => -s[lane].normal,
                    _ => Vec3::new(r(), r(), r()).normalize_or(Vec3::Z),
                });
                let got = fast.local_lighting4(&s, view);
                for lane in 0..4 {
                    let want = fast.local_lighting(&s[lane], view[lane]);
                    assert_eq!(bits(got[lane]), bits(want), "{name}, lane {lane}: {:?} {}", s[lane], view[lane]);
                }
            }
        }
    }

    #[test]
    fn spot_cone_inside_outside_between() {
        let ci = 20f32.to_radians().cos();
        let co = 30f32.to_radians().cos();
        assert_eq!(spot_cone(10f32.to_radians().cos(), ci, co), 1.0);
        assert_eq!(spot_cone(40f32.to_radians().cos(), ci, co), 0.0);
        let mid = spot_cone(25f32.to_radians().cos(), ci, co);
        assert!(mid > 0.0 && mid < 1.0);
    }

    #[test]
    fn refraction_snell_and_tir() {
        // 45° into glass (1 → 1.5): sin t = sin 45° / 1.5.
        let i = Vec3::new(1.0, -1.0, 0.0).normalize();
        let t = refract(i, Vec3::Y, 1.0, 1.5).unwrap();
        assert!((t.x - (45f32.to_radians().sin() / 1.5)).abs() < 1e-6);
        assert!(t.y < 0.0);
        // Leaving glass at 45° (1.5 → 1): sin t = 1.06 > 1 → TIR.
        let inside = Vec3::new(1.0, 1.0, 0.0).normalize();
        assert!(refract(inside, Vec3::Y, 1.0, 1.5).is_none());
        let (d, tir) = refract_or_reflect(inside, Vec3::Y, 1.0, 1.5);
        assert!(tir && (d - Vec3::new(1.0, -1.0, 0.0).normalize()).length() < 1e-6);
        // IOR 1 changes nothing.
        assert!((refract(i, Vec3::Y, 1.0, 1.0).unwrap() - i).length() < 1e-6);
    }

    #[test]
    fn cube_faces_point_the_right_way() {
        assert_eq!(cube_face_uv(Vec3::X).0, 0);
        assert_eq!(cube_face_uv(-Vec3::X).0, 1);
        assert_eq!(cube_face_uv(Vec3::Y).0, 2);
        assert_eq!(cube_face_uv(-Vec3::Y).0, 3);
        assert_eq!(cube_face_uv(Vec3::Z).0, 4);
        assert_eq!(cube_face_uv(-Vec3::Z).0, 5);
        assert!((cube_face_uv(Vec3::X).1 - Vec2::splat(0.5)).length() < 1e-6);
    }
}
