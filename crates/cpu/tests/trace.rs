//! Trace stage (paper 1 listings 8a–d) on tiny hand-built scenes with hand-computed answers.

use glam::Vec3;
use hybrid_core::PreparedScene;
use hybrid_core::blend::blend_pixel;
use hybrid_core::shading::Light;
use hybrid_core::{GBuffer, Surface};
use hybrid_cpu::bvh::SceneBvh;
use hybrid_cpu::trace::{RayCounts, TraceOutput, primary_ray_count, rt_only_gbuffer, trace};
use hybrid_scene::primitives::{cuboid, quad};
use hybrid_scene::{Camera, ColorSpace, DirectionalLight, Environment, Lights, Material, Mesh, Projection, Scene, Skybox, Texture};

const SKY: Vec3 = Vec3::new(0.3, 0.6, 0.9);

fn scene(materials: Vec<Material>, meshes: Vec<Mesh>, lights: Lights, camera: Camera) -> Scene {
    let mut scene = Scene::new(camera);
    scene.environment = Environment { ambient: Vec3::ZERO, ior: 1.0, skybox: Skybox::Color(SKY) };
    scene.materials = materials;
    scene.lights = lights;
    for (i, m) in meshes.into_iter().enumerate() {
        scene.push_mesh_object(format!("object {i}"), m);
    }
    scene
}

fn camera(position: Vec3, target: Vec3) -> Camera {
    Camera { position, target, up: Vec3::Y, projection: Projection::Perspective { fov_y_deg: 40.0, near: 0.1, far: 100.0 } }
}

/// A 1×1 G-buffer holding `s` (object 0), mask 1.
fn one_pixel(s: &Surface) -> GBuffer {
    let mut g = GBuffer::new(1, 1);
    g.write(0, 0, 0.5, s);
    g.mask[0] = 1.0;
    g
}

fn close(a: Vec3, b: Vec3, eps: f32) -> bool {
    (a - b).abs().max_element() <= eps
}

fn run(scene: &Scene, g: &GBuffer) -> TraceOutput {
    let prepared = PreparedScene::new(scene);
    let bvh = SceneBvh::build(&prepared);
    trace(&prepared, &bvh, g, &scene.camera)
}

fn emissive(c: Vec3) -> Material {
    Material { emission: c, ambient: Vec3::ZERO, diffuse: Vec3::ZERO, ..Default::default() }
}

#[test]
fn mirror_shows_an_emissive_quad() {
    let glow = Vec3::new(0.2, 0.5, 0.9);
    // The emissive quad 2 m in front of the mirror, facing it.
    let s = scene(
        vec![emissive(glow)],
        vec![quad(Vec3::new(0.0, 0.0, 2.0), Vec3::X, -Vec3::Y, 0)],
        Lights::default(),
        camera(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO),
    );
    let mirror = Surface {
        position: Vec3::ZERO,
        normal: Vec3::Z,
        diffuse: Vec3::splat(0.5),
        opacity: 1.0,
        reflectivity: 1.0,
        ior: 1.5,
        ..Default::default()
    };
    let out = run(&s, &one_pixel(&mirror));
    assert!(close(out.reflection[0], glow, 1e-6), "{}", out.reflection[0]);
    assert_eq!(out.refraction[0], Vec3::ZERO);
    assert_eq!(out.shadow[0], Vec3::ONE);
    assert_eq!(out.rays, RayCounts { primary: 0, shadow: 0, reflection: 1, refraction: 0 });
    // Blended: a perfect mirror is its reflection.
    let b = blend_pixel(Vec3::splat(0.7), out.shadow[0], out.reflection[0], out.refraction[0], Vec3::new(1.0, 1.5, 1.0), 1.0);
    assert!(close(b, glow, 1e-6));
    // Turned away from the quad, the mirror sees the sky.
    let away = Surface { normal: -Vec3::Z, position: Vec3::new(0.0, 0.0, -1.0), ..mirror };
    let s2 = Scene { camera: camera(Vec3::new(0.0, 0.0, -5.0), Vec3::ZERO), ..s.clone() };
    let out = run(&s2, &one_pixel(&away));
    assert!(close(out.reflection[0], SKY, 1e-6), "{}", out.reflection[0]);
}

