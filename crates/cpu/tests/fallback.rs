//! Issue 18's raster fallbacks on the CPU backend against analytic and ray-traced answers:
//! shadow maps against exact box shadows (directional, spot, point), a mirror sphere's probe
//! against its ray-traced reflection, and the cache (each point/spot map rendered once along a
//! camera path).

use std::path::Path;

use glam::Vec3;
use hybrid_core::fallback::Fallback;
use hybrid_core::shading::{Light, lights};
use hybrid_core::{FrameSettings, Mode};
use hybrid_cpu::frame::{CpuRenderer, Frame};
use hybrid_scene::{Camera, Scene, parse_scene};

const BOX_MIN: Vec3 = Vec3::new(-0.5, 0.5, -0.5);
const BOX_MAX: Vec3 = Vec3::new(0.5, 1.5, 0.5);

fn scene_with(light: &str) -> Scene {
    let text = format!(
        r#"
[camera]
position = [0.0, 4.0, 3.5]
target = [0.0, 0.0, 0.0]
fov = 60
near = 0.1
far = 50

[environment]
ambient = [0.1, 0.1, 0.1]

[[material]]
name = "white"
diffuse = [0.8, 0.8, 0.8]

[[object]]
name = "ground"
primitive = "plane"
scale = 14.0
material = "white"

[[object]]
name = "box"
primitive = "cube"
position = [0.0, 1.0, 0.0]
material = "white"

{light}
"#
    );
    parse_scene(&text, Path::new("fallback-test.toml")).expect("test scene parses")
}

const DIRECTIONAL: &str = "[[light]]\ntype = \"directional\"\ndirection = [0.3, -1.0, 0.2]\nintensity = 1.0\ncasts_shadows = true\n";
const SPOT: &str = "[[light]]\ntype = \"spot\"\nposition = [1.0, 5.0, 1.0]\ndirection = [-0.2, -1.0, -0.2]\ninner_angle = 35\nouter_angle = 40\nintensity = 20.0\ncasts_shadows = true\n";
const POINT: &str = "[[light]]\ntype = \"point\"\nposition = [0.6, 4.0, 0.4]\nintensity = 20.0\ncasts_shadows = true\n";

fn render(r: &mut CpuRenderer, camera: &Camera, mode: Mode, w: u32, h: u32) -> Frame {
    r.render(camera, FrameSettings { width: w, height: h, mode }, &mut |_| {})
}

/// Whether the segment from `p` towards `to_light` (unit; up to `dist`) passes through the box.
fn box_blocks(p: Vec3, to_light: Vec3, dist: f32) -> bool {
    let inv = to_light.recip();
    let (t1, t2) = ((BOX_MIN - p) * inv, (BOX_MAX - p) * inv);
    let (near, far) = (t1.min(t2).max_element(), t1.max(t2).min_element());
    near <= far && far > 1e-4 && near < dist
}

