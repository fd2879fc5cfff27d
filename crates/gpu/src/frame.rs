//! The GPU frame: design §1's stages as GPU passes, called in the same order as the CPU frame
//! (`hybrid_cpu::frame`). `GpuRenderer::render` is the whole frame on one screen; each stage is
//! its own module with explicit inputs (the scene's group 0, the frame's targets) and outputs
//! (targets it writes). One read-back sits in the middle: the heuristic's pixel counts.

use std::sync::Arc;
use std::time::Instant;

use hybrid_core::fallback::{Fallback, object_effects};
use hybrid_core::report::{AdapterReport, FallbackRenders, FrameReport, RayCounts, StageTimings};
use hybrid_core::stage::{HeuristicStage, MaskChoice};
use hybrid_core::{Frame, FrameSettings, Mode, PreparedScene, Stage};
use hybrid_heuristic::{Heuristic, HeuristicReport};
use hybrid_scene::{Camera, Scene};

use crate::accel::{RtChoice, RtPath, RtScene};
use crate::blend::BlendPass;
use crate::bvh::TriangleBvhGpu;
use crate::capsule::GpuCapsule;
use crate::context::{GpuContext, GpuError};
use crate::fallback::FallbackGpu;
use crate::heuristic::{HeuristicPasses, MaskSelection};
use crate::lighting::LightingPass;
use crate::primary::PrimaryPass;
use crate::raster::RasterPass;
use crate::readback;
use crate::scene::SceneGpu;
use crate::spheres::SpheresGpu;
use crate::targets::FrameTargets;
use crate::timing::StageTimer;
use crate::trace::TracePasses;

/// The GPU backend with everything it keeps between frames: the scene on the GPU (buffers,
/// BVHs, textures), the pipelines of every stage, the frame's targets and the heuristic's state.
pub struct GpuRenderer<'s> {
    ctx: Arc<GpuContext>,
    scene: &'s Scene,
    prepared: PreparedScene<'s>,
    gpu_scene: SceneGpu,
    spheres: SpheresGpu,
    capsule: Option<GpuCapsule>,
    raster: RasterPass,
    primary: PrimaryPass,
    lighting: LightingPass,
    heuristic_passes: HeuristicPasses,
    trace: TracePasses,
    /// The trace stage bound to no spheres (`spheres_in_trace = false`; scenes with point clouds).
    trace_without_spheres: Option<TracePasses>,
    blend: BlendPass,
    heuristic: HeuristicStage,
    targets: Option<FrameTargets>,
    timer: StageTimer,
    /// Host milliseconds spent building and uploading the scene (BVHs included).
    pub prepare_ms: f64,
    /// Hardware or software traversal, and why (`--rt`).
    rt_path: RtPath,
    /// The acceleration structures' build time (hardware path).
    build_as_ms: Option<f64>,
    /// The acceleration structures (hardware path), kept alive for the passes' group 3.
    _rt_scene: Option<RtScene>,
    /// Beyond paper 2: the point-cloud spheres cast shadows on polygons and appear in
    /// reflections and refractions (default on). Off gives the paper's behaviour (the RT-scene
    /// only merges by depth): a faster trace stage, at the cost of those effects.
    pub spheres_in_trace: bool,
    /// What pixels the trace stage left out get (`--fallback`, issue 18): shadow maps and probes
    /// (default), or nothing (paper 1 exactly).
    pub fallback: Fallback,
    /// Stage 3b's maps, probes and targets, made on the first frame that needs them.
    fallback_gpu: Option<FallbackGpu>,
    /// Whether the last frame wrote the fallback targets (read back with the frame's buffers).
    fallback_written: bool,
    /// Beyond paper 2: trace the capsule after the raster, with rays clipped at the polygon
    /// depth. Saves the rays that would end behind polygons, at the cost of running the capsule
    /// after (not beside) the raster.
    pub clip_capsule_at_raster_depth: bool,
}

impl<'s> GpuRenderer<'s> {
    /// Uploads `scene` once: vertices, materials, textures, lights, the triangle BVH and the
    /// point clouds' sphere BVH, and builds every stage's pipeline. Traces with the software
    /// traversal ([`RtChoice::Software`]; [`GpuRenderer::with_rt`] chooses).
    pub fn new(ctx: Arc<GpuContext>, scene: &'s Scene) -> Result<Self, GpuError> {
        Self::with_rt(ctx, scene, RtChoice::Software)
    }

