//! Paper 2 on the GPU against the CPU oracle: the capsule's packed RT frame (texel-exact where both
//! backends hit the same sphere) and block U's G-buffer (against `depth_merge::unpack` +
//! `raster::merge_rt_layer` into a cleared G-buffer). Needs a wgpu adapter (lavapipe in CI) and
//! fails without one.

use std::path::Path;
use std::time::Instant;

use glam::Vec3;
use hybrid_core::GBuffer;
use hybrid_core::PreparedScene;
use hybrid_core::depth_merge::{PackedRtFrame, unpack, unpack_texel};
use hybrid_cpu::camera_rays::RayGen;
use hybrid_cpu::capsule::{CapsuleRequest, PointCloudCapsule, render_sync};
use hybrid_cpu::depth_merge::merge_rt_layer;
use hybrid_cpu::spheres::SphereBvh;
use hybrid_gpu::GpuContext;
use hybrid_gpu::capsule::GpuCapsule;
use hybrid_gpu::readback::{read_gbuffer, read_packed};
use hybrid_gpu::scene::SceneGpu;
use hybrid_gpu::spheres::SpheresGpu;
use hybrid_gpu::targets::FrameTargets;
use hybrid_gpu::timing::StageTimer;
use hybrid_scene::{Attenuation, Camera, DirectionalLight, PointCloud, PointColoring, PointLight, Projection, Scene};

mod support;
use support::context;

/// What the GPU made of one frame.
struct GpuFrame {
    packed: PackedRtFrame,
    hit_ids: Vec<u32>,
    gbuffer: GBuffer,
}

fn render_gpu(ctx: &GpuContext, scene: &Scene, camera: &Camera, w: u32, h: u32) -> GpuFrame {
    let prepared = PreparedScene::new(scene);
    let scene_gpu = SceneGpu::new(ctx, &prepared).expect("scene upload");
    let t = Instant::now();
    let spheres = SpheresGpu::new(ctx, &scene.point_clouds).expect("spheres");
    eprintln!(
        "gpu spheres: {} spheres, {} nodes, depth {}, build {:.0} ms (+ upload: {:.0} ms in all), {:.1} MiB",
        spheres.count,
        spheres.node_count,
        spheres.depth,
        spheres.build_ms,
        t.elapsed().as_secs_f64() * 1e3,
        spheres.bytes as f64 / (1 << 20) as f64
    );
    let capsule = GpuCapsule::new(ctx, &scene_gpu, &spheres);
    let targets = FrameTargets::new(&ctx.device, w, h);
    scene_gpu.write_uniforms(ctx, camera, w, h, &scene.environment);
    let mut timer = StageTimer::new(ctx);
    timer.begin_frame();
    let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("test") });
    capsule.encode(&mut encoder, &scene_gpu, &spheres, &targets, false, &mut timer);
    capsule.encode_unpack(&mut encoder, &scene_gpu, &targets, true, &mut timer);
    timer.resolve(&mut encoder);
    let t = Instant::now();
    ctx.queue.submit([encoder.finish()]);
    ctx.wait().unwrap();
    eprintln!("gpu capsule + unpack: {:.0} ms wall", t.elapsed().as_secs_f64() * 1e3);
    if let Some(times) = timer.read(ctx).unwrap() {
        eprintln!("gpu timestamps: capsule stage {:.2} ms", times.capsule);
    }
    let report = capsule.report();
    assert_eq!(report.points, scene.point_clouds.iter().map(|c| c.points.len() as u64).sum::<u64>());
    assert_eq!(report.rays, w as u64 * h as u64);
    GpuFrame {
        packed: read_packed(ctx, &targets).unwrap(),
        hit_ids: capsule.read_hit_ids(ctx).unwrap(),
        gbuffer: read_gbuffer(ctx, &targets).unwrap(),
    }
}