/// Shadow-map shadows against the exact box shadow on the ground, for one light. Returns the
/// share of ground pixels excluded as within 2 texels of the shadow's edge.
fn shadow_maps_match_exact_shadows(light: &str, name: &str) -> f64 {
    let scene = scene_with(light);
    let mut r = CpuRenderer::new(&scene).unwrap();
    let (w, h) = (320, 240);
    let traced = render(&mut r, &scene.camera, Mode::All, w, h);
    let raster = render(&mut r, &scene.camera, Mode::Raster, w, h);
    let maps = r.fallback_cache().expect("raster mode used the fallbacks").shadow_maps()[0].clone().expect("the light has maps");
    let l = lights(&scene.lights).next().unwrap();
    let (light_pos, dir_to_light) = match l {
        Light::Directional(d) => (Vec3::ZERO, -d.direction.normalize()),
        Light::Point(p) => (p.position, Vec3::ZERO),
        Light::Spot(s) => (s.position, Vec3::ZERO),
    };
    let g = &raster.gbuffer;
    let (mut compared, mut excluded, mut shadowed, mut mismatched) = (0u64, 0u64, 0u64, 0u64);
    for i in 0..g.len() {
        if g.object_id[i] != 0 {
            continue;
        }
        let p = g.position[i];
        let (to_light, dist) =
            if dir_to_light != Vec3::ZERO { (dir_to_light, f32::INFINITY) } else { ((light_pos - p).normalize(), light_pos.distance(p)) };
        let view_distance = (p - scene.camera.position).dot(scene.camera.forward());
        let map = maps.map_for(p, view_distance, light_pos).unwrap();
        let texel =
            if map.view.orthographic { map.view.texel_world } else { map.view.texel_world * (map.view.view_proj * p.extend(1.0)).w };
        // Within 2 texels of the edge: the exact shadow changes somewhere in a 2-texel
        // neighbourhood, across the light's direction.
        let a = to_light.any_orthonormal_vector();
        let b = to_light.cross(a);
        let centre = box_blocks(p, to_light, dist);
        let near_edge = (0..16).any(|k| {
            let angle = k as f32 * std::f32::consts::TAU / 16.0;
            let q = p + (a * angle.cos() + b * angle.sin()) * (2.0 * texel);
            let (tl, d) = if dir_to_light != Vec3::ZERO { (to_light, dist) } else { ((light_pos - q).normalize(), light_pos.distance(q)) };
            box_blocks(q, tl, d) != centre
        });
        // The traced shadow is the exact one (a test of the test).
        let traced_dark = traced.buffers.shadow[i].x < 0.999;
        if !near_edge {
            assert_eq!(traced_dark, centre, "{name}: the traced shadow at {p} differs from the exact one");
        }
        if near_edge {
            excluded += 1;
            continue;
        }
        compared += 1;
        shadowed += u64::from(centre);
        let d = (raster.buffers.shadow_fallback[i] - traced.buffers.shadow[i]).abs().max_element();
        if d > 1e-3 {
            mismatched += 1;
        }
    }
    let share = excluded as f64 / (excluded + compared) as f64;
    eprintln!(
        "{name}: {compared} ground pixels compared ({shadowed} in shadow), {mismatched} differ; {excluded} excluded near the edge ({:.2}%)",
        share * 100.0
    );
    assert!(shadowed > 500, "{name}: the box must cast a sizeable shadow in view ({shadowed} pixels)");
    assert_eq!(mismatched, 0, "{name}: shadow-map shadow differs from the ray-traced one away from the edge");
    share
}

#[test]
fn directional_cascades_match_the_exact_shadow() {
    let share = shadow_maps_match_exact_shadows(DIRECTIONAL, "directional");
    assert!(share < 0.05, "{share}");
}

#[test]
fn spot_map_matches_the_exact_shadow() {
    let share = shadow_maps_match_exact_shadows(SPOT, "spot");
    assert!(share < 0.05, "{share}");
}

#[test]
fn point_cube_matches_the_exact_shadow() {
    let share = shadow_maps_match_exact_shadows(POINT, "point");
    assert!(share < 0.05, "{share}");
}

fn srgb8(v: &[Vec3]) -> Vec<u8> {
    v.iter().flat_map(|c| hybrid_core::blend::encode_srgb(*c)[..3].to_vec()).collect()
}

fn mean_flip(w: u32, h: u32, a: &[u8], b: &[u8]) -> f32 {
    let err = nv_flip::flip(
        nv_flip::FlipImageRgb8::with_data(w, h, a),
        nv_flip::FlipImageRgb8::with_data(w, h, b),
        nv_flip::DEFAULT_PIXELS_PER_DEGREE,
    );
    nv_flip::FlipPool::from_image(&err).mean()
}