#[test]
fn glass_slab_of_ior_one_leaves_the_sky_unchanged() {
    let glass = Material { opacity: 0.0, ior: 1.0, diffuse: Vec3::splat(0.5), ..Default::default() };
    let cam = Camera {
        position: Vec3::new(0.0, 0.0, 5.0),
        target: Vec3::ZERO,
        up: Vec3::Y,
        projection: Projection::Orthographic { height: 1.0, near: 0.1, far: 20.0 },
    };
    let s = scene(vec![glass], vec![cuboid(Vec3::new(-2.0, -2.0, -0.5), Vec3::new(2.0, 2.0, 0.5), 0)], Lights::default(), cam);
    let prepared = PreparedScene::new(&s);
    let bvh = SceneBvh::build(&prepared);
    let g = rt_only_gbuffer(&prepared, &bvh, &s.camera, 16, 12);
    assert!(g.mask.iter().all(|&m| m == 1.0), "the slab covers the whole view");
    assert!(g.normal.iter().all(|n| close(*n, Vec3::Z, 1e-6)));
    let out = trace(&prepared, &bvh, &g, &s.camera);
    for i in 0..g.len() {
        assert!(close(out.refraction[i], SKY, 1e-6), "pixel {i}: {}", out.refraction[i]);
        let b = blend_pixel(Vec3::splat(0.1), out.shadow[i], out.reflection[i], out.refraction[i], g.optical[i], g.mask[i]);
        assert!(close(b, SKY, 1e-6), "pixel {i}: {b}");
    }
    // Front face → back face (depth 1, fully transparent, so traced on) → sky: 2 rays a pixel.
    assert_eq!(out.rays, RayCounts { primary: 0, shadow: 0, reflection: 0, refraction: 2 * 16 * 12 });
    assert_eq!(primary_ray_count(16, 12), 192);
}

/// Floor pixel at the origin lit by two directional lights: one from straight above (blocked
/// by a small quad 1 m up, off-centre so the ray misses its diagonal: a ray through an edge
/// shared by two triangles may count both), one at 45° (passes beside it).
fn two_light_shadow(occluder: Material, textures: Vec<Texture>) -> (Vec3, Vec3, RayCounts) {
    let floor = Material { diffuse: Vec3::splat(0.5), ..Default::default() };
    let above = DirectionalLight { direction: -Vec3::Y, color: Vec3::ONE, intensity: 1.0, casts_shadows: true };
    let slanted = DirectionalLight {
        direction: Vec3::new(-1.0, -1.0, 0.0).normalize(),
        color: Vec3::new(1.0, 0.5, 0.25),
        intensity: 1.0,
        casts_shadows: true,
    };
    let lights = Lights { directional: vec![above, slanted], ..Default::default() };
    let mut s = scene(
        vec![floor, occluder],
        vec![quad(Vec3::ZERO, Vec3::X * 3.0, -Vec3::Z * 3.0, 0), quad(Vec3::new(0.05, 1.0, 0.03), Vec3::X * 0.2, -Vec3::Z * 0.2, 1)],
        lights,
        camera(Vec3::new(0.0, 5.0, 5.0), Vec3::ZERO),
    );
    s.textures = textures;
    let p = Surface { position: Vec3::ZERO, normal: Vec3::Y, diffuse: Vec3::splat(0.5), opacity: 1.0, ior: 1.5, ..Default::default() };
    let view = (s.camera.position - p.position).normalize();
    let blocked = Light::Directional(&above).blinn_phong(&p, view);
    assert!(close(blocked, Vec3::splat(0.5), 1e-6));
    let out = run(&s, &one_pixel(&p));
    (out.shadow[0], blocked, out.rays)
}

#[test]
fn opaque_occluder_removes_exactly_one_light() {
    let (shadow, blocked, rays) = two_light_shadow(Material::default(), Vec::new());
    assert!(close(shadow, Vec3::ONE - blocked, 1e-6), "{shadow}");
    assert_eq!(rays, RayCounts { primary: 0, shadow: 2, reflection: 0, refraction: 0 });
}

#[test]
fn half_transparent_occluder_removes_half() {
    let (shadow, blocked, _) = two_light_shadow(Material { opacity: 0.5, ..Default::default() }, Vec::new());
    assert!(close(shadow, Vec3::ONE - blocked * 0.5, 1e-6), "{shadow}");
}

