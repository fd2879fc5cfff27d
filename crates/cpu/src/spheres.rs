//! A BVH over millions of equal-radius spheres (the RT-scene's point cloud, design §5).
//!
//! - **Build**: binned SAH (16 bins along the widest axis) over the sphere centres. With one
//!   radius, a node's box is its centres' box grown by `r`, so the bins track centre bounds only.
//!   The top of the tree is built in parallel with `rayon::join`; every subtree is laid out in
//!   depth-first order and stitched by its parent, so the result does not depend on the thread
//!   count or timing (deterministic).
//! - **Layout** (memory): the binary tree is collapsed into 4-wide nodes (each opens the child
//!   of largest area until it has four), holding their children's boxes as structure of arrays
//!   (112 B per node, about one node per 6 spheres). Centres are stored in leaf order as three
//!   per-axis arrays (12 B/sphere) with their original index (4 B/sphere). [`SphereBvh::bytes`]
//!   reports the total (about 34 B per sphere).
//! - **Trace**: ordered depth-first traversal: the four children's slab tests in one SIMD pass,
//!   the nearest entered child next, the others on a stack with their entry distances (skipped
//!   when a closer hit has been found). A leaf's ≤ 4 spheres are tested at once with the exact
//!   ray–sphere test in the perpendicular-distance form (KNOWN-GOOD gotcha 13), lane by lane the
//!   same operations in the same order as the scalar [`ray_sphere`], so bit for bit its results:
//!   project the centre on the ray and compare the squared distance of the centre from the ray
//!   with r². Ties in t go to the lower index, so
//!   the result equals brute force whatever the traversal order. Rays with `t_min ≥ 0` use a
//!   cheaper slab test that enters every child the padded one enters (`Ray::slab4`).
//! - **Batches** ([`SphereBvh::closest_hits_batch`], a screen tile's primary rays): rays from one
//!   origin share the top of the tree. The batch's frustum, bounded by its rays' extreme inverse
//!   directions, is tested against the nodes once, giving a cut of ≤ 32 subtrees that holds
//!   everything any of its rays may enter (under two levels of 4-wide nodes of its own); each ray
//!   starts from the cut (its entered subtrees, about nearest first) instead of the root. On the
//!   1M-point tree scan at 1080p (8×8 tiles) the rays' slab tests per frame fall from 14.1M to
//!   4.3M (1.6M tree nodes, 2.6M of the cuts' own nodes), plus 0.34M to build the 18,490 cuts.

use glam::{Vec3, Vec4};

/// Spheres per leaf at most.
const LEAF_MAX: usize = 4;
/// SAH bins per axis.
const BINS: usize = 16;
/// Subtrees with more spheres than this are built with `rayon::join`.
const PARALLEL_MIN: usize = 16 * 1024;
/// Leaf reference flag; a leaf reference holds `start << 4 | count`.
const LEAF: u32 = 1 << 31;
/// Traversal stack capacity reserved up front (it grows past it if needed: up to 3 pushes per level).
const STACK: usize = 96;

/// A reusable traversal stack (subtree reference, entry distance).
#[derive(Debug, Clone)]
pub struct TraversalStack(Vec<(u32, f32)>);

impl Default for TraversalStack {
    fn default() -> Self {
        Self(Vec::with_capacity(STACK))
    }
}
/// Relative slack of the slab test for rays with `t_min ≥ 0` (see [`Ray::slab4`]).
const NONNEG_SLACK: f32 = 1.0 + 3e-5;
/// Most subtrees in a batch's cut ([`SphereBvh::closest_hits_batch`]).
const CUT_MAX: usize = 32;

/// One ray of a batch ([`SphereBvh::closest_hits_batch`]); the arguments of
/// [`SphereBvh::closest_hit_slot_with`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BatchRay {
    pub origin: Vec3,
    pub dir: Vec3,
    pub t_min: f32,
    pub t_max: f32,
}

/// One subtree of a batch's cut: its reference, box and box area, and whether it is an inner node.
#[derive(Debug, Clone, Copy)]
struct CutEntry {
    child: u32,
    lo: Vec3,
    hi: Vec3,
    /// Replaced by its children.
    dead: bool,
    /// The batch's entry distance (≤ each ray's).
    near: f32,
}

