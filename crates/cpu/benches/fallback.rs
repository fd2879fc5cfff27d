//! Fallback stage benchmark (issue 18): the per-pixel lookups of `FallbackCache::stage` on the
//! Sponza Spheres scene (`scenes/sponza-spheres.toml`, with `../shared/assets` beside the
//! repository) at 640×360, from its camera and at 6 s along its path. Every covered pixel is left
//! out by the trace (mask 0, as in `--mode raster`), and the maps and probes are rendered once
//! beforehand and then cached, as in a static view: what is measured is the lookups.
//!
//! Run: `cargo bench -p hybrid-cpu --bench fallback` (criterion, wall clock).
//!
//! CPU-time mode, for before/after comparisons on a noisy or loaded machine:
//! `FALLBACK_CPU=1 cargo bench -p hybrid-cpu --bench fallback` prints, per view, the best CPU
//! time of the stage on a 1-thread pool and its best wall time on the global pool over
//! `TRACE_PASSES` passes (default 5), and a checksum of the three fallback buffers, which two
//! builds that give the same images share.

#[path = "trace_scenes/mod.rs"]
mod trace_scenes;

use std::path::Path;

use criterion::{Criterion, criterion_group};
use glam::Vec3;
use hybrid_core::{GBuffer, PreparedScene};
use hybrid_cpu::fallback::FallbackCache;
use hybrid_cpu::raster::rasterize;
use hybrid_scene::{Camera, load_scene};
use trace_scenes::{HEIGHT, WIDTH, measure, report};

const SCENE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenes/sponza-spheres.toml");

/// The scene's views: its camera, and its path at 6 s (closer to the glass spheres).
fn views(scene: &hybrid_scene::Scene) -> Vec<(&'static str, Camera)> {
    let mut v = vec![("camera", scene.camera)];
    if let Some(path) = &scene.camera_path {
        v.push(("path 6 s", path.camera_at(&scene.camera, 6.0)));
    }
    v
}

/// The view's G-buffer (mask 0 everywhere) and a cache with its maps and probes rendered.
fn prepared_view<'s>(prepared: &PreparedScene<'s>, camera: &Camera) -> (GBuffer, FallbackCache) {
    let g = rasterize(prepared, camera, WIDTH, HEIGHT, None);
    let mut cache = FallbackCache::new(prepared, false);
    let mut out = [Vec::new(), Vec::new(), Vec::new()];
    let [s, m, r] = &mut out;
    cache.stage(prepared, None, &g, camera, [s, m, r]);
    (g, cache)
}

fn checksum(buffers: &[Vec<Vec3>; 3]) -> u64 {
    buffers
        .iter()
        .flatten()
        .flat_map(|v| v.to_array().map(f32::to_bits))
        .fold(0xcbf2_9ce4_8422_2325u64, |h, b| (h ^ b as u64).wrapping_mul(0x0100_0000_01b3))
}

fn fallback(c: &mut Criterion) {
    let scene = load_scene(Path::new(SCENE)).expect("scenes/sponza-spheres.toml with ../shared/assets");
    let prepared = PreparedScene::new(&scene);
    let mut group = c.benchmark_group("fallback lookups, sponza-spheres 640x360");
    group.sample_size(20);
    for (name, camera) in views(&scene) {
        let (g, mut cache) = prepared_view(&prepared, &camera);
        let mut out = [Vec::new(), Vec::new(), Vec::new()];
        group.bench_function(name, |b| {
            b.iter(|| {
                let [s, m, r] = &mut out;
                cache.stage(&prepared, None, &g, &camera, [s, m, r])
            })
        });
    }
    group.finish();
}

fn cpu_mode() {
    let scene = load_scene(Path::new(SCENE)).expect("scenes/sponza-spheres.toml with ../shared/assets");
    let prepared = PreparedScene::new(&scene);
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("pool");
    for (name, camera) in views(&scene) {
        let (g, mut cache) = prepared_view(&prepared, &camera);
        let mut out = [Vec::new(), Vec::new(), Vec::new()];
        let looked_up = g.object_id.iter().filter(|&&id| hybrid_core::is_polygon(id)).count();
        let renders = (cache.shadow_map_renders.iter().sum::<u64>(), cache.probe_renders);
        let times = measure(&one, || {
            let [s, m, r] = &mut out;
            cache.stage(&prepared, None, &g, &camera, [s, m, r]);
        });
        // Nothing was rendered again while measuring: the lookups alone.
        assert_eq!((cache.shadow_map_renders.iter().sum::<u64>(), cache.probe_renders), renders);
        report("fallback", name, looked_up, "px", times);
        println!("{:>10} {name:<22} checksum {:016x}", "", checksum(&out));
    }
}

criterion_group!(benches, fallback);

fn main() {
    // Our kernels' instruction-set path (`HYBRID_ISA` forces one).
    let isa = hybrid_cpu::isa::init_from_env().unwrap_or_else(|e| {
        eprintln!("error: {e}");
        std::process::exit(2)
    });
    eprintln!("kernels: {}", isa.name());
    if std::env::var("FALLBACK_CPU").is_ok() {
        cpu_mode();
        return;
    }
    benches();
    Criterion::default().configure_from_args().final_summary();
}
