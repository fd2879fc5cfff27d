//! Raster stage and deferred lighting on small hand-built scenes with analytic answers.

use glam::{Vec2, Vec3};
use hybrid_core::PreparedScene;
use hybrid_core::{GBuffer, NO_OBJECT, RT_SCENE_OBJECT, RtLayer};
use hybrid_cpu::camera_rays::{ViewRays, primary_ray};
use hybrid_cpu::depth_merge::merge_rt_layer;
use hybrid_cpu::lighting::deferred_lighting;
use hybrid_cpu::raster::{rasterize, rasterize_into};
use hybrid_scene::{Attenuation, Camera, ColorSpace, Environment, Lights, Material, Mesh, PointLight, Projection, Scene, Skybox, Texture};

const SKY: Vec3 = Vec3::new(0.3, 0.6, 0.9);
const W: u32 = 160;
const H: u32 = 90;

fn scene(materials: Vec<Material>, meshes: Vec<Mesh>, lights: Lights, camera: Camera) -> Scene {
    let mut scene = Scene::new(camera);
    scene.environment = Environment { ambient: Vec3::splat(0.1), ior: 1.0, skybox: Skybox::Color(SKY) };
    scene.materials = materials;
    scene.lights = lights;
    for (i, m) in meshes.into_iter().enumerate() {
        scene.push_mesh_object(format!("object {i}"), m);
    }
    scene
}

/// A quad from four corners (two triangles 0-1-2, 0-2-3) with UVs (0,0), (1,0), (1,1), (0,1).
fn quad(c: [Vec3; 4], material: usize) -> Mesh {
    Mesh {
        positions: c.to_vec(),
        uvs: vec![Vec2::new(0.0, 0.0), Vec2::new(1.0, 0.0), Vec2::new(1.0, 1.0), Vec2::new(0.0, 1.0)],
        indices: vec![[0, 1, 2], [0, 2, 3]],
        material,
        ..Default::default()
    }
}

fn tri(c: [Vec3; 3], material: usize) -> Mesh {
    Mesh { positions: c.to_vec(), indices: vec![[0, 1, 2]], material, ..Default::default() }
}

/// A UV sphere of radius `r` at `centre` (the scene crate's unit-diameter primitive, placed).
fn sphere(centre: Vec3, r: f32, slices: u32, stacks: u32, material: usize) -> Mesh {
    let mut m = hybrid_scene::primitives::sphere(slices, stacks);
    m.positions.iter_mut().for_each(|p| *p = centre + *p * (2.0 * r));
    m.material = material;
    m
}

fn perspective(position: Vec3, target: Vec3) -> Camera {
    Camera { position, target, up: Vec3::Y, projection: Projection::Perspective { fov_y_deg: 60.0, near: 0.1, far: 200.0 } }
}

fn assert_finite(g: &GBuffer) {
    for i in 0..g.len() {
        let ok = g.position[i].is_finite()
            && g.normal[i].is_finite()
            && g.emission[i].is_finite()
            && g.ambient[i].is_finite()
            && g.diffuse[i].is_finite()
            && g.specular[i].is_finite()
            && g.optical[i].is_finite()
            && g.depth[i].is_finite();
        assert!(ok, "non-finite value at pixel {i}");
        assert!((0.0..=1.0).contains(&g.depth[i]), "depth {} out of range at {i}", g.depth[i]);
    }
}

/// Ray–triangle intersection (Möller–Trumbore): t and barycentrics.
fn hit_triangle(o: Vec3, d: Vec3, [a, b, c]: [Vec3; 3]) -> Option<(f32, Vec3)> {
    let (e1, e2) = (b - a, c - a);
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-12 {
        return None;
    }
    let s = o - a;
    let u = s.dot(p) / det;
    let q = s.cross(e1);
    let v = d.dot(q) / det;
    let t = e2.dot(q) / det;
    (u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t > 0.0).then_some((t, Vec3::new(1.0 - u - v, u, v)))
}

