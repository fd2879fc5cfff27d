//! The build of the core's 4-wide nodes, straight from the binned SAH splits: each 4-wide node
//! takes the two parts its primitives split into, then splits the inner part of largest surface
//! area in place (the later one on a tie) until it has four or only leaves are left. So the
//! nodes are those a binary SAH tree collapsed that way would give, in the same depth-first
//! order, without the binary tree: no node of it is allocated, walked again or freed (a test
//! builds that tree and collapses it, and compares).

use rayon::prelude::*;

use super::build::{Bounds, BuildRules, PARALLEL_MIN, Prim, PrimBounds, split_node};
use super::{EMPTY_SLOT, LEAF, Node4, leaf_parts, leaf_ref};

/// What the build makes of the leaves.
pub(crate) trait LeafSink: Send {
    /// The child reference of the leaf over `prims`, the positions `first..` of the final
    /// order (it may add 4-wide nodes of its own to `nodes`, such as an extra node over the
    /// parts of an oversized leaf).
    fn leaf(&mut self, first: u32, prims: &[Prim], nodes: &mut Vec<Node4>) -> u32;
    /// Takes over the leaves of `later` (a subtree built on its own, which comes after this
    /// one in depth-first order); returns what to add to the first field of its leaf
    /// references.
    fn append(&mut self, later: Self) -> u32;
}

/// A built (sub)tree: its 4-wide nodes in depth-first order, its root reference (a node index
/// or a leaf reference) and its leaves' sink.
pub(crate) struct Wide<S> {
    pub(crate) nodes: Vec<Node4>,
    pub(crate) root: u32,
    pub(crate) sink: S,
}

/// Levels of 4-wide nodes whose subtrees are built in parallel (up to 16 subtrees, enough for
/// the threads of a small machine; each subtree's nodes are copied once more into place, so
/// more levels only add copying). Splits of large parts below them still run in parallel.
pub(crate) const PARALLEL_WIDE_LEVELS: u32 = 2;

/// The 4-wide tree over `prims` (their boxes and centroid boxes `pb`), partitioned in place into
/// its leaf order. The top [`PARALLEL_WIDE_LEVELS`] levels build their children's subtrees in
/// parallel, each into its own nodes and sink (from `new_sink`), stitched after their parent:
/// the same nodes in the same order as one thread would make.
pub(crate) fn build_wide<S: LeafSink>(
    rules: &BuildRules,
    prims: &mut [Prim],
    pb: PrimBounds,
    new_sink: &(impl Fn() -> S + Sync),
) -> Wide<S> {
    let root = part(rules, prims, 0, pb, 0);
    wide(rules, prims, root, PARALLEL_WIDE_LEVELS, new_sink)
}

/// A run of primitives (a node of the binary SAH tree) and the split the build made of it.
#[derive(Clone, Copy)]
struct Part {
    /// Position of its first primitive, and how many.
    first: u32,
    len: u32,
    bounds: Bounds,
    /// Binary depth (the rules' depth limits count binary levels).
    depth: u32,
    /// `None` for a leaf; else the left part's length and both parts' boxes, the primitives
    /// already partitioned.
    split: Option<(usize, PrimBounds, PrimBounds)>,
}

/// The part over `prims` (positions `first..`), split.
fn part(rules: &BuildRules, prims: &mut [Prim], first: u32, pb: PrimBounds, depth: u32) -> Part {
    let split = split_node(rules, prims, pb, depth);
    Part { first, len: prims.len() as u32, bounds: pb.bounds, depth, split }
}

/// The two parts inner part `p` (over `prims`) splits into, each split in turn (in parallel
/// when large).
fn halves(rules: &BuildRules, prims: &mut [Prim], p: &Part) -> [Part; 2] {
    let (mid, lb, rb) = p.split.expect("only inner parts have halves");
    let large = prims.len() >= PARALLEL_MIN;
    let (l, r) = prims.split_at_mut(mid);
    let (first_r, depth) = (p.first + mid as u32, p.depth + 1);
    if large {
        let (a, b) = rayon::join(|| part(rules, l, p.first, lb, depth), || part(rules, r, first_r, rb, depth));
        [a, b]
    } else {
        [part(rules, l, p.first, lb, depth), part(rules, r, first_r, rb, depth)]
    }
}

/// The 2–4 children of the 4-wide node of inner part `p` (over `prims`): its halves, then the
/// inner child of largest surface area replaced by its halves until there are four.
fn open_kids(rules: &BuildRules, prims: &mut [Prim], p: &Part) -> Kids {
    let [a, b] = halves(rules, prims, p);
    let mut kids = Kids { items: [a, b, b, b], len: 2 };
    while kids.len < 4 {
        let open = kids.items[..kids.len]
            .iter()
            .enumerate()
            .filter(|(_, k)| k.split.is_some())
            .map(|(i, k)| (i, k.bounds.half_area()))
            .max_by(|a, b| a.1.total_cmp(&b.1));
        let Some((i, _)) = open else { break };
        let k = kids.items[i];
        let start = (k.first - p.first) as usize;
        let [first, second] = halves(rules, &mut prims[start..start + k.len as usize], &k);
        kids.items.copy_within(i + 1..kids.len, i + 2);
        kids.items[i] = first;
        kids.items[i + 1] = second;
        kids.len += 1;
    }
    kids
}

