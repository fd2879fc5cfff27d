//! The bench's outputs: the machine it ran on, the CSV files, the charts and the Markdown summary.

use super::*;

/// The machine the numbers were taken on.
#[derive(Debug, Serialize)]
pub(super) struct Machine {
    /// "cpu", or "gpu (adapter name, API)".
    pub(super) backend: String,
    pub(super) cores: usize,
    pub(super) threads: usize,
    pub(super) cpu_model: Option<String>,
    /// The CPU kernels' instruction-set path (`hybrid_cpu::isa`: "sse2", "avx2", "avx512", …).
    pub(super) cpu_isa: &'static str,
    pub(super) load_average_start: Option<[f64; 3]>,
    pub(super) load_average_end: Option<[f64; 3]>,
    /// `git rev-parse HEAD` of the scene's repository when the bench ran (the binary may have been
    /// built from another tree: record the build commit separately when it matters).
    pub(super) git_head: Option<String>,
}

pub(super) fn cpu_model() -> Option<String> {
    let info = std::fs::read_to_string("/proc/cpuinfo").ok()?;
    info.lines().find(|l| l.starts_with("model name")).and_then(|l| l.split_once(':')).map(|(_, v)| v.trim().to_string())
}

pub(super) fn load_average() -> Option<[f64; 3]> {
    let s = std::fs::read_to_string("/proc/loadavg").ok()?;
    let mut it = s.split_whitespace().map(|v| v.parse::<f64>().ok());
    Some([it.next()??, it.next()??, it.next()??])
}

pub(super) fn git_commit(dir: &Path) -> Option<String> {
    let out = std::process::Command::new("git").arg("-C").arg(dir).args(["rev-parse", "HEAD"]).output().ok()?;
    out.status.success().then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

pub(super) fn policy_name(p: Policy) -> &'static str {
    match p {
        Policy::Paper => "paper",
        Policy::Knapsack => "knapsack",
    }
}

pub const FRAMES_CSV_HEADER: &str = "set,mode,frame,time_s,frame_ms,capsule_ms,raster_ms,heuristic_ms,trace_ms,blend_ms,spent,budget,budget_ms,all_cost,visible,selected,churn,flip,fallback_ms,shadow_map_renders,probe_renders,see_through_renders";

pub(super) fn opt<T: std::fmt::Display>(v: Option<T>) -> String {
    v.map_or(String::new(), |v| v.to_string())
}

pub(super) fn frames_csv<'a>(records: impl Iterator<Item = &'a FrameRecord>) -> String {
    let mut s = String::from(FRAMES_CSV_HEADER);
    s.push('\n');
    for r in records {
        let t = &r.timings;
        let _ = writeln!(
            s,
            "{},{},{},{},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{},{},{},{},{},{},{},{},{:.3},{},{},{}",
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
            opt(r.flip.map(|f| format!("{f:.5}"))),
            t.fallback,
            r.fallback_renders.shadow_maps,
            r.fallback_renders.probes,
            r.fallback_renders.see_through
        );
    }
    s
}

pub const SWEEP_CSV_HEADER: &str =
    "policy,fraction,budget,frames,mean_frame_ms,p95_frame_ms,mean_trace_ms,mean_flip,mean_churn,fallback,mean_fallback_ms";

pub(super) fn sweep_csv(points: &[SweepPoint]) -> String {
    let mut s = String::from(SWEEP_CSV_HEADER);
    s.push('\n');
    for p in points {
        let _ = writeln!(
            s,
            "{},{},{:.1},{},{:.3},{:.3},{:.3},{},{},{},{:.3}",
            p.policy,
            p.fraction,
            p.budget,
            p.frames,
            p.mean_frame_ms,
            p.p95_frame_ms,
            p.mean_trace_ms,
            opt(p.mean_flip.map(|f| format!("{f:.5}"))),
            opt(p.mean_churn.map(|c| format!("{c:.3}"))),
            p.fallback,
            p.mean_fallback_ms
        );
    }
    s
}

/// The palette colour of a mode's line, the same in every chart.
pub(super) fn mode_color(mode: Mode) -> usize {
    match mode {
        Mode::Hybrid => 0,
        Mode::All => 1,
        Mode::RtOnly => 2,
        Mode::Raster => 3,
    }
}

pub(super) fn frame_time_chart(name: &str, static_passes: &[(Mode, Pass)], path_passes: &[(Mode, Pass)], scene: &Scene) -> Chart<'static> {
    let on_path = !path_passes.is_empty();
    let passes = if on_path { path_passes } else { static_passes };
    let x = |r: &FrameRecord| r.time_s.map_or(r.frame as f64, f64::from);
    let mut series: Vec<Series> = passes
        .iter()
        .map(|(m, p)| Series {
            name: m.name().to_string(),
            points: p.records.iter().map(|r| (x(r), r.timings.frame)).collect(),
            markers: p.records.len() < 40 || *m == Mode::RtOnly,
            color: mode_color(*m),
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
        series.push(Series { name: "hybrid trace stage (RAYT)".into(), points, markers: p.records.len() < 40, color: 4 });
    }
    Chart {
        title: format!("{name}: frame time {}", if on_path { "along the camera path" } else { "at the static camera" }),
        x_label: if on_path { "path time (s)" } else { "frame" },
        y_label: "time (ms)",
        series,
        hline,
    }
}

pub(super) fn sweep_chart(name: &str, points: &[SweepPoint]) -> Chart<'static> {
    let series = [("paper", "none", 0), ("knapsack", "none", 1), ("paper", "raster", 2), ("knapsack", "raster", 3)]
        .iter()
        .filter(|(policy, fallback, _)| points.iter().any(|p| p.policy == *policy && p.fallback == *fallback))
        .map(|&(policy, fallback, color)| {
            let pts: Vec<(f64, f64)> = points
                .iter()
                .filter(|p| p.policy == policy && p.fallback == fallback)
                .filter_map(|p| p.mean_flip.map(|f| (p.mean_frame_ms, f)))
                .collect();
            Series { name: format!("policy {policy}, --fallback {fallback}"), points: pts, markers: true, color }
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

pub(super) fn cell(s: Option<&Stat>) -> String {
    s.map_or("–".into(), |s| format!("{:.2} ({:.2})", s.mean, s.p95))
}

#[allow(clippy::too_many_arguments)]
pub(super) fn markdown(
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
        "# hybrid bench — {name}, {}×{}, backend {}, {} cores ({}, {} kernels), load average {} → {}{}\n",
        args.size.0,
        args.size.1,
        machine.backend,
        machine.cores,
        machine.cpu_model.as_deref().unwrap_or("unknown CPU"),
        machine.cpu_isa,
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
        let _ = writeln!(s, "| FALLBACK (shadow maps, probes) | {} |", cell(Some(&h.fallback)));
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
            "| fallback | policy | fraction | budget (cost) | frame ms mean (p95) | RAYT ms | mean FLIP | churn |\n|---|---|---|---|---|---|---|---|"
        );
        for p in sweep {
            let _ = writeln!(
                s,
                "| {} | {} | {:.2} | {:.0} | {:.2} ({:.2}) | {:.2} | {} | {} |",
                p.fallback,
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
