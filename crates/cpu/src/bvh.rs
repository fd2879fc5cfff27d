//! `bvh`: the scene's triangle BVH for the trace stage (design §1, "PreparedScene … BVHs").
//!
//! Our own BVH rather than obvhs: a binned-SAH binary build (16 bins on all three axes; large
//! nodes are binned in parallel, and the upper levels split in parallel with `rayon::join`),
//! collapsed into a 4-wide BVH whose four child boxes are tested at once with 4-lane SIMD (glam
//! `Vec4`), as Embree's BVH4 does. Traversal is tuned for the two ray kinds of paper 1:
//! - `closest_hit`: ordered traversal (hit children sorted by entry distance, nearest first);
//!   stacked entries farther than the closest hit so far are skipped;
//! - `any_hit_attenuation` (listing 8b): unordered traversal that visits every triangle on the
//!   segment once and stops as soon as the attenuation reaches 0. Which triangles matter to
//!   shadow rays is precomputed per triangle: materials that cast no shadows (or are fully
//!   transparent) are skipped before any shading; an opaque material (opacity 1 and no texture
//!   that can lower it: no diffuse-map alpha < 1, no optical map with blue < 1) ends the ray at
//!   once; only materials whose opacity varies over a texture are evaluated with `surface_at`.
//!
//! Leaves hold their triangles in packs of four as precomputed Möller–Trumbore data (`v0`, `e1`,
//! `e2`, SoA), tested together with 4-lane SIMD; the SAH counts leaf cost in packs. A leaf is
//! referenced straight from its parent's child slot (first pack and pack count packed into the
//! `u32`), and everything a hit needs (triangle, shadow class) is indexed by its pack slot
//! (`pack · 4 + lane`), so no indirection table sits between a hit and its triangle.
//!
//! The build is deterministic (same tree for any thread count): parallel binning merges exact
//! min/max/count partials, and the parallel halves build into separate subtrees that are
//! collapsed in a fixed depth-first order.

use glam::{Vec3, Vec3A, Vec4};
use rayon::prelude::*;

use hybrid_core::prepare::{PreparedScene, SHADOW_EVALUATE, TriangleRef, material_shadow};

/// A ray–triangle hit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Distance along the ray (in units of the ray direction's length).
    pub t: f32,
    pub triangle: TriangleRef,
    /// Weights of the triangle's three corners (sum 1), as `PreparedScene::surface_at` takes them.
    pub bary: Vec3,
}

/// A 4-wide node (SoA child boxes, tested together with 4-lane SIMD): `planes[axis]` /
/// `planes[3 + axis]` hold the four children's box minima/maxima on that axis (one array, so a
/// ray picks its entry and exit planes by precomputed index instead of a per-node select). `child[k]` is an inner node index,
/// a leaf reference (`LEAF | first pack << LEAF_PACK_BITS | (packs − 1)`), or [`EMPTY_SLOT`]
/// (its box is empty, so no ray enters it).
#[derive(Debug, Clone, Copy)]
#[repr(C, align(64))]
struct Node4 {
    planes: [Vec4; 6],
    child: [u32; 4],
}

const LEAF: u32 = 1 << 31;
/// Low bits of a leaf reference that hold its pack count − 1.
const LEAF_PACK_BITS: u32 = 4;
/// Most packs one leaf reference can name; larger leaves are split under an extra node.
const MAX_LEAF_PACKS: usize = 1 << LEAF_PACK_BITS;
const EMPTY_SLOT: u32 = u32::MAX;

/// The packs of a leaf reference.
#[inline(always)]
fn leaf_packs(c: u32) -> std::ops::Range<usize> {
    let first = ((c & !LEAF) >> LEAF_PACK_BITS) as usize;
    first..first + (c & (MAX_LEAF_PACKS as u32 - 1)) as usize + 1
}

impl Node4 {
    const EMPTY: Node4 = Node4 {
        planes: [Vec4::INFINITY, Vec4::INFINITY, Vec4::INFINITY, Vec4::NEG_INFINITY, Vec4::NEG_INFINITY, Vec4::NEG_INFINITY],
        child: [EMPTY_SLOT; 4],
    };
    fn set(&mut self, k: usize, b: &Bounds, child: u32) {
        for axis in 0..3 {
            self.planes[axis][k] = b.min[axis];
            self.planes[3 + axis][k] = b.max[axis];
        }
        self.child[k] = child;
    }
    #[cfg(test)]
    fn lo(&self, axis: usize) -> Vec4 {
        self.planes[axis]
    }
    #[cfg(test)]
    fn hi(&self, axis: usize) -> Vec4 {
        self.planes[3 + axis]
    }
}

/// A ray prepared for node tests: origin and inverse direction splatted per axis, and the
/// index in `Node4::planes` of the plane entered (`near`) and left (`far`) on each axis.
struct RayPre {
    o: [Vec4; 3],
    d: [Vec4; 3],
    inv: [Vec4; 3],
    near: [usize; 3],
    far: [usize; 3],
}

impl RayPre {
    #[inline(always)]
    fn new(o: Vec3A, d: Vec3A) -> Self {
        let inv = d.recip();
        let neg = [inv.x < 0.0, inv.y < 0.0, inv.z < 0.0];
        Self {
            o: [Vec4::splat(o.x), Vec4::splat(o.y), Vec4::splat(o.z)],
            d: [Vec4::splat(d.x), Vec4::splat(d.y), Vec4::splat(d.z)],
            inv: [Vec4::splat(inv.x), Vec4::splat(inv.y), Vec4::splat(inv.z)],
            near: [0, 1, 2].map(|a| if neg[a] { 3 + a } else { a }),
            far: [0, 1, 2].map(|a| if neg[a] { a } else { 3 + a }),
        }
    }
}

