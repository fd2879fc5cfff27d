//! `hybrid-scene`: the scene model of the hybrid renderer, its TOML scene files, and the loaders
//! for models (glTF 2.0, OBJ+MTL, PLY), point clouds (PLY, LAS/LAZ) and textures (PNG, JPEG).
//!
//! Nothing here depends on a GPU API: a CPU-only user loads scenes without compiling wgpu.

pub mod camera;
pub mod error;
pub mod file;
pub mod load;
pub mod memory;
pub mod model;
pub mod model_scene;
pub mod normals;
pub mod primitives;
pub mod stats;
pub mod texture;

pub use camera::{Camera, CameraPath, Keyframe, Projection};
pub use error::SceneError;
pub use file::{
    DEMO_SCENE_TOML, MAX_TRACE_DEPTH, MAX_TRACED_DEPTH, TRACE_RAY_BUDGET, demo_scene, load_scene, load_scene_within, parse_scene,
    parse_scene_within,
};
pub use memory::{Bytes, MemoryLimit, parse_byte_size};
pub use model::*;
pub use model_scene::{ACCEPTED_INPUTS, InputKind, input_kind, load_scene_or_model, load_scene_or_model_within, model_scene_toml};
pub use normals::{DEFAULT_CREASE_ANGLE_DEG, compute_smooth_normals};
pub use stats::SceneStats;
pub use texture::{ColorSpace, Texture, TextureId};
