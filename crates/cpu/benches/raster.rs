//! Raster stage benchmark: a synthetic ~270K-triangle scene (a grid of 117 UV spheres of 2,304
//! triangles each, half of them textured, plus a floor) into the full G-buffer at 1280×720, and
//! the deferred lighting pass. Built in code, so it needs no asset files.
//!
//! Run: `cargo bench -p hybrid-cpu --bench raster`
//!
//! CPU-time mode (for before/after comparisons on a loaded machine): `RASTER_CPU=20 cargo bench
//! -p hybrid-cpu --bench raster` runs each pass 20 times on a 1-thread rayon pool and prints the
//! process CPU time per frame (from `/proc/self/stat`), plus checksums of the outputs
//! (`RASTER_THREADS=2` for a 2-thread pool). `RASTER_SCENE=room` runs it on the trace bench's
//! generated ~270K-triangle room (untextured, seen from a corner) instead; criterion runs both.

#[path = "trace_scenes/mod.rs"]
mod trace_scenes;

use criterion::{Criterion, criterion_group};
use glam::{Vec2, Vec3};
use hybrid_core::GBuffer;
use hybrid_core::PreparedScene;
use hybrid_cpu::lighting::deferred_lighting;
use hybrid_cpu::raster::{rasterize, rasterize_into};
use hybrid_scene::{
    Camera, ColorSpace, DirectionalLight, Environment, Lights, Material, Mesh, Object, ObjectSource, PointLight, Projection, Scene, Skybox,
    Texture, Transform,
};

const W: u32 = 1280;
const H: u32 = 720;

/// A UV sphere of radius `r` at `centre` (the scene crate's unit-diameter primitive, placed).
fn sphere(centre: Vec3, r: f32, slices: u32, stacks: u32, material: usize) -> Mesh {
    let mut m = hybrid_scene::primitives::sphere(slices, stacks);
    m.positions.iter_mut().for_each(|p| *p = centre + *p * (2.0 * r));
    m.material = material;
    m
}

fn object(i: usize, mesh: Mesh) -> Object {
    Object {
        name: format!("object {i}"),
        source: ObjectSource::Plane,
        transform: Transform::default(),
        meshes: vec![mesh],
        relevance: 1.0,
        cost: 1.0,
    }
}

fn bench_scene() -> (Scene, Camera) {
    let mut texels = Vec::new();
    for y in 0..256 {
        for x in 0..256 {
            texels.push(if (x / 32 + y / 32) % 2 == 0 { [220, 60, 40, 255] } else { [30, 120, 220, 255] });
        }
    }
    let tex = Texture::new("checker", 256, 256, texels, ColorSpace::Srgb);
    let plain = Material { specular: Vec3::splat(0.3), shininess: 0.5, ..Material::default() };
    let textured = Material { diffuse_map: Some(0), tiling: Vec2::new(4.0, 2.0), ..Material::default() };
    let mut objects = Vec::new();
    // 13 × 9 spheres, three depth layers staggered so they overlap (overdraw).
    for row in 0..9 {
        for col in 0..13 {
            let i = row * 13 + col;
            let c = Vec3::new(col as f32 * 1.5 - 9.0, row as f32 * 1.1 - 4.4, -((i % 3) as f32) * 1.2);
            objects.push(object(i, sphere(c, 0.75, 48, 24, i % 2)));
        }
    }
    let floor = Mesh {
        positions: vec![
            Vec3::new(-40.0, -5.5, 20.0),
            Vec3::new(40.0, -5.5, 20.0),
            Vec3::new(40.0, -5.5, -60.0),
            Vec3::new(-40.0, -5.5, -60.0),
        ],
        uvs: vec![Vec2::ZERO, Vec2::X, Vec2::ONE, Vec2::Y],
        indices: vec![[0, 1, 2], [0, 2, 3]],
        material: 1,
        ..Default::default()
    };
    objects.push(object(objects.len(), floor));
    let camera = Camera {
        position: Vec3::new(0.0, 0.5, 11.0),
        target: Vec3::new(0.0, 0.0, -1.0),
        up: Vec3::Y,
        projection: Projection::Perspective { fov_y_deg: 50.0, near: 0.1, far: 200.0 },
    };
    let lights = Lights {
        directional: vec![DirectionalLight {
            direction: Vec3::new(-0.3, -1.0, -0.5).normalize(),
            color: Vec3::ONE,
            intensity: 1.0,
            casts_shadows: true,
        }],
        point: vec![PointLight {
            position: Vec3::new(0.0, 4.0, 4.0),
            color: Vec3::ONE,
            intensity: 10.0,
            attenuation: Default::default(),
            casts_shadows: true,
        }],
        spot: Vec::new(),
    };
    let mut scene = Scene::new(camera);
    scene.environment = Environment { ambient: Vec3::splat(0.1), ior: 1.0, skybox: Skybox::Color(Vec3::new(0.4, 0.6, 0.9)) };
    scene.materials = vec![plain, textured];
    scene.textures = vec![tex];
    scene.objects = objects;
    scene.lights = lights;
    (scene, camera)
}

/// The trace bench's room (~270K triangles), with the bench scene's two lights.
fn room_scene() -> (Scene, Camera) {
    let mut scene = trace_scenes::synthetic();
    scene.lights = bench_scene().0.lights;
    let camera = scene.camera;
    (scene, camera)
}

