//! `trace`: the ray-tracing stage of paper 1 (§3.3, listings 8a–d; design §3), and the primary
//! rays of the `rt-only` mode.
//!
//! Per masked pixel (listing 8a) it writes the shadow buffer (1 minus the Blinn–Phong light that
//! shadow-casting occluders block), the reflection buffer and the refraction buffer. Secondary
//! rays shade their closest hit with listing 8c and see the skybox on a miss (listing 8d).
//!
//! Reading of listing 8c used here (the paper leaves the payload's initial values open):
//! - A ray leaving the G-buffer surface has depth 1 and importance = that surface's
//!   reflectivity (reflection ray) or transparency = 1 − opacity (refraction ray). Listing 8a
//!   traces it whenever reflectivity > 0 (resp. opacity < 1), without a cutoff test.
//! - At a hit with reflectivity `r` and transparency `τ`: "reflection-luminance" is the
//!   luminance of the grey reflectivity colour, i.e. `r` (the luminance weights sum to 1), so
//!   the child importance is `imp·r` (resp. `imp·τ`); the child is traced when that exceeds
//!   `scene.trace.importance_cutoff` and the depth is below `scene.trace.max_depth` (capped at
//!   [`MAX_TRACED_DEPTH`], the GPU's limit too), and gets depth + 1. Untraced children contribute 0.
//! - Beyond the paper (issue 22): a ray tree (the ray leaving the G-buffer and everything below
//!   it) traces at most [`TRACE_RAY_BUDGET`] rays. A node admits its reflection child, then its
//!   refraction child, while the tree's count is below the budget; the refraction subtree is
//!   traced before the reflection subtree, which is the order the GPU's stack pops them, so both
//!   backends cut the same children. A child over the budget contributes 0, as one below the
//!   cutoff.
//! - Local lighting (listing 5, unshadowed) is computed unless `r ≥ 1` or `τ ≥ 1`; at
//!   depth ≥ max depth both children are replaced by it; the result is
//!   `combine(lighting, refl, refr, r, τ)` (the eq. 5/6 average, = color1/color2 of 8c).
//!
//! Beyond the paper: a shadow ray whose light contributes nothing to the pixel (back-facing,
//! outside a spot cone, zero radiance, a surface without diffuse and specular colour) is not
//! traced, as it cannot change the result; the Blinn–Phong term is evaluated only for rays that
//! find a blocker (attenuation < 1).
//!
//! Ray origins are offset by `scene.trace.ray_bias` along the normal, on the side the new ray
//! leaves from (so refraction rays entering glass start inside it). Pixels are independent, so
//! the output is bit-identical for any thread count.
//!
//! Work items of up to [`STREAM`] pixels (sized by the frame) trace their rays in ray streams
//! (`SceneBvh`'s `closest_hits_stream` and `any_hit_attenuation_stream`): first each light's
//! shadow rays and the first reflection and refraction rays, then each pixel is finished in
//! order with those answers (the rays below the first ones one at a time).

use glam::{Vec2, Vec3};
use hybrid_core::blend::combine;
use hybrid_core::shading::{FrameLights, facing, lights, reflect, refract_or_reflect, sky};
use hybrid_core::{GBuffer, Surface};
use hybrid_scene::Camera;
use rayon::prelude::*;

use crate::bvh::{Hit, PACKET, PacketRay, STREAM, SceneBvh, ShadowCache};
use crate::camera_rays::PrimaryRays;
use crate::capsule::PointCloudCapsule;
use hybrid_core::prepare::PreparedScene;

pub use hybrid_core::report::RayCounts;

/// The trace stage's buffers (paper Fig. 5), row-major like the G-buffer.
#[derive(Debug, Clone, PartialEq)]
pub struct TraceOutput {
    /// 1 where nothing is blocked; untraced pixels hold 1.
    pub shadow: Vec<Vec3>,
    /// Untraced pixels hold 0.
    pub reflection: Vec<Vec3>,
    /// Untraced pixels hold 0.
    pub refraction: Vec<Vec3>,
    /// Shadow, reflection and refraction rays traced (primary = 0: see [`primary_ray_count`]).
    pub rays: RayCounts,
}

/// Recursion limit whatever `scene.trace.max_depth` says (the scene format's own limit, defined
/// once in `hybrid_scene`), so a huge setting between two perfect mirrors cannot overflow a
/// thread's stack.
pub use hybrid_scene::{MAX_TRACE_DEPTH, MAX_TRACED_DEPTH, TRACE_RAY_BUDGET};

