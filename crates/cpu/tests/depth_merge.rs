//! Paper 2's acceptance check on the shipped tree scene: the depth-merged frame (capsule packed
//! frame unpacked and depth-tested against the rasterized polygons) equals the `rt-only` render
//! of the combined scene except at silhouette pixels.

use std::path::Path;

use hybrid_core::{FrameSettings, Mode, RT_SCENE_OBJECT};
use hybrid_cpu::frame::{CpuRenderer, Frame};
use hybrid_scene::load_scene;

fn tree_scene() -> hybrid_scene::Scene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/tree-merge.toml");
    load_scene(&path).expect("scenes/tree-merge.toml loads (needs ../shared/assets beside the repository)")
}

fn rgb8(frame: &Frame) -> Vec<u8> {
    frame.buffers.final_srgb.iter().flat_map(|p| [p[0], p[1], p[2]]).collect()
}

#[test]
fn merged_frame_matches_rt_only_except_at_silhouettes() {
    let scene = tree_scene();
    let mut renderer = CpuRenderer::new(&scene).unwrap();
    let (w, h) = (200, 112);
    for time in [0.0, 10.0] {
        let camera = scene.camera_path.as_ref().unwrap().camera_at(&scene.camera, time);
        let merged = renderer.render(&camera, FrameSettings { width: w, height: h, mode: Mode::All }, &mut |_| {});
        let reference = renderer.render(&camera, FrameSettings { width: w, height: h, mode: Mode::RtOnly }, &mut |_| {});
        // The capsule is visible in both, and polygons occlude part of it.
        let rt_pixels = merged.gbuffer.object_id.iter().filter(|&&id| id == RT_SCENE_OBJECT).count();
        assert!(rt_pixels > (w * h) as usize / 20, "t={time}: only {rt_pixels} RT-scene pixels");
        let packed_hits = merged.rt_packed.as_ref().unwrap().texels.iter().filter(|t| t[0] != 0 || t[1] != 0).count();
        assert!(packed_hits > rt_pixels, "t={time}: polygons should hide some spheres ({packed_hits} hits, {rt_pixels} shown)");

        let a = nv_flip::FlipImageRgb8::with_data(w, h, &rgb8(&reference));
        let b = nv_flip::FlipImageRgb8::with_data(w, h, &rgb8(&merged));
        let err = nv_flip::flip(a, b, nv_flip::DEFAULT_PIXELS_PER_DEGREE).to_vec();
        let bad = err.iter().filter(|&&e| e > 0.1).count();
        let share = bad as f64 / err.len() as f64;
        eprintln!("t={time}: {bad} of {} pixels differ by FLIP > 0.1 ({:.3}%)", err.len(), share * 100.0);
        assert!(share <= 0.005, "t={time}: {:.3}% of pixels differ by FLIP > 0.1 (limit 0.5%)", share * 100.0);
    }
}
