//! Stage 1 (raster) and 1b (deferred lighting) on the GPU against the CPU backend, the oracle:
//! object ids, depth, the G-buffer's diffuse and normal, and the lighting image, for the demo
//! scene and a real textured scene (Dabrovic Sponza with spheres). Needs a GPU adapter (lavapipe
//! in CI): without one the tests FAIL.

use std::path::Path;

use glam::Vec3;
use hybrid_core::PreparedScene;
use hybrid_core::blend::encode_srgb;
use hybrid_core::{FrameBuffers, GBuffer, NO_OBJECT};
use hybrid_gpu::GpuContext;
use hybrid_gpu::lighting::LightingPass;
use hybrid_gpu::raster::RasterPass;
use hybrid_gpu::readback::{read_frame_buffers, read_gbuffer};
use hybrid_gpu::scene::SceneGpu;
use hybrid_gpu::targets::FrameTargets;
use hybrid_gpu::timing::StageTimer;
use hybrid_scene::Scene;

mod support;
use support::{context, mean_flip_linear};

/// Rasterises and lights `scene` on the GPU (`clear = true`: no RT layer).
fn render_gpu(ctx: &GpuContext, scene: &Scene, w: u32, h: u32) -> (GBuffer, FrameBuffers) {
    let prepared = PreparedScene::new(scene);
    let gpu = SceneGpu::new(ctx, &prepared).unwrap_or_else(|e| panic!("{e}"));
    let raster = RasterPass::new(ctx, &gpu);
    let lighting = LightingPass::new(ctx, &gpu);
    let targets = FrameTargets::new(&ctx.device, w, h);
    let mut timer = StageTimer::new(ctx);
    timer.begin_frame();
    gpu.write_uniforms(ctx, &scene.camera, w, h, &scene.environment);
    let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("test") });
    raster.encode(&mut encoder, &gpu, &targets, true, &mut timer);
    lighting.encode(&mut encoder, &gpu, &targets, &mut timer);
    timer.resolve(&mut encoder);
    ctx.queue.submit([encoder.finish()]);
    ctx.wait().unwrap();
    if let Some(t) = timer.read(ctx).unwrap() {
        eprintln!("GPU times: raster {:.3} ms, lighting {:.3} ms", t.raster, t.lighting);
    }
    (read_gbuffer(ctx, &targets).unwrap(), read_frame_buffers(ctx, &targets).unwrap())
}

/// The CPU backend's G-buffer and lighting for the same view.
fn render_cpu(scene: &Scene, w: u32, h: u32) -> (GBuffer, Vec<Vec3>) {
    let prepared = PreparedScene::new(scene);
    let g = hybrid_cpu::raster::rasterize(&prepared, &scene.camera, w, h, None);
    let lit = hybrid_cpu::lighting::deferred_lighting(&g, scene, &scene.camera);
    (g, lit)
}

struct Comparison {
    id_mismatches: usize,
    covered: usize,
    max_depth_diff: f32,
    flip_lighting: f32,
    flip_diffuse: f32,
    flip_normal: f32,
    /// The lighting pass alone: the CPU's deferred lighting of the GPU's own G-buffer vs the GPU's.
    flip_lighting_same_gbuffer: f32,
    max_lighting_diff_same_gbuffer: f32,
    /// Largest difference of an sRGB 8-bit code (any channel) in that comparison.
    max_code_diff_same_gbuffer: i32,
}

