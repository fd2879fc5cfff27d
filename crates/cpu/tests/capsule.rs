//! The RT-scene capsule and the depth merge's blocks D, P, U (paper 2, design §5).

use glam::{DMat4, DVec3, DVec4, Vec3};
use hybrid_core::depth_merge::{
    PackedRtFrame, alpha_kept, decode_texel, encode_hit, pack_texel, pack_unorm4x8, unpack, unpack_texel, unpack_unorm4x8,
};
use hybrid_cpu::camera_rays::RayGen;
use hybrid_cpu::capsule::{CapsuleRequest, PointCloudCapsule, PrimaryVisibility, RtCapsule, render_sync};
use hybrid_cpu::spheres::{SphereBvh, closest_hit_brute_force};
use hybrid_scene::texture::linear_to_srgb;
use hybrid_scene::{Camera, DirectionalLight, Environment, Lights, PointCloud, PointColoring, Projection};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

#[path = "support/exchange.rs"]
mod exchange;
use exchange::{ExchangeError, ExchangeState, FrameExchange, OwnedCapsuleRequest};

const TREE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/assets/tree-pointcloud/rtls_pc_tree.ply");

// ---------------------------------------------------------------- block P / U

#[test]
fn pack_unpack_is_bit_exact_on_random_and_edge_values() {
    let mut rng = StdRng::seed_from_u64(7);
    let edge = [
        0.0f32,
        -0.0,
        1.0,
        f32::from_bits(1.0f32.to_bits() - 1), // the largest depth < 1
        f32::from_bits(1),                    // smallest subnormal
        f32::from_bits(0x007F_FFFF),          // largest subnormal
        f32::MIN_POSITIVE,
        0.5,
        1e-30,
    ];
    let check = |rgba: [u8; 4], depth: f32| {
        let t = pack_texel(rgba, depth);
        let (c, d) = unpack_texel(t);
        assert_eq!(c, rgba);
        assert_eq!(d.to_bits(), depth.to_bits(), "{depth:e}");
    };
    for d in edge {
        for c in [[0, 0, 0, 0], [255, 255, 255, 255], [1, 2, 3, 4], [255, 0, 255, 0]] {
            check(c, d);
        }
    }
    for _ in 0..100_000 {
        let c: [u8; 4] = rng.random();
        // Any bit pattern round-trips, NaN payloads included.
        check(c, f32::from_bits(rng.random()));
        check(c, rng.random::<f32>());
    }
    // Colour words: pack(unpack(A)) == A for random words.
    for _ in 0..10_000 {
        let a: u32 = rng.random();
        assert_eq!(pack_unorm4x8(unpack_unorm4x8(a)), a);
    }
}

#[test]
fn alpha_at_most_one_tenth_is_discarded() {
    assert!(!alpha_kept(0.1));
    assert!(alpha_kept(f32::from_bits(0.1f32.to_bits() + 1)));
    // In 8 bits: 25/255 = 0.098 is discarded, the next value 26/255 = 0.102 is kept. Packing
    // alpha 0.1 rounds to 26 (25.5 rounds up), so it is kept.
    let texel = |a: u8| pack_texel([200, 100, 50, a], 0.5);
    assert_eq!(decode_texel(texel(25)), None);
    assert!(decode_texel(texel(26)).is_some());
    assert_eq!(pack_unorm4x8([0.0, 0.0, 0.0, 0.1]) >> 24, 26);
    assert_eq!(decode_texel(texel(0)), None);
    // Unpacked layer: discarded → depth 0 and black; kept → its depth.
    let frame = PackedRtFrame { width: 2, height: 1, texels: vec![texel(25), texel(26)] };
    let layer = unpack(&frame);
    assert_eq!(layer.depth, vec![0.0, 0.5]);
    assert_eq!(layer.color[0], Vec3::ZERO);
    assert!(layer.color[1].x > 0.5);
}

