//! Ray packets: up to sixteen coherent rays (a 4×4 pixel tile's primary rays) traverse the BVH
//! together, as Embree's `rtcIntersect16` does.
//!
//! A packet visits a node once for all of its rays: each child box is tested against every
//! active ray at once (one ray per SIMD lane, sixteen lanes: one AVX-512 register, two AVX2 or
//! four SSE2 ones, as `isa::dispatch` compiles it), and a child is entered with the rays that hit
//! it. A leaf's triangles are tested one at a time against all of those rays. What a packet
//! saves over sixteen single rays is the per-ray work around the arithmetic: node fetches, stack
//! traffic, the sorting of children and the branches, which coherent rays share. Where a packet
//! has thinned out (at most [`SINGLE_RAYS_BELOW`] rays enter a node), those rays leave it and
//! finish with the single-ray traversal, from that node and the stacked ones they entered.
//!
//! Every ray's answer is bit for bit [`SceneBvh::closest_hit`]'s: each ray–box and
//! ray–triangle test does the single-ray kernel's operations in the same order (lane by lane
//! where the single-ray kernel tests four boxes or triangles at once), and the closest hit is
//! the least `(t, slot)` pair, which does not depend on the order in which leaves are visited.
//! Rays whose directions lie in different octants (tiles on the image's centre lines) are split
//! into one packet per octant, so that a packet's rays enter every box through the same planes.

use super::*;
use crate::bvh_core::STACK_LEN;
use crate::isa;

/// Most rays in one packet.
pub const PACKET: usize = 16;

/// One ray of a packet: origin, direction (any length; `t` is in its units) and the end of its
/// segment, `t_max`.
pub type PacketRay = (Vec3, Vec3, f32);

type Lanes = [f32; PACKET];

/// A packet's rays in SoA form (`[axis][lane]`).
struct Packet {
    o: [Lanes; 3],
    d: [Lanes; 3],
    inv: [Lanes; 3],
}

/// Each lane's closest hit so far: distance, pack slot, and the weights of corners 1 and 2.
struct Best {
    t: Lanes,
    slot: [u32; PACKET],
    u: Lanes,
    v: Lanes,
}

/// A node or leaf still to visit, with the rays that entered its box and their entry distances.
#[derive(Clone, Copy)]
struct Entry {
    node: u32,
    mask: u32,
    near: Lanes,
}

const NO_ENTRY: Entry = Entry { node: 0, mask: 0, near: [0.0; PACKET] };

thread_local! {
    /// Per-thread packet traversal stack (18 KiB: too large to zero for every packet).
    static PACKET_STACK: std::cell::RefCell<[Entry; TRI_STACK_LEN]> = const { std::cell::RefCell::new([NO_ENTRY; TRI_STACK_LEN]) };
}

impl SceneBvh {
    /// The closest triangle hit of each ray, with `t_min < t < t_max` (its own `t_max`): entry
    /// `i` of the result answers `rays[i]`, exactly as [`closest_hit`](Self::closest_hit)
    /// would; entries past `rays.len()` are `None`. Fastest on rays that start close together
    /// and point the same way, such as a 4×4 tile of primary rays; incoherent rays are better
    /// traced one at a time.
    ///
    /// # Panics
    /// If `rays` holds more than [`PACKET`] rays.
    pub fn closest_hits(&self, rays: &[PacketRay], t_min: f32) -> [Option<Hit>; PACKET] {
        assert!(rays.len() <= PACKET, "a packet holds at most {PACKET} rays, not {}", rays.len());
        let mut out = [None; PACKET];
        if self.nodes.is_empty() || rays.is_empty() {
            return out;
        }
        let mut p = Packet { o: [[0.0; PACKET]; 3], d: [[0.0; PACKET]; 3], inv: [[0.0; PACKET]; 3] };
        // Unused lanes: zero directions, never active.
        let mut best = Best { t: [0.0; PACKET], slot: [0; PACKET], u: [0.0; PACKET], v: [0.0; PACKET] };
        let mut octant = [0u8; PACKET];
        for (i, &(o, d, t_max)) in rays.iter().enumerate() {
            // As `RayPre::new` has them.
            let inv = Vec3A::from(d).recip();
            for axis in 0..3 {
                p.o[axis][i] = o[axis];
                p.d[axis][i] = d[axis];
                p.inv[axis][i] = inv[axis];
            }
            best.t[i] = t_max;
            octant[i] = u8::from(inv.x < 0.0) | u8::from(inv.y < 0.0) << 1 | u8::from(inv.z < 0.0) << 2;
        }
        let mut todo = (1u32 << rays.len()) - 1;
        let mut trace = |stack: &mut [Entry; TRI_STACK_LEN]| {
            while todo != 0 {
                let oct = octant[todo.trailing_zeros() as usize & (PACKET - 1)];
                let mask = (0..rays.len()).filter(|&i| octant[i] == oct).fold(0u32, |m, i| m | 1 << i) & todo;
                todo &= !mask;
                HIT_STACK.with(|single| match single.try_borrow_mut() {
                    Ok(mut single) => isa::dispatch(
                        #[inline(always)]
                        || self.packet_with(stack, &mut single, &p, &mut best, mask, oct, t_min),
                    ),
                    Err(_) => self.packet_with(stack, &mut [0; STACK_LEN], &p, &mut best, mask, oct, t_min),
                });
            }
        };
        PACKET_STACK.with(|cell| match cell.try_borrow_mut() {
            Ok(mut stack) => trace(&mut stack),
            Err(_) => trace(&mut Box::new([NO_ENTRY; TRI_STACK_LEN])),
        });
        for (i, &(_, _, t_max)) in rays.iter().enumerate() {
            if best.t[i] < t_max {
                let (u, v) = (best.u[i], best.v[i]);
                out[i] = Some(Hit { t: best.t[i], triangle: self.slot_ref[best.slot[i] as usize], bary: Vec3::new(1.0 - u - v, u, v) });
            }
        }
        out
    }

