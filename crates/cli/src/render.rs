//! `hybrid render`: one frame of a scene to a PNG, with optional buffer dump and JSON report.

use std::sync::Arc;
use std::time::{Duration, Instant};

use hybrid_core::memory;
use hybrid_core::{Frame, FrameSettings, Mode, Stage};
use hybrid_cpu::frame::CpuRenderer;
use hybrid_gpu::frame::GpuRenderer;
use hybrid_gpu::{AdapterChoice, GpuContext, GpuError, RtChoice};
use hybrid_scene::{
    Camera, DEMO_SCENE_TOML, InputKind, MemoryLimit, Scene, demo_scene, input_kind, load_scene_or_model_within, model_scene_toml,
};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use crate::CliError;
use crate::args::{BackendChoice, CapsuleArgs, CapsuleVisibilityChoice, RenderArgs};
use crate::dump::{DumpInput, write_all, write_shadow_maps};
use crate::output::{OutputDir, check_output_file, write_bytes, write_png_rgba8};

/// Renders longer than this show a progress bar (unless `--quiet`).
const PROGRESS_AFTER: Duration = Duration::from_secs(1);

pub fn run(args: RenderArgs) -> Result<(), CliError> {
    // Check every output location before doing any work, so bad flags fail fast and nothing
    // is half-written.
    check_output_file(&args.output, "-o", &["png"])?;
    if let Some(r) = &args.report {
        check_output_file(r, "--report", &["json"])?;
    }
    let dump_dir = args.dump.as_deref().map(|d| OutputDir::prepare(d, "--dump")).transpose()?;
    crate::args::use_threads(args.threads)?;
    args.heuristic.check()?;
    // Memory: a size that cannot fit whatever the scene is refused before the scene is loaded;
    // the scene's data is checked as it is built, the whole render once the backend is known.
    let limit = memory_limit(args.max_memory);
    let extra_per_pixel = if args.dump.is_some() { memory::DUMP_BYTES_PER_PIXEL } else { 0 };
    memory::frame_only(args.size.0, args.size.1, extra_per_pixel).check(&limit).map_err(CliError::bad_input)?;
    let mut scene: Scene = match &args.scene {
        Some(path) => load_scene_or_model_within(path, &limit)?,
        None => demo_scene(),
    };
    args.heuristic.apply(&mut scene.heuristic);
    let camera = match args.time {
        None => scene.camera,
        Some(t) => {
            if !t.is_finite() {
                return Err(CliError::bad_input(format!("--time must be a finite number of seconds, got {t}")));
            }
            let name = args.scene.as_ref().map_or("the demo scene".to_string(), |p| p.display().to_string());
            let path = scene.camera_path.as_ref().ok_or_else(|| CliError::bad_input(format!("--time {t}: {name} has no [camera_path]")))?;
            if let (Some(first), Some(last)) = (path.keyframes.first(), path.keyframes.last()) {
                let clamped = t.clamp(first.time, last.time);
                if clamped != t {
                    let side = if t > last.time { "past the end" } else { "before the start" };
                    eprintln!(
                        "warning: --time {t} is {side} of the camera path ({} s to {} s); rendering at {clamped} s",
                        first.time, last.time
                    );
                }
            }
            path.camera_at(&scene.camera, t)
        }
    };
    let (width, height) = args.size;
    let settings = FrameSettings { width, height, mode: args.mode };

    let start = Instant::now();
    let backend = choose_backend(args.backend, args.quiet)?;
    let backend = match check_memory(&scene, &backend, args.size, extra_per_pixel, &limit) {
        // `--backend auto`: what does not fit beside the GPU backend may fit the CPU backend.
        Err(e) if matches!(args.backend, BackendChoice::Auto) && matches!(backend, Backend::Gpu(_)) => {
            check_memory(&scene, &Backend::Cpu, args.size, extra_per_pixel, &limit)?;
            if !args.quiet {
                eprintln!("backend: cpu (auto: {})", e.message);
            }
            Backend::Cpu
        }
        other => other.map(|()| backend)?,
    };
    if let Some(out) = &args.save_scene {
        save_scene(args.scene.as_deref(), out)?;
    }
    let progress = Progress::new(args.quiet, start);
    progress.stage("prepare");
    let file = args.scene.as_ref().map_or("demo scene".to_string(), |p| p.display().to_string());
    let options = RenderOptions::from(&args.capsule);
    if let Some(line) = check_rt(&backend, options.rt)?
        && !args.quiet
    {
        eprintln!("{line}");
    }
    let mut renderer = match AnyRenderer::new(&backend, &scene, &file, options) {
        // `--backend auto`: a GPU that refuses the scene (too large, out of memory) is not the
        // end: the CPU backend renders it, saying so.
        Err(e) if matches!(args.backend, BackendChoice::Auto) && matches!(backend, Backend::Gpu(_)) => {
            if !args.quiet {
                eprintln!("backend: cpu (auto: the GPU refused the scene: {})", e.message);
            }
            check_memory(&scene, &Backend::Cpu, args.size, extra_per_pixel, &limit)?;
            AnyRenderer::new(&Backend::Cpu, &scene, &file, options)?
        }
        other => other?,
    };
    let frame = renderer.render(&camera, settings, &mut |stage| progress.stage(stage_label(stage, settings.mode)))?;
    progress.finish();

    write_png_rgba8(&args.output, width, height, &frame.buffers.final_srgb)?;
    if let Some(dir) = &args.dump {
        write_all(dir, &DumpInput { gbuffer: &frame.gbuffer, buffers: &frame.buffers, rt_packed: frame.rt_packed.as_ref() })?;
        write_shadow_maps(dir, &renderer.shadow_maps()?)?;
    }
    if let Some(path) = &args.report {
        let json = serde_json::to_vec_pretty(&report_json(&frame.report)?).map_err(|e| CliError::failure(e.to_string()))?;
        write_bytes(path, &json)?;
    }
    if let Some(d) = dump_dir {
        d.keep();
    }
    if !args.quiet {
        let t = &frame.report.timings_ms;
        eprintln!(
            "{}: {}x{} {} in {:.1} ms ({} {:.1}, heuristic {:.2}, trace {:.1}, blend {:.1}) → {}{}",
            args.scene.as_ref().map_or("demo".to_string(), |p| p.display().to_string()),
            width,
            height,
            if settings.mode == Mode::Hybrid { "hybrid" } else { settings.mode.name() },
            t.frame,
            stage_label(Stage::Raster, settings.mode),
            t.raster,
            t.heuristic,
            t.trace,
            t.blend,
            args.output.display(),
            cpu_isa(&frame.report).map_or(String::new(), |isa| format!(" [cpu kernels: {isa}]"))
        );
    }
    Ok(())
}

