//! # hybrid-heuristic
//!
//! The per-object selection heuristic of Walewski et al. 2019 (§3.2, eq. 1–3, Table 3,
//! listing 6; design §4): under a budget, which visible objects get ray-traced shadows,
//! reflections and refractions this frame. Backend-free: the CPU and GPU backends hand it the
//! G-buffer's object-id target and a few numbers per object, and get back a selection and the
//! mask the trace stage reads.
//!
//! ## One frame
//!
//! ```
//! use glam::{Mat4, Vec3};
//! use hybrid_heuristic::{count_visible_pixels, write_mask, FrameInput, Heuristic, ObjectInput};
//! use hybrid_scene::{Budget, HeuristicSettings, Policy};
//!
//! let settings = HeuristicSettings { budget: Budget::Millis(4.0), importance: 1.0, policy: Policy::Paper };
//! let mut heuristic = Heuristic::new(settings); // keep it across frames (S, ms per cost)
//!
//! // Per frame, after the raster stage:
//! let object_id: Vec<u32> = vec![0, 0, 1, u32::MAX]; // the G-buffer's id target (u32::MAX = sky)
//! let area = count_visible_pixels(&object_id, 2); // A for every object, one pass
//! let objects: Vec<ObjectInput> = (0..2)
//!     .map(|i| ObjectInput {
//!         name: format!("object {i}"),
//!         area: area[i],
//!         bbox_center: Vec3::new(i as f32, 0.0, -5.0), // world-space bounding-box centre
//!         reflective: true,
//!         refractive: false,
//!         relevance: 1.0, // K
//!         cost: 1.0,      // E
//!     })
//!     .collect();
//! let frame = FrameInput { view_proj: Mat4::IDENTITY, camera_position: Vec3::ZERO, light_count: 1 };
//! let selection = heuristic.run(&objects, &frame);
//! let mut mask = vec![0.0f32; object_id.len()];
//! write_mask(&object_id, &selection.selected, &mut mask);
//!
//! // After the trace stage: close the millisecond loop with the measured trace time.
//! let trace_ms = 3.2;
//! heuristic.record_trace(selection.report.spent, trace_ms);
//! ```
//!
//! ## What it computes
//!
//! Per visible object (A > 0): P (centre weight), D (distance), V = A·P/D, Q (rays per pixel),
//! C = A·Q·E (cost), R = (S·I + V)·K (relevance); see [`terms`]. Objects with A = 0 are never
//! selected. Then the third phase picks objects under the budget with the [`Policy`]:
//! [`select_paper`] (listing 6) or [`select_knapsack`] (greedy by R/C). [`Budget::Unlimited`]
//! selects every visible object.
//!
//! ## Units
//!
//! - **Cost** (C, `Budget::Cost`, `spent`): A·Q·E — pixels × estimated rays per pixel × the
//!   user's cost factor E, i.e. "rays, weighted by E". Its scale is arbitrary (as in the paper);
//!   only its ratio to time matters.
//! - **ms per cost**: milliseconds of trace-stage time per unit of cost, estimated from the
//!   frames traced so far ([`Heuristic::record_trace`]).
//! - **`Budget::Millis(ms)`**: this frame's cost budget is `ms / ms_per_cost`. The first frame
//!   (no estimate yet, unless one was set with [`Heuristic::set_ms_per_cost`]) selects every
//!   visible object: the biggest possible sample to calibrate from. Each later frame calibrates
//!   again (a closed loop), so the trace time tracks the target as the view changes. With a
//!   fixed per-frame overhead `trace_ms = a + k·spent` the loop still settles where the trace
//!   time equals the target (when a < target), because the estimate then exceeds k exactly by
//!   the overhead's share.
//!
//! ## Report
//!
//! [`HeuristicReport`] (serde) holds every visible object's inputs and decisions so a user can see
//! why an object lost its effects; the CLI writes it as JSON.

mod pixels;
mod scene_inputs;
mod select;
mod terms;

use serde::Serialize;

pub use hybrid_scene::{Budget, HeuristicSettings, Policy};
pub use pixels::{RT_SCENE_ID, SKY_ID, count_visible_pixels, write_mask};
pub use scene_inputs::{frame_input, object_inputs};
pub use select::{Candidate, select, select_knapsack, select_paper, select_restatement};
pub use terms::{FrameInput, MIN_DISTANCE, ObjectInput, Terms, center_weight, distance, ray_count, terms};