#[test]
fn triangle_crossing_the_near_plane_covers_what_the_rays_hit() {
    // A huge floor triangle reaching far behind the camera (w < 0 for one corner).
    let floor = [Vec3::new(-60.0, 0.0, 30.0), Vec3::new(60.0, 0.0, 30.0), Vec3::new(0.0, 0.0, -150.0)];
    let cam = perspective(Vec3::new(0.0, 1.0, 0.0), Vec3::new(0.0, 0.6, -3.0));
    let s = scene(vec![Material::default()], vec![tri(floor, 0)], Lights::default(), cam);
    let p = PreparedScene::new(&s);
    let g = rasterize(&p, &cam, W, H, None);
    assert_finite(&g);
    let rays = ViewRays::new(&cam, W, H);
    let (mut covered, mut mismatch) = (0, 0);
    for y in 0..H {
        for x in 0..W {
            let i = (y * W + x) as usize;
            let (o, d) = rays.ray(x, y);
            let hit = hit_triangle(o, d, floor).filter(|(t, _)| t * d.dot(cam.forward()) > 0.1);
            let drawn = g.object_id[i] == 0;
            if drawn != hit.is_some() {
                mismatch += 1;
            }
            if let (true, Some((t, _))) = (drawn, hit) {
                covered += 1;
                let want = o + d * t;
                assert!(g.position[i].distance(want) <= 1e-4 * t, "({x},{y}): {} vs {want}", g.position[i]);
            }
        }
    }
    // Everything below the horizon is floor: about half the image, and only silhouette pixels
    // (none here besides the horizon row) may differ.
    assert!(covered > (W * H / 3) as usize, "floor covers only {covered} pixels");
    assert!(mismatch <= W as usize, "{mismatch} pixels disagree with the ray cast");
}

#[test]
fn perspective_correct_interpolation_on_a_grazing_plane() {
    // A long plane seen at a grazing angle: positions interpolated per pixel must be the
    // ray–plane intersection (affine interpolation would be off by metres).
    let plane = [Vec3::new(-20.0, 0.0, 5.0), Vec3::new(20.0, 0.0, 5.0), Vec3::new(20.0, 0.0, -80.0), Vec3::new(-20.0, 0.0, -80.0)];
    let cam = perspective(Vec3::new(0.0, 1.5, 4.0), Vec3::new(0.0, 0.0, -6.0));
    let s = scene(vec![Material::default()], vec![quad(plane, 0)], Lights::default(), cam);
    let p = PreparedScene::new(&s);
    let g = rasterize(&p, &cam, W, H, None);
    assert_finite(&g);
    let vp = cam.view_projection(W as f32 / H as f32);
    let mut checked = 0;
    let mut worst = 0.0f32;
    for y in 0..H {
        for x in 0..W {
            let i = (y * W + x) as usize;
            if g.object_id[i] != 0 {
                continue;
            }
            let (o, d) = primary_ray(&cam, W, H, x, y);
            let t = -o.y / d.y;
            let want = o + d * t;
            let rel = g.position[i].distance(want) / t;
            worst = worst.max(rel);
            // Depth is the projection matrix's z of the surface point (reversed-Z).
            let z = vp.project_point3(g.position[i]).z;
            assert!((z - g.depth[i]).abs() <= 1e-5 * z.abs().max(1e-3), "({x},{y}): depth {} vs projected {z}", g.depth[i]);
            checked += 1;
        }
    }
    assert!(worst <= 1e-4, "worst relative position error {worst}");
    assert!(checked > 2000, "only {checked} pixels on the plane");
    // Far pixels have small depth, near ones large (reversed-Z): bottom row nearer than top.
    let col = W as usize / 2;
    let top = (0..H as usize).find(|&y| g.object_id[y * W as usize + col] == 0).unwrap_or(0);
    assert!(g.depth[(H as usize - 1) * W as usize + col] > g.depth[top * W as usize + col]);
}