/// Reusable storage of [`SphereBvh::closest_hits_batch`] (one per thread).
#[derive(Debug, Clone, Default)]
pub struct BatchScratch {
    rays: Vec<Option<(Ray, f32)>>,
    cut: Vec<CutEntry>,
    open: std::collections::BinaryHeap<(u32, u32)>,
    chunks: Vec<Node4>,
    tops: Vec<Node4>,
}

/// Largest number of spheres (leaf starts have 27 bits).
pub const MAX_SPHERES: usize = 1 << 27;

/// One inner node: the boxes of its two children, one 4-lane vector per axis
/// `(min left, min right, max left, max right)` so both slab tests run as a few SIMD operations,
/// and the children's references (an inner-node index, or `LEAF | start << 4 | count`).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Node {
    x: Vec4,
    y: Vec4,
    z: Vec4,
    child: [u32; 2],
}

/// One 4-wide node: its ≤ 4 children's boxes, one 4-lane vector per bound (structure of arrays, so
/// the four slab tests are a few SIMD operations), and their references (an inner-node index, or
/// `LEAF | start << 4 | count`). Unused slots have an empty box (+∞ … −∞), which no ray enters.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Node4 {
    min: [Vec4; 3],
    max: [Vec4; 3],
    child: [u32; 4],
}

impl Node4 {
    const EMPTY: Self = Self { min: [Vec4::INFINITY; 3], max: [Vec4::NEG_INFINITY; 3], child: [LEAF; 4] };
}

/// A sphere BVH. Directions passed to [`SphereBvh::closest_hit`] need not be unit length.
#[derive(Debug, Clone)]
pub struct SphereBvh {
    radius: f32,
    /// Sphere centres in leaf order, one array per axis (structure of arrays, so a leaf's ≤ 4
    /// spheres are tested as one 4-lane vector), each padded by `LEAF_MAX - 1` zeros.
    xs: Vec<f32>,
    ys: Vec<f32>,
    zs: Vec<f32>,
    /// Original index (into the `centers` given to `build`) of each leaf-order sphere.
    indices: Vec<u32>,
    nodes: Vec<Node4>,
    /// The root reference (inner node 0, or a leaf when there are ≤ `LEAF_MAX` spheres).
    root: u32,
    root_min: Vec3,
    root_max: Vec3,
}

/// Why a BVH could not be built.
#[derive(Debug, Clone, PartialEq)]
pub enum SphereBvhError {
    TooManySpheres(usize),
    BadRadius(f32),
    NonFiniteCenter(usize),
}

impl std::fmt::Display for SphereBvhError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::TooManySpheres(n) => write!(f, "{n} spheres: at most {MAX_SPHERES} fit in one sphere BVH"),
            Self::BadRadius(r) => write!(f, "sphere radius {r} must be finite and > 0"),
            Self::NonFiniteCenter(i) => write!(f, "sphere {i} has a non-finite centre"),
        }
    }
}

impl std::error::Error for SphereBvhError {}

/// Build-time item: a centre and its original index (16 bytes).
#[derive(Debug, Clone, Copy)]
struct Item {
    c: [f32; 3],
    index: u32,
}

#[derive(Debug, Clone, Copy)]
struct Bounds {
    min: Vec3,
    max: Vec3,
}

impl Bounds {
    const EMPTY: Self = Self { min: Vec3::splat(f32::INFINITY), max: Vec3::splat(f32::NEG_INFINITY) };
    #[inline]
    fn grow(&mut self, p: Vec3) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }
    #[inline]
    fn union(self, o: Self) -> Self {
        Self { min: self.min.min(o.min), max: self.max.max(o.max) }
    }
    /// Half the surface area of the box grown by `r` (0 for an empty box).
    #[inline]
    fn half_area(self, r: f32) -> f32 {
        if self.min.x > self.max.x {
            return 0.0;
        }
        let e = self.max - self.min + Vec3::splat(2.0 * r);
        e.x * e.y + e.y * e.z + e.z * e.x
    }
    fn of(items: &[Item]) -> Self {
        let mut b = Self::EMPTY;
        for it in items {
            b.grow(Vec3::from(it.c));
        }
        b
    }
}

/// A subtree: its inner nodes in depth-first order (local indices, root first when inner) and its
/// root reference (local).
struct Subtree {
    nodes: Vec<Node>,
    root: u32,
}

