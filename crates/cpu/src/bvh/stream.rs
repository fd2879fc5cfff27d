//! Ray streams: many rays of any coherence traverse the BVH together, breadth-first by node
//! (after Barringer & Akenine-Möller, "Dynamic Ray Stream Traversal", 2014).
//!
//! A stream visits a node once for all of its rays that entered the node's box: each ray is
//! tested against the node's four child boxes with the single-ray kernel, and its id and entry
//! distance are written to the list of every child it enters. The children's lists are then
//! visited nearest first (by the mean entry distance of their rays). So a node is fetched once
//! per stream rather than once per ray, and the per-ray branches of a depth-first walk become
//! list writes. Where a list has thinned out (fewer than [`SINGLE_RAYS_BELOW`] rays), its rays
//! finish one at a time with the single-ray walk from that node.
//!
//! Each ray's answer is [`SceneBvh::closest_hit`]'s: the box and triangle tests are the
//! single-ray kernels, a ray's box is culled only beyond its closest hit so far (as the
//! single-ray walk culls), and the hit kept is the least `(t, slot)` pair. One case differs,
//! as it would between any two visiting orders: a ray through an edge two triangles share,
//! where rounding puts one triangle's hit a few ulps before its box's entry distance. Whichever
//! triangle a walk meets first can then cull the other, so the stream may return the
//! neighbouring triangle at a distance a few ulps off (one ray of one test scene at 320×180,
//! none of the Embree bench's 918K). The answer never depends on the thread count.
//!
//! On the AVX2 and AVX-512 paths the node tests are [`Fused`]: the same slabs with one fused
//! multiply–subtract per plane instead of a subtraction and a multiplication, as Embree tests
//! its boxes (8–15% faster closest-hit streams, 2–3% faster shadow streams, measured in one
//! process against [`Exact`]). Its distances differ in the last bits, so a ray that grazes a
//! box boundary may be culled differently there than by the single-ray walk, with the same
//! possible outcome as the shared-edge case above (none of the Embree bench's rays, one pixel
//! of pavilion's 1280×720 rt-only frame).

use super::*;
use crate::bvh_core::{Node4, STACK_LEN};
use crate::isa;
use hybrid_core::prepare::PreparedScene;

/// Rays traced as one stream; longer inputs are cut into streams of this many. Longer streams
/// share each node fetch among more rays, at the cost of larger per-thread lists (4 KiB a ray
/// reserved, only the part written touched) and coarser work items for callers that hand out
/// one stream per item. Measured best of 256, 1024, 4096 and 8192 on the Embree bench.
pub const STREAM: usize = 4096;

/// Lists of fewer rays than this leave the stream and finish one ray at a time.
const SINGLE_RAYS_BELOW: usize = 8;

/// Shadow rays that reach their light: how many of the next ones the cache does not block go
/// into the stream before one is traced alone again (to find where a shadow begins, so the
/// cache can take over). Higher values stream more of a lit region's rays, at the cost of
/// traversals, not cache tests, for the first rays of each shadow.
const PROBE_EVERY: usize = 8;

/// Most node levels a stream's lists can be open on at once: a path is at most `MAX_DEPTH`
/// (56) binary levels plus the ≤ 8 an oversized leaf adds, so at most 64 four-wide levels.
const LIST_LEVELS: usize = 64;

/// A node or leaf still to visit, with its rays: `lists[start..start + len]`. `end` is where
/// the lists of its parent's children end: everything written after it is dead once this
/// entry is taken.
#[derive(Clone, Copy)]
struct Visit {
    node: u32,
    start: u32,
    len: u32,
    end: u32,
}

/// A stream's ray, compact (64 bytes, one cache line, where a `RayPre` takes 192, so that a
/// stream's rays stay in the L1/L2 caches): origin, direction, inverse direction and the planes
/// it enters and leaves each slab by, as `RayPre::new` has them, plus origin × inverse direction
/// for [`Fused`] box tests; [`NodeRay::pre`] expands it for the leaf tests and the single-ray
/// walk.
#[derive(Clone, Copy)]
#[repr(align(64))]
struct NodeRay {
    o: [f32; 3],
    d: [f32; 3],
    inv: [f32; 3],
    /// `o · inv` per axis (rounded to f32).
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    o_inv: [f32; 3],
    near: [u8; 3],
    far: [u8; 3],
    /// Whether `inv` and `o_inv` are finite on every axis, so that [`Fused`] may test boxes for
    /// this ray (a zero direction component, or an overflow, leaves it to [`Exact`]).
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    fusable: bool,
}