#[test]
fn colour_is_packed_srgb_and_decoded_to_linear() {
    // A dark linear value keeps several distinct 8-bit codes in sRGB (it would be 0 or 1 in linear).
    let (rgba, _) = unpack_texel(encode_hit(Vec3::new(0.001, 0.002, 0.003), 0.7));
    assert!(rgba[0] >= 3 && rgba[0] < rgba[1] && rgba[1] < rgba[2], "{rgba:?}");
    assert_eq!(rgba[3], 255);
    // Decoding is within half an 8-bit step of the value, measured in sRGB.
    for v in [0.0f32, 0.001, 0.05, 0.18, 0.5, 0.9, 1.0] {
        let (c, d) = decode_texel(encode_hit(Vec3::splat(v), 0.7)).unwrap();
        assert_eq!(d, 0.7);
        assert!((linear_to_srgb(c.x) - linear_to_srgb(v)).abs() <= 0.5 / 255.0 + 1e-6, "{v} → {}", c.x);
    }
}

// ---------------------------------------------------------------- block D

fn perspective_camera() -> Camera {
    Camera {
        position: Vec3::new(1.0, 2.0, 3.0),
        target: Vec3::new(0.0, 0.5, -4.0),
        up: Vec3::Y,
        projection: Projection::Perspective { fov_y_deg: 60.0, near: 0.1, far: 100.0 },
    }
}

/// The camera's view matrix in f64 (the f32 one rounds its translation to ~1e-7 of the camera's
/// distance from the origin, which is 2e-5 of a 1 cm near distance).
fn view_f64(camera: &Camera) -> DMat4 {
    let (eye, up) = (camera.position.as_dvec3(), camera.up.as_dvec3());
    let f = (camera.target.as_dvec3() - eye).normalize();
    let s = f.cross(up).normalize();
    let u = s.cross(f);
    DMat4::from_cols(
        DVec4::new(s.x, u.x, -f.x, 0.0),
        DVec4::new(s.y, u.y, -f.y, 0.0),
        DVec4::new(s.z, u.z, -f.z, 0.0),
        DVec4::new(-s.dot(eye), -u.dot(eye), f.dot(eye), 1.0),
    )
}

/// Projects `p` with the camera's view-projection (in f64): the raster's depth of the point.
fn raster_depth(camera: &Camera, aspect: f32, p: DVec3) -> f64 {
    let m = camera.projection(aspect).as_dmat4() * view_f64(camera);
    let c = m * DVec4::new(p.x, p.y, p.z, 1.0);
    c.z / c.w
}

/// Block D against projection at the image centre and four corners, at the near end, the middle
/// and the far end of each ray. Relative error ≤ 1e-6 in depth; at the far end, where depth → 0
/// and its relative error is amplified by f/(f + z_e) for any f32 evaluation (the raster's
/// matrix path included), the same 1e-6 is asked of the view-space distance the depth encodes.
fn check_depth_synthesis(camera: Camera, w: u32, h: u32) {
    let raygen = RayGen::new(&camera, w, h);
    let aspect = w as f32 / h as f32;
    let (n, f) = camera.near_far();
    let view = view_f64(&camera);
    for (col, row) in [(w / 2, h / 2), (0, 0), (w - 1, 0), (0, h - 1), (w - 1, h - 1)] {
        let ray = raygen.ray(col, row);
        // The ray goes through the pixel centre.
        let mid = ray.origin + ray.dir * (0.5 * (ray.t_min + ray.t_max));
        let ndc = camera.view_projection(aspect).project_point3(mid);
        let px = (ndc.x + 1.0) * 0.5 * w as f32;
        let py = (1.0 - ndc.y) * 0.5 * h as f32;
        assert!((px - (col as f32 + 0.5)).abs() < 1e-3 && (py - (row as f32 + 0.5)).abs() < 1e-3, "{px},{py}");
        for (label, t) in [("near", ray.t_min * 1.0001), ("mid", ray.t_min + 0.3 * (ray.t_max - ray.t_min)), ("far", ray.t_max * 0.999)] {
            let synth = raygen.depth(&ray, t) as f64;
            let p = ray.origin.as_dvec3() + ray.dir.as_dvec3() * t as f64;
            let reference = raster_depth(&camera, aspect, p);
            assert!((0.0..=1.0).contains(&reference), "{label}: {reference}");
            let rel = (synth - reference).abs() / reference.abs();
            if label != "far" {
                assert!(rel <= 1e-6, "pixel ({col},{row}) {label}: synth {synth} vs raster {reference} (rel {rel:e})");
            } else {
                // Compare the encoded view-space distance.
                let (n, f) = (n as f64, f as f64);
                let z_of = |zw: f64| {
                    if camera.is_orthographic() { zw * (f - n) - f } else { -n * f / ((f - n) * zw + n) }
                };
                let z_ref = (view * p.extend(1.0)).z;
                let rel_z = (z_of(synth) - z_ref).abs() / z_ref.abs();
                assert!(rel_z <= 1e-6, "pixel ({col},{row}) far: z {} vs {z_ref} (rel {rel_z:e})", z_of(synth));
                assert!(rel <= 1e-3, "far depth {synth} vs {reference}");
            }
        }
        // The ends of the frustum map to 1 and 0.
        assert!((raygen.depth(&ray, ray.t_min) - 1.0).abs() < 1e-5);
        assert!(raygen.depth(&ray, ray.t_max).abs() < 1e-5);
        // Inverse.
        let t = ray.t_min + 0.2 * (ray.t_max - ray.t_min);
        assert!((raygen.t_at_depth(&ray, raygen.depth(&ray, t)) - t).abs() <= 1e-4 * t);
    }
}

