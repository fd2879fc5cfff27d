//! Issue 19: the GPU backend's hardware ray-tracing path (ray queries over acceleration
//! structures) against its software BVH2 traversal, in one run: two renderers of the same scene on
//! the same adapter, frames interleaved so both see the same machine load. Prints medians of the
//! trace stage (shadows, reflections, refractions), the capsule (point clouds) and, in rt-only
//! mode, the primary rays (reported as `raster`), all from timestamp queries at pass boundaries,
//! and the acceleration structures' build.
//!
//! ```sh
//! cargo bench -p hybrid-gpu --bench trace_hw_vs_sw                    # demo scene, 640×360
//! HYBRID_BENCH_SCENE=scenes/tree-merge.toml HYBRID_BENCH_SIZE=1280x720 HYBRID_BENCH_FRAMES=9 \
//!   HYBRID_BENCH_MODE=rt-only cargo bench -p hybrid-gpu --bench trace_hw_vs_sw
//! ```
//! Needs an adapter with ray queries (Mesa 25's lavapipe has them); says so and stops otherwise.

use std::path::PathBuf;
use std::sync::Arc;

use hybrid_core::{FrameSettings, Mode};
use hybrid_gpu::frame::GpuRenderer;
use hybrid_gpu::{AdapterChoice, GpuContext, RtChoice};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let scene_path = std::env::var("HYBRID_BENCH_SCENE").ok().map(PathBuf::from);
    let size = std::env::var("HYBRID_BENCH_SIZE").unwrap_or_else(|_| "640x360".into());
    let (w, h) = size.split_once('x').and_then(|(a, b)| Some((a.parse().ok()?, b.parse().ok()?))).expect("HYBRID_BENCH_SIZE=WxH");
    let frames: usize = std::env::var("HYBRID_BENCH_FRAMES").ok().and_then(|s| s.parse().ok()).unwrap_or(7);
    let mode = match std::env::var("HYBRID_BENCH_MODE").as_deref() {
        Ok("rt-only") => Mode::RtOnly,
        Ok("all") => Mode::All,
        _ => Mode::Hybrid,
    };
    // Relative scene paths are taken from the repository root (cargo bench runs in the crate).
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let scene = match &scene_path {
        Some(p) => hybrid_scene::load_scene(&if p.is_absolute() { p.clone() } else { root.join(p) }).unwrap_or_else(|e| panic!("{e:?}")),
        None => hybrid_scene::demo_scene(),
    };
    let name = scene_path.as_ref().map_or("demo scene".to_string(), |p| p.display().to_string());
    let ctx = Arc::new(GpuContext::new(AdapterChoice::Any).unwrap_or_else(|e| panic!("{e}")));
    if !ctx.ray_query {
        println!("trace_hw_vs_sw: the adapter `{}` has no ray queries; nothing to compare", ctx.summary.name);
        return;
    }
    let mut sw = GpuRenderer::with_rt(ctx.clone(), &scene, RtChoice::Software).unwrap_or_else(|e| panic!("{e}"));
    let mut hw = GpuRenderer::with_rt(ctx.clone(), &scene, RtChoice::Hardware).unwrap_or_else(|e| panic!("{e}"));
    let settings = FrameSettings { width: w, height: h, mode };
    let mut times = [[vec![], vec![], vec![]], [vec![], vec![], vec![]]];
    let mut build_as = 0.0;
    for frame in 0..=frames {
        for (k, r) in [&mut sw, &mut hw].into_iter().enumerate() {
            let report = r.render_to_targets(&scene.camera, settings, &mut |_| {}).unwrap_or_else(|e| panic!("{e}"));
            let g = report.gpu_timings_ms.expect("timestamp queries");
            if k == 1 {
                build_as = g.build_as.unwrap_or(0.0);
            }
            if frame > 0 {
                times[k][0].push(g.trace);
                times[k][1].push(g.capsule);
                times[k][2].push(g.raster);
            }
        }
    }
    let s = &ctx.summary;
    println!("# trace_hw_vs_sw — {name}, {w}×{h}, {mode}, {frames} frames after 1 warm-up (medians, ms)");
    println!("GPU adapter: {} ({}, {}, {})", s.name, s.backend, s.device_type, s.driver);
    println!("acceleration structures built in {build_as:.2} ms (once per scene)");
    println!("| stage | software BVH2 | hardware ray queries | hw / sw |");
    println!("|---|---|---|---|");
    let stages = ["trace (shadow + reflection + refraction)", "capsule (point-cloud primary rays)", "raster (rt-only: primary rays)"];
    for (i, stage) in stages.iter().enumerate() {
        let (a, b) = (median(times[0][i].clone()), median(times[1][i].clone()));
        // The raster entry is the primary rays only in rt-only mode.
        if a > 0.0 && (i < 2 || mode == Mode::RtOnly) {
            println!("| {stage} | {a:.2} | {b:.2} | {:.2}× |", b / a);
        }
    }
}