    /// As [`GpuRenderer::new`], tracing in hardware or software as `rt` and the adapter say
    /// (`--rt`): the hardware path also builds the acceleration structures (`crate::accel`).
    /// `RtChoice::Hardware` on an adapter without ray queries fails with `GpuError::Unsupported`.
    pub fn with_rt(ctx: Arc<GpuContext>, scene: &'s Scene, rt: RtChoice) -> Result<Self, GpuError> {
        let rt_path = rt.resolve(&ctx)?;
        // wgpu reports invalid use and exhausted memory asynchronously (by default with a panic):
        // capture both while the scene is uploaded and the pipelines built, and return them.
        let scope = ErrorScope::push(&ctx.device);
        // Pop the scopes whatever `build` returned (an early return used to drop them in the wrong
        // order: "Mismatched pop_error_scope call"); a captured device error explains an early
        // failure better than the failure itself, so it wins.
        let built = Self::build(ctx.clone(), scene, rt_path);
        let popped = scope.pop(&ctx);
        popped.and(built)
    }

    fn build(ctx: Arc<GpuContext>, scene: &'s Scene, rt_path: RtPath) -> Result<Self, GpuError> {
        let start = Instant::now();
        let prepared = PreparedScene::new(scene);
        let gpu_scene = SceneGpu::new(&ctx, &prepared)?;
        let spheres = if scene.point_clouds.is_empty() { SpheresGpu::empty(&ctx) } else { SpheresGpu::new(&ctx, &scene.point_clouds)? };
        let rt_scene = if rt_path.hardware { Some(RtScene::new(&ctx, &gpu_scene, &prepared, &spheres)?) } else { None };
        let rt = rt_scene.as_ref();
        let capsule = (!scene.point_clouds.is_empty()).then(|| GpuCapsule::new_rt(&ctx, &gpu_scene, &spheres, rt));
        let no_spheres = SpheresGpu::empty(&ctx);
        let bvh = Arc::new(TriangleBvhGpu::new(&ctx, &gpu_scene, &prepared)?);
        let trace = TracePasses::with_bvh_rt(&ctx, &gpu_scene, &prepared, bvh, &spheres, rt)?;
        let trace_without_spheres = if scene.point_clouds.is_empty() {
            None
        } else {
            Some(TracePasses::with_bvh_rt(&ctx, &gpu_scene, &prepared, trace.shared_bvh(), &no_spheres, rt)?)
        };
        Ok(Self {
            raster: RasterPass::new(&ctx, &gpu_scene),
            primary: PrimaryPass::new_rt(&ctx, &gpu_scene, trace.bvh(), rt),
            build_as_ms: rt_scene.as_ref().map(|r| r.build_ms),
            rt_path,
            _rt_scene: rt_scene,
            lighting: LightingPass::new(&ctx, &gpu_scene),
            heuristic_passes: HeuristicPasses::new(&ctx, scene.objects.len() as u32),
            blend: BlendPass::new(&ctx),
            timer: StageTimer::new(&ctx),
            heuristic: HeuristicStage::new(Heuristic::new(scene.heuristic.clone())),
            targets: None,
            prepare_ms: start.elapsed().as_secs_f64() * 1e3,
            spheres_in_trace: true,
            fallback: Fallback::default(),
            fallback_gpu: None,
            fallback_written: false,
            clip_capsule_at_raster_depth: false,
            trace,
            trace_without_spheres,
            capsule,
            spheres,
            gpu_scene,
            prepared,
            scene,
            ctx,
        })
    }

    /// Per pixel of the last frame, the global id of the sphere the capsule hit (`u32::MAX`: miss);
    /// `None` without point clouds. Waits for the GPU.
    pub fn capsule_hit_ids(&self) -> Option<Result<Vec<u32>, GpuError>> {
        self.capsule.as_ref().map(|c| c.read_hit_ids(&self.ctx))
    }

    /// Which traversal traces this renderer's rays, and why.
    pub fn rt_path(&self) -> &RtPath {
        &self.rt_path
    }

