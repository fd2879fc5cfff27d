//! Paper 2's acceptance check on the shipped tree scene: the depth-merged frame (capsule packed
//! frame unpacked and depth-tested against the rasterized polygons) equals the `rt-only` render
//! of the combined scene except at silhouette pixels.

use std::path::Path;

use hybrid_core::{FrameSettings, Mode, NO_OBJECT, RT_SCENE_OBJECT};
use hybrid_cpu::bvh::SceneBvh;
use hybrid_cpu::camera_rays::PrimaryRays;
use hybrid_cpu::capsule::PrimaryVisibility;
use hybrid_cpu::frame::{CpuRenderer, Frame};
use hybrid_cpu::spheres::SphereBvh;
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
    // An independent reference for visibility: per pixel, the nearer of the closest triangle
    // and the closest sphere along the same primary ray, compared by ray parameter t (no depth
    // synthesis, packing or depth test involved).
    let triangles = SceneBvh::build(renderer.prepared());
    let cloud = &scene.point_clouds[0];
    let spheres = SphereBvh::build(&cloud.points, cloud.radius).unwrap();
    for time in [0.0, 10.0] {
        let camera = scene.camera_path.as_ref().unwrap().camera_at(&scene.camera, time);
        let merged = renderer.render(&camera, FrameSettings { width: w, height: h, mode: Mode::All }, &mut |_| {});
        let reference = renderer.render(&camera, FrameSettings { width: w, height: h, mode: Mode::RtOnly }, &mut |_| {});
        // The capsule is visible in both, and polygons occlude part of it.
        let rt_pixels = merged.gbuffer.object_id.iter().filter(|&&id| id == RT_SCENE_OBJECT).count();
        assert!(rt_pixels > (w * h) as usize / 20, "t={time}: only {rt_pixels} RT-scene pixels");
        let packed_hits = merged.rt_packed.as_ref().unwrap().texels.iter().filter(|t| t[0] != 0 || t[1] != 0).count();
        assert!(packed_hits > rt_pixels, "t={time}: polygons should hide some spheres ({packed_hits} hits, {rt_pixels} shown)");

        let rays = PrimaryRays::new(&camera, w, h);
        let mut visibility_mismatch = 0;
        for y in 0..h {
            for x in 0..w {
                let (o, d, t_max) = rays.ray(x, y);
                let tri = triangles.closest_hit(o, d, 0.0, t_max).map(|hit| hit.t);
                let sph = spheres.closest_hit(o, d, 0.0, t_max).map(|(t, _)| t);
                let expected = match (tri, sph) {
                    (_, Some(ts)) if tri.is_none_or(|tt| ts < tt) => RT_SCENE_OBJECT,
                    (Some(_), _) => 0,
                    _ => NO_OBJECT,
                };
                let got = match merged.gbuffer.object_id[(y * w + x) as usize] {
                    RT_SCENE_OBJECT => RT_SCENE_OBJECT,
                    NO_OBJECT => NO_OBJECT,
                    _ => 0,
                };
                visibility_mismatch += (got != expected) as usize;
            }
        }
        let share = visibility_mismatch as f64 / (w * h) as f64;
        eprintln!("t={time}: {visibility_mismatch} pixels disagree with ray-parameter visibility");
        assert!(share <= 0.005, "t={time}: {:.3}% of pixels show the wrong layer (sphere vs polygon)", share * 100.0);

        let a = nv_flip::FlipImageRgb8::with_data(w, h, &rgb8(&reference));
        let b = nv_flip::FlipImageRgb8::with_data(w, h, &rgb8(&merged));
        let err = nv_flip::flip(a, b, nv_flip::DEFAULT_PIXELS_PER_DEGREE).to_vec();
        let bad = err.iter().filter(|&&e| e > 0.1).count();
        let share = bad as f64 / err.len() as f64;
        eprintln!("t={time}: {bad} of {} pixels differ by FLIP > 0.1 ({:.3}%)", err.len(), share * 100.0);
        assert!(share <= 0.005, "t={time}: {:.3}% of pixels differ by FLIP > 0.1 (limit 0.5%)", share * 100.0);
    }
}

