//! The sphere BVH's build: binned SAH over the centres (parallel for large nodes), collapsed
//! into 4-wide nodes in parallel.

use super::*;
use crate::bvh_core::{BinaryTree, LeafSink, collapse};

/// Build-time item: a centre and its original index (16 bytes).
#[derive(Debug, Clone, Copy)]
pub(super) struct Item {
    pub(super) c: [f32; 3],
    pub(super) index: u32,
}

#[derive(Debug, Clone, Copy)]
pub(super) struct Bounds {
    pub(super) min: Vec3,
    pub(super) max: Vec3,
}

impl Bounds {
    const EMPTY: Self = Self { min: Vec3::splat(f32::INFINITY), max: Vec3::splat(f32::NEG_INFINITY) };
    #[inline]
    pub(super) fn grow(&mut self, p: Vec3) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }
    #[inline]
    pub(super) fn union(self, o: Self) -> Self {
        Self { min: self.min.min(o.min), max: self.max.max(o.max) }
    }
    /// Half the surface area of the box grown by `r` (0 for an empty box).
    #[inline]
    pub(super) fn half_area(self, r: f32) -> f32 {
        if self.min.x > self.max.x {
            return 0.0;
        }
        let e = self.max - self.min + Vec3::splat(2.0 * r);
        e.x * e.y + e.y * e.z + e.z * e.x
    }
    pub(super) fn of(items: &[Item]) -> Self {
        let mut b = Self::EMPTY;
        for it in items {
            b.grow(Vec3::from(it.c));
        }
        b
    }
}

/// A subtree: its inner nodes in depth-first order (local indices, root first when inner) and its
/// root reference (local).
pub(super) struct Subtree {
    pub(super) nodes: Vec<Node>,
    pub(super) root: u32,
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
        let mut items: Vec<Item> = centers.iter().enumerate().map(|(i, c)| Item { c: c.to_array(), index: i as u32 }).collect();
        let cb = par_bounds(&items);
        let tree = if items.is_empty() { Subtree { nodes: Vec::new(), root: LEAF } } else { build_node(&mut items, 0, cb, radius, 0) };
        let (root_min, root_max) =
            if items.is_empty() { (Vec3::ZERO, Vec3::ZERO) } else { (cb.min - Vec3::splat(radius), cb.max + Vec3::splat(radius)) };
        let (nodes, root) = collapse_tree(&tree.nodes, tree.root);
        drop(tree);
        let axis = |a: usize| items.iter().map(|it| it.c[a]).chain([0.0; LEAF_MAX - 1]).collect::<Vec<f32>>();
        Ok(Self {
            radius,
            xs: axis(0),
            ys: axis(1),
            zs: axis(2),
            indices: items.iter().map(|it| it.index).collect(),
            nodes,
            root,
            root_min,
            root_max,
        })
    }
}

/// Centre bounds of many items, in parallel.
pub(super) fn par_bounds(items: &[Item]) -> Bounds {
    use rayon::prelude::*;
    if items.len() < PARALLEL_MIN {
        return Bounds::of(items);
    }
    items.par_chunks(PARALLEL_MIN).map(Bounds::of).reduce(|| Bounds::EMPTY, Bounds::union)
}

#[derive(Debug, Clone, Copy)]
pub(super) struct Bin {
    pub(super) count: u32,
    pub(super) b: Bounds,
}

pub(super) const EMPTY_BIN: Bin = Bin { count: 0, b: Bounds::EMPTY };

/// Bins of one range along all three axes.
/// Bins of one range along `axis` (the others stay empty).
pub(super) fn bin_items(items: &[Item], cmin: Vec3, scale: Vec3, axis: usize) -> [[Bin; BINS]; 3] {
    let mut bins = [[EMPTY_BIN; BINS]; 3];
    let (lo, sc) = (cmin[axis], scale[axis]);
    let row = &mut bins[axis];
    for it in items {
        let k = (((it.c[axis] - lo) * sc) as usize).min(BINS - 1);
        let bin = &mut row[k];
        bin.count += 1;
        bin.b.grow(Vec3::from(it.c));
    }
    bins
}

pub(super) fn merge_bins(mut a: [[Bin; BINS]; 3], b: [[Bin; BINS]; 3]) -> [[Bin; BINS]; 3] {
    for axis in 0..3 {
        for k in 0..BINS {
            a[axis][k].count += b[axis][k].count;
            a[axis][k].b = a[axis][k].b.union(b[axis][k].b);
        }
    }
    a
}