#[test]
fn textured_opacity_counts_in_shadows() {
    // Diffuse-map alpha 0 makes the occluder fully transparent (evaluated with surface_at).
    let tex = Texture::solid("clear", [255, 255, 255, 0], ColorSpace::Srgb);
    let (shadow, _, _) = two_light_shadow(Material { diffuse_map: Some(0), ..Default::default() }, vec![tex]);
    assert!(close(shadow, Vec3::ONE, 1e-6), "{shadow}");
    // Alpha 255: an opaque blocker again.
    let tex = Texture::solid("solid", [255, 255, 255, 255], ColorSpace::Srgb);
    let (shadow, blocked, _) = two_light_shadow(Material { diffuse_map: Some(0), ..Default::default() }, vec![tex]);
    assert!(close(shadow, Vec3::ONE - blocked, 1e-6), "{shadow}");
}

#[test]
fn non_shadow_casting_occluder_removes_nothing() {
    let (shadow, _, rays) = two_light_shadow(Material { casts_shadows: false, ..Default::default() }, Vec::new());
    assert!(close(shadow, Vec3::ONE, 1e-6), "{shadow}");
    assert_eq!(rays.shadow, 2);
}

#[test]
fn grazing_ray_inside_glass_is_totally_reflected() {
    // The G-buffer surface is the top face of glass (normal +Y), seen from inside the glass
    // 10° below the face: leaving 1.5 → 1 at 80° incidence is beyond the critical angle (41.8°).
    // The reflected ray goes down towards a red wall; a refracted one would go up to the sky.
    let red = Vec3::new(1.0, 0.0, 0.0);
    let a = 10f32.to_radians();
    let cam = camera(Vec3::new(-5.0 * a.cos(), -5.0 * a.sin(), 0.0), Vec3::ZERO);
    let s = scene(vec![emissive(red)], vec![quad(Vec3::new(3.0, -1.0, 0.0), Vec3::Y * 1.5, Vec3::Z * 1.5, 0)], Lights::default(), cam);
    let glass = Surface { position: Vec3::ZERO, normal: Vec3::Y, opacity: 0.0, ior: 1.5, ..Default::default() };
    let out = run(&s, &one_pixel(&glass));
    assert!(close(out.refraction[0], red, 1e-6), "{}", out.refraction[0]);
    assert_eq!(out.rays.refraction, 1);
    // At 20° incidence (70° from the face) it refracts out and sees the sky.
    let b = 70f32.to_radians();
    let cam = camera(Vec3::new(-5.0 * b.cos(), -5.0 * b.sin(), 0.0), Vec3::ZERO);
    let s = Scene { camera: cam, ..s };
    let out = run(&s, &one_pixel(&glass));
    assert!(close(out.refraction[0], SKY, 1e-6), "{}", out.refraction[0]);
}

#[test]
fn unmasked_and_sky_pixels() {
    let s = scene(
        vec![Material::default()],
        vec![quad(Vec3::ZERO, Vec3::X, Vec3::Y, 0)],
        Lights::default(),
        camera(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO),
    );
    let mut g = GBuffer::new(2, 1);
    let p = Surface { normal: Vec3::Z, opacity: 0.0, reflectivity: 1.0, ior: 1.5, ..Default::default() };
    g.write(0, 0, 0.5, &p); // covered but mask 0: not traced
    g.mask[1] = 1.0; // masked but nothing drawn: skybox reflection
    let out = run(&s, &g);
    assert_eq!((out.shadow[0], out.reflection[0], out.refraction[0]), (Vec3::ONE, Vec3::ZERO, Vec3::ZERO));
    assert_eq!((out.shadow[1], out.reflection[1], out.refraction[1]), (Vec3::ONE, SKY, Vec3::ZERO));
    assert_eq!(out.rays, RayCounts::default());
}

