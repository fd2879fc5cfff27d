//! `hybrid-cpu`: the pure-Rust CPU backend. Each frame stage is a module with explicit inputs
//! and outputs; `frame` calls them in order.

pub mod bvh;
pub mod prepare;
pub mod trace;

pub use prepare::PreparedScene;