/// Exponential smoothing factor of the ms-per-cost estimate: `estimate += α·(sample − estimate)`.
/// 0.5 halves the error each frame (≈ 4 frames to settle within 10% after a sudden change) while
/// averaging out frame-to-frame timing noise over the last few frames.
pub const MS_PER_COST_SMOOTHING: f64 = 0.5;

/// The heuristic across frames: its settings, S (which objects were selected last frame) and the
/// estimate of trace-stage milliseconds per unit of cost.
#[derive(Debug, Clone)]
pub struct Heuristic {
    settings: HeuristicSettings,
    last_selected: Vec<bool>,
    ms_per_cost: Option<f64>,
}

/// One frame's decision.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Selection {
    /// `selected[i]`: object `i` (index in the scene's object list) gets ray-traced effects.
    /// Same length as the `objects` given to [`Heuristic::run`].
    pub selected: Vec<bool>,
    pub report: HeuristicReport,
}

/// Why the heuristic chose what it chose this frame (JSON keys as in design §4).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HeuristicReport {
    /// `"paper"` or `"knapsack"`.
    pub policy: &'static str,
    /// The cost budget used this frame; `None` (JSON null) when unlimited, including the first
    /// frame of a millisecond budget with no estimate yet.
    pub budget: Option<f64>,
    /// The millisecond target, `None` unless the budget is given in milliseconds.
    pub budget_ms: Option<f64>,
    /// Sum of C over the selected objects (pass it to [`Heuristic::record_trace`]).
    pub spent: f64,
    /// The estimate used this frame, `None` before the first trace was recorded.
    pub ms_per_cost: Option<f64>,
    /// Number of lights (enters Q).
    pub lights: usize,
    /// I.
    pub importance: f32,
    /// Every visible object (A > 0), by id.
    pub objects: Vec<ObjectReport>,
}

/// One visible object's line in the report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ObjectReport {
    pub name: String,
    /// Index in the scene's object list.
    pub id: usize,
    #[serde(rename = "A")]
    pub a: u64,
    #[serde(rename = "P")]
    pub p: f64,
    #[serde(rename = "D")]
    pub d: f64,
    #[serde(rename = "V")]
    pub v: f64,
    #[serde(rename = "Q")]
    pub q: u64,
    #[serde(rename = "C")]
    pub c: f64,
    #[serde(rename = "R")]
    pub r: f64,
    #[serde(rename = "K")]
    pub k: f32,
    #[serde(rename = "E")]
    pub e: f32,
    /// Selected last frame, as used in R.
    #[serde(rename = "S")]
    pub s: bool,
    pub reflective: bool,
    pub refractive: bool,
    /// Selected this frame.
    pub selected: bool,
}

impl Heuristic {
    pub fn new(settings: HeuristicSettings) -> Self {
        Self { settings, last_selected: Vec::new(), ms_per_cost: None }
    }

    pub fn settings(&self) -> &HeuristicSettings {
        &self.settings
    }

    /// Changes budget, I or policy; S and the ms-per-cost estimate are kept.
    pub fn set_settings(&mut self, settings: HeuristicSettings) {
        self.settings = settings;
    }

    /// Trace-stage milliseconds per unit of cost, `None` before the first recorded trace.
    pub fn ms_per_cost(&self) -> Option<f64> {
        self.ms_per_cost
    }

    /// Seeds (or overrides) the estimate, e.g. from a previous run; `None`, or a value that is
    /// not finite and > 0, forgets it.
    pub fn set_ms_per_cost(&mut self, ms_per_cost: Option<f64>) {
        self.ms_per_cost = ms_per_cost.filter(|m| m.is_finite() && *m > 0.0);
    }

    /// S: which objects were selected last frame.
    pub fn last_selected(&self) -> &[bool] {
        &self.last_selected
    }

    /// Forgets S (e.g. after a camera cut), keeping the ms-per-cost estimate.
    pub fn forget_selection(&mut self) {
        self.last_selected.clear();
    }

    /// This frame's cost budget: `None` = unlimited.
    fn cost_budget(&self) -> Option<f64> {
        match self.settings.budget {
            Budget::Unlimited => None,
            Budget::Cost(cost) => Some(cost),
            Budget::Millis(ms) => self.ms_per_cost.map(|m| ms / m),
        }
    }

