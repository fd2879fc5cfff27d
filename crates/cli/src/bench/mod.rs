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

mod output;
mod passes;
mod plan;
mod plot;
mod stats;

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use hybrid_core::fallback::Fallback;
use hybrid_core::report::{FallbackRenders, FrameReport, StageTimings};
use hybrid_core::{FrameSettings, Mode};
use hybrid_scene::{Budget, Camera, Policy, Scene, load_scene_or_model_within};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde::Serialize;
use serde_json::json;

use self::plot::{Chart, HLine, Series, write_chart};
use crate::CliError;
use crate::args::BenchArgs;
use crate::output::{OutputDir, write_bytes};
use crate::render::{AnyRenderer, Backend, RenderOptions, check_memory, check_rt, choose_backend, memory_limit};

/// Warm-up frames rendered (and discarded) at the start of every pass.
pub const WARMUP_FRAMES: usize = 2;
/// Path seconds rendered when `--path-seconds` is not given (the paper's traversal), or the whole
/// path when it is shorter.
pub const DEFAULT_PATH_SECONDS: f32 = 20.0;
/// Budget sweep: fractions of the mean all-selected cost.
pub const SWEEP_FRACTIONS: [f64; 5] = [0.1, 0.25, 0.5, 0.75, 1.0];
/// A millisecond budget is "hit" when the trace stage lands within this fraction of the target.
pub const BUDGET_TOLERANCE: f64 = 0.1;

use self::output::*;
use self::passes::*;
use self::plan::*;
use self::stats::*;

pub fn run(args: BenchArgs) -> Result<(), CliError> {
    check_args(&args)?;
    crate::args::use_threads(args.threads)?;
    let name = args.scene.display().to_string();
    let limit = memory_limit(args.max_memory);
    // The images kept for FLIP are not known before the plan: the frame alone first.
    hybrid_core::memory::frame_only(args.size.0, args.size.1, 0).check(&limit).map_err(CliError::bad_input)?;
    let mut scene = load_scene_or_model_within(&args.scene, &limit)?;
    args.heuristic.apply(&mut scene.heuristic);
    let plan = plan(&args, &scene, &name)?;
    let backend = choose_backend(args.backend, args.quiet)?;
    check_memory(&scene, &backend, args.size, plan.extra_bytes_per_pixel(args.flip_every), &limit)?;
    let backend_name = match &backend {
        Backend::Cpu => "cpu".to_string(),
        Backend::Gpu(ctx) => format!("gpu ({}, {})", ctx.summary.name, ctx.summary.backend),
    };
    // Everything is checked: now the output folder (created and probed before any rendering;
    // removed again if the run fails, when this run created it).
    let out_dir = OutputDir::prepare(&args.out, "--out")?;

    let machine_start = load_average();
    let options = RenderOptions::from(&args.capsule);
    if let Some(line) = check_rt(&backend, options.rt)?
        && !args.quiet
    {
        eprintln!("{line}");
    }
    let rt_used = match &backend {
        Backend::Gpu(ctx) => options.rt.resolve(ctx).map_or("sw", |p| p.name()),
        Backend::Cpu => "cpu",
    };
    let mut modes: Vec<Mode> = Vec::new();
    for m in &args.modes {
        if !modes.contains(m) {
            modes.push(*m);
        }
    }
    let total =
        planned_frames(&modes, args.frames as usize, plan.path_shots.as_ref().map(Vec::len), args.flip_every as usize, args.sweep_budget);
    let progress = progress_bar(args.quiet, total);
    let bench =
        Bench { scene_name: name.clone(), size: args.size, quiet: args.quiet, backend, options: std::cell::Cell::new(options), progress };
    if !args.quiet {
        eprintln!(
            "bench {name}: {}x{}, {} static frame{}, modes {}",
            args.size.0,
            args.size.1,
            args.frames,
            if args.frames == 1 { "" } else { "s" },
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
        // Both fallbacks on one chart (issue 18): the paper's (`none`) and the raster fallbacks.
        for fallback in [Fallback::None, Fallback::Raster] {
            bench.options.set(RenderOptions { fallback, ..options });
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
                        fallback: fallback.as_str(),
                        fraction,
                        budget,
                        frames: recs.len(),
                        mean_frame_ms: frame.mean,
                        p95_frame_ms: frame.p95,
                        mean_trace_ms: mean(recs.iter().map(|r| r.timings.trace)).unwrap_or(0.0),
                        mean_fallback_ms: mean(recs.iter().map(|r| r.timings.fallback)).unwrap_or(0.0),
                        mean_flip: mean(recs.iter().filter_map(|r| r.flip.map(f64::from))),
                        mean_churn: mean(recs.iter().filter_map(|r| r.churn.map(|c| c as f64))),
                    });
                }
            }
        }
        bench.options.set(options);
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
        cpu_isa: hybrid_cpu::isa::active().name(),
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
            "fallback": options.fallback.as_str(),
            "capsule_visibility": options.capsule_visibility.name(),
            // The traversal that traced (GPU backend: "hw" or "sw"; the CPU backend: "cpu").
            "rt": rt_used,
        },
        "machine": machine,
        "static": static_summary,
        "path": path_summary,
        "sweep": if args.sweep_budget { json!(sweep) } else { json!(null) },
        // Passes of 100 frames or more: resident memory after frame 100 and at the end (soak).
        "resident_memory": static_passes
            .iter()
            .map(|(m, p)| (format!("static {m}"), p.rss))
            .chain(path_passes.iter().map(|(m, p)| (format!("path {m}"), p.rss)))
            .filter_map(|(k, r)| r.map(|r| (k, json!({
                    "frame_100_kib": r.frame_100_kib,
                    "end_kib": r.end_kib,
                    "frames": r.frames,
                    "kept_bytes": r.kept_bytes,
                    "growth": r.growth(),
                    "growth_beyond_kept": r.growth_beyond_kept(),
                }))))
            .collect::<serde_json::Map<_, _>>(),
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
    bench.progress.finish_and_clear();
    out_dir.keep();
    print!(
        "{}",
        markdown(&name, &args, &machine, &static_summary, &path_summary, &sweep, scene.point_clouds.is_empty(), plan.path_seconds)
    );
    Ok(())
}

