//! The GPU trace stage (listings 8a–d) and the rt-only primary pass against the CPU backend, on
//! lavapipe (or any adapter). The trace stage is driven with the CPU's own G-buffer, so these
//! tests compare the trace stage alone. They fail (not skip) without an adapter.

use glam::{Vec2, Vec3};
use hybrid_core::PreparedScene;
use hybrid_core::report::RayCounts;
use hybrid_core::{FrameBuffers, GBuffer, NO_OBJECT, Surface};
use hybrid_cpu::bvh::SceneBvh;
use hybrid_cpu::capsule::PointCloudCapsule;
use hybrid_cpu::trace::{TraceOutput, rt_only_gbuffer, trace, trace_with_spheres};
use hybrid_gpu::GpuContext;
use hybrid_gpu::primary::PrimaryPass;
use hybrid_gpu::readback::{read_frame_buffers, read_gbuffer, write_gbuffer};
use hybrid_gpu::scene::SceneGpu;
use hybrid_gpu::spheres::SpheresGpu;
use hybrid_gpu::targets::FrameTargets;
use hybrid_gpu::timing::StageTimer;
use hybrid_gpu::trace::TracePasses;
use hybrid_scene::primitives::{cuboid, quad};
use hybrid_scene::{
    Camera, ColorSpace, DirectionalLight, Environment, Lights, Material, Mesh, PointCloud, PointColoring, Projection, Scene, Skybox,
    Texture,
};

mod support;
use support::{context, mean_flip_linear};

const SKY: Vec3 = Vec3::new(0.3, 0.6, 0.9);

/// The GPU trace stage over `g`: (shadow, reflection, refraction buffers, ray counts). The
/// scene's point clouds are traced as spheres.
fn gpu_trace(ctx: &GpuContext, scene: &Scene, g: &GBuffer) -> (FrameBuffers, RayCounts) {
    let prepared = PreparedScene::new(scene);
    let sg = SceneGpu::new(ctx, &prepared).expect("scene upload");
    let spheres = SpheresGpu::new(ctx, &scene.point_clouds).expect("spheres upload");
    let targets = FrameTargets::new(&ctx.device, g.width, g.height);
    write_gbuffer(ctx, &targets, g);
    sg.write_uniforms(ctx, &scene.camera, g.width, g.height, &scene.environment);
    let passes = TracePasses::new(ctx, &sg, &prepared, &spheres).expect("trace passes");
    let mut timer = StageTimer::new(ctx);
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    passes.encode(&mut encoder, &sg, &targets, &mut timer);
    ctx.queue.submit([encoder.finish()]);
    let counts = passes.read_ray_counts(ctx).expect("ray counts");
    (read_frame_buffers(ctx, &targets).expect("readback"), counts)
}

fn cpu_trace(scene: &Scene, g: &GBuffer) -> TraceOutput {
    let prepared = PreparedScene::new(scene);
    let bvh = SceneBvh::build(&prepared);
    trace(&prepared, &bvh, g, &scene.camera)
}

fn max_diff(a: &[Vec3], b: &[Vec3]) -> f32 {
    a.iter().zip(b).map(|(x, y)| (*x - *y).abs().max_element()).fold(0.0, f32::max)
}

