//! The GPU heuristic passes (pixel count per object, mask) and the blend pass against the CPU
//! backend: each pass gets the CPU's inputs uploaded, so it is compared on its own.
//!
//! Needs a wgpu adapter (lavapipe in CI): the tests fail, not skip, when there is none.

use glam::Vec3;
use hybrid_core::blend::{blend_pixel, encode_srgb};
use hybrid_core::{FrameBuffers, FrameSettings, GBuffer, Mode, NO_OBJECT, RT_SCENE_OBJECT};
use hybrid_cpu::frame::CpuRenderer;
use hybrid_gpu::GpuContext;
use hybrid_gpu::blend::BlendPass;
use hybrid_gpu::heuristic::{HeuristicPasses, MaskSelection};
use hybrid_gpu::readback;
use hybrid_gpu::targets::FrameTargets;
use hybrid_gpu::timing::StageTimer;
use hybrid_heuristic::{count_visible_pixels, write_mask};
use hybrid_scene::demo_scene;

mod support;
use support::{context, mean_flip, rgb8};

/// Deterministic pseudo-random numbers (LCG).
struct Lcg(u32);
impl Lcg {
    fn next(&mut self) -> u32 {
        self.0 = self.0.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        self.0
    }
}

/// The demo scene's G-buffer from the CPU raster, with a block of RT-scene pixels and a few
/// out-of-range ids painted in (they must be neither counted nor selected).
fn demo_gbuffer(w: u32, h: u32) -> (GBuffer, usize) {
    let scene = demo_scene();
    let prepared = hybrid_core::PreparedScene::new(&scene);
    let mut g = hybrid_cpu::raster::rasterize(&prepared, &scene.camera, w, h, None);
    let objects = scene.objects.len();
    for y in h / 3..h / 2 {
        for x in w / 4..w / 2 {
            g.object_id[(y * w + x) as usize] = RT_SCENE_OBJECT;
        }
    }
    for x in 0..7 {
        g.object_id[(h as usize - 1) * w as usize + x] = objects as u32 + x as u32;
    }
    (g, objects)
}

/// Runs the count pass on `ids` (uploaded into the object-id target) and reads A back.
fn gpu_counts(ctx: &GpuContext, passes: &HeuristicPasses, w: u32, h: u32, ids: &[u32]) -> Vec<u64> {
    let targets = FrameTargets::new(&ctx.device, w, h);
    readback::write_texture_bytes(ctx, &targets.object_id, bytemuck::cast_slice(ids));
    let mut timer = StageTimer::new(ctx);
    timer.begin_frame();
    // Twice into the same encoder: the clear must reset the first pass's counts.
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    passes.encode_count(&mut encoder, &targets, &mut timer);
    passes.encode_count(&mut encoder, &targets, &mut timer);
    ctx.queue.submit([encoder.finish()]);
    passes.read_counts(ctx).expect("counts read back")
}

#[test]
fn pixel_counts_match_the_cpu_on_the_demo_scene() {
    let ctx = context();
    // Width not a multiple of the 16-pixel spans nor of the workgroup.
    let (w, h) = (173, 97);
    let (g, objects) = demo_gbuffer(w, h);
    let cpu = count_visible_pixels(&g.object_id, objects);
    let passes = HeuristicPasses::new(&ctx, objects as u32);
    let gpu = gpu_counts(&ctx, &passes, w, h, &g.object_id);
    eprintln!("demo {w}x{h}: {objects} objects, A = {cpu:?}");
    assert!(cpu.iter().filter(|&&a| a > 0).count() >= 3, "the demo view should show several objects: {cpu:?}");
    assert_eq!(gpu, cpu);
    // A second, larger frame: the same passes, other targets.
    let (g, _) = demo_gbuffer(320, 240);
    assert_eq!(gpu_counts(&ctx, &passes, 320, 240, &g.object_id), count_visible_pixels(&g.object_id, objects));
}

