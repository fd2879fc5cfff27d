//! `hybrid bench`: the paper's two sets of tests (Walewski et al. 2019, §4–5) on one scene, with
//! image quality.
//!
//! - **Static set** (Table 5): `--frames` frames after 2 warm-up frames at the scene's camera, for
//!   every mode of `--modes`: mean and p95 of every stage and of the frame.
//! - **Path set** (Table 6): the scene's camera path sampled at `--fps` frames per second of path
//!   time for `--path-seconds` seconds, every frame rendered as fast as possible, for every mode
//!   of `--modes` but `rt-only`. `rt-only` is rendered on every `--flip-every`-th path frame as the
//!   reference of the mean FLIP error (and timed there). Selection churn: per frame, the number of
//!   visible objects whose selection differs from the previous frame's (the heuristic's S).
//! - **Budget sweep** (`--sweep-budget`): the path (or the static camera when the scene has no
//!   path) at fractions of the all-selected cost, for both policies: FLIP against frame time.
//!
//! Every renderer is built fresh for each pass, so the heuristic's state (S, ms per cost) of one
//! pass never leaks into another. Each pass starts with 2 warm-up frames at its first camera.

mod plot;

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use hybrid_core::report::{FrameReport, StageTimings};
use hybrid_core::{FrameSettings, Mode};
use hybrid_scene::{Budget, Camera, Policy, Scene, load_scene_or_model};
use serde::Serialize;
use serde_json::json;

use self::plot::{Chart, HLine, Series, write_chart};
use crate::CliError;
use crate::args::BenchArgs;
use crate::output::{ensure_dir, write_bytes};
use crate::render::{AnyRenderer, Backend, RenderOptions, choose_backend};

/// Warm-up frames rendered (and discarded) at the start of every pass.
pub const WARMUP_FRAMES: usize = 2;
/// Path seconds rendered when `--path-seconds` is not given (the paper's traversal), or the whole
/// path when it is shorter.
pub const DEFAULT_PATH_SECONDS: f32 = 20.0;
/// Budget sweep: fractions of the mean all-selected cost.
pub const SWEEP_FRACTIONS: [f64; 5] = [0.1, 0.25, 0.5, 0.75, 1.0];
/// A millisecond budget is "hit" when the trace stage lands within this fraction of the target.
pub const BUDGET_TOLERANCE: f64 = 0.1;

/// One camera of a pass: where it is and, on a path, at what path time.
#[derive(Clone, Copy)]
struct Shot {
    time: Option<f32>,
    camera: Camera,
}

/// One measured frame.
#[derive(Debug, Clone, Serialize)]
struct FrameRecord {
    set: &'static str,
    mode: Mode,
    /// Index along the pass (path frame index for the path set).
    frame: usize,
    time_s: Option<f32>,
    timings: StageTimings,
    spent: Option<f64>,
    budget: Option<f64>,
    budget_ms: Option<f64>,
    /// Sum of C over the visible objects: the cost of selecting everything.
    all_cost: Option<f64>,
    visible: Option<usize>,
    selected: Option<usize>,
    churn: Option<usize>,
    flip: Option<f32>,
}

impl FrameRecord {
    fn new(set: &'static str, frame: usize, shot: &Shot, report: &FrameReport) -> Self {
        let h = report.heuristic.as_ref();
        Self {
            set,
            mode: report.mode,
            frame,
            time_s: shot.time,
            timings: report.timings_ms,
            spent: h.map(|h| h.spent),
            budget: h.and_then(|h| h.budget),
            budget_ms: h.and_then(|h| h.budget_ms),
            all_cost: h.map(|h| h.objects.iter().map(|o| o.c).sum()),
            visible: h.map(|h| h.objects.len()),
            selected: h.map(|h| h.objects.iter().filter(|o| o.selected).count()),
            churn: h.map(|h| h.objects.iter().filter(|o| o.s != o.selected).count()),
            flip: None,
        }
    }
}

/// Mean and 95th percentile (nearest rank) of a sample.
#[derive(Debug, Clone, Copy, Default, Serialize, PartialEq)]
struct Stat {
    mean: f64,
    p95: f64,
}