/// The CPU capsule's frame and, per pixel, the global id of the sphere it shows (clouds in
/// order, ids offset by the earlier clouds' sizes; u32::MAX: miss), found with the CPU's own
/// sphere BVH and the capsule's rays and closest-over-clouds rule.
fn render_cpu(scene: &Scene, camera: &Camera, w: u32, h: u32) -> (PackedRtFrame, Vec<u32>) {
    let t = Instant::now();
    let mut capsule = PointCloudCapsule::new(&scene.point_clouds, scene.lights.clone(), scene.environment.clone()).unwrap();
    let (frame, _) = render_sync(&mut capsule, &CapsuleRequest { camera: *camera, width: w, height: h, clip_depth: None });
    eprintln!("cpu capsule (build + render): {:.0} ms", t.elapsed().as_secs_f64() * 1e3);
    let bvhs: Vec<SphereBvh> = scene.point_clouds.iter().map(|c| SphereBvh::build(&c.points, c.radius).unwrap()).collect();
    let mut offsets = vec![0u32];
    for c in &scene.point_clouds {
        offsets.push(offsets.last().unwrap() + c.points.len() as u32);
    }
    let raygen = RayGen::new(camera, w, h);
    let mut ids = Vec::with_capacity((w * h) as usize);
    for row in 0..h {
        for col in 0..w {
            let ray = raygen.ray(col, row);
            let mut best: Option<(f32, u32)> = None;
            let mut limit = ray.t_max;
            for (ci, bvh) in bvhs.iter().enumerate() {
                if let Some((t, i)) = bvh.closest_hit(ray.origin, ray.dir, ray.t_min, limit)
                    && best.is_none_or(|b| t < b.0)
                {
                    best = Some((t, offsets[ci] + i));
                    limit = t;
                }
            }
            ids.push(best.map_or(u32::MAX, |b| b.1));
        }
    }
    (frame, ids)
}

#[derive(Debug, Default)]
struct PackedDiff {
    pixels: usize,
    same_sphere: usize,
    /// Same sphere, texel bit-identical.
    exact: usize,
    /// Same sphere: colour bytes differ / depth bits differ (largest difference).
    color_diff: usize,
    max_color_diff: i32,
    depth_diff: usize,
    max_depth_ulps: i64,
    different_sphere: usize,
    gpu_only: usize,
    cpu_only: usize,
}

fn compare_packed(gpu: &GpuFrame, cpu: &PackedRtFrame, cpu_ids: &[u32]) -> PackedDiff {
    let mut d = PackedDiff { pixels: cpu.texels.len(), ..Default::default() };
    assert_eq!(gpu.packed.texels.len(), cpu.texels.len());
    for (i, (&c, &cid)) in cpu.texels.iter().zip(cpu_ids).enumerate() {
        let (g, gid) = (gpu.packed.texels[i], gpu.hit_ids[i]);
        // The hit ids agree with the texels: a miss is all zero, a hit has alpha 255.
        assert_eq!(gid == u32::MAX, g == [0; 4], "pixel {i}: gpu id {gid} texel {g:?}");
        assert_eq!(cid == u32::MAX, c == [0; 4], "pixel {i}: cpu id {cid} texel {c:?}");
        match (gid == u32::MAX, cid == u32::MAX) {
            (true, true) => {}
            (false, true) => d.gpu_only += 1,
            (true, false) => d.cpu_only += 1,
            (false, false) if gid != cid => d.different_sphere += 1,
            (false, false) => {
                d.same_sphere += 1;
                if g == c {
                    d.exact += 1;
                    continue;
                }
                let ((gc, gz), (cc, cz)) = (unpack_texel(g), unpack_texel(c));
                if gc != cc {
                    d.color_diff += 1;
                    let m = (0..4).map(|k| (gc[k] as i32 - cc[k] as i32).abs()).max().unwrap();
                    d.max_color_diff = d.max_color_diff.max(m);
                }
                if gz.to_bits() != cz.to_bits() {
                    d.depth_diff += 1;
                    d.max_depth_ulps = d.max_depth_ulps.max((gz.to_bits() as i64 - cz.to_bits() as i64).abs());
                }
            }
        }
    }
    d
}