#[test]
fn clipping_capsule_rays_at_the_raster_depth_changes_nothing_visible() {
    let scene = tree_scene();
    let mut renderer = CpuRenderer::new(&scene).unwrap();
    let settings = FrameSettings { width: 160, height: 90, mode: Mode::All };
    let camera = scene.camera_path.as_ref().unwrap().camera_at(&scene.camera, 10.0);
    let unclipped = renderer.render(&camera, settings, &mut |_| {});
    renderer.clip_capsule_at_raster_depth = true;
    let clipped = renderer.render(&camera, settings, &mut |_| {});
    assert_eq!(unclipped.gbuffer.object_id, clipped.gbuffer.object_id);
    assert_eq!(unclipped.gbuffer.depth, clipped.gbuffer.depth);
    assert_eq!(unclipped.buffers.final_srgb, clipped.buffers.final_srgb);
    // Behind polygons the clipped capsule reports misses where the unclipped one hit.
    let hits = |f: &Frame| f.rt_packed.as_ref().unwrap().texels.iter().filter(|t| t[0] != 0 || t[1] != 0).count();
    assert!(hits(&clipped) < hits(&unclipped), "{} vs {}", hits(&clipped), hits(&unclipped));
}

#[test]
fn capsule_visibility_by_projection_or_bvh_gives_the_same_frame() {
    let scene = tree_scene();
    let mut renderer = CpuRenderer::new(&scene).unwrap();
    for time in [0.0, 10.0] {
        let camera = scene.camera_path.as_ref().unwrap().camera_at(&scene.camera, time);
        let settings = FrameSettings { width: 160, height: 90, mode: Mode::Hybrid };
        renderer.set_capsule_visibility(PrimaryVisibility::Projected);
        let projected = renderer.render(&camera, settings, &mut |_| {});
        renderer.set_capsule_visibility(PrimaryVisibility::Bvh);
        let bvh = renderer.render(&camera, settings, &mut |_| {});
        let packed = projected.rt_packed.as_ref().unwrap();
        assert!(packed.texels.iter().filter(|t| t[3] != 0).count() > 1000, "t={time}: few capsule hits");
        assert_eq!(projected.rt_packed, bvh.rt_packed, "t={time}: packed frames");
        assert_eq!(projected.buffers.final_srgb, bvh.buffers.final_srgb, "t={time}: final images");
    }
}

#[test]
fn spheres_cast_shadows_on_polygons_and_appear_in_reflections() {
    let scene = tree_scene();
    let mut renderer = CpuRenderer::new(&scene).unwrap();
    let camera = scene.camera_path.as_ref().unwrap().camera_at(&scene.camera, 10.0);
    let f = renderer.render(&camera, FrameSettings { width: 160, height: 90, mode: Mode::All }, &mut |_| {});
    // The same G-buffer traced without the spheres.
    let bvh = SceneBvh::build(renderer.prepared());
    let without = hybrid_cpu::trace::trace(renderer.prepared(), &bvh, &f.gbuffer, &camera);
    let n = f.gbuffer.len();
    let darker = (0..n).filter(|&i| f.buffers.shadow[i].x < without.shadow[i].x - 1e-3).count();
    let brighter = (0..n).filter(|&i| f.buffers.shadow[i].x > without.shadow[i].x + 1e-6).count();
    eprintln!("{darker} pixels shadowed by spheres");
    assert!(darker > n / 100, "spheres shadow only {darker} of {n} pixels");
    assert_eq!(brighter, 0, "spheres can only block light");
    let reflected = (0..n).filter(|&i| (f.buffers.reflection[i] - without.reflection[i]).abs().max_element() > 1e-3).count();
    eprintln!("{reflected} reflection pixels show spheres");
    assert!(reflected > 0, "the mirror ball shows no sphere");
}

#[test]
fn recycled_frames_give_identical_buffers() {
    // Frames of changing size and mode (clipped capsule too), each rendered by a renderer that
    // reuses the previous frame's memory and by a fresh one: every buffer must be equal.
    let scene = tree_scene();
    let camera = scene.camera_path.as_ref().unwrap().camera_at(&scene.camera, 10.0);
    let mut reusing = CpuRenderer::new(&scene).unwrap();
    let mut fresh = CpuRenderer::new(&scene).unwrap();
    let frames = [
        (Mode::All, 96, 54, false),
        (Mode::Raster, 64, 40, false),
        (Mode::All, 64, 40, true),
        (Mode::RtOnly, 64, 40, false),
        (Mode::RtOnly, 96, 54, false),
        (Mode::All, 96, 54, false),
    ];
    for (mode, width, height, clip) in frames {
        let settings = FrameSettings { width, height, mode };
        reusing.clip_capsule_at_raster_depth = clip;
        fresh.clip_capsule_at_raster_depth = clip;
        let got = reusing.render(&camera, settings, &mut |_| {});
        let expected = fresh.render(&camera, settings, &mut |_| {});
        assert_eq!(got.gbuffer, expected.gbuffer, "{mode:?} {width}×{height}");
        assert_eq!(got.buffers, expected.buffers, "{mode:?} {width}×{height}");
        assert_eq!(got.rt_packed, expected.rt_packed, "{mode:?} {width}×{height}");
        reusing.recycle(got);
    }
}
