//! Stage 3b, the raster fallbacks (issue 18), on the GPU against the CPU backend (the oracle):
//! the three fallback buffers and the final image within mean FLIP 0.02, in raster mode and in
//! hybrid with a small budget, on the demo scene and an asset scene; and the shadow-map cache,
//! which renders each spot and point map once over a camera path, as the CPU's does. Runs on
//! whatever adapter wgpu finds (lavapipe in CI); fails when there is none.

use std::path::Path;
use std::sync::Arc;

use glam::Vec3;
use hybrid_core::fallback::{Fallback, Refractor, refractors, see_through_objects};
use hybrid_core::prepare::PreparedScene;
use hybrid_core::shading::{Light, lights};
use hybrid_core::{Frame, FrameSettings, Mode};
use hybrid_cpu::frame::CpuRenderer;
use hybrid_gpu::GpuContext;
use hybrid_gpu::frame::GpuRenderer;
use hybrid_scene::{Budget, Camera, Scene, demo_scene, load_scene};

mod support;
use support::{mean_flip, mean_flip_linear, rgb8};

fn context() -> Arc<GpuContext> {
    Arc::new(support::context())
}

fn render_both(ctx: &Arc<GpuContext>, scene: &Scene, mode: Mode, w: u32, h: u32) -> (Frame, Frame) {
    let settings = FrameSettings { width: w, height: h, mode };
    let mut cpu = CpuRenderer::new(scene).unwrap();
    let mut gpu = GpuRenderer::new(ctx.clone(), scene).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((cpu.fallback, gpu.fallback), (Fallback::Raster, Fallback::Raster));
    let c = cpu.render(&scene.camera, settings, &mut |_| {});
    let g = gpu.render(&scene.camera, settings, &mut |_| {}).unwrap_or_else(|e| panic!("{e}"));
    (c, g)
}

/// A budget that selects some objects but not all: 30% of what tracing everything costs.
fn small_budget(scene: &mut Scene, w: u32, h: u32) {
    scene.heuristic.budget = Budget::Unlimited;
    let mut cpu = CpuRenderer::new(scene).unwrap();
    let f = cpu.render(&scene.camera, FrameSettings { width: w, height: h, mode: Mode::All }, &mut |_| {});
    let spent = f.report.heuristic.expect("mode all runs the heuristic").spent;
    scene.heuristic.budget = Budget::Cost(spent * 0.3);
}

/// The fallback buffers and the final image within mean FLIP `limit` of the CPU's, and the same
/// maps and probes rendered. Returns the pixels that took a fallback.
fn assert_fallbacks_match(name: &str, mode: Mode, c: &Frame, g: &Frame, limit: f32) -> usize {
    let (w, h) = (c.settings.width, c.settings.height);
    let (cb, gb) = (&c.buffers, &g.buffers);
    let n = (w * h) as usize;
    for (buffer, a, b) in [
        ("shadow_fallback", &cb.shadow_fallback, &gb.shadow_fallback),
        ("reflection_fallback", &cb.reflection_fallback, &gb.reflection_fallback),
        ("refraction_fallback", &cb.refraction_fallback, &gb.refraction_fallback),
    ] {
        assert_eq!((a.len(), b.len()), (n, n), "{name} {mode}: {buffer} sizes");
    }
    let flips = [
        ("shadow_fallback", mean_flip_linear(w, h, &cb.shadow_fallback, &gb.shadow_fallback)),
        ("reflection_fallback", mean_flip_linear(w, h, &cb.reflection_fallback, &gb.reflection_fallback)),
        ("refraction_fallback", mean_flip_linear(w, h, &cb.refraction_fallback, &gb.refraction_fallback)),
        ("final", mean_flip(w, h, &rgb8(&cb.final_srgb), &rgb8(&gb.final_srgb))),
    ];
    let untraced = c.gbuffer.object_id.iter().zip(&c.gbuffer.mask).filter(|(id, m)| hybrid_core::is_polygon(**id) && **m < 1e-4).count();
    eprintln!(
        "{name} {mode}: {untraced} untraced pixels, renders cpu {:?} gpu {:?}; FLIP {flips:?}",
        c.report.fallback_renders, g.report.fallback_renders
    );
    for (buffer, flip) in flips {
        assert!(flip <= limit, "{name} {mode}: {buffer} mean FLIP {flip:.4} > {limit}");
    }
    assert_eq!(g.report.fallback, Fallback::Raster);
    assert_eq!(g.report.fallback_renders, c.report.fallback_renders, "{name} {mode}: maps and probes rendered");
    untraced
}