#[test]
fn rt_only_depth_matches_the_projection_and_covers_the_quad() {
    let (n, f, d) = (0.1f32, 100.0f32, 5.0f32);
    let s = scene(
        vec![Material::default()],
        vec![quad(Vec3::ZERO, Vec3::X, Vec3::Y, 0)],
        Lights::default(),
        camera(Vec3::new(0.0, 0.0, d), Vec3::ZERO),
    );
    let prepared = PreparedScene::new(&s);
    let bvh = SceneBvh::build(&prepared);
    let (w, h) = (40, 30);
    let g = rt_only_gbuffer(&prepared, &bvh, &s.camera, w, h);
    // The quad spans ±1 m at 5 m with a 40° vertical fov: tan(20°)·5 = 1.82 m half-height, so
    // it covers |ndc| < 1/1.82 vertically and 1/(1.82·4/3) horizontally.
    let half_h = (20f32.to_radians()).tan() * d;
    let vp = s.camera.view_projection(w as f32 / h as f32);
    let mut covered = 0;
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            let nx = (x as f32 + 0.5) / w as f32 * 2.0 - 1.0;
            let ny = 1.0 - (y as f32 + 0.5) / h as f32 * 2.0;
            let aspect = w as f32 / h as f32;
            let inside = nx.abs() * half_h * aspect < 1.0 && ny.abs() * half_h < 1.0;
            assert_eq!(g.mask[i] == 1.0, inside, "pixel {x},{y}");
            if inside {
                covered += 1;
                let closed = n * f / ((f - n) * d) - n / (f - n);
                assert!((g.depth[i] - closed).abs() < 1e-6, "{} vs {closed}", g.depth[i]);
                // The hit projects back onto the pixel centre.
                let p = vp.project_point3(g.position[i]);
                assert!((p.x - nx).abs() < 1e-4 && (p.y - ny).abs() < 1e-4);
                assert_eq!(g.object_id[i], 0);
            } else {
                assert_eq!(g.object_id[i], hybrid_core::NO_OBJECT);
            }
        }
    }
    assert!(covered > 50);
}

/// A small scene with every effect: mirror box, glass box, diffuse floor, two lights.
fn busy_scene() -> Scene {
    let mats = vec![
        Material { diffuse: Vec3::new(0.6, 0.5, 0.4), specular: Vec3::splat(0.3), shininess: 0.4, ..Default::default() },
        Material { reflectivity: 0.8, diffuse: Vec3::splat(0.2), ..Default::default() },
        Material { opacity: 0.1, ior: 1.5, reflectivity: 0.1, diffuse: Vec3::new(0.2, 0.4, 0.3), ..Default::default() },
    ];
    let meshes = vec![
        quad(Vec3::ZERO, Vec3::X * 4.0, -Vec3::Z * 4.0, 0),
        cuboid(Vec3::new(-1.5, 0.0, -1.0), Vec3::new(-0.3, 1.2, 0.2), 1),
        cuboid(Vec3::new(0.3, 0.0, -0.5), Vec3::new(1.4, 1.0, 0.6), 2),
    ];
    let lights = Lights {
        directional: vec![DirectionalLight {
            direction: Vec3::new(-0.3, -1.0, -0.4).normalize(),
            color: Vec3::ONE,
            intensity: 0.8,
            casts_shadows: true,
        }],
        point: vec![hybrid_scene::PointLight {
            position: Vec3::new(1.0, 3.0, 2.0),
            color: Vec3::new(1.0, 0.9, 0.8),
            intensity: 6.0,
            attenuation: Default::default(),
            casts_shadows: true,
        }],
        ..Default::default()
    };
    scene(mats, meshes, lights, camera(Vec3::new(0.5, 2.5, 6.0), Vec3::new(0.0, 0.5, 0.0)))
}