fn stat(values: &[f64]) -> Stat {
    if values.is_empty() {
        return Stat::default();
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let rank = ((0.95 * v.len() as f64).ceil() as usize).clamp(1, v.len());
    Stat { mean: v.iter().sum::<f64>() / v.len() as f64, p95: v[rank - 1] }
}

fn mean(values: impl Iterator<Item = f64>) -> Option<f64> {
    let (sum, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    (n > 0).then(|| sum / n as f64)
}

/// Mean and p95 of every stage over some frames.
#[derive(Debug, Clone, Copy, Default, Serialize)]
struct StageStats {
    capsule: Stat,
    raster: Stat,
    heuristic: Stat,
    trace: Stat,
    blend: Stat,
    frame: Stat,
}

fn stage_stats(records: &[&FrameRecord]) -> StageStats {
    let s = |f: fn(&StageTimings) -> f64| stat(&records.iter().map(|r| f(&r.timings)).collect::<Vec<_>>());
    StageStats {
        capsule: s(|t| t.capsule),
        raster: s(|t| t.raster),
        heuristic: s(|t| t.heuristic),
        trace: s(|t| t.trace),
        blend: s(|t| t.blend),
        frame: s(|t| t.frame),
    }
}

/// What one pass produced: its records and the RGB images of the frames asked for.
struct Pass {
    records: Vec<FrameRecord>,
    images: BTreeMap<usize, Vec<u8>>,
}

struct Bench {
    scene_name: String,
    size: (u32, u32),
    quiet: bool,
    backend: Backend,
    options: RenderOptions,
}

impl Bench {
    /// Renders `shots` in `mode` with a fresh renderer (after the warm-up), keeping the images of
    /// the frames for which `keep` is true.
    fn pass(&self, scene: &Scene, set: &'static str, mode: Mode, shots: &[Shot], keep: &dyn Fn(usize) -> bool) -> Result<Pass, CliError> {
        if !self.quiet && set == "sweep" {
            let policy = policy_name(scene.heuristic.policy);
            eprint!("  budget {:?}, policy {policy}:", scene.heuristic.budget);
        }
        let (width, height) = self.size;
        let settings = FrameSettings { width, height, mode };
        let mut renderer = AnyRenderer::new(&self.backend, scene, &self.scene_name, self.options)?;
        if let Some(first) = shots.first() {
            for _ in 0..WARMUP_FRAMES {
                let frame = renderer.render(&first.camera, settings, &mut |_| {})?;
                renderer.recycle(frame);
            }
        }
        let mut records = Vec::with_capacity(shots.len());
        let mut images = BTreeMap::new();
        for (i, shot) in shots.iter().enumerate() {
            let frame = renderer.render(&shot.camera, settings, &mut |_| {})?;
            records.push(FrameRecord::new(set, i, shot, &frame.report));
            if keep(i) {
                images.insert(i, frame.buffers.final_srgb.iter().flat_map(|p| [p[0], p[1], p[2]]).collect());
            }
            renderer.recycle(frame);
        }
        if !self.quiet {
            let m = mean(records.iter().map(|r| r.timings.frame)).unwrap_or(0.0);
            eprintln!("  {set} {mode}: {} frames, mean {m:.1} ms", records.len());
        }
        Ok(Pass { records, images })
    }

    fn flip(&self, reference: &[u8], test: &[u8]) -> f32 {
        let (w, h) = self.size;
        let a = nv_flip::FlipImageRgb8::with_data(w, h, reference);
        let b = nv_flip::FlipImageRgb8::with_data(w, h, test);
        let err = nv_flip::flip(a, b, nv_flip::DEFAULT_PIXELS_PER_DEGREE);
        nv_flip::FlipPool::from_image(&err).mean()
    }

    /// Fills in `flip` of every record that has an image and a reference image.
    fn add_flip(&self, pass: &mut Pass, reference: &BTreeMap<usize, Vec<u8>>) {
        for (i, img) in &pass.images {
            if let Some(r) = reference.get(i) {
                pass.records[*i].flip = Some(self.flip(r, img));
            }
        }
    }
}

/// The checked plan of a bench run: everything is validated before anything is rendered or written.
struct Plan {
    path_shots: Option<Vec<Shot>>,
    path_seconds: Option<f32>,
}

fn check_args(args: &BenchArgs) -> Result<(), CliError> {
    if !(args.fps.is_finite() && args.fps > 0.0 && args.fps <= 1000.0) {
        return Err(CliError::bad_input(format!("--fps must be a number of frames per second in (0, 1000], got {}", args.fps)));
    }
    if let Some(s) = args.path_seconds
        && !(s.is_finite() && s > 0.0)
    {
        return Err(CliError::bad_input(format!("--path-seconds must be a positive number of seconds, got {s}")));
    }
    if args.modes.is_empty() {
        return Err(CliError::bad_input("--modes needs at least one mode (hybrid, all, rt-only, raster)"));
    }
    args.heuristic.check()?;
    if args.threads == Some(0) {
        return Err(CliError::bad_input("--threads must be at least 1"));
    }
    if args.sweep_budget && !args.modes.iter().any(|m| matches!(m, Mode::Hybrid | Mode::All)) {
        return Err(CliError::bad_input("--sweep-budget needs `hybrid` or `all` in --modes (for the all-selected cost)"));
    }
    Ok(())
}

fn plan(args: &BenchArgs, scene: &Scene, name: &str) -> Result<Plan, CliError> {
    let Some(path) = scene.camera_path.as_ref() else {
        if let Some(s) = args.path_seconds {
            return Err(CliError::bad_input(format!("--path-seconds {s}: {name} has no [camera_path]")));
        }
        return Ok(Plan { path_shots: None, path_seconds: None });
    };
    let duration = path.duration();
    let seconds = match args.path_seconds {
        Some(s) if s > duration + 1e-3 => {
            return Err(CliError::bad_input(format!("--path-seconds {s}: the camera path of {name} is only {duration} s long")));
        }
        Some(s) => s,
        None => DEFAULT_PATH_SECONDS.min(duration),
    };
    let start = path.keyframes.first().map_or(0.0, |k| k.time);
    let count = ((seconds * args.fps).round() as usize).max(1);
    let shots = (0..count)
        .map(|i| {
            let t = start + i as f32 / args.fps;
            Shot { time: Some(t), camera: path.camera_at(&scene.camera, t) }
        })
        .collect();
    Ok(Plan { path_shots: Some(shots), path_seconds: Some(seconds) })
}

/// The machine the numbers were taken on.
#[derive(Debug, Serialize)]
struct Machine {
    /// "cpu", or "gpu (adapter name, API)".
    backend: String,
    cores: usize,
    threads: usize,
    cpu_model: Option<String>,
    load_average_start: Option<[f64; 3]>,
    load_average_end: Option<[f64; 3]>,
    /// `git rev-parse HEAD` of the scene's repository when the bench ran (the binary may have been
    /// built from another tree: record the build commit separately when it matters).
    git_head: Option<String>,
}

fn cpu_model() -> Option<String> {
    let info = std::fs::read_to_string("/proc/cpuinfo").ok()?;
    info.lines().find(|l| l.starts_with("model name")).and_then(|l| l.split_once(':')).map(|(_, v)| v.trim().to_string())
}

fn load_average() -> Option<[f64; 3]> {
    let s = std::fs::read_to_string("/proc/loadavg").ok()?;
    let mut it = s.split_whitespace().map(|v| v.parse::<f64>().ok());
    Some([it.next()??, it.next()??, it.next()??])
}

fn git_commit(dir: &Path) -> Option<String> {
    let out = std::process::Command::new("git").arg("-C").arg(dir).args(["rev-parse", "HEAD"]).output().ok()?;
    out.status.success().then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

/// Summary of the static set for one mode.
#[derive(Debug, Serialize)]
struct StaticSummary {
    frames: usize,
    stages: StageStats,
    /// FLIP of the last frame against rt-only's last frame.
    flip_vs_rt_only: Option<f32>,
}

/// Summary of the path set for one mode.
#[derive(Debug, Serialize)]
struct PathSummary {
    frames: usize,
    stages: StageStats,
    mean_flip: Option<f64>,
    flip_frames: usize,
    mean_churn: Option<f64>,
    max_churn: Option<usize>,
    mean_spent: Option<f64>,
    mean_all_cost: Option<f64>,
    /// Millisecond budget only: share of frames whose trace stage is within ±10% of the target
    /// (or below it when every visible object was selected, so the budget did not bind).
    budget_hit_rate: Option<f64>,
    /// Millisecond budget only: share of frames whose trace stage exceeds the target by > 10%.
    budget_over_rate: Option<f64>,
}

fn path_summary(records: &[&FrameRecord]) -> PathSummary {
    let flips: Vec<f64> = records.iter().filter_map(|r| r.flip.map(f64::from)).collect();
    let churn: Vec<usize> = records.iter().filter_map(|r| r.churn).collect();
    let ms: Vec<(f64, f64, bool)> =
        records.iter().filter_map(|r| r.budget_ms.map(|b| (b, r.timings.trace, r.selected.is_some() && r.selected == r.visible))).collect();
    let hit = |&&(b, t, all): &&(f64, f64, bool)| t <= b * (1.0 + BUDGET_TOLERANCE) && (t >= b * (1.0 - BUDGET_TOLERANCE) || all);
    let over = |&&(b, t, _): &&(f64, f64, bool)| t > b * (1.0 + BUDGET_TOLERANCE);
    PathSummary {
        frames: records.len(),
        stages: stage_stats(records),
        mean_flip: mean(flips.iter().copied()),
        flip_frames: flips.len(),
        mean_churn: mean(churn.iter().map(|&c| c as f64)),
        max_churn: churn.iter().copied().max(),
        mean_spent: mean(records.iter().filter_map(|r| r.spent)),
        mean_all_cost: mean(records.iter().filter_map(|r| r.all_cost)),
        budget_hit_rate: (!ms.is_empty()).then(|| ms.iter().filter(hit).count() as f64 / ms.len() as f64),
        budget_over_rate: (!ms.is_empty()).then(|| ms.iter().filter(over).count() as f64 / ms.len() as f64),
    }
}

/// One point of the budget sweep.
#[derive(Debug, Serialize)]
struct SweepPoint {
    policy: &'static str,
    fraction: f64,
    budget: f64,
    frames: usize,
    mean_frame_ms: f64,
    p95_frame_ms: f64,
    mean_trace_ms: f64,
    mean_flip: Option<f64>,
    mean_churn: Option<f64>,
}

fn policy_name(p: Policy) -> &'static str {
    match p {
        Policy::Paper => "paper",
        Policy::Knapsack => "knapsack",
    }
}

pub fn run(args: BenchArgs) -> Result<(), CliError> {
    check_args(&args)?;
    let name = args.scene.display().to_string();
    let mut scene = load_scene_or_model(&args.scene)?;
    args.heuristic.apply(&mut scene.heuristic);
    let plan = plan(&args, &scene, &name)?;
    let backend = choose_backend(args.backend, args.quiet)?;
    let backend_name = match &backend {
        Backend::Cpu => "cpu".to_string(),
        Backend::Gpu(ctx) => format!("gpu ({}, {})", ctx.summary.name, ctx.summary.backend),
    };
    // Everything is checked: now the output folder (created and probed before any rendering).
    ensure_dir(&args.out)?;
    if let Some(n) = args.threads {
        rayon::ThreadPoolBuilder::new().num_threads(n).build_global().map_err(|e| CliError::failure(e.to_string()))?;
    }

    let machine_start = load_average();
    let options = RenderOptions::from(&args.capsule);
    let bench = Bench { scene_name: name.clone(), size: args.size, quiet: args.quiet, backend, options };
    let mut modes: Vec<Mode> = Vec::new();
    for m in &args.modes {
        if !modes.contains(m) {
            modes.push(*m);
        }
    }
    if !args.quiet {
        eprintln!(
            "bench {name}: {}x{}, {} static frames, modes {}",
            args.size.0,
            args.size.1,
            args.frames,
            modes.iter().map(|m| m.name()).collect::<Vec<_>>().join(",")
        );
    }

    // Static set: the scene's camera; FLIP of the last frame against rt-only's last frame.
    let static_shots = vec![Shot { time: None, camera: scene.camera }; args.frames as usize];
    let last = static_shots.len() - 1;
    let mut static_passes: Vec<(Mode, Pass)> = Vec::new();
    for &mode in &modes {
        static_passes.push((mode, bench.pass(&scene, "static", mode, &static_shots, &|i| i == last)?));
    }
    let static_reference = match static_passes.iter().find(|(m, _)| *m == Mode::RtOnly) {
        Some((_, p)) => p.images.clone(),
        None if args.sweep_budget && plan.path_shots.is_none() => {
            bench.pass(&scene, "static", Mode::RtOnly, &static_shots[..1], &|_| true)?.images.into_values().map(|v| (last, v)).collect()
        }
        None => BTreeMap::new(),
    };
    for (_, pass) in &mut static_passes {
        bench.add_flip(pass, &static_reference);
    }

    // Path set.
    let k = args.flip_every as usize;
    let mut path_passes: Vec<(Mode, Pass)> = Vec::new();
    let mut path_reference = BTreeMap::new();
    if let Some(shots) = &plan.path_shots {
        let flip_frames: Vec<Shot> = shots.iter().step_by(k).copied().collect();
        let mut reference = bench.pass(&scene, "path", Mode::RtOnly, &flip_frames, &|_| true)?;
        // Re-index the reference frames by their path frame index.
        for (j, r) in reference.records.iter_mut().enumerate() {
            r.frame = j * k;
        }
        path_reference = reference.images.iter().map(|(j, img)| (j * k, img.clone())).collect();
        reference.images.clear();
        for &mode in modes.iter().filter(|m| **m != Mode::RtOnly) {
            let mut pass = bench.pass(&scene, "path", mode, shots, &|i| i.is_multiple_of(k))?;
            bench.add_flip(&mut pass, &path_reference);
            pass.images.clear();
            path_passes.push((mode, pass));
        }
        if modes.contains(&Mode::RtOnly) {
            path_passes.push((Mode::RtOnly, reference));
        }
    }

    // Budget sweep.
    let mut sweep: Vec<SweepPoint> = Vec::new();
    if args.sweep_budget {
        let on_path = plan.path_shots.is_some();
        let shots: &[Shot] = plan.path_shots.as_deref().unwrap_or(&static_shots);
        let reference = if on_path { &path_reference } else { &static_reference };
        let set_passes = if on_path { &path_passes } else { &static_passes };
        let all_cost = set_passes
            .iter()
            .filter(|(m, _)| matches!(m, Mode::Hybrid | Mode::All))
            .find_map(|(_, p)| mean(p.records.iter().filter_map(|r| r.all_cost)))
            .unwrap_or(0.0);
        let keep_every = if plan.path_shots.is_some() { k } else { shots.len() };
        let original = scene.heuristic.clone();
        for policy in [Policy::Paper, Policy::Knapsack] {
            for fraction in SWEEP_FRACTIONS {
                let budget = fraction * all_cost;
                scene.heuristic.policy = policy;
                scene.heuristic.budget = Budget::Cost(budget);
                let keep = |i: usize| if keep_every == shots.len() { i == last } else { i.is_multiple_of(keep_every) };
                let mut pass = bench.pass(&scene, "sweep", Mode::Hybrid, shots, &keep)?;
                bench.add_flip(&mut pass, reference);
                let recs: Vec<&FrameRecord> = pass.records.iter().collect();
                let frame = stat(&recs.iter().map(|r| r.timings.frame).collect::<Vec<_>>());
                sweep.push(SweepPoint {
                    policy: policy_name(policy),
                    fraction,
                    budget,
                    frames: recs.len(),
                    mean_frame_ms: frame.mean,
                    p95_frame_ms: frame.p95,
                    mean_trace_ms: mean(recs.iter().map(|r| r.timings.trace)).unwrap_or(0.0),
                    mean_flip: mean(recs.iter().filter_map(|r| r.flip.map(f64::from))),
                    mean_churn: mean(recs.iter().filter_map(|r| r.churn.map(|c| c as f64))),
                });
            }
        }
        scene.heuristic = original;
    }

    // Summaries.
    let static_summary: BTreeMap<String, StaticSummary> = static_passes
        .iter()
        .map(|(m, p)| {
            let recs: Vec<&FrameRecord> = p.records.iter().collect();
            let flip_vs_rt_only = p.records.iter().find_map(|r| r.flip);
            (m.name().to_string(), StaticSummary { frames: recs.len(), stages: stage_stats(&recs), flip_vs_rt_only })
        })
        .collect();
    let path_summary: BTreeMap<String, PathSummary> =
        path_passes.iter().map(|(m, p)| (m.name().to_string(), path_summary(&p.records.iter().collect::<Vec<_>>()))).collect();
    let threads = rayon::current_num_threads();
    let machine = Machine {
        backend: backend_name,
        cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
        threads,
        cpu_model: cpu_model(),
        load_average_start: machine_start,
        load_average_end: load_average(),
        git_head: git_commit(args.scene.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."))),
    };
    let budget_desc = match scene.heuristic.budget {
        Budget::Unlimited => json!(null),
        Budget::Cost(c) => json!({ "cost": c }),
        Budget::Millis(ms) => json!({ "ms": ms }),
    };
    let report = json!({
        "scene": name,
        "size": [args.size.0, args.size.1],
        "settings": {
            "frames": args.frames,
            "warmup_frames": WARMUP_FRAMES,
            "path_seconds": plan.path_seconds,
            "fps": args.fps,
            "flip_every": args.flip_every,
            "modes": modes.iter().map(|m| m.name()).collect::<Vec<_>>(),
            "budget": budget_desc,
            "policy": policy_name(scene.heuristic.policy),
            "importance": scene.heuristic.importance,
            "clip_capsule": options.clip_capsule,
            "sphere_effects": options.sphere_effects,
            "capsule_visibility": options.capsule_visibility.name(),
        },
        "machine": machine,
        "static": static_summary,
        "path": path_summary,
        "sweep": if args.sweep_budget { json!(sweep) } else { json!(null) },
    });

    // Outputs (each written atomically).
    let out: &Path = &args.out;
    let json_bytes = serde_json::to_vec_pretty(&report).map_err(|e| CliError::failure(e.to_string()))?;
    write_bytes(&out.join("bench.json"), &json_bytes)?;
    let all_records = static_passes.iter().chain(&path_passes).flat_map(|(_, p)| &p.records);
    write_bytes(&out.join("frames.csv"), frames_csv(all_records).as_bytes())?;
    write_chart(&out.join("frame_times.png"), &frame_time_chart(&name, &static_passes, &path_passes, &scene))?;
    if args.sweep_budget {
        write_bytes(&out.join("sweep.csv"), sweep_csv(&sweep).as_bytes())?;
        write_chart(&out.join("sweep.png"), &sweep_chart(&name, &sweep))?;
    }
    print!(
        "{}",
        markdown(&name, &args, &machine, &static_summary, &path_summary, &sweep, scene.point_clouds.is_empty(), plan.path_seconds)
    );
    Ok(())
}

pub const FRAMES_CSV_HEADER: &str = "set,mode,frame,time_s,frame_ms,capsule_ms,raster_ms,heuristic_ms,trace_ms,blend_ms,spent,budget,budget_ms,all_cost,visible,selected,churn,flip";

fn opt<T: std::fmt::Display>(v: Option<T>) -> String {
    v.map_or(String::new(), |v| v.to_string())
}

fn frames_csv<'a>(records: impl Iterator<Item = &'a FrameRecord>) -> String {
    let mut s = String::from(FRAMES_CSV_HEADER);
    s.push('\n');
    for r in records {
        let t = &r.timings;
        let _ = writeln!(
            s,
            "{},{},{},{},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{},{},{},{},{},{},{},{}",
            r.set,
            r.mode,
            r.frame,
            opt(r.time_s),
            t.frame,
            t.capsule,
            t.raster,
            t.heuristic,
            t.trace,
            t.blend,
            opt(r.spent.map(|v| format!("{v:.1}"))),
            opt(r.budget.map(|v| format!("{v:.1}"))),
            opt(r.budget_ms),
            opt(r.all_cost.map(|v| format!("{v:.1}"))),
            opt(r.visible),
            opt(r.selected),
            opt(r.churn),
            opt(r.flip.map(|f| format!("{f:.5}")))
        );
    }
    s
}

pub const SWEEP_CSV_HEADER: &str = "policy,fraction,budget,frames,mean_frame_ms,p95_frame_ms,mean_trace_ms,mean_flip,mean_churn";

fn sweep_csv(points: &[SweepPoint]) -> String {
    let mut s = String::from(SWEEP_CSV_HEADER);
    s.push('\n');
    for p in points {
        let _ = writeln!(
            s,
            "{},{},{:.1},{},{:.3},{:.3},{:.3},{},{}",
            p.policy,
            p.fraction,
            p.budget,
            p.frames,
            p.mean_frame_ms,
            p.p95_frame_ms,
            p.mean_trace_ms,
            opt(p.mean_flip.map(|f| format!("{f:.5}"))),
            opt(p.mean_churn.map(|c| format!("{c:.3}")))
        );
    }
    s
}

fn frame_time_chart(name: &str, static_passes: &[(Mode, Pass)], path_passes: &[(Mode, Pass)], scene: &Scene) -> Chart<'static> {
    let on_path = !path_passes.is_empty();
    let passes = if on_path { path_passes } else { static_passes };
    let x = |r: &FrameRecord| r.time_s.map_or(r.frame as f64, f64::from);
    let mut series: Vec<Series> = passes
        .iter()
        .map(|(m, p)| Series {
            name: m.name().to_string(),
            points: p.records.iter().map(|r| (x(r), r.timings.frame)).collect(),
            markers: p.records.len() < 40 || *m == Mode::RtOnly,
        })
        .collect();
    let hline = match scene.heuristic.budget {
        Budget::Millis(ms) => Some(HLine { name: format!("trace budget {ms} ms"), y: ms }),
        _ => None,
    };
    // With a millisecond budget, the trace stage it controls, next to its target line.
    if hline.is_some()
        && let Some((_, p)) = passes.iter().find(|(m, _)| *m == Mode::Hybrid)
    {
        let points = p.records.iter().map(|r| (x(r), r.timings.trace)).collect();
        series.push(Series { name: "hybrid trace stage (RAYT)".into(), points, markers: p.records.len() < 40 });
    }
    Chart {
        title: format!("{name}: frame time {}", if on_path { "along the camera path" } else { "at the static camera" }),
        x_label: if on_path { "path time (s)" } else { "frame" },
        y_label: "time (ms)",
        series,
        hline,
    }
}

fn sweep_chart(name: &str, points: &[SweepPoint]) -> Chart<'static> {
    let series = ["paper", "knapsack"]
        .iter()
        .map(|&policy| {
            let pts: Vec<(f64, f64)> =
                points.iter().filter(|p| p.policy == policy).filter_map(|p| p.mean_flip.map(|f| (p.mean_frame_ms, f))).collect();
            Series { name: format!("policy {policy}"), points: pts, markers: true }
        })
        .collect();
    Chart {
        title: format!("{name}: budget sweep, image error against frame time"),
        x_label: "mean frame time (ms)",
        y_label: "mean FLIP vs rt-only",
        series,
        hline: None,
    }
}