/// How many pixels of `v` differ from `value` by more than 0.01 in some channel.
fn differing(v: &[Vec3], value: Vec3) -> usize {
    v.iter().filter(|x| (**x - value).abs().max_element() > 0.01).count()
}

#[test]
fn demo_fallbacks_match_the_cpu() {
    let ctx = context();
    let (w, h) = (160, 90);
    let mut scene = demo_scene();
    let (c, g) = render_both(&ctx, &scene, Mode::Raster, w, h);
    let untraced = assert_fallbacks_match("demo", Mode::Raster, &c, &g, 0.02);
    // The comparison means something: shadows, reflections and refractions all came from the
    // fallbacks (the demo has shadowed floor, a mirror sphere and glass).
    assert!(untraced > (w * h / 2) as usize, "{untraced}");
    for (buffer, v, untouched) in [
        ("shadow", &g.buffers.shadow_fallback, Vec3::ONE),
        ("reflection", &g.buffers.reflection_fallback, Vec3::ZERO),
        ("refraction", &g.buffers.refraction_fallback, Vec3::ZERO),
    ] {
        assert!(differing(v, untouched) > 50, "demo raster: the GPU's {buffer} fallback is (nearly) empty");
    }
    assert!(g.report.fallback_renders.shadow_maps > 0 && g.report.fallback_renders.probes > 0, "{:?}", g.report.fallback_renders);
    // Same objects, same paths per effect.
    assert_eq!(g.report.effects, c.report.effects);

    small_budget(&mut scene, w, h);
    let (c, g) = render_both(&ctx, &scene, Mode::Hybrid, w, h);
    let selected = c.gbuffer.mask.iter().filter(|&&m| m >= 1e-4).count();
    let untraced = assert_fallbacks_match("demo", Mode::Hybrid, &c, &g, 0.02);
    assert!(untraced > 0 && selected > 0, "the small budget should trace some objects and not others");
    assert_eq!(g.report.effects, c.report.effects);
}

/// `--fallback none` leaves the fallback buffers empty and the image as the paper's.
#[test]
fn no_fallback_leaves_the_buffers_empty() {
    let ctx = context();
    let scene = demo_scene();
    let settings = FrameSettings { width: 64, height: 36, mode: Mode::Raster };
    let mut gpu = GpuRenderer::new(ctx.clone(), &scene).unwrap_or_else(|e| panic!("{e}"));
    gpu.fallback = Fallback::None;
    let g = gpu.render(&scene.camera, settings, &mut |_| {}).unwrap_or_else(|e| panic!("{e}"));
    assert!(g.buffers.shadow_fallback.is_empty() && g.buffers.reflection_fallback.is_empty());
    assert_eq!(g.report.fallback_renders, Default::default());
    // Raster mode without fallbacks: the final image is the lighting, as on the CPU.
    let mut cpu = CpuRenderer::new(&scene).unwrap();
    cpu.fallback = Fallback::None;
    let c = cpu.render(&scene.camera, settings, &mut |_| {});
    assert!(mean_flip(64, 36, &rgb8(&c.buffers.final_srgb), &rgb8(&g.buffers.final_srgb)) <= 0.02);
}

#[test]
fn sponza_spheres_fallbacks_match_the_cpu() {
    let ctx = context();
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/sponza-spheres.toml");
    let mut scene = load_scene(&path).unwrap_or_else(|e| panic!("{e}"));
    let (w, h) = (96, 54);
    let (c, g) = render_both(&ctx, &scene, Mode::Raster, w, h);
    assert!(assert_fallbacks_match("sponza-spheres", Mode::Raster, &c, &g, 0.02) > 0);
    small_budget(&mut scene, w, h);
    let (c, g) = render_both(&ctx, &scene, Mode::Hybrid, w, h);
    assert_fallbacks_match("sponza-spheres", Mode::Hybrid, &c, &g, 0.02);
}