impl NodeRay {
    #[inline(always)]
    fn new(o: Vec3, d: Vec3) -> Self {
        let r = RayPre::new(Vec3A::from(o), Vec3A::from(d));
        let (o, inv) = (r.o.map(|v| v.x), r.inv.map(|v| v.x));
        let o_inv = [0, 1, 2].map(|a| o[a] * inv[a]);
        NodeRay {
            o,
            d: r.d.map(|v| v.x),
            inv,
            o_inv,
            near: r.near.map(|i| i as u8),
            far: r.far.map(|i| i as u8),
            fusable: inv.iter().chain(&o_inv).all(|v| v.is_finite()),
        }
    }

    /// The ray as `RayPre::new` makes it (the same values).
    #[inline(always)]
    fn pre(&self) -> RayPre {
        RayPre {
            o: self.o.map(Vec4::splat),
            d: self.d.map(Vec4::splat),
            inv: self.inv.map(Vec4::splat),
            near: self.near.map(usize::from),
            far: self.far.map(usize::from),
        }
    }

    /// [`node_hits`] of this ray (the same bits).
    #[inline(always)]
    fn hits(&self, n: &Node4, t_min: f32, t_max: f32) -> (Vec4, u32) {
        slab_hits(
            n,
            self.o.map(Vec4::splat),
            self.inv.map(Vec4::splat),
            self.near.map(usize::from),
            self.far.map(usize::from),
            t_min,
            t_max,
        )
    }
}

/// How a stream tests its rays against a node's four child boxes: the entry distances and the
/// mask of the boxes entered within `[t_min, t_max]`.
trait BoxTest: Copy {
    fn hits(self, r: &NodeRay, n: &Node4, t_min: f32, t_max: f32) -> (Vec4, u32);
}

/// The single-ray slab test ([`node_hits`]'s bits): `(plane − o) · inv`, a subtraction and a
/// multiplication per plane. Every instruction-set path has it.
#[derive(Clone, Copy)]
struct Exact;

impl BoxTest for Exact {
    #[inline(always)]
    fn hits(self, r: &NodeRay, n: &Node4, t_min: f32, t_max: f32) -> (Vec4, u32) {
        r.hits(n, t_min, t_max)
    }
}

/// The slab test with fused multiply–subtracts, `plane · inv − o · inv` in one rounding, as
/// Embree's kernels test boxes: half the arithmetic of [`Exact`] per plane, for the AVX2 and
/// AVX-512 paths (their FMA unit; the token proves the CPU has it). Rays whose `inv` or `o · inv`
/// is not finite (a zero direction component) take [`Exact`]'s test instead, which handles them.
///
/// The distances differ from [`Exact`]'s in the last bits (relative to the origin's magnitude
/// rather than to the distance), so a box can be entered or missed differently only where a ray
/// grazes its boundary. Boxes only cull: the hit a ray finds is the same unless its hit point
/// lies within that rounding of a box boundary (the exception the module notes describe for
/// shared edges). Measured: none of the Embree bench's 918K closest-hit rays, and none of this
/// crate's stream tests, answer differently.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
struct Fused(pulp::x86::V3);

#[cfg(target_arch = "x86_64")]
impl BoxTest for Fused {
    #[inline(always)]
    fn hits(self, r: &NodeRay, n: &Node4, t_min: f32, t_max: f32) -> (Vec4, u32) {
        if !r.fusable {
            return Exact.hits(r, n, t_min, t_max);
        }
        let fma = self.0.fma;
        let mut near = Vec4::splat(t_min);
        let mut far = Vec4::splat(t_max);
        for axis in 0..3 {
            let (inv, o_inv) = (Vec4::splat(r.inv[axis]).into(), Vec4::splat(r.o_inv[axis]).into());
            let entry = fma._mm_fmsub_ps(n.planes[usize::from(r.near[axis])].into(), inv, o_inv);
            let exit = fma._mm_fmsub_ps(n.planes[usize::from(r.far[axis])].into(), inv, o_inv);
            near = near.max(Vec4::from(entry));
            far = far.min(Vec4::from(exit));
        }
        (near, near.cmple(far).bitmask())
    }
}

