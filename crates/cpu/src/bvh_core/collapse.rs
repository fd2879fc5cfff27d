//! The collapse of a binary SAH tree into the core's 4-wide nodes.

use glam::Vec3A;

use super::{EMPTY_SLOT, LEAF, Node4, leaf_parts, leaf_ref};

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

/// Levels of 4-wide nodes whose subtrees the BVH builds collapse in parallel (up to 16 subtrees,
/// enough for the threads of a small machine; each subtree's nodes are copied once more into
/// place, so more levels only add copying).
pub(crate) const PARALLEL_COLLAPSE_LEVELS: u32 = 2;

/// The binary tree under `root` as 4-wide nodes, depth-first: each 4-wide node takes its binary
/// node's two children and opens the inner child of largest surface area (the later one on a
/// tie; its children take its place) until it has four or only leaves are left. The top
/// `parallel_levels` levels of 4-wide nodes collapse their children's subtrees in parallel,
/// each into its own nodes and sink (from `new_sink`), stitched after their parent: the same
/// nodes in the same order as with none in parallel.
pub(crate) fn collapse<T: BinaryTree, S: LeafSink<T::Ref>>(
    tree: &T,
    root: T::Ref,
    parallel_levels: u32,
    new_sink: &(impl Fn() -> S + Sync),
) -> Collapsed<S> {
    use rayon::prelude::*;
    let kids = match open_kids(tree, root) {
        Some(kids) if parallel_levels > 0 => kids,
        _ => {
            let (mut nodes, mut sink) = (Vec::new(), new_sink());
            let root = collapse_into(tree, root, &mut nodes, &mut sink);
            return Collapsed { nodes, root, sink };
        }
    };
    let subs: Vec<Collapsed<S>> = kids.par_iter().map(|&k| collapse(tree, k, parallel_levels - 1, new_sink)).collect();
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

#[cfg(test)]
mod tests {
    use super::super::build::{BuildNode, BuildRules, BuildTree, Prim, PrimBounds, build};
    use super::*;
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    /// Leaves of up to four primitives, as references to their positions.
    struct Positions(usize);

    impl<'a> LeafSink<&'a BuildNode> for Positions {
        fn leaf(&mut self, r: &'a BuildNode, _: &mut Vec<Node4>) -> u32 {
            let BuildNode::Leaf { first, count, .. } = r else { unreachable!() };
            self.0 += 1;
            leaf_ref(*first, *count)
        }
        fn append(&mut self, later: Self) -> u32 {
            self.0 += later.0;
            0
        }
    }

    #[test]
    fn parallel_collapse_equals_serial_and_covers_every_primitive() {
        let rules = BuildRules {
            traversal_cost: 1.0,
            intersect_cost: 1.0,
            leaf_unit_shift: 0,
            max_leaf: 4,
            small_is_leaf: true,
            leaf_at_depth: u32::MAX,
            halve_at_depth: 64,
            widest_axis_only: false,
        };
        let mut rng = StdRng::seed_from_u64(3);
        let mut prims: Vec<Prim> = (0..20_000)
            .map(|i| {
                let c = Vec3A::new(rng.random_range(-50.0..50.0), rng.random_range(-5.0..5.0), rng.random_range(-20.0..20.0));
                Prim::new(i, c - Vec3A::splat(0.3), c + Vec3A::splat(0.3))
            })
            .collect();
        let pb = PrimBounds::of(&prims);
        let tree = build(&rules, &mut prims, pb, 0, 0);
        let serial = collapse(&BuildTree::NEW, &tree, 0, &|| Positions(0));
        for levels in [1, 2, 3] {
            let parallel = collapse(&BuildTree::NEW, &tree, levels, &|| Positions(0));
            assert_eq!((parallel.root, parallel.sink.0), (serial.root, serial.sink.0), "{levels} parallel levels");
            assert!(parallel.nodes == serial.nodes, "{levels} parallel levels: other nodes");
        }
        // Every position in exactly one leaf, inside every box on its way down.
        let mut seen = vec![0u32; prims.len()];
        let mut todo = vec![(serial.root, Vec3A::splat(f32::NEG_INFINITY), Vec3A::splat(f32::INFINITY))];
        while let Some((c, lo, hi)) = todo.pop() {
            if c == EMPTY_SLOT {
                continue;
            }
            if c & LEAF == 0 {
                let n = &serial.nodes[c as usize];
                todo.extend((0..4).map(|k| (n.child[k], n.child_box(k).0, n.child_box(k).1)));
                continue;
            }
            let (first, count) = leaf_parts(c);
            assert!((1..=4).contains(&count));
            for p in &prims[first..first + count as usize] {
                seen[p.index() as usize] += 1;
                let b = p.bounds();
                assert!(lo.cmple(b.min).all() && b.max.cmple(hi).all());
            }
        }
        assert!(seen.iter().all(|&s| s == 1));
    }
}