/// Over a short camera path, each spot and point map is rendered once (their views do not
/// depend on the camera) and the cascades only when the camera moved them: the same counts, light
/// by light, as the CPU's cache.
#[test]
fn shadow_maps_are_cached_along_a_camera_path() {
    let ctx = context();
    let scene = demo_scene();
    let settings = FrameSettings { width: 64, height: 36, mode: Mode::Raster };
    let mut cpu = CpuRenderer::new(&scene).unwrap();
    let mut gpu = GpuRenderer::new(ctx.clone(), &scene).unwrap_or_else(|e| panic!("{e}"));
    let mut total = 0;
    for k in 0..5 {
        let offset = Vec3::new(0.05, 0.0, -0.03) * k as f32;
        let camera = Camera { position: scene.camera.position + offset, target: scene.camera.target + offset, ..scene.camera };
        let c = cpu.render(&camera, settings, &mut |_| {});
        let g = gpu.render(&camera, settings, &mut |_| {}).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(g.report.fallback_renders.shadow_maps, c.report.fallback_renders.shadow_maps, "frame {k}");
        if k > 0 {
            assert_eq!(g.report.fallback_renders.probes, 0, "frame {k}: probes are rendered once");
        }
        total += g.report.fallback_renders.shadow_maps;
    }
    let cpu_counts = &cpu.fallback_cache().expect("the CPU needed fallbacks").shadow_map_renders;
    let gpu_counts = &gpu.fallback_gpu().expect("the GPU needed fallbacks").shadow_map_renders;
    assert_eq!(gpu_counts, cpu_counts);
    assert_eq!(gpu_counts.iter().sum::<u64>(), total);
    for (k, light) in lights(&scene.lights).enumerate() {
        match light {
            Light::Point(_) => assert_eq!(gpu_counts[k], 6, "light {k}: six cube faces, once"),
            Light::Spot(_) => assert_eq!(gpu_counts[k], 1, "light {k}: one spot map, once"),
            Light::Directional(_) => assert!(gpu_counts[k] >= 3, "light {k}: three cascades at least once"),
        }
    }
}

/// The tree scan's spheres cast into the maps (as the CPU's discs) onto the ground below.
#[test]
fn tree_merge_sphere_shadows_match_the_cpu() {
    let ctx = context();
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/tree-merge.toml");
    let scene = load_scene(&path).unwrap_or_else(|e| panic!("{e}"));
    let (c, g) = render_both(&ctx, &scene, Mode::Raster, 96, 54);
    assert!(assert_fallbacks_match("tree-merge", Mode::Raster, &c, &g, 0.02) > 0);
    assert!(differing(&g.buffers.shadow_fallback, Vec3::ONE) > 50, "no shadows in the GPU's shadow fallback");
}

/// The pavilion: the glass walls take their reflections and refractions from probes marched
/// through their distances, the pool's water (planar) its refraction from the see-through
/// layer; the sun's cascades shadow the floor. Probe faces and the see-through layer sample
/// textures at level 0 on both backends.
#[test]
fn pavilion_fallbacks_match_the_cpu() {
    let ctx = context();
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/pavilion.toml");
    let mut scene = load_scene(&path).unwrap_or_else(|e| panic!("{e}"));
    let (w, h) = (96, 54);
    let (c, g) = render_both(&ctx, &scene, Mode::Raster, w, h);
    assert!(assert_fallbacks_match("pavilion", Mode::Raster, &c, &g, 0.02) > 0);
    assert_see_through_matches("pavilion raster", &scene, &c, &g);
    small_budget(&mut scene, w, h);
    let (c, g) = render_both(&ctx, &scene, Mode::Hybrid, w, h);
    assert_fallbacks_match("pavilion", Mode::Hybrid, &c, &g, 0.02);
}