/// Compares every buffer and the ray counts; returns the worst mean FLIP.
fn compare(name: &str, w: u32, h: u32, cpu: &TraceOutput, gpu: &FrameBuffers, gpu_rays: RayCounts) -> f32 {
    let mut worst = 0.0f32;
    for (buffer, c, g) in [
        ("shadow", &cpu.shadow, &gpu.shadow),
        ("reflection", &cpu.reflection, &gpu.reflection),
        ("refraction", &cpu.refraction, &gpu.refraction),
    ] {
        let flip = mean_flip_linear(w, h, c, g);
        let far = c.iter().zip(g.iter()).filter(|(x, y)| (**x - **y).abs().max_element() > 0.05).count();
        eprintln!("{name} {buffer}: mean FLIP {flip:.5}, max |diff| {:.4}, {far} of {} pixels differ by > 0.05", max_diff(c, g), c.len());
        worst = worst.max(flip);
    }
    let (c, g) = (cpu.rays, gpu_rays);
    eprintln!("{name} rays: CPU {c:?}\n{name} rays: GPU {g:?}");
    for (kind, a, b) in
        [("shadow", c.shadow, g.shadow), ("reflection", c.reflection, g.reflection), ("refraction", c.refraction, g.refraction)]
    {
        let rel = (a as f64 - b as f64).abs() / (a.max(1) as f64);
        assert!(rel <= 0.01, "{name}: {kind} rays CPU {a} vs GPU {b}");
    }
    worst
}

#[test]
fn demo_scene_matches_the_cpu_trace() {
    let ctx = context();
    let scene = hybrid_scene::file::demo_scene();
    let (w, h) = (160, 120);
    let prepared = PreparedScene::new(&scene);
    let mut g = hybrid_cpu::raster::rasterize(&prepared, &scene.camera, w, h, None);
    // Trace every pixel but a band (untraced: 1 / 0 / 0), sky pixels included (reflection = sky).
    for y in 0..h {
        for x in 0..w {
            g.mask[(y * w + x) as usize] = if (40..52).contains(&y) { 0.0 } else { 1.0 };
        }
    }
    let cpu = cpu_trace(&scene, &g);
    let (gpu, rays) = gpu_trace(&ctx, &scene, &g);
    let worst = compare("demo", w, h, &cpu, &gpu, rays);
    assert!(worst <= 0.02, "demo: mean FLIP {worst} > 0.02");
    for y in 40..52 {
        for x in 0..w {
            let i = (y * w + x) as usize;
            assert_eq!(
                (gpu.shadow[i], gpu.reflection[i], gpu.refraction[i]),
                (Vec3::ONE, Vec3::ZERO, Vec3::ZERO),
                "untraced pixel {x},{y}"
            );
        }
    }
}

// ---- hand-built scenes with known answers (as crates/cpu/tests/trace.rs) ----

fn scene(materials: Vec<Material>, meshes: Vec<Mesh>, lights: Lights, camera: Camera) -> Scene {
    let mut scene = Scene::new(camera);
    scene.environment = Environment { ambient: Vec3::ZERO, ior: 1.0, skybox: Skybox::Color(SKY) };
    scene.materials = materials;
    scene.lights = lights;
    for (i, m) in meshes.into_iter().enumerate() {
        scene.push_mesh_object(format!("object {i}"), m);
    }
    scene
}

fn camera(position: Vec3, target: Vec3) -> Camera {
    Camera { position, target, up: Vec3::Y, projection: Projection::Perspective { fov_y_deg: 40.0, near: 0.1, far: 100.0 } }
}

fn one_pixel(s: &Surface) -> GBuffer {
    let mut g = GBuffer::new(1, 1);
    g.write(0, 0, 0.5, s);
    g.mask[0] = 1.0;
    g
}

fn close(a: Vec3, b: Vec3, eps: f32) -> bool {
    (a - b).abs().max_element() <= eps
}

fn emissive(c: Vec3) -> Material {
    Material { emission: c, ambient: Vec3::ZERO, diffuse: Vec3::ZERO, ..Default::default() }
}

/// f16 targets: answers within half-float precision.
const EPS: f32 = 2e-3;

