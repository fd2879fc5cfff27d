//! `stage`: the frame's stages by name (one list for both backends: timings, progress, reports)
//! and stage 2, the heuristic, which both backends run the same way around their own pixel count
//! and mask writing.

use std::fmt;
use std::ops::{Index, IndexMut};

use hybrid_heuristic::{Heuristic, HeuristicReport, Selection, frame_input, object_inputs};
use hybrid_scene::Camera;

use crate::frame::Mode;
use crate::prepare::PreparedScene;
use crate::report::StageTimings;

/// The stages of a frame, in the order a frame runs them (the capsule first in paper 2's order;
/// `--clip-capsule` runs it after the raster). `Lighting` is the deferred-lighting part of stage 1.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Stage {
    /// 0: the point-cloud capsule's packed frame and its unpack (paper 2).
    Capsule,
    /// 1: the G-buffer (rasterized, or from primary rays in `rt-only`).
    Raster,
    /// 1: deferred Blinn–Phong lighting of the G-buffer (the P-buffer).
    Lighting,
    /// 2: pixels per object, the heuristic's selection, the mask.
    Heuristic,
    /// 3: shadow, reflection and refraction rays of masked pixels.
    Trace,
    /// 3b (issue 18, beyond the paper): shadow maps and probes for the covered pixels the trace
    /// stage left out (maps rendered when missing or moved, then a lookup per pixel).
    Fallback,
    /// 4: lighting and traced terms combined (eq. 4–6), sRGB-encoded.
    Blend,
}

impl Stage {
    /// Every stage, in frame order.
    pub const ALL: [Stage; 7] =
        [Stage::Capsule, Stage::Raster, Stage::Lighting, Stage::Heuristic, Stage::Trace, Stage::Fallback, Stage::Blend];

    /// The stage's name in reports and progress lines (`StageTimings`' field name).
    pub fn name(self) -> &'static str {
        match self {
            Stage::Capsule => "capsule",
            Stage::Raster => "raster",
            Stage::Lighting => "lighting",
            Stage::Heuristic => "heuristic",
            Stage::Trace => "trace",
            Stage::Fallback => "fallback",
            Stage::Blend => "blend",
        }
    }
}

impl fmt::Display for Stage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A stage's milliseconds. `raster` holds all of stage 1 (G-buffer and lighting) once a frame is
/// done; `lighting` its deferred-lighting part.
impl Index<Stage> for StageTimings {
    type Output = f64;
    fn index(&self, stage: Stage) -> &f64 {
        match stage {
            Stage::Capsule => &self.capsule,
            Stage::Raster => &self.raster,
            Stage::Lighting => &self.lighting,
            Stage::Heuristic => &self.heuristic,
            Stage::Trace => &self.trace,
            Stage::Fallback => &self.fallback,
            Stage::Blend => &self.blend,
        }
    }
}

impl IndexMut<Stage> for StageTimings {
    fn index_mut(&mut self, stage: Stage) -> &mut f64 {
        match stage {
            Stage::Capsule => &mut self.capsule,
            Stage::Raster => &mut self.raster,
            Stage::Lighting => &mut self.lighting,
            Stage::Heuristic => &mut self.heuristic,
            Stage::Trace => &mut self.trace,
            Stage::Fallback => &mut self.fallback,
            Stage::Blend => &mut self.blend,
        }
    }
}

/// What stage 2 decided the mask holds.
#[derive(Debug, Clone)]
pub enum MaskChoice {
    /// `raster`: nothing is traced (mask 0 everywhere).
    Nothing,
    /// `rt-only`: every pixel with an object id (RT-scene pixels included) is traced.
    AllCovered,
    /// `hybrid` / `all`: the pixels of the selected objects (`selection.selected[id]`).
    Objects(Selection),
}

impl MaskChoice {
    /// `selected[id]` when objects were chosen.
    pub fn selected(&self) -> Option<&[bool]> {
        match self {
            MaskChoice::Objects(s) => Some(&s.selected),
            _ => None,
        }
    }

