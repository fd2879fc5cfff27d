//! The BVH's build: binned SAH over all three axes (in parallel for large nodes and the upper
//! levels), then the collapse into 4-wide nodes and leaf packs. Deterministic for any thread count.

use super::*;
use crate::bvh_core::{BinaryTree, LeafSink, collapse};
use crate::isa;

pub(super) const BINS: usize = 16;
/// Leaves are forced below this many triangles unless the centroids coincide.
pub(super) const MAX_LEAF: usize = 8;
/// Nodes at this depth become leaves whatever their size, so traversal stacks stay bounded.
pub(super) const MAX_DEPTH: u32 = 56;
/// Subtrees larger than this are split in parallel.
pub(super) const PARALLEL_MIN: usize = 8192;
/// Nodes larger than this are binned in parallel (chunks of this size).
pub(super) const PARALLEL_BIN_MIN: usize = 32 * 1024;
/// SAH: cost of a 4-wide node test relative to a 4-triangle test.
pub(super) const TRAVERSAL_COST: f32 = 1.0;
pub(super) const INTERSECT_COST: f32 = 0.6;

#[derive(Clone, Copy)]
pub(super) struct Bounds {
    pub(super) min: Vec3A,
    pub(super) max: Vec3A,
}

impl Bounds {
    const EMPTY: Self = Self { min: Vec3A::splat(f32::INFINITY), max: Vec3A::splat(f32::NEG_INFINITY) };
    #[inline]
    pub(super) fn grow(&mut self, b: &Bounds) {
        self.min = self.min.min(b.min);
        self.max = self.max.max(b.max);
    }
    #[inline]
    pub(super) fn grow_point(&mut self, p: Vec3A) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }
    #[inline]
    pub(super) fn half_area(&self) -> f32 {
        let d = (self.max - self.min).max(Vec3A::ZERO);
        d.x * d.y + d.y * d.z + d.z * d.x
    }
}

/// Box and centroid box of a run of primitives.
#[derive(Clone, Copy)]
pub(super) struct PrimBounds {
    pub(super) bounds: Bounds,
    pub(super) centroids: Bounds,
}

impl PrimBounds {
    const EMPTY: Self = Self { bounds: Bounds::EMPTY, centroids: Bounds::EMPTY };
    #[inline(always)]
    pub(super) fn add(&mut self, p: &Prim) {
        self.bounds.grow(&p.bounds());
        self.centroids.grow_point(p.centroid2());
    }
    pub(super) fn merge(mut self, o: Self) -> Self {
        self.bounds.grow(&o.bounds);
        self.centroids.grow(&o.centroids);
        self
    }
    pub(super) fn of(prims: &[Prim]) -> Self {
        let serial = |c: &[Prim]| {
            isa::dispatch(
                #[inline(always)]
                || {
                    let mut b = PrimBounds::EMPTY;
                    c.iter().for_each(|p| b.add(p));
                    b
                },
            )
        };
        if prims.len() >= PARALLEL_BIN_MIN {
            prims.par_chunks(PARALLEL_BIN_MIN).map(serial).reduce(|| PrimBounds::EMPTY, PrimBounds::merge)
        } else {
            serial(prims)
        }
    }
}

pub(super) enum BuildNode {
    Leaf { bounds: Bounds, first: u32, count: u32 },
    Inner { bounds: Bounds, children: Box<(BuildNode, BuildNode)> },
}

/// A primitive during the build: its box, with its triangle index in the bits of `lo.w` (a
/// subnormal float: kept out of every arithmetic, see `centroid2`). The
/// build partitions these records themselves (not indices into them), so every pass over a
/// node's primitives reads memory in order.
#[derive(Clone, Copy)]
pub(super) struct Prim {
    pub(super) lo: Vec4,
    pub(super) hi: Vec4,
}