/// Builds the subtree over `items` (whose first item is sphere slot `base`; `cb` their centre
/// bounds). Splits are binned SAH; degenerate ranges (all centres equal) split at the middle, so
/// the depth stays ≤ log2(n) + a few and below the traversal stack.
pub(super) fn build_node(items: &mut [Item], base: usize, cb: Bounds, r: f32, depth: u32) -> Subtree {
    let n = items.len();
    if n < PARALLEL_MIN {
        // Small subtrees are built serially straight into one vector (no stitching copies).
        let mut nodes = Vec::with_capacity(n / 2);
        let root = build_serial(items, base, cb, r, depth, &mut nodes);
        return Subtree { nodes, root };
    }
    let (mid, lb, rb) = split_items(items, cb, r, depth);
    let (left_items, right_items) = items.split_at_mut(mid);
    let (left, right) =
        rayon::join(|| build_node(left_items, base, lb, r, depth + 1), || build_node(right_items, base + mid, rb, r, depth + 1));
    // Stitch: this node, then the left subtree, then the right one (depth-first order).
    let mut nodes = Vec::with_capacity(1 + left.nodes.len() + right.nodes.len());
    let left_off = 1u32;
    let right_off = 1 + left.nodes.len() as u32;
    let fix = |c: u32, off: u32| if c & LEAF != 0 { c } else { c + off };
    nodes.push(make_node(lb, rb, r, fix(left.root, left_off), fix(right.root, right_off)));
    append_offset(&mut nodes, left.nodes, left_off);
    append_offset(&mut nodes, right.nodes, right_off);
    Subtree { nodes, root: 0 }
}

/// Serial build of the subtree over `items` into `nodes` (depth-first); returns its reference.
pub(super) fn build_serial(items: &mut [Item], base: usize, cb: Bounds, r: f32, depth: u32, nodes: &mut Vec<Node>) -> u32 {
    let n = items.len();
    if n <= LEAF_MAX {
        return leaf_ref(base as u32, n as u32);
    }
    let (mid, lb, rb) = split_items(items, cb, r, depth);
    let (left_items, right_items) = items.split_at_mut(mid);
    let idx = nodes.len();
    nodes.push(make_node(lb, rb, r, 0, 0));
    let left = build_serial(left_items, base, lb, r, depth + 1, nodes);
    let right = build_serial(right_items, base + mid, rb, r, depth + 1, nodes);
    nodes[idx].child = [left, right];
    idx as u32
}

pub(super) fn make_node(lb: Bounds, rb: Bounds, r: f32, left: u32, right: u32) -> Node {
    let rr = Vec3::splat(r);
    let (l0, l1) = (lb.min - rr, lb.max + rr);
    let (r0, r1) = (rb.min - rr, rb.max + rr);
    Node {
        x: Vec4::new(l0.x, r0.x, l1.x, r1.x),
        y: Vec4::new(l0.y, r0.y, l1.y, r1.y),
        z: Vec4::new(l0.z, r0.z, l1.z, r1.z),
        child: [left, right],
    }
}