    /// The second and third phases for one frame. `objects[i]` is the scene's object `i`.
    ///
    /// S is read from the previous call (objects beyond the previous call's count start with
    /// S = false) and replaced by this frame's selection.
    pub fn run(&mut self, objects: &[ObjectInput], frame: &FrameInput) -> Selection {
        self.last_selected.resize(objects.len(), false);
        let importance = self.settings.importance;

        // Second phase: a node for every visible object.
        let visible: Vec<usize> = (0..objects.len()).filter(|&i| objects[i].area > 0).collect();
        let node_terms: Vec<Terms> = visible.iter().map(|&i| terms(&objects[i], frame, self.last_selected[i], importance)).collect();

        // Third phase.
        let budget = self.cost_budget();
        let chosen_nodes: Vec<usize> = match budget {
            None => (0..visible.len()).collect(),
            Some(budget) => {
                let nodes: Vec<Candidate> = node_terms.iter().map(|t| Candidate { cost: t.c, relevance: t.r }).collect();
                select(self.settings.policy, &nodes, budget)
            }
        };
        let mut selected = vec![false; objects.len()];
        let mut spent = 0.0;
        for &node in &chosen_nodes {
            selected[visible[node]] = true;
            spent += node_terms[node].c;
        }

        let report = HeuristicReport {
            policy: match self.settings.policy {
                Policy::Paper => "paper",
                Policy::Knapsack => "knapsack",
            },
            budget,
            budget_ms: match self.settings.budget {
                Budget::Millis(ms) => Some(ms),
                _ => None,
            },
            spent,
            ms_per_cost: self.ms_per_cost,
            lights: frame.light_count,
            importance,
            objects: visible
                .iter()
                .zip(&node_terms)
                .map(|(&id, t)| {
                    let object = &objects[id];
                    ObjectReport {
                        name: object.name.clone(),
                        id,
                        a: object.area,
                        p: t.p,
                        d: t.d,
                        v: t.v,
                        q: t.q,
                        c: t.c,
                        r: t.r,
                        k: object.relevance,
                        e: object.cost,
                        s: self.last_selected[id],
                        reflective: object.reflective,
                        refractive: object.refractive,
                        selected: selected[id],
                    }
                })
                .collect(),
        };
        self.last_selected.clone_from(&selected);
        Selection { selected, report }
    }

