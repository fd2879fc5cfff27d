//! `bvh`: the scene's triangle BVH for the trace stage (DESIGN §1, "PreparedScene … BVHs").
//!
//! Our own binary BVH rather than obvhs: a binned-SAH build (16 bins on all three axes, the
//! upper levels split in parallel with `rayon::join`) and a traversal tuned for the two ray
//! kinds of paper 1:
//! - `closest_hit`: ordered (near child first) stack traversal, the far child pushed only when
//!   its box entry is before the current closest hit;
//! - `any_hit_attenuation` (listing 8b): unordered traversal that visits every triangle on the
//!   segment once and stops as soon as the attenuation reaches 0 (an opaque blocker).
//!
//! Leaves hold triangles in leaf order as precomputed Möller–Trumbore data (`v0`, `e1`, `e2`),
//! so a leaf test touches one contiguous array. Nodes are 32 bytes; the two children of an inner
//! node are adjacent, so both child boxes share one cache line.
//!
//! The build is deterministic (same tree for any thread count): the parallel halves build into
//! separate subtrees that are flattened in a fixed depth-first order.

use glam::{Vec3, Vec3A, Vec4};
use rayon::prelude::*;

use crate::prepare::{PreparedScene, TriangleRef};

/// A ray–triangle hit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Distance along the ray (in units of the ray direction's length).
    pub t: f32,
    pub triangle: TriangleRef,
    /// Weights of the triangle's three corners (sum 1), as `PreparedScene::surface_at` takes them.
    pub bary: Vec3,
}

/// One node: bounds in `min.xyz`/`max.xyz`; `min.w` holds the bits of the first child index
/// (inner) or the first leaf triangle (leaf), `max.w` the bits of the triangle count (0 = inner).
#[derive(Debug, Clone, Copy)]
struct Node {
    min: Vec4,
    max: Vec4,
}

impl Node {
    #[inline(always)]
    fn first(&self) -> u32 {
        self.min.w.to_bits()
    }
    #[inline(always)]
    fn count(&self) -> u32 {
        self.max.w.to_bits()
    }
    fn new(min: Vec3A, max: Vec3A, first: u32, count: u32) -> Self {
        Self { min: min.extend(f32::from_bits(first)), max: max.extend(f32::from_bits(count)) }
    }
}

/// Precomputed Möller–Trumbore triangle.
#[derive(Debug, Clone, Copy)]
struct Tri {
    v0: Vec3A,
    e1: Vec3A,
    e2: Vec3A,
}

/// What a shadow ray does at a triangle (listing 8b), precomputed per triangle in leaf order.
/// `IGNORE` (material casts no shadows) = transparency 1; constant opacity without maps =
/// that transparency; `EVALUATE` = textured opacity, evaluated with `surface_at` at the hit.
const EVALUATE: f32 = -1.0;

/// Triangle BVH over every triangle of a [`PreparedScene`].
#[derive(Debug, Clone)]
pub struct SceneBvh {
    nodes: Vec<Node>,
    tris: Vec<Tri>,
    refs: Vec<TriangleRef>,
    /// Shadow-ray transparency per leaf-ordered triangle, or [`EVALUATE`].
    shadow_transparency: Vec<f32>,
}

const BINS: usize = 16;
/// Leaves are forced below this many triangles unless the centroids coincide.
const MAX_LEAF: usize = 8;
/// Nodes at this depth become leaves whatever their size, so traversal stacks stay bounded.
const MAX_DEPTH: u32 = 56;
const STACK: usize = 64;
/// Subtrees larger than this are split in parallel.
const PARALLEL_MIN: usize = 8192;
/// SAH: cost of a box test relative to a triangle test.
const TRAVERSAL_COST: f32 = 1.0;
const INTERSECT_COST: f32 = 1.0;

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

enum BuildNode {
    Leaf { bounds: Bounds, first: u32, count: u32 },
    Inner { bounds: Bounds, children: Box<(BuildNode, BuildNode)> },
}

struct BuildInput {
    boxes: Vec<Bounds>,
    centroids: Vec<Vec3A>,
}