impl Prim {
    /// Triangle `index` with corners `corners`. Non-finite corners make a point box: such
    /// triangles can never be hit anyway.
    #[inline(always)]
    pub(super) fn of_triangle(index: u32, corners: [Vec3; 3]) -> Prim {
        let [a, b, d] = corners.map(Vec3A::from);
        let idx = f32::from_bits(index);
        if !(a.is_finite() && b.is_finite() && d.is_finite()) {
            return Prim { lo: Vec4::ZERO.with_w(idx), hi: Vec4::ZERO };
        }
        Prim { lo: a.min(b).min(d).extend(idx), hi: a.max(b).max(d).extend(0.0) }
    }

    #[inline(always)]
    pub(super) fn bounds(&self) -> Bounds {
        Bounds { min: Vec3A::from_vec4(self.lo.with_w(0.0)), max: Vec3A::from_vec4(self.hi) }
    }
    /// Twice the box centre (the factor 2 does not change any split).
    #[inline(always)]
    pub(super) fn centroid2(&self) -> Vec3A {
        // `w` cleared: the index's bits are a subnormal float, and arithmetic on subnormals
        // stalls for a microcode assist on Intel cores (≈3× the whole build there).
        Vec3A::from_vec4(self.lo.with_w(0.0)) + Vec3A::from_vec4(self.hi)
    }
    #[inline(always)]
    pub(super) fn index(&self) -> u32 {
        self.lo.w.to_bits()
    }
}

/// Lays out leaf packs in depth-first leaf order during the collapse (the packs themselves are
/// filled afterwards, in parallel, from these descriptors).
pub(super) struct Packer<'a> {
    /// The primitives in their order after the build's partitioning.
    pub(super) prims: &'a [Prim],
    /// Per pack: first position in `prims` and number of triangles (1–4).
    pub(super) packs: Vec<(u32, u32)>,
    pub(super) leaves: usize,
}

impl Packer<'_> {
    /// Packs the triangles `first..first + count` (positions in `prims`); returns the reference
    /// to them: a leaf, or an extra node over up to four leaves when they need more than
    /// [`MAX_LEAF_PACKS`] packs.
    pub(super) fn leaf(&mut self, first: u32, count: u32, nodes: &mut Vec<Node4>) -> u32 {
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
        let part = (n_packs.div_ceil(4) * 4) as u32;
        let idx = nodes.len();
        nodes.push(Node4::EMPTY);
        let mut node = Node4::EMPTY;
        for (k, s) in (first..first + count).step_by(part as usize).enumerate() {
            let c = part.min(first + count - s);
            let mut b = Bounds::EMPTY;
            self.prims[s as usize..(s + c) as usize].iter().for_each(|p| b.grow(&p.bounds()));
            let r = self.leaf(s, c, nodes);
            node.set(k, b.min, b.max, r);
        }
        nodes[idx] = node;
        idx as u32
    }
}

