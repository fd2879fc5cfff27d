//! The G-buffer pass on the GPU backend against the CPU backend's rasterizer, in one run:
//! the same scene, camera and size, frames interleaved so both see the same machine load.
//! On lavapipe (Mesa's software Vulkan, itself a CPU rasterizer) this compares two CPU
//! rasterizers; on a real GPU it shows the GPU's lead.
//!
//! ```sh
//! cargo bench -p hybrid-gpu --bench raster_vs_cpu                       # sponza-spheres, 1280×720
//! HYBRID_BENCH_SCENE=scenes/dining-room.toml HYBRID_BENCH_SIZE=1920x1080 HYBRID_BENCH_FRAMES=9 \
//!   cargo bench -p hybrid-gpu --bench raster_vs_cpu
//! ```
//! GPU times are timestamp queries at the raster pass's boundaries (and the wall time of
//! submit → done); CPU times are wall-clock. Medians over the frames after one warm-up.

use std::path::{Path, PathBuf};
use std::time::Instant;

use hybrid_core::GBuffer;
use hybrid_core::PreparedScene;
use hybrid_gpu::lighting::LightingPass;
use hybrid_gpu::raster::RasterPass;
use hybrid_gpu::scene::SceneGpu;
use hybrid_gpu::targets::FrameTargets;
use hybrid_gpu::timing::StageTimer;
use hybrid_gpu::{AdapterChoice, GpuContext};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let scene_path = std::env::var("HYBRID_BENCH_SCENE").map_or(root.join("scenes/sponza-spheres.toml"), PathBuf::from);
    let size = std::env::var("HYBRID_BENCH_SIZE").unwrap_or_else(|_| "1280x720".into());
    let (w, h) = size.split_once('x').and_then(|(a, b)| Some((a.parse().ok()?, b.parse().ok()?))).expect("HYBRID_BENCH_SIZE=WxH");
    let frames: usize = std::env::var("HYBRID_BENCH_FRAMES").ok().and_then(|s| s.parse().ok()).unwrap_or(7);

    let scene = hybrid_scene::load_scene(&scene_path).unwrap_or_else(|e| panic!("{e:?}"));
    let ctx = GpuContext::new(AdapterChoice::Any).unwrap_or_else(|e| panic!("{e}"));
    let prepared = PreparedScene::new(&scene);
    let gpu_scene = SceneGpu::new(&ctx, &prepared).unwrap_or_else(|e| panic!("{e}"));
    let raster = RasterPass::new(&ctx, &gpu_scene);
    let lighting = LightingPass::new(&ctx, &gpu_scene);
    let targets = FrameTargets::new(&ctx.device, w, h);
    let mut timer = StageTimer::new(&ctx);
    let mut cpu_gbuffer = GBuffer::new(w, h);
    let camera = scene.camera;

    let (mut cpu_raster, mut cpu_lighting, mut gpu_raster, mut gpu_lighting, mut gpu_wall) = (vec![], vec![], vec![], vec![], vec![]);
    for frame in 0..=frames {
        let t = Instant::now();
        hybrid_cpu::raster::rasterize_into(&prepared, &camera, None, &mut cpu_gbuffer);
        let c_raster = t.elapsed().as_secs_f64() * 1e3;
        let t = Instant::now();
        let lit = hybrid_cpu::lighting::deferred_lighting(&cpu_gbuffer, &scene, &camera);
        let c_light = t.elapsed().as_secs_f64() * 1e3;
        drop(lit);

        timer.begin_frame();
        gpu_scene.write_uniforms(&ctx, &camera, w, h, &scene.environment);
        let t = Instant::now();
        let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("bench") });
        raster.encode(&mut encoder, &gpu_scene, &targets, true, &mut timer);
        lighting.encode(&mut encoder, &gpu_scene, &targets, &mut timer);
        timer.resolve(&mut encoder);
        ctx.queue.submit([encoder.finish()]);
        ctx.wait().expect("GPU");
        let wall = t.elapsed().as_secs_f64() * 1e3;
        let g = timer.read(&ctx).expect("timestamps");
        if frame == 0 {
            continue; // warm-up: pipelines, caches, page faults
        }
        cpu_raster.push(c_raster);
        cpu_lighting.push(c_light);
        gpu_wall.push(wall);
        if let Some(g) = g {
            gpu_raster.push(g.raster);
            gpu_lighting.push(g.lighting);
        }
    }
    let s = &ctx.summary;
    println!("# raster_vs_cpu — {}, {w}×{h}, {frames} frames after 1 warm-up (medians)", scene_path.display());
    println!(
        "GPU adapter: {} ({}, {}), {} CPU threads for the CPU backend",
        s.name,
        s.backend,
        s.device_type,
        rayon::current_num_threads()
    );
    println!("| stage | CPU backend ms | GPU backend ms (timestamps) | CPU / GPU |");
    println!("|---|---|---|---|");
    let row = |name: &str, c: &[f64], g: &[f64]| {
        if g.is_empty() {
            println!("| {name} | {:.2} | (no timestamps) | |", median(c.to_vec()));
        } else {
            let (c, g) = (median(c.to_vec()), median(g.to_vec()));
            println!("| {name} | {c:.2} | {g:.2} | {:.2}× |", c / g);
        }
    };
    row("G-buffer (raster)", &cpu_raster, &gpu_raster);
    row("deferred lighting", &cpu_lighting, &gpu_lighting);
    let cpu_total: Vec<f64> = cpu_raster.iter().zip(&cpu_lighting).map(|(a, b)| a + b).collect();
    println!(
        "| raster + lighting, GPU wall (submit → done) | {:.2} | {:.2} | {:.2}× |",
        median(cpu_total.clone()),
        median(gpu_wall.clone()),
        median(cpu_total) / median(gpu_wall)
    );
}