/// Slab test of the four children: entry distances and the bit mask of children hit within
/// `[t_min, t_max]`.
#[inline(always)]
fn node_hits(n: &Node4, r: &RayPre, t_min: f32, t_max: f32) -> (Vec4, u32) {
    let mut near = Vec4::splat(t_min);
    let mut far = Vec4::splat(t_max);
    for axis in 0..3 {
        near = near.max((n.planes[r.near[axis]] - r.o[axis]) * r.inv[axis]);
        far = far.min((n.planes[r.far[axis]] - r.o[axis]) * r.inv[axis]);
    }
    (near, near.cmple(far).bitmask())
}

/// Four precomputed Möller–Trumbore triangles in SoA form (`[axis]` lanes = triangles), tested
/// together. Unused lanes are degenerate (all zero) and never hit.
#[derive(Debug, Clone, Copy)]
struct Tri4 {
    v0: [Vec4; 3],
    e1: [Vec4; 3],
    e2: [Vec4; 3],
}

impl Tri4 {
    const EMPTY: Tri4 = Tri4 { v0: [Vec4::ZERO; 3], e1: [Vec4::ZERO; 3], e2: [Vec4::ZERO; 3] };
}

/// The last opaque shadow blocker of one light, for
/// [`SceneBvh::any_hit_attenuation_cached`]. Starts empty, and is emptied by a ray that no
/// opaque triangle blocks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ShadowCache {
    /// Leaf reference (as in [`Node4::child`]) of the last opaque blocker; [`EMPTY_SLOT`]
    /// when none.
    leaf: u32,
}

impl Default for ShadowCache {
    fn default() -> Self {
        Self { leaf: EMPTY_SLOT }
    }
}

/// Triangle of an unused pack lane.
const NO_TRI: TriangleRef = TriangleRef { mesh: u32::MAX, triangle: u32::MAX };

/// Triangle BVH over every triangle of a [`PreparedScene`].
#[derive(Debug, Clone)]
pub struct SceneBvh {
    /// 4-wide nodes; the root is node 0 (when there are triangles).
    nodes: Vec<Node4>,
    packs: Vec<Tri4>,
    /// Per pack, for shadow rays: bits 0–3 = lanes that can block light (material casts
    /// shadows, transparency < 1); bits 4–7 = lanes that block it fully (transparency 0).
    pack_shadow: Vec<u8>,
    /// Triangle of each pack slot (`pack · 4 + lane`); [`NO_TRI`] for unused lanes.
    slot_ref: Vec<TriangleRef>,
    /// Shadow-ray transparency of each pack slot (1 − opacity), or [`SHADOW_EVALUATE`].
    slot_shadow: Vec<f32>,
    triangles: usize,
    leaves: usize,
}

const BINS: usize = 16;
/// Leaves are forced below this many triangles unless the centroids coincide.
const MAX_LEAF: usize = 8;
/// Nodes at this depth become leaves whatever their size, so traversal stacks stay bounded.
const MAX_DEPTH: u32 = 56;
/// Subtrees larger than this are split in parallel.
const PARALLEL_MIN: usize = 8192;
/// Nodes larger than this are binned in parallel (chunks of this size).
const PARALLEL_BIN_MIN: usize = 32 * 1024;
/// SAH: cost of a 4-wide node test relative to a 4-triangle test.
const TRAVERSAL_COST: f32 = 1.0;
const INTERSECT_COST: f32 = 0.6;

#[derive(Clone, Copy)]
struct Bounds {
    min: Vec3A,
    max: Vec3A,
}

impl Bounds {
    const EMPTY: Self = Self { min: Vec3A::splat(f32::INFINITY), max: Vec3A::splat(f32::NEG_INFINITY) };
    #[inline]
    fn grow(&mut self, b: &Bounds) {
        self.min = self.min.min(b.min);
        self.max = self.max.max(b.max);
    }
    #[inline]
    fn grow_point(&mut self, p: Vec3A) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }
    #[inline]
    fn half_area(&self) -> f32 {
        let d = (self.max - self.min).max(Vec3A::ZERO);
        d.x * d.y + d.y * d.z + d.z * d.x
    }
}

/// Box and centroid box of a run of primitives.
#[derive(Clone, Copy)]
struct PrimBounds {
    bounds: Bounds,
    centroids: Bounds,
}

impl PrimBounds {
    const EMPTY: Self = Self { bounds: Bounds::EMPTY, centroids: Bounds::EMPTY };
    #[inline(always)]
    fn add(&mut self, p: &Prim) {
        self.bounds.grow(&p.bounds());
        self.centroids.grow_point(p.centroid2());
    }
    fn merge(mut self, o: Self) -> Self {
        self.bounds.grow(&o.bounds);
        self.centroids.grow(&o.centroids);
        self
    }
    fn of(prims: &[Prim]) -> Self {
        let serial = |c: &[Prim]| {
            let mut b = PrimBounds::EMPTY;
            c.iter().for_each(|p| b.add(p));
            b
        };
        if prims.len() >= PARALLEL_BIN_MIN {
            prims.par_chunks(PARALLEL_BIN_MIN).map(serial).reduce(|| PrimBounds::EMPTY, PrimBounds::merge)
        } else {
            serial(prims)
        }
    }
}

enum BuildNode {
    Leaf { bounds: Bounds, first: u32, count: u32 },
    Inner { bounds: Bounds, children: Box<(BuildNode, BuildNode)> },
}

/// A primitive during the build: its box, with its triangle index in the bits of `lo.w`. The
/// build partitions these records themselves (not indices into them), so every pass over a
/// node's primitives reads memory in order.
#[derive(Clone, Copy)]
struct Prim {
    lo: Vec4,
    hi: Vec4,
}

impl Prim {
    #[inline(always)]
    fn bounds(&self) -> Bounds {
        Bounds { min: Vec3A::from_vec4(self.lo), max: Vec3A::from_vec4(self.hi) }
    }
    /// Twice the box centre (the factor 2 does not change any split).
    #[inline(always)]
    fn centroid2(&self) -> Vec3A {
        Vec3A::from_vec4(self.lo) + Vec3A::from_vec4(self.hi)
    }
    #[inline(always)]
    fn index(&self) -> u32 {
        self.lo.w.to_bits()
    }
}

