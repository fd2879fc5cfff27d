//! Stage 3b, the raster fallbacks (issue 18; the maths in `hybrid_core::fallback`): shadow maps
//! and reflection/refraction probes rendered with this backend's raster, cached between frames,
//! and looked up for every covered polygon pixel the trace stage left out.
//!
//! Inputs: the G-buffer (surfaces, object ids, mask), the camera, the prepared scene (and the
//! capsule, whose spheres cast into the maps and appear in the probes). Outputs: the three
//! fallback buffers (`shadow_fallback`, `reflection_fallback`, `refraction_fallback`) and how
//! many maps and probes were rendered.

use glam::Vec3;
use hybrid_core::blend::MASK_EPSILON;
use hybrid_core::fallback::{
    FallbackScene, FallbackSettings, LightShadowMaps, Probe, ProbePlan, Refractor, SeeThrough, ShadowMap, ShadowView, caster_meshes,
    nearest_see_through, plan_light_views, plan_probes, project, refractors, scene_bounds, see_through_layer_kept, see_through_objects,
    see_through_view, shadowed_lights,
};
use hybrid_core::prepare::PreparedScene;
use hybrid_core::report::FallbackRenders;
use hybrid_core::shading::{FrameLights, lights};
use hybrid_core::{GBuffer, RtLayer, is_polygon};
use hybrid_scene::{Aabb, Camera};
use rayon::prelude::*;

use crate::capsule::{CapsuleRequest, PointCloudCapsule, RtCapsule};
use crate::{depth_merge, lighting, raster};

/// The fallbacks' cache: each light's maps (kept while their view stays the same), each
/// object's probe (kept: scenes are static), and what was rendered so far.
pub struct FallbackCache {
    pub settings: FallbackSettings,
    /// Per light in `lights()` order.
    maps: Vec<Option<LightShadowMaps>>,
    /// Per object.
    probes: Vec<Option<Probe>>,
    plans: Vec<Option<ProbePlan>>,
    /// Meshes that cast into the maps.
    casters: Vec<bool>,
    /// Per object: planar refractive objects, whose refraction looks through the see-through
    /// layer; per mesh: the meshes that layer draws (all the others).
    see_through_objects: Vec<bool>,
    see_through_meshes: Vec<bool>,
    /// Per object: what a refraction ray leaves it by (`refractors`).
    refractors: Vec<Option<Refractor>>,
    bounds: Aabb,
    /// Shadow maps rendered per light (cascades, spot maps, cube faces), since the cache was made.
    pub shadow_map_renders: Vec<u64>,
    /// Probes rendered since the cache was made.
    pub probe_renders: u64,
    /// The last see-through layer, kept while the view stays close to it (scenes are static).
    see_through: Option<SeeThroughLayer>,
    /// See-through layers rendered since the cache was made.
    pub see_through_renders: u64,
}

/// A see-through layer: the widened view's camera, its G-buffer and lighting.
struct SeeThroughLayer {
    view: Camera,
    gbuffer: GBuffer,
    lit: Vec<Vec3>,
}

impl FallbackCache {
    pub fn new(prepared: &PreparedScene, spheres_cast: bool) -> Self {
        let scene = prepared.scene;
        let bounds = scene_bounds(prepared, spheres_cast);
        let casters = caster_meshes(prepared);
        let refractors = refractors(prepared);
        let see_through_objects = see_through_objects(prepared, &refractors);
        let see_through_meshes = prepared.meshes.iter().map(|m| !see_through_objects[m.object as usize]).collect();
        let mut plans = vec![None; scene.objects.len()];
        for p in plan_probes(prepared, &scene_bounds(prepared, false)) {
            plans[p.object as usize] = Some(p);
        }
        let n_lights = lights(&scene.lights).count();
        Self {
            settings: FallbackSettings::default(),
            maps: vec![None; n_lights],
            probes: vec![None; scene.objects.len()],
            plans,
            casters,
            see_through_objects,
            see_through_meshes,
            refractors,
            bounds,
            shadow_map_renders: vec![0; n_lights],
            probe_renders: 0,
            see_through: None,
            see_through_renders: 0,
        }
    }

