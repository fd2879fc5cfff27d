//! The 4-wide BVH core that both of the CPU backend's BVHs are made of: the triangle BVH of the
//! trace stage ([`crate::bvh`]) and the sphere BVH of the point-cloud capsule
//! ([`crate::spheres`]). One node layout, one leaf reference, one build of 4-wide nodes from
//! binned SAH splits, and one ordered closest-hit traversal, generic over the two things that
//! differ: how a ray tests a node's four boxes ([`NodeTest`]: the triangles' exact slabs, the
//! spheres' padded ones) and what a leaf holds (a closure: packs of four triangles, or up to
//! four spheres), so a change to any of these lands in both.

use glam::{Vec3A, Vec4};

pub(crate) mod build;
mod wide;

pub(crate) use wide::{LeafSink, Wide, build_wide};

/// Set in a child reference that names a leaf; the rest of the bits are the leaf's own
/// (`first << LEAF_COUNT_BITS | count bits`, see [`leaf_ref`]).
pub(crate) const LEAF: u32 = 1 << 31;
/// Low bits of a leaf reference that hold its count (of triangle packs − 1, or of spheres).
pub(crate) const LEAF_COUNT_BITS: u32 = 4;
/// The child reference of an unused slot (its box is empty, so no ray enters it).
pub(crate) const EMPTY_SLOT: u32 = u32::MAX;

/// Length of the traversal stacks (a power of two). A 4-wide node stacks at most three
/// children, and a path is at most 91 binary levels deep (the sphere build's 64 SAH levels and
/// then halving by count, ≤ 27 more for 2²⁷ spheres; the triangle build stops at 56 plus the
/// ≤ 8 levels an oversized leaf adds), so at most 273 entries are ever stacked.
pub(crate) const STACK_LEN: usize = 512;

/// A leaf reference: `first` (a pack or a sphere slot) and the leaf's `count` bits.
#[inline]
pub(crate) fn leaf_ref(first: u32, count_bits: u32) -> u32 {
    debug_assert!(first < 1 << (31 - LEAF_COUNT_BITS) && count_bits < 1 << LEAF_COUNT_BITS);
    LEAF | first << LEAF_COUNT_BITS | count_bits
}

/// The first pack or slot of leaf reference `c`, and its count bits.
#[inline(always)]
pub(crate) fn leaf_parts(c: u32) -> (usize, u32) {
    (((c & !LEAF) >> LEAF_COUNT_BITS) as usize, c & ((1 << LEAF_COUNT_BITS) - 1))
}

/// A 4-wide node (SoA child boxes, tested together with 4-lane SIMD): `planes[axis]` /
/// `planes[3 + axis]` hold the four children's box minima/maxima on that axis (one array, so a
/// ray can pick its entry and exit planes by a precomputed index instead of a per-node select).
/// `child[k]` is an inner node index, a leaf reference, or [`EMPTY_SLOT`].
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C, align(64))]
pub(crate) struct Node4 {
    pub(crate) planes: [Vec4; 6],
    pub(crate) child: [u32; 4],
}

impl Node4 {
    pub(crate) const EMPTY: Node4 = Node4 {
        planes: [Vec4::INFINITY, Vec4::INFINITY, Vec4::INFINITY, Vec4::NEG_INFINITY, Vec4::NEG_INFINITY, Vec4::NEG_INFINITY],
        child: [EMPTY_SLOT; 4],
    };

    /// Child slot `k`: box `min..max` and reference `child`.
    #[inline]
    pub(crate) fn set(&mut self, k: usize, min: Vec3A, max: Vec3A, child: u32) {
        for axis in 0..3 {
            self.planes[axis][k] = min[axis];
            self.planes[3 + axis][k] = max[axis];
        }
        self.child[k] = child;
    }

    /// The four children's box minima on `axis`.
    #[inline(always)]
    pub(crate) fn lo(&self, axis: usize) -> Vec4 {
        self.planes[axis]
    }

    /// The four children's box maxima on `axis`.
    #[inline(always)]
    pub(crate) fn hi(&self, axis: usize) -> Vec4 {
        self.planes[3 + axis]
    }

    /// Child slot `k`'s box.
    #[inline]
    pub(crate) fn child_box(&self, k: usize) -> (Vec3A, Vec3A) {
        (
            Vec3A::new(self.planes[0][k], self.planes[1][k], self.planes[2][k]),
            Vec3A::new(self.planes[3][k], self.planes[4][k], self.planes[5][k]),
        )
    }
}

