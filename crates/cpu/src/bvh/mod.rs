//! `bvh`: the scene's triangle BVH for the trace stage (design §1, "PreparedScene … BVHs").
//!
//! Our own BVH rather than obvhs: 4-wide nodes built straight from binned-SAH binary splits
//! (16 bins on all three axes; large nodes are binned in parallel, the halves of large nodes
//! split in parallel with `rayon::join`, and the top levels' subtrees built in parallel), each
//! node's four child boxes tested at once with 4-lane SIMD (glam `Vec4`), as Embree's BVH4
//! does. The node layout, leaf references and the ordered closest-hit walk are `bvh_core`'s,
//! shared with the sphere BVH. Traversal is tuned for the two ray kinds of paper 1:
//! - `closest_hit`: ordered traversal (hit children sorted by entry distance, nearest first);
//!   stacked entries farther than the closest hit so far are skipped; the hit is the least
//!   `(t, pack slot)` pair, so it does not depend on the order leaves are visited in;
//! - `closest_hits` (`packet.rs`): the same for up to 16 coherent rays at once (a 4×4 tile of
//!   primary rays), each ray's hit bit for bit `closest_hit`'s;
//! - `closest_hits_stream` (`stream.rs`): the same for thousands of rays of any coherence at
//!   once, breadth-first by node (the trace stage's first reflection and refraction rays);
//!   `any_hit_attenuation_stream` likewise for a light's shadow rays, one at a time with the
//!   shadow cache where they are being blocked, as a stream where they reach the light;
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
//! min/max/count partials, and subtrees built in parallel are stitched in a fixed depth-first
//! order.

use glam::{Vec3, Vec3A, Vec4};
use rayon::prelude::*;

use hybrid_core::prepare::{PreparedScene, SHADOW_EVALUATE, TriangleRef};

use crate::bvh_core::{EMPTY_SLOT, LEAF, LEAF_COUNT_BITS, Node4, leaf_parts, leaf_ref};

/// A ray–triangle hit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Distance along the ray (in units of the ray direction's length).
    pub t: f32,
    pub triangle: TriangleRef,
    /// Weights of the triangle's three corners (sum 1), as `PreparedScene::surface_at` takes them.
    pub bary: Vec3,
}

/// Most packs one leaf reference can name; larger leaves are split under an extra node. A leaf
/// reference's count bits hold its pack count − 1.
const MAX_LEAF_PACKS: usize = 1 << LEAF_COUNT_BITS;

/// The packs of a leaf reference.
#[inline(always)]
fn leaf_packs(c: u32) -> std::ops::Range<usize> {
    let (first, count) = leaf_parts(c);
    first..first + count as usize + 1
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
    slab_hits(n, r.o, r.inv, r.near, r.far, t_min, t_max)
}