/// Chooses the split of `items` (> `LEAF_MAX` of them, centre bounds `cb`), partitions them in
/// place and returns the left count and both sides' centre bounds.
pub(super) fn split_items(items: &mut [Item], cb: Bounds, r: f32, depth: u32) -> (usize, Bounds, Bounds) {
    let n = items.len();
    let extent = cb.max - cb.min;
    let mut split = None;
    // Past depth 64 (pathological distributions) halve by count, which bounds the depth.
    if extent.max_element() > 0.0 && depth < 64 {
        let scale = Vec3::select(extent.cmpgt(Vec3::ZERO), Vec3::splat(BINS as f32) / extent, Vec3::ZERO);
        // Bin along the widest axis only (a third of the work of all three; for point clouds the
        // widest axis nearly always holds the best split).
        let main = extent.max_position();
        let bins = if n >= PARALLEL_MIN {
            use rayon::prelude::*;
            items.par_chunks(PARALLEL_MIN).map(|c| bin_items(c, cb.min, scale, main)).reduce(|| [[EMPTY_BIN; BINS]; 3], merge_bins)
        } else {
            bin_items(items, cb.min, scale, main)
        };
        // SAH: sweep from the right, then from the left.
        let mut best_cost = f32::INFINITY;
        for axis in 0..3 {
            if extent[axis] <= 0.0 || axis != main {
                continue;
            }
            let b = &bins[axis];
            let mut right_area = [0f32; BINS];
            let mut right_bounds = [Bounds::EMPTY; BINS];
            let mut acc = Bounds::EMPTY;
            let mut count = 0u32;
            let mut right_count = [0u32; BINS];
            for k in (1..BINS).rev() {
                acc = acc.union(b[k].b);
                count += b[k].count;
                right_area[k] = acc.half_area(r);
                right_bounds[k] = acc;
                right_count[k] = count;
            }
            let mut lacc = Bounds::EMPTY;
            let mut lcount = 0u32;
            for k in 1..BINS {
                lacc = lacc.union(b[k - 1].b);
                lcount += b[k - 1].count;
                if lcount == 0 || right_count[k] == 0 {
                    continue;
                }
                let cost = lacc.half_area(r) * lcount as f32 + right_area[k] * right_count[k] as f32;
                if cost < best_cost {
                    best_cost = cost;
                    split = Some((axis, k, lcount as usize, lacc, right_bounds[k]));
                }
            }
        }
    }
    let (mid, lb, rb) = match split {
        Some((axis, k, lcount, lb, rb)) => {
            let scale = BINS as f32 / extent[axis];
            let lo = cb.min[axis];
            let mid = partition(items, |it| (((it.c[axis] - lo) * scale) as usize).min(BINS - 1) < k);
            debug_assert_eq!(mid, lcount);
            (mid, lb, rb)
        }
        None => {
            // All centres equal (or no useful split): halve by count.
            let mid = n / 2;
            (mid, Bounds::of(&items[..mid]), Bounds::of(&items[mid..]))
        }
    };
    (mid, lb, rb)
}

pub(super) fn append_offset(dst: &mut Vec<Node>, src: Vec<Node>, off: u32) {
    if off == 0 {
        dst.extend(src);
        return;
    }
    dst.extend(src.into_iter().map(|mut n| {
        for c in &mut n.child {
            if *c & LEAF == 0 {
                *c += off;
            }
        }
        n
    }));
}

/// The sphere build's binary tree, for the core's [`collapse`]: a reference is a child reference
/// (an index into the nodes or a leaf reference) with the box its parent holds for it.
struct SphereTree<'a>(&'a [Node]);

impl BinaryTree for SphereTree<'_> {
    type Ref = (u32, Vec3A, Vec3A);
    fn children(&self, (r, ..): Self::Ref) -> Option<[Self::Ref; 2]> {
        if r & LEAF != 0 {
            return None;
        }
        let n = &self.0[r as usize];
        let kid = |l: usize| (n.child[l], Vec3A::new(n.x[l], n.y[l], n.z[l]), Vec3A::new(n.x[l + 2], n.y[l + 2], n.z[l + 2]));
        Some([kid(0), kid(1)])
    }
    fn bounds(&self, (_, lo, hi): Self::Ref) -> (Vec3A, Vec3A) {
        (lo, hi)
    }
}

/// The sphere leaves' references are made by the build (slots in leaf order), so the collapse
/// takes them as they are.
struct SphereLeaves;

impl LeafSink<(u32, Vec3A, Vec3A)> for SphereLeaves {
    fn leaf(&mut self, (r, ..): (u32, Vec3A, Vec3A), _: &mut Vec<Node4>) -> u32 {
        r
    }
    fn append(&mut self, _: Self) -> u32 {
        0
    }
}

/// The binary tree under `root` collapsed into 4-wide nodes, the top two levels in parallel.
pub(super) fn collapse_tree(nodes2: &[Node], root: u32) -> (Vec<Node4>, u32) {
    let c = collapse(&SphereTree(nodes2), (root, Vec3A::ZERO, Vec3A::ZERO), 2, 0, &|| SphereLeaves);
    (c.nodes, c.root)
}

/// In-place partition: items for which `left` holds first; returns their count.
pub(super) fn partition(items: &mut [Item], left: impl Fn(&Item) -> bool) -> usize {
    let mut i = 0;
    let mut j = items.len();
    loop {
        while i < j && left(&items[i]) {
            i += 1;
        }
        while i < j && !left(&items[j - 1]) {
            j -= 1;
        }
        if i >= j {
            return i;
        }
        items.swap(i, j - 1);
        i += 1;
        j -= 1;
    }
}
