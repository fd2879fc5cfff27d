//! The sphere BVH's build: the core's binned SAH ([`crate::bvh_core::build`]) over the spheres'
//! boxes with the spheres' rules ([`SPHERE_RULES`]), then the core's collapse into 4-wide nodes
//! (the top two levels in parallel).

use glam::Vec3A;
use rayon::prelude::*;

use super::*;
use crate::bvh_core::build::{BuildNode, BuildRules, BuildTree, Prim, PrimBounds, build};
use crate::bvh_core::{LeafSink, PARALLEL_COLLAPSE_LEVELS, collapse};

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

impl<'a> LeafSink<&'a BuildNode> for SphereLeaves {
    fn leaf(&mut self, r: &'a BuildNode, _: &mut Vec<Node4>) -> u32 {
        match r {
            BuildNode::Leaf { first, count, .. } => leaf_ref(*first, *count),
            BuildNode::Inner { .. } => unreachable!("the collapse hands over leaves only"),
        }
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
        let (nodes, root, root_min, root_max, tree) = if prims.is_empty() {
            (Vec::new(), LEAF, Vec3::ZERO, Vec3::ZERO, None)
        } else {
            let pb = PrimBounds::of(&prims);
            let tree = build(&SPHERE_RULES, &mut prims, pb, 0, 0);
            let c = collapse(&BuildTree::NEW, &tree, PARALLEL_COLLAPSE_LEVELS, &|| SphereLeaves);
            (c.nodes, c.root, Vec3::from(pb.bounds.min), Vec3::from(pb.bounds.max), Some(tree))
        };
        let axis = |a: usize| {
            prims.par_iter().map(|p| centers[p.index() as usize][a]).chain(rayon::iter::repeat_n(0.0, LEAF_MAX - 1)).collect::<Vec<f32>>()
        };
        // The binary tree is freed (one free per inner node, serial otherwise) on one thread
        // while the others gather the centres in leaf order.
        let ((), (xs, ys, zs, indices)) =
            rayon::join(move || drop(tree), || (axis(0), axis(1), axis(2), prims.par_iter().map(Prim::index).collect()));
        Ok(Self { radius, xs, ys, zs, indices, nodes, root, root_min, root_max })
    }
}