fn compare(name: &str, scene: &Scene, w: u32, h: u32) -> Comparison {
    let ctx = context();
    let (gg, gb) = render_gpu(&ctx, scene, w, h);
    let (cg, clit) = render_cpu(scene, w, h);
    let n = (w * h) as usize;
    assert_eq!(gg.object_id.len(), n);
    let mut id_mismatches = 0;
    let mut max_depth_diff = 0.0f32;
    let mut worst = None;
    for i in 0..n {
        let (a, b) = (cg.object_id[i], gg.object_id[i]);
        if a != b {
            id_mismatches += 1;
            if worst.is_none() {
                worst = Some((i % w as usize, i / w as usize, a, b, cg.depth[i], gg.depth[i]));
            }
        } else if a != NO_OBJECT {
            max_depth_diff = max_depth_diff.max((cg.depth[i] - gg.depth[i]).abs());
        }
    }
    let covered = cg.object_id.iter().filter(|&&id| id != NO_OBJECT).count();
    // Sky pixels: depth stays at the clear value on both.
    for i in 0..n {
        if gg.object_id[i] == NO_OBJECT {
            assert_eq!(gg.depth[i], 0.0, "{name}: sky pixel {i} has depth {}", gg.depth[i]);
        }
    }
    let same = hybrid_cpu::lighting::deferred_lighting(&gg, scene, &scene.camera);
    let diffuse = |g: &GBuffer| -> Vec<Vec3> { g.diffuse.iter().map(|d| d.truncate()).collect() };
    let normal = |g: &GBuffer| -> Vec<Vec3> { g.normal.iter().map(|&v| v * 0.5 + Vec3::splat(0.5)).collect() };
    let c = Comparison {
        id_mismatches,
        covered,
        max_depth_diff,
        flip_lighting: mean_flip_linear(w, h, &clit, &gb.lighting),
        flip_diffuse: mean_flip_linear(w, h, &diffuse(&cg), &diffuse(&gg)),
        flip_normal: mean_flip_linear(w, h, &normal(&cg), &normal(&gg)),
        flip_lighting_same_gbuffer: mean_flip_linear(w, h, &same, &gb.lighting),
        max_code_diff_same_gbuffer: same
            .iter()
            .zip(&gb.lighting)
            .map(|(a, b)| {
                let (a, b) = (encode_srgb(*a), encode_srgb(*b));
                (0..3).map(|k| (i32::from(a[k]) - i32::from(b[k])).abs()).max().unwrap_or(0)
            })
            .max()
            .unwrap_or(0),
        max_lighting_diff_same_gbuffer: same.iter().zip(&gb.lighting).map(|(a, b)| (*a - *b).abs().max_element()).fold(0.0, f32::max),
    };
    eprintln!(
        "{name} {w}x{h}: object-id mismatches {} of {n} pixels ({:.3}%; first {worst:?} = (x, y, cpu id, gpu id, cpu depth, gpu depth)), covered {}, \
         max |depth diff| {:.3e}, mean FLIP lighting {:.4}, diffuse {:.4}, normal {:.4}; \
         lighting of the GPU's G-buffer: mean FLIP {:.4}, max abs diff {:.3e}, max 8-bit code diff {}",
        c.id_mismatches,
        100.0 * c.id_mismatches as f64 / n as f64,
        c.covered,
        c.max_depth_diff,
        c.flip_lighting,
        c.flip_diffuse,
        c.flip_normal,
        c.flip_lighting_same_gbuffer,
        c.max_lighting_diff_same_gbuffer,
        c.max_code_diff_same_gbuffer
    );
    assert!(gb.lighting.iter().all(|c| c.is_finite()), "{name}: non-finite lighting");
    c
}

/// The shared checks. Object ids: the GPU rasteriser's sub-pixel precision and tie rules differ
/// from the CPU's (1/256-pixel snapping, its own top-left rule and f64 planes), so pixel centres
/// lying (almost) exactly on an edge may go to the neighbouring triangle; that only moves
/// silhouette pixels, a small fraction of the image, hence ≤ 0.5 % of pixels.
fn check(name: &str, c: &Comparison, w: u32, h: u32) {
    let n = (w * h) as usize;
    assert!(c.covered > n / 4, "{name}: only {} pixels covered", c.covered);
    assert!(c.id_mismatches * 200 <= n, "{name}: {} object-id mismatches > 0.5 % of {n}", c.id_mismatches);
    assert!(c.max_depth_diff < 1e-3, "{name}: depth differs by {}", c.max_depth_diff);
    assert!(c.flip_lighting <= 0.02, "{name}: lighting mean FLIP {}", c.flip_lighting);
    assert!(c.flip_diffuse <= 0.02, "{name}: diffuse mean FLIP {}", c.flip_diffuse);
    assert!(c.flip_normal <= 0.02, "{name}: normal mean FLIP {}", c.flip_normal);
    // The lighting pass alone: only f32 rounding (GPU pow/normalize) and the Rgba16Float target
    // (1 f16 ulp) separate it from the CPU, i.e. at most one sRGB code here and there.
    assert!(c.flip_lighting_same_gbuffer <= 0.01, "{name}: lighting pass mean FLIP {}", c.flip_lighting_same_gbuffer);
    assert!(c.max_code_diff_same_gbuffer <= 2, "{name}: lighting pass differs by {} sRGB codes", c.max_code_diff_same_gbuffer);
}

#[test]
fn demo_scene_matches_the_cpu() {
    let scene = hybrid_scene::demo_scene();
    let (w, h) = (160, 90);
    let c = compare("demo", &scene, w, h);
    check("demo", &c, w, h);
}

#[test]
fn sponza_spheres_matches_the_cpu() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/sponza-spheres.toml");
    let scene = hybrid_scene::load_scene(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let (w, h) = (160, 90);
    let c = compare("sponza-spheres", &scene, w, h);
    check("sponza-spheres", &c, w, h);
}