/// The see-through layer is re-rendered when the view moves beyond `see_through_layer_kept`'s
/// 2° and kept within it, on both backends alike, and after the camera moved the GPU's lookups
/// still match the CPU's.
#[test]
fn pavilion_see_through_follows_the_camera() {
    let ctx = context();
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/pavilion.toml");
    let scene = load_scene(&path).unwrap_or_else(|e| panic!("{e}"));
    let settings = FrameSettings { width: 96, height: 54, mode: Mode::Raster };
    let mut cpu = CpuRenderer::new(&scene).unwrap();
    let mut gpu = GpuRenderer::new(ctx.clone(), &scene).unwrap_or_else(|e| panic!("{e}"));
    // Frame 1 moves 0.52 away: a new layer. Frame 2 moves on by 0.9 of what
    // `see_through_layer_kept` allows from the nearest see-through object: both backends keep
    // frame 1's layer and still agree.
    let prepared = PreparedScene::new(&scene);
    let objects = see_through(&prepared);
    let at_1 = scene.camera.position + Vec3::new(0.4, 0.15, -0.3);
    let nearest = hybrid_core::fallback::nearest_see_through(at_1, &prepared.object_bounds, &objects, &vec![true; objects.len()]);
    let step = 0.9 * nearest * hybrid_core::fallback::SEE_THROUGH_KEEP_DEGREES.to_radians().tan();
    assert!(step > 0.01, "{step}");
    for (k, (position, renders)) in [(scene.camera.position, 1), (at_1, 2), (at_1 + Vec3::new(step, 0.0, 0.0), 2)].into_iter().enumerate() {
        let camera = Camera { position, ..scene.camera };
        let c = cpu.render(&camera, settings, &mut |_| {});
        let g = gpu.render(&camera, settings, &mut |_| {}).unwrap_or_else(|e| panic!("{e}"));
        assert_fallbacks_match(&format!("pavilion frame {k}"), Mode::Raster, &c, &g, 0.02);
        assert_see_through_matches(&format!("pavilion frame {k}"), &scene, &c, &g);
        let fb = gpu.fallback_gpu().expect("the pavilion needs fallbacks");
        assert_eq!(fb.see_through_renders, renders, "frame {k}");
        assert_eq!(cpu.fallback_cache().unwrap().see_through_renders, renders, "frame {k} on the CPU");
        assert_eq!(fb.see_through_objects(), &objects[..]);
    }
}

/// The pavilion at 14 s along its path (`--time 14`), in hybrid mode: the camera looks through
/// the glass panes (convex hulls: refracted in and out again) at the chrome dragon, whose texels
/// in the see-through layer are shaded as secondary hits (its probe's reflections), so the dragon
/// has a probe on both backends. The budget is `--budget 150000` at 640 × 360 scaled to this
/// frame's pixels (at 160 × 90, 150000 itself traces every object), so that, as there, the panes
/// are left to the fallbacks and the rest traced. The fallback buffers and the image match the
/// CPU's, and so does the refraction over the panes' pixels. A pane's lookup runs parallel to the
/// camera ray, so it lands where the pixel's centre does in the layer (widened 1.5×): at a
/// texel's centre when the frame's width and height are multiples of 4 (as here and at
/// 640 × 360), on a texel edge otherwise (160 × 90: rows), where the two backends' rounding
/// picks either side and the textured wall behind the panes then differs by a row.
#[test]
fn pavilion_panes_at_14s_match_the_cpu() {
    let ctx = context();
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/pavilion.toml");
    let mut scene = load_scene(&path).unwrap_or_else(|e| panic!("{e}"));
    let (w, h) = (128, 72);
    scene.heuristic.budget = Budget::Cost(150_000.0 * f64::from(w * h) / f64::from(640 * 360));
    let camera = scene.camera_path.as_ref().expect("the pavilion has a camera path").camera_at(&scene.camera, 14.0);
    let settings = FrameSettings { width: w, height: h, mode: Mode::Hybrid };
    let mut cpu = CpuRenderer::new(&scene).unwrap();
    let mut gpu = GpuRenderer::new(ctx.clone(), &scene).unwrap_or_else(|e| panic!("{e}"));
    let c = cpu.render(&camera, settings, &mut |_| {});
    let g = gpu.render(&camera, settings, &mut |_| {}).unwrap_or_else(|e| panic!("{e}"));
    assert!(assert_fallbacks_match("pavilion 14 s", Mode::Hybrid, &c, &g, 0.02) > 0);
    assert_see_through_matches("pavilion 14 s", &scene, &c, &g);
    let prepared = PreparedScene::new(&scene);
    let hulls = refractors(&prepared);
    let panes: Vec<bool> =
        see_through(&prepared).iter().zip(&hulls).map(|(&see, r)| see && matches!(r, Some(Refractor::Hull(_)))).collect();
    assert_refraction_matches_on("pavilion 14 s panes", &panes, &c, &g);
    let traced = c.gbuffer.mask.iter().filter(|&&m| m >= 1e-4).count();
    assert!(traced > 0, "the budget should trace the objects but the panes");
}