/// The CPU kernels' instruction-set path, for a frame the CPU backend rendered.
fn cpu_isa(report: &hybrid_core::report::FrameReport) -> Option<&'static str> {
    (report.backend == "cpu").then(|| hybrid_cpu::isa::active().name())
}

/// `--report`'s JSON: the frame report, plus `cpu_isa` (the CPU kernels' instruction-set path,
/// `hybrid_cpu::isa`) when the CPU backend rendered it.
fn report_json(report: &hybrid_core::report::FrameReport) -> Result<serde_json::Value, CliError> {
    let mut json = serde_json::to_value(report).map_err(|e| CliError::failure(e.to_string()))?;
    if let (Some(isa), Some(map)) = (cpu_isa(report), json.as_object_mut()) {
        map.insert("cpu_isa".into(), isa.into());
    }
    Ok(json)
}

/// A stage's name for people: stage 1 is `primary rays` in `rt-only`, which has no raster (its
/// time is still reported under the `raster` key of `--report` and of `hybrid bench`'s files).
pub fn stage_label(stage: Stage, mode: Mode) -> &'static str {
    match (stage, mode) {
        (Stage::Raster, Mode::RtOnly) => "primary rays",
        _ => stage.name(),
    }
}

/// `--max-memory`, or the machine's default limit.
pub fn memory_limit(flag: Option<u64>) -> MemoryLimit {
    flag.map_or_else(MemoryLimit::machine_default, MemoryLimit::explicit)
}

/// Refuses (exit 2) rendering `scene` at `size` on `backend` when the estimate
/// (`hybrid_core::memory::estimate`, with `extra_per_pixel` beyond the frame) is above `limit`.
pub fn check_memory(scene: &Scene, backend: &Backend, size: (u32, u32), extra_per_pixel: u64, limit: &MemoryLimit) -> Result<(), CliError> {
    let kind = match backend {
        Backend::Cpu => memory::Backend::Cpu,
        Backend::Gpu(_) => memory::Backend::Gpu,
    };
    memory::estimate(scene, kind, size.0, size.1, extra_per_pixel).check(limit).map_err(CliError::bad_input)
}