    /// The rendered shadow maps (per light in `lights()` order), e.g. for `--dump`.
    pub fn shadow_maps(&self) -> &[Option<LightShadowMaps>] {
        &self.maps
    }

    /// Object `object`'s probe, if one was rendered.
    pub fn probe(&self, object: usize) -> Option<&Probe> {
        self.probes.get(object).and_then(Option::as_ref)
    }

    /// Stage 3b: brings the maps and the needed probes up to date, then writes the fallback
    /// terms of every covered polygon pixel with mask < ε into `[shadow, reflection, refraction]`
    /// (1, 0, 0 elsewhere).
    pub fn stage(
        &mut self,
        prepared: &PreparedScene,
        mut capsule: Option<&mut PointCloudCapsule>,
        gbuffer: &GBuffer,
        camera: &Camera,
        [shadow, reflection, refraction]: [&mut Vec<Vec3>; 3],
    ) -> FallbackRenders {
        let n = gbuffer.len();
        for (b, v) in [(&mut *shadow, Vec3::ONE), (&mut *reflection, Vec3::ZERO), (&mut *refraction, Vec3::ZERO)] {
            b.clear();
            b.resize(n, v);
        }
        let scene = prepared.scene;
        let mut renders = FallbackRenders::default();
        // Objects with untraced pixels.
        let mut needed = vec![false; scene.objects.len()];
        for (&id, &m) in gbuffer.object_id.iter().zip(&gbuffer.mask) {
            if m < MASK_EPSILON
                && is_polygon(id)
                && let Some(x) = needed.get_mut(id as usize)
            {
                *x = true;
            }
        }
        if !needed.iter().any(|&x| x) {
            return renders;
        }

        // Shadow maps: re-rendered where the view changed (cascades when the camera moved them).
        let aspect = gbuffer.width as f32 / gbuffer.height.max(1) as f32;
        let spheres = if capsule.is_some() { &scene.point_clouds[..] } else { &[] };
        let previous = |light: usize, k: usize| self.maps[light].as_ref().and_then(|m| m.maps.get(k)).map(|m| m.view);
        for lv in plan_light_views(scene, &self.bounds, camera, aspect, &self.settings, &previous) {
            // Last frame's maps, moved (not copied) into this frame's where the view is the same.
            let mut old: Vec<Option<ShadowMap>> =
                self.maps[lv.light].take().map_or_else(Vec::new, |o| o.maps.into_iter().map(Some).collect());
            let mut maps = Vec::with_capacity(lv.views.len());
            for (k, view) in lv.views.iter().enumerate() {
                match old.get_mut(k).and_then(Option::take).filter(|m| m.view == *view) {
                    Some(m) => maps.push(m),
                    None => {
                        let mut depth = raster::rasterize_depth(prepared, view.view_proj, view.size, &self.casters);
                        splat_spheres(view, spheres, &mut depth);
                        maps.push(ShadowMap { view: *view, depth });
                        self.shadow_map_renders[lv.light] += 1;
                        renders.shadow_maps += 1;
                    }
                }
            }
            self.maps[lv.light] = Some(LightShadowMaps { light: lv.light, kind: lv.kind, maps });
        }

        // The see-through layer, when a planar or convex refractive object has untraced pixels:
        // the view rasterized without those objects, lit; kept while the view stays close to
        // the layer's (`see_through_layer_kept`). Its texels are shaded with their probes, so
        // what shows in it needs probes as well.
        let see_through_needed = needed.iter().zip(&self.see_through_objects).any(|(&n, &s)| n && s);
        if see_through_needed {
            let (view, w, h) = see_through_view(camera, gbuffer.width, gbuffer.height);
            let nearest = nearest_see_through(camera.position, &prepared.object_bounds, &self.see_through_objects, &needed);
            let kept = self
                .see_through
                .as_ref()
                .is_some_and(|l| see_through_layer_kept(&l.view, (l.gbuffer.width, l.gbuffer.height), &view, (w, h), nearest));
            if !kept {
                let g = raster::rasterize_meshes(prepared, &view, w, h, &self.see_through_meshes);
                let lit = lighting::deferred_lighting(&g, scene, &view);
                // What it shows gets its probe below; a kept layer's objects got theirs when it
                // was rendered.
                for &id in &g.object_id {
                    if let Some(x) = needed.get_mut(id as usize) {
                        *x = true;
                    }
                }
                self.see_through = Some(SeeThroughLayer { view, gbuffer: g, lit });
                self.see_through_renders += 1;
                renders.see_through += 1;
            }
        }
        let layer = self.see_through.as_ref().filter(|_| see_through_needed);

        // Probes of the reflective and refractive objects that need one, once each.
        for (object, need) in needed.iter().enumerate() {
            if !need || self.probes[object].is_some() {
                continue;
            }
            let Some(plan) = self.plans[object] else { continue };
            self.probes[object] = Some(render_probe(prepared, capsule.as_deref_mut(), plan, self.settings.probe_size));
            self.probe_renders += 1;
            renders.probes += 1;
        }

        // The lookups.
        let frame_lights = FrameLights::new(&scene.lights, &scene.environment);
        let fb = FallbackScene {
            scene,
            frame_lights: &frame_lights,
            shadowed: shadowed_lights(scene, &self.maps.iter().map(Option::as_ref).collect::<Vec<_>>()),
            probes: self.probes.iter().map(Option::as_ref).collect(),
            camera,
            camera_forward: camera.forward(),
            pcf_radius: self.settings.pcf_radius,
            see_through_objects: &self.see_through_objects,
            refractors: &self.refractors,
            see_through: layer.map(|l| SeeThrough {
                view_proj: l.view.view_projection(l.gbuffer.width as f32 / l.gbuffer.height.max(1) as f32),
                layer: &l.gbuffer,
                color: &l.lit,
            }),
        };
        const CHUNK: usize = 256;
        shadow.par_chunks_mut(CHUNK).zip(reflection.par_chunks_mut(CHUNK)).zip(refraction.par_chunks_mut(CHUNK)).enumerate().for_each(
            |(c, ((s, m), r))| {
                // Compiled for the machine's widest instruction set (the lookups are inlined).
                crate::isa::dispatch(
                    #[inline(always)]
                    || {
                        // The chunk's pixels the trace stage left out, four at a time
                        // (`FallbackScene::pixel4`), the rest one by one.
                        let mut todo = [0usize; CHUNK];
                        let mut count = 0;
                        for k in 0..s.len() {
                            let i = c * CHUNK + k;
                            let id = gbuffer.object_id[i];
                            let has_normal = gbuffer.normal[i].length_squared() > 0.0;
                            if gbuffer.mask[i] >= MASK_EPSILON || !is_polygon(id) || !has_normal {
                                continue;
                            }
                            todo[count] = k;
                            count += 1;
                        }
                        let todo = &todo[..count];
                        let surface = |k: usize| gbuffer.surface(c * CHUNK + k).expect("a covered pixel");
                        let id = |k: usize| gbuffer.object_id[c * CHUNK + k];
                        let quads = todo.chunks_exact(4);
                        let rest = quads.remainder();
                        for q in quads {
                            let out = fb.pixel4(
                                [id(q[0]), id(q[1]), id(q[2]), id(q[3])],
                                &[surface(q[0]), surface(q[1]), surface(q[2]), surface(q[3])],
                            );
                            for (&k, o) in q.iter().zip(out) {
                                (s[k], m[k], r[k]) = o;
                            }
                        }
                        for &k in rest {
                            (s[k], m[k], r[k]) = fb.pixel(id(k), &surface(k));
                        }
                    },
                )
            },
        );
        renders
    }
}

