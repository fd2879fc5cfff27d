//! The BVH's traversals: ordered closest-hit (nearest child first) and the unordered pack walk
//! that shadow rays use.

use super::*;
use crate::bvh_core::{NodeTest, STACK_LEN, closest_walk};
use crate::isa;

impl SceneBvh {
    /// The closest triangle hit with `t_min < t < t_max` along `origin + t·dir`.
    pub fn closest_hit(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Option<Hit> {
        if self.nodes.is_empty() {
            return None;
        }
        HIT_STACK.with(|cell| match cell.try_borrow_mut() {
            Ok(mut stack) => isa::dispatch(
                #[inline(always)]
                || self.closest_hit_with(&mut stack, origin, dir, t_min, t_max),
            ),
            Err(_) => self.closest_hit_with(&mut [0; STACK_LEN], origin, dir, t_min, t_max),
        })
    }

    #[inline(always)]
    pub(super) fn closest_hit_with(&self, stack: &mut [u64; STACK_LEN], origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Option<Hit> {
        let r = RayPre::new(Vec3A::from(origin), Vec3A::from(dir));
        // The hit is the least (t, slot) pair, whatever order the leaves come in (so that a
        // packet, which visits them in another order, finds the same one): a triangle at the
        // closest distance so far still wins if its slot is lower. Slot 0 to start with means
        // that nothing ties with `t_max` itself, so a hit was found iff `best_t < t_max`.
        let mut best = ClosestSoFar { t: t_max, slot: 0, uv: (0.0, 0.0) };
        self.closest_from(stack, &r, t_min, 0, &mut best);
        (best.t < t_max).then(|| self.hit_of(&best))
    }

    /// The closest-hit traversal of the subtree of `start` (a node index or a leaf reference),
    /// improving on `closest`: [`closest_walk`] with the exact slab test and the leaves' packs.
    #[inline(always)]
    pub(super) fn closest_from(&self, stack: &mut [u64; STACK_LEN], r: &RayPre, t_min: f32, start: u32, closest: &mut ClosestSoFar) {
        let (mut best, mut best_uv) = (closest.slot, closest.uv);
        let mut best_t = closest.t;
        let test = ExactSlabs { r, t_min };
        closest_walk(
            &self.nodes,
            stack,
            0,
            start,
            &mut best_t,
            &test,
            #[inline(always)]
            |leaf: u32, best_t: f32| (self.leaf_closest(leaf, r, t_min, best_t, &mut best, &mut best_uv), false),
        );
        *closest = ClosestSoFar { t: best_t, slot: best, uv: best_uv };
    }

    /// Tests the packs of `leaf` for a hit closer than `(best_t, best)` (the `(t, slot)` rule);
    /// returns the new closest distance, with `best` and `best_uv` updated on a hit.
    #[inline(always)]
    pub(super) fn leaf_closest(
        &self,
        leaf: u32,
        r: &RayPre,
        t_min: f32,
        mut best_t: f32,
        best: &mut usize,
        best_uv: &mut (f32, f32),
    ) -> f32 {
        let range = leaf_packs(leaf);
        let first = range.start;
        for (pi, pack) in self.packs[range].iter().enumerate() {
            let (t, u, v, mut mask) = intersect4_upto(pack, r, t_min, best_t);
            if mask != 0 {
                let (t, u, v) = (t.to_array(), u.to_array(), v.to_array());
                while mask != 0 {
                    let lane = mask.trailing_zeros() as usize & 3;
                    mask &= mask - 1;
                    let slot = (first + pi) * 4 + lane;
                    if t[lane] < best_t || (t[lane] == best_t && slot < *best) {
                        best_t = t[lane];
                        *best = slot;
                        *best_uv = (u[lane], v[lane]);
                    }
                }
            }
        }
        best_t
    }

    /// The hit of a ray's closest hit so far.
    #[inline(always)]
    pub(super) fn hit_of(&self, c: &ClosestSoFar) -> Hit {
        Hit { t: c.t, triangle: self.slot_ref[c.slot], bary: Vec3::new(1.0 - c.uv.0 - c.uv.1, c.uv.0, c.uv.1) }
    }

    /// Whether a triangle whose material casts shadows and is not fully transparent is hit
    /// with `t_min < t < t_max`.
    pub fn occluded(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> bool {
        let mut hit = false;
        self.for_each_pack_hit(origin, dir, t_min, t_max, |_, _, _, _, _| {
            hit = true;
            false
        });
        hit
    }

    /// Calls `f(leaf reference, first slot of the pack, mask, u, v)` for every pack with triangles hit on the
    /// segment that can block light, in no particular order, until `f` returns false. `mask`
    /// bits 0–3 are the lanes hit (triangles that cast shadows, transparency < 1); bits 4–7
    /// are set instead (bits 0–3 clear) when one of the lanes hit is opaque.
    #[inline]
    pub(super) fn for_each_pack_hit(
        &self,
        origin: Vec3,
        dir: Vec3,
        t_min: f32,
        t_max: f32,
        f: impl FnMut(u32, usize, u32, [f32; 4], [f32; 4]) -> bool,
    ) {
        if self.nodes.is_empty() {
            return;
        }
        self.for_each_pack_hit_with(&RayPre::new(Vec3A::from(origin), Vec3A::from(dir)), t_min, t_max, f)
    }

    #[inline(always)]
    pub(super) fn for_each_pack_hit_with(
        &self,
        r: &RayPre,
        t_min: f32,
        t_max: f32,
        f: impl FnMut(u32, usize, u32, [f32; 4], [f32; 4]) -> bool,
    ) {
        self.for_each_pack_hit_from(r, t_min, t_max, 0, f);
    }

    /// [`for_each_pack_hit`](Self::for_each_pack_hit) in the subtree of `start` (a node
    /// index or a leaf reference); returns false if `f` stopped the walk.
    #[inline(always)]
    pub(super) fn for_each_pack_hit_from(
        &self,
        r: &RayPre,
        t_min: f32,
        t_max: f32,
        start: u32,
        mut f: impl FnMut(u32, usize, u32, [f32; 4], [f32; 4]) -> bool,
    ) -> bool {
        // The nodes still to visit are `stack[..sp]`: a fixed array indexed modulo its
        // power-of-two length, so that no bounds or capacity check sits in the loop (a `Vec`'s
        // push and pop were measurably slower). It cannot fill: see `STACK_LEN`.
        let mut stack = [0u32; TRI_STACK_LEN];
        const WRAP: usize = TRI_STACK_LEN - 1;
        let mut sp = 0usize;
        let mut cur = start;
        loop {
            if cur & LEAF == 0 {
                let n = &self.nodes[cur as usize];
                let (_, mut mask) = node_hits(n, r, t_min, t_max);
                if mask != 0 {
                    cur = n.child[mask.trailing_zeros() as usize & 3];
                    mask &= mask - 1;
                    while mask != 0 {
                        debug_assert!(sp < TRI_STACK_LEN, "any-hit stack overflow");
                        stack[sp & WRAP] = n.child[mask.trailing_zeros() as usize & 3];
                        sp += 1;
                        mask &= mask - 1;
                    }
                    continue;
                }
            } else if !self.leaf_pack_hits(cur, r, t_min, t_max, &mut f) {
                return false;
            }
            if sp == 0 {
                return true;
            }
            sp -= 1;
            cur = stack[sp & WRAP];
        }
    }

    /// The any-hit walk's leaf: calls `f` (as [`for_each_pack_hit`](Self::for_each_pack_hit)
    /// does) for each pack of `leaf` with triangles hit that can block light; false if `f`
    /// stopped.
    #[inline(always)]
    pub(super) fn leaf_pack_hits(
        &self,
        leaf: u32,
        r: &RayPre,
        t_min: f32,
        t_max: f32,
        f: &mut impl FnMut(u32, usize, u32, [f32; 4], [f32; 4]) -> bool,
    ) -> bool {
        let range = leaf_packs(leaf);
        let first = range.start;
        for (k, (pack, &shadow)) in self.packs[range.clone()].iter().zip(&self.pack_shadow[range]).enumerate() {
            let (_, u, v, hit) = intersect4(pack, r, t_min, t_max);
            let hit = hit & shadow as u32 & 15;
            if hit != 0 {
                let opaque = hit & (shadow as u32 >> 4);
                let mask = if opaque != 0 { opaque << 4 } else { hit };
                if !f(leaf, (first + k) * 4, mask, u.to_array(), v.to_array()) {
                    return false;
                }
            }
        }
        true
    }
}

/// A ray's closest hit so far: distance, pack slot, and the weights of corners 1 and 2.
#[derive(Clone, Copy)]
pub(super) struct ClosestSoFar {
    pub(super) t: f32,
    pub(super) slot: usize,
    pub(super) uv: (f32, f32),
}

/// Length of the any-hit and packet traversal stacks (a power of two; the closest-hit walk's is
/// [`STACK_LEN`]). A 4-wide node stacks at most three children, and a path is at most
/// `MAX_DEPTH` (56) nodes deep plus the ≤ 8 levels `Packer::leaf` adds above an oversized leaf,
/// so at most 192 entries are ever stacked.
pub(super) const TRI_STACK_LEN: usize = 256;

/// The triangle BVH's node test: the exact slab test of [`node_hits`] from `t_min`.
pub(super) struct ExactSlabs<'a> {
    pub(super) r: &'a RayPre,
    pub(super) t_min: f32,
}

impl NodeTest for ExactSlabs<'_> {
    #[inline(always)]
    fn enter(&self, n: &Node4, best_t: f32) -> (Vec4, u32) {
        node_hits(n, self.r, self.t_min, best_t)
    }
    #[inline(always)]
    fn may_enter(&self, near: f32, best_t: f32) -> bool {
        near <= best_t
    }
}

thread_local! {
    /// Per-thread closest-hit traversal stack, reused from ray to ray (its 64-bit entries
    /// would make a large array to zero for every ray).
    pub(super) static HIT_STACK: std::cell::RefCell<[u64; STACK_LEN]> = const { std::cell::RefCell::new([0; STACK_LEN]) };
}

/// Möller–Trumbore's arithmetic, once for every lane type: `(t, u, v)` of the ray `o + t·d`
/// against the triangle `v0, v0 + e1, v0 + e2` (`u`, `v`: the weights of corners 1 and 2).
/// `intersect4` runs it on four triangles (`Vec4` lanes, the ray splatted) and the packets on
/// one triangle and one ray per `f32` lane: the same operations in the same order, so the same
/// bits. Degenerate triangles give NaN or infinite lanes, which fail every hit test.
#[inline(always)]
pub(super) fn moller_trumbore<T>(o: [T; 3], d: [T; 3], v0: [T; 3], e1: [T; 3], e2: [T; 3], one: T) -> (T, T, T)
where
    T: Copy + std::ops::Add<Output = T> + std::ops::Sub<Output = T> + std::ops::Mul<Output = T> + std::ops::Div<Output = T>,
{
    let [dx, dy, dz] = d;
    let [e1x, e1y, e1z] = e1;
    let [e2x, e2y, e2z] = e2;
    // p = d × e2
    let px = dy * e2z - dz * e2y;
    let py = dz * e2x - dx * e2z;
    let pz = dx * e2y - dy * e2x;
    let det = e1x * px + e1y * py + e1z * pz;
    let inv_det = one / det;
    let sx = o[0] - v0[0];
    let sy = o[1] - v0[1];
    let sz = o[2] - v0[2];
    let u = (sx * px + sy * py + sz * pz) * inv_det;
    // q = s × e1
    let qx = sy * e1z - sz * e1y;
    let qy = sz * e1x - sx * e1z;
    let qz = sx * e1y - sy * e1x;
    let v = (dx * qx + dy * qy + dz * qz) * inv_det;
    let t = (e2x * qx + e2y * qy + e2z * qz) * inv_det;
    (t, u, v)
}

/// Möller–Trumbore on four triangles: `(t, u, v, mask of lanes hit with t_min < t < t_max)`;
/// `u`/`v` are the weights of corners 1/2.
#[inline(always)]
pub(super) fn intersect4(p: &Tri4, r: &RayPre, t_min: f32, t_max: f32) -> (Vec4, Vec4, Vec4, u32) {
    intersect4_in::<false>(p, r, t_min, t_max)
}

/// [`intersect4`] with `t_max` included (`t_min < t ≤ t_max`): closest-hit rays keep a
/// triangle that ties with the closest hit so far, for the (t, slot) rule.
#[inline(always)]
pub(super) fn intersect4_upto(p: &Tri4, r: &RayPre, t_min: f32, t_max: f32) -> (Vec4, Vec4, Vec4, u32) {
    intersect4_in::<true>(p, r, t_min, t_max)
}

#[inline(always)]
fn intersect4_in<const UPTO: bool>(p: &Tri4, r: &RayPre, t_min: f32, t_max: f32) -> (Vec4, Vec4, Vec4, u32) {
    let (t, u, v) = moller_trumbore(r.o, r.d, p.v0, p.e1, p.e2, Vec4::ONE);
    // NaN lanes (degenerate or unused triangles) fail every comparison.
    let below_max = if UPTO { t.cmple(Vec4::splat(t_max)) } else { t.cmplt(Vec4::splat(t_max)) };
    let hit = u.cmpge(Vec4::ZERO) & v.cmpge(Vec4::ZERO) & (u + v).cmple(Vec4::ONE) & t.cmpgt(Vec4::splat(t_min)) & below_max;
    (t, u, v, hit.bitmask())
}