    pub fn context(&self) -> &GpuContext {
        &self.ctx
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

    /// Renders one frame and reads every buffer back (for the image, dumps and tests).
    /// `on_stage` is told each stage's name as it is recorded.
    pub fn render(&mut self, camera: &Camera, settings: FrameSettings, on_stage: &mut dyn FnMut(Stage)) -> Result<Frame, GpuError> {
        let report = self.render_to_targets(camera, settings, on_stage)?;
        let targets = self.targets.as_ref().ok_or_else(|| GpuError::Device("the frame's targets are missing after the frame".into()))?;
        let gbuffer = readback::read_gbuffer(&self.ctx, targets)?;
        let mut buffers = readback::read_frame_buffers(&self.ctx, targets)?;
        if self.fallback_written
            && let Some(outputs) = self.fallback_gpu.as_ref().and_then(FallbackGpu::outputs)
        {
            [buffers.shadow_fallback, buffers.reflection_fallback, buffers.refraction_fallback] =
                readback::read_fallback(&self.ctx, outputs)?;
        }
        let rt_packed = if self.capsule.is_some() { Some(readback::read_packed(&self.ctx, targets)?) } else { None };
        Ok(Frame { settings, gbuffer, buffers, rt_packed, report })
    }

    /// Renders one frame's passes into the renderer's targets without reading any buffer back
    /// (the interactive viewer's frame path): the final image and every other buffer stay on the
    /// GPU, reachable through [`GpuRenderer::targets`]. Returns the frame's report.
    pub fn render_to_targets(
        &mut self,
        camera: &Camera,
        settings: FrameSettings,
        on_stage: &mut dyn FnMut(Stage),
    ) -> Result<FrameReport, GpuError> {
        let (w, h) = (settings.width, settings.height);
        let scope = ErrorScope::push(&self.ctx.device);
        let targets = match self.targets.take() {
            Some(t) if t.width == w && t.height == h => t,
            _ => FrameTargets::new(&self.ctx.device, w, h),
        };
        let rendered = self.render_into(&targets, camera, settings, on_stage);
        // Always popped, in order, whatever the frame returned (see `new`).
        let result = scope.pop(&self.ctx).and(rendered);
        let report = result.map(|(mut report, wall)| {
            report.timings_ms.frame = wall;
            report
        });
        if report.is_ok() {
            self.targets = Some(targets);
        }
        report
    }

    /// The targets of the last frame rendered (by [`GpuRenderer::render`] or
    /// [`GpuRenderer::render_to_targets`]), if any: `final_image` is the sRGB-encoded result.
    pub fn targets(&self) -> Option<&FrameTargets> {
        self.targets.as_ref()
    }

    /// The frame's passes into `targets`: returns the report and the wall-clock ms of the frame
    /// (submission to completion, read-backs of buffers not included).
    fn render_into(
        &mut self,
        targets: &FrameTargets,
        camera: &Camera,
        settings: FrameSettings,
        on_stage: &mut dyn FnMut(Stage),
    ) -> Result<(FrameReport, f64), GpuError> {
        let start = Instant::now();
        let (w, h, mode) = (settings.width, settings.height, settings.mode);
        let ctx = self.ctx.clone();
        let device = &ctx.device;
        self.gpu_scene.write_uniforms(&self.ctx, camera, w, h, &self.scene.environment);
        self.timer.begin_frame();

        // First submission: stages 0–1 and the pixel count of stage 2.
        let mut enc = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("frame: capsule, raster, count") });
        let clip = self.clip_capsule_at_raster_depth && self.capsule.is_some();
        if clip {
            // Beyond paper 2: polygons first, then the capsule's rays stop at their depth and its
            // frame is merged into theirs.
            on_stage(Stage::Raster);
            self.geometry_stage(&mut enc, targets, mode, true);
            on_stage(Stage::Capsule);
            self.capsule_stage(&mut enc, targets, true);
        } else {
            // Paper 2: the capsule's frame first, the polygons depth-tested against it.
            on_stage(Stage::Capsule);
            self.capsule_stage(&mut enc, targets, false);
            on_stage(Stage::Raster);
            self.geometry_stage(&mut enc, targets, mode, self.capsule.is_none());
        }
        self.lighting.encode(&mut enc, &self.gpu_scene, targets, &mut self.timer);
        on_stage(Stage::Heuristic);
        // A per object: the heuristic's input (hybrid, all), and in every mode which objects
        // were traced and which were not (the report's effects, the fallbacks' probes).
        self.heuristic_passes.encode_count(&mut enc, targets, &mut self.timer);
        self.ctx.queue.submit([enc.finish()]);
        // The heuristic needs A: wait for stages 0–2's passes (their GPU times are measured by
        // the timer; the host time below is the heuristic's own).
        self.ctx.wait()?;

