//! Every shipped asset scene renders in every mode at a small size: real models, textures and
//! point clouds through the whole frame. Needs `../shared/assets` beside the repository.

use std::path::Path;

use hybrid_core::{FrameSettings, Mode, NO_OBJECT};
use hybrid_cpu::frame::CpuRenderer;
use hybrid_scene::load_scene;

fn render_all_modes(name: &str) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes").join(name);
    let scene = load_scene(&path).unwrap_or_else(|e| panic!("{e}"));
    let mut renderer = CpuRenderer::new(&scene).unwrap();
    let (w, h) = (96, 54);
    let mut finals = Vec::new();
    for mode in Mode::ALL {
        let f = renderer.render(&scene.camera, FrameSettings { width: w, height: h, mode }, &mut |_| {});
        let covered = f.gbuffer.object_id.iter().filter(|&&id| id != NO_OBJECT).count();
        assert!(covered > (w * h) as usize / 4, "{name} {mode}: only {covered} pixels covered");
        assert!(f.buffers.lighting.iter().all(|c| c.is_finite()), "{name} {mode}: non-finite lighting");
        let mean: f64 =
            f.buffers.final_srgb.iter().map(|p| (p[0] as u32 + p[1] as u32 + p[2] as u32) as f64).sum::<f64>() / (3.0 * (w * h) as f64);
        assert!(mean > 10.0 && mean < 250.0, "{name} {mode}: mean pixel value {mean} (black or white image)");
        if mode != Mode::Raster {
            assert!(f.report.rays.shadow > 0, "{name} {mode}: no shadow rays");
        }
        finals.push(f.buffers.final_srgb);
    }
    // Ray-traced effects change the picture: raster differs from all.
    assert_ne!(finals[3], finals[1], "{name}: raster and all are identical");
}

#[test]
fn sponza_spheres_renders_in_every_mode() {
    render_all_modes("sponza-spheres.toml");
}

#[test]
fn sponza_armadillo_renders_in_every_mode() {
    render_all_modes("sponza-armadillo.toml");
}

#[test]
fn dining_room_renders_in_every_mode() {
    render_all_modes("dining-room.toml");
}

#[test]
fn pavilion_renders_in_every_mode() {
    render_all_modes("pavilion.toml");
}

#[test]
fn tree_merge_renders_in_every_mode() {
    render_all_modes("tree-merge.toml");
}
