//! Steady-state stage timings of the CPU frame at a scene's camera: the fastest and the median
//! of N frames after one warm-up frame, per stage. The fastest frame is the one least disturbed
//! by other work on a shared machine, so A/B comparisons of two builds run alternately in one
//! sitting are best read from it (see BENCHMARKS.md).
//!
//! `cargo run --release -p hybrid-cpu --example frame_stages -- SCENE [FRAMES] [WIDTHxHEIGHT]`
//! (default 10 frames at 1920x1080). Environment: `MODE=all|rt-only|raster` (default hybrid),
//! `CLIP=1` traces the capsule after the raster with rays clipped at its depth, `NO_SPHERES=1`
//! leaves the point cloud out of the trace stage, `VIS=auto|projected|bvh` picks how the capsule
//! finds its primary rays' spheres (default auto).

use std::process::ExitCode;

use hybrid_core::{FrameSettings, Mode};
use hybrid_cpu::capsule::PrimaryVisibility;
use hybrid_cpu::frame::CpuRenderer;

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("frame_stages: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<(), String> {
    let mut args = std::env::args().skip(1);
    let path = args.next().ok_or("usage: frame_stages SCENE [FRAMES] [WIDTHxHEIGHT]")?;
    let frames: usize = match args.next() {
        Some(n) => n.parse().map_err(|_| format!("FRAMES must be a positive integer, not `{n}`"))?,
        None => 10,
    };
    let (width, height) = match args.next() {
        Some(size) => size
            .split_once('x')
            .and_then(|(w, h)| Some((w.parse().ok()?, h.parse().ok()?)))
            .filter(|&(w, h): &(u32, u32)| w > 0 && h > 0)
            .ok_or(format!("size must be WIDTHxHEIGHT, not `{size}`"))?,
        None => (1920, 1080),
    };
    if frames == 0 {
        return Err("FRAMES must be at least 1".into());
    }
    let mode = match std::env::var("MODE").as_deref() {
        Ok("all") => Mode::All,
        Ok("rt-only") => Mode::RtOnly,
        Ok("raster") => Mode::Raster,
        Ok("hybrid") | Err(_) => Mode::Hybrid,
        Ok(other) => return Err(format!("MODE must be hybrid, all, rt-only or raster, not `{other}`")),
    };
    let scene = hybrid_scene::file::load_scene(std::path::Path::new(&path)).map_err(|e| e.to_string())?;
    let mut renderer = CpuRenderer::new(&scene).map_err(|e| format!("{path}: {e}"))?;
    renderer.clip_capsule_at_raster_depth = std::env::var_os("CLIP").is_some();
    renderer.spheres_in_trace = std::env::var_os("NO_SPHERES").is_none();
    renderer.set_capsule_visibility(match std::env::var("VIS").as_deref() {
        Err(_) | Ok("auto") => PrimaryVisibility::Auto,
        Ok("projected") => PrimaryVisibility::Projected,
        Ok("bvh") => PrimaryVisibility::Bvh,
        Ok(other) => return Err(format!("VIS must be auto, projected or bvh, not `{other}`")),
    });
    let settings = FrameSettings { width, height, mode };
    // Per stage: frame, capsule, raster (with lighting), lighting, trace, blend.
    let mut times: [Vec<f64>; 6] = Default::default();
    for i in 0..=frames {
        let frame = renderer.render(&scene.camera, settings, &mut |_| {});
        let t = &frame.report.timings_ms;
        if i > 0 {
            for (v, ms) in times.iter_mut().zip([t.frame, t.capsule, t.raster, t.lighting, t.trace, t.blend]) {
                v.push(ms);
            }
        }
        renderer.recycle(frame);
    }
    for v in &mut times {
        v.sort_by(f64::total_cmp);
    }
    let row = |name: &str, pick: &dyn Fn(&[f64]) -> f64| {
        let [f, c, r, l, t, b] = times.each_ref().map(|v| pick(v));
        println!("{name:<6} frame {f:7.1}  capsule {c:6.1}  raster {r:6.1} (lighting {l:5.1})  trace {t:6.1}  blend {b:5.1} ms");
    };
    println!("{path}, {width}x{height}, {mode:?}, {frames} frames");
    row("min", &|v| v[0]);
    row("median", &|v| v[v.len() / 2]);
    Ok(())
}