    /// The heuristic's per-object report (modes `hybrid` and `all`).
    pub fn into_report(self) -> Option<HeuristicReport> {
        match self {
            MaskChoice::Objects(s) => Some(s.report),
            _ => None,
        }
    }
}

/// Stage 2 as both backends run it: the heuristic's state (S per object, the ms-per-cost
/// estimate) carried between frames, the selection per mode, and the budget's closed loop.
/// The backends count pixels per object and write the mask each their own way.
#[derive(Debug, Clone)]
pub struct HeuristicStage {
    heuristic: Heuristic,
    /// Per object: K and E set live (the viewer's object table), in place of the scene file's.
    weights: Vec<Option<(f32, f32)>>,
}

impl HeuristicStage {
    pub fn new(heuristic: Heuristic) -> Self {
        Self { heuristic, weights: Vec::new() }
    }

    /// Object `id`'s K (static relevance) and E (estimated cost) from now on, in place of the
    /// scene file's; `None` goes back to the file's.
    pub fn set_object_weights(&mut self, id: usize, weights: Option<(f32, f32)>) {
        if self.weights.len() <= id {
            self.weights.resize(id + 1, None);
        }
        self.weights[id] = weights;
    }

    /// The heuristic, e.g. to change its settings between frames.
    pub fn heuristic_mut(&mut self) -> &mut Heuristic {
        &mut self.heuristic
    }

    pub fn heuristic(&self) -> &Heuristic {
        &self.heuristic
    }

    /// What to trace this frame. `raster` traces nothing and `rt-only` every covered pixel, without
    /// counting; `hybrid` runs the heuristic on the pixel counts `count_areas` gives (A per object),
    /// `all` selects every visible object.
    pub fn choose<E>(
        &mut self,
        prepared: &PreparedScene,
        camera: &Camera,
        (width, height): (u32, u32),
        mode: Mode,
        count_areas: impl FnOnce() -> Result<Vec<u64>, E>,
    ) -> Result<MaskChoice, E> {
        Ok(match mode {
            Mode::Raster => MaskChoice::Nothing,
            Mode::RtOnly => MaskChoice::AllCovered,
            Mode::Hybrid | Mode::All => {
                let areas = count_areas()?;
                let mut objects = object_inputs(prepared.scene, &prepared.object_bounds, &areas);
                for (o, w) in objects.iter_mut().zip(&self.weights) {
                    if let Some((k, e)) = *w {
                        (o.relevance, o.cost) = (k, e);
                    }
                }
                let frame = frame_input(prepared.scene, camera, width, height);
                MaskChoice::Objects(if mode == Mode::All {
                    self.heuristic.run_unlimited(&objects, &frame)
                } else {
                    self.heuristic.run(&objects, &frame)
                })
            }
        })
    }

