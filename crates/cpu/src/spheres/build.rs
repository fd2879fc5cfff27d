//! The sphere BVH's build: the core's 4-wide build from binned SAH splits
//! ([`crate::bvh_core::build_wide`]) over the spheres' boxes with the spheres' rules
//! ([`SPHERE_RULES`]).

use glam::Vec3A;
use rayon::prelude::*;

use super::*;
use crate::bvh_core::build::{BuildRules, Prim, PrimBounds};
use crate::bvh_core::{LeafSink, build_wide};

/// The sphere BVH's SAH: leaves of at most [`LEAF_MAX`] spheres (tested four at a time), bins
/// along the widest axis only, and past depth 64 (pathological distributions) halving by count,
/// which bounds the depth below the traversal stack's.
pub(super) const SPHERE_RULES: BuildRules = BuildRules {
    traversal_cost: 1.0,
    intersect_cost: 1.0,
    leaf_unit_shift: 0,
    max_leaf: LEAF_MAX,
    small_is_leaf: true,
    leaf_at_depth: u32::MAX,
    halve_at_depth: 64,
    widest_axis_only: true,
};

/// The spheres' leaves become leaf references to their slots (in leaf order).
struct SphereLeaves;

impl LeafSink for SphereLeaves {
    fn leaf(&mut self, first: u32, prims: &[Prim], _: &mut Vec<Node4>) -> u32 {
        leaf_ref(first, prims.len() as u32)
    }
    fn append(&mut self, _: Self) -> u32 {
        0
    }
}

impl SphereBvh {
    /// Builds the BVH over spheres of one `radius` at `centers`.
    pub fn build(centers: &[Vec3], radius: f32) -> Result<Self, SphereBvhError> {
        if !(radius.is_finite() && radius > 0.0) {
            return Err(SphereBvhError::BadRadius(radius));
        }
        if centers.len() > MAX_SPHERES {
            return Err(SphereBvhError::TooManySpheres(centers.len()));
        }
        if let Some(i) = centers.iter().position(|c| !c.is_finite()) {
            return Err(SphereBvhError::NonFiniteCenter(i));
        }
        let r = Vec3A::splat(radius);
        let mut prims: Vec<Prim> = centers
            .par_iter()
            .enumerate()
            .map(|(i, &c)| {
                let c = Vec3A::from(c);
                Prim::new(i as u32, c - r, c + r)
            })
            .collect();
        // A node's box is its centres' box grown by `r` (x ↦ x ± r rounds monotonically).
        let (nodes, root, root_min, root_max) = if prims.is_empty() {
            (Vec::new(), LEAF, Vec3::ZERO, Vec3::ZERO)
        } else {
            let pb = PrimBounds::of(&prims);
            let c = build_wide(&SPHERE_RULES, &mut prims, pb, &|| SphereLeaves);
            (c.nodes, c.root, Vec3::from(pb.bounds.min), Vec3::from(pb.bounds.max))
        };
        let axis = |a: usize| {
            prims.par_iter().map(|p| centers[p.index() as usize][a]).chain(rayon::iter::repeat_n(0.0, LEAF_MAX - 1)).collect::<Vec<f32>>()
        };
        let (xs, ys, zs, indices) = (axis(0), axis(1), axis(2), prims.par_iter().map(Prim::index).collect());
        Ok(Self { radius, xs, ys, zs, indices, nodes, root, root_min, root_max })
    }
}