/// `see_through_objects` with the scene's refractors.
fn see_through(prepared: &PreparedScene) -> Vec<bool> {
    see_through_objects(prepared, &refractors(prepared))
}

/// The refraction fallback over the untraced pixels of the see-through objects (where the
/// see-through layer answers, not the probes) close to the CPU's ([`assert_refraction_matches_on`]).
fn assert_see_through_matches(name: &str, scene: &Scene, c: &Frame, g: &Frame) {
    let planar = see_through(&PreparedScene::new(scene));
    assert!(planar.iter().any(|&p| p), "{name}: the scene has a planar refractive object");
    assert_refraction_matches_on(name, &planar, c, g);
}

/// The refraction fallback over the untraced pixels of `objects` close to the CPU's, pixel by
/// pixel: there are more than 50 such pixels, and the mean of their largest channel difference
/// is below 0.05 (the whole-image FLIP dilutes them among the rest).
fn assert_refraction_matches_on(name: &str, objects: &[bool], c: &Frame, g: &Frame) {
    let pixels: Vec<usize> = (0..c.gbuffer.object_id.len())
        .filter(|&i| {
            let id = c.gbuffer.object_id[i];
            hybrid_core::is_polygon(id) && c.gbuffer.mask[i] < 1e-4 && objects.get(id as usize).copied().unwrap_or(false)
        })
        .collect();
    let (cr, gr) = (&c.buffers.refraction_fallback, &g.buffers.refraction_fallback);
    let mean = pixels.iter().map(|&i| (cr[i] - gr[i]).abs().max_element()).sum::<f32>() / pixels.len().max(1) as f32;
    let far = pixels.iter().filter(|&&i| (cr[i] - gr[i]).abs().max_element() > 0.1).count();
    eprintln!("{name}: {} see-through pixels, mean max-channel difference {mean:.4}, {far} differ by > 0.1", pixels.len());
    assert!(pixels.len() > 50, "{name}: {} untraced pixels of the objects", pixels.len());
    assert!(mean < 0.05, "{name}: see-through refraction mean difference {mean:.4}");
}

/// The maps themselves, texel by texel: the same views, the same caster depths but for the
/// texels on triangle edges (the two rasterizers' coverage rules) and the spheres' disc rims.
#[test]
fn shadow_maps_match_the_cpu_texel_by_texel() {
    let ctx = context();
    for name in ["demo.toml", "tree-merge.toml"] {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes").join(name);
        let scene = load_scene(&path).unwrap_or_else(|e| panic!("{e}"));
        let settings = FrameSettings { width: 64, height: 36, mode: Mode::Raster };
        let mut cpu = CpuRenderer::new(&scene).unwrap();
        let mut gpu = GpuRenderer::new(ctx.clone(), &scene).unwrap_or_else(|e| panic!("{e}"));
        cpu.render(&scene.camera, settings, &mut |_| {});
        gpu.render(&scene.camera, settings, &mut |_| {}).unwrap_or_else(|e| panic!("{e}"));
        let cpu_maps: Vec<_> = cpu.fallback_cache().expect("fallbacks ran").shadow_maps().iter().flatten().cloned().collect();
        let gpu_maps = gpu.shadow_maps().unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(gpu_maps.len(), cpu_maps.len(), "{name}: lights with maps");
        for (c, g) in cpu_maps.iter().zip(&gpu_maps) {
            assert_eq!((g.light, g.kind, g.maps.len()), (c.light, c.kind, c.maps.len()), "{name}");
            for (k, (cm, gm)) in c.maps.iter().zip(&g.maps).enumerate() {
                assert_eq!(gm.view, cm.view, "{name} light {} map {k}", c.light);
                let differ = cm.depth.iter().zip(&gm.depth).filter(|(a, b)| (**a - **b).abs() > 1e-5).count();
                let covered = cm.depth.iter().filter(|&&d| d > 0.0).count();
                let share = differ as f64 / cm.depth.len() as f64;
                eprintln!("{name} light {} map {k}: {covered} covered texels, {differ} differ ({:.4}%)", c.light, share * 100.0);
                assert!(share < 0.001, "{name} light {} map {k}: {differ} of {} texels differ", c.light, cm.depth.len());
            }
        }
    }
}
