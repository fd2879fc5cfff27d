//! The 4-wide BVH core that both of the CPU backend's BVHs are made of: the triangle BVH of the
//! trace stage ([`crate::bvh`]) and the sphere BVH of the point-cloud capsule
//! ([`crate::spheres`]). One node layout, one leaf reference, one collapse of a binary SAH tree
//! into 4-wide nodes, and one ordered closest-hit traversal, generic over the two things that
//! differ: how a ray tests a node's four boxes ([`NodeTest`]: the triangles' exact slabs, the
//! spheres' padded ones) and what a leaf holds (a closure: packs of four triangles, or up to
//! four spheres), so a change to any of these lands in both.

use glam::{Vec3A, Vec4};

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
/// offered, so the order of the visits changes the time taken, not the answer.
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

/// A binary BVH as a build made it, for [`collapse`].
pub(crate) trait BinaryTree: Sync {
    /// A node of the tree (inner or leaf), carrying what [`BinaryTree::bounds`] needs.
    type Ref: Copy + Send + Sync;
    /// The two children of an inner node; `None` for a leaf.
    fn children(&self, r: Self::Ref) -> Option<[Self::Ref; 2]>;
    /// The node's box.
    fn bounds(&self, r: Self::Ref) -> (Vec3A, Vec3A);
}

/// What the collapse makes of the binary tree's leaves.
pub(crate) trait LeafSink<R>: Send {
    /// The child reference of leaf `r` (it may add 4-wide nodes of its own to `nodes`, such as
    /// an extra node over the parts of an oversized leaf).
    fn leaf(&mut self, r: R, nodes: &mut Vec<Node4>) -> u32;
    /// Takes over the leaves of `later` (a subtree collapsed on its own, which comes after
    /// this one in depth-first order); returns what to add to the first field of its leaf
    /// references.
    fn append(&mut self, later: Self) -> u32;
}

/// A collapsed (sub)tree: its 4-wide nodes in depth-first order, its root reference (a node
/// index or a leaf reference) and its leaves' sink.
pub(crate) struct Collapsed<S> {
    pub(crate) nodes: Vec<Node4>,
    pub(crate) root: u32,
    pub(crate) sink: S,
}

/// The binary tree under `root` as 4-wide nodes, depth-first: each 4-wide node takes its binary
/// node's two children and opens the inner child of largest surface area (the later one on a
/// tie; its children take its place) until it has four or only leaves are left. The top
/// `parallel_levels` levels of 4-wide nodes collapse their children's subtrees in parallel,
/// each into its own nodes and sink (from `new_sink`), stitched after their parent: the same
/// nodes in the same order as with none in parallel. A serial collapse reserves
/// `node_capacity` nodes up front.
pub(crate) fn collapse<T: BinaryTree, S: LeafSink<T::Ref>>(
    tree: &T,
    root: T::Ref,
    parallel_levels: u32,
    node_capacity: usize,
    new_sink: &(impl Fn() -> S + Sync),
) -> Collapsed<S> {
    use rayon::prelude::*;
    let kids = match open_kids(tree, root) {
        Some(kids) if parallel_levels > 0 => kids,
        _ => {
            let (mut nodes, mut sink) = (Vec::with_capacity(node_capacity), new_sink());
            let root = collapse_into(tree, root, &mut nodes, &mut sink);
            return Collapsed { nodes, root, sink };
        }
    };
    let subs: Vec<Collapsed<S>> = kids.par_iter().map(|&k| collapse(tree, k, parallel_levels - 1, 0, new_sink)).collect();
    let mut nodes = Vec::with_capacity(1 + subs.iter().map(|s| s.nodes.len()).sum::<usize>());
    nodes.push(Node4::EMPTY);
    let mut node = Node4::EMPTY;
    let mut sink: Option<S> = None;
    for (k, (sub, &kid)) in subs.into_iter().zip(kids.iter()).enumerate() {
        let node_offset = nodes.len() as u32;
        let leaf_offset = match &mut sink {
            None => {
                sink = Some(sub.sink);
                0
            }
            Some(s) => s.append(sub.sink),
        };
        let shift = |c: u32| match c {
            EMPTY_SLOT => c,
            _ if c & LEAF != 0 => {
                let (first, count) = leaf_parts(c);
                leaf_ref(first as u32 + leaf_offset, count)
            }
            _ => c + node_offset,
        };
        nodes.extend(sub.nodes.into_iter().map(|mut n| {
            n.child = n.child.map(shift);
            n
        }));
        let (lo, hi) = tree.bounds(kid);
        node.set(k, lo, hi, shift(sub.root));
    }
    nodes[0] = node;
    Collapsed { nodes, root: 0, sink: sink.expect("an inner node has children") }
}

/// [`collapse`] of the subtree `r` into `nodes` and `sink`, serially; returns its reference.
fn collapse_into<T: BinaryTree, S: LeafSink<T::Ref>>(tree: &T, r: T::Ref, nodes: &mut Vec<Node4>, sink: &mut S) -> u32 {
    let Some(kids) = open_kids(tree, r) else { return sink.leaf(r, nodes) };
    let idx = nodes.len();
    nodes.push(Node4::EMPTY);
    let mut node = Node4::EMPTY;
    for (k, &kid) in kids.iter().enumerate() {
        let child = collapse_into(tree, kid, nodes, sink);
        let (lo, hi) = tree.bounds(kid);
        node.set(k, lo, hi, child);
    }
    nodes[idx] = node;
    idx as u32
}

/// The ≤ 4 children of the 4-wide node made from inner node `r` (`None` for a leaf): its two
/// children, then the inner child of largest surface area opened in place until there are four.
fn open_kids<T: BinaryTree>(tree: &T, r: T::Ref) -> Option<Kids<T::Ref>> {
    let [a, b] = tree.children(r)?;
    let mut kids = Kids::new(a, b);
    while kids.len() < 4 {
        let half_area = |r: T::Ref| {
            let (lo, hi) = tree.bounds(r);
            let d = (hi - lo).max(Vec3A::ZERO);
            d.x * d.y + d.y * d.z + d.z * d.x
        };
        let open =
            kids.iter().enumerate().filter_map(|(i, &k)| tree.children(k).map(|c| (i, half_area(k), c))).max_by(|a, b| a.1.total_cmp(&b.1));
        let Some((i, _, [first, second])) = open else { break };
        kids.open(i, first, second);
    }
    Some(kids)
}

/// The children of a 4-wide node being made (two to four).
#[derive(Clone, Copy)]
struct Kids<R: Copy> {
    items: [R; 4],
    len: usize,
}

impl<R: Copy> Kids<R> {
    fn new(a: R, b: R) -> Self {
        Self { items: [a, b, b, b], len: 2 }
    }
    fn len(&self) -> usize {
        self.len
    }
    /// Replaces child `i` by `first` and `second`, in its place.
    fn open(&mut self, i: usize, first: R, second: R) {
        self.items.copy_within(i + 1..self.len, i + 2);
        self.items[i] = first;
        self.items[i + 1] = second;
        self.len += 1;
    }
}

impl<R: Copy> std::ops::Deref for Kids<R> {
    type Target = [R];
    fn deref(&self) -> &[R] {
        &self.items[..self.len]
    }
}