/// Random runs of ids (0..40, sky, RT-scene) of 0 to 40 pixels, crossing rows and spans.
fn random_ids(n: usize, seed: u32) -> Vec<u32> {
    let mut rng = Lcg(seed);
    let mut ids = Vec::with_capacity(n);
    while ids.len() < n {
        let r = rng.next();
        let id = match r >> 29 {
            0 => NO_OBJECT,
            1 => RT_SCENE_OBJECT,
            _ => (r >> 8) % 40,
        };
        let run = ((r >> 3) % 41) as usize;
        ids.extend(std::iter::repeat_n(id, run.min(n - ids.len())));
    }
    ids
}

#[test]
fn pixel_counts_match_the_cpu_on_random_ids() {
    let ctx = context();
    let (w, h) = (131, 75);
    let ids = random_ids((w * h) as usize, 7);
    // Fewer objects than ids in use: the higher ids must be dropped, as the CPU does.
    for objects in [40, 25, 1] {
        let cpu = count_visible_pixels(&ids, objects);
        let passes = HeuristicPasses::new(&ctx, objects as u32);
        assert_eq!(gpu_counts(&ctx, &passes, w, h, &ids), cpu, "{objects} objects");
    }
    let passes = HeuristicPasses::new(&ctx, 0);
    assert_eq!(gpu_counts(&ctx, &passes, w, h, &ids), Vec::<u64>::new());
}

/// Runs the mask pass for `selection` over `g`'s ids (the mask target starts at 0.5 everywhere,
/// so every pixel must be written) and reads the mask back.
fn gpu_mask(ctx: &GpuContext, passes: &HeuristicPasses, g: &GBuffer, selection: MaskSelection<'_>) -> Vec<f32> {
    let targets = FrameTargets::new(&ctx.device, g.width, g.height);
    readback::write_texture_bytes(ctx, &targets.object_id, bytemuck::cast_slice(&g.object_id));
    readback::write_texture_bytes(ctx, &targets.mask, bytemuck::cast_slice(&vec![0.5f32; g.len()]));
    let mut timer = StageTimer::new(ctx);
    timer.begin_frame();
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    passes.encode_mask(ctx, &mut encoder, &targets, selection, &mut timer);
    ctx.queue.submit([encoder.finish()]);
    readback::read_f32(ctx, &targets.mask).expect("mask read back")
}

fn mismatches(a: &[f32], b: &[f32]) -> usize {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).filter(|(x, y)| x.to_bits() != y.to_bits()).count()
}

#[test]
fn masks_match_the_cpu() {
    let ctx = context();
    let (w, h) = (173, 97);
    let (g, objects) = demo_gbuffer(w, h);
    let passes = HeuristicPasses::new(&ctx, objects as u32);

    // hybrid / all: random selections (and all, and none) → write_mask exactly.
    let mut rng = Lcg(99);
    let random: Vec<bool> = (0..objects).map(|_| rng.next() >> 31 == 1).collect();
    let all = vec![true; objects];
    let none = vec![false; objects];
    let short = vec![true; objects / 2]; // ids beyond the selection's length get 0
    for selected in [&random, &all, &none, &short] {
        let mut cpu = vec![0.5f32; g.len()];
        write_mask(&g.object_id, selected, &mut cpu);
        let gpu = gpu_mask(&ctx, &passes, &g, MaskSelection::Objects(selected));
        let ones = cpu.iter().filter(|&&m| m == 1.0).count();
        let bad = mismatches(&gpu, &cpu);
        eprintln!("selection {selected:?}: {ones} masked pixels, {bad} mismatches");
        assert_eq!(bad, 0, "selection {selected:?}");
    }
    // The random selection is not degenerate (some pixels on, some off).
    let mut cpu = vec![0.0; g.len()];
    write_mask(&g.object_id, &random, &mut cpu);
    assert!(cpu.contains(&1.0) && cpu.iter().any(|&m| m == 0.0 && m.to_bits() == 0));

    // rt-only: the CPU frame's rule, every pixel with an id (RT-scene included).
    let cpu: Vec<f32> = g.object_id.iter().map(|&id| if id != NO_OBJECT { 1.0 } else { 0.0 }).collect();
    assert!(g.object_id.contains(&NO_OBJECT) && g.object_id.contains(&RT_SCENE_OBJECT));
    assert_eq!(mismatches(&gpu_mask(&ctx, &passes, &g, MaskSelection::AllCovered), &cpu), 0);

    // raster: nothing traced.
    assert_eq!(mismatches(&gpu_mask(&ctx, &passes, &g, MaskSelection::Nothing), &vec![0.0; g.len()]), 0);
}

