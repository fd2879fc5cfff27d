//! Stage 1b, deferred lighting (paper listing 5): the G-buffer into the P-buffer. Covered pixels
//! get `emission + env_ambient · ambient + Σ lights Blinn–Phong` (unshadowed; shadows are the
//! trace stage's), sky pixels the skybox seen along the pixel's view ray.
//! Sky pixels look along `camera_rays::ViewRays`, which also gives every pixel's view direction.

use glam::{Vec3, Vec4};
use hybrid_core::shading::{FrameLights, sky};
use hybrid_core::{GBuffer, NO_OBJECT, Surface};
use hybrid_scene::{Camera, Environment, Scene, Skybox, Texture};
use rayon::prelude::*;

use crate::camera_rays::ViewRays;
use crate::isa;

/// Rows per parallel task of [`deferred_lighting`].
const LIGHTING_ROWS: usize = 8;

/// Lights from which [`deferred_lighting`] shades four pixels at a time.
const VECTOR_LIGHTS_MIN: usize = 2;

/// Listing 5 over the whole G-buffer: the P-buffer (linear RGB, row-major). Deterministic and
/// parallel over rows. Per-light constants are computed once per frame ([`FrameLights`]), only
/// the targets lighting needs are read, and covered pixels are shaded four at a time
/// ([`FrameLights::local_lighting4`]): the same result, bit for bit, as `local_lighting` per pixel.
pub fn deferred_lighting(gbuffer: &GBuffer, scene: &Scene, camera: &Camera) -> Vec<Vec3> {
    let mut out = Vec::new();
    deferred_lighting_into(gbuffer, scene, camera, &mut out);
    out
}

/// [`deferred_lighting`] into `out` (resized to the G-buffer; every pixel written), so a frame
/// loop can reuse last frame's memory instead of allocating and page-faulting a new buffer.
pub fn deferred_lighting_into(gbuffer: &GBuffer, scene: &Scene, camera: &Camera, out: &mut Vec<Vec3>) {
    let (w, h) = (gbuffer.width as usize, gbuffer.height as usize);
    let n = gbuffer.len();
    if out.len() != n || w == 0 || h == 0 || n != w * h {
        out.clear();
        out.resize(n, Vec3::ZERO);
    }
    if w == 0 || h == 0 || n != w * h {
        return;
    }
    let rays = ViewRays::new(camera, gbuffer.width, gbuffer.height);
    let env = &scene.environment;
    let frame_lights = FrameLights::new(&scene.lights, env);
    let g = gbuffer;
    out.par_chunks_mut(w * LIGHTING_ROWS).enumerate().for_each(|(band, rows)| {
        isa::dispatch(
            #[inline(always)]
            || {
                let base = band * w * LIGHTING_ROWS;
                let range = base..base + rows.len();
                let (ids, pos, nrm, emi, amb, dif, spe) = (
                    &g.object_id[range.clone()],
                    &g.position[range.clone()],
                    &g.normal[range.clone()],
                    &g.emission[range.clone()],
                    &g.ambient[range.clone()],
                    &g.diffuse[range.clone()],
                    &g.specular[range],
                );
                let mut sky_pixels = Vec::new();
                let mut lit_pixels = Vec::with_capacity(rows.len());
                for (k, &id) in ids.iter().enumerate() {
                    if id == NO_OBJECT {
                        // The skybox behind the pixel, four pixels at a time below.
                        sky_pixels.push(k as u32);
                    } else {
                        lit_pixels.push(k);
                    }
                }
                // The fields lighting reads, exactly as `GBuffer::surface` gives them.
                let surface = |k: usize| {
                    let (d, s) = (dif[k], spe[k]);
                    Surface {
                        position: pos[k],
                        normal: nrm[k],
                        emission: emi[k],
                        ambient: amb[k],
                        diffuse: d.truncate(),
                        opacity: d.w,
                        specular: s.truncate(),
                        shininess: s.w,
                        reflectivity: 0.0,
                        ior: 1.0,
                    }
                };
                // Covered pixels four at a time (`FrameLights::local_lighting4`: each lane exactly the
                // one-pixel path), the rest one by one. With a single light, gathering the lanes costs
                // more than it saves (tree-merge at 1080p: lighting 16.5 → 17.9 ms), so all one by one.
                let vector = if frame_lights.len() >= VECTOR_LIGHTS_MIN { lit_pixels.len() / 4 * 4 } else { 0 };
                for g in lit_pixels[..vector].chunks_exact(4) {
                    let s = [surface(g[0]), surface(g[1]), surface(g[2]), surface(g[3])];
                    // Indexed, not `s.map`: mapping an array of large `Surface`s became an out-of-line
                    // call that copied them through memory (a store-forwarding stall per group).
                    let view = [0, 1, 2, 3].map(|l| rays.view_dir(s[l].position));
                    let c = frame_lights.local_lighting4(&s, view);
                    for (&k, c) in g.iter().zip(c) {
                        rows[k] = c;
                    }
                }
                for &k in &lit_pixels[vector..] {
                    let s = surface(k);
                    rows[k] = frame_lights.local_lighting(&s, rays.view_dir(s.position));
                }
                sky_run(&rays, env, &scene.textures, w, band * LIGHTING_ROWS, &sky_pixels, rows);
            },
        )
    });
}