fn cell(s: Option<&Stat>) -> String {
    s.map_or("–".into(), |s| format!("{:.2} ({:.2})", s.mean, s.p95))
}

#[allow(clippy::too_many_arguments)]
fn markdown(
    name: &str,
    args: &BenchArgs,
    machine: &Machine,
    static_summary: &BTreeMap<String, StaticSummary>,
    path: &BTreeMap<String, PathSummary>,
    sweep: &[SweepPoint],
    no_capsule: bool,
    path_seconds: Option<f32>,
) -> String {
    let mut s = String::new();
    let load = |l: Option<[f64; 3]>| l.map_or("?".into(), |l| format!("{:.2}", l[0]));
    let _ = writeln!(
        s,
        "# hybrid bench — {name}, {}×{}, backend {}, {} cores ({}), load average {} → {}{}\n",
        args.size.0,
        args.size.1,
        machine.backend,
        machine.cores,
        machine.cpu_model.as_deref().unwrap_or("unknown CPU"),
        load(machine.load_average_start),
        load(machine.load_average_end),
        machine.git_head.as_ref().map_or(String::new(), |c| format!(", git HEAD {}", &c[..c.len().min(10)]))
    );
    let stages = |mode: &str| static_summary.get(mode).map(|v| v.stages);
    let _ = writeln!(s, "## Static set (Table 5), ms: mean (p95) over {} frames after {WARMUP_FRAMES} warm-up\n", args.frames);
    let _ = writeln!(s, "| | {name} |\n|---|---|");
    if let Some(h) = stages("hybrid") {
        let _ = writeln!(s, "| FRAME | {} |", cell(Some(&h.frame)));
        if !no_capsule {
            let _ = writeln!(s, "| CAPSULE | {} |", cell(Some(&h.capsule)));
        }
        let _ = writeln!(s, "| RAST | {} |", cell(Some(&h.raster)));
        let _ = writeln!(s, "| HEUR | {} |", cell(Some(&h.heuristic)));
        let _ = writeln!(s, "| RAYT | {} |", cell(Some(&h.trace)));
        let _ = writeln!(s, "| BLEND | {} |", cell(Some(&h.blend)));
    }
    for (mode, label) in [("all", "NO HEURISTIC FRAME (all)"), ("rt-only", "RAYT ONLY FRAME"), ("raster", "RASTER ONLY FRAME")] {
        if let Some(st) = stages(mode) {
            let _ = writeln!(s, "| {label} | {} |", cell(Some(&st.frame)));
        }
    }
    let flip = |mode: &str| static_summary.get(mode).and_then(|v| v.flip_vs_rt_only);
    for (mode, label) in [("hybrid", "FLIP hybrid vs rt-only"), ("all", "FLIP all vs rt-only")] {
        if let Some(f) = flip(mode) {
            let _ = writeln!(s, "| {label} | {f:.4} |");
        }
    }
    if let (Some(h), Some(r)) = (stages("hybrid"), stages("rt-only"))
        && h.frame.mean > 0.0
    {
        let _ = writeln!(s, "| RAYT ONLY / hybrid | {:.2}× |", r.frame.mean / h.frame.mean);
    }
    if let Some(h) = stages("hybrid")
        && h.frame.mean > 0.0
    {
        let _ = writeln!(s, "| HEUR share of FRAME | {:.2}% |", 100.0 * h.heuristic.mean / h.frame.mean);
    }
    s.push('\n');

    if path.is_empty() {
        let _ = writeln!(s, "## Path set (Table 6): not run ({name} has no camera path)\n");
    } else {
        let n = path.values().map(|p| p.frames).max().unwrap_or(0);
        let _ = writeln!(
            s,
            "## Path set (Table 6), ms: mean (p95) over {n} frames ({} s of path at {} frames per path second), FLIP on every frame i with i mod {} = 0\n",
            path_seconds.unwrap_or(0.0),
            args.fps,
            args.flip_every
        );
        let _ = writeln!(s, "| | {name} |\n|---|---|");
        for (mode, label) in [
            ("hybrid", "Frame rendering time – with heuristic"),
            ("all", "Frame rendering time – no heuristic"),
            ("raster", "Frame rendering time – raster only"),
        ] {
            if let Some(p) = path.get(mode) {
                let _ = writeln!(s, "| {label} | {} |", cell(Some(&p.stages.frame)));
            }
        }
        if let Some(p) = path.get("rt-only") {
            let _ = writeln!(s, "| Frame rendering time – rt-only ({} frames) | {} |", p.frames, cell(Some(&p.stages.frame)));
        }
        for (mode, label) in [
            ("hybrid", "Mean FLIP vs rt-only – with heuristic"),
            ("all", "Mean FLIP vs rt-only – no heuristic"),
            ("raster", "Mean FLIP vs rt-only – raster only"),
        ] {
            if let Some(f) = path.get(mode).and_then(|p| p.mean_flip) {
                let _ = writeln!(s, "| {label} | {f:.4} |");
            }
        }
        if let Some(p) = path.get("hybrid") {
            if let (Some(c), Some(m)) = (p.mean_churn, p.max_churn) {
                let _ = writeln!(s, "| Selection churn (objects/frame, mean / max) | {c:.2} / {m} |");
            }
            if p.stages.frame.mean > 0.0 {
                let _ = writeln!(s, "| HEUR share of FRAME | {:.2}% |", 100.0 * p.stages.heuristic.mean / p.stages.frame.mean);
            }
            if let Some(r) = p.budget_hit_rate {
                let _ = writeln!(s, "| Frames with RAYT within ±10% of budget_ms | {:.1}% |", 100.0 * r);
            }
            if let Some(r) = p.budget_over_rate {
                let _ = writeln!(s, "| Frames with RAYT over budget_ms by > 10% | {:.1}% |", 100.0 * r);
            }
        }
        s.push('\n');
    }

    if !sweep.is_empty() {
        let _ = writeln!(s, "## Budget sweep (fractions of the mean all-selected cost)\n");
        let _ = writeln!(
            s,
            "| policy | fraction | budget (cost) | frame ms mean (p95) | RAYT ms | mean FLIP | churn |\n|---|---|---|---|---|---|---|"
        );
        for p in sweep {
            let _ = writeln!(
                s,
                "| {} | {:.2} | {:.0} | {:.2} ({:.2}) | {:.2} | {} | {} |",
                p.policy,
                p.fraction,
                p.budget,
                p.mean_frame_ms,
                p.p95_frame_ms,
                p.mean_trace_ms,
                p.mean_flip.map_or("–".into(), |f| format!("{f:.4}")),
                p.mean_churn.map_or("–".into(), |c| format!("{c:.2}"))
            );
        }
        s.push('\n');
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stats() {
        let v: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(stat(&v), Stat { mean: 50.5, p95: 95.0 });
        assert_eq!(stat(&[3.0]), Stat { mean: 3.0, p95: 3.0 });
        assert_eq!(stat(&[2.0, 1.0]), Stat { mean: 1.5, p95: 2.0 });
        assert_eq!(stat(&[]), Stat::default());
        assert_eq!(mean([1.0, 2.0].into_iter()), Some(1.5));
        assert_eq!(mean(std::iter::empty()), None);
    }

    fn record(trace: f64, budget_ms: Option<f64>, visible: usize, selected: usize, churn: usize) -> FrameRecord {
        FrameRecord {
            set: "path",
            mode: Mode::Hybrid,
            frame: 0,
            time_s: Some(0.0),
            timings: StageTimings { trace, frame: trace + 1.0, ..Default::default() },
            spent: Some(1.0),
            budget: None,
            budget_ms,
            all_cost: Some(2.0),
            visible: Some(visible),
            selected: Some(selected),
            churn: Some(churn),
            flip: None,
        }
    }

    #[test]
    fn budget_hit_rate_counts_frames_near_the_target_or_unbound() {
        let recs = [
            record(10.0, Some(10.0), 3, 2, 0), // on target
            record(10.9, Some(10.0), 3, 2, 1), // within +10%
            record(12.0, Some(10.0), 3, 2, 3), // over
            record(5.0, Some(10.0), 3, 2, 0),  // under, budget binding: a miss
            record(5.0, Some(10.0), 3, 3, 0),  // under, everything selected: fine
        ];
        let s = path_summary(&recs.iter().collect::<Vec<_>>());
        assert_eq!(s.budget_hit_rate, Some(3.0 / 5.0));
        assert_eq!(s.budget_over_rate, Some(1.0 / 5.0));
        assert_eq!(s.mean_churn, Some(0.8));
        assert_eq!(s.max_churn, Some(3));
        let no_ms = [record(5.0, None, 1, 1, 0)];
        assert_eq!(path_summary(&no_ms.iter().collect::<Vec<_>>()).budget_hit_rate, None);
    }

    #[test]
    fn csv_rows_have_every_column() {
        let mut r = record(1.0, None, 2, 1, 1);
        r.flip = Some(0.0123);
        let csv = frames_csv([&r].into_iter());
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines.len(), 2);
        let cols = FRAMES_CSV_HEADER.split(',').count();
        assert_eq!(lines[1].split(',').count(), cols);
        assert!(lines[1].starts_with("path,hybrid,0,0,2.000,"));
        assert!(lines[1].ends_with(",0.01230"));
    }
}