/// Uploads the blend inputs (G-buffer with optical + mask, and the frame buffers), runs the blend
/// pass and reads the final image back.
fn gpu_blend(ctx: &GpuContext, g: &GBuffer, b: &FrameBuffers) -> (Vec<[u8; 4]>, FrameTargets) {
    let targets = FrameTargets::new(&ctx.device, g.width, g.height);
    readback::write_gbuffer(ctx, &targets, g);
    readback::write_frame_buffers(ctx, &targets, b);
    let pass = BlendPass::new(ctx);
    let mut timer = StageTimer::new(ctx);
    timer.begin_frame();
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    pass.encode(&mut encoder, &targets, None, &mut timer);
    timer.resolve(&mut encoder);
    ctx.queue.submit([encoder.finish()]);
    match timer.read(ctx).expect("timestamps read back") {
        Some(t) => eprintln!("blend pass {}x{}: {:.3} ms GPU", g.width, g.height, t.blend),
        None => eprintln!("no timestamp queries on this adapter"),
    }
    let image = readback::read_rgba8(ctx, &targets.final_image).expect("final image read back");
    (image, targets)
}

#[test]
fn hand_computed_blend_pixels() {
    let ctx = context();
    // Four pixels, inputs exact in f16:
    // 0: masked. L = 0.5, S = 0.75 → C = 0.25; M = 1, R = 0.25, OM = 0.5, opacity 0.75 (OR = 0.25):
    //    CM = 0.5·1 + 0.5·(0.25·0.25 + 0.75·0.25) = 0.625; CR = 0.25·0.25 + 0.75·(0.5·1 + 0.5·0.25)
    //    = 0.53125; final 0.578125 → sRGB 1.055·0.578125^(1/2.4) − 0.055 = 0.78464 → ·255 + 0.5 = 200.6 → 200.
    //    Green: L = 0.25, S = 1 → C = 0.25; M = 0, R = 0: CM = 0.5·0.75·0.25 = 0.09375, CR =
    //    0.75·0.5·0.25 = 0.09375 → sRGB 0.33845 → 86.8 → 86. Blue: C = 0, M = 0, R = 1 →
    //    CM = 0.5·0.25 = 0.125, CR = 0.25 + 0.75·0 = 0.25 → 0.1875 → sRGB 0.47019 → 120.4 → 120.
    // 1: mask 5e-5 (< 1e-4: not traced) → the lighting (0.5, 0.25, 0): 188, 137, 0.
    // 2: not traced, L = (+inf, 2, −1): non-finite → 0, clamped → 255, 0.
    // 3: masked perfect mirror (OM = 1, opacity 1) → M = (0.0031308 → ·12.92 = 0.04045 → 10.8 → 10, 1 → 255, 0.5 → 188).
    let mut g = GBuffer::new(4, 1);
    g.mask = vec![1.0, 5e-5, 0.0, 1.0];
    g.optical = vec![Vec3::new(0.5, 1.5, 0.75), Vec3::new(1.0, 1.0, 0.0), Vec3::new(0.0, 1.0, 1.0), Vec3::new(1.0, 1.0, 1.0)];
    let b = FrameBuffers {
        width: 4,
        height: 1,
        lighting: vec![Vec3::new(0.5, 0.25, 0.0), Vec3::new(0.5, 0.25, 0.0), Vec3::new(f32::INFINITY, 2.0, -1.0), Vec3::splat(0.3)],
        shadow: vec![Vec3::new(0.75, 1.0, 1.0), Vec3::ONE, Vec3::ONE, Vec3::ONE],
        reflection: vec![Vec3::new(1.0, 0.0, 0.0), Vec3::ONE, Vec3::ONE, Vec3::new(0.003_130_8, 1.0, 0.5)],
        refraction: vec![Vec3::new(0.25, 0.0, 1.0), Vec3::ONE, Vec3::ONE, Vec3::ZERO],
        ..FrameBuffers::default()
    };
    let expected = [[200, 86, 120, 255], [188, 137, 0, 255], [0, 255, 0, 255], [10, 255, 188, 255]];
    // The CPU twin agrees with the hand values (f16-exact inputs but pixel 3's 0.0031308, whose
    // f16 rounding does not move its byte).
    for (i, want) in expected.iter().enumerate() {
        let cpu = encode_srgb(blend_pixel(b.lighting[i], b.shadow[i], b.reflection[i], b.refraction[i], g.optical[i], g.mask[i]));
        assert_eq!(&cpu, want, "CPU pixel {i}");
    }
    let (gpu, _) = gpu_blend(&ctx, &g, &b);
    assert_eq!(gpu, expected.to_vec());
}

