//! `hybrid-cpu`: the pure-Rust CPU backend. Each frame stage is a module with explicit inputs
//! and outputs; `frame` calls them in order.

pub mod blend;
pub mod bvh;
pub(crate) mod bvh_core;
pub mod camera_rays;
pub mod capsule;
pub mod depth_merge;
pub mod fallback;
pub mod frame;
pub mod isa;
pub mod lighting;
pub mod raster;
pub mod spheres;
pub mod trace;