/// The children of a 4-wide node being made (two to four), in primitive order.
struct Kids {
    items: [Part; 4],
    len: usize,
}

/// [`build_wide`] below part `p` (over `prims`), the top `levels` levels in parallel.
fn wide<S: LeafSink>(rules: &BuildRules, prims: &mut [Prim], p: Part, levels: u32, new_sink: &(impl Fn() -> S + Sync)) -> Wide<S> {
    if p.split.is_none() || levels == 0 {
        let (mut nodes, mut sink) = (Vec::new(), new_sink());
        let root = wide_into(rules, prims, &p, &mut nodes, &mut sink);
        return Wide { nodes, root, sink };
    }
    let kids = open_kids(rules, prims, &p);
    let kids = &kids.items[..kids.len];
    // Each child's primitives: consecutive runs, in order.
    let mut runs = Vec::with_capacity(kids.len());
    let mut rest = prims;
    for k in kids {
        let (run, tail) = rest.split_at_mut(k.len as usize);
        runs.push((run, *k));
        rest = tail;
    }
    let subs: Vec<Wide<S>> = runs.into_par_iter().map(|(run, k)| wide(rules, run, k, levels - 1, new_sink)).collect();
    let mut nodes = Vec::with_capacity(1 + subs.iter().map(|s| s.nodes.len()).sum::<usize>());
    nodes.push(Node4::EMPTY);
    let mut node = Node4::EMPTY;
    let mut sink: Option<S> = None;
    for (slot, (sub, kid)) in subs.into_iter().zip(kids).enumerate() {
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
        node.set(slot, kid.bounds.min, kid.bounds.max, shift(sub.root));
    }
    nodes[0] = node;
    Wide { nodes, root: 0, sink: sink.expect("an inner node has children") }
}