/// `clear = false` loads what is in the targets (the capsule's unpack pass writes the RT-scene
/// pixels and their depth there): an occluder scene (a box in front of the camera, left half of
/// the view) is rasterised first with `clear = true`, then the demo scene with `clear = false`.
/// The CPU reference is the demo scene rasterised with the occluder's depth as its RT layer:
/// where that layer wins (`RT_SCENE_OBJECT`) the GPU must still hold the occluder's pixel
/// (its depth, its object id 0), everywhere else the demo's own object.
#[test]
fn load_keeps_nearer_pixels_already_in_the_targets() {
    use hybrid_core::{RT_SCENE_OBJECT, RtLayer};
    use hybrid_scene::{Material, primitives};

    let demo = hybrid_scene::demo_scene();
    let (w, h) = (160, 90);
    let cam = &demo.camera;
    let fwd = cam.forward();
    let right = fwd.cross(Vec3::Y).normalize();
    let centre = cam.position + fwd * 4.0 - right * 1.5;
    let mut occluder = Scene::new(*cam);
    occluder.materials.push(Material::default());
    let mut mesh = primitives::cube();
    // Thin in view depth, about 2 × 2 across; rotated to face the camera (yaw only).
    let yaw = f32::atan2(fwd.x, fwd.z);
    let rot = glam::Mat3::from_rotation_y(yaw);
    for p in &mut mesh.positions {
        *p = centre + rot * (*p * Vec3::new(2.0, 2.0, 0.2));
    }
    for n in &mut mesh.normals {
        *n = rot * *n;
    }
    mesh.material = 0;
    occluder.push_mesh_object("occluder", mesh);

    let ctx = context();
    let targets = FrameTargets::new(&ctx.device, w, h);
    let mut timer = StageTimer::new(&ctx);
    timer.begin_frame();
    let prep_o = PreparedScene::new(&occluder);
    let prep_d = PreparedScene::new(&demo);
    let gpu_o = SceneGpu::new(&ctx, &prep_o).unwrap();
    let gpu_d = SceneGpu::new(&ctx, &prep_d).unwrap();
    gpu_o.write_uniforms(&ctx, cam, w, h, &occluder.environment);
    gpu_d.write_uniforms(&ctx, cam, w, h, &demo.environment);
    let raster_o = RasterPass::new(&ctx, &gpu_o);
    let raster_d = RasterPass::new(&ctx, &gpu_d);
    let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("test") });
    raster_o.encode(&mut encoder, &gpu_o, &targets, true, &mut timer);
    raster_d.encode(&mut encoder, &gpu_d, &targets, false, &mut timer);
    ctx.queue.submit([encoder.finish()]);
    ctx.wait().unwrap();
    let g = read_gbuffer(&ctx, &targets).unwrap();

    let occ = hybrid_cpu::raster::rasterize(&prep_o, cam, w, h, None);
    let layer = RtLayer { width: w, height: h, color: vec![Vec3::ONE; (w * h) as usize], depth: occ.depth.clone() };
    let cpu = hybrid_cpu::raster::rasterize(&prep_d, cam, w, h, Some(&layer));
    let n = (w * h) as usize;
    let (mut occluded, mut mismatches, mut max_depth) = (0, 0, 0.0f32);
    for i in 0..n {
        let (want_id, want_depth) = if cpu.object_id[i] == RT_SCENE_OBJECT {
            occluded += 1;
            (0, occ.depth[i])
        } else {
            (cpu.object_id[i], cpu.depth[i])
        };
        if g.object_id[i] != want_id {
            mismatches += 1;
        } else if want_id != NO_OBJECT {
            max_depth = max_depth.max((g.depth[i] - want_depth).abs());
        }
    }
    let demo_pixels = cpu.object_id.iter().filter(|&&id| id != RT_SCENE_OBJECT && id != NO_OBJECT).count();
    eprintln!(
        "load: {occluded} pixels kept from the first pass, {demo_pixels} drawn over by the demo, {mismatches} object-id mismatches, \
         max |depth diff| {max_depth:.3e}"
    );
    assert!(occluded > n / 10 && demo_pixels > n / 4, "occluder test scene covers {occluded}, demo {demo_pixels} pixels");
    assert!(mismatches * 200 <= n, "{mismatches} object-id mismatches > 0.5 % of {n}");
    assert!(max_depth < 1e-3, "depth differs by {max_depth}");
}

/// The other shipped asset scenes (real models and textures), same checks.
#[test]
fn asset_scenes_match_the_cpu() {
    for name in ["sponza-armadillo.toml", "dining-room.toml", "pavilion.toml"] {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes").join(name);
        let scene = hybrid_scene::load_scene(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let (w, h) = (160, 90);
        let c = compare(name, &scene, w, h);
        check(name, &c, w, h);
    }
}

/// An orthographic camera (parallel view rays: `view_dir` and `primary_ray` take the other
/// branch) on the demo scene, at an odd size (partial 8 × 8 workgroups at the borders).
#[test]
fn orthographic_demo_matches_the_cpu() {
    let mut scene = hybrid_scene::demo_scene();
    let (near, far) = scene.camera.near_far();
    scene.camera.projection = hybrid_scene::Projection::Orthographic { height: 8.0, near, far };
    let (w, h) = (123, 77);
    let c = compare("demo (orthographic)", &scene, w, h);
    check("demo (orthographic)", &c, w, h);
}
