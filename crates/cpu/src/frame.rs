//! The CPU frame: design §1's stages called in order. `CpuRenderer::render` is the whole frame
//! on one screen; each stage lives in its own module with explicit inputs and outputs.

use std::time::Instant;

use glam::Vec3;
pub use hybrid_core::Frame;
use hybrid_core::depth_merge::PackedRtFrame;
use hybrid_core::report::{CapsuleReport, FrameReport, RayCounts, StageTimings};
use hybrid_core::stage::{HeuristicStage, MaskChoice};
use hybrid_core::{FrameBuffers, FrameSettings, GBuffer, Mode, NO_OBJECT, RtLayer, Stage};
use hybrid_heuristic::{Heuristic, HeuristicReport, count_visible_pixels, write_mask};
use hybrid_scene::{Camera, Scene};

use crate::bvh::SceneBvh;
use crate::capsule::{CapsuleError, CapsuleRequest, PointCloudCapsule, PrimaryVisibility, RtCapsule};
use crate::fallback::FallbackCache;
use crate::{blend, depth_merge, lighting, raster, trace};
use hybrid_core::fallback::{Fallback, object_effects_of};
use hybrid_core::prepare::PreparedScene;
use hybrid_core::report::FallbackRenders;

/// The CPU backend with everything it keeps between frames: the prepared scene, its BVH, the
/// point-cloud capsule and the heuristic's state (S per object, ms per cost unit).
pub struct CpuRenderer<'s> {
    scene: &'s Scene,
    prepared: PreparedScene<'s>,
    bvh: SceneBvh,
    capsule: Option<PointCloudCapsule>,
    heuristic: HeuristicStage,
    /// Beyond paper 2: trace the capsule after the raster, with rays clipped at the polygon
    /// depth. Saves the rays that would end behind polygons, at the cost of running the
    /// capsule after (not beside) the raster.
    pub clip_capsule_at_raster_depth: bool,
    /// Beyond paper 2: the point-cloud spheres cast shadows on polygons and appear in
    /// reflections and refractions (default on). Off gives the paper's behaviour (the RT-scene
    /// only merges by depth): a faster trace stage, at the cost of those effects.
    pub spheres_in_trace: bool,
    /// What pixels the trace stage left out get (`--fallback`, issue 18): shadow maps and probes
    /// (default), or nothing (paper 1 exactly).
    pub fallback: Fallback,
    /// The fallbacks' maps and probes, made on first use and kept between frames.
    fallback_cache: Option<FallbackCache>,
    /// A G-buffer handed back with [`CpuRenderer::recycle`], reused by the next raster (saves
    /// allocating and page-faulting ~100 MB per 1280×720 frame).
    spare_gbuffer: Option<GBuffer>,
    /// The other per-frame buffers handed back with [`CpuRenderer::recycle`] (lighting, trace
    /// outputs and final image: ~150 MB at 1920×1080), and the packed RT frame.
    spare_buffers: Option<FrameBuffers>,
    spare_packed: Option<PackedRtFrame>,
    /// The unpacked RT layer of the last frame (block U's output, kept for the next frame).
    spare_rt_layer: Option<RtLayer>,
}

impl<'s> CpuRenderer<'s> {
    /// How the capsule finds each primary ray's sphere ([`PrimaryVisibility`]; the frame is the
    /// same either way). No effect on a scene without point clouds.
    pub fn set_capsule_visibility(&mut self, visibility: PrimaryVisibility) {
        if let Some(c) = self.capsule.as_mut() {
            c.primary_visibility = visibility;
        }
    }

    /// Prepares `scene` once: world-space meshes, the triangle BVH, the capsule's sphere BVH.
    /// Fails only when a point cloud cannot be built into a sphere BVH.
    pub fn new(scene: &'s Scene) -> Result<Self, CapsuleError> {
        let prepared = PreparedScene::new(scene);
        let bvh = SceneBvh::build(&prepared);
        let capsule = if scene.point_clouds.is_empty() {
            None
        } else {
            Some(PointCloudCapsule::new(&scene.point_clouds, scene.lights.clone(), scene.environment.clone())?)
        };
        Ok(Self {
            scene,
            prepared,
            bvh,
            capsule,
            heuristic: HeuristicStage::new(Heuristic::new(scene.heuristic.clone())),
            clip_capsule_at_raster_depth: false,
            spheres_in_trace: true,
            fallback: Fallback::default(),
            fallback_cache: None,
            spare_gbuffer: None,
            spare_buffers: None,
            spare_packed: None,
            spare_rt_layer: None,
        })
    }