/// The probe's six faces: the raster path (G-buffer without the probe's own object, the
/// capsule's spheres merged by depth, deferred lighting; the skybox where nothing was drawn).
fn render_probe(prepared: &PreparedScene, mut capsule: Option<&mut PointCloudCapsule>, plan: ProbePlan, size: u32) -> Probe {
    let mut probe = Probe::new(plan, size);
    let include: Vec<bool> = prepared.meshes.iter().map(|m| m.object != plan.object).collect();
    let texels = (size * size) as usize;
    for face in 0..6 {
        let camera = probe.face_camera(face);
        let layer = capsule.as_deref_mut().map(|c| {
            let request = CapsuleRequest { camera, width: size, height: size, clip_depth: None };
            let mut packed = hybrid_core::depth_merge::PackedRtFrame::new(size, size);
            c.render(&request, &mut packed);
            let mut layer = RtLayer::new(size, size);
            depth_merge::unpack_layer_into(&packed, &mut layer);
            layer
        });
        let mut g = raster::rasterize_meshes(prepared, &camera, size, size, &include);
        if let Some(layer) = &layer {
            depth_merge::merge_rt_layer(&mut g, layer, &camera);
        }
        let lit = lighting::deferred_lighting(&g, prepared.scene, &camera);
        probe.texels[face * texels..(face + 1) * texels].copy_from_slice(&lit);
        for (d, (pos, &id)) in probe.distance[face * texels..(face + 1) * texels].iter_mut().zip(g.position.iter().zip(&g.object_id)) {
            *d = if id == hybrid_core::NO_OBJECT { plan.far } else { pos.distance(plan.centre).min(plan.far) };
        }
    }
    probe
}

