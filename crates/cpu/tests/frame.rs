//! Whole-frame tests of the CPU backend: modes agree where they must, frames are deterministic,
//! and every stage's output is sane on the demo scene.

use hybrid_core::{FrameSettings, Mode, NO_OBJECT};
use hybrid_cpu::frame::{CpuRenderer, Frame};
use hybrid_scene::{Budget, Scene, demo_scene};

fn render(scene: &Scene, mode: Mode, w: u32, h: u32) -> Frame {
    let mut r = CpuRenderer::new(scene).expect("scene prepares");
    r.render(&scene.camera, FrameSettings { width: w, height: h, mode }, &mut |_| {})
}

fn rgb8(frame: &Frame) -> Vec<u8> {
    frame.buffers.final_srgb.iter().flat_map(|p| [p[0], p[1], p[2]]).collect()
}

/// Mean FLIP error between two 8-bit sRGB images (0 = identical).
fn mean_flip(reference: &Frame, test: &Frame) -> f32 {
    let (w, h) = (reference.settings.width, reference.settings.height);
    let a = nv_flip::FlipImageRgb8::with_data(w, h, &rgb8(reference));
    let b = nv_flip::FlipImageRgb8::with_data(w, h, &rgb8(test));
    let err = nv_flip::flip(a, b, nv_flip::DEFAULT_PIXELS_PER_DEGREE);
    nv_flip::FlipPool::from_image(&err).mean()
}

#[test]
fn all_and_rt_only_agree_on_the_demo_scene() {
    let scene = demo_scene();
    let all = render(&scene, Mode::All, 320, 180);
    let rt = render(&scene, Mode::RtOnly, 320, 180);
    // Every visible object was selected in `all`.
    let report = all.report.heuristic.as_ref().expect("all mode runs the heuristic");
    assert!(report.objects.iter().all(|o| o.selected), "all mode must select every visible object");
    let flip = mean_flip(&rt, &all);
    eprintln!("mean FLIP all vs rt-only: {flip:.4}");
    assert!(flip <= 0.05, "mean FLIP {flip} > 0.05");
    // And the raster-only image is measurably different (the effects matter), so the check above
    // is not vacuous.
    let raster = render(&scene, Mode::Raster, 320, 180);
    let flip_raster = mean_flip(&rt, &raster);
    assert!(flip_raster > flip * 2.0 && flip_raster > 0.05, "raster vs rt-only FLIP {flip_raster} vs all {flip}");
}

#[test]
fn hybrid_with_unlimited_budget_equals_all() {
    let mut scene = demo_scene();
    scene.heuristic.budget = Budget::Unlimited;
    let hybrid = render(&scene, Mode::Hybrid, 160, 90);
    let all = render(&scene, Mode::All, 160, 90);
    assert_eq!(hybrid.buffers.final_srgb, all.buffers.final_srgb);
}

#[test]
fn a_small_budget_traces_fewer_pixels_and_rays() {
    let mut scene = demo_scene();
    scene.heuristic.budget = Budget::Unlimited;
    let all = render(&scene, Mode::Hybrid, 160, 90);
    let spent = all.report.heuristic.as_ref().unwrap().spent;
    scene.heuristic.budget = Budget::Cost(spent * 0.3);
    let some = render(&scene, Mode::Hybrid, 160, 90);
    let masked = |f: &Frame| f.gbuffer.mask.iter().filter(|&&m| m > 0.0).count();
    assert!(masked(&some) < masked(&all), "{} vs {}", masked(&some), masked(&all));
    let r = |f: &Frame| f.report.rays.shadow + f.report.rays.reflection + f.report.rays.refraction;
    assert!(r(&some) < r(&all));
    let h = some.report.heuristic.as_ref().unwrap();
    assert!(h.spent <= spent * 0.3 + 1e-9, "spent {} over budget {}", h.spent, spent * 0.3);
    assert!(h.objects.iter().any(|o| !o.selected));
}

#[test]
fn frames_are_deterministic_across_runs_and_thread_counts() {
    let scene = demo_scene();
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let two = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    for mode in [Mode::Hybrid, Mode::RtOnly] {
        let a = one.install(|| render(&scene, mode, 160, 90));
        let b = two.install(|| render(&scene, mode, 160, 90));
        let c = two.install(|| render(&scene, mode, 160, 90));
        assert_eq!(a.gbuffer, b.gbuffer, "{mode}: G-buffer differs between 1 and 2 threads");
        assert_eq!(a.buffers, b.buffers, "{mode}: frame buffers differ between 1 and 2 threads");
        assert_eq!(b.buffers.final_srgb, c.buffers.final_srgb, "{mode}: two renders differ");
    }
}

#[test]
fn every_mode_fills_its_buffers() {
    let scene = demo_scene();
    for mode in Mode::ALL {
        let f = render(&scene, mode, 96, 54);
        let n = 96 * 54;
        assert_eq!(f.buffers.final_srgb.len(), n);
        let covered = f.gbuffer.object_id.iter().filter(|&&id| id != NO_OBJECT).count();
        assert!(covered > n / 2, "{mode}: only {covered} of {n} pixels covered");
        assert!(f.buffers.lighting.iter().all(|c| c.is_finite()), "{mode}: non-finite lighting");
        let masked = f.gbuffer.mask.iter().filter(|&&m| m > 0.0).count();
        match mode {
            Mode::Raster => {
                assert_eq!(masked, 0);
                assert_eq!(f.report.rays.shadow + f.report.rays.reflection, 0);
            }
            Mode::RtOnly => {
                assert_eq!(masked, covered);
                assert_eq!(f.report.rays.primary, n as u64);
            }
            _ => assert!(masked > 0 && f.report.rays.shadow > 0),
        }
    }
}

#[test]
fn recycled_gbuffers_give_identical_frames() {
    let scene = demo_scene();
    let settings = FrameSettings { width: 160, height: 90, mode: Mode::Hybrid };
    let path = scene.camera_path.as_ref().expect("the demo has a camera path");
    let (a, b) = (path.camera_at(&scene.camera, 0.0), path.camera_at(&scene.camera, path.duration() * 0.5));
    let mut fresh = CpuRenderer::new(&scene).unwrap();
    let expected = fresh.render(&b, settings, &mut |_| {});
    let mut reusing = CpuRenderer::new(&scene).unwrap();
    let first = reusing.render(&a, settings, &mut |_| {});
    reusing.recycle(first);
    let second = reusing.render(&b, settings, &mut |_| {});
    assert_eq!(second.gbuffer, expected.gbuffer);
    assert_eq!(second.buffers.final_srgb, expected.buffers.final_srgb);
}