/// The unpacked G-buffer against the CPU's block U + merge into a cleared G-buffer, both from
/// the GPU's packed frame (so block U is compared on its own).
fn check_unpack(gpu: &GpuFrame, camera: &Camera) {
    let (w, h) = (gpu.packed.width, gpu.packed.height);
    let mut cpu = GBuffer::new(w, h);
    merge_rt_layer(&mut cpu, &unpack(&gpu.packed), camera);
    let g = &gpu.gbuffer;
    let ids_differ = g.object_id.iter().zip(&cpu.object_id).filter(|(a, b)| a != b).count();
    let depth_differ = g.depth.iter().zip(&cpu.depth).filter(|(a, b)| a.to_bits() != b.to_bits()).count();
    let rt_pixels = cpu.object_id.iter().filter(|&&id| id != u32::MAX).count();
    let mut max_emission = 0f32;
    let mut max_position = 0f32;
    let mut max_normal = 0f32;
    let mut other = 0usize;
    for i in 0..g.len() {
        // Rgba16Float targets: half precision (11-bit mantissa) relative error.
        max_emission =
            max_emission.max(((g.emission[i] - cpu.emission[i]).abs() / cpu.emission[i].abs().max(Vec3::splat(1e-3))).max_element());
        let scale = cpu.position[i].abs().max_element().max(1.0);
        max_position = max_position.max((g.position[i] - cpu.position[i]).abs().max_element() / scale);
        max_normal = max_normal.max((g.normal[i] - cpu.normal[i]).abs().max_element());
        if g.ambient[i] != cpu.ambient[i]
            || g.diffuse[i] != cpu.diffuse[i]
            || g.specular[i] != cpu.specular[i]
            || g.optical[i] != cpu.optical[i]
        {
            other += 1;
        }
    }
    eprintln!(
        "unpack: {rt_pixels} RT pixels of {}; object ids differ {ids_differ}, depth bits differ {depth_differ}, \
         max rel. emission err {max_emission:.2e}, max rel. position err {max_position:.2e}, max normal err {max_normal:.2e}, \
         ambient/diffuse/specular/optical differ {other}",
        g.len()
    );
    assert!(rt_pixels > 0, "no RT pixels to compare");
    assert_eq!(ids_differ, 0);
    assert_eq!(depth_differ, 0);
    assert_eq!(other, 0);
    assert!(max_emission < 1e-3, "emission {max_emission}");
    assert!(max_position < 1e-4, "position {max_position}");
    assert!(max_normal < 2e-3, "normal {max_normal}");
}

/// Where both hit the same sphere: `exact_depth` = depth bits identical (else within 4 ulps: the
/// orthographic rays); colour bytes may differ by 1 on a few pixels (the GPU's `pow` in the
/// shading and the sRGB encode is not correctly rounded, so a byte rarely flips).
fn check_frame(name: &str, ctx: &GpuContext, scene: &Scene, camera: &Camera, w: u32, h: u32, exact_depth: bool) {
    let gpu = render_gpu(ctx, scene, camera, w, h);
    let (cpu, cpu_ids) = render_cpu(scene, camera, w, h);
    let d = compare_packed(&gpu, &cpu, &cpu_ids);
    let hits = d.same_sphere + d.different_sphere + d.cpu_only;
    eprintln!("{name} {w}x{h}: {d:?}");
    eprintln!(
        "{name}: {} CPU hits; same sphere {} (texel-exact {}), different sphere {}, one-sided {} (gpu only {}, cpu only {})",
        hits,
        d.same_sphere,
        d.exact,
        d.different_sphere,
        d.gpu_only + d.cpu_only,
        d.gpu_only,
        d.cpu_only
    );
    assert!(hits > d.pixels / 20, "{name}: too few hits ({hits}) to test anything");
    if exact_depth {
        assert_eq!(d.depth_diff, 0, "{name}: depths differ where both hit the same sphere");
    } else {
        assert!(d.max_depth_ulps <= 4, "{name}: {d:?}");
    }
    assert!(d.max_color_diff <= 1 && d.color_diff * 200 <= d.same_sphere, "{name}: colours differ: {d:?}");
    let disagree = d.different_sphere + d.gpu_only + d.cpu_only;
    assert!(disagree * 100 <= d.pixels, "{name}: {disagree} of {} pixels show different spheres", d.pixels);
    check_unpack(&gpu, camera);
}

