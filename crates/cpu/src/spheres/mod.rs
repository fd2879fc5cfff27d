//! A BVH over millions of equal-radius spheres (the RT-scene's point cloud, design §5).
//!
//! - **Build**: the `bvh_core` binned SAH the triangle BVH uses too, over the spheres'
//!   boxes (16 bins along the centres' widest axis, leaves of at most four spheres; see
//!   `build::SPHERE_RULES`). The top of the tree is built in parallel with `rayon::join`, and the
//!   result does not depend on the thread count or timing (deterministic).
//! - **Layout** (memory): the binary tree is collapsed into 4-wide nodes (each opens the child
//!   of largest area until it has four), holding their children's boxes as structure of arrays
//!   (the `bvh_core` node the triangle BVH uses too: 128 B per node, about one node per
//!   6 spheres). Centres are stored in leaf order as three per-axis arrays (12 B/sphere) with
//!   their original index (4 B/sphere). [`SphereBvh::bytes`] reports the total (about 37 B per
//!   sphere).
//! - **Trace**: the core's ordered depth-first traversal (`bvh_core::closest_walk`):
//!   the four children's slab tests in one SIMD pass, the nearest entered child next, the others
//!   on a stack with their entry distances (skipped when a closer hit has been found). A leaf's
//!   ≤ 4 spheres are tested at once with the exact ray–sphere test in the perpendicular-distance
//!   form (KNOWN-GOOD gotcha 13), lane by lane the same operations in the same order as the
//!   scalar [`ray_sphere`], so bit for bit its results:
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

use glam::{Vec3, Vec3A, Vec4};

use crate::bvh_core::{EMPTY_SLOT, LEAF, Node4, STACK_LEN, leaf_parts, leaf_ref};

/// Spheres per leaf at most.
const LEAF_MAX: usize = 4;
/// A reusable traversal stack (the core's: entry distance and subtree reference per entry).
#[derive(Debug, Clone)]
pub struct TraversalStack(Box<[u64; STACK_LEN]>);

impl Default for TraversalStack {
    fn default() -> Self {
        Self(Box::new([0; STACK_LEN]))
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

mod build;
mod traverse;

use traverse::*;
pub use traverse::{PreparedRay, closest_hit_brute_force, ray_sphere, sphere_hits4};

impl SphereBvh {
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
}