/// Pixels per parallel work item of a frame of `pixels` pixels (uneven ray cost: items are
/// handed out one at a time). An item's rays form its ray streams, so the larger the item the
/// more rays share each node fetch (up to [`STREAM`]), at the cost of coarser load balancing
/// between threads: frames get at least 64 items (of at least 256 pixels). The size depends
/// on the frame alone, so the output does not depend on the thread count.
fn work_item_pixels(pixels: usize) -> usize {
    (pixels / 64).clamp(256, STREAM)
}

/// Listing 8a over every pixel of `gbuffer` whose mask is > 0.
pub fn trace(prepared: &PreparedScene, bvh: &SceneBvh, gbuffer: &GBuffer, camera: &Camera) -> TraceOutput {
    trace_with_spheres(prepared, bvh, None, gbuffer, camera)
}

/// [`trace`] with the RT-scene's spheres as geometry too (beyond paper 2): they block shadow
/// rays (opaque casters) and are seen, shaded as the capsule shades them, by reflection and
/// refraction rays.
pub fn trace_with_spheres(
    prepared: &PreparedScene,
    bvh: &SceneBvh,
    spheres: Option<&PointCloudCapsule>,
    gbuffer: &GBuffer,
    camera: &Camera,
) -> TraceOutput {
    let (mut shadow, mut reflection, mut refraction) = (Vec::new(), Vec::new(), Vec::new());
    let rays = trace_with_spheres_into(prepared, bvh, spheres, gbuffer, camera, [&mut shadow, &mut reflection, &mut refraction]);
    TraceOutput { shadow, reflection, refraction, rays }
}

/// [`trace_with_spheres`] into `[shadow, reflection, refraction]` (each resized to the G-buffer,
/// every pixel written: untraced ones get 1, 0, 0), reusing their memory; returns the rays traced.
pub fn trace_with_spheres_into(
    prepared: &PreparedScene,
    bvh: &SceneBvh,
    spheres: Option<&PointCloudCapsule>,
    gbuffer: &GBuffer,
    camera: &Camera,
    [shadow, reflection, refraction]: [&mut Vec<Vec3>; 3],
) -> RayCounts {
    let n = gbuffer.len();
    for b in [&mut *shadow, &mut *reflection, &mut *refraction] {
        b.resize(n, Vec3::ZERO);
    }
    let tracer = Tracer {
        prepared,
        bvh,
        spheres,
        camera,
        primary: PrimaryRays::new(camera, gbuffer.width, gbuffer.height),
        frame_lights: FrameLights::new(&prepared.scene.lights, &prepared.scene.environment),
    };
    let chunk = work_item_pixels(n);
    shadow
        .par_chunks_mut(chunk)
        .zip(reflection.par_chunks_mut(chunk))
        .zip(refraction.par_chunks_mut(chunk))
        .enumerate()
        .with_max_len(1)
        .map(|(c, ((s, m), r))| {
            let mut rays = RayCounts::default();
            let mut caches = vec![ShadowCache::default(); lights(&prepared.scene.lights).count()];
            // The chunk's first reflection and refraction rays go out as one ray stream, in
            // pixel order (the hits one at a time would find, found faster); the rest of each
            // pixel's work, and the rays below those two, are traced pixel by pixel.
            let surfaces: Vec<Option<(Surface, Vec3)>> = (0..s.len())
                .map(|k| (gbuffer.mask[c * chunk + k] > 0.0).then(|| tracer.surface(gbuffer, c * chunk + k)).flatten())
                .collect();
            let first_rays: Vec<(Vec3, Vec3)> = surfaces
                .iter()
                .flatten()
                .flat_map(|(surface, incident)| {
                    let [refl, refr] = tracer.first_rays(surface, *incident);
                    refl.into_iter().chain(refr)
                })
                .collect();
            let hits = bvh.closest_hits_stream(&first_rays, 0.0, f32::INFINITY);
            let mut first_hits = hits.into_iter();
            // Each light's shadow rays of the chunk together too (with the light's cache), in
            // pixel order: `ShadowRays` per light, walked along with the pixels below.
            let mut shadow_hits: Vec<ShadowRays> = lights(&prepared.scene.lights)
                .zip(caches.iter_mut())
                .enumerate()
                .map(|(light, (l, cache))| {
                    let (mut pixels, mut rays, mut radiance) = (Vec::new(), Vec::new(), Vec::new());
                    if l.casts_shadows() {
                        for (k, (surface, incident)) in surfaces.iter().enumerate().filter_map(|(k, s)| Some((k, s.as_ref()?))) {
                            if let Some((origin, dir, dist, rad)) = tracer.shadow_ray(surface, -*incident, light) {
                                pixels.push(k as u32);
                                rays.push((origin, dir, dist));
                                radiance.push(rad);
                            }
                        }
                    }
                    let attenuation = bvh.any_hit_attenuation_stream(prepared, &rays, Some(cache));
                    ShadowRays { pixels, rays, radiance, attenuation, next: 0 }
                })
                .collect();
            for (k, surface) in surfaces.iter().enumerate() {
                let i = c * chunk + k;
                (s[k], m[k], r[k]) = if gbuffer.mask[i] > 0.0 {
                    tracer.pixel(gbuffer, i, k as u32, surface.as_ref(), &mut first_hits, &mut shadow_hits, &mut rays)
                } else {
                    (Vec3::ONE, Vec3::ZERO, Vec3::ZERO)
                };
            }
            debug_assert!(first_hits.next().is_none(), "every streamed hit is used");
            debug_assert!(shadow_hits.iter().all(|l| l.next == l.pixels.len()), "every shadow ray is used");
            rays
        })
        .reduce(RayCounts::default, |mut a, b| {
            a += b;
            a
        })
}