#[test]
fn nearer_triangle_wins_regardless_of_submission_order() {
    let cam = perspective(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO);
    let near = quad([Vec3::new(-1.0, -1.0, 1.0), Vec3::new(1.0, -1.0, 1.0), Vec3::new(1.0, 1.0, 1.0), Vec3::new(-1.0, 1.0, 1.0)], 0);
    let far = quad([Vec3::new(-2.0, -0.5, -1.0), Vec3::new(2.0, -0.5, -1.0), Vec3::new(2.0, 0.5, -1.0), Vec3::new(-2.0, 0.5, -1.0)], 0);
    let centre = (H / 2 * W + W / 2) as usize;
    let vp = cam.view_projection(W as f32 / H as f32);
    for (meshes, near_id) in [(vec![near.clone(), far.clone()], 0u32), (vec![far, near], 1u32)] {
        let s = scene(vec![Material::default()], meshes, Lights::default(), cam);
        let p = PreparedScene::new(&s);
        let g = rasterize(&p, &cam, W, H, None);
        assert_eq!(g.object_id[centre], near_id);
        let want = vp.project_point3(Vec3::new(0.0, 0.0, 1.0)).z;
        assert!((g.depth[centre] - want).abs() < 1e-6, "{} vs {want}", g.depth[centre]);
        // The far quad still shows left and right of the near one.
        let side = (H / 2 * W + 57) as usize;
        assert_eq!(g.object_id[side], 1 - near_id);
        assert_eq!(g.object_id[0], NO_OBJECT);
        assert_eq!(g.depth[0], 0.0);
        assert_eq!(g.normal[0], Vec3::ZERO);
    }
}

/// A scene with enough triangles for several bands and setup chunks, textured (mip footprints).
fn busy_scene() -> (Scene, Camera) {
    let mut checker = Vec::new();
    for y in 0..16 {
        for x in 0..16 {
            checker.push(if (x + y) % 2 == 0 { [230, 40, 40, 255] } else { [20, 200, 60, 255] });
        }
    }
    let tex = Texture::new("checker", 16, 16, checker, ColorSpace::Srgb);
    let textured = Material { diffuse_map: Some(0), tiling: Vec2::splat(4.0), ..Material::default() };
    let mut meshes = Vec::new();
    for i in 0..12 {
        let c = Vec3::new((i % 4) as f32 * 1.6 - 2.4, (i / 4) as f32 * 1.4 - 1.2, -((i % 3) as f32));
        meshes.push(sphere(c, 0.8, 40, 20, i % 2));
    }
    // Coplanar overlapping quads: equal depths everywhere → first in scene order must win.
    let q = [Vec3::new(-6.0, -2.5, -3.0), Vec3::new(6.0, -2.5, -3.0), Vec3::new(6.0, 3.0, -3.0), Vec3::new(-6.0, 3.0, -3.0)];
    meshes.push(quad(q, 1));
    meshes.push(quad(q, 0));
    let cam = perspective(Vec3::new(0.3, 0.2, 4.0), Vec3::new(0.0, 0.0, -1.0));
    let mut s = scene(vec![Material::default(), textured], meshes, Lights::default(), cam);
    s.textures.push(tex);
    (s, cam)
}

#[test]
fn output_is_bit_identical_for_one_and_two_threads() {
    let (s, cam) = busy_scene();
    let p = PreparedScene::new(&s);
    let mut layer = RtLayer::new(W, H);
    for (i, d) in layer.depth.iter_mut().enumerate() {
        if i % 7 == 0 {
            *d = 0.02 + (i % 13) as f32 * 0.01;
            layer.color[i] = Vec3::new(0.5, 0.25, 0.125);
        }
    }
    let run = |threads: usize| -> GBuffer {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("thread pool");
        pool.install(|| rasterize(&p, &cam, W, H, Some(&layer)))
    };
    let (one, two) = (run(1), run(2));
    assert_finite(&one);
    assert!(one == two, "1-thread and 2-thread G-buffers differ");
    // The coplanar quads tie everywhere: the first (object 12) keeps every pixel it shares.
    assert!(one.object_id.contains(&12));
    assert!(!one.object_id.contains(&13), "the later coplanar quad won a tie");
    // Reusing a dirty buffer gives the same result as a fresh one.
    let mut reused = GBuffer::new(W, H);
    reused.object_id.iter_mut().for_each(|o| *o = 5);
    reused.mask.iter_mut().for_each(|m| *m = 1.0);
    reused.position.iter_mut().for_each(|p| *p = Vec3::ONE);
    rasterize_into(&p, &cam, Some(&layer), &mut reused);
    assert!(reused == one, "rasterize_into on a reused buffer differs");
}