#[test]
fn mirror_shows_an_emissive_quad_and_the_sky() {
    let ctx = context();
    let glow = Vec3::new(0.2, 0.5, 0.9);
    let s = scene(
        vec![emissive(glow)],
        vec![quad(Vec3::new(0.0, 0.0, 2.0), Vec3::X, -Vec3::Y, 0)],
        Lights::default(),
        camera(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO),
    );
    let mirror = Surface {
        position: Vec3::ZERO,
        normal: Vec3::Z,
        diffuse: Vec3::splat(0.5),
        opacity: 1.0,
        reflectivity: 1.0,
        ior: 1.5,
        ..Default::default()
    };
    let (out, rays) = gpu_trace(&ctx, &s, &one_pixel(&mirror));
    eprintln!("mirror: reflection {} (expected {glow}), rays {rays:?}", out.reflection[0]);
    assert!(close(out.reflection[0], glow, EPS), "{}", out.reflection[0]);
    assert_eq!((out.shadow[0], out.refraction[0]), (Vec3::ONE, Vec3::ZERO));
    assert_eq!(rays, RayCounts { primary: 0, shadow: 0, reflection: 1, refraction: 0 });
    // Turned away from the quad, the mirror sees the sky.
    let away = Surface { normal: -Vec3::Z, position: Vec3::new(0.0, 0.0, -1.0), ..mirror };
    let s2 = Scene { camera: camera(Vec3::new(0.0, 0.0, -5.0), Vec3::ZERO), ..s.clone() };
    let (out, _) = gpu_trace(&ctx, &s2, &one_pixel(&away));
    assert!(close(out.reflection[0], SKY, EPS), "{}", out.reflection[0]);
}

#[test]
fn glass_slab_of_ior_one_leaves_the_sky_unchanged() {
    let ctx = context();
    let glass = Material { opacity: 0.0, ior: 1.0, diffuse: Vec3::splat(0.5), ..Default::default() };
    let cam = Camera {
        position: Vec3::new(0.0, 0.0, 5.0),
        target: Vec3::ZERO,
        up: Vec3::Y,
        projection: Projection::Orthographic { height: 1.0, near: 0.1, far: 20.0 },
    };
    let s = scene(vec![glass], vec![cuboid(Vec3::new(-2.0, -2.0, -0.5), Vec3::new(2.0, 2.0, 0.5), 0)], Lights::default(), cam);
    let prepared = PreparedScene::new(&s);
    let bvh = SceneBvh::build(&prepared);
    let g = rt_only_gbuffer(&prepared, &bvh, &s.camera, 16, 12);
    let (out, rays) = gpu_trace(&ctx, &s, &g);
    for i in 0..g.len() {
        assert!(close(out.refraction[i], SKY, EPS), "pixel {i}: {}", out.refraction[i]);
    }
    // Front face → back face (depth 1, fully transparent, traced on) → sky: 2 rays a pixel.
    assert_eq!(rays, RayCounts { primary: 0, shadow: 0, reflection: 0, refraction: 2 * 16 * 12 });
}

/// Floor pixel lit by two directional lights, one blocked by a small quad above (as the CPU test).
/// Returns (GPU shadow, the blocked light's Blinn–Phong term, GPU rays, CPU shadow).
fn two_light_shadow(ctx: &GpuContext, occluder: Material, textures: Vec<Texture>) -> (Vec3, Vec3, RayCounts, Vec3) {
    let floor = Material { diffuse: Vec3::splat(0.5), ..Default::default() };
    let above = DirectionalLight { direction: -Vec3::Y, color: Vec3::ONE, intensity: 1.0, casts_shadows: true };
    let slanted = DirectionalLight {
        direction: Vec3::new(-1.0, -1.0, 0.0).normalize(),
        color: Vec3::new(1.0, 0.5, 0.25),
        intensity: 1.0,
        casts_shadows: true,
    };
    let lights = Lights { directional: vec![above, slanted], ..Default::default() };
    let mut s = scene(
        vec![floor, occluder],
        vec![quad(Vec3::ZERO, Vec3::X * 3.0, -Vec3::Z * 3.0, 0), quad(Vec3::new(0.05, 1.0, 0.03), Vec3::X * 0.2, -Vec3::Z * 0.2, 1)],
        lights,
        camera(Vec3::new(0.0, 5.0, 5.0), Vec3::ZERO),
    );
    s.textures = textures;
    let p = Surface { position: Vec3::ZERO, normal: Vec3::Y, diffuse: Vec3::splat(0.5), opacity: 1.0, ior: 1.5, ..Default::default() };
    let view = (s.camera.position - p.position).normalize();
    let blocked = hybrid_core::shading::Light::Directional(&above).blinn_phong(&p, view);
    let (out, rays) = gpu_trace(ctx, &s, &one_pixel(&p));
    let cpu = cpu_trace(&s, &one_pixel(&p));
    (out.shadow[0], blocked, rays, cpu.shadow[0])
}