/// The scene `RASTER_SCENE` names: `spheres` (default) or `room`.
fn chosen_scene() -> (Scene, Camera) {
    match std::env::var("RASTER_SCENE").as_deref() {
        Ok("room") => room_scene(),
        Ok("spheres") | Err(_) => bench_scene(),
        Ok(other) => panic!("RASTER_SCENE must be spheres or room, not `{other}`"),
    }
}

fn raster(c: &mut Criterion) {
    for (name, (scene, camera)) in [("270k_tris", bench_scene()), ("room_270k_tris", room_scene())] {
        let prepared = PreparedScene::new(&scene);
        let tris = prepared.triangles.len();
        let g = rasterize(&prepared, &camera, W, H, None);
        let covered = g.object_id.iter().filter(|&&o| o != hybrid_core::NO_OBJECT).count();
        eprintln!("raster bench {name}: {tris} triangles, {W}x{H}, {covered} pixels covered");

        let mut group = c.benchmark_group("raster");
        group.sample_size(20);
        group.bench_function(format!("rasterize_into_{name}_1280x720"), |b| {
            let mut g = GBuffer::new(W, H);
            b.iter(|| rasterize_into(&prepared, &camera, None, &mut g));
        });
        group.bench_function(format!("rasterize_alloc_{name}_1280x720"), |b| b.iter(|| rasterize(&prepared, &camera, W, H, None)));
        group.bench_function(format!("deferred_lighting_{name}_1280x720"), |b| b.iter(|| deferred_lighting(&g, &scene, &camera)));
        group.finish();
    }
}

/// Process CPU time (user + system) in ms, from `/proc/self/stat` (Linux; 0 elsewhere).
fn cpu_ms() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else { return 0.0 };
    // Fields after the command name (which is in parentheses): utime is the 12th, stime the 13th.
    let Some(rest) = stat.rsplit_once(')').map(|(_, r)| r) else { return 0.0 };
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    (ticks(11) + ticks(12)) * 10.0
}

fn checksum<T: Copy>(v: &[T], bits: impl Fn(T) -> Vec<u32>) -> u64 {
    v.iter().flat_map(|x| bits(*x)).fold(0xcbf2_9ce4_8422_2325u64, |h, b| (h ^ b as u64).wrapping_mul(0x0100_0000_01b3))
}

fn cpu_mode(iters: u32) {
    let (scene, camera) = chosen_scene();
    let prepared = PreparedScene::new(&scene);
    eprintln!("{} triangles", prepared.triangles.len());
    let threads = std::env::var("RASTER_THREADS").ok().and_then(|v| v.parse::<usize>().ok()).unwrap_or(1);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("pool");
    let mut g = GBuffer::new(W, H);
    pool.install(|| rasterize_into(&prepared, &camera, None, &mut g));
    let t0 = cpu_ms();
    let w0 = std::time::Instant::now();
    for _ in 0..iters {
        pool.install(|| rasterize_into(&prepared, &camera, None, &mut g));
    }
    let (raster_cpu, raster_wall) = ((cpu_ms() - t0) / iters as f64, w0.elapsed().as_secs_f64() * 1e3 / iters as f64);
    let mut lit = Vec::new();
    let t0 = cpu_ms();
    let w0 = std::time::Instant::now();
    for _ in 0..iters {
        lit = pool.install(|| deferred_lighting(&g, &scene, &camera));
    }
    let (light_cpu, light_wall) = ((cpu_ms() - t0) / iters as f64, w0.elapsed().as_secs_f64() * 1e3 / iters as f64);
    let v3 = |v: Vec3| v.to_array().map(f32::to_bits).to_vec();
    let v4 = |v: glam::Vec4| v.to_array().map(f32::to_bits).to_vec();
    let gsum = [
        checksum(&g.position, v3),
        checksum(&g.normal, v3),
        checksum(&g.emission, v3),
        checksum(&g.ambient, v3),
        checksum(&g.diffuse, v4),
        checksum(&g.specular, v4),
        checksum(&g.optical, v3),
        checksum(&g.object_id, |x| vec![x]),
        checksum(&g.depth, |x| vec![x.to_bits()]),
    ];
    println!(
        "{threads} thread(s), {iters} iterations: rasterize_into {raster_cpu:.1} ms CPU ({raster_wall:.1} wall), deferred_lighting {light_cpu:.1} ms CPU ({light_wall:.1} wall)"
    );
    println!("gbuffer checksums {gsum:016x?}");
    println!("lighting checksum {:016x}", checksum(&lit, v3));
}

criterion_group!(benches, raster);

fn main() {
    // Our kernels' instruction-set path (`HYBRID_ISA` forces one).
    let isa = hybrid_cpu::isa::init_from_env().unwrap_or_else(|e| {
        eprintln!("error: {e}");
        std::process::exit(2)
    });
    eprintln!("kernels: {}", isa.name());
    if let Some(n) = std::env::var("RASTER_CPU").ok().and_then(|v| v.parse::<u32>().ok()) {
        cpu_mode(n.max(1));
        return;
    }
    benches();
    Criterion::default().configure_from_args().final_summary();
}