impl SceneBvh {
    /// Builds the BVH over `prepared.triangles`.
    pub fn build(prepared: &PreparedScene) -> SceneBvh {
        let corners: Vec<[Vec3; 3]> = prepared.triangles.par_iter().map(|t| prepared.triangle(*t)).collect();
        let boxes: Vec<Bounds> = corners
            .par_iter()
            .map(|c| {
                let [a, b, d] = c.map(Vec3A::from);
                // Non-finite corners make an empty box: such triangles can never be hit anyway.
                if !(a.is_finite() && b.is_finite() && d.is_finite()) {
                    return Bounds { min: Vec3A::ZERO, max: Vec3A::ZERO };
                }
                Bounds { min: a.min(b).min(d), max: a.max(b).max(d) }
            })
            .collect();
        let centroids = boxes.par_iter().map(|b| (b.min + b.max) * 0.5).collect();
        let input = BuildInput { boxes, centroids };
        let mut order: Vec<u32> = (0..prepared.triangles.len() as u32).collect();

        let mut nodes = Vec::with_capacity(order.len());
        if !order.is_empty() {
            let root = build_rec(&input, &mut order, 0, 0);
            nodes.push(Node::new(Vec3A::ZERO, Vec3A::ZERO, 0, 0));
            flatten(&root, 0, &mut nodes);
        }

        let tris = order
            .par_iter()
            .map(|&i| {
                let [a, b, c] = corners[i as usize].map(Vec3A::from);
                Tri { v0: a, e1: b - a, e2: c - a }
            })
            .collect();
        let refs: Vec<TriangleRef> = order.iter().map(|&i| prepared.triangles[i as usize]).collect();
        let shadow_transparency = refs
            .iter()
            .map(|t| {
                let m = prepared.material(*t);
                if !m.casts_shadows {
                    1.0
                } else if m.diffuse_map.is_none() && m.optical_map.is_none() {
                    1.0 - m.opacity.clamp(0.0, 1.0)
                } else {
                    EVALUATE
                }
            })
            .collect();
        SceneBvh { nodes, tris, refs, shadow_transparency }
    }

    /// Number of triangles in the BVH.
    pub fn triangle_count(&self) -> usize {
        self.tris.len()
    }