/// A deterministic pseudo-random value in [0, 1).
fn hash01(i: u32, salt: u32) -> f32 {
    let mut x = i.wrapping_mul(0x9E37_79B9) ^ salt.wrapping_mul(0x85EB_CA6B);
    x ^= x >> 16;
    x = x.wrapping_mul(0x7FEB_352D);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846C_A68B);
    x ^= x >> 16;
    (x >> 8) as f32 / (1u32 << 24) as f32
}

fn synthetic_scene(camera: Camera) -> Scene {
    let mut scene = Scene::new(camera);
    scene.environment.ambient = Vec3::new(0.2, 0.22, 0.25);
    scene.lights.directional.push(DirectionalLight {
        direction: Vec3::new(-0.3, -1.0, -0.4).normalize(),
        color: Vec3::ONE,
        intensity: 1.5,
        casts_shadows: false,
    });
    scene.lights.point.push(PointLight {
        position: Vec3::new(2.0, 3.0, 2.0),
        color: Vec3::new(1.0, 0.8, 0.6),
        intensity: 6.0,
        attenuation: Attenuation::default(),
        casts_shadows: true,
    });
    // A ball of 4000 points coloured by height, and a uniform-coloured ring with a larger radius
    // that overlaps it (ties between clouds, different radii).
    let ball: Vec<Vec3> = (0..4000)
        .map(|i| {
            let v = Vec3::new(hash01(i, 1) * 2.0 - 1.0, hash01(i, 2) * 2.0 - 1.0, hash01(i, 3) * 2.0 - 1.0);
            v.normalize_or_zero() * 1.2 * hash01(i, 4).cbrt()
        })
        .collect();
    let ring: Vec<Vec3> = (0..600)
        .map(|i| {
            let a = i as f32 / 600.0 * std::f32::consts::TAU;
            Vec3::new(1.5 * a.cos(), 0.1 * (5.0 * a).sin(), 1.5 * a.sin())
        })
        .collect();
    let cloud = |name: &str, points, radius, coloring| PointCloud {
        name: name.into(),
        source: "synthetic".into(),
        points,
        colors: vec![],
        radius,
        coloring,
        specular: Vec3::splat(0.2),
        shininess: 0.4,
    };
    scene.point_clouds.push(cloud("ball", ball, 0.04, PointColoring::Height));
    scene.point_clouds.push(cloud("ring", ring, 0.08, PointColoring::Uniform(Vec3::new(0.7, 0.2, 0.1))));
    scene
}

#[test]
fn synthetic_clouds_match_the_cpu_capsule() {
    let ctx = context();
    let perspective = Camera {
        position: Vec3::new(0.5, 1.5, 4.0),
        target: Vec3::ZERO,
        up: Vec3::Y,
        projection: Projection::Perspective { fov_y_deg: 50.0, near: 0.1, far: 50.0 },
    };
    let scene = synthetic_scene(perspective);
    check_frame("synthetic perspective", &ctx, &scene, &perspective, 160, 120, true);
    let ortho = Camera { projection: Projection::Orthographic { height: 3.5, near: 0.5, far: 20.0 }, ..perspective };
    check_frame("synthetic orthographic", &ctx, &scene, &ortho, 128, 96, false);
}

#[test]
fn tree_merge_scene_matches_the_cpu_capsule() {
    let ctx = context();
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/tree-merge.toml");
    let t = Instant::now();
    let scene = hybrid_scene::file::load_scene(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let points: usize = scene.point_clouds.iter().map(|c| c.points.len()).sum();
    eprintln!("tree-merge: loaded {points} points in {:.0} ms", t.elapsed().as_secs_f64() * 1e3);
    assert!(points > 1_000_000);
    let camera = scene.camera;
    check_frame("tree-merge", &ctx, &scene, &camera, 160, 120, true);
}