    /// Traverses with the rays of `mask`, whose directions all lie in octant `oct` (bit `a` set:
    /// negative on axis `a`).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn packet_with(
        &self,
        stack: &mut [Entry; TRI_STACK_LEN],
        single: &mut [u64; STACK_LEN],
        p: &Packet,
        best: &mut Best,
        mask: u32,
        oct: u8,
        t_min: f32,
    ) {
        let neg = |a: usize| oct >> a & 1 != 0;
        let near_plane = [0, 1, 2].map(|a| if neg(a) { 3 + a } else { a });
        let far_plane = [0, 1, 2].map(|a| if neg(a) { a } else { 3 + a });
        const WRAP: usize = TRI_STACK_LEN - 1;
        let mut sp = 0usize;
        let (mut cur, mut cur_mask) = (0u32, mask);
        // Rays that finished on their own.
        let mut finished = 0u32;
        loop {
            if cur_mask.count_ones() <= SINGLE_RAYS_BELOW {
                // Too few rays here to fill the lanes: each finishes on its own, through this
                // subtree and then the stacked ones it entered (their order does not change
                // the least (t, slot) hit).
                for i in lanes_of(cur_mask) {
                    let r = RayPre::new(Vec3A::new(p.o[0][i], p.o[1][i], p.o[2][i]), Vec3A::new(p.d[0][i], p.d[1][i], p.d[2][i]));
                    let mut closest = ClosestSoFar { t: best.t[i], slot: best.slot[i] as usize, uv: (best.u[i], best.v[i]) };
                    self.closest_from(single, &r, t_min, cur, &mut closest);
                    for j in (0..sp).rev() {
                        let e = &stack[j & WRAP];
                        if e.mask >> i & 1 != 0 && e.near[i] <= closest.t {
                            self.closest_from(single, &r, t_min, e.node, &mut closest);
                        }
                    }
                    (best.t[i], best.slot[i], best.u[i], best.v[i]) = (closest.t, closest.slot as u32, closest.uv.0, closest.uv.1);
                }
                finished |= cur_mask;
            } else if cur & LEAF == 0 {
                let n = &self.nodes[cur as usize];
                let mut near = [[0.0; PACKET]; 4];
                let mut hits = [0u32; 4];
                for k in 0..4 {
                    let lo = near_plane.map(|plane| n.planes[plane][k]);
                    let hi = far_plane.map(|plane| n.planes[plane][k]);
                    hits[k] = slab16(lo, hi, p, &best.t, t_min, &mut near[k]) & cur_mask;
                }
                if hits.iter().any(|&h| h != 0) {
                    // Visit the children nearest first, as the packet's first ray sees them
                    // (children it misses last); stack the others, farthest first.
                    let lead = cur_mask.trailing_zeros() as usize & (PACKET - 1);
                    let mut order = [(0u32, 0usize); 4];
                    let mut count = 0;
                    for k in 0..4 {
                        if hits[k] != 0 {
                            let key = if hits[k] >> lead & 1 != 0 { near[k][lead].to_bits() } else { u32::MAX };
                            let mut j = count;
                            while j > 0 && order[j - 1].0 > key {
                                order[j] = order[j - 1];
                                j -= 1;
                            }
                            order[j] = (key, k);
                            count += 1;
                        }
                    }
                    debug_assert!(sp + count <= TRI_STACK_LEN, "packet stack overflow");
                    for &(_, k) in order[1..count].iter().rev() {
                        stack[sp & WRAP] = Entry { node: n.child[k], mask: hits[k], near: near[k] };
                        sp += 1;
                    }
                    let k = order[0].1;
                    (cur, cur_mask) = (n.child[k], hits[k]);
                    continue;
                }
            } else {
                let range = leaf_packs(cur);
                let first = range.start;
                for (pi, pack) in self.packs[range].iter().enumerate() {
                    for lane in 0..4 {
                        tri16(pack, lane, ((first + pi) * 4 + lane) as u32, p, best, cur_mask, t_min);
                    }
                }
            }
            // Pop the next entry with rays that enter it before their closest hit so far.
            loop {
                if sp == 0 {
                    return;
                }
                sp -= 1;
                let e = &stack[sp & WRAP];
                let m = e.mask & !finished & lanes_le(&e.near, &best.t);
                if m != 0 {
                    (cur, cur_mask) = (e.node, m);
                    break;
                }
            }
        }
    }
}