#[test]
fn a_mirror_spheres_probe_reflects_what_rays_do() {
    let text = r#"
[camera]
position = [0.0, 0.4, 3.2]
target = [0.0, 0.0, 0.0]
fov = 45

[environment.skybox]
zenith = [0.1, 0.25, 0.9]
horizon = [0.95, 0.9, 0.8]
ground = [0.3, 0.2, 0.1]

[[material]]
name = "mirror"
diffuse = [0.0, 0.0, 0.0]
reflectivity = 1.0

[[object]]
name = "ball"
primitive = "sphere"
slices = 96
stacks = 48
scale = 2.0
material = "mirror"
"#;
    let scene = parse_scene(text, Path::new("mirror.toml")).unwrap();
    let mut r = CpuRenderer::new(&scene).unwrap();
    let (w, h) = (256, 256);
    let traced = render(&mut r, &scene.camera, Mode::All, w, h);
    let raster = render(&mut r, &scene.camera, Mode::Raster, w, h);
    let on_ball = |v: &[Vec3]| -> Vec<Vec3> {
        v.iter().zip(&traced.gbuffer.object_id).map(|(c, &id)| if id == 0 { *c } else { Vec3::ZERO }).collect()
    };
    let covered = traced.gbuffer.object_id.iter().filter(|&&id| id == 0).count();
    assert!(covered > 20_000, "{covered}");
    let (a, b) = (srgb8(&on_ball(&traced.buffers.reflection)), srgb8(&on_ball(&raster.buffers.reflection_fallback)));
    let flip = mean_flip(w, h, &a, &b);
    // FLIP over the ball's pixels only (the rest is identical black).
    let per_ball = flip * (w * h) as f32 / covered as f32;
    eprintln!("mirror sphere: probe vs rays mean FLIP {per_ball:.4} over {covered} pixels");
    assert!(per_ball <= 0.02, "probe reflection vs ray-traced reflection: mean FLIP {per_ball}");
    // And the final images agree as closely.
    let final_flip = mean_flip(w, h, &srgb_final(&traced), &srgb_final(&raster));
    assert!(final_flip <= 0.02, "{final_flip}");
    // Without fallbacks the ball is black (no reflection at all): the comparison is not vacuous.
    r.fallback = Fallback::None;
    let none = render(&mut r, &scene.camera, Mode::Raster, w, h);
    assert!(mean_flip(w, h, &srgb_final(&traced), &srgb_final(&none)) > 0.05);
}

fn srgb_final(f: &Frame) -> Vec<u8> {
    f.buffers.final_srgb.iter().flat_map(|p| [p[0], p[1], p[2]]).collect()
}

#[test]
fn point_and_spot_maps_render_once_along_a_camera_path() {
    let scene = scene_with(&format!("{POINT}\n{SPOT}\n{DIRECTIONAL}"));
    let mut r = CpuRenderer::new(&scene).unwrap();
    let mut total = 0;
    for k in 0..6 {
        let t = k as f32 * 0.4;
        let camera = Camera { position: Vec3::new(6.0 * t.sin(), 7.0, 6.0 * t.cos()), ..scene.camera };
        let f = render(&mut r, &camera, Mode::Raster, 96, 64);
        total += f.report.fallback_renders.shadow_maps;
    }
    let cache = r.fallback_cache().unwrap();
    // Lights in order directional, point, spot.
    let renders = &cache.shadow_map_renders;
    eprintln!("shadow maps rendered per light along the path: {renders:?} (frames' total {total})");
    assert_eq!(renders[1], 6, "the point light's six cube faces, once");
    assert_eq!(renders[2], 1, "the spot light's map, once");
    assert!(renders[0] >= 3, "the cascades at least once");
    assert_eq!(renders.iter().sum::<u64>(), total);
}