#[test]
fn synthesized_depth_equals_raster_projection_perspective() {
    check_depth_synthesis(perspective_camera(), 160, 90);
    check_depth_synthesis(
        Camera { projection: Projection::Perspective { fov_y_deg: 100.0, near: 0.01, far: 10_000.0 }, ..perspective_camera() },
        97,
        31,
    );
}

#[test]
fn synthesized_depth_equals_raster_projection_orthographic() {
    check_depth_synthesis(
        Camera { projection: Projection::Orthographic { height: 6.0, near: 0.5, far: 40.0 }, ..perspective_camera() },
        160,
        90,
    );
}

// ---------------------------------------------------------------- sphere BVH

#[test]
fn sphere_bvh_equals_brute_force() {
    let mut rng = StdRng::seed_from_u64(42);
    for (n, radius) in [(3000usize, 0.05f32), (2000, 0.002), (50, 0.3), (4, 0.5)] {
        let mut centers: Vec<Vec3> =
            (0..n).map(|_| Vec3::new(rng.random_range(-5.0..5.0), rng.random_range(-5.0..5.0), rng.random_range(-5.0..5.0))).collect();
        // Tiny spheres far away (a few hundred units) in a cluster, and duplicates.
        for c in centers.iter_mut().take(n / 10) {
            *c = Vec3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), 400.0 + rng.random_range(-1.0..1.0));
        }
        if n > 20 {
            centers[11] = centers[10];
        }
        let bvh = SphereBvh::build(&centers, radius).unwrap();
        assert_eq!(bvh.len(), n);
        let mut hits = 0;
        for k in 0..3000 {
            let origin = Vec3::new(rng.random_range(-8.0..8.0), rng.random_range(-8.0..8.0), rng.random_range(-8.0..-6.0));
            // Aim at a random sphere (slightly off centre) most of the time, so rays hit.
            let target = if k % 4 == 0 {
                Vec3::new(rng.random_range(-5.0..5.0), rng.random_range(-5.0..5.0), rng.random_range(-5.0..5.0))
            } else {
                centers[rng.random_range(0..n)] + Vec3::new(rng.random(), rng.random(), rng.random()) * radius * 0.9
            };
            let dir = (target - origin) * rng.random_range(0.5..3.0);
            let (t_min, t_max) = if k % 7 == 0 { (1.0, 2.0) } else { (0.0, f32::INFINITY) };
            let got = bvh.closest_hit(origin, dir, t_min, t_max);
            let want = closest_hit_brute_force(&centers, radius, origin, dir, t_min, t_max);
            assert_eq!(got, want, "n {n} r {radius} ray {k}: {origin} {dir}");
            hits += got.is_some() as usize;
        }
        assert!(hits > 1000, "too few hits to test anything: {hits}");
    }
}

#[test]
fn sphere_bvh_is_compact() {
    let mut rng = StdRng::seed_from_u64(3);
    let centers: Vec<Vec3> = (0..100_000).map(|_| Vec3::new(rng.random(), rng.random(), rng.random()) * 10.0).collect();
    let bvh = SphereBvh::build(&centers, 0.01).unwrap();
    let per_point = bvh.bytes() as f64 / centers.len() as f64;
    assert!(per_point <= 64.0, "{per_point} B/point");
}