/// Frames the run renders, warm-ups included, pass by pass as `run` renders them: the static set
/// (each mode, and an rt-only reference of one frame when the sweep needs one and there is no
/// path), the path set (its rt-only reference on every `flip_every`-th frame, each other mode on
/// every frame) and the sweep (2 policies × [`SWEEP_FRACTIONS`] on the path, or on the static
/// frames).
fn planned_frames(modes: &[Mode], frames: usize, path_frames: Option<usize>, flip_every: usize, sweep: bool) -> u64 {
    let pass = |shots: usize| (WARMUP_FRAMES + shots) as u64;
    let mut total = modes.len() as u64 * pass(frames);
    if sweep && path_frames.is_none() && !modes.contains(&Mode::RtOnly) {
        total += pass(1);
    }
    if let Some(n) = path_frames {
        total += pass(n.div_ceil(flip_every.max(1)));
        total += modes.iter().filter(|m| **m != Mode::RtOnly).count() as u64 * pass(n);
    }
    if sweep {
        // Two fallbacks × two policies × the fractions.
        total += 4 * SWEEP_FRACTIONS.len() as u64 * pass(path_frames.unwrap_or(frames));
    }
    total
}

/// The run's progress bar on stderr (hidden with `--quiet`; indicatif hides it by itself when
/// stderr is not a terminal, so logs and tests see only the per-pass lines).
fn progress_bar(quiet: bool, total: u64) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr());
    if let Ok(style) = ProgressStyle::with_template("{msg} [{bar:24}] frame {pos}/{len}, {elapsed} elapsed, ETA {eta}") {
        bar.set_style(style.progress_chars("=> "));
    }
    bar
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn planned_frames_by_hand() {
        let (h, a, r) = (Mode::Hybrid, Mode::All, Mode::RtOnly);
        // Default modes, 20 static frames, a 40-frame path, FLIP every 10th, no sweep:
        // static 3 × 22; path reference 2 + 4, hybrid and all 2 × 42.
        assert_eq!(planned_frames(&[h, a, r], 20, Some(40), 10, false), 66 + 6 + 84);
        // With the sweep on the path (2 fallbacks × 2 policies × 5 fractions): + 20 × 42.
        assert_eq!(planned_frames(&[h, a, r], 20, Some(40), 10, true), 66 + 6 + 84 + 840);
        // No path, sweep without rt-only: static 1 × 22, the 1-frame reference 3, the sweep 20 × 22.
        assert_eq!(planned_frames(&[h], 20, None, 10, true), 22 + 3 + 440);
        // 41 path frames every 10th: 5 reference frames.
        assert_eq!(planned_frames(&[r], 1, Some(41), 10, false), 3 + 7);
    }

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
            fallback_renders: Default::default(),
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
        // Each column found by its header name: FLIP, the fallback stage's milliseconds and
        // what it rendered.
        let field = |name: &str| {
            let k = FRAMES_CSV_HEADER.split(',').position(|c| c == name).unwrap_or_else(|| panic!("no column {name}"));
            lines[1].split(',').nth(k).unwrap().to_string()
        };
        assert_eq!(field("flip"), "0.01230", "{}", lines[1]);
        assert_eq!(field("fallback_ms"), "0.000", "{}", lines[1]);
        for renders in ["shadow_map_renders", "probe_renders", "see_through_renders"] {
            assert_eq!(field(renders), "0", "{}", lines[1]);
        }
    }

    #[test]
    fn each_mode_has_its_own_colour_in_every_chart() {
        let modes = [Mode::Hybrid, Mode::All, Mode::RtOnly, Mode::Raster];
        let colours: std::collections::BTreeSet<usize> = modes.iter().map(|&m| mode_color(m)).collect();
        assert_eq!(colours.len(), modes.len());
        // The trace-stage line (colour 4) is none of them.
        assert!(!colours.contains(&4));
    }
}