/// The point clouds' spheres into a shadow map: each sphere a disc of the depth of its point
/// nearest the light, over the texels whose centres it covers (Greater wins).
fn splat_spheres(view: &ShadowView, clouds: &[hybrid_scene::PointCloud], depth: &mut [f32]) {
    let n = view.size as i32;
    if clouds.is_empty() || n == 0 {
        return;
    }
    // (centre x, centre y in texels, radius in texels, depth) per visible sphere.
    let discs: Vec<[f32; 4]> =
        clouds.iter().flat_map(|c| c.points.par_iter().filter_map(move |&p| disc(view, p, c.radius)).collect::<Vec<_>>()).collect();
    let band_rows = raster::BAND_ROWS as i32;
    let bands = (n + band_rows - 1) / band_rows;
    let mut bins: Vec<Vec<u32>> = vec![Vec::new(); bands as usize];
    for (i, d) in discs.iter().enumerate() {
        let (y0, y1) = (((d[1] - d[2]).floor() as i32).max(0), ((d[1] + d[2]).ceil() as i32).min(n - 1));
        if y0 > y1 {
            continue;
        }
        for b in y0 / band_rows..=y1 / band_rows {
            bins[b as usize].push(i as u32);
        }
    }
    depth.par_chunks_mut((n * band_rows) as usize).zip(&bins).enumerate().for_each(|(band, (rows, bin))| {
        let y_lo = band as i32 * band_rows;
        let y_hi = y_lo + rows.len() as i32 / n;
        for &i in bin {
            let [cx, cy, r, z] = discs[i as usize];
            let (y0, y1) = (((cy - r - 0.5).ceil() as i32).max(y_lo), ((cy + r - 0.5).floor() as i32).min(y_hi - 1));
            for y in y0..=y1 {
                let dy = y as f32 + 0.5 - cy;
                let half = (r * r - dy * dy).max(0.0).sqrt();
                let (x0, x1) = (((cx - half - 0.5).ceil() as i32).max(0), ((cx + half - 0.5).floor() as i32).min(n - 1));
                if x0 > x1 {
                    continue;
                }
                let row = &mut rows[((y - y_lo) * n) as usize..((y - y_lo + 1) * n) as usize];
                for d in &mut row[x0 as usize..=x1 as usize] {
                    if z > *d {
                        *d = z;
                    }
                }
            }
        }
    });
}

/// A sphere's disc in a map: centre and radius in texels, depth of its point nearest the light.
fn disc(view: &ShadowView, p: Vec3, radius: f32) -> Option<[f32; 4]> {
    let (uv, z) = project(&view.view_proj, p)?;
    let d = view.linear_depth(z);
    let texel = if view.orthographic { view.texel_world } else { view.texel_world * d };
    let n = view.size as f32;
    let r = radius / texel.max(1e-12);
    let (x, y) = (uv.x * n, uv.y * n);
    if x + r < 0.0 || y + r < 0.0 || x - r > n || y - r > n || !(0.0..=1.0).contains(&z) {
        return None;
    }
    let front = view.depth_of((d - radius).max(view.near)).min(1.0);
    Some([x, y, r, front])
}