#[test]
fn shadows_through_opaque_half_transparent_textured_and_non_casting_occluders() {
    let ctx = context();
    let (shadow, blocked, rays, _) = two_light_shadow(&ctx, Material::default(), Vec::new());
    eprintln!("opaque occluder: shadow {shadow} (expected {})", Vec3::ONE - blocked);
    assert!(close(shadow, Vec3::ONE - blocked, EPS), "{shadow}");
    assert_eq!(rays, RayCounts { primary: 0, shadow: 2, reflection: 0, refraction: 0 });

    let (shadow, blocked, _, _) = two_light_shadow(&ctx, Material { opacity: 0.5, ..Default::default() }, Vec::new());
    assert!(close(shadow, Vec3::ONE - blocked * 0.5, EPS), "{shadow}");

    // Diffuse-map alpha 0 makes the occluder fully transparent; 255 opaque.
    let tex = Texture::solid("clear", [255, 255, 255, 0], ColorSpace::Srgb);
    let (shadow, _, _, _) = two_light_shadow(&ctx, Material { diffuse_map: Some(0), ..Default::default() }, vec![tex]);
    assert!(close(shadow, Vec3::ONE, EPS), "{shadow}");
    let tex = Texture::solid("solid", [255, 255, 255, 255], ColorSpace::Srgb);
    let (shadow, blocked, _, _) = two_light_shadow(&ctx, Material { diffuse_map: Some(0), ..Default::default() }, vec![tex]);
    assert!(close(shadow, Vec3::ONE - blocked, EPS), "{shadow}");
    // Alpha that varies over the texture: evaluated at the hit, as the CPU does.
    let alphas = [0u8, 200, 90, 255];
    let varying = Texture::new("varying", 2, 2, alphas.map(|a| [255, 255, 255, a]).to_vec(), ColorSpace::Srgb);
    let (shadow, blocked, _, cpu) = two_light_shadow(&ctx, Material { diffuse_map: Some(0), ..Default::default() }, vec![varying]);
    eprintln!("varying alpha occluder: GPU shadow {shadow}, CPU {cpu}");
    assert!(close(shadow, cpu, EPS), "GPU {shadow} vs CPU {cpu}");
    assert!(shadow.x < 1.0 - 0.05 && shadow.x > 1.0 - blocked.x + 0.05, "partly transparent: {shadow}");

    let (shadow, _, rays, _) = two_light_shadow(&ctx, Material { casts_shadows: false, ..Default::default() }, Vec::new());
    assert!(close(shadow, Vec3::ONE, EPS), "{shadow}");
    assert_eq!(rays.shadow, 2);
}

#[test]
fn unmasked_and_sky_pixels() {
    let ctx = context();
    let s = scene(
        vec![Material::default()],
        vec![quad(Vec3::ZERO, Vec3::X, Vec3::Y, 0)],
        Lights::default(),
        camera(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO),
    );
    let mut g = GBuffer::new(2, 1);
    let p = Surface { normal: Vec3::Z, opacity: 0.0, reflectivity: 1.0, ior: 1.5, ..Default::default() };
    g.write(0, 0, 0.5, &p);
    g.mask[1] = 1.0;
    let (out, rays) = gpu_trace(&ctx, &s, &g);
    assert_eq!((out.shadow[0], out.reflection[0], out.refraction[0]), (Vec3::ONE, Vec3::ZERO, Vec3::ZERO));
    assert!(out.shadow[1] == Vec3::ONE && close(out.reflection[1], SKY, EPS) && out.refraction[1] == Vec3::ZERO);
    assert_eq!(rays, RayCounts::default());
    assert_eq!(g.object_id[1], NO_OBJECT);
}