/// A packet's rays go on one at a time where at most this many of them enter a node: below
/// that, testing sixteen lanes per box costs more than the rays' own traversals.
const SINGLE_RAYS_BELOW: u32 = 2;

/// The lanes set in `mask`, lowest first.
#[inline(always)]
fn lanes_of(mut mask: u32) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (mask != 0).then(|| {
            let i = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            i
        })
    })
}

/// `_mm_max_ps`'s rule (the second operand when either is NaN), as `Vec4::max` in `node_hits`.
#[inline(always)]
fn max_ps(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

/// `_mm_min_ps`'s rule, as `Vec4::min` in `node_hits`.
#[inline(always)]
fn min_ps(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

/// The lanes with `a ≤ b`, as a bit mask.
#[inline(always)]
fn lanes_le(a: &Lanes, b: &Lanes) -> u32 {
    let mut m = 0u32;
    for i in 0..PACKET {
        m |= u32::from(a[i] <= b[i]) << i;
    }
    m
}

/// Slab test of one box (entry planes `lo`, exit planes `hi`, per axis) against every lane, as
/// `node_hits` does it for one lane: entry distances into `near`, and the lanes that hit within
/// `[t_min, t_max]` as a bit mask.
#[inline(always)]
fn slab16(lo: [f32; 3], hi: [f32; 3], p: &Packet, t_max: &Lanes, t_min: f32, near: &mut Lanes) -> u32 {
    let mut far = [0.0; PACKET];
    for i in 0..PACKET {
        let (mut a, mut b) = (t_min, t_max[i]);
        for axis in 0..3 {
            a = max_ps(a, (lo[axis] - p.o[axis][i]) * p.inv[axis][i]);
            b = min_ps(b, (hi[axis] - p.o[axis][i]) * p.inv[axis][i]);
        }
        near[i] = a;
        far[i] = b;
    }
    lanes_le(near, &far)
}

/// Möller–Trumbore of triangle `lane` of a pack against every ray of `mask` (`moller_trumbore`,
/// as `intersect4` runs it for one ray), keeping each ray's least `(t, slot)` hit.
#[inline(always)]
fn tri16(pack: &Tri4, lane: usize, slot: u32, p: &Packet, best: &mut Best, mask: u32, t_min: f32) {
    let [e1, e2, v0] = [pack.e1, pack.e2, pack.v0].map(|c| c.map(|v| v[lane]));
    for i in 0..PACKET {
        let (t, u, v) = moller_trumbore([0, 1, 2].map(|a| p.o[a][i]), [0, 1, 2].map(|a| p.d[a][i]), v0, e1, e2, 1.0);
        // `&`, not `&&`: every condition is evaluated, so the loop stays branch-free.
        let hit = (u >= 0.0) & (v >= 0.0) & (u + v <= 1.0) & (t > t_min) & (t <= best.t[i]) & (mask >> i & 1 != 0);
        let better = hit & ((t < best.t[i]) | (slot < best.slot[i]));
        best.t[i] = if better { t } else { best.t[i] };
        best.slot[i] = if better { slot } else { best.slot[i] };
        best.u[i] = if better { u } else { best.u[i] };
        best.v[i] = if better { v } else { best.v[i] };
    }
}
