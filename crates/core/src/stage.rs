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
    /// 4: lighting and traced terms combined (eq. 4–6), sRGB-encoded.
    Blend,
}

impl Stage {
    /// Every stage, in frame order.
    pub const ALL: [Stage; 6] = [Stage::Capsule, Stage::Raster, Stage::Lighting, Stage::Heuristic, Stage::Trace, Stage::Blend];

    /// The stage's name in reports and progress lines (`StageTimings`' field name).
    pub fn name(self) -> &'static str {
        match self {
            Stage::Capsule => "capsule",
            Stage::Raster => "raster",
            Stage::Lighting => "lighting",
            Stage::Heuristic => "heuristic",
            Stage::Trace => "trace",
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
}

impl HeuristicStage {
    pub fn new(heuristic: Heuristic) -> Self {
        Self { heuristic }
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
                let objects = object_inputs(prepared.scene, &prepared.object_bounds, &areas);
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
