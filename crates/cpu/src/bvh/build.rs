//! The triangle BVH's build: the core's 4-wide build from binned SAH splits over all three
//! axes with the triangles' rules ([`TRIANGLE_RULES`]), with leaf packs.
//! Deterministic for any thread count.

use super::*;
use crate::bvh_core::build::{Bounds, BuildRules, Prim, PrimBounds};
use crate::bvh_core::{LeafSink, Wide, build_wide};

/// Leaves are forced below this many triangles unless the centroids coincide.
pub(super) const MAX_LEAF: usize = 8;
/// Nodes at this depth become leaves whatever their size, so traversal stacks stay bounded.
pub(super) const MAX_DEPTH: u32 = 56;
/// SAH: cost of a 4-wide node test relative to a 4-triangle test.
pub(super) const TRAVERSAL_COST: f32 = 1.0;
pub(super) const INTERSECT_COST: f32 = 0.6;

/// The triangle BVH's SAH: leaves cost by packs of four triangles, at most [`MAX_LEAF`]
/// triangles unless [`MAX_DEPTH`] is reached (an oversized leaf is then split under extra nodes
/// by the packer).
pub(super) const TRIANGLE_RULES: BuildRules = BuildRules {
    traversal_cost: TRAVERSAL_COST,
    intersect_cost: INTERSECT_COST,
    // Triangles are tested four at a time (one pack).
    leaf_unit_shift: 2,
    max_leaf: MAX_LEAF,
    small_is_leaf: false,
    leaf_at_depth: MAX_DEPTH,
    halve_at_depth: u32::MAX,
    widest_axis_only: false,
};

/// The build's primitive of triangle `index` with corners `corners`. Non-finite corners make a
/// point box: such triangles can never be hit anyway.
#[inline(always)]
pub(super) fn triangle_prim(index: u32, corners: [Vec3; 3]) -> Prim {
    let [a, b, d] = corners.map(Vec3A::from);
    if !(a.is_finite() && b.is_finite() && d.is_finite()) {
        return Prim::new(index, Vec3A::ZERO, Vec3A::ZERO);
    }
    Prim::new(index, a.min(b).min(d), a.max(b).max(d))
}

/// Lays out leaf packs in depth-first leaf order during the build (the packs themselves are
/// filled afterwards, in parallel, from these descriptors).
pub(super) struct Packer {
    /// Per pack: first position in the build's final primitive order and number of triangles
    /// (1–4).
    pub(super) packs: Vec<(u32, u32)>,
    pub(super) leaves: usize,
}

impl LeafSink for Packer {
    /// Packs the triangles `prims`, at positions `first..` of the final order; returns the
    /// reference to them: a leaf, or an extra node over up to four leaves when they need more
    /// than [`MAX_LEAF_PACKS`] packs.
    fn leaf(&mut self, first: u32, prims: &[Prim], nodes: &mut Vec<Node4>) -> u32 {
        let count = prims.len() as u32;
        let n_packs = (count as usize).div_ceil(4);
        if n_packs <= MAX_LEAF_PACKS {
            let start = self.packs.len() as u32;
            for chunk in (first..first + count).step_by(4) {
                self.packs.push((chunk, (first + count - chunk).min(4)));
            }
            self.leaves += 1;
            return leaf_ref(start, n_packs as u32 - 1);
        }
        // Triangles per part: a multiple of 4, at most four parts.
        let part = n_packs.div_ceil(4) * 4;
        let idx = nodes.len();
        nodes.push(Node4::EMPTY);
        let mut node = Node4::EMPTY;
        for (k, run) in prims.chunks(part).enumerate() {
            let mut b = Bounds::EMPTY;
            run.iter().for_each(|p| b.grow(&p.bounds()));
            let r = self.leaf(first + (k * part) as u32, run, nodes);
            node.set(k, b.min, b.max, r);
        }
        nodes[idx] = node;
        idx as u32
    }

    fn append(&mut self, later: Self) -> u32 {
        let offset = self.packs.len() as u32;
        self.packs.extend(later.packs);
        self.leaves += later.leaves;
        offset
    }
}

impl SceneBvh {
    /// Builds the BVH over `prepared.triangles`.
    pub fn build(prepared: &PreparedScene) -> SceneBvh {
        // The corners are read from the prepared meshes twice (here and for the packs) rather
        // than gathered into an array of their own: a fresh array costs a page fault per 4 KiB
        // written (about 2 µs each on a VM), about as much as the gather itself.
        let mut prims: Vec<Prim> =
            prepared.triangles.par_iter().enumerate().map(|(i, t)| triangle_prim(i as u32, prepared.triangle(*t))).collect();

        let pack_capacity = prims.len() / 3;
        let new_packer = || Packer { packs: Vec::with_capacity(pack_capacity), leaves: 0 };
        let (nodes, Packer { packs: descs, leaves }) = if prims.is_empty() {
            (Vec::new(), new_packer())
        } else {
            let pb = PrimBounds::of(&prims);
            match build_wide(&TRIANGLE_RULES, &mut prims, pb, &new_packer) {
                // A single leaf: a root node with one child.
                Wide { nodes, root, sink } if root & LEAF != 0 => {
                    let mut root_node = Node4::EMPTY;
                    root_node.set(0, pb.bounds.min, pb.bounds.max, root);
                    debug_assert!(nodes.is_empty(), "a leaf at the root is never oversized");
                    (vec![root_node], sink)
                }
                Wide { nodes, sink, .. } => (nodes, sink),
            }
        };

        // Per pack lane (slot), in parallel passes that each write their array once: the
        // triangle (`NO_TRI` in unused lanes) and its shadow transparency; then per pack the
        // triangle data and the shadow bits.
        let slot_ref: Vec<TriangleRef> = (0..descs.len() * 4)
            .into_par_iter()
            .map(|slot| {
                let (first, n) = descs[slot / 4];
                let lane = (slot % 4) as u32;
                if lane < n { prepared.triangles[prims[(first + lane) as usize].index() as usize] } else { NO_TRI }
            })
            .collect();
        let triangles = prims.len();
        drop(prims);
        let slot_shadow: Vec<f32> =
            slot_ref.par_iter().map(|t| if *t == NO_TRI { 1.0 } else { prepared.mesh_shadow(t.mesh as usize) }).collect();
        let packs: Vec<Tri4> = slot_ref
            .par_chunks_exact(4)
            .map(|refs| {
                let mut p = Tri4::EMPTY;
                for (lane, &t) in refs.iter().enumerate().filter(|(_, t)| **t != NO_TRI) {
                    let [a, b, c] = prepared.triangle(t);
                    let (e1, e2) = (b - a, c - a);
                    for axis in 0..3 {
                        p.v0[axis][lane] = a[axis];
                        p.e1[axis][lane] = e1[axis];
                        p.e2[axis][lane] = e2[axis];
                    }
                }
                p
            })
            .collect();
        // Bits 0–3: lanes that can block light; bits 4–7: lanes that block it fully.
        let pack_shadow: Vec<u8> = slot_shadow
            .par_chunks_exact(4)
            .map(|l| (0..4).fold(0u8, |bits, k| bits | u8::from(l[k] != 1.0) << k | u8::from(l[k] == 0.0) << (k + 4)))
            .collect();
        SceneBvh { nodes, packs, pack_shadow, slot_ref, slot_shadow, triangles, leaves }
    }
}
