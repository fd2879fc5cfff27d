//! The binned SAH split both BVHs use ([`split_node`]): a node's primitives binned by centroid
//! (16 bins on all three axes, or along the widest one; large nodes binned in parallel) and
//! partitioned in place at the cheapest split, or left as a leaf where each BVH's
//! [`BuildRules`] say. [`super::wide`] applies it from the root down, making 4-wide nodes.
//! Deterministic for any thread count: parallel binning merges exact min/max/count partials.

use glam::{Vec3A, Vec4};
use rayon::prelude::*;

use crate::isa;

pub(crate) const BINS: usize = 16;
/// Subtrees larger than this are split in parallel.
pub(crate) const PARALLEL_MIN: usize = 8192;
/// Nodes larger than this are binned in parallel (chunks of this size).
pub(crate) const PARALLEL_BIN_MIN: usize = 32 * 1024;

/// What a BVH's build optimises and where it stops.
#[derive(Debug, Clone, Copy)]
pub(crate) struct BuildRules {
    /// SAH cost of a node test, in the unit of `intersect_cost`.
    pub(crate) traversal_cost: f32,
    /// SAH cost of one of a leaf's test units (see [`BuildRules::leaf_units`]).
    pub(crate) intersect_cost: f32,
    /// A leaf's primitives are tested `1 << leaf_unit_shift` at a time (four triangles at once:
    /// 2; spheres one by one: 0). A shift rather than a function, so the SAH sweep's cost of
    /// every candidate split is inline arithmetic instead of two indirect calls.
    pub(crate) leaf_unit_shift: u32,
    /// Nodes of more primitives always split; smaller ones become leaves where the SAH says a
    /// split costs more (or always, with `small_is_leaf`).
    pub(crate) max_leaf: usize,
    /// Nodes of at most `max_leaf` primitives become leaves without asking the SAH.
    pub(crate) small_is_leaf: bool,
    /// Nodes this deep become leaves whatever their size (so traversal stacks stay bounded).
    pub(crate) leaf_at_depth: u32,
    /// Nodes this deep split in halves by count instead of by the SAH (also bounds the depth,
    /// for pathological distributions, without oversized leaves).
    pub(crate) halve_at_depth: u32,
    /// Bin along the centroids' widest axis only: a third of the binning, at the cost of the
    /// splits the other axes would have found (for point clouds the widest axis nearly always
    /// holds the best one).
    pub(crate) widest_axis_only: bool,
}

impl BuildRules {
    /// The test units of a leaf of `n` primitives: `n / 2^leaf_unit_shift`, rounded up.
    #[inline(always)]
    pub(crate) fn leaf_units(&self, n: usize) -> f32 {
        ((n + (1 << self.leaf_unit_shift) - 1) >> self.leaf_unit_shift) as f32
    }
}

#[derive(Clone, Copy)]
pub(crate) struct Bounds {
    pub(crate) min: Vec3A,
    pub(crate) max: Vec3A,
}

impl Bounds {
    pub(crate) const EMPTY: Self = Self { min: Vec3A::splat(f32::INFINITY), max: Vec3A::splat(f32::NEG_INFINITY) };
    #[inline]
    pub(crate) fn grow(&mut self, b: &Bounds) {
        self.min = self.min.min(b.min);
        self.max = self.max.max(b.max);
    }
    #[inline]
    pub(crate) fn grow_point(&mut self, p: Vec3A) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }
    #[inline]
    pub(crate) fn half_area(&self) -> f32 {
        let d = (self.max - self.min).max(Vec3A::ZERO);
        d.x * d.y + d.y * d.z + d.z * d.x
    }
}

/// Box and centroid box of a run of primitives.
#[derive(Clone, Copy)]
pub(crate) struct PrimBounds {
    pub(crate) bounds: Bounds,
    pub(crate) centroids: Bounds,
}

