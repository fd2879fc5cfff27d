//! The hardware ray-tracing path (ray queries over acceleration structures, `hybrid_gpu::accel`)
//! against the software BVH2 traversal on the same adapter: the demo scene, tree-merge.toml (point
//! clouds: the capsule and spheres in the trace stage as AABB geometry) and the pavilion (glass
//! and mirrors), in hybrid and rt-only modes. Needs an adapter with ray queries (lavapipe from
//! Mesa 25 has them: VK_KHR_ray_query + VK_KHR_acceleration_structure); fails without one.

use std::path::Path;
use std::sync::Arc;

use hybrid_core::{Frame, FrameSettings, Mode};
use hybrid_gpu::frame::GpuRenderer;
use hybrid_gpu::{GpuContext, RtChoice};
use hybrid_scene::{Scene, demo_scene, load_scene};

mod support;
use support::compare_frames;

fn context() -> Arc<GpuContext> {
    let ctx = support::context();
    assert!(
        ctx.ray_query,
        "the adapter `{}` has no ray queries: these tests need one (Mesa 25's lavapipe: apt-get install -t bookworm-backports mesa-vulkan-drivers)",
        ctx.summary.name
    );
    Arc::new(ctx)
}

/// The beyond-the-papers switches (`--clip-capsule`, `--no-sphere-effects`).
#[derive(Clone, Copy, Default)]
struct Options {
    clip_capsule: bool,
    no_sphere_effects: bool,
}

/// One frame on `rt`, and the capsule's hit ids (scenes with point clouds).
fn render(ctx: &Arc<GpuContext>, scene: &Scene, rt: RtChoice, settings: FrameSettings, o: Options) -> (Frame, Option<Vec<u32>>, bool) {
    let mut r = GpuRenderer::with_rt(ctx.clone(), scene, rt).unwrap_or_else(|e| panic!("{e}"));
    r.clip_capsule_at_raster_depth = o.clip_capsule;
    r.spheres_in_trace = !o.no_sphere_effects;
    let frame = r.render(&scene.camera, settings, &mut |_| {}).unwrap_or_else(|e| panic!("{e}"));
    let ids = r.capsule_hit_ids().map(|ids| ids.unwrap_or_else(|e| panic!("{e}")));
    (frame, ids, r.rt_path().hardware)
}

fn hardware_matches_software(name: &str, scene: &Scene, w: u32, h: u32) {
    for mode in [Mode::Hybrid, Mode::RtOnly] {
        hardware_matches_software_with(name, scene, w, h, mode, Options::default());
    }
}

fn hardware_matches_software_with(name: &str, scene: &Scene, w: u32, h: u32, mode: Mode, o: Options) {
    let ctx = context();
    {
        let settings = FrameSettings { width: w, height: h, mode };
        let (sw, sw_ids, sw_hw) = render(&ctx, scene, RtChoice::Software, settings, o);
        let (hw, hw_ids, hw_hw) = render(&ctx, scene, RtChoice::Hardware, settings, o);
        assert!(!sw_hw && hw_hw, "{name}: the renderers took the paths asked for");
        assert_eq!(hw.report.adapter.as_ref().map(|a| a.ray_tracing.as_str()), Some("hw"));
        assert_eq!(sw.report.adapter.as_ref().map(|a| a.ray_tracing.as_str()), Some("sw"));
        let built = hw.report.timings_ms.build_as;
        assert!(built.is_some_and(|ms| ms > 0.0), "{name}: the acceleration structures' build is timed: {built:?}");
        assert_eq!(sw.report.timings_ms.build_as, None);
        // The same rays were traced (the secondary trees are walked identically).
        assert_eq!(sw.report.rays, hw.report.rays, "{name} {mode}");

        let cmp = compare_frames(&sw, &hw);
        eprintln!("{name} {mode}: hw vs sw: {cmp}");
        for (buffer, flip) in &cmp.flip {
            assert!(*flip <= 0.01, "{name} {mode}: {buffer} mean FLIP {flip:.4} > 0.01");
        }
        assert_eq!(cmp.object_id_mismatches, 0, "{name} {mode}: object ids differ");
        assert_eq!(cmp.mask_mismatches, 0, "{name} {mode}: masks differ");

        // The capsule: texel for texel where both hit the same sphere.
        assert_eq!(sw_ids.is_some(), hw_ids.is_some());
        if let (Some(a), Some(b)) = (sw_ids, hw_ids) {
            let (pa, pb) = (sw.rt_packed.as_ref().expect("packed frame"), hw.rt_packed.as_ref().expect("packed frame"));
            let mut same = 0;
            for (i, (x, y)) in a.iter().zip(&b).enumerate() {
                if x == y && *x != u32::MAX {
                    same += 1;
                    assert_eq!(pa.texels[i], pb.texels[i], "{name} {mode}: packed texel {i} (sphere {x})");
                }
            }
            let differ = a.iter().zip(&b).filter(|(x, y)| x != y).count();
            eprintln!("{name} {mode}: capsule texels on the same sphere {same}, on different spheres or hit/miss {differ}");
            assert!(same > 0, "{name}: the capsule hit spheres");
            assert_eq!(differ, 0, "{name} {mode}: the capsule hit other spheres in hardware");
        }
    }
}

#[test]
fn demo_scene_hardware_matches_software() {
    hardware_matches_software("demo", &demo_scene(), 160, 120);
}

#[test]
fn tree_merge_hardware_matches_software() {
    let scene = load_scene(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/tree-merge.toml")).unwrap();
    hardware_matches_software("tree-merge", &scene, 160, 120);
}

/// The capsule clipped at the polygons' depth (its hardware variant too), and the trace stage
/// without the spheres (the hardware variant bound to no spheres finds none).
#[test]
fn tree_merge_options_hardware_matches_software() {
    let scene = load_scene(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/tree-merge.toml")).unwrap();
    let o = Options { clip_capsule: true, no_sphere_effects: true };
    hardware_matches_software_with("tree-merge clipped, no sphere effects", &scene, 160, 120, Mode::Hybrid, o);
}

#[test]
fn pavilion_hardware_matches_software() {
    let scene = load_scene(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/pavilion.toml")).unwrap();
    hardware_matches_software("pavilion", &scene, 160, 90);
}