#[test]
fn rt_layer_merges_by_depth() {
    // A wall at z = 0 seen from z = 5; the RT layer is nearer at one pixel and farther at another.
    let cam = perspective(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO);
    let wall = quad([Vec3::new(-5.0, -5.0, 0.0), Vec3::new(5.0, -5.0, 0.0), Vec3::new(5.0, 5.0, 0.0), Vec3::new(-5.0, 5.0, 0.0)], 0);
    let s = scene(vec![Material::default()], vec![wall], Lights::default(), cam);
    let p = PreparedScene::new(&s);
    let vp = cam.view_projection(W as f32 / H as f32);
    let wall_depth = vp.project_point3(Vec3::ZERO).z;
    let nearer = vp.project_point3(Vec3::new(0.0, 0.0, 2.0)).z;
    let farther = vp.project_point3(Vec3::new(0.0, 0.0, -2.0)).z;
    let (a, b) = ((40 * W + 80) as usize, (50 * W + 60) as usize);
    let mut layer = RtLayer::new(W, H);
    layer.depth[a] = nearer;
    layer.color[a] = Vec3::new(0.9, 0.1, 0.2);
    layer.depth[b] = farther;
    layer.color[b] = Vec3::new(0.1, 0.9, 0.2);
    let g = rasterize(&p, &cam, W, H, Some(&layer));
    assert_eq!(g.object_id[a], RT_SCENE_OBJECT);
    assert_eq!(g.depth[a], nearer);
    assert_eq!(g.emission[a], layer.color[a]);
    assert_eq!(g.diffuse[a].w, 1.0);
    assert_eq!(g.optical[a], Vec3::new(0.0, 1.0, 1.0));
    // Position: the pixel centre unprojected at the layer depth (on the plane z = 2), normal
    // towards the camera.
    let (o, d) = primary_ray(&cam, W, H, 80, 40);
    let want = o + d * ((2.0 - o.z) / d.z);
    assert!(g.position[a].distance(want) < 1e-4, "{} vs {want}", g.position[a]);
    assert!(g.normal[a].distance((cam.position - want).normalize()) < 1e-4);
    assert_eq!(g.object_id[b], 0, "a farther RT pixel must be overwritten by the wall");
    assert!((g.depth[b] - wall_depth).abs() < 1e-4);
    // Deferred lighting of an RT pixel reproduces its colour.
    let lit = deferred_lighting(&g, &s, &cam);
    assert!((lit[a] - layer.color[a]).abs().max_element() < 1e-6);
    // The merge into a finished G-buffer (rt-only mode) agrees.
    let mut g2 = rasterize(&p, &cam, W, H, None);
    merge_rt_layer(&mut g2, &layer, &cam);
    assert!(g2 == g, "merge_rt_layer differs from merging during the raster");
}