/// A small scene with every effect (mirror box, glass box, floor, two lights), as the CPU tests'
/// but with the boxes lifted off the floor: a box bottom coplanar with the floor makes rays
/// leaving the glass downwards hit two triangles at the same distance, and which one wins
/// depends on the BVH (CPU and GPU trees differ).
fn busy_scene() -> Scene {
    let mats = vec![
        // A checkerboard floor, tiled: mip selection from the UV footprint in the primary pass.
        Material {
            diffuse: Vec3::new(0.6, 0.5, 0.4),
            specular: Vec3::splat(0.3),
            shininess: 0.4,
            diffuse_map: Some(0),
            tiling: Vec2::splat(6.0),
            ..Default::default()
        },
        Material { reflectivity: 0.8, diffuse: Vec3::splat(0.2), ..Default::default() },
        Material { opacity: 0.1, ior: 1.5, reflectivity: 0.1, diffuse: Vec3::new(0.2, 0.4, 0.3), ..Default::default() },
    ];
    let meshes = vec![
        quad(Vec3::ZERO, Vec3::X * 4.0, -Vec3::Z * 4.0, 0),
        cuboid(Vec3::new(-1.5, 0.02, -1.0), Vec3::new(-0.3, 1.2, 0.2), 1),
        cuboid(Vec3::new(0.3, 0.02, -0.5), Vec3::new(1.4, 1.0, 0.6), 2),
    ];
    let lights = Lights {
        directional: vec![DirectionalLight {
            direction: Vec3::new(-0.3, -1.0, -0.4).normalize(),
            color: Vec3::ONE,
            intensity: 0.8,
            casts_shadows: true,
        }],
        point: vec![hybrid_scene::PointLight {
            position: Vec3::new(1.0, 3.0, 2.0),
            color: Vec3::new(1.0, 0.9, 0.8),
            intensity: 6.0,
            attenuation: Default::default(),
            casts_shadows: true,
        }],
        ..Default::default()
    };
    let mut s = scene(mats, meshes, lights, camera(Vec3::new(0.5, 2.5, 6.0), Vec3::new(0.0, 0.5, 0.0)));
    let checker: Vec<[u8; 4]> =
        (0..16 * 16).map(|i| if (i % 16 / 2 + i / 16 / 2) % 2 == 0 { [240, 230, 220, 255] } else { [40, 60, 90, 255] }).collect();
    s.textures = vec![Texture::new("checker", 16, 16, checker, ColorSpace::Srgb)];
    s
}

#[test]
fn busy_scene_matches_the_cpu_trace() {
    let ctx = context();
    let s = busy_scene();
    let (w, h) = (128, 96);
    let prepared = PreparedScene::new(&s);
    let bvh = SceneBvh::build(&prepared);
    let g = rt_only_gbuffer(&prepared, &bvh, &s.camera, w, h);
    let cpu = trace(&prepared, &bvh, &g, &s.camera);
    let (gpu, rays) = gpu_trace(&ctx, &s, &g);
    let worst = compare("busy", w, h, &cpu, &gpu, rays);
    assert!(worst <= 0.02, "busy: mean FLIP {worst} > 0.02");
}

// ---- the rt-only primary pass ----