// ---------------------------------------------------------------- the capsule

fn lights() -> Lights {
    Lights {
        directional: vec![DirectionalLight {
            direction: Vec3::new(-0.3, -1.0, -0.4).normalize(),
            color: Vec3::ONE,
            intensity: 2.0,
            casts_shadows: false,
        }],
        point: vec![],
        spot: vec![],
    }
}

fn cloud(points: Vec<Vec3>, radius: f32, coloring: PointColoring) -> PointCloud {
    PointCloud {
        name: "test".into(),
        source: "synthetic".into(),
        points,
        colors: vec![],
        radius,
        coloring,
        specular: Vec3::splat(0.1),
        shininess: 0.3,
    }
}

/// The single-tree scan, Z-up → Y-up, or (if the scene loader cannot read PLY point clouds yet)
/// a synthetic tree-like cloud; says which.
fn tree_points() -> Vec<Vec3> {
    match hybrid_scene::load::load_point_cloud(std::path::Path::new(TREE)) {
        Ok((points, _)) if !points.is_empty() => {
            eprintln!("tree: {} points from {TREE}", points.len());
            points.into_iter().map(|p| Vec3::new(p.x, p.z, -p.y)).collect()
        }
        other => {
            eprintln!("tree: loader unavailable ({:?}); using a synthetic cloud", other.err().map(|e| e.to_string()));
            let mut rng = StdRng::seed_from_u64(1);
            (0..75_848)
                .map(|i| {
                    if i % 4 == 0 {
                        // Trunk.
                        let a: f32 = rng.random_range(0.0..std::f32::consts::TAU);
                        Vec3::new(0.15 * a.cos(), rng.random_range(0.0..3.0), 0.15 * a.sin())
                    } else {
                        // Crown: a ball.
                        let v = Vec3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
                        v.normalize_or_zero() * 1.8 * rng.random::<f32>().cbrt() + Vec3::new(0.0, 4.0, 0.0)
                    }
                })
                .collect()
        }
    }
}

fn framing_camera(points: &[Vec3]) -> Camera {
    let (lo, hi) = points.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(a, b), p| (a.min(*p), b.max(*p)));
    let c = 0.5 * (lo + hi);
    let size = (hi - lo).max_element();
    Camera {
        position: c + Vec3::new(0.3, 0.2, 1.0).normalize() * size * 1.4,
        target: c,
        up: Vec3::Y,
        projection: Projection::Perspective { fov_y_deg: 50.0, near: 0.05, far: size * 4.0 },
    }
}