/// A collapsed subtree: its 4-wide nodes in depth-first order and its root reference (local).
struct Subtree4 {
    nodes: Vec<Node4>,
    root: u32,
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
        let Subtree4 { nodes, root } = collapse_par(&tree.nodes, tree.root, 0);
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

    pub fn len(&self) -> usize {
        self.indices.len()
    }
    pub fn is_empty(&self) -> bool {
        self.indices.is_empty()
    }
    pub fn radius(&self) -> f32 {
        self.radius
    }
    /// Inner nodes (4-wide).
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }
    /// Heap bytes held: centres, original indices and nodes.
    pub fn bytes(&self) -> usize {
        (self.xs.len() + self.ys.len() + self.zs.len()) * size_of::<f32>()
            + self.indices.len() * size_of::<u32>()
            + self.nodes.len() * size_of::<Node4>()
    }
    /// The centre of the sphere in leaf-order slot `slot`.
    pub fn center_of_slot(&self, slot: u32) -> Vec3 {
        let i = slot as usize;
        Vec3::new(self.xs[i], self.ys[i], self.zs[i])
    }

    /// Bounds of all spheres (zero box when empty).
    pub fn bounds(&self) -> (Vec3, Vec3) {
        (self.root_min, self.root_max)
    }

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
    fn query<const ANY: bool>(&self, stack: &mut TraversalStack, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Option<(f32, u32)> {
        let (ray, len) = self.prepare(origin, dir, t_min, t_max)?;
        // Entry distances are never negative when `t_min` is not: the cheaper slab form applies.
        let stack = &mut stack.0;
        stack.clear();
        if ray.t_min >= 0.0 {
            self.traverse::<true, ANY>(stack, &ray, len, self.root)
        } else {
            self.traverse::<false, ANY>(stack, &ray, len, self.root)
        }
    }

    /// The ray of [`SphereBvh::closest_hit_slot_with`], prepared: `(ray, |dir|)`, or `None` when
    /// it cannot hit anything (empty tree, unusable direction or range, or it misses the root box).
    #[inline]
    fn prepare(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Option<(Ray, f32)> {
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
            stack.clear();
            if ray.t_min < 0.0 {
                *hit = self.traverse::<false, false>(stack, ray, *len, self.root);
                continue;
            }
            if !cut {
                *hit = self.traverse::<true, false>(stack, ray, *len, self.root);
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
            stack.extend(order[1..k].iter().rev());
            *hit = self.traverse::<true, false>(stack, ray, *len, order[0].0);
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
    fn batch_cut(&self, scratch: &mut BatchScratch) -> bool {
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
                    (n.min[a], n.max[a])
                } else if hi[a] < 0.0 {
                    (n.max[a], n.min[a])
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
                    if n.child[lane] == LEAF {
                        continue;
                    }
                    let lo = Vec3::new(n.min[0][lane], n.min[1][lane], n.min[2][lane]);
                    let hi = Vec3::new(n.max[0][lane], n.max[1][lane], n.max[2][lane]);
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
                node.child[lane] = c.child;
                for a in 0..3 {
                    node.min[a][lane] = c.lo[a];
                    node.max[a][lane] = c.hi[a];
                }
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
                    top.min[a][lane] = c.min[a].min_element();
                    top.max[a][lane] = c.max[a].max_element();
                }
            }
            scratch.tops.push(top);
        }
        true
    }

    /// Ordered depth-first traversal from the subtree `root`, then the subtrees on `stack`
    /// (see the module notes). `NONNEG`: the ray's `t_min` is ≥ 0 (see [`Ray::slab4`]). `ANY`:
    /// return the first hit found instead of the closest (for occlusion queries).
    #[inline]
    fn traverse<const NONNEG: bool, const ANY: bool>(
        &self,
        stack: &mut Vec<(u32, f32)>,
        ray: &Ray,
        len: f32,
        root: u32,
    ) -> Option<(f32, u32)> {
        let mut best_t = ray.t_max;
        let mut best = u32::MAX;
        let mut best_slot = 0u32;
        let mut cur = root;
        loop {
            if cur & LEAF != 0 {
                let start = ((cur & !LEAF) >> 4) as usize;
                let count = cur & 0xF;
                let hits = ray.spheres4(&self.xs[start..], &self.ys[start..], &self.zs[start..], best_t, count);
                if let Some((t4, mut mask)) = hits {
                    let t4 = t4.to_array();
                    if ANY {
                        let lane = mask.trailing_zeros() as usize;
                        return Some((t4[lane] / len, (start + lane) as u32));
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
                }
            } else {
                let n = &self.nodes[cur as usize];
                let (entry, mut mask) = ray.slab4::<NONNEG>(n, best_t);
                if mask != 0 {
                    let first = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    if mask == 0 {
                        cur = n.child[first];
                        continue;
                    }
                    // Several children: visit the nearest now, push the others farthest first.
                    let entry = entry.to_array();
                    let mut order = [(0u32, 0f32); 4];
                    order[0] = (n.child[first], entry[first]);
                    let mut k = 1;
                    while mask != 0 {
                        let lane = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        let item = (n.child[lane], entry[lane]);
                        // Insertion sort by entry distance, nearest first.
                        let mut j = k;
                        while j > 0 && order[j - 1].1 > item.1 {
                            order[j] = order[j - 1];
                            j -= 1;
                        }
                        order[j] = item;
                        k += 1;
                    }
                    for &o in order[1..k].iter().rev() {
                        stack.push(o);
                    }
                    cur = order[0].0;
                    continue;
                }
            }
            // Pop the next subtree that can still hold a closer hit.
            loop {
                let Some((r, e)) = stack.pop() else {
                    return if best == u32::MAX { None } else { Some((best_t / len, best_slot)) };
                };
                if Ray::may_enter::<NONNEG>(e, best_t) {
                    cur = r;
                    break;
                }
            }
        }
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
struct Ray {
    o: Vec3,
    d: Vec3,
    inv: Vec3,
    t_min: f32,
    t_max: f32,
    r: f32,
}

impl Ray {
    #[inline]
    fn new(o: Vec3, d: Vec3, t_min: f32, t_max: f32, r: f32) -> Self {
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
    fn slab4<const NONNEG: bool>(&self, n: &Node4, limit: f32) -> (Vec4, u32) {
        // For a negative direction the max plane is entered first.
        let axis = |a: usize| {
            let o = Vec4::splat(self.o[a]);
            let inv = Vec4::splat(self.inv[a]);
            let t0 = (n.min[a] - o) * inv;
            let t1 = (n.max[a] - o) * inv;
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
    fn may_enter<const NONNEG: bool>(e: f32, best_t: f32) -> bool {
        if NONNEG { e <= best_t * NONNEG_SLACK } else { e <= best_t }
    }

    /// Entry and exit parameters of the box (entry > exit: miss), clipped to `[t_min, t_max]`.
    /// Boxes are padded by a relative epsilon so tangent sphere hits are never culled.
    #[inline]
    fn slab(&self, min: Vec3, max: Vec3) -> (f32, f32) {
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
    fn spheres4(&self, xs: &[f32], ys: &[f32], zs: &[f32], t_max: f32, count: u32) -> Option<(Vec4, u32)> {
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

/// Centre bounds of many items, in parallel.
fn par_bounds(items: &[Item]) -> Bounds {
    use rayon::prelude::*;
    if items.len() < PARALLEL_MIN {
        return Bounds::of(items);
    }
    items.par_chunks(PARALLEL_MIN).map(Bounds::of).reduce(|| Bounds::EMPTY, Bounds::union)
}

#[derive(Debug, Clone, Copy)]
struct Bin {
    count: u32,
    b: Bounds,
}

const EMPTY_BIN: Bin = Bin { count: 0, b: Bounds::EMPTY };

/// Bins of one range along all three axes.
/// Bins of one range along `axis` (the others stay empty).
fn bin_items(items: &[Item], cmin: Vec3, scale: Vec3, axis: usize) -> [[Bin; BINS]; 3] {
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

fn merge_bins(mut a: [[Bin; BINS]; 3], b: [[Bin; BINS]; 3]) -> [[Bin; BINS]; 3] {
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
fn build_node(items: &mut [Item], base: usize, cb: Bounds, r: f32, depth: u32) -> Subtree {
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
fn build_serial(items: &mut [Item], base: usize, cb: Bounds, r: f32, depth: u32, nodes: &mut Vec<Node>) -> u32 {
    let n = items.len();
    if n <= LEAF_MAX {
        return LEAF | ((base as u32) << 4) | n as u32;
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

fn make_node(lb: Bounds, rb: Bounds, r: f32, left: u32, right: u32) -> Node {
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
fn split_items(items: &mut [Item], cb: Bounds, r: f32, depth: u32) -> (usize, Bounds, Bounds) {
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

fn append_offset(dst: &mut Vec<Node>, src: Vec<Node>, off: u32) {
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

/// The BVH2 subtree `root` (an index into `nodes2` or a leaf) as 4-wide nodes appended to `out`
/// depth-first: each 4-wide node takes its BVH2 node's two children and opens the inner child of
/// largest surface area until it has four (or only leaves are left). Returns its reference.
fn collapse(nodes2: &[Node], root: u32, out: &mut Vec<Node4>) -> u32 {
    if root & LEAF != 0 {
        return root;
    }
    let (kids, k) = open_kids(nodes2, root);
    let idx = out.len();
    out.push(Node4::EMPTY);
    let mut node = Node4::EMPTY;
    for (lane, &(r, lo, hi)) in kids[..k].iter().enumerate() {
        node.child[lane] = collapse(nodes2, r, out);
        for a in 0..3 {
            node.min[a][lane] = lo[a];
            node.max[a][lane] = hi[a];
        }
    }
    out[idx] = node;
    idx as u32
}

/// [`collapse`] with the top `COLLAPSE_PARALLEL_DEPTH` levels of 4-wide nodes in parallel: each
/// child subtree collapsed on its own and stitched depth-first after its parent (the same nodes
/// in the same order as the serial collapse).
fn collapse_par(nodes2: &[Node], root: u32, depth: u32) -> Subtree4 {
    const COLLAPSE_PARALLEL_DEPTH: u32 = 2;
    if root & LEAF != 0 {
        return Subtree4 { nodes: Vec::new(), root };
    }
    if depth >= COLLAPSE_PARALLEL_DEPTH {
        let mut nodes = Vec::new();
        let root = collapse(nodes2, root, &mut nodes);
        return Subtree4 { nodes, root };
    }
    let (kids, k) = open_kids(nodes2, root);
    use rayon::prelude::*;
    let subs: Vec<Subtree4> = kids[..k].par_iter().map(|&(r, _, _)| collapse_par(nodes2, r, depth + 1)).collect();
    let mut node = Node4::EMPTY;
    let mut nodes = Vec::with_capacity(1 + subs.iter().map(|s| s.nodes.len()).sum::<usize>());
    nodes.push(node);
    for (lane, (sub, &(_, lo, hi))) in subs.into_iter().zip(&kids[..k]).enumerate() {
        let off = nodes.len() as u32;
        node.child[lane] = if sub.root & LEAF != 0 { sub.root } else { sub.root + off };
        for a in 0..3 {
            node.min[a][lane] = lo[a];
            node.max[a][lane] = hi[a];
        }
        nodes.extend(sub.nodes.into_iter().map(|mut n| {
            for c in &mut n.child {
                if *c & LEAF == 0 {
                    *c += off;
                }
            }
            n
        }));
    }
    nodes[0] = node;
    Subtree4 { nodes, root: 0 }
}

/// The ≤ 4 children of the 4-wide node made from BVH2 node `root`: its two children, then the inner
/// child of largest surface area opened until there are four (or only leaves are left).
fn open_kids(nodes2: &[Node], root: u32) -> ([(u32, Vec3, Vec3); 4], usize) {
    let kids_of = |r: u32| {
        let n = &nodes2[r as usize];
        let lo = |l: usize| Vec3::new(n.x[l], n.y[l], n.z[l]);
        [(n.child[0], lo(0), lo(2)), (n.child[1], lo(1), lo(3))]
    };
    let mut kids = [(LEAF, Vec3::ZERO, Vec3::ZERO); 4];
    kids[..2].copy_from_slice(&kids_of(root));
    let mut k = 2;
    while k < 4 {
        let area = |(_, lo, hi): (u32, Vec3, Vec3)| {
            let e = hi - lo;
            e.x * e.y + e.y * e.z + e.z * e.x
        };
        let open = (0..k).filter(|&i| kids[i].0 & LEAF == 0).max_by(|&a, &b| area(kids[a]).total_cmp(&area(kids[b])));
        let Some(i) = open else { break };
        let [a, b] = kids_of(kids[i].0);
        kids[i] = a;
        kids[k] = b;
        k += 1;
    }
    (kids, k)
}

/// In-place partition: items for which `left` holds first; returns their count.
fn partition(items: &mut [Item], left: impl Fn(&Item) -> bool) -> usize {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn perpendicular_form_hits_and_misses() {
        let o = Vec3::ZERO;
        let d = Vec3::Z;
        assert_eq!(ray_sphere(o, d, Vec3::new(0.0, 0.0, 5.0), 1.0, 0.0, 100.0), Some(4.0));
        assert_eq!(ray_sphere(o, d, Vec3::new(0.0, 1.5, 5.0), 1.0, 0.0, 100.0), None);
        // From inside: the far side.
        assert_eq!(ray_sphere(o, d, Vec3::ZERO, 1.0, 0.0, 100.0), Some(1.0));
        // Behind.
        assert_eq!(ray_sphere(o, d, Vec3::new(0.0, 0.0, -5.0), 1.0, 0.0, 100.0), None);
        // Beyond t_max.
        assert_eq!(ray_sphere(o, d, Vec3::new(0.0, 0.0, 5.0), 1.0, 0.0, 3.9), None);
        // A 1 mm sphere 10 km away is still found.
        let t = ray_sphere(o, d, Vec3::new(0.0005, 0.0, 10_000.0), 0.001, 0.0, f32::INFINITY).unwrap();
        assert!((t - 10_000.0).abs() < 0.01);
    }

    #[test]
    fn small_trees_and_duplicates() {
        assert!(SphereBvh::build(&[], 1.0).unwrap().closest_hit(Vec3::ZERO, Vec3::Z, 0.0, 10.0).is_none());
        let one = SphereBvh::build(&[Vec3::new(0.0, 0.0, 3.0)], 0.5).unwrap();
        assert_eq!(one.closest_hit(Vec3::ZERO, Vec3::Z, 0.0, 10.0), Some((2.5, 0)));
        // 100 identical centres: the lowest index wins the tie.
        let same = vec![Vec3::new(0.0, 0.0, 3.0); 100];
        let bvh = SphereBvh::build(&same, 0.5).unwrap();
        assert_eq!(bvh.closest_hit(Vec3::ZERO, Vec3::Z * 2.0, 0.0, 10.0), Some((1.25, 0)));
        assert!(matches!(SphereBvh::build(&same, 0.0), Err(SphereBvhError::BadRadius(_))));
        assert!(matches!(SphereBvh::build(&[Vec3::NAN], 1.0), Err(SphereBvhError::NonFiniteCenter(0))));
    }

    /// Batches (one origin, narrow to wide cones, directions with zero components, negative
    /// `t_min`, varied `t_max`, a stray origin) give exactly the single-ray results and brute
    /// force's, ties (duplicated centres) included.
    #[test]
    fn batch_equals_single_rays_and_brute_force() {
        use rand::rngs::StdRng;
        use rand::{Rng, SeedableRng};
        let mut rng = StdRng::seed_from_u64(7);
        // A blob, a thin shell and a far cluster; the first 400 centres come in equal pairs.
        let mut centers: Vec<Vec3> = (0..4000)
            .map(|i| match i % 3 {
                0 => Vec3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)),
                1 => {
                    Vec3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)).normalize_or(Vec3::X)
                        * 3.0
                }
                _ => Vec3::new(rng.random_range(-0.5..0.5), rng.random_range(-0.5..0.5), 40.0 + rng.random_range(-0.5..0.5)),
            })
            .collect();
        for i in 0..200 {
            centers[2 * i + 1] = centers[2 * i];
        }
        let radius = 0.04;
        let bvh = SphereBvh::build(&centers, radius).unwrap();
        let mut scratch = BatchScratch::default();
        let mut stack = TraversalStack::default();
        let (mut hits, mut ties, mut cuts) = (0, 0, 0);
        for b in 0..90 {
            let origin = Vec3::new(rng.random_range(-6.0..6.0), rng.random_range(-6.0..6.0), rng.random_range(-8.0..-4.0));
            let origin = if b % 9 == 4 { Vec3::new(0.1, 0.2, 0.3) } else { origin };
            let aim = (centers[rng.random_range(0..400)] - origin).normalize();
            let spread = [0.003, 0.03, 0.3, 2.0][b % 4];
            let rays: Vec<BatchRay> = (0..64)
                .map(|j| {
                    let mut dir =
                        aim + Vec3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)) * spread;
                    if j % 11 == 3 {
                        dir.x = 0.0;
                    }
                    if j % 13 == 5 {
                        dir = Vec3::new(0.0, -0.0, 1.0);
                    }
                    let dir = dir * rng.random_range(0.5..2.0);
                    let (t_min, t_max) = match j % 5 {
                        0 => (0.0, f32::INFINITY),
                        1 => (rng.random_range(0.0..3.0), rng.random_range(3.0..12.0)),
                        2 if b % 3 == 0 => (-2.0, f32::INFINITY),
                        _ => (rng.random_range(0.0..0.5), rng.random_range(2.0..60.0)),
                    };
                    let origin = if b % 10 == 7 && j == 9 { origin + Vec3::new(1e-3, 0.0, 0.0) } else { origin };
                    BatchRay { origin, dir, t_min, t_max }
                })
                .collect();
            let mut got = vec![None; rays.len()];
            bvh.closest_hits_batch(&mut scratch, &mut stack, &rays, &mut got);
            cuts += (b % 10 != 7 && !scratch.chunks.is_empty()) as usize;
            for (k, (r, h)) in rays.iter().zip(&got).enumerate() {
                assert_eq!(*h, bvh.closest_hit_slot(r.origin, r.dir, r.t_min, r.t_max), "batch {b} ray {k}");
                let want = closest_hit_brute_force(&centers, radius, r.origin, r.dir, r.t_min, r.t_max);
                assert_eq!(h.map(|(t, s)| (t, bvh.index_of_slot(s))), want, "batch {b} ray {k}");
                hits += h.is_some() as usize;
                ties += want.is_some_and(|(_, i)| i < 400 && i % 2 == 0) as usize;
            }
        }
        assert!(hits > 1500 && ties > 200 && cuts > 50, "too little tested: {hits} hits, {ties} ties, {cuts} cuts");
    }

    /// The occlusion query answers exactly whether the closest-hit query finds a hit, for rays
    /// that start inside, outside and between spheres, with open and short ranges.
    #[test]
    fn any_hit_agrees_with_closest_hit() {
        use rand::rngs::StdRng;
        use rand::{Rng, SeedableRng};
        let mut rng = StdRng::seed_from_u64(11);
        let centers: Vec<Vec3> =
            (0..3000).map(|_| Vec3::new(rng.random_range(-2.0..2.0), rng.random_range(-2.0..2.0), rng.random_range(-2.0..2.0))).collect();
        let bvh = SphereBvh::build(&centers, 0.05).unwrap();
        let mut stack = TraversalStack::default();
        let (mut blocked, mut clear) = (0, 0);
        for k in 0..4000 {
            let origin = Vec3::new(rng.random_range(-3.0..3.0), rng.random_range(-3.0..3.0), rng.random_range(-3.0..3.0));
            let dir = Vec3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
            let (t_min, t_max) = match k % 3 {
                0 => (0.0, f32::INFINITY),
                1 => (0.0, rng.random_range(0.0..1.5)),
                _ => (-0.5, rng.random_range(0.0..4.0)),
            };
            let any = bvh.any_hit_with(&mut stack, origin, dir, t_min, t_max);
            assert_eq!(any, bvh.closest_hit_slot(origin, dir, t_min, t_max).is_some(), "ray {k}");
            if any { blocked += 1 } else { clear += 1 }
        }
        assert!(blocked > 500 && clear > 500, "too little tested: {blocked} blocked, {clear} clear");
    }

    #[test]
    fn partition_splits_by_predicate() {
        let mut items: Vec<Item> = (0..37).map(|i| Item { c: [i as f32, 0.0, 0.0], index: i }).collect();
        let mid = partition(&mut items, |it| it.index % 3 == 0);
        assert_eq!(mid, 13);
        assert!(items[..mid].iter().all(|it| it.index % 3 == 0));
        assert!(items[mid..].iter().all(|it| it.index % 3 != 0));
    }
}