impl PrimBounds {
    pub(crate) const EMPTY: Self = Self { bounds: Bounds::EMPTY, centroids: Bounds::EMPTY };
    #[inline(always)]
    pub(crate) fn add(&mut self, p: &Prim) {
        self.bounds.grow(&p.bounds());
        self.centroids.grow_point(p.centroid2());
    }
    pub(crate) fn merge(mut self, o: Self) -> Self {
        self.bounds.grow(&o.bounds);
        self.centroids.grow(&o.centroids);
        self
    }
    pub(crate) fn of(prims: &[Prim]) -> Self {
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

/// A primitive during the build: its box, with its index (a triangle, a sphere) in the bits of `lo.w` (a
/// subnormal float: kept out of every arithmetic, see `centroid2`). The
/// build partitions these records themselves (not indices into them), so every pass over a
/// node's primitives reads memory in order.
#[derive(Clone, Copy)]
pub(crate) struct Prim {
    pub(crate) lo: Vec4,
    pub(crate) hi: Vec4,
}

impl Prim {
    /// Primitive `index` with box `lo..hi`.
    #[inline(always)]
    pub(crate) fn new(index: u32, lo: Vec3A, hi: Vec3A) -> Prim {
        Prim { lo: lo.extend(f32::from_bits(index)), hi: hi.extend(0.0) }
    }

    #[inline(always)]
    pub(crate) fn bounds(&self) -> Bounds {
        Bounds { min: Vec3A::from_vec4(self.lo.with_w(0.0)), max: Vec3A::from_vec4(self.hi) }
    }
    /// Twice the box centre (the factor 2 does not change any split).
    #[inline(always)]
    pub(crate) fn centroid2(&self) -> Vec3A {
        // `w` cleared: the index's bits are a subnormal float, and arithmetic on subnormals
        // stalls for a microcode assist on Intel cores (≈3× the whole build there).
        Vec3A::from_vec4(self.lo.with_w(0.0)) + Vec3A::from_vec4(self.hi)
    }
    #[inline(always)]
    pub(crate) fn index(&self) -> u32 {
        self.lo.w.to_bits()
    }
}

/// Bin of a centroid on each axis, in `0..nb` (`nb ≤ BINS`): `(c − lo) · scale` rounded down
/// (rounded to nearest after − ½, with the 2²³ trick so the conversion stays in SIMD registers;
/// the build uses this one function for binning and partitioning, so both agree exactly). NaN
/// lands in bin 0.
#[inline(always)]
pub(crate) fn bins_of(c: Vec3A, lo: Vec3A, scale: Vec3A, nb: usize) -> [usize; 3] {
    const MAGIC: f32 = 8_388_608.0;
    let x = ((c - lo) * scale - Vec3A::splat(0.5)).clamp(Vec3A::ZERO, Vec3A::splat(nb as f32 - 1.0)) + Vec3A::splat(MAGIC);
    x.to_array().map(|v| (v.to_bits() as usize) & (BINS - 1))
}

/// [`bins_of`] on one axis (the same operations in the same order, so the same bin): the
/// partition needs only the split axis.
#[inline(always)]
pub(crate) fn bin_of(c: f32, lo: f32, scale: f32, nb: usize) -> usize {
    const MAGIC: f32 = 8_388_608.0;
    let x = ((c - lo) * scale - 0.5).clamp(0.0, nb as f32 - 1.0) + MAGIC;
    (x.to_bits() as usize) & (BINS - 1)
}

/// Bins per unit on each axis of a centroid box (0 on axes without a usable extent).
pub(crate) fn bin_scale(cb: &Bounds, nb: usize) -> Vec3A {
    let extent = cb.max - cb.min;
    Vec3A::from_array([0, 1, 2].map(|a| if extent[a] > 0.0 && extent[a].is_finite() { nb as f32 / extent[a] } else { 0.0 }))
}

/// Per-axis bin boxes and counts.
#[derive(Clone, Copy)]
pub(crate) struct Bins {
    pub(crate) bounds: [[Bounds; BINS]; 3],
    pub(crate) counts: [[u32; BINS]; 3],
}

impl Bins {
    pub(crate) const EMPTY: Self = Self { bounds: [[Bounds::EMPTY; BINS]; 3], counts: [[0; BINS]; 3] };
    pub(crate) fn merge(mut self, o: Self) -> Self {
        self.merge_from(&o, BINS, None);
        self
    }
}

impl Bins {
    /// Empties bins `0..nb` of the axes binned (`axis`, or all three): the only ones the binning
    /// fills and the sweep reads, so a small node does not clear all 48.
    #[inline(always)]
    fn reset(&mut self, nb: usize, axis: Option<usize>) {
        for a in axis.map_or(0..3, |a| a..a + 1) {
            self.bounds[a][..nb].fill(Bounds::EMPTY);
            self.counts[a][..nb].fill(0);
        }
    }

    /// Grows bins `0..nb` of the axes binned (`axis`, or all three) by `o`'s, in place (exact
    /// min/max/count, so the order of merges does not matter).
    #[inline(always)]
    fn merge_from(&mut self, o: &Bins, nb: usize, axis: Option<usize>) {
        for a in axis.map_or(0..3, |a| a..a + 1) {
            for b in 0..nb {
                self.bounds[a][b].grow(&o.bounds[a][b]);
                self.counts[a][b] += o.counts[a][b];
            }
        }
    }

    /// [`Bins::add`] on `axis` only (`lo`, `scale`: that axis's).
    #[inline(always)]
    fn add_on_axis(&mut self, p: &Prim, lo: f32, scale: f32, nb: usize, axis: usize) {
        let b = bin_of(p.lo[axis] + p.hi[axis], lo, scale, nb);
        self.bounds[axis][b].grow(&p.bounds());
        self.counts[axis][b] += 1;
    }

    #[inline(always)]
    pub(crate) fn add(&mut self, p: &Prim, lo: Vec3A, scale: Vec3A, nb: usize) {
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
pub(crate) const BIN_TWO_WAY_MIN: usize = 64;
/// Primitives from which binning alternates between four sets instead (the room's build, one
/// thread: 96–98 → 88–93 ms).
pub(crate) const BIN_FOUR_WAY_MIN: usize = 256;

thread_local! {
    /// Each thread's bins for the nodes it bins alone (below [`PARALLEL_BIN_MIN`]): reset bin by
    /// bin where used, instead of a new 1.7 KiB `Bins` per node copied in and out.
    static NODE_BINS: std::cell::RefCell<Bins> = const { std::cell::RefCell::new(Bins::EMPTY) };
}

/// The bins of `prims` on all three axes, or on `axis` only, in `out`: bins `0..nb` of those
/// axes are reset and filled, the rest of `out` is left as it was (no sweep reads it). Nodes
/// below [`BIN_TWO_WAY_MIN`] primitives are binned straight into `out`; larger ones deal
/// consecutive primitives round two or four sets of bins, merged into it.
pub(crate) fn bin_prims_into(out: &mut Bins, prims: &[Prim], lo: Vec3A, scale: Vec3A, nb: usize, axis: Option<usize>) {
    out.reset(nb, axis);
    isa::dispatch(
        #[inline(always)]
        || match (axis, prims.len()) {
            (None, n) if n < BIN_TWO_WAY_MIN => prims.iter().for_each(|p| out.add(p, lo, scale, nb)),
            (None, n) if n < BIN_FOUR_WAY_MIN => out.merge_from(&bin_interleaved::<2>(prims, lo, scale, nb), nb, None),
            (None, _) => out.merge_from(&bin_interleaved::<4>(prims, lo, scale, nb), nb, None),
            (Some(a), n) if n < BIN_TWO_WAY_MIN => prims.iter().for_each(|p| out.add_on_axis(p, lo[a], scale[a], nb, a)),
            (Some(a), _) => out.merge_from(&bin_one_axis(prims, lo[a], scale[a], nb, a), nb, Some(a)),
        },
    )
}

/// Binning on one axis, consecutive primitives dealt round two sets of bins.
#[inline(always)]
fn bin_one_axis(prims: &[Prim], lo: f32, scale: f32, nb: usize, axis: usize) -> Bins {
    let mut sets = [Bins::EMPTY; 2];
    for (k, p) in prims.iter().enumerate() {
        sets[k & 1].add_on_axis(p, lo, scale, nb, axis);
    }
    let [a, b] = sets;
    a.merge(b)
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

/// The best binned SAH split of a node: primitives in bins `0..=last_left_bin` on `axis` go left.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Split {
    pub(crate) axis: usize,
    pub(crate) last_left_bin: usize,
    pub(crate) cost: f32,
}

/// Where the binary SAH build splits a node over `prims` (its box and centroid box `pb`, at
/// binary depth `depth`): `None` for a leaf, else the left part's length and both parts' boxes,
/// with `prims` partitioned in place (left part first).
pub(crate) fn split_node(rules: &BuildRules, prims: &mut [Prim], pb: PrimBounds, depth: u32) -> Option<(usize, PrimBounds, PrimBounds)> {
    let PrimBounds { bounds, centroids: cb } = pb;
    let n = prims.len();
    let small = n <= rules.max_leaf;
    // A split costs at least one node test more than a leaf of one unit.
    if n <= 1
        || depth >= rules.leaf_at_depth
        || (small && (rules.small_is_leaf || rules.leaf_units(n) * rules.intersect_cost <= rules.traversal_cost))
    {
        return None;
    }
    let nb = n.clamp(4, BINS);
    let split = if depth >= rules.halve_at_depth { None } else { best_split(rules, prims, &cb, &bounds, nb) };
    let parts = match split {
        Some(s) if s.cost < rules.leaf_units(n) * rules.intersect_cost || !small => {
            let scale = bin_scale(&cb, nb);
            let (axis, bin) = (s.axis, s.last_left_bin);
            let (lo, sc) = (cb.min[axis], scale[axis]);
            partition(prims, |p| bin_of(p.lo[axis] + p.hi[axis], lo, sc, nb) <= bin)
        }
        Some(_) => return None,
        None => (0, PrimBounds::EMPTY, PrimBounds::EMPTY),
    };
    match parts {
        (mid, lb, rb) if mid > 0 && mid < n => Some((mid, lb, rb)),
        // All centroids equal, binning could not separate them, or too deep: any split is as good.
        _ if !small => Some((n / 2, PrimBounds::of(&prims[..n / 2]), PrimBounds::of(&prims[n / 2..]))),
        _ => None,
    }
}

/// Binned SAH with `nb ≤ BINS` bins over all three axes at once, or the widest one (one pass
/// over the primitives, in parallel chunks for large nodes).
pub(crate) fn best_split(rules: &BuildRules, prims: &[Prim], cb: &Bounds, bounds: &Bounds, nb: usize) -> Option<Split> {
    let extent = cb.max - cb.min;
    let mut usable = [0, 1, 2].map(|a| extent[a] > 0.0 && extent[a].is_finite());
    let only = rules.widest_axis_only.then(|| {
        let widest = (0..3).filter(|&a| usable[a]).max_by(|&a, &b| extent[a].total_cmp(&extent[b]).then(b.cmp(&a)));
        usable = [0, 1, 2].map(|a| Some(a) == widest);
        widest
    });
    if !usable.iter().any(|&u| u) {
        return None;
    }
    let scale = bin_scale(cb, nb);
    let axis = only.flatten();
    if prims.len() >= PARALLEL_BIN_MIN {
        let bins = prims
            .par_chunks(PARALLEL_BIN_MIN / 2)
            .map(|c| {
                let mut bins = Bins::EMPTY;
                bin_prims_into(&mut bins, c, cb.min, scale, nb, axis);
                bins
            })
            .reduce(|| Bins::EMPTY, Bins::merge);
        return cheapest_split(rules, &bins, usable, prims.len(), bounds, nb);
    }
    // No parallel work starts while the thread's bins are borrowed (binning and the sweep are
    // serial), so no task of this thread can ask for them meanwhile.
    NODE_BINS.with_borrow_mut(|bins| {
        bin_prims_into(bins, prims, cb.min, scale, nb, axis);
        cheapest_split(rules, bins, usable, prims.len(), bounds, nb)
    })
}

/// The SAH sweep of [`best_split`] over `bins` (`0..nb` on the `usable` axes) of a node of `n`
/// primitives with box `bounds`.
fn cheapest_split(rules: &BuildRules, bins: &Bins, usable: [bool; 3], n: usize, bounds: &Bounds, nb: usize) -> Option<Split> {
    let mut best: Option<Split> = None;
    let inv_area = 1.0 / bounds.half_area().max(f32::MIN_POSITIVE);
    let total = n as u32;
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
            let cost = rules.traversal_cost
                + rules.intersect_cost
                    * (left.half_area() * rules.leaf_units(nl as usize) + right_area[i + 1] * rules.leaf_units(nr as usize))
                    * inv_area;
            if best.is_none_or(|b| cost < b.cost) {
                best = Some(Split { axis, last_left_bin: i, cost });
            }
        }
    }
    best
}

/// In-place partition: elements with `pred` true first; returns how many, and the boxes of
/// both sides (gathered on the way, so the children need no pass of their own).
pub(crate) fn partition(v: &mut [Prim], pred: impl Fn(&Prim) -> bool) -> (usize, PrimBounds, PrimBounds) {
    isa::dispatch(
        #[inline(always)]
        || partition_with(v, pred),
    )
}

/// Hoare's two-sided partition: from the front, the elements that stay; from the back, those that
/// stay there; then the two misplaced elements found swap. Each element is tested once and only
/// misplaced pairs move (a one-sided loop that swaps every element going right with the last one
/// built the same trees 3–5% slower).
#[inline(always)]
fn partition_with(v: &mut [Prim], pred: impl Fn(&Prim) -> bool) -> (usize, PrimBounds, PrimBounds) {
    let (mut lb, mut rb) = (PrimBounds::EMPTY, PrimBounds::EMPTY);
    let (mut i, mut j) = (0, v.len());
    loop {
        while i < j && pred(&v[i]) {
            lb.add(&v[i]);
            i += 1;
        }
        while i < j && !pred(&v[j - 1]) {
            j -= 1;
            rb.add(&v[j]);
        }
        if i == j {
            return (i, lb, rb);
        }
        // `v[i]` goes right and `v[j - 1]` left.
        j -= 1;
        v.swap(i, j);
        lb.add(&v[i]);
        rb.add(&v[j]);
        i += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    #[test]
    fn the_index_lane_stays_out_of_the_builds_arithmetic() {
        // The index's bits are a subnormal float (index 5 = 5 · 2⁻¹⁴⁹); what the build adds and
        // multiplies must not carry it, or every operation stalls on Intel cores.
        let p = Prim { lo: Vec4::new(1.0, 2.0, 3.0, f32::from_bits(5)), hi: Vec4::new(2.0, 3.0, 4.0, 0.0) };
        assert_eq!(p.index(), 5);
        assert!(p.lo.w.is_subnormal());
        let b = p.bounds();
        #[cfg(target_arch = "x86_64")]
        for v in [p.centroid2(), b.min, b.max] {
            // The SIMD register's fourth lane, which `Vec3A` hides.
            let raw = Vec4::from(std::arch::x86_64::__m128::from(v));
            assert!(!raw.w.is_subnormal(), "{v:?}: w = {:e}", raw.w);
        }
        assert_eq!(p.centroid2(), Vec3A::new(3.0, 5.0, 7.0));
    }

    #[test]
    fn leaf_units_round_up_to_whole_test_units() {
        let rules = |leaf_unit_shift| BuildRules {
            traversal_cost: 1.0,
            intersect_cost: 1.0,
            leaf_unit_shift,
            max_leaf: 8,
            small_is_leaf: false,
            leaf_at_depth: 56,
            halve_at_depth: u32::MAX,
            widest_axis_only: false,
        };
        let (packs, single) = (rules(2), rules(0));
        let got: Vec<f32> = [0, 1, 4, 5, 8, 9, 255_361].iter().map(|&n| packs.leaf_units(n)).collect();
        assert_eq!(got, [0.0, 1.0, 1.0, 2.0, 2.0, 3.0, 63_841.0]);
        assert_eq!((single.leaf_units(0), single.leaf_units(7)), (0.0, 7.0));
    }

    /// Bins reused from node to node hold exactly what fresh bins would, for every node size
    /// (one set, two, four), bin count and axis choice, starting from bins a larger node filled.
    #[test]
    fn bins_filled_in_place_equal_fresh_bins() {
        let mut rng = StdRng::seed_from_u64(5);
        let mut reused = Bins::EMPTY;
        for (k, n) in [1usize, 3, 17, 63, 64, 100, 255, 256, 700, 2000].into_iter().cycle().take(40).enumerate() {
            let prims: Vec<Prim> = (0..n)
                .map(|i| {
                    let mut v = |range: std::ops::Range<f32>| {
                        Vec3A::new(rng.random_range(range.clone()), rng.random_range(range.clone()), rng.random_range(range))
                    };
                    let lo = v(-5.0..5.0);
                    Prim::new(i as u32, lo, lo + v(0.0..1.0))
                })
                .collect();
            let cb = PrimBounds::of(&prims).centroids;
            let nb = [4, 9, 16][k % 3];
            let axis = [None, Some(0), Some(2), None][k % 4];
            let scale = bin_scale(&cb, nb);
            let mut fresh = Bins::EMPTY;
            for p in &prims {
                let b = bins_of(p.centroid2(), cb.min, scale, nb);
                for a in axis.map_or(0..3, |a| a..a + 1) {
                    fresh.bounds[a][b[a]].grow(&p.bounds());
                    fresh.counts[a][b[a]] += 1;
                }
            }
            bin_prims_into(&mut reused, &prims, cb.min, scale, nb, axis);
            let bits = |b: &Bounds| (b.min.to_array().map(f32::to_bits), b.max.to_array().map(f32::to_bits));
            for a in axis.map_or(0..3, |a| a..a + 1) {
                for b in 0..nb {
                    assert_eq!(reused.counts[a][b], fresh.counts[a][b], "node {k} ({n} prims), axis {a}, bin {b}");
                    assert_eq!(bits(&reused.bounds[a][b]), bits(&fresh.bounds[a][b]), "node {k} ({n} prims), axis {a}, bin {b}");
                }
            }
        }
    }

    #[test]
    fn one_axis_bin_equals_simd_bins() {
        let mut rng = StdRng::seed_from_u64(17);
        let special = [0.0, -0.0, f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 1e30, -1e30, f32::MIN_POSITIVE];
        for k in 0..20_000 {
            let mut r = || if k % 7 == 0 { special[rng.random_range(0..special.len())] } else { rng.random_range(-10.0f32..10.0) };
            let (c, lo) = (Vec3A::new(r(), r(), r()), Vec3A::new(r(), r(), r()));
            let scale = Vec3A::new(r().abs(), r().abs(), r().abs());
            let nb = 4 + k % 13;
            let all = bins_of(c, lo, scale, nb);
            for axis in 0..3 {
                assert_eq!(bin_of(c[axis], lo[axis], scale[axis], nb), all[axis], "{c} {lo} {scale} {nb}");
            }
        }
    }

    #[test]
    fn partition_splits_by_predicate_and_gathers_both_sides_boxes() {
        let mut prims: Vec<Prim> = (0..37).map(|i| Prim::new(i, Vec3A::splat(i as f32), Vec3A::splat(i as f32 + 1.0))).collect();
        let (mid, lb, rb) = partition(&mut prims, |p| p.index() % 3 == 0);
        assert_eq!(mid, 13);
        assert!(prims[..mid].iter().all(|p| p.index() % 3 == 0));
        assert!(prims[mid..].iter().all(|p| p.index() % 3 != 0));
        // Left: primitives 0, 3, …, 36; right: 1, 2, 4, …, 35.
        assert_eq!((lb.bounds.min, lb.bounds.max), (Vec3A::splat(0.0), Vec3A::splat(37.0)));
        assert_eq!((rb.bounds.min, rb.bounds.max), (Vec3A::splat(1.0), Vec3A::splat(36.0)));
        assert_eq!((lb.centroids.min, lb.centroids.max), (Vec3A::splat(1.0), Vec3A::splat(73.0)));
        assert_eq!((rb.centroids.min, rb.centroids.max), (Vec3A::splat(3.0), Vec3A::splat(71.0)));
    }
}