/// How one ray tests a node's four child boxes.
pub(crate) trait NodeTest {
    /// The children's entry distances and the bit mask of those the ray enters before `best_t`
    /// (its closest hit so far). Entries are ordered by the bits of their entry distance, so
    /// they should be ≥ 0 for the best order (a wrong order only costs time).
    fn enter(&self, n: &Node4, best_t: f32) -> (Vec4, u32);
    /// Whether a stacked child entered at `near` may still hold a hit at or before `best_t`.
    fn may_enter(&self, near: f32, best_t: f32) -> bool;
}

/// A stack entry of [`closest_walk`]: entry distance bits above, child reference below.
#[inline(always)]
pub(crate) fn stack_entry(child: u32, near: f32) -> u64 {
    (near.to_bits() as u64) << 32 | child as u64
}

/// Ordered closest-hit traversal of `nodes` from `start` (a node index or a leaf reference),
/// then from the entries `stack[..sp]` (see [`stack_entry`]; pushed last first). Hit children
/// are visited nearest first and the others stacked; an entry is skipped when
/// [`NodeTest::may_enter`] says it starts beyond `best_t`. `leaf(reference, best_t)` tests a
/// leaf and returns the new `best_t` (lower on a hit) and whether to stop the walk there (an
/// any-hit query).
///
/// Whatever the leaf test's tie rule, the hit found is the one it prefers among all it is
/// offered, so the order of the visits changes the time taken, not the answer, with one
/// exception: a ray through an edge two triangles share, where rounding puts one triangle's
/// hit a few ulps before its box's entry distance, keeps whichever it meets first.
#[inline(always)]
pub(crate) fn closest_walk<N: NodeTest>(
    nodes: &[Node4],
    stack: &mut [u64; STACK_LEN],
    mut sp: usize,
    start: u32,
    best_t: &mut f32,
    test: &N,
    mut leaf: impl FnMut(u32, f32) -> (f32, bool),
) {
    // Entries still to visit are `stack[..sp]`, indexed modulo the power-of-two length (no
    // bounds check; it cannot fill, see `STACK_LEN`).
    const WRAP: usize = STACK_LEN - 1;
    let mut t = *best_t;
    let mut cur = start;
    loop {
        if cur & LEAF == 0 {
            let n = &nodes[cur as usize];
            let (near, mask) = test.enter(n, t);
            if mask != 0 {
                if mask & (mask - 1) == 0 {
                    cur = n.child[mask.trailing_zeros() as usize & 3];
                    continue;
                }
                // Several children: sort them by entry distance (farthest first) with a
                // branch-free sorting network on `distance bits << 32 | child` keys; stack all
                // but the nearest, visit that one. Children missed get key 0, also without a
                // branch (a hit's key is never 0: the root, node 0, is nobody's child).
                let near = near.to_array();
                let key = |c: usize| stack_entry(n.child[c], near[c]) & (u64::from(mask >> c & 1)).wrapping_neg();
                let mut k = [key(0), key(1), key(2), key(3)];
                let mut swap = |a: usize, b: usize| {
                    let (x, y) = (k[a], k[b]);
                    k[a] = x.max(y);
                    k[b] = x.min(y);
                };
                swap(0, 1);
                swap(2, 3);
                swap(0, 2);
                swap(1, 3);
                swap(1, 2);
                let hits = mask.count_ones() as usize;
                // All three written, the stack grown by the hits but the nearest.
                debug_assert!(sp + 3 <= STACK_LEN, "traversal stack overflow");
                for (j, &key) in k[..3].iter().enumerate() {
                    stack[(sp + j) & WRAP] = key;
                }
                sp += hits - 1;
                cur = k[(hits - 1) & 3] as u32;
                continue;
            }
        } else {
            let stop;
            (t, stop) = leaf(cur, t);
            if stop {
                *best_t = t;
                return;
            }
        }
        // Pop the next entry that may start before the closest hit so far.
        loop {
            if sp == 0 {
                *best_t = t;
                return;
            }
            sp -= 1;
            let key = stack[sp & WRAP];
            if test.may_enter(f32::from_bits((key >> 32) as u32), t) {
                cur = key as u32;
                break;
            }
        }
    }
}
