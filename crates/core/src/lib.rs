//! `hybrid-core`: what every backend shares — the frame's modes and settings, the buffers of
//! design §2, the shading and blend formulas of paper 1 (listings 5, 8, 10), the depth synthesis
//! and packing of paper 2, and the per-frame report. Backends implement the stages; the maths
//! they must agree on lives here, once.

pub mod blend;
pub mod buffer_view;
pub mod buffers;
pub mod depth_merge;
pub mod fallback;
pub mod frame;
pub mod lanes;
pub mod memory;
pub mod point_colors;
pub mod prepare;
pub mod report;
pub mod shading;
pub mod stage;
#[cfg(any(test, feature = "test-support"))]
pub mod test_rng;

pub use buffers::{FrameBuffers, GBuffer, NO_OBJECT, RT_SCENE_OBJECT, RtLayer, Surface, is_polygon};
pub use frame::{Frame, FrameSettings, Mode};
pub use prepare::PreparedScene;
pub use stage::Stage;