#[test]
fn fallback_none_is_the_paper() {
    // `--fallback none`: a raster frame is the lighting exactly; no fallback buffers.
    let scene = scene_with(DIRECTIONAL);
    let mut r = CpuRenderer::new(&scene).unwrap();
    r.fallback = Fallback::None;
    let f = render(&mut r, &scene.camera, Mode::Raster, 64, 48);
    assert!(f.buffers.shadow_fallback.is_empty());
    let lit: Vec<[u8; 4]> = f.buffers.lighting.iter().map(|c| hybrid_core::blend::encode_srgb(*c)).collect();
    assert_eq!(f.buffers.final_srgb, lit);
    assert!(f.report.effects.iter().all(|e| e.shadow == hybrid_core::fallback::EffectPath::None));
    // With fallbacks the ground's shadow path says raster.
    r.fallback = Fallback::Raster;
    let f = render(&mut r, &scene.camera, Mode::Raster, 64, 48);
    let ground = f.report.effects.iter().find(|e| e.name == "ground").unwrap();
    assert_eq!(ground.shadow, hybrid_core::fallback::EffectPath::Raster);
}

#[test]
fn glass_pane_cube_and_sphere_refract_as_rays_do() {
    // Clear glass (no reflection, fully transparent) in front of coloured boxes: a pane
    // modelled as a thin box, a cube and a sphere, each turned so that the rays bend. The
    // fallback refracts in and out of each (the pane and the cube through the see-through
    // layer, the sphere into its probe), as the trace stage's rays do.
    let text = r#"
[camera]
position = [0.0, 1.2, 5.0]
target = [0.0, 1.0, 0.0]
fov = 50

[environment]
ambient = [0.2, 0.2, 0.2]

[environment.skybox]
zenith = [0.1, 0.25, 0.9]
horizon = [0.95, 0.9, 0.8]
ground = [0.3, 0.2, 0.1]

[[material]]
name = "glass"
diffuse = [0.0, 0.0, 0.0]
opacity = 0.0
ior = 1.5

[[material]]
name = "red"
diffuse = [0.9, 0.1, 0.1]

[[material]]
name = "green"
diffuse = [0.1, 0.8, 0.2]

[[material]]
name = "blue"
diffuse = [0.1, 0.2, 0.9]

[[material]]
name = "floor"
diffuse = [0.7, 0.7, 0.6]

[[object]]
name = "floor"
primitive = "plane"
scale = 20.0
material = "floor"

[[object]]
name = "pane"
primitive = "cube"
position = [-1.6, 1.0, 1.5]
rotation = [0.0, 35.0, 0.0]
scale = [1.4, 1.6, 0.06]
material = "glass"

[[object]]
name = "cube"
primitive = "cube"
position = [0.1, 0.9, 1.5]
rotation = [10.0, 30.0, 0.0]
scale = 0.9
material = "glass"

[[object]]
name = "ball"
primitive = "sphere"
slices = 64
stacks = 32
position = [1.7, 1.0, 1.5]
scale = 1.1
material = "glass"

[[object]]
name = "red-box"
primitive = "cube"
position = [-1.5, 0.6, -1.5]
scale = [1.2, 1.2, 0.5]
material = "red"

[[object]]
name = "green-box"
primitive = "cube"
position = [0.0, 1.0, -2.0]
rotation = [0.0, 20.0, 0.0]
scale = [1.0, 2.0, 0.5]
material = "green"

[[object]]
name = "blue-box"
primitive = "cube"
position = [1.6, 0.5, -1.0]
scale = [0.8, 1.0, 0.8]
material = "blue"

[[light]]
type = "directional"
direction = [-0.3, -1.0, -0.5]
intensity = 1.0
"#;
    let scene = parse_scene(text, Path::new("glass.toml")).unwrap();
    let prepared = hybrid_core::prepare::PreparedScene::new(&scene);
    let refractors = hybrid_core::fallback::refractors(&prepared);
    assert!(matches!(refractors[1], Some(hybrid_core::fallback::Refractor::Hull(_))), "the pane");
    assert!(matches!(refractors[2], Some(hybrid_core::fallback::Refractor::Hull(_))), "the cube");
    assert!(matches!(refractors[3], Some(hybrid_core::fallback::Refractor::Sphere { .. })), "the ball");
    let mut r = CpuRenderer::new(&scene).unwrap();
    let (w, h) = (240, 160);
    let traced = render(&mut r, &scene.camera, Mode::All, w, h);
    let raster = render(&mut r, &scene.camera, Mode::Raster, w, h);
    let mut flips = Vec::new();
    for (object, name) in [(1u32, "pane"), (2, "cube"), (3, "ball")] {
        let covered = traced.gbuffer.object_id.iter().filter(|&&id| id == object).count();
        assert!(covered > 1000, "{name}: {covered} pixels");
        let only = |v: &[Vec3]| -> Vec<Vec3> {
            v.iter().zip(&traced.gbuffer.object_id).map(|(c, &id)| if id == object { *c } else { Vec3::ZERO }).collect()
        };
        let (a, b) = (srgb8(&only(&traced.buffers.refraction)), srgb8(&only(&raster.buffers.refraction_fallback)));
        let per_object = mean_flip(w, h, &a, &b) * (w * h) as f32 / covered as f32;
        eprintln!("{name}: fallback refraction vs rays, mean FLIP {per_object:.4} over {covered} pixels");
        flips.push(per_object);
    }
    let final_flip = mean_flip(w, h, &srgb_final(&traced), &srgb_final(&raster));
    eprintln!("final images: mean FLIP {final_flip:.4}");
    // Measured: pane 0.009, cube 0.18, ball 0.065, final 0.020. Refracted once (into the
    // layer or the probe, as before `Refractor`) they were 0.17, 0.87, 0.40 and 0.12. The
    // cube keeps the most error: rays reflected inside it more than once, and rays leaving it
    // towards the camera, which the layer cannot show.
    let [pane, cube, ball] = flips[..] else { unreachable!() };
    assert!(pane <= 0.02 && cube <= 0.25 && ball <= 0.1, "fallback refraction vs rays, mean FLIP: pane {pane}, cube {cube}, ball {ball}");
    assert!(final_flip <= 0.03, "final images: mean FLIP {final_flip}");
    // The see-through layer is kept while the view stays the same (the traced frame needed none).
    let renders = |r: &CpuRenderer| r.fallback_cache().unwrap().see_through_renders;
    assert_eq!(renders(&r), 1);
    let again = render(&mut r, &scene.camera, Mode::Raster, w, h);
    assert_eq!(renders(&r), 1);
    assert_eq!(again.buffers.refraction_fallback, raster.buffers.refraction_fallback);
    // ... and while it stays close: moved by 0.9 of what `see_through_layer_kept` allows from
    // the nearest see-through object, the kept layer gives nearly the refractions a fresh one
    // does; moved by 1.1 of it, the layer is rendered again.
    let see_through = hybrid_core::fallback::see_through_objects(&prepared, &refractors);
    let needed = vec![true; see_through.len()];
    let nearest = hybrid_core::fallback::nearest_see_through(scene.camera.position, &prepared.object_bounds, &see_through, &needed);
    assert!(nearest > 1.0 && nearest < 10.0, "{nearest}");
    let step = nearest * hybrid_core::fallback::SEE_THROUGH_KEEP_DEGREES.to_radians().tan();
    let moved = |by: f32| Camera { position: scene.camera.position + Vec3::new(by, 0.0, 0.0), ..scene.camera };
    let kept = render(&mut r, &moved(0.9 * step), Mode::Raster, w, h);
    assert_eq!(renders(&r), 1, "kept within {step}");
    let fresh = render(&mut CpuRenderer::new(&scene).unwrap(), &moved(0.9 * step), Mode::Raster, w, h);
    assert_ne!(kept.buffers.refraction_fallback, fresh.buffers.refraction_fallback, "the kept layer is not a fresh one");
    let kept_flip = mean_flip(w, h, &srgb_final(&fresh), &srgb_final(&kept));
    eprintln!("kept see-through layer vs a fresh one, moved {:.3}: final images mean FLIP {kept_flip:.4}", 0.9 * step);
    assert!(kept_flip <= 0.01, "{kept_flip}");
    render(&mut r, &moved(1.1 * step), Mode::Raster, w, h);
    assert_eq!(renders(&r), 2);
}