    /// Feeds back the trace stage's measured time for the frame whose selection spent
    /// `spent_cost` (its `report.spent`), updating ms per cost with exponential smoothing
    /// ([`MS_PER_COST_SMOOTHING`]); the first sample is taken as is.
    ///
    /// Samples that carry no information are ignored: a non-finite or non-positive `trace_ms`,
    /// or a non-finite `spent_cost`. When nothing was traced (`spent_cost` ≤ 0) but an estimate
    /// exists, the estimate is relaxed by the factor (1 − α): the budget grows until something
    /// fits again, so a frame whose every visible object was too costly does not freeze the loop
    /// (a sample is taken as soon as something is traced).
    pub fn record_trace(&mut self, spent_cost: f64, trace_ms: f64) {
        if !spent_cost.is_finite() {
            return;
        }
        if spent_cost <= 0.0 {
            if let Some(m) = self.ms_per_cost.as_mut() {
                *m = (*m * (1.0 - MS_PER_COST_SMOOTHING)).max(f64::MIN_POSITIVE);
            }
            return;
        }
        if !(trace_ms.is_finite() && trace_ms > 0.0) {
            return;
        }
        let sample = trace_ms / spent_cost;
        self.ms_per_cost = Some(match self.ms_per_cost {
            None => sample,
            Some(m) => m + MS_PER_COST_SMOOTHING * (sample - m),
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn object(area: u64, x: f32, reflective: bool) -> ObjectInput {
        ObjectInput {
            name: format!("o{x}"),
            area,
            bbox_center: Vec3::new(x, 0.0, -5.0),
            reflective,
            refractive: false,
            relevance: 1.0,
            cost: 1.0,
        }
    }

    fn frame() -> FrameInput {
        FrameInput {
            view_proj: hybrid_scene::camera::look_at_rh(Vec3::ZERO, Vec3::NEG_Z, Vec3::Y),
            camera_position: Vec3::ZERO,
            light_count: 1,
        }
    }

    fn settings(budget: Budget) -> HeuristicSettings {
        HeuristicSettings { budget, importance: 1.0, policy: Policy::Paper }
    }

    #[test]
    fn zero_area_is_never_selected_and_clears_s() {
        let mut h = Heuristic::new(settings(Budget::Unlimited));
        let objects = vec![object(10, 0.0, true), object(0, 0.5, true), object(5, 1.0, false)];
        let s = h.run(&objects, &frame());
        assert_eq!(s.selected, vec![true, false, true]);
        assert_eq!(s.report.objects.iter().map(|o| o.id).collect::<Vec<_>>(), vec![0, 2]);
        assert_eq!(s.report.budget, None);
        // Object 0 disappears: it loses S.
        let objects = vec![object(0, 0.0, true), object(0, 0.5, true), object(5, 1.0, false)];
        let s = h.run(&objects, &frame());
        assert_eq!(s.selected, vec![false, false, true]);
        assert_eq!(h.last_selected(), &[false, false, true]);
        // Even with a huge cost budget.
        h.set_settings(settings(Budget::Cost(1e12)));
        let s = h.run(&objects, &frame());
        assert_eq!(s.selected, vec![false, false, true]);
        assert!(s.report.objects[0].s);
    }

    #[test]
    fn s_resizes_with_object_count() {
        let mut h = Heuristic::new(settings(Budget::Unlimited));
        h.run(&[object(1, 0.0, false), object(1, 0.0, false)], &frame());
        assert_eq!(h.last_selected(), &[true, true]);
        let s = h.run(&[object(1, 0.0, false), object(1, 0.0, false), object(1, 0.0, false)], &frame());
        assert_eq!(s.report.objects.iter().map(|o| o.s).collect::<Vec<_>>(), vec![true, true, false]);
        let s = h.run(&[object(1, 0.0, false)], &frame());
        assert_eq!(s.selected.len(), 1);
        assert_eq!(h.last_selected().len(), 1);
        h.forget_selection();
        let s = h.run(&[object(1, 0.0, false)], &frame());
        assert!(!s.report.objects[0].s);
    }

    #[test]
    fn millis_budget_first_frame_selects_all_then_calibrates() {
        let mut h = Heuristic::new(settings(Budget::Millis(2.0)));
        let objects = vec![object(100, 0.0, false), object(100, 1.0, false)]; // C = 100 each
        let s = h.run(&objects, &frame());
        assert_eq!(s.selected, vec![true, true]);
        assert_eq!((s.report.budget, s.report.budget_ms, s.report.ms_per_cost), (None, Some(2.0), None));
        assert_eq!(s.report.spent, 200.0);
        h.record_trace(200.0, 4.0); // 0.02 ms per cost → budget 100
        assert_eq!(h.ms_per_cost(), Some(0.02));
        let s = h.run(&objects, &frame());
        assert_eq!(s.report.budget, Some(100.0));
        assert_eq!(s.selected.iter().filter(|&&b| b).count(), 1);
        // Smoothing: sample 0.04 → 0.02 + 0.5·0.02 = 0.03.
        h.record_trace(100.0, 4.0);
        assert!((h.ms_per_cost().unwrap_or(0.0) - 0.03).abs() < 1e-12);
        // Useless samples are ignored.
        h.record_trace(f64::NAN, 1.0);
        h.record_trace(100.0, 0.0);
        h.record_trace(100.0, f64::INFINITY);
        assert!((h.ms_per_cost().unwrap_or(0.0) - 0.03).abs() < 1e-12);
        // Nothing traced: the estimate relaxes so the budget grows.
        h.record_trace(0.0, 0.5);
        assert!((h.ms_per_cost().unwrap_or(0.0) - 0.015).abs() < 1e-12);
        h.set_ms_per_cost(Some(-1.0));
        assert_eq!(h.ms_per_cost(), None);
    }

    #[test]
    fn unlimited_and_cost_budget() {
        let objects = vec![object(100, 0.0, false), object(50, 1.0, true)]; // C = 100, 50·3
        let mut h = Heuristic::new(settings(Budget::Cost(120.0)));
        let s = h.run(&objects, &frame());
        assert_eq!(s.selected, vec![true, false]);
        assert_eq!(s.report.spent, 100.0);
        assert_eq!(s.report.budget, Some(120.0));
        let mut h = Heuristic::new(settings(Budget::Cost(0.0)));
        assert_eq!(h.run(&objects, &frame()).selected, vec![false, false]);
        let mut h = Heuristic::new(settings(Budget::Unlimited));
        let s = h.run(&objects, &frame());
        assert_eq!(s.selected, vec![true, true]);
        assert_eq!(s.report.spent, 250.0);
    }
}