/// Lays out leaf packs in depth-first leaf order during the collapse (the packs themselves are
/// filled afterwards, in parallel, from these descriptors).
struct Packer<'a> {
    corners: &'a [[Vec3; 3]],
    /// Triangle index of each primitive position after the build's partitioning.
    order: &'a [u32],
    /// Per pack: first position in `order` and number of triangles (1–4).
    packs: Vec<(u32, u32)>,
    leaves: usize,
}

impl Packer<'_> {
    /// Packs the triangles `first..first + count` (positions in `order`); returns the reference
    /// to them: a leaf, or an extra node over up to four leaves when they need more than
    /// [`MAX_LEAF_PACKS`] packs.
    fn leaf(&mut self, first: u32, count: u32, nodes: &mut Vec<Node4>) -> u32 {
        let n_packs = (count as usize).div_ceil(4);
        if n_packs <= MAX_LEAF_PACKS {
            let start = self.packs.len() as u32;
            for chunk in (first..first + count).step_by(4) {
                self.packs.push((chunk, (first + count - chunk).min(4)));
            }
            self.leaves += 1;
            return LEAF | start << LEAF_PACK_BITS | (n_packs as u32 - 1);
        }
        // Triangles per part: a multiple of 4, at most four parts.
        let part = (n_packs.div_ceil(4) * 4) as u32;
        let idx = nodes.len();
        nodes.push(Node4::EMPTY);
        let mut node = Node4::EMPTY;
        for (k, s) in (first..first + count).step_by(part as usize).enumerate() {
            let c = part.min(first + count - s);
            let mut b = Bounds::EMPTY;
            for &tri in &self.order[s as usize..(s + c) as usize] {
                self.corners[tri as usize].iter().for_each(|p| b.grow_point(Vec3A::from(*p)));
            }
            let r = self.leaf(s, c, nodes);
            node.set(k, &b, r);
        }
        nodes[idx] = node;
        idx as u32
    }
}

impl SceneBvh {
    /// Builds the BVH over `prepared.triangles`.
    pub fn build(prepared: &PreparedScene) -> SceneBvh {
        let corners: Vec<[Vec3; 3]> = prepared.triangles.par_iter().map(|t| prepared.triangle(*t)).collect();
        let mut prims: Vec<Prim> = corners
            .par_iter()
            .enumerate()
            .map(|(i, c)| {
                let [a, b, d] = c.map(Vec3A::from);
                let idx = f32::from_bits(i as u32);
                // Non-finite corners make a point box: such triangles can never be hit anyway.
                if !(a.is_finite() && b.is_finite() && d.is_finite()) {
                    return Prim { lo: Vec4::ZERO.with_w(idx), hi: Vec4::ZERO };
                }
                Prim { lo: a.min(b).min(d).extend(idx), hi: a.max(b).max(d).extend(0.0) }
            })
            .collect();

        let scene = prepared.scene;
        let (root, material_shadow) = rayon::join(
            || {
                (!prims.is_empty()).then(|| {
                    let pb = PrimBounds::of(&prims);
                    build_rec(&mut prims, pb, 0, 0)
                })
            },
            || scene.materials.par_iter().map(|m| material_shadow(m, &scene.textures)).collect::<Vec<f32>>(),
        );

        let order: Vec<u32> = prims.iter().map(Prim::index).collect();
        drop(prims);
        let mut nodes = Vec::with_capacity(order.len() / 8);
        let mut packer = Packer { corners: &corners, order: &order, packs: Vec::with_capacity(order.len() / 3), leaves: 0 };
        match &root {
            None => {}
            Some(BuildNode::Leaf { bounds, first, count }) => {
                // A single leaf: a root node with one child.
                nodes.push(Node4::EMPTY);
                let r = packer.leaf(*first, *count, &mut nodes);
                nodes[0].set(0, bounds, r);
            }
            Some(inner) => {
                collapse(inner, &mut nodes, &mut packer);
            }
        }
        drop(root);

        let Packer { packs: descs, leaves, .. } = packer;
        // Per pack, in one parallel pass: the triangle data, and per lane the triangle and its
        // shadow transparency.
        let (packs, lanes): (Vec<Tri4>, Vec<[(TriangleRef, f32); 4]>) = descs
            .par_iter()
            .map(|&(first, n)| {
                let mut p = Tri4::EMPTY;
                let mut lanes = [(NO_TRI, 1.0f32); 4];
                for (lane, &tri) in order[first as usize..(first + n) as usize].iter().enumerate() {
                    let [a, b, c] = corners[tri as usize];
                    let (e1, e2) = (b - a, c - a);
                    for axis in 0..3 {
                        p.v0[axis][lane] = a[axis];
                        p.e1[axis][lane] = e1[axis];
                        p.e2[axis][lane] = e2[axis];
                    }
                    let t = prepared.triangles[tri as usize];
                    lanes[lane] = (t, material_shadow.get(prepared.meshes[t.mesh as usize].material).copied().unwrap_or(1.0));
                }
                (p, lanes)
            })
            .unzip();
        let slot_ref: Vec<TriangleRef> = lanes.iter().flat_map(|l| l.map(|(t, _)| t)).collect();
        let slot_shadow: Vec<f32> = lanes.iter().flat_map(|l| l.map(|(_, s)| s)).collect();
        // Bits 0–3: lanes that can block light; bits 4–7: lanes that block it fully.
        let pack_shadow: Vec<u8> = lanes
            .iter()
            .map(|l| (0..4).fold(0u8, |bits, k| bits | u8::from(l[k].1 != 1.0) << k | u8::from(l[k].1 == 0.0) << (k + 4)))
            .collect();
        SceneBvh { nodes, packs, pack_shadow, slot_ref, slot_shadow, triangles: order.len(), leaves }
    }