/// One light's shadow rays of a work item, in pixel order: the pixel (its number in the work
/// item) each starts from, the ray `(origin, dir, distance)`, the light's radiance there and
/// the triangles' attenuation ([`SceneBvh::any_hit_attenuation_stream`]); `next` is the first
/// not yet used.
struct ShadowRays {
    pixels: Vec<u32>,
    rays: Vec<(Vec3, Vec3, f32)>,
    radiance: Vec<Vec3>,
    attenuation: Vec<f32>,
    next: usize,
}

#[derive(Clone, Copy)]
enum Kind {
    Reflection,
    Refraction,
}

struct Tracer<'a, 's> {
    prepared: &'a PreparedScene<'s>,
    bvh: &'a SceneBvh,
    spheres: Option<&'a PointCloudCapsule>,
    camera: &'a Camera,
    primary: PrimaryRays,
    /// The scene's lights with their per-frame constants (same shading, bit for bit).
    frame_lights: FrameLights,
}

impl Tracer<'_, '_> {
    /// The surface drawn at pixel `i` (`None` where nothing is) and the view ray's direction
    /// towards it.
    #[inline]
    fn surface(&self, g: &GBuffer, i: usize) -> Option<(Surface, Vec3)> {
        let s = g.surface(i).filter(|s| s.normal.length_squared() > 0.0)?;
        let incident = self.camera.incident_towards(s.position);
        Some((s, incident))
    }

    /// Listing 8a for pixel `i`, whose surface and view direction are `surface`
    /// ([`Tracer::surface`]): (shadow, reflection, refraction). `first_hits` yields the
    /// closest triangle hits of the pixel's first reflection and refraction rays
    /// ([`Tracer::first_rays`], in that order), traced beforehand; `shadow_hits[light]` the
    /// shadow rays of each light, likewise, where this pixel is number `k` of its work item.
    #[allow(clippy::too_many_arguments)]
    fn pixel(
        &self,
        g: &GBuffer,
        i: usize,
        k: u32,
        surface: Option<&(Surface, Vec3)>,
        first_hits: &mut impl Iterator<Item = Option<Hit>>,
        shadow_hits: &mut [ShadowRays],
        rays: &mut RayCounts,
    ) -> (Vec3, Vec3, Vec3) {
        let scene = self.prepared.scene;
        let Some(&(s, incident)) = surface else {
            // Nothing drawn (zero-length normal): the skybox behind the pixel.
            let (x, y) = ((i % g.width as usize) as u32, (i / g.width as usize) as u32);
            let (_, dir, _) = self.primary.ray(x, y);
            return (Vec3::ONE, sky(&scene.environment, &scene.textures, dir), Vec3::ZERO);
        };
        let view = -incident;
        let [refl, refr] = self.first_rays(&s, incident);
        let mut traced = |ray: Option<(Vec3, Vec3)>, importance: f32, kind: Kind, rays: &mut RayCounts| match ray {
            Some((origin, dir)) => {
                let hit = first_hits.next().expect("a streamed hit for every first ray");
                self.secondary(origin, dir, Some(hit), importance, 1, kind, &mut 1, rays)
            }
            None => Vec3::ZERO,
        };
        let shadow = self.shadow_rays(&s, view, k, shadow_hits, rays);
        let reflection = traced(refl, s.reflectivity, Kind::Reflection, rays);
        let refraction = traced(refr, 1.0 - s.opacity, Kind::Refraction, rays);
        (shadow, reflection, refraction)
    }