/// Beyond-the-paper switches both backends take.
#[derive(Debug, Clone, Copy)]
pub struct RenderOptions {
    /// `--clip-capsule`.
    pub clip_capsule: bool,
    /// Not `--no-sphere-effects`.
    pub sphere_effects: bool,
    /// `--capsule-visibility` (CPU backend).
    pub capsule_visibility: CapsuleVisibilityChoice,
    /// `--rt` (GPU backend).
    pub rt: RtChoice,
    /// `--fallback`.
    pub fallback: hybrid_core::fallback::Fallback,
}

impl From<&CapsuleArgs> for RenderOptions {
    fn from(a: &CapsuleArgs) -> Self {
        Self {
            clip_capsule: a.clip_capsule,
            sphere_effects: !a.no_sphere_effects,
            capsule_visibility: a.capsule_visibility,
            rt: a.rt.choice(),
            fallback: a.fallback.fallback(),
        }
    }
}

/// A renderer on either backend, for commands that render frames (`render`, `bench`).
pub enum AnyRenderer<'s> {
    Cpu(Box<CpuRenderer<'s>>),
    Gpu(Box<GpuRenderer<'s>>),
}

impl<'s> AnyRenderer<'s> {
    /// Prepares `scene` (named `file` in errors) on `backend`.
    pub fn new(backend: &Backend, scene: &'s Scene, file: &str, options: RenderOptions) -> Result<Self, CliError> {
        Ok(match backend {
            Backend::Cpu => {
                let mut r = CpuRenderer::new(scene).map_err(|e| CliError::bad_input(format!("{file}: {e}")))?;
                r.clip_capsule_at_raster_depth = options.clip_capsule;
                r.spheres_in_trace = options.sphere_effects;
                r.fallback = options.fallback;
                r.set_capsule_visibility(options.capsule_visibility.primary_visibility());
                AnyRenderer::Cpu(Box::new(r))
            }
            Backend::Gpu(ctx) => {
                let mut r =
                    GpuRenderer::with_rt(ctx.clone(), scene, options.rt).map_err(|e| CliError::bad_input(format!("{file}: {e}")))?;
                r.clip_capsule_at_raster_depth = options.clip_capsule;
                r.spheres_in_trace = options.sphere_effects;
                r.fallback = options.fallback;
                AnyRenderer::Gpu(Box::new(r))
            }
        })
    }

    /// The shadow maps the raster fallbacks used in the last frame (for `--dump`).
    pub fn shadow_maps(&self) -> Result<Vec<hybrid_core::fallback::LightShadowMaps>, CliError> {
        match self {
            AnyRenderer::Cpu(r) => Ok(r.fallback_cache().map(|c| c.shadow_maps().iter().flatten().cloned().collect()).unwrap_or_default()),
            AnyRenderer::Gpu(r) => r.shadow_maps().map_err(|e| CliError::bad_input(format!("--backend gpu: {e}"))),
        }
    }

    pub fn render(&mut self, camera: &Camera, settings: FrameSettings, on_stage: &mut dyn FnMut(Stage)) -> Result<Frame, CliError> {
        match self {
            AnyRenderer::Cpu(r) => Ok(r.render(camera, settings, on_stage)),
            // Out of memory, too large, device lost: the scene/size does not fit this GPU (exit 2).
            AnyRenderer::Gpu(r) => r.render(camera, settings, on_stage).map_err(|e| CliError::bad_input(format!("--backend gpu: {e}"))),
        }
    }

    /// Hands a finished frame back for reuse (CPU: its G-buffer memory).
    pub fn recycle(&mut self, frame: Frame) {
        if let AnyRenderer::Cpu(r) = self {
            r.recycle(frame);
        }
    }
}

/// `--rt` against the backend: `hw` needs the GPU backend on an adapter with ray queries (else
/// exit 2, naming the flag). Returns the line saying which traversal traces (GPU backend).
pub fn check_rt(backend: &Backend, rt: RtChoice) -> Result<Option<String>, CliError> {
    match backend {
        Backend::Cpu if rt == RtChoice::Hardware => {
            Err(CliError::bad_input("--rt hw: the CPU backend has no hardware ray tracing (use --backend gpu, or --rt auto|sw)"))
        }
        Backend::Cpu => Ok(None),
        Backend::Gpu(ctx) => {
            let path = rt.resolve(ctx).map_err(|e| CliError::bad_input(format!("--rt hw: {e}")))?;
            let how =
                if path.hardware { "hardware (ray queries over acceleration structures)" } else { "software (BVH2 traversal in WGSL)" };
            let auto = if rt == RtChoice::Auto { "auto: " } else { "" };
            Ok(Some(format!("ray tracing: {how} ({auto}{})", path.why)))
        }
    }
}

/// The backend a command runs on.
pub enum Backend {
    Cpu,
    Gpu(Arc<GpuContext>),
}

/// `--backend`: `cpu`; `gpu` (any wgpu adapter, software ones such as lavapipe included; none is
/// an error, exit 2); `auto` (a hardware GPU when one exists, else the CPU). Says which it chose
/// unless `quiet`.
pub fn choose_backend(choice: BackendChoice, quiet: bool) -> Result<Backend, CliError> {
    let say = |what: String| {
        if !quiet {
            eprintln!("{what}");
        }
    };
    match choice {
        BackendChoice::Cpu => Ok(Backend::Cpu),
        BackendChoice::Gpu => {
            let ctx = GpuContext::new(AdapterChoice::Any).map_err(|e| CliError::bad_input(format!("--backend gpu: {e}")))?;
            say(format!("backend: gpu ({}, {})", ctx.summary.name, ctx.summary.backend));
            Ok(Backend::Gpu(Arc::new(ctx)))
        }
        BackendChoice::Auto => match GpuContext::new(AdapterChoice::HardwareOnly) {
            Ok(ctx) => {
                say(format!("backend: gpu (auto: hardware adapter {}, {})", ctx.summary.name, ctx.summary.backend));
                Ok(Backend::Gpu(Arc::new(ctx)))
            }
            Err(e) => {
                say(format!("backend: cpu (auto: {})", no_hardware_reason(&e)));
                Ok(Backend::Cpu)
            }
        },
    }
}

fn no_hardware_reason(e: &GpuError) -> String {
    match e {
        GpuError::NoAdapter => "no hardware GPU adapter".into(),
        other => format!("no usable hardware GPU: {other}"),
    }
}

/// A progress bar that only appears once a render has taken longer than a second.
struct Progress {
    bar: ProgressBar,
}

impl Progress {
    fn new(quiet: bool, start: Instant) -> Self {
        let bar = ProgressBar::with_draw_target(Some(6), ProgressDrawTarget::hidden());
        if let Ok(style) = ProgressStyle::with_template("{spinner} [{elapsed}] {bar:20} {msg}") {
            bar.set_style(style);
        }
        if !quiet {
            // Show the bar only if the render is still going after PROGRESS_AFTER.
            let late = bar.clone();
            std::thread::spawn(move || {
                std::thread::sleep(PROGRESS_AFTER.saturating_sub(start.elapsed()));
                if !late.is_finished() {
                    late.set_draw_target(ProgressDrawTarget::stderr());
                    late.enable_steady_tick(Duration::from_millis(100));
                }
            });
        }
        Self { bar }
    }
    fn stage(&self, name: &str) {
        self.bar.set_message(name.to_string());
        self.bar.inc(1);
    }
    fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

/// `--save-scene`: writes the default scene of a model file (or the built-in demo scene) as TOML,
/// with the model's path relative to `out`. A scene file is already editable, so it is refused.
fn save_scene(input: Option<&std::path::Path>, out: &std::path::Path) -> Result<(), CliError> {
    let text = match input {
        None => DEMO_SCENE_TOML.to_string(),
        Some(path) => {
            if input_kind(path)? == InputKind::Scene {
                return Err(CliError::bad_input(format!(
                    "--save-scene: {} is already a scene file; copy it to edit it (--save-scene writes the default scene of a model file)",
                    path.display()
                )));
            }
            model_scene_toml(path, out)?
        }
    };
    if out.extension().and_then(|e| e.to_str()).is_none_or(|e| !e.eq_ignore_ascii_case("toml")) {
        return Err(CliError::bad_input(format!("--save-scene {}: the file name must end in .toml", out.display())));
    }
    std::fs::write(out, text).map_err(|e| CliError::bad_input(format!("--save-scene {}: cannot write: {e}", out.display())))
}