#[test]
fn tree_scan_renders_merges_and_clips() {
    let points = tree_points();
    let camera = framing_camera(&points);
    let mut capsule = PointCloudCapsule::new(&[cloud(points, 0.01, PointColoring::Height)], lights(), Environment::default()).unwrap();
    let (w, h) = (160u32, 90u32);
    let (frame, stats) = render_sync(&mut capsule, &CapsuleRequest { camera, width: w, height: h, clip_depth: None });
    assert_eq!(stats.rays, (w * h) as u64);
    assert!(stats.hits > (w * h) as u64 / 20 && stats.hits < (w * h) as u64, "hits {}", stats.hits);
    assert!(stats.bytes as f64 / stats.points as f64 <= 64.0);
    let layer = unpack(&frame);
    let covered = layer.depth.iter().filter(|d| **d > 0.0).count();
    assert_eq!(covered as u64, stats.hits);
    assert!(layer.depth.iter().all(|d| (0.0..=1.0).contains(d)));
    // Height colour map: the top third of the covered pixels is greener than the bottom third.
    let mean_green = |rows: std::ops::Range<u32>| {
        let (mut s, mut k) = (0.0, 0);
        for r in rows {
            for c in 0..w {
                let i = (r * w + c) as usize;
                if layer.depth[i] > 0.0 {
                    s += layer.color[i].y / layer.color[i].element_sum().max(1e-6);
                    k += 1;
                }
            }
        }
        s / k.max(1) as f32
    };
    assert!(mean_green(0..h / 3) > mean_green(2 * h / 3..h), "top should be greener than bottom");

    // A wall (constant raster depth) in front of the left half: clipping stops rays at it.
    let mut clip = vec![0.0f32; (w * h) as usize];
    let wall = {
        let mut d: Vec<f32> = layer.depth.iter().copied().filter(|d| *d > 0.0).collect();
        d.sort_by(f32::total_cmp);
        d[d.len() / 2] // half of the tree's pixels are in front of the wall
    };
    for r in 0..h {
        for c in 0..w / 2 {
            clip[(r * w + c) as usize] = wall;
        }
    }
    let (clipped, clipped_stats) = render_sync(&mut capsule, &CapsuleRequest { camera, width: w, height: h, clip_depth: Some(&clip) });
    assert!(clipped_stats.hits < stats.hits);
    let (mut same, mut removed) = (0, 0);
    for (i, &wall_here) in clip.iter().enumerate() {
        let full = decode_texel(frame.texels[i]);
        let cut = decode_texel(clipped.texels[i]);
        match full {
            Some((_, d)) if wall_here > 0.0 && d < wall * (1.0 - 1e-4) => {
                // Behind the wall: the unclipped closest hit is behind it, so nothing is in front.
                assert_eq!(cut, None, "pixel {i}: behind the wall but still traced");
                removed += 1;
            }
            Some((_, d)) if wall_here > 0.0 && d <= wall * (1.0 + 1e-4) => {} // at the wall: either
            _ => {
                assert_eq!(clipped.texels[i], frame.texels[i], "pixel {i}: clipping changed a visible pixel");
                same += 1;
            }
        }
    }
    assert!(removed > 0 && same > 0);
}

#[test]
fn single_sphere_pixel_depth_and_colour() {
    // One sphere straight ahead: the centre pixel sees its front point at distance 5 − r.
    let camera = Camera {
        position: Vec3::ZERO,
        target: Vec3::NEG_Z,
        up: Vec3::Y,
        projection: Projection::Perspective { fov_y_deg: 40.0, near: 0.5, far: 50.0 },
    };
    let red = Vec3::new(0.6, 0.05, 0.05);
    let mut capsule = PointCloudCapsule::new(
        &[cloud(vec![Vec3::new(0.0, 0.0, -5.0)], 0.5, PointColoring::Uniform(red))],
        Lights::default(),
        Environment { ambient: Vec3::ONE, ..Environment::default() },
    )
    .unwrap();
    let (frame, stats) = render_sync(&mut capsule, &CapsuleRequest { camera, width: 31, height: 31, clip_depth: None });
    assert!(stats.hits > 10);
    let (c, d) = decode_texel(frame.texels[15 * 31 + 15]).unwrap();
    let (n, f) = (0.5f32, 50.0f32);
    let expected = n * f / ((f - n) * 4.5) - n / (f - n);
    assert!((d - expected).abs() <= 1e-6 * expected, "{d} vs {expected}");
    // Ambient only (env ambient 1 × albedo), within 8-bit sRGB quantisation.
    assert!((c - red).abs().max_element() < 0.01, "{c}");
    // Corner pixels miss.
    assert_eq!(frame.texels[0], [0; 4]);
}

#[test]
fn multiple_clouds_closest_wins() {
    let camera = Camera {
        position: Vec3::ZERO,
        target: Vec3::NEG_Z,
        up: Vec3::Y,
        projection: Projection::Perspective { fov_y_deg: 40.0, near: 0.5, far: 50.0 },
    };
    let near = cloud(vec![Vec3::new(0.0, 0.0, -5.0)], 0.2, PointColoring::Uniform(Vec3::new(0.0, 0.5, 0.0)));
    let far = cloud(vec![Vec3::new(0.0, 0.0, -8.0)], 1.5, PointColoring::Uniform(Vec3::new(0.5, 0.0, 0.0)));
    let env = Environment { ambient: Vec3::ONE, ..Environment::default() };
    for clouds in [[near.clone(), far.clone()], [far, near]] {
        let mut capsule = PointCloudCapsule::new(&clouds, Lights::default(), env.clone()).unwrap();
        let (frame, _) = render_sync(&mut capsule, &CapsuleRequest { camera, width: 21, height: 21, clip_depth: None });
        let (c, _) = decode_texel(frame.texels[10 * 21 + 10]).unwrap();
        assert!(c.y > 0.4 && c.x < 0.01, "the near green sphere must win: {c}");
    }
}