    /// Listing 8a's first rays from surface `s` seen along `incident`, as `(origin, dir)`: the
    /// reflection ray (the view ray reflected about the normal) if the surface reflects, and
    /// the refraction ray (refracted by the IOR ratio; reflected on total internal reflection)
    /// if it is not opaque.
    #[inline]
    fn first_rays(&self, s: &Surface, incident: Vec3) -> [Option<(Vec3, Vec3)>; 2] {
        let reflection = (s.reflectivity > 0.0).then(|| {
            let dir = reflect(incident, s.normal).normalize_or_zero();
            (self.offset(s, dir), dir)
        });
        let refraction = (s.opacity < 1.0).then(|| {
            let (dir, _tir) = refract_or_reflect(incident, s.normal, self.prepared.scene.environment.ior, s.ior);
            (self.offset(s, dir), dir)
        });
        [reflection, refraction]
    }

    /// Light `light`'s shadow ray from surface `s` seen along `view` (the light casting
    /// shadows), as `(origin, dir, distance, radiance)`; `None` where the light cannot change
    /// the pixel: the surface has no diffuse or specular colour, no radiance arrives, or the
    /// light is behind the surface (the cheap half of Blinn–Phong; the full term is evaluated
    /// only where the ray finds a blocker).
    #[inline]
    fn shadow_ray(&self, s: &Surface, view: Vec3, light: usize) -> Option<(Vec3, Vec3, f32, Vec3)> {
        if s.diffuse == Vec3::ZERO && s.specular == Vec3::ZERO {
            return None;
        }
        let (dir, dist, radiance) = self.frame_lights.incident_and_distance(light, s.position);
        if radiance == Vec3::ZERO || facing(s.normal, view).dot(dir) <= 0.0 {
            return None;
        }
        Some((self.offset(s, dir), dir, dist, radiance))
    }

    /// Listing 8a's shadows for surface `s` (pixel `k` of its work item) seen along `view`: 1
    /// minus the Blinn–Phong light of each shadow-casting light that occluders block (× 1 −
    /// their attenuation, listing 8b). The triangles' attenuations come from `shadow_hits`,
    /// traced beforehand; the RT scene's spheres are tested here.
    #[inline]
    fn shadow_rays(&self, s: &Surface, view: Vec3, k: u32, shadow_hits: &mut [ShadowRays], rays: &mut RayCounts) -> Vec3 {
        let mut shadow = Vec3::ONE;
        for l in shadow_hits.iter_mut() {
            if l.pixels.get(l.next) != Some(&k) {
                continue;
            }
            let ((origin, dir, dist), radiance, mut att) = (l.rays[l.next], l.radiance[l.next], l.attenuation[l.next]);
            l.next += 1;
            rays.shadow += 1;
            if att > 0.0 && self.spheres.is_some_and(|c| c.occluded(origin, dir, 0.0, dist)) {
                att = 0.0;
            }
            if att < 1.0 {
                shadow -= self.frame_lights.blinn_phong_incident((dir, radiance), s, view) * (1.0 - att);
            }
        }
        shadow
    }

    /// `s.position` moved by the ray bias along the normal, to the side `dir` leaves towards.
    #[inline]
    fn offset(&self, s: &Surface, dir: Vec3) -> Vec3 {
        let bias = self.prepared.scene.trace.ray_bias;
        let side = s.normal.dot(dir);
        if side > 0.0 {
            s.position + s.normal * bias
        } else if side < 0.0 {
            s.position - s.normal * bias
        } else {
            s.position
        }
    }