    pub fn prepared(&self) -> &PreparedScene<'s> {
        &self.prepared
    }

    /// The heuristic, e.g. to change its budget or policy between frames (its state carries over).
    pub fn heuristic_mut(&mut self) -> &mut Heuristic {
        self.heuristic.heuristic_mut()
    }

    /// The heuristic stage, e.g. to set an object's K and E live
    /// ([`HeuristicStage::set_object_weights`]).
    pub fn heuristic_stage_mut(&mut self) -> &mut HeuristicStage {
        &mut self.heuristic
    }

    /// Hands a finished frame back so the next frame reuses its memory (G-buffer, lighting,
    /// trace outputs, final image, packed RT frame) instead of allocating and page-faulting it
    /// anew (for loops that render many frames; optional).
    pub fn recycle(&mut self, frame: Frame) {
        self.spare_gbuffer = Some(frame.gbuffer);
        self.spare_buffers = Some(frame.buffers);
        self.spare_packed = frame.rt_packed;
    }

    /// Renders one frame. `on_stage` is told each stage's name as it starts (progress display).
    pub fn render(&mut self, camera: &Camera, settings: FrameSettings, on_stage: &mut dyn FnMut(Stage)) -> Frame {
        let frame_start = Instant::now();
        let mut t = StageTimings::default();
        let mode = settings.mode;

        let mut buffers = self.spare_buffers.take().unwrap_or_default();
        (buffers.width, buffers.height) = (settings.width, settings.height);

        let (mut gbuffer, primary_rays, rt_packed, capsule_report) = if self.clip_capsule_at_raster_depth {
            // Beyond paper 2: raster first, then the capsule with rays clipped at the polygons.
            on_stage(Stage::Raster);
            let (mut gbuffer, primary_rays) = timed(&mut t[Stage::Raster], || self.geometry_stage(camera, settings, None));
            on_stage(Stage::Capsule);
            let (rt_packed, rt_layer, capsule_report) =
                timed(&mut t[Stage::Capsule], || self.capsule_stage(camera, settings, Some(&gbuffer.depth)));
            // Block U's depth test, after the fact (counted with the raster, where the
            // unclipped order does it).
            let mut merge_ms = 0.0;
            if let Some(layer) = &rt_layer {
                timed(&mut merge_ms, || depth_merge::merge_rt_layer(&mut gbuffer, layer, camera));
            }
            t[Stage::Raster] += merge_ms;
            self.spare_rt_layer = rt_layer;
            timed(&mut t[Stage::Lighting], || lighting::deferred_lighting_into(&gbuffer, self.scene, camera, &mut buffers.lighting));
            (gbuffer, primary_rays, rt_packed, capsule_report)
        } else {
            // Paper 2: the capsule's frame first, merged by depth as the polygons are drawn.
            on_stage(Stage::Capsule);
            let (rt_packed, rt_layer, capsule_report) = timed(&mut t[Stage::Capsule], || self.capsule_stage(camera, settings, None));
            on_stage(Stage::Raster);
            let (gbuffer, primary_rays) = timed(&mut t[Stage::Raster], || self.geometry_stage(camera, settings, rt_layer.as_ref()));
            self.spare_rt_layer = rt_layer;
            timed(&mut t[Stage::Lighting], || lighting::deferred_lighting_into(&gbuffer, self.scene, camera, &mut buffers.lighting));
            (gbuffer, primary_rays, rt_packed, capsule_report)
        };
        t[Stage::Raster] += t[Stage::Lighting];

        on_stage(Stage::Heuristic);
        let heuristic_report = timed(&mut t[Stage::Heuristic], || self.heuristic_stage(&mut gbuffer, camera, mode));

        on_stage(Stage::Trace);
        let traced_rays = timed(&mut t[Stage::Trace], || {
            self.trace_stage(&gbuffer, camera, mode, [&mut buffers.shadow, &mut buffers.reflection, &mut buffers.refraction])
        });

        on_stage(Stage::Fallback);
        let fallback_renders = timed(&mut t[Stage::Fallback], || self.fallback_stage(&gbuffer, camera, mode, &mut buffers));

        on_stage(Stage::Blend);
        let b = &mut buffers;
        let fallback = (!b.shadow_fallback.is_empty()).then_some([&b.shadow_fallback[..], &b.reflection_fallback, &b.refraction_fallback]);
        timed(&mut t[Stage::Blend], || {
            blend::blend_into(&gbuffer, &b.lighting, [&b.shadow, &b.reflection, &b.refraction], fallback, &mut b.final_srgb)
        });
        let effects = object_effects_of(self.scene, &gbuffer.object_id, &gbuffer.mask, self.fallback_applies(mode));

        self.heuristic.record_trace(mode, heuristic_report.as_ref(), t[Stage::Trace]);
        t.frame = ms_since(frame_start);
        let rays = RayCounts { primary: primary_rays, ..traced_rays };
        let report = FrameReport {
            backend: "cpu".into(),
            size: [settings.width, settings.height],
            mode,
            timings_ms: t,
            rays,
            triangles: self.prepared.triangles.len() as u64,
            objects: self.scene.objects.len() as u64,
            heuristic: heuristic_report,
            capsule: capsule_report,
            fallback: self.fallback,
            effects,
            fallback_renders,
            gpu_timings_ms: None,
            adapter: None,
        };
        Frame { settings, gbuffer, buffers, rt_packed, report }
    }

    /// Stage 0 (paper 2): the capsule renders its packed frame (blocks D and P), the host
    /// unpacks it (block U) into colour + depth for the merge.
    fn capsule_stage(
        &mut self,
        camera: &Camera,
        settings: FrameSettings,
        clip_depth: Option<&[f32]>,
    ) -> (Option<PackedRtFrame>, Option<RtLayer>, Option<CapsuleReport>) {
        let Some(capsule) = self.capsule.as_mut() else { return (None, None, None) };
        // `render` resizes and clears it.
        let mut packed = self.spare_packed.take().unwrap_or_else(|| PackedRtFrame::new(0, 0));
        let request = CapsuleRequest { camera: *camera, width: settings.width, height: settings.height, clip_depth };
        let stats = capsule.render(&request, &mut packed);
        let unpack_start = Instant::now();
        // Block U. Every texel is written, so last frame's layer of the same size needs no
        // clearing.
        let mut layer = self
            .spare_rt_layer
            .take()
            .filter(|l| (l.width, l.height) == (settings.width, settings.height))
            .unwrap_or_else(|| RtLayer::new(settings.width, settings.height));
        depth_merge::unpack_layer_into(&packed, &mut layer);
        let report = CapsuleReport {
            points: stats.points,
            build_ms: stats.build_ms,
            trace_ms: stats.trace_ms,
            pack_ms: stats.pack_ms,
            unpack_ms: ms_since(unpack_start),
            rays: stats.rays,
        };
        (Some(packed), Some(layer), Some(report))
    }

    /// Stage 1 (geometry): the G-buffer — rasterized, or from primary rays in rt-only mode —
    /// merged by depth with the RT layer. Returns the primary-ray count. Deferred lighting into
    /// the P-buffer follows (`lighting::deferred_lighting`).
    fn geometry_stage(&mut self, camera: &Camera, settings: FrameSettings, rt_layer: Option<&RtLayer>) -> (GBuffer, u64) {
        let (w, h) = (settings.width, settings.height);
        if settings.mode == Mode::RtOnly {
            let mut g = self.spare_gbuffer.take().filter(|g| g.width == w && g.height == h).unwrap_or_else(|| GBuffer::new(w, h));
            trace::rt_only_gbuffer_into(&self.prepared, &self.bvh, camera, &mut g);
            if let Some(layer) = rt_layer {
                depth_merge::merge_rt_layer(&mut g, layer, camera);
            }
            (g, trace::primary_ray_count(w, h))
        } else {
            match self.spare_gbuffer.take().filter(|g| g.width == w && g.height == h) {
                Some(mut g) => {
                    raster::rasterize_into(&self.prepared, camera, rt_layer, &mut g);
                    (g, 0)
                }
                None => (raster::rasterize(&self.prepared, camera, w, h, rt_layer), 0),
            }
        }
    }

    /// Stage 2: the shared heuristic stage on A per object from the object-id target (one pass),
    /// then the mask. `all` selects every visible object; `rt-only` traces every covered pixel;
    /// `raster` traces nothing (the raster left the mask at 0).
    fn heuristic_stage(&mut self, gbuffer: &mut GBuffer, camera: &Camera, mode: Mode) -> Option<HeuristicReport> {
        let object_count = self.scene.objects.len();
        let count = || Ok::<_, std::convert::Infallible>(count_visible_pixels(&gbuffer.object_id, object_count));
        let Ok(choice) = self.heuristic.choose(&self.prepared, camera, (gbuffer.width, gbuffer.height), mode, count);
        match &choice {
            MaskChoice::Nothing => {}
            MaskChoice::AllCovered => {
                for (m, &id) in gbuffer.mask.iter_mut().zip(&gbuffer.object_id) {
                    *m = if id != NO_OBJECT { 1.0 } else { 0.0 };
                }
            }
            MaskChoice::Objects(selection) => write_mask(&gbuffer.object_id, &selection.selected, &mut gbuffer.mask),
        }
        choice.into_report()
    }

    /// The fallback that applies in `mode` (`rt-only` traces every pixel: none).
    fn fallback_applies(&self, mode: Mode) -> Fallback {
        if mode == Mode::RtOnly { Fallback::None } else { self.fallback }
    }

    /// Stage 3b: the raster fallbacks for the pixels the trace stage left out, into the
    /// frame's fallback buffers (left empty when there are none). Returns what it rendered.
    fn fallback_stage(&mut self, gbuffer: &GBuffer, camera: &Camera, mode: Mode, buffers: &mut FrameBuffers) -> FallbackRenders {
        let out = [&mut buffers.shadow_fallback, &mut buffers.reflection_fallback, &mut buffers.refraction_fallback];
        if self.fallback_applies(mode) == Fallback::None {
            out.into_iter().for_each(Vec::clear);
            return FallbackRenders::default();
        }
        let spheres_cast = self.spheres_in_trace && self.capsule.is_some();
        let cache = self.fallback_cache.get_or_insert_with(|| FallbackCache::new(&self.prepared, spheres_cast));
        let capsule = self.capsule.as_mut().filter(|_| self.spheres_in_trace);
        cache.stage(&self.prepared, capsule, gbuffer, camera, out)
    }

    /// The fallbacks' cache (shadow maps, probes and their render counts), once a frame has
    /// needed it.
    pub fn fallback_cache(&self) -> Option<&FallbackCache> {
        self.fallback_cache.as_ref()
    }

    /// Stage 3: shadow, reflection and refraction rays for masked pixels (listings 8a–d), into
    /// `[shadow, reflection, refraction]`.
    fn trace_stage(&self, gbuffer: &GBuffer, camera: &Camera, mode: Mode, out: [&mut Vec<Vec3>; 3]) -> RayCounts {
        if mode == Mode::Raster {
            let n = gbuffer.len();
            for (buffer, untraced) in out.into_iter().zip([Vec3::ONE, Vec3::ZERO, Vec3::ZERO]) {
                buffer.clear();
                buffer.resize(n, untraced);
            }
            return RayCounts::default();
        }
        let spheres = self.capsule.as_ref().filter(|_| self.spheres_in_trace);
        trace::trace_with_spheres_into(&self.prepared, &self.bvh, spheres, gbuffer, camera, out)
    }
}

fn timed<T>(slot: &mut f64, f: impl FnOnce() -> T) -> T {
    let start = Instant::now();
    let out = f();
    *slot = ms_since(start);
    out
}

fn ms_since(start: Instant) -> f64 {
    start.elapsed().as_secs_f64() * 1e3
}