#[test]
fn deterministic_across_thread_counts() {
    let points = tree_points();
    let camera = framing_camera(&points);
    let pc = cloud(points, 0.012, PointColoring::Height);
    let render = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let mut capsule = PointCloudCapsule::new(std::slice::from_ref(&pc), lights(), Environment::default()).unwrap();
            render_sync(&mut capsule, &CapsuleRequest { camera, width: 120, height: 80, clip_depth: None }).0
        })
    };
    let one = render(1);
    let two = render(2);
    assert!(one.texels.iter().any(|t| t[1] != 0));
    assert!(one == two, "packed frames differ between 1 and 2 threads");
}

#[test]
fn handshake_exchange_matches_sync_and_checks_order() {
    let points: Vec<Vec3> = (0..400).map(|i| Vec3::new((i % 20) as f32 * 0.1 - 1.0, (i / 20) as f32 * 0.1 - 1.0, -3.0)).collect();
    let pc = cloud(points, 0.04, PointColoring::Height);
    let camera = Camera { position: Vec3::new(0.0, 0.0, 1.0), target: Vec3::new(0.0, 0.0, -3.0), ..Camera::default() };
    let mut sync_capsule = PointCloudCapsule::new(std::slice::from_ref(&pc), lights(), Environment::default()).unwrap();
    let (want, _) = render_sync(&mut sync_capsule, &CapsuleRequest { camera, width: 64, height: 48, clip_depth: None });
    assert!(want.texels.iter().any(|t| *t != [0; 4]));

    let capsule: Box<dyn RtCapsule> = Box::new(PointCloudCapsule::new(&[pc], lights(), Environment::default()).unwrap());
    let mut exchange = FrameExchange::spawn(capsule).unwrap();
    assert_eq!(exchange.wait_capsule_finished().err(), Some(ExchangeError::OutOfOrder(ExchangeState::HostOwnsFrame)));
    for _frame in 0..3 {
        // Host finished (S1) → capsule renders → capsule finished (S2) → host merges.
        exchange.host_finished(OwnedCapsuleRequest { camera, width: 64, height: 48, clip_depth: None }).unwrap();
        assert_eq!(exchange.state(), ExchangeState::CapsuleRendering);
        let again = exchange.host_finished(OwnedCapsuleRequest { camera, width: 64, height: 48, clip_depth: None });
        assert_eq!(again.err(), Some(ExchangeError::OutOfOrder(ExchangeState::CapsuleRendering)));
        let (frame, stats) = exchange.wait_capsule_finished().unwrap();
        assert_eq!(exchange.state(), ExchangeState::HostOwnsFrame);
        assert_eq!(stats.rays, 64 * 48);
        assert!(frame == want);
        exchange.recycle(frame);
    }
}