#[test]
fn deferred_lighting_matches_hand_computed_blinn_phong() {
    // Diffuse floor y = 0 (albedo 0.5, ambient 1), a point light 2 m above the origin with
    // intensity 4 and 1/d² attenuation, environment ambient 0.1; camera looking down at it.
    let floor = quad([Vec3::new(-5.0, 0.0, 5.0), Vec3::new(5.0, 0.0, 5.0), Vec3::new(5.0, 0.0, -5.0), Vec3::new(-5.0, 0.0, -5.0)], 0);
    let mat = Material { diffuse: Vec3::splat(0.5), ambient: Vec3::ONE, ..Material::default() };
    let light = PointLight {
        position: Vec3::new(0.0, 2.0, 0.0),
        color: Vec3::ONE,
        intensity: 4.0,
        attenuation: Attenuation { constant: 0.0, linear: 0.0, quadratic: 1.0 },
        casts_shadows: true,
    };
    let lights = Lights { point: vec![light], ..Lights::default() };
    let cam = perspective(Vec3::new(0.0, 3.0, 3.0), Vec3::ZERO);
    let s = scene(vec![mat], vec![floor], lights, cam);
    let p = PreparedScene::new(&s);
    let g = rasterize(&p, &cam, W, H, None);
    let lit = deferred_lighting(&g, &s, &cam);
    let mut checked = 0;
    for (x, y) in [(80u32, 45u32), (20, 70), (140, 80), (100, 30)] {
        let i = (y * W + x) as usize;
        assert_eq!(g.object_id[i], 0, "pixel ({x},{y}) should see the floor");
        let pos = g.position[i];
        assert!(pos.y.abs() < 1e-5);
        // By hand: L = 0.1·1 + 0.5 · cos θ · 4 / d², cos θ = 2 / d.
        let d = (light.position - pos).length();
        let want = 0.1 + 0.5 * (2.0 / d) * 4.0 / (d * d);
        assert!((lit[i] - Vec3::splat(want)).abs().max_element() < 1e-5, "({x},{y}): {} vs {want}", lit[i]);
        checked += 1;
    }
    assert_eq!(checked, 4);
    // Sky pixel (top row looks above the floor's far edge): the skybox colour.
    let top = 0usize;
    assert_eq!(g.object_id[top], NO_OBJECT);
    assert_eq!(lit[top], SKY);
}

#[test]
fn orthographic_square_covers_its_pixels() {
    // A 2 × 2 square seen orthographically with a 4-unit tall view on 80 × 80 pixels: exactly
    // 40 × 40 pixels (the edges fall between pixel centres).
    let cam = Camera {
        position: Vec3::new(0.0, 0.0, 5.0),
        target: Vec3::ZERO,
        up: Vec3::Y,
        projection: Projection::Orthographic { height: 4.0, near: 0.1, far: 20.0 },
    };
    let sq = quad([Vec3::new(-1.0, -1.0, 0.0), Vec3::new(1.0, -1.0, 0.0), Vec3::new(1.0, 1.0, 0.0), Vec3::new(-1.0, 1.0, 0.0)], 0);
    let s = scene(vec![Material::default()], vec![sq], Lights::default(), cam);
    let p = PreparedScene::new(&s);
    let g = rasterize(&p, &cam, 80, 80, None);
    let n = g.object_id.iter().filter(|&&o| o == 0).count();
    assert_eq!(n, 40 * 40);
    assert_eq!(g.object_id[40 * 80 + 40], 0);
    assert_eq!(g.object_id[19 * 80 + 40], NO_OBJECT);
    assert_eq!(g.object_id[20 * 80 + 40], 0);
    assert_eq!(g.object_id[59 * 80 + 40], 0);
    assert_eq!(g.object_id[60 * 80 + 40], NO_OBJECT);
    // Orthographic depth is linear: the plane halfway between... z = 0 at distance 5.
    let want = cam.view_projection(1.0).project_point3(Vec3::ZERO).z;
    assert!((g.depth[40 * 80 + 40] - want).abs() < 1e-6);
}

#[test]
fn empty_image_and_empty_scene() {
    let cam = perspective(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO);
    let s = scene(vec![Material::default()], vec![], Lights::default(), cam);
    let p = PreparedScene::new(&s);
    let g = rasterize(&p, &cam, 0, 0, None);
    assert!(g.is_empty());
    let g = rasterize(&p, &cam, 7, 5, None);
    assert_eq!(g, GBuffer::new(7, 5));
    let lit = deferred_lighting(&g, &s, &cam);
    assert!(lit.iter().all(|c| *c == SKY));
}