/// [`node_hits`] from the ray's parts: origin and inverse direction splatted per axis, and the
/// planes entered and left on each axis (one body, so every caller gets the same bits).
#[inline(always)]
fn slab_hits(
    n: &Node4,
    o: [Vec4; 3],
    inv: [Vec4; 3],
    near_plane: [usize; 3],
    far_plane: [usize; 3],
    t_min: f32,
    t_max: f32,
) -> (Vec4, u32) {
    let mut near = Vec4::splat(t_min);
    let mut far = Vec4::splat(t_max);
    for axis in 0..3 {
        near = near.max((n.planes[near_plane[axis]] - o[axis]) * inv[axis]);
        far = far.min((n.planes[far_plane[axis]] - o[axis]) * inv[axis]);
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

mod build;
mod packet;
mod shadow;
mod stream;
mod traverse;

pub use packet::{PACKET, PacketRay};
pub use stream::STREAM;

#[cfg(test)]
use build::*;
use traverse::*;

impl SceneBvh {
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bvh_core::LeafSink;
    use crate::bvh_core::build::Prim;
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
        brute_hits_with_margin(p, o, d, t_min, t_max).into_iter().map(|(t, i, _)| (t, i)).collect()
    }

    /// [`brute_hits`] with each hit's least barycentric coordinate (near 0: the ray passes
    /// close to an edge, where f32 arithmetic may decide otherwise).
    fn brute_hits_with_margin(p: &PreparedScene, o: Vec3, d: Vec3, t_min: f32, t_max: f32) -> Vec<(f64, usize, f64)> {
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
                hits.push((tt, i, u.min(v).min(1.0 - u - v)));
            }
        }
        hits
    }

    fn random_ray(rng: &mut StdRng) -> (Vec3, Vec3) {
        let o = Vec3::new(rng.random_range(-8.0..8.0), rng.random_range(-8.0..8.0), rng.random_range(-8.0..8.0));
        let target = Vec3::new(rng.random_range(-4.0..4.0), rng.random_range(-4.0..4.0), rng.random_range(-4.0..4.0));
        (o, (target - o).normalize())
    }

    /// The frame of a 4×4 fan of rays: a random eye, the unit direction from it to a random
    /// point near the soup's middle, and that direction's right and up axes.
    fn fan_frame(rng: &mut StdRng) -> (Vec3, Vec3, Vec3, Vec3) {
        let eye = Vec3::new(rng.random_range(-9.0..9.0), rng.random_range(-9.0..9.0), rng.random_range(-9.0..9.0));
        let centre = (Vec3::new(rng.random_range(-3.0..3.0), rng.random_range(-3.0..3.0), rng.random_range(-3.0..3.0)) - eye).normalize();
        let (right, up) = centre.any_orthonormal_pair();
        (eye, centre, right, up)
    }

    /// Ray `k` of a set with awkward directions: a random ray, but every 11th with a zero
    /// component and every 13th along an axis (infinite inverses).
    fn awkward_ray(rng: &mut StdRng, k: usize) -> (Vec3, Vec3) {
        let (o, mut d) = random_ray(rng);
        if k.is_multiple_of(11) {
            d[k % 3] = 0.0;
        }
        if k.is_multiple_of(13) {
            d = [Vec3::X, Vec3::NEG_Y, Vec3::Z][k % 3];
        }
        (o, d)
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
    fn tiny_scenes_answer_as_brute_force() {
        // One to twenty triangles: a root that is a single leaf (under a node of one child),
        // then the first splits.
        for n in 1..=20 {
            let scene = soup_scene(n, 40 + n as u64, vec![Material::default()]);
            let p = PreparedScene::new(&scene);
            let bvh = SceneBvh::build(&p);
            assert_eq!(bvh.triangle_count(), n);
            assert!(bvh.node_count() >= 1);
            let mut rng = StdRng::seed_from_u64(n as u64);
            let rays: Vec<(Vec3, Vec3)> = (0..300)
                .map(|_| {
                    // Aimed at a random triangle's centre, so most rays hit.
                    let [a, b, c] = p.triangle(p.triangles[rng.random_range(0..n)]);
                    let o = Vec3::new(rng.random_range(-8.0..8.0), rng.random_range(-8.0..8.0), rng.random_range(-8.0..8.0));
                    (o, ((a + b + c) / 3.0 - o).normalize())
                })
                .collect();
            let streamed = bvh.closest_hits_stream(&rays, 0.0, f32::INFINITY);
            for (k, (&(o, d), s)) in rays.iter().zip(&streamed).enumerate() {
                let brute = brute_hits_with_margin(&p, o, d, 0.0, f32::INFINITY);
                let got = bvh.closest_hit(o, d, 0.0, f32::INFINITY);
                assert_eq!(hit_bits(got), hit_bits(*s), "{n} triangles, ray {k}: stream");
                // Hits clear of every edge (f32 and f64 agree on them) are found, and none is
                // nearer than the BVH's; the BVH's own hit is one of the brute force's. (Random
                // thin triangles seen at a slant put f32 distances up to ~1e-3 off f64 ones.)
                let clear = |h: &&(f64, usize, f64)| h.2 > 1e-4;
                let near = |t: f64, u: f64| (t - u).abs() < 1e-2 * t.max(1.0);
                match got {
                    None => assert!(!brute.iter().any(|h| clear(&h)), "{n} triangles, ray {k}: missed {brute:?}"),
                    Some(h) => {
                        let t = h.t as f64;
                        assert!(
                            brute.iter().any(|b| near(b.0, t) && p.triangles[b.1] == h.triangle),
                            "{n} triangles, ray {k}: {h:?} not in {brute:?}"
                        );
                        assert!(
                            !brute.iter().filter(clear).any(|b| b.0 < t && !near(b.0, t)),
                            "{n} triangles, ray {k}: {h:?}, nearer in {brute:?}"
                        );
                    }
                }
                let any_clear = brute.iter().any(|h| clear(&h));
                if any_clear || brute.is_empty() {
                    assert_eq!(bvh.occluded(o, d, 0.0, f32::INFINITY), any_clear, "{n} triangles, ray {k}: any hit");
                }
            }
        }
    }

    /// Rays in the plane where coordinate `axis` is 0 (the origin's and the direction's
    /// component exactly 0, so the inverse is infinite and origin × inverse is not a number),
    /// each aimed at a point inside a triangle that straddles that plane.
    fn in_plane_rays(p: &PreparedScene, rng: &mut StdRng) -> Vec<(Vec3, Vec3)> {
        let mut rays = Vec::new();
        for (k, &t) in p.triangles.iter().enumerate() {
            let axis = k % 3;
            let v = p.triangle(t);
            // The two edge points on the plane, where the corners lie on both sides of it.
            let crossings: Vec<Vec3> = [(0, 1), (1, 2), (2, 0)]
                .into_iter()
                .filter(|&(i, j)| (v[i][axis] < 0.0) != (v[j][axis] < 0.0))
                .map(|(i, j)| v[i] + (v[j] - v[i]) * (v[i][axis] / (v[i][axis] - v[j][axis])))
                .collect();
            if crossings.len() != 2 {
                continue;
            }
            let mut target = (crossings[0] + crossings[1]) * 0.5;
            let mut o = target + Vec3::new(rng.random_range(-6.0..6.0), rng.random_range(-6.0..6.0), rng.random_range(-6.0..6.0));
            target[axis] = 0.0;
            o[axis] = 0.0;
            rays.push((o, (target - o).normalize()));
        }
        rays
    }

    fn hit_bits(h: Option<Hit>) -> Option<(u32, TriangleRef, [u32; 3])> {
        h.map(|h| (h.t.to_bits(), h.triangle, h.bary.to_array().map(f32::to_bits)))
    }

    /// Every ray of `rays`, traced in packets of up to 16 (in order), answers bit for bit as
    /// `closest_hit` does; returns the number of hits.
    fn packets_match_single_rays(bvh: &SceneBvh, rays: &[PacketRay], t_min: f32) -> usize {
        let mut hits = 0;
        for (c, chunk) in rays.chunks(PACKET).enumerate() {
            let packet = bvh.closest_hits(chunk, t_min);
            for (i, &(o, d, t_max)) in chunk.iter().enumerate() {
                let single = bvh.closest_hit(o, d, t_min, t_max);
                assert_eq!(hit_bits(packet[i]), hit_bits(single), "packet {c}, ray {i}: {o} {d} {t_max}");
                hits += single.is_some() as usize;
            }
            assert!(packet[chunk.len()..].iter().all(Option::is_none));
        }
        hits
    }

    #[test]
    fn streams_answer_as_single_rays_do() {
        let scene = soup_scene(3000, 11, vec![Material::default()]);
        let p = PreparedScene::new(&scene);
        let bvh = SceneBvh::build(&p);
        let mut rng = StdRng::seed_from_u64(5);
        // Fans of nearby rays (coherent), then random rays with zero components and rays along
        // axes (infinite inverses): more than one stream's worth, so the input is cut.
        let mut rays = Vec::new();
        for _ in 0..200 {
            let (eye, centre, right, up) = fan_frame(&mut rng);
            for j in 0..16 {
                let (x, y) = ((j % 4) as f32 - 1.5, (j / 4) as f32 - 1.5);
                rays.push((eye, (centre + (right * x + up * y) * 0.02).normalize()));
            }
        }
        for k in 0..3000 {
            rays.push(awkward_ray(&mut rng, k));
        }
        // Rays whose box tests cannot be fused (the AVX2 and AVX-512 paths test their boxes
        // the exact way): without that, they would miss everything.
        let in_plane = in_plane_rays(&p, &mut rng);
        let in_plane_hits = bvh.closest_hits_stream(&in_plane, 0.0, f32::INFINITY).iter().flatten().count();
        assert!(in_plane_hits > 100, "too few in-plane rays hit to test anything: {in_plane_hits} of {}", in_plane.len());
        rays.extend(in_plane);
        assert!(rays.len() > STREAM);
        let mut hits = 0;
        for (t_min, t_max) in [(0.0, f32::INFINITY), (0.5, 12.0)] {
            for rays in [&rays[..], &rays[..1], &rays[3200..3210]] {
                let streamed = bvh.closest_hits_stream(rays, t_min, t_max);
                assert_eq!(streamed.len(), rays.len());
                for (k, (&(o, d), &h)) in rays.iter().zip(&streamed).enumerate() {
                    let single = bvh.closest_hit(o, d, t_min, t_max);
                    assert_eq!(hit_bits(h), hit_bits(single), "ray {k}: {o} {d}, t in ({t_min}, {t_max})");
                    hits += usize::from(single.is_some());
                }
            }
        }
        assert!(hits > 3000, "too few hits to test anything: {hits}");
        // No triangles: no hits.
        let empty = SceneBvh::build(&PreparedScene::new(&soup_scene(0, 1, vec![Material::default()])));
        assert!(empty.closest_hits_stream(&rays[..5], 0.0, f32::INFINITY).iter().all(Option::is_none));
    }

    #[test]
    fn packets_answer_as_single_rays_do() {
        let scene = soup_scene(3000, 7, vec![Material::default()]);
        let p = PreparedScene::new(&scene);
        let bvh = SceneBvh::build(&p);
        let mut rng = StdRng::seed_from_u64(21);
        // Coherent: 4×4 fans of rays from one eye (some straddling an axis, so split by
        // octant), with and without a segment end, some unnormalised.
        let mut rays = Vec::new();
        for k in 0..300 {
            let (eye, centre, right, up) = fan_frame(&mut rng);
            let spread = if k % 5 == 0 { 0.3 } else { 0.01 };
            let t_max = if k % 3 == 0 { rng.random_range(2.0..20.0) } else { f32::INFINITY };
            for j in 0..16 {
                let (x, y) = ((j % 4) as f32 - 1.5, (j / 4) as f32 - 1.5);
                let d = centre + (right * x + up * y) * spread;
                let d = if k % 7 == 0 { d * 3.0 } else { d.normalize() };
                rays.push((eye + right * (x * 1e-3), d, t_max));
            }
        }
        let coherent = packets_match_single_rays(&bvh, &rays, 0.0);
        // Incoherent, with directions along axes and zero components (infinite inverses),
        // in packets of every length.
        let mut rays = Vec::new();
        for k in 0..2000 {
            let (o, d) = awkward_ray(&mut rng, k);
            rays.push((o, d, if k % 2 == 0 { f32::INFINITY } else { rng.random_range(1.0..15.0) }));
        }
        let mut incoherent = 0;
        let mut at = 0;
        for len in (1..=PACKET).cycle() {
            if at + len > rays.len() {
                break;
            }
            incoherent += packets_match_single_rays(&bvh, &rays[at..at + len], 0.5);
            at += len;
        }
        assert!(coherent > 1000 && incoherent > 400, "too few hits to test anything: {coherent}, {incoherent}");
    }

    #[test]
    fn ties_go_to_the_lowest_slot_in_packets_and_single_rays() {
        // Overlapping triangles with integer corners in the plane z = 0, among vertical walls:
        // a ray straight down hits every flat triangle over its point at exactly t = 4 (all of
        // Möller–Trumbore's arithmetic is exact there), and the walls (which such rays never
        // hit) raise some leaves' boxes, so the traversal reaches the tied triangles in an order
        // that is not their slots' order.
        let mut rng = StdRng::seed_from_u64(31);
        let mut mesh = Mesh { material: 0, ..Default::default() };
        let corner = |mesh: &mut Mesh, p: Vec3| {
            mesh.positions.push(p);
            mesh.uvs.push(Vec2::ZERO);
            mesh.positions.len() as u32 - 1
        };
        for k in 0..600 {
            let (x, y) = (rng.random_range(0..10) as f32, rng.random_range(0..10) as f32);
            let tri = if k % 3 == 0 {
                let h = rng.random_range(1..4) as f32;
                [Vec3::new(x, y, 0.0), Vec3::new(x + 2.0, y, 0.0), Vec3::new(x + 1.0, y, h)]
            } else {
                let (w, h) = (rng.random_range(1..5) as f32, rng.random_range(1..5) as f32);
                [Vec3::new(x, y, 0.0), Vec3::new(x + w, y, 0.0), Vec3::new(x, y + h, 0.0)]
            };
            let i = tri.map(|p| corner(&mut mesh, p));
            mesh.indices.push(i);
        }
        let mut scene = soup_scene(0, 1, vec![Material::default()]);
        scene.objects[0].meshes = vec![mesh];
        let p = PreparedScene::new(&scene);
        let bvh = SceneBvh::build(&p);
        let rays: Vec<PacketRay> = (0..40 * 40)
            .map(|k| (Vec3::new((k % 40) as f32 * 0.25 + 0.1, (k / 40) as f32 * 0.25 + 0.05, 4.0), Vec3::NEG_Z, f32::INFINITY))
            .collect();
        assert!(packets_match_single_rays(&bvh, &rays, 0.0) > 1000);
        // Where several triangles tie, the one in the lowest slot wins.
        let mut ties = 0;
        for &(o, d, _) in &rays {
            let Some(hit) = bvh.closest_hit(o, d, 0.0, f32::INFINITY) else { continue };
            let r = RayPre::new(Vec3A::from(o), Vec3A::from(d));
            let slots: Vec<usize> = (0..bvh.slot_ref.len())
                .filter(|&s| {
                    let (t, _, _, m) = intersect4_upto(&bvh.packs[s / 4], &r, 0.0, f32::INFINITY);
                    m >> (s % 4) & 1 != 0 && t[s % 4] == hit.t
                })
                .collect();
            ties += (slots.len() > 1) as usize;
            assert_eq!(bvh.slot_ref[slots[0]], hit.triangle, "ray through {o}: slots {slots:?}");
        }
        assert!(ties > 500, "too few ties to test the rule: {ties}");
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

    /// Materials for shadow tests: opaque, half-transparent and non-casting triangles mixed.
    fn shadow_mix() -> Vec<Material> {
        vec![Material::default(), Material { opacity: 0.5, ..Default::default() }, Material { casts_shadows: false, ..Default::default() }]
    }

    #[test]
    fn shadow_cache_never_changes_the_attenuation() {
        let scene = soup_scene(3000, 7, shadow_mix());
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
    fn shadow_streams_attenuate_as_single_rays_do() {
        // Bundles of nearby rays (as a light's shadow rays) and single ones, more than one
        // stream's worth.
        let scene = soup_scene(3000, 13, shadow_mix());
        let p = PreparedScene::new(&scene);
        let bvh = SceneBvh::build(&p);
        let mut rng = StdRng::seed_from_u64(17);
        let mut rays = Vec::new();
        for k in 0..3000 {
            let (o, d) = random_ray(&mut rng);
            let t_max = rng.random_range(2.0..20.0);
            for j in 0..if k % 2 == 0 { 4 } else { 1 } {
                rays.push((o + Vec3::splat(j as f32 * 1e-3), d, t_max));
            }
        }
        // Rays whose box tests cannot be fused (see `streams_answer_as_single_rays_do`).
        let in_plane: Vec<_> = in_plane_rays(&p, &mut rng).into_iter().map(|(o, d)| (o, d, 30.0)).collect();
        let in_plane_blocked = bvh.any_hit_attenuation_stream(&p, &in_plane, None).iter().filter(|&&a| a < 1.0).count();
        assert!(in_plane_blocked > 100, "too few in-plane rays blocked: {in_plane_blocked} of {}", in_plane.len());
        rays.extend(in_plane);
        assert!(rays.len() > STREAM);
        let single: Vec<f32> = rays.iter().map(|&(o, d, t)| bvh.any_hit_attenuation(&p, o, d, t)).collect();
        let (mut blocked, mut partial) = (0, 0);
        for cached in [false, true] {
            // Without a cache (every ray in the stream) and with one carried from call to call
            // (blocked runs one ray at a time), the same attenuations.
            let mut cache = ShadowCache::default();
            let mut streamed = Vec::new();
            for part in rays.chunks(5000) {
                streamed.extend(bvh.any_hit_attenuation_stream(&p, part, cached.then_some(&mut cache)));
            }
            for (k, (&a, &b)) in single.iter().zip(&streamed).enumerate() {
                // Several transparent casters may be multiplied in another order.
                assert!(a == b || (a > 0.0 && (a - b).abs() <= 1e-6 * a), "ray {k}: single {a}, stream {b}");
                blocked += u32::from(a == 0.0);
                partial += u32::from(a > 0.0 && a < 1.0);
            }
        }
        assert!(blocked > 1000 && partial > 300, "too few blocked or partly shadowed rays: {blocked}, {partial}");
        // No triangles: nothing blocks.
        let empty = SceneBvh::build(&PreparedScene::new(&soup_scene(0, 1, vec![Material::default()])));
        assert_eq!(empty.any_hit_attenuation_stream(&p, &rays[..3], None), [1.0; 3]);
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
        let prims: Vec<Prim> = corners.iter().enumerate().map(|(i, c)| triangle_prim(i as u32, *c)).collect();
        let mut packer = Packer { packs: Vec::new(), leaves: 0 };
        let mut nodes = Vec::new();
        // 150 triangles = 38 packs: one extra node over four leaves of ≤ 16 packs.
        let r = packer.leaf(0, &prims, &mut nodes);
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
                    let t = prims[pos as usize].index();
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
}