#[test]
fn deterministic_with_one_or_two_threads() {
    let s = busy_scene();
    let prepared = PreparedScene::new(&s);
    let bvh = SceneBvh::build(&prepared);
    let run_with = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("thread pool");
        pool.install(|| {
            let g = rt_only_gbuffer(&prepared, &bvh, &s.camera, 64, 48);
            let out = trace(&prepared, &bvh, &g, &s.camera);
            (g, out)
        })
    };
    let (g1, o1) = run_with(1);
    let (g2, o2) = run_with(2);
    let bits = |v: &[Vec3]| v.iter().flat_map(|c| c.to_array().map(f32::to_bits)).collect::<Vec<_>>();
    assert_eq!(g1.depth.iter().map(|d| d.to_bits()).collect::<Vec<_>>(), g2.depth.iter().map(|d| d.to_bits()).collect::<Vec<_>>());
    assert_eq!(bits(&o1.shadow), bits(&o2.shadow));
    assert_eq!(bits(&o1.reflection), bits(&o2.reflection));
    assert_eq!(bits(&o1.refraction), bits(&o2.refraction));
    assert_eq!(o1.rays, o2.rays);
    // The scene exercises every ray kind, with some shadowed and some inter-reflected pixels.
    assert!(o1.rays.shadow > 0 && o1.rays.reflection > 0 && o1.rays.refraction > 0, "{:?}", o1.rays);
    assert!(o1.shadow.iter().any(|s| s.x < 0.9));
    assert!(o1.reflection.iter().zip(&g1.optical).any(|(r, o)| o.x > 0.5 && *r != SKY && *r != Vec3::ZERO));
}

#[test]
fn facing_mirrors_stop_at_max_depth() {
    // Two perfect mirrors 2 m apart: the reflection ray bounces until max depth, where listing 8c
    // replaces both children by the lighting (0 on a fully reflective surface).
    let mirror = Material { reflectivity: 1.0, emission: Vec3::splat(0.5), ..Default::default() };
    let mut s = scene(
        vec![mirror],
        vec![quad(Vec3::ZERO, Vec3::X, Vec3::Y, 0), quad(Vec3::new(0.0, 0.0, 2.0), Vec3::X, -Vec3::Y, 0)],
        Lights::default(),
        camera(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO),
    );
    let p = Surface { position: Vec3::ZERO, normal: Vec3::Z, opacity: 1.0, reflectivity: 1.0, ior: 1.5, ..Default::default() };
    for (max_depth, rays) in [(1, 1), (5, 5), (1_000_000, hybrid_cpu::trace::MAX_TRACED_DEPTH as u64)] {
        s.trace.max_depth = max_depth;
        let out = run(&s, &one_pixel(&p));
        assert_eq!(out.rays.reflection, rays, "max depth {max_depth}");
        assert_eq!(out.reflection[0], Vec3::ZERO);
    }
    // A 0.5-reflective mirror pair: ray k carries importance 0.5^k; ray 7 would carry
    // 0.5^7 = 0.0078 < cutoff 0.01, so the chain stops at 6 rays although max depth is 10.
    s.materials[0].reflectivity = 0.5;
    s.trace.max_depth = 10;
    let half = Surface { reflectivity: 0.5, ..p };
    let out = run(&s, &one_pixel(&half));
    assert_eq!(out.rays.reflection, 6);
    assert!(out.reflection[0].x > 0.0);
}

/// The rt-only rays of `file` (in `tests/data`) at 8×6.
fn rt_only_rays(file: &str) -> RayCounts {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data").join(file);
    let s = hybrid_scene::load_scene(&path).unwrap();
    let prepared = PreparedScene::new(&s);
    let bvh = SceneBvh::build(&prepared);
    let g = rt_only_gbuffer(&prepared, &bvh, &s.camera, 8, 6);
    assert!(g.object_id.iter().all(|&id| id != hybrid_core::NO_OBJECT), "{file}: every pixel sees the scene");
    trace(&prepared, &bvh, &g, &s.camera).rays
}

#[test]
fn ray_trees_stop_at_the_ray_budget() {
    use hybrid_cpu::trace::TRACE_RAY_BUDGET;
    // Glass between parallel mirrors: every tree (reflection and refraction per pixel) would
    // double per glass hit; each is cut at exactly the budget.
    let rays = rt_only_rays("ray-budget.toml");
    assert_eq!(rays.reflection + rays.refraction, 48 * 2 * TRACE_RAY_BUDGET as u64, "{rays:?}");
    // Glass in a mirror box at max_depth 64 (ran for minutes before the budget): bounded.
    let rays = rt_only_rays("mirror-box.toml");
    assert!(rays.reflection + rays.refraction <= 48 * 2 * TRACE_RAY_BUDGET as u64, "{rays:?}");
    assert!(rays.reflection + rays.refraction > 48 * TRACE_RAY_BUDGET as u64, "the budget binds: {rays:?}");
}