/// Runs `$body` with `$test` bound to the box test of the instruction-set path in use:
/// [`Fused`] on the AVX2 and AVX-512 paths, [`Exact`] on the others. Once per stream, so each
/// walk is compiled for both and the choice costs nothing per ray.
macro_rules! with_box_test {
    ($test:ident => $body:expr) => {{
        #[cfg(target_arch = "x86_64")]
        match isa::fma_token() {
            Some(simd) => {
                let $test = Fused(simd);
                $body
            }
            None => {
                let $test = Exact;
                $body
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let $test = Exact;
            $body
        }
    }};
}

/// A ray in a list: its index in the stream and its entry distance into the list's box.
type Listed = (u32, f32);

/// Per-thread scratch of the stream traversal, kept from stream to stream (too large to zero
/// for each).
struct Scratch {
    /// The stream's rays.
    node_rays: Vec<NodeRay>,
    /// Each ray's closest hit so far, and its distance alone (read at every box test).
    best: Vec<ClosestSoFar>,
    best_t: Vec<f32>,
    /// Shadow rays: each ray's segment end and attenuation so far.
    t_max: Vec<f32>,
    att: Vec<f32>,
    lists: Vec<Listed>,
    visits: Vec<Visit>,
    single: [u64; STACK_LEN],
}

thread_local! {
    static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::new(Scratch::new());
}

/// Runs `f` with this thread's scratch (a fresh one if it is in use further up the stack).
fn with_scratch<R>(f: impl FnOnce(&mut Scratch) -> R) -> R {
    SCRATCH.with(|cell| match cell.try_borrow_mut() {
        Ok(mut s) => f(&mut s),
        Err(_) => f(&mut Scratch::new()),
    })
}

impl Scratch {
    fn new() -> Self {
        Scratch {
            node_rays: Vec::with_capacity(STREAM),
            best: Vec::with_capacity(STREAM),
            best_t: Vec::with_capacity(STREAM),
            t_max: Vec::with_capacity(STREAM),
            att: Vec::with_capacity(STREAM),
            // Zeroed memory from the system: only the pages written are ever touched.
            lists: vec![(0, 0.0); (LIST_LEVELS * 4 + 1) * STREAM],
            visits: Vec::with_capacity(LIST_LEVELS * 4),
            single: [0; STACK_LEN],
        }
    }
}

impl SceneBvh {
    /// One answer per ray of `rays`, each `fill` to start with (and to the end in a BVH
    /// without triangles): `f` runs on each stream of `rays` (at most [`STREAM`] of them) and
    /// its part of the answers, with this thread's scratch, compiled for the instruction set in
    /// use.
    #[inline(always)]
    fn in_streams<R, O: Clone>(&self, rays: &[R], fill: O, mut f: impl FnMut(&mut Scratch, &[R], &mut [O])) -> Vec<O> {
        let mut out = vec![fill; rays.len()];
        if !self.nodes.is_empty() {
            with_scratch(|scratch| {
                for (rays, out) in rays.chunks(STREAM).zip(out.chunks_mut(STREAM)) {
                    isa::dispatch(
                        #[inline(always)]
                        || f(scratch, rays, out),
                    );
                }
            });
        }
        out
    }

    /// The closest triangle hit of each ray `(origin, dir)` with `t_min < t < t_max`, in the
    /// order of `rays`, each as [`closest_hit`](Self::closest_hit) would answer it (but for
    /// rays through shared edges, see the module notes).
    /// Faster than one ray at a time when many rays cross the same parts of the scene, such as
    /// a frame's reflection or bounce rays, at the cost of a list write per ray and child box
    /// entered.
    pub fn closest_hits_stream(&self, rays: &[(Vec3, Vec3)], t_min: f32, t_max: f32) -> Vec<Option<Hit>> {
        self.in_streams(
            rays,
            None,
            #[inline(always)]
            |scratch, rays, out| with_box_test!(test => self.stream_with(test, scratch, rays, t_min, t_max, out)),
        )
    }

    /// Listing 8b for each ray `(origin, dir, t_max)`, as
    /// [`any_hit_attenuation_cached`](Self::any_hit_attenuation_cached) would answer them one
    /// after another with `cache` (rays towards one light, in pixel order). Rays go one at a
    /// time while they are being blocked (the cache then ends most of them after one leaf
    /// test); the rays of a lit run, which the cache cannot help, go out together as a ray
    /// stream (after each lit ray traced alone, the next 8 that the cache does not block).
    /// `cache` is left as the rays traced alone leave it. With no cache, every ray goes into
    /// the stream (as [`any_hit_attenuation`](Self::any_hit_attenuation) would answer each).
    ///
    /// Attenuations are bit for bit the single rays' where a ray meets at most one
    /// transparent shadow caster; where it meets several, their transparencies may be
    /// multiplied in another order (a difference in the last bits).
    pub fn any_hit_attenuation_stream(
        &self,
        prepared: &PreparedScene,
        rays: &[(Vec3, Vec3, f32)],
        mut cache: Option<&mut ShadowCache>,
    ) -> Vec<f32> {
        self.in_streams(
            rays,
            1.0,
            #[inline(always)]
            |scratch, rays, out| with_box_test!(test => self.shadow_stream_with(test, scratch, prepared, rays, cache.as_deref_mut(), out)),
        )
    }

    #[inline(always)]
    fn shadow_stream_with(
        &self,
        test: impl BoxTest,
        s: &mut Scratch,
        prepared: &PreparedScene,
        rays: &[(Vec3, Vec3, f32)],
        cache: Option<&mut ShadowCache>,
        out: &mut [f32],
    ) {
        s.node_rays.clear();
        s.node_rays.extend(rays.iter().map(|&(o, d, _)| NodeRay::new(o, d)));
        s.t_max.clear();
        s.t_max.extend(rays.iter().map(|r| r.2));
        s.att.clear();
        s.att.resize(rays.len(), 1.0);
        let (node_rays, t_max, att, lists) = (&s.node_rays, &s.t_max, &mut s.att, &mut s.lists);
        // One ray at a time first, in order, as `any_hit_attenuation_cached` does: the cached
        // blocker, and where it does not block, either a traversal of the ray's own or a place
        // in the stream. Where rays are being blocked (the cache or the last traversal found a
        // blocker), they keep to their own traversals, which move the cache onto each new
        // blocker; where they reach the light, the next `PROBE_EVERY` rays the cache misses go
        // into the stream, then one traverses alone again to see whether a shadow begins.
        let Some(cache) = cache else {
            // No cache: every ray in the stream.
            for (id, l) in lists[..rays.len()].iter_mut().enumerate() {
                *l = (id as u32, 0.0);
            }
            return self.shadow_stream_walk(test, s, prepared, rays.len(), out);
        };
        let mut n = 0;
        let mut lit_run: Option<usize> = None;
        for (id, r) in node_rays.iter().map(NodeRay::pre).enumerate() {
            if self.cache_blocks(cache, &r, t_max[id]) {
                att[id] = 0.0;
                lit_run = None;
            } else if let Some(run) = lit_run.filter(|&run| run < PROBE_EVERY) {
                lists[n] = (id as u32, 0.0);
                n += 1;
                lit_run = Some(run + 1);
            } else {
                att[id] = self.attenuation_traversed(prepared, &r, t_max[id], cache);
                lit_run = (att[id] > 0.0).then_some(0);
            }
        }
        self.shadow_stream_walk(test, s, prepared, n, out);
    }

    /// The stream walk of the shadow rays `s.lists[..n]` (prepared in `s`), then every ray's
    /// attenuation into `out`.
    #[inline(always)]
    fn shadow_stream_walk(&self, test: impl BoxTest, s: &mut Scratch, prepared: &PreparedScene, n: usize, out: &mut [f32]) {
        let (node_rays, t_max, att, lists) = (&s.node_rays, &s.t_max, &mut s.att, &mut s.lists);
        // The blockers the stream finds are not kept (the caller's cache follows the rays
        // traced alone), but `attenuate` records one.
        let mut unused = ShadowCache::default();
        s.visits.clear();
        if n > 0 {
            s.visits.push(Visit { node: 0, start: 0, len: n as u32, end: n as u32 });
        }
        while let Some(v) = s.visits.pop() {
            let (start, len) = (v.start as usize, v.len as usize);
            if v.node & LEAF != 0 || len < SINGLE_RAYS_BELOW {
                for &(id, _) in &lists[start..start + len] {
                    let id = id as usize;
                    if att[id] > 0.0 {
                        let a = &mut att[id];
                        let mut step = |leaf, slot0, mask, u, v| self.attenuate(prepared, a, &mut unused, leaf, slot0, mask, u, v);
                        if v.node & LEAF != 0 {
                            self.leaf_pack_hits(v.node, &node_rays[id].pre(), 0.0, t_max[id], &mut step);
                        } else {
                            self.for_each_pack_hit_from(&node_rays[id].pre(), 0.0, t_max[id], v.node, step);
                        }
                    }
                }
                continue;
            }
            let base = v.end as usize;
            let node = &self.nodes[v.node as usize];
            let (below, above) = lists.split_at_mut(base);
            let child_lists = &mut above[..4 * len];
            let mut counts = [0usize; 4];
            for &(id, _) in &below[start..start + len] {
                if att[id as usize] <= 0.0 {
                    continue;
                }
                let (_, mask) = test.hits(&node_rays[id as usize], node, 0.0, t_max[id as usize]);
                for (k, count) in counts.iter_mut().enumerate() {
                    child_lists[k * len + *count] = (id, 0.0);
                    *count += (mask >> k & 1) as usize;
                }
            }
            // Children in index order (the last pushed is taken first).
            let end = (base + 4 * len) as u32;
            for k in (0..4).rev() {
                if counts[k] > 0 {
                    s.visits.push(Visit { node: node.child[k], start: (base + k * len) as u32, len: counts[k] as u32, end });
                }
            }
        }
        for (o, &a) in out.iter_mut().zip(att.iter()) {
            *o = a.max(0.0);
        }
    }

    #[inline(always)]
    fn stream_with(&self, test: impl BoxTest, s: &mut Scratch, rays: &[(Vec3, Vec3)], t_min: f32, t_max: f32, out: &mut [Option<Hit>]) {
        let n = rays.len();
        s.node_rays.clear();
        s.node_rays.extend(rays.iter().map(|&(o, d)| NodeRay::new(o, d)));
        s.best.clear();
        s.best.resize(n, ClosestSoFar { t: t_max, slot: 0, uv: (0.0, 0.0) });
        s.best_t.clear();
        s.best_t.resize(n, t_max);
        let (node_rays, best, best_t) = (&s.node_rays, &mut s.best, &mut s.best_t);
        let lists = &mut s.lists;
        for (i, l) in lists[..n].iter_mut().enumerate() {
            *l = (i as u32, t_min);
        }
        s.visits.clear();
        s.visits.push(Visit { node: 0, start: 0, len: n as u32, end: n as u32 });
        while let Some(v) = s.visits.pop() {
            let (start, len) = (v.start as usize, v.len as usize);
            if v.node & LEAF != 0 {
                for &(id, near) in &lists[start..start + len] {
                    let b = &mut best[id as usize];
                    if near <= b.t {
                        b.t = self.leaf_closest(v.node, &node_rays[id as usize].pre(), t_min, b.t, &mut b.slot, &mut b.uv);
                        best_t[id as usize] = b.t;
                    }
                }
                continue;
            }
            if len < SINGLE_RAYS_BELOW {
                for &(id, near) in &lists[start..start + len] {
                    let b = &mut best[id as usize];
                    if near <= b.t {
                        self.closest_from(&mut s.single, &node_rays[id as usize].pre(), t_min, v.node, b);
                        best_t[id as usize] = b.t;
                    }
                }
                continue;
            }
            // The children's lists, one after another from `end` (the rays' list lies below it).
            let base = v.end as usize;
            let node = &self.nodes[v.node as usize];
            let (below, above) = lists.split_at_mut(base);
            let child_lists = &mut above[..4 * len];
            let mut counts = [0usize; 4];
            let mut near_sum = [0.0f32; 4];
            for &(id, near) in &below[start..start + len] {
                let t = best_t[id as usize];
                if near > t {
                    continue;
                }
                let (near, mask) = test.hits(&node_rays[id as usize], node, t_min, t);
                let near = near.to_array();
                for k in 0..4 {
                    let entered = mask >> k & 1 != 0;
                    child_lists[k * len + counts[k]] = (id, near[k]);
                    counts[k] += usize::from(entered);
                    near_sum[k] += if entered { near[k] } else { 0.0 };
                }
            }
            // Farthest first on the stack, so the nearest is taken next.
            let mean: [f32; 4] = std::array::from_fn(|k| near_sum[k] / counts[k].max(1) as f32);
            let mut order = [0usize, 1, 2, 3];
            order.sort_unstable_by(|&a, &b| mean[b].total_cmp(&mean[a]));
            let end = (base + 4 * len) as u32;
            for k in order {
                if counts[k] > 0 {
                    s.visits.push(Visit { node: node.child[k], start: (base + k * len) as u32, len: counts[k] as u32, end });
                }
            }
        }
        for (o, b) in out.iter_mut().zip(best.iter()) {
            *o = (b.t < t_max).then(|| self.hit_of(b));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    /// A node of four random boxes (some slots empty) around the origin, at scale `s`.
    fn random_node(rng: &mut StdRng, s: f32) -> Node4 {
        let mut n = Node4::EMPTY;
        for k in 0..4 {
            if rng.random_range(0..6) == 0 {
                continue;
            }
            let c = Vec3A::new(rng.random_range(-s..s), rng.random_range(-s..s), rng.random_range(-s..s));
            let h = Vec3A::new(rng.random_range(0.0..s), rng.random_range(0.0..s), rng.random_range(0.0..s)) * 0.3;
            n.set(k, c - h, c + h, k as u32);
        }
        n
    }

    /// The fused box test's entry distances are the exact test's within its stated rounding
    /// (a few ulps of `|o · inv|` and of the distance itself), and where the two disagree on
    /// whether a box is entered, the exact test's entry and exit (or the ray's limits) lie
    /// within that rounding of each other: a grazing ray. Rays whose box tests cannot be fused
    /// get the exact test's bits.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn fused_box_tests_are_the_exact_ones_within_rounding() {
        // The AVX2 + FMA path; a CPU without it never runs the fused test.
        let Some(simd) = pulp::x86::V3::try_new() else { return };
        let fused = Fused(simd);
        let mut rng = StdRng::seed_from_u64(23);
        let (mut compared, mut disagreed) = (0, 0);
        for k in 0..200_000 {
            let s = [0.01, 1.0, 100.0, 1e4][k % 4];
            let n = random_node(&mut rng, s);
            let mut o =
                Vec3::new(rng.random_range(-2.0 * s..2.0 * s), rng.random_range(-2.0 * s..2.0 * s), rng.random_range(-2.0 * s..2.0 * s));
            // Aimed near a box's centre, so that most rays enter some box and some graze one.
            let (lo, hi) = n.child_box(k % 4);
            let aim = if lo.x <= hi.x { Vec3::from((lo + hi) * 0.5) } else { Vec3::ZERO };
            let jitter = Vec3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
            let mut d = (aim + jitter * (0.3 * s) - o).normalize_or(Vec3::X);
            // Zero components (not fusable), tiny ones (huge inverses), and an origin on a
            // box's plane.
            match k % 17 {
                0 => d[k % 3] = 0.0,
                1 => d[k % 3] = 1e-30,
                _ => {}
            }
            if k % 19 == 0 {
                o.x = n.planes[0][0];
            }
            let r = NodeRay::new(o, d);
            let (t_min, t_max) = (0.0, if k % 5 == 0 { rng.random_range(0.0..3.0 * s) } else { f32::INFINITY });
            let (exact_near, exact_mask) = Exact.hits(&r, &n, t_min, t_max);
            let (near, mask) = fused.hits(&r, &n, t_min, t_max);
            if !r.fusable {
                assert_eq!((near.to_array().map(f32::to_bits), mask), (exact_near.to_array().map(f32::to_bits), exact_mask), "ray {k}");
                continue;
            }
            // Each slab distance is off by at most ~ε(|o · inv| + |t|) per rounding: the
            // product o · inv, the fused operation's result, and the exact test's two.
            let eps = 4.0 * f32::EPSILON;
            let slack = |t: f32| eps * (r.o_inv.iter().map(|v| v.abs()).fold(0.0, f32::max) + t.abs());
            // The exact test's exit distances (it returns only the entries).
            let mut exact_far = Vec4::splat(t_max);
            for axis in 0..3 {
                exact_far = exact_far.min((n.planes[r.far[axis] as usize] - Vec4::splat(r.o[axis])) * Vec4::splat(r.inv[axis]));
            }
            for lane in 0..4 {
                let (a, b) = (exact_near[lane], near[lane]);
                if exact_mask >> lane & 1 != 0 && mask >> lane & 1 != 0 {
                    compared += 1;
                    assert!((a - b).abs() <= slack(a), "ray {k}, box {lane}: entry {a} exact, {b} fused");
                }
                if (exact_mask ^ mask) >> lane & 1 != 0 {
                    disagreed += 1;
                    let f = exact_far[lane];
                    assert!((a - f).abs() <= 2.0 * (slack(a) + slack(f)), "ray {k}, box {lane}: entered one way only, [{a}, {f}]");
                }
            }
        }
        assert!(compared > 40_000, "too few boxes entered to compare: {compared}");
        // Grazing rays are rare even in this set, built to have some (origins on planes).
        assert!(disagreed * 500 < compared, "{disagreed} disagreements in {compared} boxes");
    }
}
