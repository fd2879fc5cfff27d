//! `hybrid-cpu`: the pure-Rust CPU backend. Each frame stage is a module with explicit inputs
//! and outputs; `frame` calls them in order.

pub mod blend;
pub mod bvh;
pub mod capsule;
pub mod frame;
pub mod lighting;
pub mod prepare;
pub mod raster;
pub mod spheres;
pub mod trace;

#[cfg(test)]
mod test_rng;

pub use prepare::PreparedScene;
