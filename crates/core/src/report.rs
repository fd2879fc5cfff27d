//! The per-frame report (`hybrid render --report FILE.json`): what every stage took, how many
//! rays of each kind were traced, and why each object did or did not get its effects.

use serde::Serialize;

use crate::frame::Mode;

/// Wall-clock milliseconds per stage (design §1). `frame` is the whole frame.
#[derive(Debug, Clone, Copy, Default, Serialize, PartialEq)]
pub struct StageTimings {
    /// Stage 0: the RT-scene capsule (trace + pack) and its unpack; 0 without point clouds.
    pub capsule: f64,
    /// Stage 1: G-buffer fill and deferred lighting (`lighting` is the deferred-lighting part).
    pub raster: f64,
    pub lighting: f64,
    pub heuristic: f64,
    pub trace: f64,
    /// The raster fallbacks (issue 18): shadow maps and probes rendered this frame, and the
    /// per-pixel lookups; 0 with `--fallback none`.
    pub fallback: f64,
    pub blend: f64,
    pub frame: f64,
    /// GPU backend, hardware ray tracing only: building the acceleration structures (once per
    /// scene, wall-clock ms of the build's submission; reported on every frame like the capsule's
    /// `build_ms`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub build_as: Option<f64>,
}

/// Rays traced in one frame, by kind.
#[derive(Debug, Clone, Copy, Default, Serialize, PartialEq, Eq)]
pub struct RayCounts {
    pub primary: u64,
    pub shadow: u64,
    pub reflection: u64,
    pub refraction: u64,
}

impl RayCounts {
    pub fn total(&self) -> u64 {
        self.primary + self.shadow + self.reflection + self.refraction
    }
}

impl std::ops::AddAssign for RayCounts {
    fn add_assign(&mut self, o: Self) {
        self.primary += o.primary;
        self.shadow += o.shadow;
        self.reflection += o.reflection;
        self.refraction += o.refraction;
    }
}

/// What the RT-scene capsule did (paper 2).
#[derive(Debug, Clone, Copy, Default, Serialize, PartialEq)]
pub struct CapsuleReport {
    pub points: u64,
    /// Sphere BVH build (once per scene; reported on every frame).
    pub build_ms: f64,
    pub trace_ms: f64,
    pub pack_ms: f64,
    pub unpack_ms: f64,
    pub rays: u64,
}

/// Everything `--report` writes for one frame.
#[derive(Debug, Clone, Serialize)]
pub struct FrameReport {
    pub backend: String,
    /// [width, height] in pixels.
    pub size: [u32; 2],
    pub mode: Mode,
    pub timings_ms: StageTimings,
    pub rays: RayCounts,
    pub triangles: u64,
    pub objects: u64,
    pub heuristic: Option<hybrid_heuristic::HeuristicReport>,
    pub capsule: Option<CapsuleReport>,
    /// What pixels the trace stage left out got (`--fallback`).
    pub fallback: crate::fallback::Fallback,
    /// Per visible object: which path its shadows, reflections and refractions took this frame
    /// (`traced`, `raster` = shadow maps / probe, `none`).
    pub effects: Vec<crate::fallback::ObjectEffects>,
    /// Shadow maps and probes rendered this frame (0 when all came from the cache).
    pub fallback_renders: FallbackRenders,
    /// GPU backend: per-stage GPU times (timestamp queries at pass boundaries), when the adapter
    /// offers timestamps. `timings_ms` stays wall-clock time on the host.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gpu_timings_ms: Option<StageTimings>,
    /// GPU backend: which adapter rendered the frame.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub adapter: Option<AdapterReport>,
}

/// How many shadow maps (one per cascade, spot light or cube face) and probes a frame rendered;
/// the rest came from the cache.
#[derive(Debug, Clone, Copy, Default, Serialize, PartialEq, Eq)]
pub struct FallbackRenders {
    pub shadow_maps: u64,
    pub probes: u64,
    /// See-through layers (0 or 1: the layer is kept while the view stays close to its own).
    pub see_through: u64,
}

/// The GPU adapter a frame ran on.
#[derive(Debug, Clone, Serialize, PartialEq, Eq)]
pub struct AdapterReport {
    pub name: String,
    /// "vulkan", "metal", "dx12" or "gl".
    pub backend: String,
    /// "discrete-gpu", "integrated-gpu", "virtual-gpu", "cpu" (software, e.g. lavapipe) or "other".
    pub device_type: String,
    pub driver: String,
    /// Which traversal traced the frame's rays: "hw" (ray queries over acceleration structures)
    /// or "sw" (the BVH2 traversal in WGSL).
    pub ray_tracing: String,
}