fn mean_flip_rgba(w: u32, h: u32, reference: &[[u8; 4]], test: &[[u8; 4]]) -> f32 {
    mean_flip(w, h, &rgb8(reference), &rgb8(test))
}

/// (max per-channel difference, differing bytes)
fn byte_diff(a: &[[u8; 4]], b: &[[u8; 4]]) -> (u8, usize) {
    assert_eq!(a.len(), b.len());
    let diffs = a.iter().zip(b).flat_map(|(p, q)| (0..4).map(move |c| p[c].abs_diff(q[c])));
    diffs.fold((0, 0), |(max, n), d| (max.max(d), n + usize::from(d > 0)))
}

#[test]
fn blend_matches_the_cpu_frame_on_the_demo_scene() {
    let ctx = context();
    let scene = demo_scene();
    let (w, h) = (160, 120);
    let mut renderer = CpuRenderer::new(&scene).expect("demo scene prepares");
    let frame = renderer.render(&scene.camera, FrameSettings { width: w, height: h, mode: Mode::All }, &mut |_| {});
    let (g, b) = (&frame.gbuffer, &frame.buffers);
    // The frame has what the blend mixes: traced pixels, mirrors and glass.
    let masked = g.mask.iter().filter(|&&m| m > 0.0).count();
    let mirrors = (0..g.len()).filter(|&i| g.mask[i] > 0.0 && g.optical[i].x > 0.0).count();
    let glass = (0..g.len()).filter(|&i| g.mask[i] > 0.0 && g.optical[i].z < 1.0).count();
    eprintln!("demo {w}x{h} all: {masked} masked pixels, {mirrors} reflective, {glass} transparent");
    assert!(masked > 0 && mirrors > 0 && glass > 0);

    let (gpu, targets) = gpu_blend(&ctx, g, b);

    // Against the CPU's own final image (its inputs are f32; the GPU's went through Rgba16Float).
    let (max, bytes) = byte_diff(&gpu, &b.final_srgb);
    let flip = mean_flip_rgba(w, h, &b.final_srgb, &gpu);
    eprintln!("GPU blend vs CPU final_srgb: max channel diff {max}, {bytes} differing bytes of {}, mean FLIP {flip:.5}", gpu.len() * 4);
    assert!(max <= 2, "max channel difference {max}");
    assert!(flip <= 0.005, "mean FLIP {flip}");

    // Against the CPU blend of exactly the GPU's inputs (read back after the f16 rounding): only
    // pow/rounding-boundary differences remain.
    let g16 = readback::read_gbuffer(&ctx, &targets).expect("G-buffer read back");
    let b16 = readback::read_frame_buffers(&ctx, &targets).expect("buffers read back");
    let cpu16 = hybrid_cpu::blend::blend(&g16, &b16.lighting, &b16.shadow, &b16.reflection, &b16.refraction);
    let (max16, bytes16) = byte_diff(&gpu, &cpu16);
    eprintln!("GPU blend vs CPU blend of the f16 inputs: max channel diff {max16}, {bytes16} differing bytes");
    assert!(max16 <= 1, "max channel difference {max16} on identical inputs");
    assert!(bytes16 * 1000 <= gpu.len() * 4, "{bytes16} bytes differ on identical inputs");
    assert!(gpu.iter().all(|p| p[3] == 255));
    // The mask was not lost on the way (R32Float is exact).
    assert_eq!(g16.mask, g.mask);
}