impl SceneBvh {
    /// Builds the BVH over `prepared.triangles`.
    pub fn build(prepared: &PreparedScene) -> SceneBvh {
        // The corners are read from the prepared meshes twice (here and for the packs) rather
        // than gathered into an array of their own: a fresh array costs a page fault per 4 KiB
        // written (about 2 µs each on a VM), about as much as the gather itself.
        let mut prims: Vec<Prim> =
            prepared.triangles.par_iter().enumerate().map(|(i, t)| Prim::of_triangle(i as u32, prepared.triangle(*t))).collect();

        let root = (!prims.is_empty()).then(|| {
            let pb = PrimBounds::of(&prims);
            build_rec(&mut prims, pb, 0, 0)
        });

        let node_capacity = prims.len() / 8;
        let new_packer = || Packer { prims: &prims, packs: Vec::with_capacity(prims.len() / 3), leaves: 0 };
        let (nodes, packer) = match &root {
            None => (Vec::new(), new_packer()),
            Some(BuildNode::Leaf { bounds, first, count }) => {
                // A single leaf: a root node with one child.
                let (mut nodes, mut packer) = (vec![Node4::EMPTY], new_packer());
                let r = packer.leaf(*first, *count, &mut nodes);
                nodes[0].set(0, bounds.min, bounds.max, r);
                (nodes, packer)
            }
            Some(inner) => {
                let c = collapse(&BuildTree(std::marker::PhantomData), inner, 0, node_capacity, &new_packer);
                (c.nodes, c.sink)
            }
        };
        drop(root);
        let Packer { packs: descs, leaves, .. } = packer;

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

pub(super) fn build_rec(prims: &mut [Prim], pb: PrimBounds, offset: u32, depth: u32) -> BuildNode {
    let PrimBounds { bounds, centroids: cb } = pb;
    let n = prims.len();
    let leaf = BuildNode::Leaf { bounds, first: offset, count: n as u32 };
    // A split costs at least one node test more than a leaf of one pack.
    if n <= 1 || depth >= MAX_DEPTH || (n <= MAX_LEAF && packs_of(n) * INTERSECT_COST <= TRAVERSAL_COST) {
        return leaf;
    }
    let nb = n.clamp(4, BINS);
    let split = best_split(prims, &cb, &bounds, nb);
    let parts = match split {
        Some((axis, bin, cost)) if cost < packs_of(n) * INTERSECT_COST || n > MAX_LEAF => {
            let scale = bin_scale(&cb, nb);
            let (lo, sc) = (cb.min[axis], scale[axis]);
            partition(prims, |p| bin_of(p.lo[axis] + p.hi[axis], lo, sc, nb) <= bin)
        }
        Some(_) => return leaf,
        None => (0, PrimBounds::EMPTY, PrimBounds::EMPTY),
    };
    let (mid, lb, rb) = match parts {
        (mid, lb, rb) if mid > 0 && mid < n => (mid, lb, rb),
        // All centroids equal (or binning could not separate them): any split is as good.
        _ if n > MAX_LEAF => (n / 2, PrimBounds::of(&prims[..n / 2]), PrimBounds::of(&prims[n / 2..])),
        _ => return leaf,
    };
    let (l, r) = prims.split_at_mut(mid);
    let (a, b) = if n >= PARALLEL_MIN {
        rayon::join(|| build_rec(l, lb, offset, depth + 1), || build_rec(r, rb, offset + mid as u32, depth + 1))
    } else {
        (build_rec(l, lb, offset, depth + 1), build_rec(r, rb, offset + mid as u32, depth + 1))
    };
    BuildNode::Inner { bounds, children: Box::new((a, b)) }
}

/// Leaf cost unit: triangles are tested four at a time.
#[inline]
pub(super) fn packs_of(n: usize) -> f32 {
    n.div_ceil(4) as f32
}

/// Bin of a centroid on each axis, in `0..nb` (`nb ≤ BINS`): `(c − lo) · scale` rounded down
/// (rounded to nearest after − ½, with the 2²³ trick so the conversion stays in SIMD registers;
/// the build uses this one function for binning and partitioning, so both agree exactly). NaN
/// lands in bin 0.
#[inline(always)]
pub(super) fn bins_of(c: Vec3A, lo: Vec3A, scale: Vec3A, nb: usize) -> [usize; 3] {
    const MAGIC: f32 = 8_388_608.0;
    let x = ((c - lo) * scale - Vec3A::splat(0.5)).clamp(Vec3A::ZERO, Vec3A::splat(nb as f32 - 1.0)) + Vec3A::splat(MAGIC);
    x.to_array().map(|v| (v.to_bits() as usize) & (BINS - 1))
}

/// [`bins_of`] on one axis (the same operations in the same order, so the same bin): the
/// partition needs only the split axis.
#[inline(always)]
pub(super) fn bin_of(c: f32, lo: f32, scale: f32, nb: usize) -> usize {
    const MAGIC: f32 = 8_388_608.0;
    let x = ((c - lo) * scale - 0.5).clamp(0.0, nb as f32 - 1.0) + MAGIC;
    (x.to_bits() as usize) & (BINS - 1)
}

/// Bins per unit on each axis of a centroid box (0 on axes without a usable extent).
pub(super) fn bin_scale(cb: &Bounds, nb: usize) -> Vec3A {
    let extent = cb.max - cb.min;
    Vec3A::from_array([0, 1, 2].map(|a| if extent[a] > 0.0 && extent[a].is_finite() { nb as f32 / extent[a] } else { 0.0 }))
}

/// Per-axis bin boxes and counts.
#[derive(Clone, Copy)]
pub(super) struct Bins {
    pub(super) bounds: [[Bounds; BINS]; 3],
    pub(super) counts: [[u32; BINS]; 3],
}

impl Bins {
    const EMPTY: Self = Self { bounds: [[Bounds::EMPTY; BINS]; 3], counts: [[0; BINS]; 3] };
    pub(super) fn merge(mut self, o: Self) -> Self {
        for axis in 0..3 {
            for b in 0..BINS {
                self.bounds[axis][b].grow(&o.bounds[axis][b]);
                self.counts[axis][b] += o.counts[axis][b];
            }
        }
        self
    }
}

impl Bins {
    #[inline(always)]
    pub(super) fn add(&mut self, p: &Prim, lo: Vec3A, scale: Vec3A, nb: usize) {
        let b = bins_of(p.centroid2(), lo, scale, nb);
        let pb = p.bounds();
        for ((bounds, counts), b) in self.bounds.iter_mut().zip(&mut self.counts).zip(b) {
            bounds[b].grow(&pb);
            counts[b] += 1;
        }
    }
}

/// Primitives from which binning alternates between two sets of bins (merged at the end, exact
/// min/max/count, so the same result): consecutive primitives often fall in the same bins, and
/// one set would chain every update on the previous one through memory.
pub(super) const BIN_TWO_WAY_MIN: usize = 64;
/// Primitives from which binning alternates between four sets instead (the room's build, one
/// thread: 96–98 → 88–93 ms).
pub(super) const BIN_FOUR_WAY_MIN: usize = 256;

pub(super) fn bin_prims(prims: &[Prim], lo: Vec3A, scale: Vec3A, nb: usize) -> Bins {
    isa::dispatch(
        #[inline(always)]
        || bin_prims_with(prims, lo, scale, nb),
    )
}

#[inline(always)]
fn bin_prims_with(prims: &[Prim], lo: Vec3A, scale: Vec3A, nb: usize) -> Bins {
    match prims.len() {
        n if n < BIN_TWO_WAY_MIN => bin_interleaved::<1>(prims, lo, scale, nb),
        n if n < BIN_FOUR_WAY_MIN => bin_interleaved::<2>(prims, lo, scale, nb),
        _ => bin_interleaved::<4>(prims, lo, scale, nb),
    }
}

/// Binning with consecutive primitives dealt round `N` sets of bins, merged in order at the end.
#[inline(always)]
fn bin_interleaved<const N: usize>(prims: &[Prim], lo: Vec3A, scale: Vec3A, nb: usize) -> Bins {
    let mut sets = [Bins::EMPTY; N];
    let mut groups = prims.chunks_exact(N);
    for group in &mut groups {
        for (bins, p) in sets.iter_mut().zip(group) {
            bins.add(p, lo, scale, nb);
        }
    }
    groups.remainder().iter().for_each(|p| sets[0].add(p, lo, scale, nb));
    sets.into_iter().reduce(Bins::merge).unwrap_or(Bins::EMPTY)
}

/// Binned SAH with `nb ≤ BINS` bins over all three axes at once (one pass over the primitives,
/// in parallel chunks for large nodes): `(axis, last bin of the left side, cost)`.
pub(super) fn best_split(prims: &[Prim], cb: &Bounds, bounds: &Bounds, nb: usize) -> Option<(usize, usize, f32)> {
    let extent = cb.max - cb.min;
    let usable = [0, 1, 2].map(|a| extent[a] > 0.0 && extent[a].is_finite());
    if !usable.iter().any(|&u| u) {
        return None;
    }
    let scale = bin_scale(cb, nb);
    let bins = if prims.len() >= PARALLEL_BIN_MIN {
        prims.par_chunks(PARALLEL_BIN_MIN / 2).map(|c| bin_prims(c, cb.min, scale, nb)).reduce(|| Bins::EMPTY, Bins::merge)
    } else {
        bin_prims(prims, cb.min, scale, nb)
    };
    let mut best: Option<(usize, usize, f32)> = None;
    let inv_area = 1.0 / bounds.half_area().max(f32::MIN_POSITIVE);
    let total = prims.len() as u32;
    for axis in (0..3).filter(|&a| usable[a]) {
        let (bins, counts) = (&bins.bounds[axis], &bins.counts[axis]);
        // Sweep from the right, then from the left.
        let mut right_area = [0.0f32; BINS];
        let mut acc = Bounds::EMPTY;
        for i in (1..nb).rev() {
            acc.grow(&bins[i]);
            right_area[i] = acc.half_area();
        }
        let mut left = Bounds::EMPTY;
        let mut nl = 0u32;
        for i in 0..nb - 1 {
            left.grow(&bins[i]);
            nl += counts[i];
            let nr = total - nl;
            if nl == 0 || nr == 0 {
                continue;
            }
            let cost = TRAVERSAL_COST
                + INTERSECT_COST * (left.half_area() * packs_of(nl as usize) + right_area[i + 1] * packs_of(nr as usize)) * inv_area;
            if best.is_none_or(|b| cost < b.2) {
                best = Some((axis, i, cost));
            }
        }
    }
    best
}

/// In-place partition: elements with `pred` true first; returns how many, and the boxes of
/// both sides (gathered on the way, so the children need no pass of their own).
pub(super) fn partition(v: &mut [Prim], pred: impl Fn(&Prim) -> bool) -> (usize, PrimBounds, PrimBounds) {
    isa::dispatch(
        #[inline(always)]
        || partition_with(v, pred),
    )
}

#[inline(always)]
fn partition_with(v: &mut [Prim], pred: impl Fn(&Prim) -> bool) -> (usize, PrimBounds, PrimBounds) {
    let (mut lb, mut rb) = (PrimBounds::EMPTY, PrimBounds::EMPTY);
    let mut i = 0;
    let mut j = v.len();
    while i < j {
        let p = v[i];
        if pred(&p) {
            lb.add(&p);
            i += 1;
        } else {
            rb.add(&p);
            j -= 1;
            v.swap(i, j);
        }
    }
    (i, lb, rb)
}

pub(super) fn bounds_of(n: &BuildNode) -> &Bounds {
    match n {
        BuildNode::Leaf { bounds, .. } | BuildNode::Inner { bounds, .. } => bounds,
    }
}

/// The binary build tree, for [`collapse`] (its nodes are their own references).
pub(super) struct BuildTree<'a>(std::marker::PhantomData<&'a BuildNode>);

impl<'a> BinaryTree for BuildTree<'a> {
    type Ref = &'a BuildNode;
    fn children(&self, r: &'a BuildNode) -> Option<[&'a BuildNode; 2]> {
        match r {
            BuildNode::Leaf { .. } => None,
            BuildNode::Inner { children, .. } => Some([&children.0, &children.1]),
        }
    }
    fn bounds(&self, r: &'a BuildNode) -> (Vec3A, Vec3A) {
        let b = bounds_of(r);
        (b.min, b.max)
    }
}

impl<'a> LeafSink<&'a BuildNode> for Packer<'_> {
    fn leaf(&mut self, r: &'a BuildNode, nodes: &mut Vec<Node4>) -> u32 {
        match r {
            BuildNode::Leaf { first, count, .. } => Packer::leaf(self, *first, *count, nodes),
            BuildNode::Inner { .. } => unreachable!("the collapse hands over leaves only"),
        }
    }
    fn append(&mut self, later: Self) -> u32 {
        let offset = self.packs.len() as u32;
        self.packs.extend(later.packs);
        self.leaves += later.leaves;
        offset
    }
}
