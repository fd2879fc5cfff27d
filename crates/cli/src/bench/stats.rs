//! What a bench run measures: one record per frame, and the statistics over them (mean, p95,
//! per stage; the path set's quality and churn; the budget sweep's points).

use super::*;

/// One measured frame.
#[derive(Debug, Clone, Serialize)]
pub(super) struct FrameRecord {
    pub(super) set: &'static str,
    pub(super) mode: Mode,
    /// Index along the pass (path frame index for the path set).
    pub(super) frame: usize,
    pub(super) time_s: Option<f32>,
    pub(super) timings: StageTimings,
    pub(super) spent: Option<f64>,
    pub(super) budget: Option<f64>,
    pub(super) budget_ms: Option<f64>,
    /// Sum of C over the visible objects: the cost of selecting everything.
    pub(super) all_cost: Option<f64>,
    pub(super) visible: Option<usize>,
    pub(super) selected: Option<usize>,
    pub(super) churn: Option<usize>,
    pub(super) flip: Option<f32>,
    /// Shadow maps and probes the fallback stage rendered in this frame (0 when cached).
    pub(super) fallback_renders: FallbackRenders,
}

impl FrameRecord {
    pub(super) fn new(set: &'static str, frame: usize, shot: &Shot, report: &FrameReport) -> Self {
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
            fallback_renders: report.fallback_renders,
        }
    }
}

/// Mean and 95th percentile (nearest rank) of a sample.
#[derive(Debug, Clone, Copy, Default, Serialize, PartialEq)]
pub(super) struct Stat {
    pub(super) mean: f64,
    pub(super) p95: f64,
}

pub(super) fn stat(values: &[f64]) -> Stat {
    if values.is_empty() {
        return Stat::default();
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let rank = ((0.95 * v.len() as f64).ceil() as usize).clamp(1, v.len());
    Stat { mean: v.iter().sum::<f64>() / v.len() as f64, p95: v[rank - 1] }
}

pub(super) fn mean(values: impl Iterator<Item = f64>) -> Option<f64> {
    let (sum, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    (n > 0).then(|| sum / n as f64)
}

/// Mean and p95 of every stage over some frames.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub(super) struct StageStats {
    pub(super) capsule: Stat,
    pub(super) raster: Stat,
    pub(super) heuristic: Stat,
    pub(super) trace: Stat,
    /// Stage 3b, the raster fallbacks (issue 18): maps and probes rendered, lookups.
    pub(super) fallback: Stat,
    pub(super) blend: Stat,
    pub(super) frame: Stat,
}

pub(super) fn stage_stats(records: &[&FrameRecord]) -> StageStats {
    let s = |f: fn(&StageTimings) -> f64| stat(&records.iter().map(|r| f(&r.timings)).collect::<Vec<_>>());
    StageStats {
        capsule: s(|t| t.capsule),
        raster: s(|t| t.raster),
        heuristic: s(|t| t.heuristic),
        trace: s(|t| t.trace),
        fallback: s(|t| t.fallback),
        blend: s(|t| t.blend),
        frame: s(|t| t.frame),
    }
}

/// Summary of the static set for one mode.
#[derive(Debug, Serialize)]
pub(super) struct StaticSummary {
    pub(super) frames: usize,
    pub(super) stages: StageStats,
    /// FLIP of the last frame against rt-only's last frame.
    pub(super) flip_vs_rt_only: Option<f32>,
}

/// Summary of the path set for one mode.
#[derive(Debug, Serialize)]
pub(super) struct PathSummary {
    pub(super) frames: usize,
    pub(super) stages: StageStats,
    pub(super) mean_flip: Option<f64>,
    pub(super) flip_frames: usize,
    pub(super) mean_churn: Option<f64>,
    pub(super) max_churn: Option<usize>,
    pub(super) mean_spent: Option<f64>,
    pub(super) mean_all_cost: Option<f64>,
    /// Millisecond budget only: share of frames whose trace stage is within ±10% of the target
    /// (or below it when every visible object was selected, so the budget did not bind).
    pub(super) budget_hit_rate: Option<f64>,
    /// Millisecond budget only: share of frames whose trace stage exceeds the target by > 10%.
    pub(super) budget_over_rate: Option<f64>,
}

pub(super) fn path_summary(records: &[&FrameRecord]) -> PathSummary {
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
pub(super) struct SweepPoint {
    pub(super) policy: &'static str,
    /// `--fallback` of the point's pass (the sweep runs both).
    pub(super) fallback: &'static str,
    pub(super) fraction: f64,
    pub(super) budget: f64,
    pub(super) frames: usize,
    pub(super) mean_frame_ms: f64,
    pub(super) p95_frame_ms: f64,
    pub(super) mean_trace_ms: f64,
    /// Mean of the fallback stage (shadow maps, probes, lookups); 0 with `--fallback none`.
    pub(super) mean_fallback_ms: f64,
    pub(super) mean_flip: Option<f64>,
    pub(super) mean_churn: Option<f64>,
}
