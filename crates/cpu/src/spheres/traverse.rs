//! The sphere BVH's traversals: single rays (closest and any hit), the capsule's tile batches
//! from a shared cut, and the exact perpendicular-distance sphere tests they end in.

use super::*;
use crate::bvh_core::{NodeTest, closest_walk, stack_entry};

impl SphereBvh {
    /// The closest sphere hit by the ray `origin + t·dir` with `t_min ≤ t ≤ t_max`: the hit `t`
    /// (in units of `dir`'s length) and the sphere's index into the `centers` given to `build`.
    /// Rays starting inside a sphere hit its far side.
    pub fn closest_hit(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Option<(f32, u32)> {
        self.closest_hit_slot(origin, dir, t_min, t_max).map(|(t, slot)| (t, self.indices[slot as usize]))
    }

    /// The original index (into the `centers` given to `build`) of leaf-order slot `slot`.
    pub fn index_of_slot(&self, slot: u32) -> u32 {
        self.indices[slot as usize]
    }

    /// As [`SphereBvh::closest_hit`], but returns the sphere's leaf-order slot (see
    /// [`SphereBvh::center_of_slot`], [`SphereBvh::index_of_slot`]).
    pub fn closest_hit_slot(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Option<(f32, u32)> {
        self.closest_hit_slot_with(&mut TraversalStack::default(), origin, dir, t_min, t_max)
    }

    /// As [`SphereBvh::closest_hit_slot`], reusing `stack` (one per thread saves its set-up per ray).
    pub fn closest_hit_slot_with(&self, stack: &mut TraversalStack, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Option<(f32, u32)> {
        self.query::<false>(stack, origin, dir, t_min, t_max)
    }

    /// Whether any sphere is hit with `t_min ≤ t ≤ t_max` (exactly when
    /// [`SphereBvh::closest_hit_slot_with`] finds a hit), stopping at the first one found.
    pub fn any_hit_with(&self, stack: &mut TraversalStack, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> bool {
        self.query::<true>(stack, origin, dir, t_min, t_max).is_some()
    }

    /// One ray from the root: the closest hit, or (`ANY`) the first one found.
    #[inline]
    pub(super) fn query<const ANY: bool>(
        &self,
        stack: &mut TraversalStack,
        origin: Vec3,
        dir: Vec3,
        t_min: f32,
        t_max: f32,
    ) -> Option<(f32, u32)> {
        let (ray, len) = self.prepare(origin, dir, t_min, t_max)?;
        // Entry distances are never negative when `t_min` is not: the cheaper slab form applies.
        let stack = &mut stack.0;
        if ray.t_min >= 0.0 {
            self.traverse::<true, ANY>(stack, 0, &ray, len, self.root)
        } else {
            self.traverse::<false, ANY>(stack, 0, &ray, len, self.root)
        }
    }

    /// The ray of [`SphereBvh::closest_hit_slot_with`], prepared: `(ray, |dir|)`, or `None` when
    /// it cannot hit anything (empty tree, unusable direction or range, or it misses the root box).
    #[inline]
    pub(super) fn prepare(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Option<(Ray, f32)> {
        if self.indices.is_empty() {
            return None;
        }
        let len = dir.length();
        let usable = len > 0.0 && len.is_finite() && t_max >= t_min;
        if !usable {
            return None;
        }
        // `dir / len` as one vector division (the same quotients as three scalar ones).
        let ray = Ray::new(origin, (dir.extend(0.0) / len).truncate(), t_min * len, t_max * len, self.radius);
        // Cull against the root box first.
        let (e, x) = ray.slab(self.root_min, self.root_max);
        if e > x { None } else { Some((ray, len)) }
    }

    /// The ray of [`SphereBvh::closest_hit_slot_with`] as the traversal sees it, for a caller that
    /// finds candidate spheres by other means ([`crate::capsule`]'s projected primary rays) and
    /// tests them with [`sphere_hits4`]: unit direction, `t` range in its units, and `|dir|`
    /// to divide a hit's `t` by. `None` exactly where the traversal would not start.
    #[inline]
    pub fn prepare_ray(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Option<PreparedRay> {
        self.prepare(origin, dir, t_min, t_max).map(|(r, len)| PreparedRay { o: r.o, d: r.d, t_min: r.t_min, t_max: r.t_max, len })
    }

    /// Sphere centres in leaf-order slots, one slice per axis (each padded past [`SphereBvh::len`]).
    pub fn centers_soa(&self) -> (&[f32], &[f32], &[f32]) {
        (&self.xs, &self.ys, &self.zs)
    }

    /// [`SphereBvh::closest_hit_slot_with`] for a batch of rays (for instance one screen tile's
    /// primary rays): `hits[i]` is exactly its result for `rays[i]`. When the rays share one
    /// origin (bit for bit) and have `t_min ≥ 0`, the subtrees that any of them may enter are found
    /// once for the batch (a cut of the tree under the batch's frustum, [`BatchScratch`]) and each
    /// ray starts from them instead of the root, skipping the levels above.
    pub fn closest_hits_batch(
        &self,
        scratch: &mut BatchScratch,
        stack: &mut TraversalStack,
        rays: &[BatchRay],
        hits: &mut [Option<(f32, u32)>],
    ) {
        assert_eq!(rays.len(), hits.len(), "one hit slot per ray");
        let prepared = &mut scratch.rays;
        prepared.clear();
        prepared.extend(rays.iter().map(|r| self.prepare(r.origin, r.dir, r.t_min, r.t_max)));
        let shared = rays.first().map(|r| r.origin.to_array());
        let cut = shared.is_some_and(|o| rays.iter().all(|r| r.origin.to_array() == o)) && self.root & LEAF == 0;
        let cut = cut && self.batch_cut(scratch);
        let stack = &mut stack.0;
        for (p, hit) in scratch.rays.iter().zip(hits.iter_mut()) {
            *hit = None;
            let Some((ray, len)) = p else { continue };
            if ray.t_min < 0.0 {
                *hit = self.traverse::<false, false>(stack, 0, ray, *len, self.root);
                continue;
            }
            if !cut {
                *hit = self.traverse::<true, false>(stack, 0, ray, *len, self.root);
                continue;
            }
            // The cut's entries this ray enters, in the cut's order (nearest first for the
            // batch, about so for each ray; the order only steers pruning): the first is visited
            // now, the others stacked last first.
            let mut order = [(0u32, 0f32); CUT_MAX];
            let mut k = 0;
            for (top, chunks) in scratch.tops.iter().zip(scratch.chunks.chunks(4)) {
                let (_, mut chunk_mask) = ray.slab4::<true>(top, ray.t_max);
                while chunk_mask != 0 {
                    let node = &chunks[chunk_mask.trailing_zeros() as usize];
                    chunk_mask &= chunk_mask - 1;
                    let (entry, mut mask) = ray.slab4::<true>(node, ray.t_max);
                    let entry = entry.to_array();
                    while mask != 0 {
                        let lane = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        order[k] = (node.child[lane], entry[lane]);
                        k += 1;
                    }
                }
            }
            if k == 0 {
                continue;
            }
            for (j, &(child, near)) in order[1..k].iter().rev().enumerate() {
                stack[j] = stack_entry(child, near);
            }
            *hit = self.traverse::<true, false>(stack, k - 1, ray, *len, order[0].0);
        }
    }

    /// The cut of the tree for the prepared rays in `scratch` (those with `t_min ≥ 0`; all share
    /// one origin): subtrees, at most `CUT_MAX`, such that any node or leaf one of these rays
    /// enters (by [`Ray::slab4`]'s `NONNEG` test) on its way down from the root lies in one of them.
    /// Stored as 4-wide nodes in `scratch.chunks` (their boxes as in their parents) under
    /// 4-wide nodes in `scratch.tops` (one per four chunks); returns false when there is no ray to
    /// trace (then the scratch is stale).
    ///
    /// The batch's test bounds each ray's: per axis (where all the rays' directions have one
    /// sign) the slab plane distances `fl((p − o)·inv)` are monotone in `inv`, so they lie between
    /// those at the batch's extreme `inv`; max and min keep the order, so each ray's `near` is ≥ the
    /// batch's and its `far` (with `limit ≤ t_max`) ≤ the batch's, and `near ≤ fl(far·S)` for the
    /// ray gives it for the batch (rounding is monotone). Axes along which the directions change
    /// sign are left out of the batch's test (no constraint).
    pub(super) fn batch_cut(&self, scratch: &mut BatchScratch) -> bool {
        // Bounds of (1/d, t_min) and (1/d, t_max) as 4 lanes (no NaN here: usable rays only).
        let (mut lo4, mut hi4) = (Vec4::INFINITY, Vec4::NEG_INFINITY);
        let mut origin = None;
        for (ray, _) in scratch.rays.iter().flatten().filter(|(r, _)| r.t_min >= 0.0) {
            lo4 = lo4.min(ray.inv.extend(ray.t_min));
            hi4 = hi4.max(ray.inv.extend(ray.t_max));
            origin = Some(ray.o);
        }
        let Some(o) = origin else { return false };
        let (lo, hi, t_lo, t_hi) = (lo4.truncate(), hi4.truncate(), lo4.w, hi4.w);
        let test = |n: &Node4| -> (Vec4, u32) {
            let mut near = Vec4::splat(t_lo);
            let mut far = Vec4::splat(t_hi);
            for a in 0..3 {
                let (l, h) = (Vec4::splat(lo[a]), Vec4::splat(hi[a]));
                let oa = Vec4::splat(o[a]);
                let (p_near, p_far) = if lo[a] > 0.0 {
                    (n.lo(a), n.hi(a))
                } else if hi[a] < 0.0 {
                    (n.hi(a), n.lo(a))
                } else {
                    continue;
                };
                let (a_near, a_far) = (p_near - oa, p_far - oa);
                near = near.max((a_near * l).min(a_near * h));
                far = far.min((a_far * l).max(a_far * h));
            }
            (near, near.cmple(far * Vec4::splat(NONNEG_SLACK)).bitmask())
        };
        // Greedy: open the entry with the largest box while the cut stays within `CUT_MAX`. Opened
        // entries stay in `cut` marked dead (no shifting); `open` is a max-heap of the open
        // entries by box area (non-negative, so the bits order like the floats).
        let cut = &mut scratch.cut;
        cut.clear();
        let open = &mut scratch.open;
        open.clear();
        let push_kids =
            |cut: &mut Vec<CutEntry>, open: &mut std::collections::BinaryHeap<(u32, u32)>, n: &Node4, (near, mut mask): (Vec4, u32)| {
                while mask != 0 {
                    let lane = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    if n.child[lane] == EMPTY_SLOT {
                        continue;
                    }
                    let (lo, hi) = n.child_box(lane);
                    let (lo, hi) = (Vec3::from(lo), Vec3::from(hi));
                    if n.child[lane] & LEAF == 0 {
                        let e = hi - lo;
                        open.push(((e.x * e.y + e.y * e.z + e.z * e.x).to_bits(), cut.len() as u32));
                    }
                    cut.push(CutEntry { child: n.child[lane], lo, hi, dead: false, near: near[lane] });
                }
            };
        let root = &self.nodes[self.root as usize];
        push_kids(cut, open, root, test(root));
        let mut live = cut.len();
        // Stop at the first entry that does not fit (each try costs a node fetch).
        while let Some(&(_, i)) = open.peek() {
            let i = i as usize;
            let n = &self.nodes[cut[i].child as usize];
            let tested = test(n);
            let kids = tested.1.count_ones() as usize;
            if live - 1 + kids > CUT_MAX {
                break;
            }
            open.pop();
            cut[i].dead = true;
            live = live - 1 + kids;
            push_kids(cut, open, n, tested);
        }
        cut.retain(|e| !e.dead);
        // Nearest first by the batch's entry distance: each ray then finds the entries it enters
        // in about its own near-to-far order without sorting them.
        cut.sort_by(|a, b| a.near.total_cmp(&b.near));
        scratch.chunks.clear();
        for group in cut.chunks(4) {
            let mut node = Node4::EMPTY;
            for (lane, c) in group.iter().enumerate() {
                node.set(lane, Vec3A::from(c.lo), Vec3A::from(c.hi), c.child);
            }
            scratch.chunks.push(node);
        }
        // Two levels: the chunks, then 4-wide nodes over the chunks' bounding boxes (a ray that
        // enters a box enters any box holding it: the slab distances are monotone in the planes).
        scratch.tops.clear();
        for group in scratch.chunks.chunks(4) {
            let mut top = Node4::EMPTY;
            for (lane, c) in group.iter().enumerate() {
                for a in 0..3 {
                    top.planes[a][lane] = c.lo(a).min_element();
                    top.planes[3 + a][lane] = c.hi(a).max_element();
                }
            }
            scratch.tops.push(top);
        }
        true
    }

    /// Ordered depth-first traversal from the subtree `root`, then the entries `stack[..sp]`:
    /// [`closest_walk`] with [`Ray::slab4`] and the leaves' spheres four at a time. `NONNEG`: the
    /// ray's `t_min` is ≥ 0 (see [`Ray::slab4`]). `ANY`: return the first hit found instead of
    /// the closest (for occlusion queries).
    #[inline]
    pub(super) fn traverse<const NONNEG: bool, const ANY: bool>(
        &self,
        stack: &mut [u64; STACK_LEN],
        sp: usize,
        ray: &Ray,
        len: f32,
        root: u32,
    ) -> Option<(f32, u32)> {
        let mut best_t = ray.t_max;
        let mut best = u32::MAX;
        let mut best_slot = 0u32;
        closest_walk(
            &self.nodes,
            stack,
            sp,
            root,
            &mut best_t,
            &PaddedSlabs::<NONNEG>(ray),
            #[inline(always)]
            |leaf: u32, mut best_t: f32| {
                let (start, count) = leaf_parts(leaf);
                let Some((t4, mut mask)) = ray.spheres4(&self.xs[start..], &self.ys[start..], &self.zs[start..], best_t, count) else {
                    return (best_t, false);
                };
                let t4 = t4.to_array();
                if ANY {
                    let lane = mask.trailing_zeros() as usize;
                    (best, best_slot) = (0, (start + lane) as u32);
                    return (t4[lane], true);
                }
                while mask != 0 {
                    let lane = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    let (t, slot) = (t4[lane], start + lane);
                    let idx = self.indices[slot];
                    if t < best_t || (t == best_t && idx < best) {
                        best_t = t;
                        best = idx;
                        best_slot = slot as u32;
                    }
                }
                (best_t, false)
            },
        );
        if best == u32::MAX { None } else { Some((best_t / len, best_slot)) }
    }
}

/// The sphere BVH's node test: [`Ray::slab4`] and [`Ray::may_enter`].
struct PaddedSlabs<'a, const NONNEG: bool>(&'a Ray);

impl<const NONNEG: bool> NodeTest for PaddedSlabs<'_, NONNEG> {
    #[inline(always)]
    fn enter(&self, n: &Node4, best_t: f32) -> (Vec4, u32) {
        self.0.slab4::<NONNEG>(n, best_t)
    }
    #[inline(always)]
    fn may_enter(&self, near: f32, best_t: f32) -> bool {
        Ray::may_enter::<NONNEG>(near, best_t)
    }
}

/// Exact ray–sphere intersection in the perpendicular-distance form for a unit direction `d`:
/// the ray parameter of the first intersection within `[t_min, t_max]`, if any.
#[inline]
pub fn ray_sphere(origin: Vec3, d: Vec3, center: Vec3, radius: f32, t_min: f32, t_max: f32) -> Option<f32> {
    let oc = center - origin;
    let tc = oc.dot(d);
    let perp = oc - tc * d;
    let p2 = perp.length_squared();
    let r2 = radius * radius;
    if p2 > r2 {
        return None;
    }
    let half = (r2 - p2).sqrt();
    let t0 = tc - half;
    if t0 >= t_min {
        return if t0 <= t_max { Some(t0) } else { None };
    }
    let t1 = tc + half;
    if t1 >= t_min && t1 <= t_max { Some(t1) } else { None }
}

/// Brute force over all spheres (for tests): the same test and tie rule as the BVH.
pub fn closest_hit_brute_force(centers: &[Vec3], radius: f32, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Option<(f32, u32)> {
    let len = dir.length();
    if !(len > 0.0 && len.is_finite()) {
        return None;
    }
    let d = dir / len;
    let mut best: Option<(f32, u32)> = None;
    for (i, c) in centers.iter().enumerate() {
        let limit = best.map_or(t_max * len, |b| b.0);
        if let Some(t) = ray_sphere(origin, d, *c, radius, t_min * len, limit)
            && best.is_none_or(|b| t < b.0)
        {
            best = Some((t, i as u32));
        }
    }
    best.map(|(t, i)| (t / len, i))
}

/// A ray as [`SphereBvh::prepare_ray`] gives it: origin, unit direction, `t` range in the unit
/// direction's units, and the length of the direction it was made from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PreparedRay {
    pub o: Vec3,
    pub d: Vec3,
    pub t_min: f32,
    pub t_max: f32,
    pub len: f32,
}

/// [`ray_sphere`] of one sphere (centre `c`, squared radius `r2`) against four rays (lanes: origins
/// `o`, unit directions `d`, ranges `t_min..=t_max`), each lane exactly the scalar operations in
/// the same order (so bit for bit [`ray_sphere`] and the traversal's leaf test): each lane's `t`
/// and the mask of the lanes hit.
#[inline(always)]
pub fn sphere_hits4(c: Vec3, r2: f32, o: [Vec4; 3], d: [Vec4; 3], t_min: Vec4, t_max: Vec4) -> (Vec4, u32) {
    let (ox, oy, oz) = (Vec4::splat(c.x) - o[0], Vec4::splat(c.y) - o[1], Vec4::splat(c.z) - o[2]);
    let [dx, dy, dz] = d;
    let tc = ox * dx + oy * dy + oz * dz;
    let (px, py, pz) = (ox - tc * dx, oy - tc * dy, oz - tc * dz);
    let p2 = px * px + py * py + pz * pz;
    let r2 = Vec4::splat(r2);
    let inside = p2.cmple(r2);
    let half = (r2 - p2).sqrt();
    let t0 = tc - half;
    let t1 = tc + half;
    let t = Vec4::select(t0.cmpge(t_min), t0, t1);
    (t, (inside & t.cmpge(t_min) & t.cmple(t_max)).bitmask())
}

/// A ray prepared for traversal (unit direction).
#[derive(Debug, Clone, Copy)]
pub(super) struct Ray {
    pub(super) o: Vec3,
    pub(super) d: Vec3,
    pub(super) inv: Vec3,
    pub(super) t_min: f32,
    pub(super) t_max: f32,
    pub(super) r: f32,
}

impl Ray {
    #[inline]
    pub(super) fn new(o: Vec3, d: Vec3, t_min: f32, t_max: f32, r: f32) -> Self {
        // A finite stand-in for 1/0 keeps 0·(1/d) from becoming NaN when the origin lies on a slab
        // plane. One vector division: each lane is the scalar `1.0 / c`, bit for bit.
        let d4 = d.extend(1.0);
        let tiny = d4.abs().cmplt(Vec4::splat(1e-30));
        let inv = Vec4::select(tiny, Vec4::splat(1e30).copysign(d4), Vec4::ONE / d4).truncate();
        Self { o, d, inv, t_min, t_max, r }
    }

    /// All four children's slab tests at once: their entry distances and the bit mask of the
    /// children entered within `[t_min, limit]`.
    ///
    /// `NONNEG = false` (any `t_min`): the entry distances are padded, `e = near − |near|·10⁻⁵`,
    /// `x = far + |far|·10⁻⁵` (this relative slack covers the rounding of the box and of the slab
    /// planes), and a child is entered when `e ≤ x` and `e ≤ limit`.
    ///
    /// `NONNEG = true` (`t_min ≥ 0`, so `near ≥ 0`): the same children and more, in fewer
    /// operations: entered when `near ≤ far·(1 + 3·10⁻⁵)`, the unpadded `near` returned. Whenever
    /// the padded test passes, `near·(1 − 10⁻⁵) ≤ far·(1 + 10⁻⁵)` up to two roundings (relative
    /// 2⁻²⁴ each), so `near ≤ far·(1 + 2.1·10⁻⁵)` (and `far ≤ limit`, `e ≤ limit` are covered by
    /// `far = min(…, limit)`); when `far < 0` the padded test fails (`x < 0 ≤ e`) whatever this one
    /// says. Hence no child, and so no sphere, is ever culled that the padded test would enter;
    /// [`Ray::may_enter`] likewise for the stacked entries.
    #[inline]
    pub(super) fn slab4<const NONNEG: bool>(&self, n: &Node4, limit: f32) -> (Vec4, u32) {
        // For a negative direction the max plane is entered first.
        let axis = |a: usize| {
            let o = Vec4::splat(self.o[a]);
            let inv = Vec4::splat(self.inv[a]);
            let t0 = (n.lo(a) - o) * inv;
            let t1 = (n.hi(a) - o) * inv;
            if self.inv[a] < 0.0 { (t1, t0) } else { (t0, t1) }
        };
        let (nx, fx) = axis(0);
        let (ny, fy) = axis(1);
        let (nz, fz) = axis(2);
        let limit = Vec4::splat(limit);
        let near = nx.max(ny).max(nz).max(Vec4::splat(self.t_min));
        let far = fx.min(fy).min(fz).min(limit);
        if NONNEG {
            // Empty slots give near = +∞, far = −∞ here and fail.
            return (near, near.cmple(far * Vec4::splat(NONNEG_SLACK)).bitmask());
        }
        // Empty slots give NaN here and fail both comparisons.
        let e = near - near.abs() * 1e-5;
        let x = far + far.abs() * 1e-5;
        (e, (e.cmple(x) & e.cmple(limit)).bitmask())
    }

    /// Whether a stacked child with entry distance `e` (from [`Ray::slab4`]) may still hold a hit
    /// at `t ≤ best_t`: `e ≤ best_t`, or for `NONNEG` (unpadded `e = near ≥ 0`) the looser
    /// `near ≤ best_t·(1 + 3·10⁻⁵)`, which holds whenever `near·(1 − 10⁻⁵) ≤ best_t` does.
    #[inline]
    pub(super) fn may_enter<const NONNEG: bool>(e: f32, best_t: f32) -> bool {
        if NONNEG { e <= best_t * NONNEG_SLACK } else { e <= best_t }
    }

    /// Entry and exit parameters of the box (entry > exit: miss), clipped to `[t_min, t_max]`.
    /// Boxes are padded by a relative epsilon so tangent sphere hits are never culled.
    #[inline]
    pub(super) fn slab(&self, min: Vec3, max: Vec3) -> (f32, f32) {
        let a = (min - self.o) * self.inv;
        let b = (max - self.o) * self.inv;
        let lo = a.min(b);
        let hi = a.max(b);
        let e = lo.max_element().max(self.t_min);
        let x = hi.min_element().min(self.t_max);
        // 1e-5 relative slack covers the rounding of the box and of the slab planes.
        (e - e.abs() * 1e-5, x + x.abs() * 1e-5)
    }

    /// [`ray_sphere`] on the `count` (≤ 4) spheres whose centres start these slices (each holds at
    /// least 4 values), as 4 lanes with exactly the scalar operations in the same order, so the
    /// results are bit for bit those of [`ray_sphere`]: each lane's `t` and the mask of the lanes
    /// hit within `[t_min, t_max]`.
    #[inline]
    pub(super) fn spheres4(&self, xs: &[f32], ys: &[f32], zs: &[f32], t_max: f32, count: u32) -> Option<(Vec4, u32)> {
        let (ox, oy, oz) = (Vec4::from_slice(xs) - self.o.x, Vec4::from_slice(ys) - self.o.y, Vec4::from_slice(zs) - self.o.z);
        let (dx, dy, dz) = (Vec4::splat(self.d.x), Vec4::splat(self.d.y), Vec4::splat(self.d.z));
        let tc = ox * dx + oy * dy + oz * dz;
        let (px, py, pz) = (ox - tc * dx, oy - tc * dy, oz - tc * dz);
        let p2 = px * px + py * py + pz * pz;
        let r2 = Vec4::splat(self.r * self.r);
        let inside = p2.cmple(r2).bitmask() & ((1u32 << count) - 1);
        if inside == 0 {
            return None;
        }
        let half = (r2 - p2).sqrt();
        let t0 = tc - half;
        let t1 = tc + half;
        let t_min = Vec4::splat(self.t_min);
        let t = Vec4::select(t0.cmpge(t_min), t0, t1);
        let mask = inside & (t.cmpge(t_min) & t.cmple(Vec4::splat(t_max))).bitmask();
        if mask == 0 { None } else { Some((t, mask)) }
    }
}