/// `out[k] = sky(env, textures, rays.ray(x, y).1)` for every band pixel `k` in `pixels` (band
/// pixel `k` is image pixel (`k % width`, `first_row + k / width`)), bit for bit. A gradient
/// skybox seen through perspective rays, the common case, is evaluated four pixels at a time:
/// each lane does exactly the scalar path's operations (the ray direction from the pixel centre,
/// normalised, normalised again by `sky`, the elevation clamped, the gradient interpolated), so
/// the division and square roots of four pixels cost those of one.
fn sky_run(rays: &ViewRays, env: &Environment, textures: &[Texture], width: usize, first_row: usize, pixels: &[u32], out: &mut [Vec3]) {
    let pixel = |k: u32| ((k as usize % width) as u32, (first_row + k as usize / width) as u32);
    let gradient = match (&env.skybox, rays.orthographic) {
        (Skybox::Gradient { zenith, horizon, ground }, false) => Some((zenith, horizon, ground)),
        _ => None,
    };
    // Whole groups of four go the vector way (when it applies), the rest one by one.
    let vector = if gradient.is_some() { pixels.len() / 4 * 4 } else { 0 };
    for &k in &pixels[vector..] {
        let (x, y) = pixel(k);
        out[k as usize] = sky(env, textures, rays.ray(x, y).1);
    }
    let Some((zenith, horizon, ground)) = gradient else { return };
    let groups = pixels[..vector].chunks_exact(4);
    let splat = |v: Vec3| [Vec4::splat(v.x), Vec4::splat(v.y), Vec4::splat(v.z)];
    let (f, r, u) = (splat(rays.forward), splat(rays.right), splat(rays.up));
    let (zenith, horizon, ground) = (splat(*zenith), splat(*horizon), splat(*ground));
    for group in groups {
        // `ViewRays::ray_at` at the four pixel centres.
        let (mut a, mut b) = ([0.0; 4], [0.0; 4]);
        for (lane, &k) in group.iter().enumerate() {
            let (x, y) = pixel(k);
            let (sx, sy) = (x as f32 + 0.5, y as f32 + 0.5);
            a[lane] = (sx / rays.width * 2.0 - 1.0) * rays.half_w;
            b[lane] = (1.0 - sy / rays.height * 2.0) * rays.half_h;
        }
        let (a, b) = (Vec4::from_array(a), Vec4::from_array(b));
        let v = [0, 1, 2].map(|c| f[c] + (r[c] * a + u[c] * b));
        let normalize_or = |v: [Vec4; 3], fallback: [Vec4; 3]| {
            let rcp = Vec4::ONE / (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            let ok = rcp.is_finite_mask() & rcp.cmpgt(Vec4::ZERO);
            [0, 1, 2].map(|c| Vec4::select(ok, v[c] * rcp, fallback[c]))
        };
        let dir = normalize_or(v, f);
        // `sky`: normalised again, elevation clamped like `f32::clamp` (NaN stays NaN).
        let y = normalize_or(dir, [Vec4::ZERO; 3])[1];
        let y = Vec4::select(y.cmplt(Vec4::NEG_ONE), Vec4::NEG_ONE, y);
        let y = Vec4::select(y.cmpgt(Vec4::ONE), Vec4::ONE, y);
        let up = y.cmpge(Vec4::ZERO);
        let s = Vec4::select(up, y, -y);
        let c = [0, 1, 2].map(|c| horizon[c] * (Vec4::ONE - s) + Vec4::select(up, zenith[c], ground[c]) * s);
        let c = c.map(|v| v.to_array());
        for (lane, &k) in group.iter().enumerate() {
            out[k as usize] = Vec3::new(c[0][lane], c[1][lane], c[2][lane]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hybrid_scene::Projection;

    /// The four-wide sky path gives every sky pixel exactly `sky` of its view ray, for
    /// perspective and orthographic cameras, gradient and one-colour skyboxes, and sizes whose
    /// rows do not split into groups of four.
    #[test]
    fn sky_pixels_equal_the_scalar_sky() {
        use hybrid_scene::Skybox;
        let gradient =
            Skybox::Gradient { zenith: Vec3::new(0.1, 0.3, 0.9), horizon: Vec3::new(0.8, 0.85, 0.9), ground: Vec3::new(0.3, 0.2, 0.1) };
        for (projection, skybox, (w, h)) in [
            (Projection::Perspective { fov_y_deg: 70.0, near: 0.1, far: 100.0 }, gradient.clone(), (67, 41)),
            (Projection::Perspective { fov_y_deg: 150.0, near: 0.1, far: 100.0 }, gradient.clone(), (33, 64)),
            (Projection::Orthographic { height: 6.0, near: 0.1, far: 100.0 }, gradient, (17, 9)),
            (Projection::Perspective { fov_y_deg: 50.0, near: 0.1, far: 100.0 }, Skybox::Color(Vec3::new(0.2, 0.4, 0.6)), (9, 7)),
        ] {
            for target in [Vec3::new(-1.0, 0.5, -2.0), Vec3::new(1.0, 2.0, 3.2), Vec3::new(1.0, -5.0, 3.0)] {
                let camera = Camera { position: Vec3::new(1.0, 2.0, 3.0), target, up: Vec3::Y, projection };
                let mut scene = Scene::new(camera);
                scene.environment.skybox = skybox.clone();
                let lit = deferred_lighting(&GBuffer::new(w, h), &scene, &camera);
                let rays = ViewRays::new(&camera, w, h);
                for (i, c) in lit.iter().enumerate() {
                    let (x, y) = ((i % w as usize) as u32, (i / w as usize) as u32);
                    let want = sky(&scene.environment, &scene.textures, rays.ray(x, y).1);
                    assert_eq!(c.to_array().map(f32::to_bits), want.to_array().map(f32::to_bits), "pixel ({x}, {y}) of {w}×{h}");
                }
            }
        }
    }
}
