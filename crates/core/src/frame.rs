//! Frame modes, per-frame settings and what a frame produces (design §1).

use std::fmt;
use std::str::FromStr;

use serde::Serialize;

use crate::buffers::{FrameBuffers, GBuffer};
use crate::depth_merge::PackedRtFrame;
use crate::report::FrameReport;

/// Which stages run (design §1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Mode {
    /// Raster + heuristic + trace of the selected objects + blend.
    Hybrid,
    /// Heuristic off: every visible object gets its effects (paper's "no heuristic").
    All,
    /// No raster: primary rays from the camera, every effect traced (paper's "RAYT ONLY").
    RtOnly,
    /// Raster and deferred lighting only (stages 0–1).
    Raster,
}

impl Mode {
    pub const ALL: [Mode; 4] = [Mode::Hybrid, Mode::All, Mode::RtOnly, Mode::Raster];
    pub fn name(self) -> &'static str {
        match self {
            Mode::Hybrid => "hybrid",
            Mode::All => "all",
            Mode::RtOnly => "rt-only",
            Mode::Raster => "raster",
        }
    }
}

impl fmt::Display for Mode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Mode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Mode::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| format!("unknown mode `{s}` (expected one of: hybrid, all, rt-only, raster)"))
    }
}

/// What one frame is asked to produce.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameSettings {
    pub width: u32,
    pub height: u32,
    pub mode: Mode,
}

impl FrameSettings {
    pub fn aspect(&self) -> f32 {
        self.width as f32 / self.height as f32
    }
    pub fn pixel_count(&self) -> usize {
        self.width as usize * self.height as usize
    }
}

/// Everything one frame produced, on either backend: the buffers (for the image, dumps and tests) and the report.
#[derive(Debug)]
pub struct Frame {
    pub settings: FrameSettings,
    pub gbuffer: GBuffer,
    pub buffers: FrameBuffers,
    /// The capsule's packed RGBA16UI frame (paper 2), when the scene has point clouds.
    pub rt_packed: Option<PackedRtFrame>,
    pub report: FrameReport,
}