/// Both ways of finding a primary ray's sphere give the same packed frame, bit for bit: the tree
/// scan from outside, from inside the crown (spheres beside, behind and across the near plane),
/// clipped by a raster depth, orthographic, and two overlapping clouds of different radii sharing
/// points (ties keep the earlier cloud, and within a cloud the lower index).
#[test]
fn projected_and_bvh_primary_visibility_give_identical_frames() {
    let points = tree_points();
    let outside = framing_camera(&points);
    let (lo, hi) = points.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(a, b), p| (a.min(*p), b.max(*p)));
    let centre = 0.5 * (lo + hi);
    let inside = Camera {
        position: centre + Vec3::new(0.05, 0.3, 0.02),
        target: centre + Vec3::new(1.0, 0.2, -1.0),
        up: Vec3::Y,
        projection: Projection::Perspective { fov_y_deg: 90.0, near: 0.01, far: 100.0 },
    };
    let ortho = Camera { projection: Projection::Orthographic { height: (hi - lo).max_element(), near: 0.1, far: 100.0 }, ..outside };
    let mut rng = StdRng::seed_from_u64(7);
    let shared: Vec<Vec3> = points.iter().step_by(7).copied().collect();
    let mut other: Vec<Vec3> = shared.iter().map(|p| *p + Vec3::new(rng.random_range(-0.02..0.02), 0.0, 0.0)).collect();
    other.extend(shared.iter().take(500));
    let one = [cloud(points.clone(), 0.012, PointColoring::Height)];
    let two = [cloud(shared, 0.02, PointColoring::Uniform(Vec3::new(0.6, 0.2, 0.1))), cloud(other, 0.02, PointColoring::Height)];
    let (w, h) = (150u32, 97u32);
    // A raster depth over the left half: a wall at the cloud's centre distance.
    let (n, f) = outside.near_far();
    let wall = hybrid_core::depth_merge::synthesize_depth(outside.position.distance(centre), -1.0, n, f);
    let clip: Vec<f32> = (0..w * h).map(|i| if i % w < w / 2 { wall } else { 0.0 }).collect();
    /// Name, clouds, camera, raster depth to clip at.
    type Case<'a> = (&'a str, &'a [PointCloud], Camera, Option<&'a [f32]>);
    let cases: [Case; 5] = [
        ("outside", &one, outside, None),
        ("inside", &one, inside, None),
        ("clipped", &one, outside, Some(&clip)),
        ("orthographic", &one, ortho, None),
        ("two clouds", &two, outside, None),
    ];
    for (name, clouds, camera, clip_depth) in cases {
        let mut capsule = PointCloudCapsule::new(clouds, lights(), Environment::default()).unwrap();
        let request = CapsuleRequest { camera, width: w, height: h, clip_depth };
        capsule.primary_visibility = PrimaryVisibility::Projected;
        let (projected, stats) = render_sync(&mut capsule, &request);
        capsule.primary_visibility = PrimaryVisibility::Bvh;
        let (bvh, bvh_stats) = render_sync(&mut capsule, &request);
        assert!(stats.hits > 100, "{name}: only {} hits", stats.hits);
        assert_eq!(stats.hits, bvh_stats.hits, "{name}: hit counts");
        let differ = projected.texels.iter().zip(&bvh.texels).filter(|(a, b)| a != b).count();
        assert_eq!(differ, 0, "{name}: {differ} texels differ");
    }
    // Tiny and odd sizes (one pixel, a band shorter than 8 rows, a row shorter than 4 pixels),
    // the same frames both ways.
    for (w, h) in [(1, 1), (3, 2), (5, 9), (17, 1)] {
        let mut capsule = PointCloudCapsule::new(&one, lights(), Environment::default()).unwrap();
        let request = CapsuleRequest { camera: framing_camera(&points), width: w, height: h, clip_depth: None };
        capsule.primary_visibility = PrimaryVisibility::Projected;
        let (projected, _) = render_sync(&mut capsule, &request);
        capsule.primary_visibility = PrimaryVisibility::Bvh;
        let (bvh, _) = render_sync(&mut capsule, &request);
        assert!(projected == bvh, "{w}×{h}: frames differ");
    }
}

#[test]
fn auto_visibility_projects_up_to_two_points_per_pixel() {
    let points: Vec<Vec3> = (0..2000).map(|i| Vec3::new((i % 50) as f32 * 0.1, (i / 50) as f32 * 0.1, -3.0)).collect();
    let mut capsule = PointCloudCapsule::new(&[cloud(points, 0.02, PointColoring::Height)], lights(), Environment::default()).unwrap();
    assert_eq!(capsule.primary_visibility, PrimaryVisibility::Auto);
    // 2000 points: 1000 pixels or more project, fewer traverse.
    assert_eq!(capsule.resolved_visibility(40, 25), PrimaryVisibility::Projected);
    assert_eq!(capsule.resolved_visibility(40, 24), PrimaryVisibility::Bvh);
    capsule.primary_visibility = PrimaryVisibility::Projected;
    assert_eq!(capsule.resolved_visibility(4, 4), PrimaryVisibility::Projected);
    // Wider than the bins address: traversal whatever is asked.
    assert_eq!(capsule.resolved_visibility(70_000, 1), PrimaryVisibility::Bvh);
    capsule.primary_visibility = PrimaryVisibility::Bvh;
    assert_eq!(capsule.resolved_visibility(4000, 4000), PrimaryVisibility::Bvh);
}