/// The GPU primary pass's G-buffer (cleared first) for `scene` at w×h.
fn gpu_primary(ctx: &GpuContext, scene: &Scene, w: u32, h: u32) -> GBuffer {
    let prepared = PreparedScene::new(scene);
    let sg = SceneGpu::new(ctx, &prepared).expect("scene upload");
    let targets = FrameTargets::new(&ctx.device, w, h);
    sg.write_uniforms(ctx, &scene.camera, w, h, &scene.environment);
    let passes = TracePasses::new(ctx, &sg, &prepared, &SpheresGpu::empty(ctx)).expect("trace passes");
    let primary = PrimaryPass::new(ctx, &sg, passes.bvh());
    let mut timer = StageTimer::new(ctx);
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    primary.encode(&mut encoder, &sg, &targets, true, &mut timer);
    ctx.queue.submit([encoder.finish()]);
    read_gbuffer(ctx, &targets).expect("readback")
}

/// Compares the GPU primary G-buffer with the CPU's `rt_only_gbuffer`: returns the number of
/// pixels whose object id differs.
fn compare_primary(name: &str, scene: &Scene, w: u32, h: u32) -> usize {
    let ctx = context();
    let prepared = PreparedScene::new(scene);
    let bvh = SceneBvh::build(&prepared);
    let cpu = rt_only_gbuffer(&prepared, &bvh, &scene.camera, w, h);
    let gpu = gpu_primary(&ctx, scene, w, h);
    let mut id_diff = 0;
    let (mut depth, mut position, mut normal, mut diffuse) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
    let mut covered = 0;
    for i in 0..cpu.len() {
        if cpu.object_id[i] != gpu.object_id[i] {
            id_diff += 1;
            continue;
        }
        if cpu.object_id[i] == NO_OBJECT {
            assert_eq!(gpu.depth[i], 0.0, "{name}: sky pixel {i} has depth");
            continue;
        }
        covered += 1;
        depth = depth.max((cpu.depth[i] - gpu.depth[i]).abs() / cpu.depth[i].abs().max(1e-6));
        position = position.max(cpu.position[i].distance(gpu.position[i]));
        normal = normal.max((cpu.normal[i] - gpu.normal[i]).abs().max_element());
        diffuse = diffuse.max((cpu.diffuse[i] - gpu.diffuse[i]).abs().max_element());
    }
    eprintln!(
        "{name} primary {w}x{h}: {id_diff} of {} pixels with another object id, {covered} covered pixels compared: \
         max relative depth diff {depth:.2e}, max position diff {position:.2e}, max normal diff {normal:.2e}, max diffuse diff {diffuse:.2e}",
        cpu.len()
    );
    assert!(covered > cpu.len() / 4, "{name}: too few covered pixels ({covered})");
    assert!(depth < 1e-3, "{name}: depth differs by {depth} (relative)");
    assert!(position < 1e-2 && normal < 1e-2 && diffuse < 1e-2, "{name}: surfaces differ");
    id_diff
}

#[test]
fn primary_pass_matches_rt_only_gbuffer_on_the_demo() {
    let n = compare_primary("demo", &hybrid_scene::file::demo_scene(), 160, 120);
    assert!(n <= 10, "demo: {n} pixels with another object id");
}

#[test]
fn primary_pass_matches_rt_only_gbuffer_on_the_busy_scene() {
    let n = compare_primary("busy", &busy_scene(), 128, 96);
    assert!(n <= 10, "busy: {n} pixels with another object id");
}