        // Stage 2 on the host: A per object → the shared heuristic → the mask pass.
        let heuristic_start = Instant::now();
        let mut enc = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("frame: mask, trace, blend") });
        let (heuristic_report, selected, counts) = self.heuristic_stage(&mut enc, targets, camera, mode)?;
        let heuristic_host_ms = heuristic_start.elapsed().as_secs_f64() * 1e3;
        // Covered pixels per object that are traced (mask 1: selected) and that are not.
        let traced: Vec<u64> = counts.iter().zip(&selected).map(|(&c, &on)| if on { c } else { 0 }).collect();
        let untraced: Vec<u64> = counts.iter().zip(&selected).map(|(&c, &on)| if on { 0 } else { c }).collect();
        let fallback = self.fallback_applies(mode);

        on_stage(Stage::Trace);
        if mode == Mode::Raster {
            clear_trace_outputs(&mut enc, targets);
        } else {
            chosen_trace(&self.trace, &self.trace_without_spheres, self.spheres_in_trace).encode(
                &mut enc,
                &self.gpu_scene,
                targets,
                &mut self.timer,
            );
        }
        on_stage(Stage::Fallback);
        let (fallback_renders, probe_ms) = self.fallback_stage(&mut enc, targets, camera, fallback, &untraced)?;
        on_stage(Stage::Blend);
        let fallback_targets = if self.fallback_written { self.fallback_gpu.as_ref().and_then(FallbackGpu::outputs) } else { None };
        self.blend.encode(&mut enc, targets, fallback_targets, &mut self.timer);
        self.timer.resolve(&mut enc);
        let second = Instant::now();
        self.ctx.queue.submit([enc.finish()]);
        self.ctx.wait()?;
        let second_ms = second.elapsed().as_secs_f64() * 1e3;
        let wall = start.elapsed().as_secs_f64() * 1e3;

        let gpu_timings = self.timer.read(&self.ctx)?;
        let mut rays = if mode == Mode::Raster {
            RayCounts::default()
        } else {
            chosen_trace(&self.trace, &self.trace_without_spheres, self.spheres_in_trace).read_ray_counts(&self.ctx)?
        };
        if mode == Mode::RtOnly {
            rays.primary = w as u64 * h as u64;
        }
        // Host-side stage times: GPU times where timestamps exist (the passes run back to back
        // inside two submissions, so host time per stage is not observable); the heuristic's
        // entry is its host part (read-back, selection) plus its GPU passes.
        let gpu_timings = gpu_timings.map(|g| StageTimings { build_as: self.build_as_ms, ..g });
        let mut timings = gpu_timings.unwrap_or(StageTimings { trace: second_ms, ..Default::default() });
        timings.heuristic += heuristic_host_ms;
        // The probes' faces run in their own submissions before the frame's second one: their
        // host time counts with the stage.
        timings.fallback += probe_ms;
        self.heuristic.record_trace(mode, heuristic_report.as_ref(), timings[Stage::Trace]);
        let capsule = self.capsule.as_ref().map(|c| {
            let mut r = c.report();
            r.trace_ms = gpu_timings.map_or(0.0, |g| g.capsule);
            r
        });
        let s = &self.ctx.summary;
        let report = FrameReport {
            backend: "gpu".into(),
            size: [w, h],
            mode,
            timings_ms: timings,
            rays,
            triangles: self.prepared.triangles.len() as u64,
            objects: self.scene.objects.len() as u64,
            heuristic: heuristic_report,
            capsule,
            fallback: self.fallback,
            effects: object_effects(self.scene, &traced, &untraced, fallback),
            fallback_renders,
            gpu_timings_ms: gpu_timings,
            adapter: Some(AdapterReport {
                name: s.name.clone(),
                backend: s.backend.clone(),
                device_type: s.device_type.clone(),
                driver: s.driver.clone(),
                ray_tracing: self.rt_path.name().into(),
            }),
        };
        Ok((report, wall))
    }

    /// Stage 0 (paper 2): the capsule's packed frame (blocks D + P), unpacked into the G-buffer
    /// (block U). `clipped`: after the raster, rays stopped at the polygons, merged into them.
    fn capsule_stage(&mut self, enc: &mut wgpu::CommandEncoder, targets: &FrameTargets, clipped: bool) {
        if let Some(capsule) = &self.capsule {
            capsule.encode(enc, &self.gpu_scene, &self.spheres, targets, clipped, &mut self.timer);
            capsule.encode_unpack(enc, &self.gpu_scene, targets, !clipped, &mut self.timer);
        }
    }

    /// Stage 1's geometry: the G-buffer rasterized, or from primary rays in rt-only mode;
    /// `clear = false` keeps (and depth-tests against) the RT layer already there.
    fn geometry_stage(&mut self, enc: &mut wgpu::CommandEncoder, targets: &FrameTargets, mode: Mode, clear: bool) {
        if mode == Mode::RtOnly {
            self.primary.encode(enc, &self.gpu_scene, targets, clear, &mut self.timer);
        } else {
            self.raster.encode(enc, &self.gpu_scene, targets, clear, &mut self.timer);
        }
    }

    /// Stage 2: the shared heuristic stage on A per object read back from the count pass (modes
    /// hybrid and all), then the mask pass. rt-only masks every covered pixel; raster masks nothing.
    /// Also returns, per object, whether its pixels are traced (mask 1) and A (read back in every
    /// mode).
    #[allow(clippy::type_complexity)]
    fn heuristic_stage(
        &mut self,
        enc: &mut wgpu::CommandEncoder,
        targets: &FrameTargets,
        camera: &Camera,
        mode: Mode,
    ) -> Result<(Option<HeuristicReport>, Vec<bool>, Vec<u64>), GpuError> {
        let ctx = &self.ctx;
        let passes = &self.heuristic_passes;
        let mut counted = None;
        let choice = self.heuristic.choose(&self.prepared, camera, (targets.width, targets.height), mode, || {
            let counts = passes.read_counts(ctx)?;
            counted = Some(counts.clone());
            Ok::<_, GpuError>(counts)
        })?;
        let counts = match counted {
            Some(c) => c,
            None => passes.read_counts(ctx)?,
        };
        let n = counts.len();
        let (mask, selected) = match &choice {
            MaskChoice::Nothing => (MaskSelection::Nothing, vec![false; n]),
            MaskChoice::AllCovered => (MaskSelection::AllCovered, vec![true; n]),
            MaskChoice::Objects(selection) => {
                let mut on = selection.selected.clone();
                on.resize(n, false);
                (MaskSelection::Objects(&selection.selected), on)
            }
        };
        self.heuristic_passes.encode_mask(ctx, enc, targets, mask, &mut self.timer);
        Ok((choice.into_report(), selected, counts))
    }

    /// The fallback that applies in `mode` (`rt-only` traces every pixel: none).
    fn fallback_applies(&self, mode: Mode) -> Fallback {
        if mode == Mode::RtOnly { Fallback::None } else { self.fallback }
    }

    /// Stage 3b (issue 18): the see-through layer where a planar refractive object has untraced
    /// pixels, then the probes of objects with untraced pixels (`untraced`, per object) or shown
    /// in that layer that have none yet (their own submissions, now), the shadow maps whose views changed and
    /// the lookups into the fallback targets (recorded into `enc`). Nothing when `fallback` is
    /// none. Returns what was rendered and the probes' host ms.
    fn fallback_stage(
        &mut self,
        enc: &mut wgpu::CommandEncoder,
        targets: &FrameTargets,
        camera: &Camera,
        fallback: Fallback,
        untraced: &[u64],
    ) -> Result<(FallbackRenders, f64), GpuError> {
        self.fallback_written = false;
        let mut renders = FallbackRenders::default();
        if fallback == Fallback::None {
            return Ok((renders, 0.0));
        }
        if self.fallback_gpu.is_none() {
            let spheres_cast = self.spheres_in_trace && self.capsule.is_some();
            self.fallback_gpu = Some(FallbackGpu::new(&self.ctx, &self.gpu_scene, &self.prepared, &self.spheres, spheres_cast)?);
        }
        let Some(fb) = self.fallback_gpu.as_mut() else { return Ok((renders, 0.0)) };
        fb.ensure_outputs(targets.width, targets.height);
        let mut needed: Vec<bool> = untraced.iter().map(|&u| u > 0).collect();
        let mut to_render = Vec::new();
        let mut probe_ms = 0.0;
        if needed.iter().any(|&x| x) {
            let start = Instant::now();
            // The see-through layer (planar refractive objects with untraced pixels; kept while
            // the view stays close to its own), before the probes: the objects that show in it
            // are shaded with their probes too.
            let see_through = fb.render_see_through(
                &self.ctx,
                &self.gpu_scene,
                &self.prepared,
                &self.raster,
                &self.lighting,
                &self.heuristic_passes,
                camera,
                (targets.width, targets.height),
                &needed,
            )?;
            renders.see_through = u64::from(see_through.is_some());
            for (need, &shown) in needed.iter_mut().zip(see_through.iter().flatten()) {
                *need |= shown;
            }
            // As the CPU: the spheres appear in the probes when they take part in the trace stage.
            let capsule = self.capsule.as_ref().filter(|_| self.spheres_in_trace).map(|c| (c, &self.spheres));
            renders.probes = fb.render_probes(&self.ctx, &self.gpu_scene, self.scene, &self.raster, &self.lighting, capsule, &needed);
            if renders.probes > 0 || see_through.is_some() {
                // The see-through layer and the probes' faces wrote their cameras into the frame
                // uniforms.
                self.gpu_scene.write_uniforms(&self.ctx, camera, targets.width, targets.height, &self.scene.environment);
            }
            probe_ms = start.elapsed().as_secs_f64() * 1e3;
            let aspect = targets.width as f32 / targets.height.max(1) as f32;
            to_render = fb.update_views(&self.ctx, self.scene, camera, aspect);
            renders.shadow_maps = to_render.len() as u64;
        }
        // As the CPU: the spheres cast into the maps when they take part in the trace stage.
        let splat = self.spheres_in_trace && self.capsule.is_some();
        fb.encode(enc, &self.gpu_scene, targets, &to_render, splat, &mut self.timer);
        self.fallback_written = true;
        Ok((renders, probe_ms))
    }

    /// The shadow maps the raster fallbacks used in the last frame that needed them, read back
    /// (empty before); waits for the GPU.
    pub fn shadow_maps(&self) -> Result<Vec<hybrid_core::fallback::LightShadowMaps>, GpuError> {
        self.fallback_gpu.as_ref().map_or(Ok(Vec::new()), |f| f.shadow_maps(&self.ctx))
    }

    /// Stage 3b's state (maps, probes, render counts), once a frame has needed it.
    pub fn fallback_gpu(&self) -> Option<&FallbackGpu> {
        self.fallback_gpu.as_ref()
    }
}