    /// Number of nodes (inner and leaf).
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// The closest triangle hit with `t_min < t < t_max` along `origin + t·dir`.
    pub fn closest_hit(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Option<Hit> {
        let o = Vec3A::from(origin);
        let d = Vec3A::from(dir);
        let inv = d.recip();
        if self.tris.is_empty() {
            return None;
        }
        let mut best_t = t_max;
        let mut best = u32::MAX;
        let mut best_uv = (0.0f32, 0.0f32);
        let mut stack = [0u32; STACK];
        let mut sp = 0usize;
        let mut node = &self.nodes[0];
        if box_entry(node, o, inv, t_min, best_t) == f32::INFINITY {
            return None;
        }
        loop {
            let count = node.count();
            if count == 0 {
                let c = node.first() as usize;
                let (a, b) = (&self.nodes[c], &self.nodes[c + 1]);
                let ta = box_entry(a, o, inv, t_min, best_t);
                let tb = box_entry(b, o, inv, t_min, best_t);
                if ta != f32::INFINITY {
                    if tb != f32::INFINITY {
                        let (near, far) = if ta <= tb { (c, c + 1) } else { (c + 1, c) };
                        stack[sp] = far as u32;
                        sp += 1;
                        node = &self.nodes[near];
                    } else {
                        node = a;
                    }
                    continue;
                } else if tb != f32::INFINITY {
                    node = b;
                    continue;
                }
            } else {
                let first = node.first() as usize;
                for i in first..first + count as usize {
                    if let Some((t, u, v)) = intersect(&self.tris[i], o, d, t_min, best_t) {
                        best_t = t;
                        best = i as u32;
                        best_uv = (u, v);
                    }
                }
            }
            // Pop the next node whose box is still before the closest hit.
            loop {
                if sp == 0 {
                    return (best != u32::MAX).then(|| Hit {
                        t: best_t,
                        triangle: self.refs[best as usize],
                        bary: Vec3::new(1.0 - best_uv.0 - best_uv.1, best_uv.0, best_uv.1),
                    });
                }
                sp -= 1;
                let n = &self.nodes[stack[sp] as usize];
                if box_entry(n, o, inv, t_min, best_t) != f32::INFINITY {
                    node = n;
                    break;
                }
            }
        }
    }

    /// Whether a triangle whose material casts shadows (whatever its opacity) is hit with
    /// `t_min < t < t_max`.
    pub fn occluded(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> bool {
        let mut hit = false;
        self.for_each_hit(origin, dir, t_min, t_max, |_, _, _| {
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
        let mut att = 1.0f32;
        self.for_each_hit(origin, dir, 0.0, t_max, |i, u, v| {
            let tr = self.shadow_transparency[i];
            let tr = if tr == EVALUATE {
                let s = prepared.surface_at(self.refs[i], Vec3::new(1.0 - u - v, u, v), 0.0);
                1.0 - s.opacity
            } else {
                tr
            };
            att *= tr;
            att > 0.0
        });
        att.max(0.0)
    }

    /// Calls `f(leaf triangle, u, v)` for every triangle hit on the segment, in no particular
    /// order, until `f` returns false. Cheap triangles (transparency 1) are skipped up front.
    #[inline]
    fn for_each_hit(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32, mut f: impl FnMut(usize, f32, f32) -> bool) {
        let o = Vec3A::from(origin);
        let d = Vec3A::from(dir);
        let inv = d.recip();
        if self.tris.is_empty() {
            return;
        }
        let mut stack = [0u32; STACK];
        let mut sp = 0usize;
        let mut node = &self.nodes[0];
        if box_entry(node, o, inv, t_min, t_max) == f32::INFINITY {
            return;
        }
        loop {
            let count = node.count();
            if count == 0 {
                let c = node.first() as usize;
                let (a, b) = (&self.nodes[c], &self.nodes[c + 1]);
                let ha = box_entry(a, o, inv, t_min, t_max) != f32::INFINITY;
                let hb = box_entry(b, o, inv, t_min, t_max) != f32::INFINITY;
                if ha {
                    if hb {
                        stack[sp] = c as u32 + 1;
                        sp += 1;
                    }
                    node = a;
                    continue;
                } else if hb {
                    node = b;
                    continue;
                }
            } else {
                let first = node.first() as usize;
                for i in first..first + count as usize {
                    if self.shadow_transparency[i] == 1.0 {
                        continue;
                    }
                    if let Some((_, u, v)) = intersect(&self.tris[i], o, d, t_min, t_max)
                        && !f(i, u, v)
                    {
                        return;
                    }
                }
            }
            if sp == 0 {
                return;
            }
            sp -= 1;
            node = &self.nodes[stack[sp] as usize];
        }
    }
}

/// Slab test: the entry distance into the node's box within `[t_min, t_max]`, or ∞ on a miss.
#[inline(always)]
fn box_entry(n: &Node, o: Vec3A, inv: Vec3A, t_min: f32, t_max: f32) -> f32 {
    let t1 = (Vec3A::from_vec4(n.min) - o) * inv;
    let t2 = (Vec3A::from_vec4(n.max) - o) * inv;
    let near = t1.min(t2).max_element().max(t_min);
    let far = t1.max(t2).min_element().min(t_max);
    if near <= far { near } else { f32::INFINITY }
}

/// Möller–Trumbore: `(t, u, v)` with `t_min < t < t_max`, `u`/`v` the weights of corners 1/2.
#[inline(always)]
fn intersect(tri: &Tri, o: Vec3A, d: Vec3A, t_min: f32, t_max: f32) -> Option<(f32, f32, f32)> {
    let p = d.cross(tri.e2);
    let det = tri.e1.dot(p);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let inv_det = 1.0 / det;
    let s = o - tri.v0;
    let u = s.dot(p) * inv_det;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(tri.e1);
    let v = d.dot(q) * inv_det;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = tri.e2.dot(q) * inv_det;
    (t > t_min && t < t_max).then_some((t, u, v))
}

fn build_rec(input: &BuildInput, prims: &mut [u32], offset: u32, depth: u32) -> BuildNode {
    let mut bounds = Bounds::EMPTY;
    let mut cb = Bounds::EMPTY;
    for &p in prims.iter() {
        bounds.grow(&input.boxes[p as usize]);
        cb.grow_point(input.centroids[p as usize]);
    }
    let n = prims.len();
    let leaf = BuildNode::Leaf { bounds, first: offset, count: n as u32 };
    if n <= 1 || depth >= MAX_DEPTH {
        return leaf;
    }
    let extent = cb.max - cb.min;
    let split = best_split(input, prims, &cb, &bounds);
    let mid = match split {
        Some((axis, bin, cost)) if cost < n as f32 * INTERSECT_COST || n > MAX_LEAF => {
            let scale = BINS as f32 / extent[axis];
            let lo = cb.min[axis];
            partition(prims, |p| bin_of(input.centroids[p as usize][axis], lo, scale) <= bin)
        }
        Some(_) => return leaf,
        None if n > MAX_LEAF => n / 2, // all centroids equal: any split is as good
        None => return leaf,
    };
    if mid == 0 || mid == n {
        return leaf;
    }
    let (l, r) = prims.split_at_mut(mid);
    let (a, b) = if n >= PARALLEL_MIN {
        rayon::join(|| build_rec(input, l, offset, depth + 1), || build_rec(input, r, offset + mid as u32, depth + 1))
    } else {
        (build_rec(input, l, offset, depth + 1), build_rec(input, r, offset + mid as u32, depth + 1))
    };
    BuildNode::Inner { bounds, children: Box::new((a, b)) }
}

#[inline]
fn bin_of(c: f32, lo: f32, scale: f32) -> usize {
    (((c - lo) * scale) as usize).min(BINS - 1)
}

/// Binned SAH over all three axes: `(axis, last bin of the left side, cost)`.
fn best_split(input: &BuildInput, prims: &[u32], cb: &Bounds, bounds: &Bounds) -> Option<(usize, usize, f32)> {
    let extent = cb.max - cb.min;
    let mut best: Option<(usize, usize, f32)> = None;
    let inv_area = 1.0 / bounds.half_area().max(f32::MIN_POSITIVE);
    for axis in 0..3 {
        if extent[axis] <= 0.0 || !extent[axis].is_finite() {
            continue;
        }
        let scale = BINS as f32 / extent[axis];
        let lo = cb.min[axis];
        let mut bins = [Bounds::EMPTY; BINS];
        let mut counts = [0u32; BINS];
        for &p in prims {
            let b = bin_of(input.centroids[p as usize][axis], lo, scale);
            bins[b].grow(&input.boxes[p as usize]);
            counts[b] += 1;
        }
        // Sweep from the right, then from the left.
        let mut right_area = [0.0f32; BINS];
        let mut acc = Bounds::EMPTY;
        for i in (1..BINS).rev() {
            acc.grow(&bins[i]);
            right_area[i] = acc.half_area();
        }
        let mut left = Bounds::EMPTY;
        let mut nl = 0u32;
        let total: u32 = counts.iter().sum();
        for i in 0..BINS - 1 {
            left.grow(&bins[i]);
            nl += counts[i];
            let nr = total - nl;
            if nl == 0 || nr == 0 {
                continue;
            }
            let cost = TRAVERSAL_COST + INTERSECT_COST * (left.half_area() * nl as f32 + right_area[i + 1] * nr as f32) * inv_area;
            if best.is_none_or(|b| cost < b.2) {
                best = Some((axis, i, cost));
            }
        }
    }
    best
}

/// In-place partition: elements with `pred` true first; returns how many.
fn partition(v: &mut [u32], pred: impl Fn(u32) -> bool) -> usize {
    let mut i = 0;
    let mut j = v.len();
    while i < j {
        if pred(v[i]) {
            i += 1;
        } else {
            j -= 1;
            v.swap(i, j);
        }
    }
    i
}

fn flatten(n: &BuildNode, idx: usize, nodes: &mut Vec<Node>) {
    match n {
        BuildNode::Leaf { bounds, first, count } => nodes[idx] = Node::new(bounds.min, bounds.max, *first, *count),
        BuildNode::Inner { bounds, children } => {
            let c = nodes.len();
            nodes.push(Node::new(Vec3A::ZERO, Vec3A::ZERO, 0, 0));
            nodes.push(Node::new(Vec3A::ZERO, Vec3A::ZERO, 0, 0));
            nodes[idx] = Node::new(bounds.min, bounds.max, c as u32, 0);
            flatten(&children.0, c, nodes);
            flatten(&children.1, c + 1, nodes);
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
    fn build_is_deterministic_and_empty_scene_has_no_hits() {
        let scene = soup_scene(20_000, 11, vec![Material::default()]);
        let p = PreparedScene::new(&scene);
        let a = SceneBvh::build(&p);
        let b = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("pool").install(|| SceneBvh::build(&p));
        assert_eq!(a.refs, b.refs);
        assert_eq!(a.nodes.len(), b.nodes.len());
        assert!(a.nodes.iter().zip(&b.nodes).all(|(x, y)| x.min.to_array().map(f32::to_bits) == y.min.to_array().map(f32::to_bits)
            && x.max.to_array().map(f32::to_bits) == y.max.to_array().map(f32::to_bits)));
        // Every triangle is in exactly one leaf.
        let mut seen = vec![false; a.tris.len()];
        for n in a.nodes.iter().filter(|n| n.count() > 0) {
            for i in n.first()..n.first() + n.count() {
                assert!(!seen[i as usize]);
                seen[i as usize] = true;
            }
        }
        assert!(seen.iter().all(|&s| s));

        let empty = soup_scene(0, 1, vec![Material::default()]);
        let p = PreparedScene::new(&empty);
        let bvh = SceneBvh::build(&p);
        assert!(bvh.closest_hit(Vec3::ZERO, Vec3::X, 0.0, f32::INFINITY).is_none());
        assert_eq!(bvh.any_hit_attenuation(&p, Vec3::ZERO, Vec3::X, f32::INFINITY), 1.0);
    }
}