    /// Number of triangles in the BVH.
    pub fn triangle_count(&self) -> usize {
        self.triangles
    }

    /// Number of (4-wide) inner nodes.
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Number of leaves.
    pub fn leaf_count(&self) -> usize {
        self.leaves
    }

    /// The closest triangle hit with `t_min < t < t_max` along `origin + t·dir`.
    pub fn closest_hit(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Option<Hit> {
        if self.nodes.is_empty() {
            return None;
        }
        HIT_STACK.with(|cell| match cell.try_borrow_mut() {
            Ok(mut stack) => self.closest_hit_with(&mut stack, origin, dir, t_min, t_max),
            Err(_) => self.closest_hit_with(&mut [0; STACK_LEN], origin, dir, t_min, t_max),
        })
    }

    fn closest_hit_with(&self, stack: &mut [u64; STACK_LEN], origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Option<Hit> {
        let r = RayPre::new(Vec3A::from(origin), Vec3A::from(dir));
        let mut best_t = t_max;
        let mut best = usize::MAX;
        let mut best_uv = (0.0f32, 0.0f32);
        // Entries still to visit are `stack[..sp]`, indexed modulo the power-of-two length (no
        // bounds check; it cannot fill, see `STACK_LEN`).
        const WRAP: usize = STACK_LEN - 1;
        let mut sp = 0usize;
        let mut cur = 0u32;
        loop {
            if cur & LEAF == 0 {
                let n = &self.nodes[cur as usize];
                let (near, mask) = node_hits(n, &r, t_min, best_t);
                if mask != 0 {
                    if mask & (mask - 1) == 0 {
                        cur = n.child[mask.trailing_zeros() as usize & 3];
                        continue;
                    }
                    // Several children: sort them by entry distance (farthest first) with a
                    // branch-free sorting network on `distance bits << 32 | child` keys (entry
                    // distances are ≥ t_min ≥ 0 for the rays we trace, so their bits order like
                    // the floats; a wrong order would only cost time); stack all but the
                    // nearest, visit that one. Children missed get key 0, also without a
                    // branch (a hit's key is never 0: the root, node 0, is nobody's child).
                    let near = near.to_array();
                    let key = |c: usize| ((near[c].to_bits() as u64) << 32 | n.child[c] as u64) & (u64::from(mask >> c & 1)).wrapping_neg();
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
                    debug_assert!(sp + 3 <= STACK_LEN, "closest-hit stack overflow");
                    for (j, &key) in k[..3].iter().enumerate() {
                        stack[(sp + j) & WRAP] = key;
                    }
                    sp += hits - 1;
                    cur = k[(hits - 1) & 3] as u32;
                    continue;
                }
            } else {
                let range = leaf_packs(cur);
                let first = range.start;
                for (pi, pack) in self.packs[range].iter().enumerate() {
                    let (t, u, v, mut mask) = intersect4(pack, &r, t_min, best_t);
                    if mask != 0 {
                        let (t, u, v) = (t.to_array(), u.to_array(), v.to_array());
                        while mask != 0 {
                            let lane = mask.trailing_zeros() as usize & 3;
                            mask &= mask - 1;
                            if t[lane] < best_t {
                                best_t = t[lane];
                                best = (first + pi) * 4 + lane;
                                best_uv = (u[lane], v[lane]);
                            }
                        }
                    }
                }
            }
            // Pop the next entry that starts before the closest hit so far.
            loop {
                if sp == 0 {
                    return (best != usize::MAX).then(|| Hit {
                        t: best_t,
                        triangle: self.slot_ref[best],
                        bary: Vec3::new(1.0 - best_uv.0 - best_uv.1, best_uv.0, best_uv.1),
                    });
                }
                sp -= 1;
                let key = stack[sp & WRAP];
                if f32::from_bits((key >> 32) as u32) <= best_t {
                    cur = key as u32;
                    break;
                }
            }
        }
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

    /// Listing 8b: the fraction of light that passes along `origin + t·dir`, `0 < t < t_max`.
    /// Starts at 1; every triangle hit whose material casts shadows multiplies it by that
    /// surface's transparency (1 − opacity, textures included via `surface_at`); stops at 0.
    /// Each triangle counts once; materials that cast no shadows are ignored.
    pub fn any_hit_attenuation(&self, prepared: &PreparedScene, origin: Vec3, dir: Vec3, t_max: f32) -> f32 {
        self.any_hit_attenuation_cached(prepared, origin, dir, t_max, &mut ShadowCache::default())
    }

    /// [`any_hit_attenuation`](Self::any_hit_attenuation) with a shadow cache (Haines &
    /// Greenberg 1986): the leaf of the last opaque blocker found through `cache` is tested
    /// first, and a hit there ends the ray at 0 without a traversal. Neighbouring shadow rays
    /// towards one light are usually blocked by the same triangles, so keep one cache per light
    /// and trace a light's rays in pixel order. The result is the same as without the cache
    /// (an opaque blocker anywhere on the segment gives 0 either way).
    pub fn any_hit_attenuation_cached(
        &self,
        prepared: &PreparedScene,
        origin: Vec3,
        dir: Vec3,
        t_max: f32,
        cache: &mut ShadowCache,
    ) -> f32 {
        if self.nodes.is_empty() {
            return 1.0;
        }
        let r = RayPre::new(Vec3A::from(origin), Vec3A::from(dir));
        // A cache from another tree only costs time: any pack of this tree hit by an opaque lane
        // is a true blocker.
        if cache.leaf != EMPTY_SLOT && leaf_packs(cache.leaf).end <= self.packs.len() {
            let range = leaf_packs(cache.leaf);
            for (pack, &shadow) in self.packs[range.clone()].iter().zip(&self.pack_shadow[range]) {
                let (_, _, _, hit) = intersect4(pack, &r, 0.0, t_max);
                if hit & (shadow as u32 >> 4) != 0 {
                    return 0.0;
                }
            }
        }
        let mut att = 1.0f32;
        self.for_each_pack_hit_with(&r, 0.0, t_max, |leaf, slot0, mut mask, u, v| {
            if mask >> 4 != 0 {
                // An opaque blocker.
                cache.leaf = leaf;
                att = 0.0;
                return false;
            }
            while mask != 0 {
                let lane = mask.trailing_zeros() as usize & 3;
                mask &= mask - 1;
                let tr = self.slot_shadow[slot0 + lane];
                let tr = if tr == SHADOW_EVALUATE { self.textured_transparency(prepared, slot0 + lane, u[lane], v[lane]) } else { tr };
                att *= tr;
                if att <= 0.0 {
                    return false;
                }
            }
            true
        });
        if att > 0.0 {
            // No opaque blocker: the next ray towards this light most likely passes too, so
            // testing this blocker first would only cost time.
            cache.leaf = EMPTY_SLOT;
        }
        att.max(0.0)
    }

    /// Shadow transparency (1 − opacity) of the slot's triangle at corner weights (1 − u − v,
    /// u, v), from its textures. Out of line: it is rare, and inlined it would crowd the
    /// traversal loop.
    #[inline(never)]
    fn textured_transparency(&self, prepared: &PreparedScene, slot: usize, u: f32, v: f32) -> f32 {
        1.0 - prepared.surface_at(self.slot_ref[slot], Vec3::new(1.0 - u - v, u, v), 0.0).opacity
    }

    /// Calls `f(leaf reference, first slot of the pack, mask, u, v)` for every pack with triangles hit on the
    /// segment that can block light, in no particular order, until `f` returns false. `mask`
    /// bits 0–3 are the lanes hit (triangles that cast shadows, transparency < 1); bits 4–7
    /// are set instead (bits 0–3 clear) when one of the lanes hit is opaque.
    #[inline]
    fn for_each_pack_hit(
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
    fn for_each_pack_hit_with(&self, r: &RayPre, t_min: f32, t_max: f32, mut f: impl FnMut(u32, usize, u32, [f32; 4], [f32; 4]) -> bool) {
        // The nodes still to visit are `stack[..sp]`: a fixed array indexed modulo its
        // power-of-two length, so that no bounds or capacity check sits in the loop (a `Vec`'s
        // push and pop were measurably slower). It cannot fill: see `STACK_LEN`.
        let mut stack = [0u32; STACK_LEN];
        const WRAP: usize = STACK_LEN - 1;
        let mut sp = 0usize;
        let mut cur = 0u32;
        loop {
            if cur & LEAF == 0 {
                let n = &self.nodes[cur as usize];
                let (_, mut mask) = node_hits(n, r, t_min, t_max);
                if mask != 0 {
                    cur = n.child[mask.trailing_zeros() as usize & 3];
                    mask &= mask - 1;
                    while mask != 0 {
                        debug_assert!(sp < STACK_LEN, "any-hit stack overflow");
                        stack[sp & WRAP] = n.child[mask.trailing_zeros() as usize & 3];
                        sp += 1;
                        mask &= mask - 1;
                    }
                    continue;
                }
            } else {
                let range = leaf_packs(cur);
                let first = range.start;
                for (k, (pack, &shadow)) in self.packs[range.clone()].iter().zip(&self.pack_shadow[range]).enumerate() {
                    let (_, u, v, hit) = intersect4(pack, r, t_min, t_max);
                    let hit = hit & shadow as u32 & 15;
                    if hit != 0 {
                        let opaque = hit & (shadow as u32 >> 4);
                        let mask = if opaque != 0 { opaque << 4 } else { hit };
                        if !f(cur, (first + k) * 4, mask, u.to_array(), v.to_array()) {
                            return;
                        }
                    }
                }
            }
            if sp == 0 {
                return;
            }
            sp -= 1;
            cur = stack[sp & WRAP];
        }
    }
}

/// Length of the traversal stacks (a power of two). A 4-wide node stacks at most three
/// children, and a path is at most `MAX_DEPTH` (56) nodes deep plus the ≤ 8 levels
/// `Packer::leaf` adds above an oversized leaf, so at most 192 entries are ever stacked.
const STACK_LEN: usize = 256;

thread_local! {
    /// Per-thread closest-hit traversal stack, reused from ray to ray (its 64-bit entries
    /// would make a large array to zero for every ray).
    static HIT_STACK: std::cell::RefCell<[u64; STACK_LEN]> = const { std::cell::RefCell::new([0; STACK_LEN]) };
}

/// Möller–Trumbore on four triangles: `(t, u, v, mask of lanes hit with t_min < t < t_max)`;
/// `u`/`v` are the weights of corners 1/2.
#[inline(always)]
fn intersect4(p: &Tri4, r: &RayPre, t_min: f32, t_max: f32) -> (Vec4, Vec4, Vec4, u32) {
    let [dx, dy, dz] = r.d;
    let [e1x, e1y, e1z] = p.e1;
    let [e2x, e2y, e2z] = p.e2;
    // p = d × e2
    let px = dy * e2z - dz * e2y;
    let py = dz * e2x - dx * e2z;
    let pz = dx * e2y - dy * e2x;
    let det = e1x * px + e1y * py + e1z * pz;
    let inv_det = det.recip();
    let sx = r.o[0] - p.v0[0];
    let sy = r.o[1] - p.v0[1];
    let sz = r.o[2] - p.v0[2];
    let u = (sx * px + sy * py + sz * pz) * inv_det;
    // q = s × e1
    let qx = sy * e1z - sz * e1y;
    let qy = sz * e1x - sx * e1z;
    let qz = sx * e1y - sy * e1x;
    let v = (dx * qx + dy * qy + dz * qz) * inv_det;
    let t = (e2x * qx + e2y * qy + e2z * qz) * inv_det;
    // NaN lanes (degenerate or unused triangles) fail every comparison.
    let hit =
        u.cmpge(Vec4::ZERO) & v.cmpge(Vec4::ZERO) & (u + v).cmple(Vec4::ONE) & t.cmpgt(Vec4::splat(t_min)) & t.cmplt(Vec4::splat(t_max));
    (t, u, v, hit.bitmask())
}

fn build_rec(prims: &mut [Prim], pb: PrimBounds, offset: u32, depth: u32) -> BuildNode {
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
fn packs_of(n: usize) -> f32 {
    n.div_ceil(4) as f32
}

/// Bin of a centroid on each axis, in `0..nb` (`nb ≤ BINS`): `(c − lo) · scale` rounded down
/// (rounded to nearest after − ½, with the 2²³ trick so the conversion stays in SIMD registers;
/// the build uses this one function for binning and partitioning, so both agree exactly). NaN
/// lands in bin 0.
#[inline(always)]
fn bins_of(c: Vec3A, lo: Vec3A, scale: Vec3A, nb: usize) -> [usize; 3] {
    const MAGIC: f32 = 8_388_608.0;
    let x = ((c - lo) * scale - Vec3A::splat(0.5)).clamp(Vec3A::ZERO, Vec3A::splat(nb as f32 - 1.0)) + Vec3A::splat(MAGIC);
    x.to_array().map(|v| (v.to_bits() as usize) & (BINS - 1))
}

/// [`bins_of`] on one axis (the same operations in the same order, so the same bin): the
/// partition needs only the split axis.
#[inline(always)]
fn bin_of(c: f32, lo: f32, scale: f32, nb: usize) -> usize {
    const MAGIC: f32 = 8_388_608.0;
    let x = ((c - lo) * scale - 0.5).clamp(0.0, nb as f32 - 1.0) + MAGIC;
    (x.to_bits() as usize) & (BINS - 1)
}

/// Bins per unit on each axis of a centroid box (0 on axes without a usable extent).
fn bin_scale(cb: &Bounds, nb: usize) -> Vec3A {
    let extent = cb.max - cb.min;
    Vec3A::from_array([0, 1, 2].map(|a| if extent[a] > 0.0 && extent[a].is_finite() { nb as f32 / extent[a] } else { 0.0 }))
}

/// Per-axis bin boxes and counts.
#[derive(Clone, Copy)]
struct Bins {
    bounds: [[Bounds; BINS]; 3],
    counts: [[u32; BINS]; 3],
}

impl Bins {
    const EMPTY: Self = Self { bounds: [[Bounds::EMPTY; BINS]; 3], counts: [[0; BINS]; 3] };
    fn merge(mut self, o: Self) -> Self {
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
    fn add(&mut self, p: &Prim, lo: Vec3A, scale: Vec3A, nb: usize) {
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
const BIN_TWO_WAY_MIN: usize = 64;

fn bin_prims(prims: &[Prim], lo: Vec3A, scale: Vec3A, nb: usize) -> Bins {
    let mut bins = Bins::EMPTY;
    if prims.len() < BIN_TWO_WAY_MIN {
        prims.iter().for_each(|p| bins.add(p, lo, scale, nb));
        return bins;
    }
    let mut odd = Bins::EMPTY;
    let mut pairs = prims.chunks_exact(2);
    for pair in &mut pairs {
        bins.add(&pair[0], lo, scale, nb);
        odd.add(&pair[1], lo, scale, nb);
    }
    pairs.remainder().iter().for_each(|p| bins.add(p, lo, scale, nb));
    bins.merge(odd)
}

/// Binned SAH with `nb ≤ BINS` bins over all three axes at once (one pass over the primitives,
/// in parallel chunks for large nodes): `(axis, last bin of the left side, cost)`.
fn best_split(prims: &[Prim], cb: &Bounds, bounds: &Bounds, nb: usize) -> Option<(usize, usize, f32)> {
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
fn partition(v: &mut [Prim], pred: impl Fn(&Prim) -> bool) -> (usize, PrimBounds, PrimBounds) {
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

fn bounds_of(n: &BuildNode) -> &Bounds {
    match n {
        BuildNode::Leaf { bounds, .. } | BuildNode::Inner { bounds, .. } => bounds,
    }
}

/// Collapses the binary build tree into 4-wide nodes (each node takes up to four descendants,
/// opening the largest-area inner child first), packing leaves on the way; returns the
/// reference to `n`.
fn collapse(n: &BuildNode, nodes: &mut Vec<Node4>, packer: &mut Packer) -> u32 {
    match n {
        BuildNode::Leaf { first, count, .. } => packer.leaf(*first, *count, nodes),
        BuildNode::Inner { children, .. } => {
            let mut kids: [&BuildNode; 4] = [&children.0, &children.1, &children.1, &children.1];
            let mut len = 2;
            while len < 4 {
                let open = kids[..len]
                    .iter()
                    .enumerate()
                    .filter(|(_, k)| matches!(k, BuildNode::Inner { .. }))
                    .max_by(|a, b| bounds_of(a.1).half_area().total_cmp(&bounds_of(b.1).half_area()))
                    .map(|(i, _)| i);
                let Some(i) = open else { break };
                if let BuildNode::Inner { children, .. } = kids[i] {
                    kids.copy_within(i + 1..len, i + 2);
                    kids[i] = &children.0;
                    kids[i + 1] = &children.1;
                    len += 1;
                }
            }
            let idx = nodes.len();
            nodes.push(Node4::EMPTY);
            let mut node = Node4::EMPTY;
            for (k, kid) in kids[..len].iter().enumerate() {
                let r = collapse(kid, nodes, packer);
                node.set(k, bounds_of(kid), r);
            }
            nodes[idx] = node;
            idx as u32
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec2;
    use hybrid_scene::{Material, Mesh, Object, ObjectSource, Scene, Transform};
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    fn soup_scene(n: usize, seed: u64, materials: Vec<Material>) -> Scene {
        let mut rng = StdRng::seed_from_u64(seed);
        let mut rv = |s: f32| Vec3::new(rng.random_range(-s..s), rng.random_range(-s..s), rng.random_range(-s..s));
        let mut meshes = Vec::new();
        for m in 0..materials.len() {
            let mut mesh = Mesh { material: m, ..Default::default() };
            for _ in 0..n / materials.len() {
                let c = rv(5.0);
                let base = mesh.positions.len() as u32;
                mesh.positions.extend([c + rv(0.6), c + rv(0.6), c + rv(0.6)]);
                mesh.uvs.extend([Vec2::ZERO, Vec2::X, Vec2::Y]);
                mesh.indices.push([base, base + 1, base + 2]);
            }
            meshes.push(mesh);
        }
        let object =
            Object { name: "soup".into(), source: ObjectSource::Plane, transform: Transform::default(), meshes, relevance: 1.0, cost: 1.0 };
        Scene {
            source: None,
            camera: Default::default(),
            environment: Default::default(),
            heuristic: Default::default(),
            trace: Default::default(),
            materials,
            textures: Vec::new(),
            objects: vec![object],
            lights: Default::default(),
            point_clouds: Vec::new(),
            camera_path: None,
        }
    }

    /// Brute force Möller–Trumbore in f64 over every triangle: all hits `(t, index)` on the segment.
    fn brute_hits(p: &PreparedScene, o: Vec3, d: Vec3, t_min: f32, t_max: f32) -> Vec<(f64, usize)> {
        let (o, d) = (o.as_dvec3(), d.as_dvec3());
        let mut hits = Vec::new();
        for (i, t) in p.triangles.iter().enumerate() {
            let [a, b, c] = p.triangle(*t).map(|v| v.as_dvec3());
            let (e1, e2) = (b - a, c - a);
            let q = d.cross(e2);
            let det = e1.dot(q);
            if det == 0.0 {
                continue;
            }
            let s = o - a;
            let u = s.dot(q) / det;
            let r = s.cross(e1);
            let v = d.dot(r) / det;
            let tt = e2.dot(r) / det;
            if u >= 0.0 && v >= 0.0 && u + v <= 1.0 && tt > t_min as f64 && tt < t_max as f64 {
                hits.push((tt, i));
            }
        }
        hits
    }

    fn random_ray(rng: &mut StdRng) -> (Vec3, Vec3) {
        let o = Vec3::new(rng.random_range(-8.0..8.0), rng.random_range(-8.0..8.0), rng.random_range(-8.0..8.0));
        let target = Vec3::new(rng.random_range(-4.0..4.0), rng.random_range(-4.0..4.0), rng.random_range(-4.0..4.0));
        (o, (target - o).normalize())
    }

    #[test]
    fn closest_hit_equals_brute_force() {
        let scene = soup_scene(3000, 7, vec![Material::default()]);
        let p = PreparedScene::new(&scene);
        let bvh = SceneBvh::build(&p);
        assert_eq!(bvh.triangle_count(), 3000);
        let mut rng = StdRng::seed_from_u64(99);
        let mut hits = 0;
        for k in 0..4000 {
            let (o, d) = random_ray(&mut rng);
            let t_max = if k % 3 == 0 { rng.random_range(1.0..15.0) } else { f32::INFINITY };
            let brute = brute_hits(&p, o, d, 0.0, t_max);
            let nearest = brute.iter().copied().min_by(|a, b| a.0.total_cmp(&b.0));
            let got = bvh.closest_hit(o, d, 0.0, t_max);
            match (nearest, got) {
                (None, None) => {}
                (Some((t, i)), Some(h)) => {
                    hits += 1;
                    assert!((h.t as f64 - t).abs() < 1e-4 * t.max(1.0), "ray {k}: t {} vs {t}", h.t);
                    // Same triangle unless another one is hit at (nearly) the same distance.
                    let ties = brute.iter().filter(|b| (b.0 - t).abs() < 1e-4).count();
                    if ties == 1 {
                        assert_eq!(h.triangle, p.triangles[i], "ray {k}");
                    }
                    // The barycentrics reproduce the hit point.
                    let [a, b, c] = p.triangle(h.triangle);
                    let q = a * h.bary.x + b * h.bary.y + c * h.bary.z;
                    assert!(q.distance(o + d * h.t) < 1e-3, "ray {k}");
                }
                (n, g) => panic!("ray {k}: brute {n:?} vs bvh {g:?}"),
            }
        }
        assert!(hits > 1000, "too few hits to test anything: {hits}");
    }

    #[test]
    fn any_hit_counts_every_blocker_once() {
        // Half the triangles opacity 0.5 (each passes half), half non-shadow-casting.
        let mats = vec![Material { opacity: 0.5, ..Default::default() }, Material { casts_shadows: false, ..Default::default() }];
        let scene = soup_scene(2000, 3, mats);
        let p = PreparedScene::new(&scene);
        let bvh = SceneBvh::build(&p);
        let mut rng = StdRng::seed_from_u64(5);
        let mut multi = 0;
        for k in 0..2000 {
            let (o, d) = random_ray(&mut rng);
            let t_max = rng.random_range(2.0..20.0);
            let blockers = brute_hits(&p, o, d, 0.0, t_max).iter().filter(|(_, i)| p.material(p.triangles[*i]).casts_shadows).count();
            multi += (blockers > 1) as u32;
            let att = bvh.any_hit_attenuation(&p, o, d, t_max);
            assert!((att - 0.5f32.powi(blockers as i32)).abs() < 1e-6, "ray {k}: {att} with {blockers} blockers");
            assert_eq!(bvh.occluded(o, d, 0.0, t_max), blockers > 0);
        }
        assert!(multi > 50, "too few rays through several blockers: {multi}");
    }

    #[test]
    fn shadow_cache_never_changes_the_attenuation() {
        // Opaque, half-transparent and textured-opacity-free non-casting triangles mixed.
        let mats = vec![
            Material::default(),
            Material { opacity: 0.5, ..Default::default() },
            Material { casts_shadows: false, ..Default::default() },
        ];
        let scene = soup_scene(3000, 7, mats);
        let p = PreparedScene::new(&scene);
        let bvh = SceneBvh::build(&p);
        let other_scene = soup_scene(50, 8, vec![Material::default()]);
        let other_p = PreparedScene::new(&other_scene);
        let other = SceneBvh::build(&other_p);
        let mut rng = StdRng::seed_from_u64(9);
        let mut cache = ShadowCache::default();
        let (mut blocked, mut from_cache) = (0, 0);
        for k in 0..3000 {
            // Bundles of nearby rays towards one point (as a light's shadow rays), then a jump.
            let (o, d) = random_ray(&mut rng);
            let t_max = rng.random_range(2.0..20.0);
            for j in 0..4 {
                let o = o + Vec3::splat(j as f32 * 1e-3);
                let plain = bvh.any_hit_attenuation(&p, o, d, t_max);
                let had = cache;
                let cached = bvh.any_hit_attenuation_cached(&p, o, d, t_max, &mut cache);
                assert_eq!(plain.to_bits(), cached.to_bits(), "ray {k}.{j}");
                blocked += (plain == 0.0) as u32;
                from_cache += (plain == 0.0 && had == cache && had != ShadowCache::default()) as u32;
            }
            if k % 100 == 0 {
                // A cache left by another tree is harmless.
                other.any_hit_attenuation_cached(&other_p, Vec3::splat(-9.0), Vec3::ONE.normalize(), 1e9, &mut cache);
            }
        }
        assert!(blocked > 1000 && from_cache > 300, "too few blocked rays to test the cache: {blocked}, {from_cache} from the cache");
    }

    #[test]
    fn build_is_deterministic_and_empty_scene_has_no_hits() {
        let scene = soup_scene(20_000, 11, vec![Material::default()]);
        let p = PreparedScene::new(&scene);
        let a = SceneBvh::build(&p);
        let b = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("pool").install(|| SceneBvh::build(&p));
        assert_eq!(a.slot_ref, b.slot_ref);
        assert_eq!(a.nodes.len(), b.nodes.len());
        assert_eq!(a.leaf_count(), b.leaf_count());
        let bits = |n: &Node4| (n.planes.map(|v| v.to_array().map(f32::to_bits)), n.child);
        assert!(a.nodes.iter().zip(&b.nodes).all(|(x, y)| bits(x) == bits(y)));
        // Every triangle is in exactly one leaf slot, every pack in exactly one leaf.
        let (seen, packs) = coverage(&a, &p.triangles);
        assert!(seen.iter().all(|&s| s == 1));
        assert!(packs.iter().all(|&s| s == 1));
        assert_eq!(a.triangle_count(), 20_000);

        let empty = soup_scene(0, 1, vec![Material::default()]);
        let p = PreparedScene::new(&empty);
        let bvh = SceneBvh::build(&p);
        assert!(bvh.closest_hit(Vec3::ZERO, Vec3::X, 0.0, f32::INFINITY).is_none());
        assert_eq!(bvh.any_hit_attenuation(&p, Vec3::ZERO, Vec3::X, f32::INFINITY), 1.0);
    }

    /// How often each triangle (by index in `p.triangles`) and each pack is reached from the
    /// root, walking every node.
    fn coverage(bvh: &SceneBvh, triangles: &[TriangleRef]) -> (Vec<u32>, Vec<u32>) {
        let index: std::collections::HashMap<(u32, u32), usize> =
            triangles.iter().enumerate().map(|(i, t)| ((t.mesh, t.triangle), i)).collect();
        let mut seen = vec![0u32; triangles.len()];
        let mut packs = vec![0u32; bvh.packs.len()];
        let mut todo = vec![0u32];
        while let Some(c) = todo.pop() {
            if c == EMPTY_SLOT {
                continue;
            }
            if c & LEAF == 0 {
                todo.extend(bvh.nodes[c as usize].child);
                continue;
            }
            for pi in leaf_packs(c) {
                packs[pi] += 1;
                for slot in pi * 4..pi * 4 + 4 {
                    let t = bvh.slot_ref[slot];
                    if t != NO_TRI {
                        seen[index[&(t.mesh, t.triangle)]] += 1;
                    }
                }
            }
        }
        (seen, packs)
    }

    #[test]
    fn oversized_leaves_split_under_extra_nodes() {
        let scene = soup_scene(150, 4, vec![Material::default()]);
        let p = PreparedScene::new(&scene);
        let corners: Vec<[Vec3; 3]> = p.triangles.iter().map(|t| p.triangle(*t)).collect();
        let order: Vec<u32> = (0..150).collect();
        let mut packer = Packer { corners: &corners, order: &order, packs: Vec::new(), leaves: 0 };
        let mut nodes = Vec::new();
        // 150 triangles = 38 packs: one extra node over four leaves of ≤ 16 packs.
        let r = packer.leaf(0, 150, &mut nodes);
        assert_eq!(r, 0);
        assert_eq!(nodes.len(), 1);
        assert_eq!(packer.leaves, 4);
        let mut seen = vec![0; 150];
        for (k, &c) in nodes[0].child.iter().enumerate() {
            assert!(c & LEAF != 0);
            let packs = leaf_packs(c);
            assert!(packs.len() <= MAX_LEAF_PACKS);
            for &(first, n) in &packer.packs[packs] {
                assert!((1..=4).contains(&n));
                for pos in first..first + n {
                    let t = order[pos as usize];
                    seen[t as usize] += 1;
                    // The child box holds the triangle.
                    for v in corners[t as usize] {
                        for axis in 0..3 {
                            assert!(nodes[0].lo(axis)[k] <= v[axis] && v[axis] <= nodes[0].hi(axis)[k]);
                        }
                    }
                }
            }
        }
        assert!(seen.iter().all(|&s| s == 1));
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
}