/// Validation and out-of-memory errors of the device, captured instead of wgpu's default panic.
///
/// Field order matters: a guard dropped without `pop` pops its scope, fields drop in declaration
/// order, and scopes must pop in reverse push order (validation, pushed last, first).
struct ErrorScope {
    validation: wgpu::ErrorScopeGuard,
    out_of_memory: wgpu::ErrorScopeGuard,
}

impl ErrorScope {
    fn push(device: &wgpu::Device) -> Self {
        let out_of_memory = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
        Self { out_of_memory, validation }
    }

    /// The first error captured since `push`, as a `GpuError` naming the adapter.
    fn pop(self, ctx: &GpuContext) -> Result<(), GpuError> {
        let validation = pollster::block_on(self.validation.pop());
        let out_of_memory = pollster::block_on(self.out_of_memory.pop());
        match (out_of_memory, validation) {
            (Some(e), _) => Err(GpuError::TooLarge { adapter: ctx.summary.name.clone(), why: e.to_string() }),
            (None, Some(e)) => Err(GpuError::Unsupported { adapter: ctx.summary.name.clone(), why: e.to_string() }),
            (None, None) => Ok(()),
        }
    }
}

/// The trace stage with the point-cloud spheres, or without them (`spheres_in_trace` off, on
/// scenes that have them).
fn chosen_trace<'t>(with_spheres: &'t TracePasses, without: &'t Option<TracePasses>, spheres_in_trace: bool) -> &'t TracePasses {
    match without {
        Some(t) if !spheres_in_trace => t,
        _ => with_spheres,
    }
}

/// Raster mode traces nothing: shadow 1 (nothing blocked), reflection and refraction 0, as the
/// CPU backend's buffers.
fn clear_trace_outputs(enc: &mut wgpu::CommandEncoder, targets: &FrameTargets) {
    let attach = |view, c: f64| {
        Some(wgpu::RenderPassColorAttachment {
            view,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations { load: wgpu::LoadOp::Clear(wgpu::Color { r: c, g: c, b: c, a: 1.0 }), store: wgpu::StoreOp::Store },
        })
    };
    let _pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some("trace: nothing traced"),
        color_attachments: &[
            attach(&targets.shadow.view, 1.0),
            attach(&targets.reflection.view, 0.0),
            attach(&targets.refraction.view, 0.0),
        ],
        ..Default::default()
    });
}
