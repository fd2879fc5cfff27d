//! `hybrid-cpu`: the pure-Rust CPU backend. Each frame stage is a module with explicit inputs
//! and outputs; `frame` calls them in order.

pub mod prepare;

pub use prepare::PreparedScene;