#[test]
fn primary_pass_loads_and_depth_tests_against_what_is_there() {
    // A quad at 5 m; a second frame with clear = false over a depth buffer already holding a
    // nearer layer (the first frame of a scene with a nearer quad) keeps that layer.
    let ctx = context();
    let near = scene(
        vec![Material::default()],
        vec![quad(Vec3::new(0.0, 0.0, 2.0), Vec3::X * 0.3, Vec3::Y * 0.3, 0)],
        Lights::default(),
        camera(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO),
    );
    let far = scene(
        vec![Material::default()],
        vec![quad(Vec3::ZERO, Vec3::X, Vec3::Y, 0), quad(Vec3::new(0.0, 0.0, -3.0), Vec3::X * 9.0, Vec3::Y * 9.0, 0)],
        Lights::default(),
        near.camera,
    );
    let (w, h) = (32, 24);
    let targets = FrameTargets::new(&ctx.device, w, h);
    let mut timer = StageTimer::new(&ctx);
    let mut run = |s: &Scene, clear: bool| {
        let prepared = PreparedScene::new(s);
        let sg = SceneGpu::new(&ctx, &prepared).expect("scene upload");
        sg.write_uniforms(&ctx, &s.camera, w, h, &s.environment);
        let passes = TracePasses::new(&ctx, &sg, &prepared, &SpheresGpu::empty(&ctx)).expect("trace passes");
        let primary = PrimaryPass::new(&ctx, &sg, passes.bvh());
        timer.begin_frame();
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        primary.encode(&mut encoder, &sg, &targets, clear, &mut timer);
        ctx.queue.submit([encoder.finish()]);
        read_gbuffer(&ctx, &targets).expect("readback")
    };
    let first = run(&near, true);
    let merged = run(&far, false);
    let centre = (h / 2 * w + w / 2) as usize;
    assert_eq!(first.object_id[centre], 0);
    assert!((merged.position[centre].z - 2.0).abs() < 1e-4, "the nearer layer stays: {}", merged.position[centre]);
    // Outside the near quad the far scene's back wall (object 1) fills every pixel.
    assert_eq!(merged.object_id[0], 1);
    assert!(merged.depth[0] > 0.0 && merged.depth[0] < first.depth[centre]);
}

// ---- phase 2: the RT-scene's spheres in the trace (as the CPU's trace_with_spheres) ----

#[test]
fn spheres_block_shadows_and_show_in_reflections_and_refractions_as_on_the_cpu() {
    let ctx = context();
    let mut s = busy_scene();
    // A block of 12×8×6 small spheres between the boxes and the camera, above the floor: they
    // shadow the floor, show in the mirror box and through the glass box.
    let mut points = Vec::new();
    for i in 0..12 {
        for j in 0..8 {
            for k in 0..6 {
                points.push(Vec3::new(-0.9 + i as f32 * 0.15, 0.4 + j as f32 * 0.12, 0.7 + k as f32 * 0.12));
            }
        }
    }
    s.point_clouds.push(PointCloud {
        name: "block".into(),
        source: "block.ply".into(),
        points,
        colors: Vec::new(),
        radius: 0.04,
        coloring: PointColoring::Height,
        specular: Vec3::splat(0.2),
        shininess: 0.5,
    });
    let (w, h) = (128, 96);
    let prepared = PreparedScene::new(&s);
    let bvh = SceneBvh::build(&prepared);
    let g = rt_only_gbuffer(&prepared, &bvh, &s.camera, w, h);
    let capsule = PointCloudCapsule::new(&s.point_clouds, s.lights.clone(), s.environment.clone()).expect("capsule");
    let cpu = trace_with_spheres(&prepared, &bvh, Some(&capsule), &g, &s.camera);
    let without = trace(&prepared, &bvh, &g, &s.camera);
    let changed = |a: &[Vec3], b: &[Vec3]| a.iter().zip(b).filter(|(x, y)| (**x - **y).abs().max_element() > 0.01).count();
    let (cs, cm, cr) = (
        changed(&cpu.shadow, &without.shadow),
        changed(&cpu.reflection, &without.reflection),
        changed(&cpu.refraction, &without.refraction),
    );
    eprintln!("spheres change {cs} shadow, {cm} reflection, {cr} refraction pixels on the CPU");
    assert!(cs > 50 && cm > 20 && cr > 20, "the test scene must exercise the spheres");
    let (gpu, rays) = gpu_trace(&ctx, &s, &g);
    let worst = compare("spheres", w, h, &cpu, &gpu, rays);
    assert!(worst <= 0.02, "spheres: mean FLIP {worst} > 0.02");
}