    /// Traces a secondary ray: closest hit shaded with listing 8c, miss = skybox (listing 8d).
    /// `triangle` is its closest triangle hit when already traced (`None`: trace it here).
    /// `admitted` counts the rays of this ray tree admitted so far (this one included), against
    /// [`TRACE_RAY_BUDGET`].
    #[allow(clippy::too_many_arguments)]
    fn secondary(
        &self,
        origin: Vec3,
        dir: Vec3,
        triangle: Option<Option<Hit>>,
        importance: f32,
        depth: u32,
        kind: Kind,
        admitted: &mut u32,
        rays: &mut RayCounts,
    ) -> Vec3 {
        match kind {
            Kind::Reflection => rays.reflection += 1,
            Kind::Refraction => rays.refraction += 1,
        }
        let scene = self.prepared.scene;
        let triangle = triangle.unwrap_or_else(|| self.bvh.closest_hit(origin, dir, 0.0, f32::INFINITY));
        let sphere = self.spheres.and_then(|c| c.closest_surface(origin, dir, 0.0, triangle.map_or(f32::INFINITY, |h| h.t)));
        let s = match (sphere, triangle) {
            (Some((_, s)), _) => s,
            (None, Some(hit)) => self.prepared.surface_at(hit.triangle, hit.bary, 0.0),
            (None, None) => return sky(&scene.environment, &scene.textures, dir),
        };
        let settings = &scene.trace;
        let max_depth = settings.max_depth.min(MAX_TRACED_DEPTH);
        let reflectivity = s.reflectivity;
        let transparency = 1.0 - s.opacity;

        // Admission: reflection child, then refraction child, while the tree is under budget.
        let mut admit = |imp: f32| {
            let ok = imp > settings.importance_cutoff && depth < max_depth && *admitted < TRACE_RAY_BUDGET;
            *admitted += u32::from(ok);
            ok
        };
        let refl_imp = importance * reflectivity;
        let refr_imp = importance * transparency;
        let (trace_refl, trace_refr) = (admit(refl_imp), admit(refr_imp));
        // The refraction subtree first (the GPU's pop order), then the reflection subtree.
        let mut refr = Vec3::ZERO;
        if trace_refr {
            let (d, _tir) = refract_or_reflect(dir, s.normal, scene.environment.ior, s.ior);
            refr = self.secondary(self.offset(&s, d), d, None, refr_imp, depth + 1, Kind::Refraction, admitted, rays);
        }
        let mut refl = Vec3::ZERO;
        if trace_refl {
            let d = reflect(dir, s.normal).normalize_or_zero();
            refl = self.secondary(self.offset(&s, d), d, None, refl_imp, depth + 1, Kind::Reflection, admitted, rays);
        }
        let lighting = if reflectivity < 1.0 && transparency < 1.0 { self.frame_lights.local_lighting(&s, -dir) } else { Vec3::ZERO };
        if depth >= max_depth {
            refl = lighting;
            refr = lighting;
        }
        combine(lighting, refl, refr, reflectivity, transparency)
    }
}

/// Primary rays of an `rt-only` frame: one per pixel.
pub fn primary_ray_count(width: u32, height: u32) -> u64 {
    width as u64 * height as u64
}

/// The `rt-only` mode's G-buffer: a primary ray per pixel centre, every target filled from the
/// closest hit with `surface_at` (as the raster would), depth = the hit projected with the
/// camera's view-projection (reversed-Z), mask = 1 on covered pixels. Count its rays with
/// [`primary_ray_count`].
pub fn rt_only_gbuffer(prepared: &PreparedScene, bvh: &SceneBvh, camera: &Camera, width: u32, height: u32) -> GBuffer {
    let mut g = GBuffer::new(width, height);
    rt_only_gbuffer_into(prepared, bvh, camera, &mut g);
    g
}