    /// After the trace stage: in `hybrid` mode, the cost spent and the trace stage's time
    /// calibrate the ms budget (the closed loop); other modes leave the estimate alone.
    pub fn record_trace(&mut self, mode: Mode, report: Option<&HeuristicReport>, trace_ms: f64) {
        if mode == Mode::Hybrid {
            self.heuristic.record_trace(report.map_or(0.0, |r| r.spent), trace_ms);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hybrid_scene::{Budget, HeuristicSettings, demo_scene};

    fn stage_for(budget: Budget) -> HeuristicStage {
        HeuristicStage::new(Heuristic::new(HeuristicSettings { budget, ..HeuristicSettings::default() }))
    }

    #[test]
    fn stage_names_are_the_report_keys() {
        let json = serde_json::to_value(StageTimings::default()).unwrap();
        for stage in Stage::ALL {
            assert!(json.get(stage.name()).is_some(), "{stage} is not a key of the report's timings");
            let mut t = StageTimings::default();
            t[stage] = 7.0;
            assert_eq!(serde_json::to_value(t).unwrap()[stage.name()], 7.0);
        }
    }

    #[test]
    fn raster_and_rt_only_choose_without_counting() {
        let scene = demo_scene();
        let prepared = PreparedScene::new(&scene);
        let mut stage = stage_for(Budget::Cost(0.0));
        let never = || -> Result<Vec<u64>, ()> { panic!("pixels counted") };
        assert!(matches!(stage.choose(&prepared, &scene.camera, (64, 36), Mode::Raster, never), Ok(MaskChoice::Nothing)));
        assert!(matches!(stage.choose(&prepared, &scene.camera, (64, 36), Mode::RtOnly, never), Ok(MaskChoice::AllCovered)));
    }

    #[test]
    fn all_selects_every_visible_object_whatever_the_budget_and_hybrid_keeps_to_it() {
        let scene = demo_scene();
        let prepared = PreparedScene::new(&scene);
        let n = scene.objects.len();
        // Every object visible but the last.
        let areas: Vec<u64> = (0..n as u64).map(|i| if i + 1 == n as u64 { 0 } else { 100 + i }).collect();
        let count = || Ok::<_, ()>(areas.clone());
        let mut stage = stage_for(Budget::Cost(0.0));
        let all = stage.choose(&prepared, &scene.camera, (64, 36), Mode::All, count).unwrap();
        let want: Vec<bool> = areas.iter().map(|&a| a > 0).collect();
        assert_eq!(all.selected(), Some(&want[..]));
        // The budget is untouched by `all`: hybrid with a zero budget selects nothing.
        let hybrid = stage.choose(&prepared, &scene.camera, (64, 36), Mode::Hybrid, count).unwrap();
        assert_eq!(hybrid.selected(), Some(&vec![false; n][..]));
        assert_eq!(hybrid.into_report().map(|r| r.spent), Some(0.0));
    }

    #[test]
    fn only_hybrid_frames_calibrate_the_ms_budget() {
        let scene = demo_scene();
        let prepared = PreparedScene::new(&scene);
        let areas = vec![1000u64; scene.objects.len()];
        let mut stage = stage_for(Budget::Millis(1.0));
        let choice = stage.choose(&prepared, &scene.camera, (64, 36), Mode::All, || Ok::<_, ()>(areas.clone())).unwrap();
        let report = choice.into_report();
        stage.record_trace(Mode::All, report.as_ref(), 5.0);
        assert_eq!(stage.heuristic().ms_per_cost(), None);
        let choice = stage.choose(&prepared, &scene.camera, (64, 36), Mode::Hybrid, || Ok::<_, ()>(areas.clone())).unwrap();
        let report = choice.into_report();
        assert!(report.as_ref().is_some_and(|r| r.spent > 0.0), "the first ms-budget frame traces something to measure");
        stage.record_trace(Mode::Hybrid, report.as_ref(), 5.0);
        assert!(stage.heuristic().ms_per_cost().is_some_and(|m| m > 0.0));
    }

    #[test]
    fn object_weights_set_live_replace_the_files_k_and_e() {
        let scene = demo_scene();
        let prepared = PreparedScene::new(&scene);
        let areas = vec![100u64; scene.objects.len()];
        let mut stage = stage_for(Budget::Unlimited);
        let run = |stage: &mut HeuristicStage| {
            stage.choose(&prepared, &scene.camera, (64, 36), Mode::Hybrid, || Ok::<_, ()>(areas.clone())).unwrap().into_report().unwrap()
        };
        let before = run(&mut stage);
        stage.set_object_weights(2, Some((3.0, 0.5)));
        let after = run(&mut stage);
        let (b, a) = (&before.objects[2], &after.objects[2]);
        assert_eq!((a.k, a.e), (3.0, 0.5));
        // C = A·Q·E: halved with E from 1 to 0.5 (the demo's objects have the default E = 1).
        assert_eq!(b.e, 1.0);
        assert_eq!(a.c, b.c * 0.5);
        // The other objects keep the file's weights; `None` restores the file's.
        let (b1, a1) = (&before.objects[1], &after.objects[1]);
        assert_eq!((a1.k, a1.e, a1.c), (b1.k, b1.e, b1.c));
        stage.set_object_weights(2, None);
        assert_eq!((run(&mut stage).objects[2].k, run(&mut stage).objects[2].e), (b.k, b.e));
    }
}
