//! `hybrid render`: one frame of a scene to a PNG, with optional buffer dump and JSON report.

use std::time::{Duration, Instant};

use hybrid_core::{FrameSettings, Mode};
use hybrid_cpu::frame::CpuRenderer;
use hybrid_scene::{Scene, demo_scene, load_scene};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use crate::CliError;
use crate::args::{BackendChoice, RenderArgs};
use crate::dump::{DumpInput, write_all};
use crate::output::{ensure_dir, ensure_parent, write_bytes, write_png_rgba8};

/// Renders longer than this show a progress bar (unless `--quiet`).
const PROGRESS_AFTER: Duration = Duration::from_secs(1);

pub fn run(args: RenderArgs) -> Result<(), CliError> {
    // Check every output location before doing any work, so bad flags fail fast and nothing
    // is half-written.
    ensure_parent(&args.output)?;
    if let Some(r) = &args.report {
        ensure_parent(r)?;
    }
    if let Some(d) = &args.dump {
        ensure_dir(d)?;
    }
    if let Some(n) = args.threads {
        if n == 0 {
            return Err(CliError::bad_input("--threads must be at least 1"));
        }
        rayon::ThreadPoolBuilder::new().num_threads(n).build_global().map_err(|e| CliError::failure(e.to_string()))?;
    }
    args.heuristic.check()?;
    match args.backend {
        BackendChoice::Cpu => {}
        BackendChoice::Auto => {
            if !args.quiet {
                eprintln!("backend: cpu (auto: this build has no GPU backend)");
            }
        }
        BackendChoice::Gpu => {
            return Err(CliError::bad_input("--backend gpu: this build has no GPU backend yet; use --backend cpu"));
        }
    }

    let mut scene: Scene = match &args.scene {
        Some(path) => load_scene(path)?,
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
            path.camera_at(&scene.camera, t)
        }
    };
    let (width, height) = args.size;
    let settings = FrameSettings { width, height, mode: args.mode };

    let start = Instant::now();
    let progress = Progress::new(args.quiet, start);
    progress.stage("prepare");
    let mut renderer = CpuRenderer::new(&scene).map_err(|e| {
        let file = args.scene.as_ref().map_or("demo scene".to_string(), |p| p.display().to_string());
        CliError::bad_input(format!("{file}: {e}"))
    })?;
    renderer.clip_capsule_at_raster_depth = args.clip_capsule;
    renderer.spheres_in_trace = !args.no_sphere_effects;
    let frame = renderer.render(&camera, settings, &mut |stage| progress.stage(stage));
    progress.finish();

    write_png_rgba8(&args.output, width, height, &frame.buffers.final_srgb)?;
    if let Some(dir) = &args.dump {
        write_all(dir, &DumpInput { gbuffer: &frame.gbuffer, buffers: &frame.buffers, rt_packed: frame.rt_packed.as_ref() })?;
    }
    if let Some(path) = &args.report {
        let json = serde_json::to_vec_pretty(&frame.report).map_err(|e| CliError::failure(e.to_string()))?;
        write_bytes(path, &json)?;
    }
    if !args.quiet {
        let t = &frame.report.timings_ms;
        eprintln!(
            "{}: {}x{} {} in {:.1} ms (raster {:.1}, heuristic {:.2}, trace {:.1}, blend {:.1}) → {}",
            args.scene.as_ref().map_or("demo".to_string(), |p| p.display().to_string()),
            width,
            height,
            if settings.mode == Mode::Hybrid { "hybrid" } else { settings.mode.name() },
            t.frame,
            t.raster,
            t.heuristic,
            t.trace,
            t.blend,
            args.output.display()
        );
    }
    Ok(())
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