/// [`wide`] of part `p` (over `prims`) into `nodes` and `sink`, on this thread; returns its
/// reference.
fn wide_into<S: LeafSink>(rules: &BuildRules, prims: &mut [Prim], p: &Part, nodes: &mut Vec<Node4>, sink: &mut S) -> u32 {
    if p.split.is_none() {
        return sink.leaf(p.first, prims, nodes);
    }
    let kids = open_kids(rules, prims, p);
    let idx = nodes.len();
    nodes.push(Node4::EMPTY);
    let mut node = Node4::EMPTY;
    for (slot, kid) in kids.items[..kids.len].iter().enumerate() {
        let start = (kid.first - p.first) as usize;
        let child = wide_into(rules, &mut prims[start..start + kid.len as usize], kid, nodes, sink);
        node.set(slot, kid.bounds.min, kid.bounds.max, child);
    }
    nodes[idx] = node;
    idx as u32
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3A;
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    /// Leaves as references to their positions (up to 15 primitives).
    struct Positions(usize);

    impl LeafSink for Positions {
        fn leaf(&mut self, first: u32, prims: &[Prim], _: &mut Vec<Node4>) -> u32 {
            self.0 += 1;
            leaf_ref(first, prims.len() as u32)
        }
        fn append(&mut self, later: Self) -> u32 {
            self.0 += later.0;
            0
        }
    }

    /// The oracle: a binary tree of the same splits, built whole first.
    enum Binary {
        Leaf { bounds: Bounds, first: u32, count: u32 },
        Inner { bounds: Bounds, children: Box<(Binary, Binary)> },
    }

    impl Binary {
        fn build(rules: &BuildRules, prims: &mut [Prim], pb: PrimBounds, first: u32, depth: u32) -> Binary {
            let Some((mid, lb, rb)) = split_node(rules, prims, pb, depth) else {
                return Binary::Leaf { bounds: pb.bounds, first, count: prims.len() as u32 };
            };
            let (l, r) = prims.split_at_mut(mid);
            let children = (Self::build(rules, l, lb, first, depth + 1), Self::build(rules, r, rb, first + mid as u32, depth + 1));
            Binary::Inner { bounds: pb.bounds, children: Box::new(children) }
        }
        fn bounds(&self) -> Bounds {
            match self {
                Binary::Leaf { bounds, .. } | Binary::Inner { bounds, .. } => *bounds,
            }
        }
        /// Collapsed into 4-wide nodes: each takes its node's two children and opens the inner
        /// child of largest area (the later on a tie) until it has four.
        fn collapse(&self, nodes: &mut Vec<Node4>) -> u32 {
            let Binary::Inner { children, .. } = self else {
                let Binary::Leaf { first, count, .. } = self else { unreachable!() };
                return leaf_ref(*first, *count);
            };
            let mut kids: Vec<&Binary> = vec![&children.0, &children.1];
            while kids.len() < 4 {
                let open = kids
                    .iter()
                    .enumerate()
                    .filter(|(_, k)| matches!(k, Binary::Inner { .. }))
                    .map(|(i, k)| (i, k.bounds().half_area()))
                    .max_by(|a, b| a.1.total_cmp(&b.1));
                let Some((i, _)) = open else { break };
                let Binary::Inner { children, .. } = kids[i] else { unreachable!() };
                kids.splice(i..=i, [&children.0, &children.1]);
            }
            let idx = nodes.len();
            nodes.push(Node4::EMPTY);
            let mut node = Node4::EMPTY;
            for (slot, kid) in kids.into_iter().enumerate() {
                let child = kid.collapse(nodes);
                let b = kid.bounds();
                node.set(slot, b.min, b.max, child);
            }
            nodes[idx] = node;
            idx as u32
        }
    }

    fn rules(small_is_leaf: bool, widest_axis_only: bool) -> BuildRules {
        BuildRules {
            traversal_cost: 1.0,
            intersect_cost: if small_is_leaf { 1.0 } else { 0.6 },
            leaf_unit_shift: if small_is_leaf { 0 } else { 2 },
            max_leaf: if small_is_leaf { 4 } else { 8 },
            small_is_leaf,
            leaf_at_depth: 56,
            halve_at_depth: if small_is_leaf { 12 } else { u32::MAX },
            widest_axis_only,
        }
    }

    #[test]
    fn wide_build_equals_the_binary_tree_collapsed_and_covers_every_primitive() {
        let mut rng = StdRng::seed_from_u64(3);
        // Spread and clustered boxes, the later ones on a few coincident centres (the halving
        // and count splits), over both BVHs' rules.
        let boxes: Vec<Prim> = (0..30_000)
            .map(|i| {
                let c = if i % 5 == 4 {
                    Vec3A::splat((i % 3) as f32)
                } else {
                    Vec3A::new(rng.random_range(-50.0..50.0), rng.random_range(-5.0..5.0), rng.random_range(-20.0..20.0))
                };
                let r = Vec3A::new(rng.random_range(0.01..0.5), rng.random_range(0.01..0.5), rng.random_range(0.01..0.5));
                Prim::new(i, c - r, c + r)
            })
            .collect();
        for rules in [rules(false, false), rules(true, true), rules(true, false)] {
            let mut oracle_prims = boxes.clone();
            let pb = PrimBounds::of(&oracle_prims);
            let tree = Binary::build(&rules, &mut oracle_prims, pb, 0, 0);
            let mut oracle = Vec::new();
            let oracle_root = tree.collapse(&mut oracle);

            let mut prims = boxes.clone();
            let wide = build_wide(&rules, &mut prims, pb, &|| Positions(0));
            assert_eq!(wide.root, oracle_root);
            assert!(wide.nodes == oracle, "other nodes");
            assert!(prims.iter().zip(&oracle_prims).all(|(a, b)| a.index() == b.index()), "other leaf order");
            // One thread's build (no subtree built apart): the same.
            let mut serial_prims = boxes.clone();
            let root = part(&rules, &mut serial_prims, 0, pb, 0);
            let (mut serial, mut serial_leaves) = (Vec::new(), Positions(0));
            assert_eq!(wide_into(&rules, &mut serial_prims, &root, &mut serial, &mut serial_leaves), oracle_root);
            assert!(serial == oracle, "other nodes on one thread");

            // Every position in exactly one leaf, inside every box on its way down.
            let mut seen = vec![0u32; prims.len()];
            let mut todo = vec![(wide.root, Vec3A::splat(f32::NEG_INFINITY), Vec3A::splat(f32::INFINITY))];
            while let Some((c, lo, hi)) = todo.pop() {
                if c == EMPTY_SLOT {
                    continue;
                }
                if c & LEAF == 0 {
                    let n = &wide.nodes[c as usize];
                    todo.extend((0..4).map(|k| (n.child[k], n.child_box(k).0, n.child_box(k).1)));
                    continue;
                }
                let (first, count) = leaf_parts(c);
                assert!((1..=15).contains(&count));
                for p in &prims[first..first + count as usize] {
                    seen[p.index() as usize] += 1;
                    let b = p.bounds();
                    assert!(lo.cmple(b.min).all() && b.max.cmple(hi).all());
                }
            }
            assert!(seen.iter().all(|&s| s == 1));
            // Every leaf handed to the sink once, by either build.
            let leaves = oracle.iter().flat_map(|n| n.child).filter(|&c| c != EMPTY_SLOT && c & LEAF != 0).count();
            assert_eq!((wide.sink.0, serial_leaves.0), (leaves, leaves));
        }
    }
}
