//! `hybrid-gpu`: the wgpu backend (design §1). The same stages as `hybrid-cpu`, as GPU passes
//! (WGSL beside the Rust in `src/shaders/`), headless on any wgpu adapter (Vulkan, Metal, DX12;
//! Mesa's lavapipe in CI) that can hold the frame's targets: OpenGL adapters are refused (see
//! `context`). The CPU backend is its oracle in tests.

pub mod accel;
pub mod blend;
pub mod bvh;
pub mod capsule;
pub mod context;
pub mod fallback;
pub mod frame;
pub mod heuristic;
#[cfg(test)]
mod layouts;
pub mod lighting;
pub mod primary;
pub mod raster;
pub mod readback;
pub mod scene;
pub mod shaders;
pub mod spheres;
pub mod targets;
pub mod timing;
pub mod trace;

pub use accel::{RtChoice, RtPath};
pub use context::{AdapterChoice, AdapterSummary, GpuContext, GpuError};