/// [`rt_only_gbuffer`] into an existing G-buffer (its size is the frame size): every pixel of
/// every target is overwritten (uncovered pixels as [`GBuffer::new`] holds them), so a buffer can
/// be reused frame after frame. Rows are traced and written in parallel bands, each in 4×4 pixel
/// tiles traced as one ray packet ([`SceneBvh::closest_hits`]: the same hits as one ray at a
/// time).
pub fn rt_only_gbuffer_into(prepared: &PreparedScene, bvh: &SceneBvh, camera: &Camera, g: &mut GBuffer) {
    let (width, height) = (g.width, g.height);
    if width == 0 || height == 0 {
        return;
    }
    let rays = PrimaryRays::new(camera, width, height);
    let vp = camera.view_projection(width as f32 / height as f32);
    let band_len = width as usize * PRIMARY_BAND_ROWS;
    let w = width as usize;
    g.bands_mut(band_len).into_par_iter().enumerate().with_max_len(1).for_each(|(band, mut rows)| {
        // The band's rows in tiles of TILE_WIDTH × PRIMARY_BAND_ROWS pixels, each traced as one
        // packet.
        let band_rows = rows.len() / w;
        let mut pixel = [0usize; PACKET];
        let mut packet: [PacketRay; PACKET] = [(Vec3::ZERO, Vec3::ZERO, 0.0); PACKET];
        for x0 in (0..w).step_by(TILE_WIDTH) {
            let mut n = 0;
            for row in 0..band_rows {
                for x in x0..(x0 + TILE_WIDTH).min(w) {
                    pixel[n] = row * w + x;
                    packet[n] = rays.ray(x as u32, (band * PRIMARY_BAND_ROWS + row) as u32);
                    n += 1;
                }
            }
            let hits = bvh.closest_hits(&packet[..n], 0.0);
            for ((&k, &(origin, dir, _)), hit) in pixel[..n].iter().zip(&packet[..n]).zip(hits) {
                let Some(hit) = hit else {
                    rows.clear(k);
                    continue;
                };
                let point = origin + dir * hit.t;
                let footprint = uv_footprint(prepared, hit.triangle, dir, rays.pixel_world_size(point));
                let s = prepared.surface_at(hit.triangle, hit.bary, footprint);
                let object = prepared.meshes[hit.triangle.mesh as usize].object;
                let depth = vp.project_point3(s.position).z.clamp(0.0, 1.0);
                rows.write(k, object, depth, &s);
                rows.set_mask(k, 1.0);
            }
        }
    });
}

/// Rows per parallel work item of [`rt_only_gbuffer_into`]: the height of its ray packets'
/// tiles ([`PACKET`] / 4 = 4 rows of 4 pixels).
const PRIMARY_BAND_ROWS: usize = 4;
/// Width of those tiles, so that a tile fills a packet.
const TILE_WIDTH: usize = PACKET / PRIMARY_BAND_ROWS;

/// UV change per pixel on a triangle seen along `dir` with pixel size `world` at the hit:
/// the pixel's footprint (stretched by the viewing angle, as the raster's larger screen
/// derivative is) times the triangle's UV-per-world-length scale.
fn uv_footprint(prepared: &PreparedScene, t: hybrid_core::prepare::TriangleRef, dir: Vec3, world: f32) -> f32 {
    let mesh = &prepared.meshes[t.mesh as usize];
    if mesh.uvs.is_empty() {
        return 0.0;
    }
    let [i0, i1, i2] = mesh.indices[t.triangle as usize].map(|i| i as usize);
    let [p0, p1, p2] = prepared.triangle(t);
    let cross = (p1 - p0).cross(p2 - p0);
    let world_area = cross.length();
    let (u0, u1, u2): (Vec2, Vec2, Vec2) = (mesh.uvs[i0], mesh.uvs[i1], mesh.uvs[i2]);
    let uv_area = (u1 - u0).perp_dot(u2 - u0).abs();
    if world_area <= 0.0 || !world_area.is_finite() {
        return 0.0;
    }
    let cos = (cross / world_area).dot(dir).abs().max(0.25);
    let f = world / cos * (uv_area / world_area).sqrt();
    if f.is_finite() { f } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn work_items_are_whole_streams_on_large_frames_and_many_on_small_ones() {
        // 1280×720 and up: one full stream per item.
        assert_eq!(work_item_pixels(1280 * 720), STREAM);
        assert_eq!(work_item_pixels(3840 * 2160), STREAM);
        // Smaller frames: at least 64 items, of at least 256 pixels.
        assert_eq!(work_item_pixels(320 * 180), 900);
        assert_eq!(work_item_pixels(160 * 90), 256);
        assert_eq!(work_item_pixels(1), 256);
        for pixels in [100, 10_000, 57_600, 200_000, 262_144, 262_207] {
            let item = work_item_pixels(pixels);
            assert!((256..=STREAM).contains(&item));
            assert!(pixels.div_ceil(item) >= 64 || item == 256, "{pixels}: {item}");
        }
    }
}
