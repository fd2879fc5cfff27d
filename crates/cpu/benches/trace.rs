//! Trace-stage benchmarks: BVH build time and traced rays per second by ray kind.
//!
//! Scenes: a synthetic room of ~270K triangles (tessellated spheres on a floor, closed walls),
//! and Sponza (`shared/assets/sponza-dabrovic/sponza_dabrovic.obj` beside the repository) when the OBJ loader can
//! read it. Rays: primary hits from `rt_only_gbuffer` at 640×360; shadow rays from each hit
//! towards a point light (`any_hit_attenuation`); reflection rays (view direction reflected about
//! the normal, `closest_hit`). Rays are traced in parallel as the trace stage does.
//!
//! `cargo bench -p hybrid-cpu --bench trace`; the throughput is printed by criterion as
//! elements/s (= rays/s).
//!
//! On a shared (loaded) machine wall-clock numbers are noisy, so `TRACE_CPU_TIME=1 cargo bench
//! -p hybrid-cpu --bench trace` instead measures the **CPU time** of each workload on a 1-thread
//! rayon pool (the thread's own run time from `/proc/thread-self/schedstat`, best of several
//! passes) and prints rays per CPU-second, ×2 as the 2-thread estimate, then the wall-clock
//! 2-thread rate next to the load average. Workloads: BVH build; shadow rays
//! (`any_hit_attenuation`); reflection rays (`closest_hit` only, and with the secondary-hit
//! shading of the trace stage: `surface_at` + `local_lighting`); the whole trace stage
//! (`trace::trace`, one point light, every pixel masked).

use std::path::Path;
use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group};
use glam::{Vec2, Vec3};
use hybrid_core::GBuffer;
use hybrid_core::shading::{local_lighting, reflect};
use hybrid_cpu::PreparedScene;
use hybrid_cpu::bvh::{SceneBvh, ShadowCache};
use hybrid_cpu::trace::{rt_only_gbuffer, trace};
use hybrid_scene::{Camera, Lights, Material, Mesh, Object, ObjectSource, PointLight, Projection, Scene, Transform};
use rayon::prelude::*;

const SPONZA: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/assets/sponza-dabrovic/sponza_dabrovic.obj");
const WIDTH: u32 = 640;
const HEIGHT: u32 = 360;

fn scene_of(meshes: Vec<Mesh>, materials: Vec<Material>, camera: Camera, textures: Vec<hybrid_scene::Texture>) -> Scene {
    let object =
        Object { name: "all".into(), source: ObjectSource::Plane, transform: Transform::default(), meshes, relevance: 1.0, cost: 1.0 };
    let mut scene = Scene::new(camera);
    scene.materials = materials;
    scene.textures = textures;
    scene.objects.push(object);
    scene
}

/// A UV sphere of radius `r` at `c` (the scene crate's unit-diameter primitive, placed).
fn sphere(c: Vec3, r: f32, slices: u32, stacks: u32) -> Mesh {
    let mut m = hybrid_scene::primitives::sphere(slices, stacks);
    m.positions.iter_mut().for_each(|p| *p = c + *p * (2.0 * r));
    m
}

/// A grid-subdivided quad (n×n cells) centred at `c` spanned by half-edges `u`, `v`.
fn grid(c: Vec3, u: Vec3, v: Vec3, n: u32) -> Mesh {
    let mut m = Mesh::default();
    let nrm = u.cross(v).normalize();
    for j in 0..=n {
        for i in 0..=n {
            let (s, t) = (i as f32 / n as f32 * 2.0 - 1.0, j as f32 / n as f32 * 2.0 - 1.0);
            m.positions.push(c + u * s + v * t);
            m.normals.push(nrm);
            m.uvs.push(Vec2::new(s, t));
        }
    }
    for j in 0..n {
        for i in 0..n {
            let a = j * (n + 1) + i;
            m.indices.push([a, a + 1, a + n + 2]);
            m.indices.push([a, a + n + 2, a + n + 1]);
        }
    }
    m
}

/// ~270K triangles: 16×16 spheres of 1,024 triangles in a closed 40×12×40 m room.
fn synthetic() -> Scene {
    let mut meshes = Vec::new();
    for z in 0..16 {
        for x in 0..16 {
            let c = Vec3::new(-15.0 + x as f32 * 2.0, 0.8 + ((x * 7 + z * 3) % 5) as f32 * 0.5, -15.0 + z as f32 * 2.0);
            meshes.push(sphere(c, 0.7, 32, 16));
        }
    }
    let (h, y) = (20.0, 6.0);
    meshes.push(grid(Vec3::ZERO, Vec3::X * h, -Vec3::Z * h, 40));
    meshes.push(grid(Vec3::Y * 2.0 * y, Vec3::X * h, Vec3::Z * h, 40));
    meshes.push(grid(Vec3::new(0.0, y, -h), Vec3::X * h, Vec3::Y * y, 20));
    meshes.push(grid(Vec3::new(0.0, y, h), Vec3::Y * y, Vec3::X * h, 20));
    meshes.push(grid(Vec3::new(-h, y, 0.0), Vec3::Y * y, Vec3::Z * h, 20));
    meshes.push(grid(Vec3::new(h, y, 0.0), Vec3::Z * h, Vec3::Y * y, 20));
    let camera = Camera {
        position: Vec3::new(-18.0, 7.0, 18.0),
        target: Vec3::new(0.0, 0.0, 0.0),
        up: Vec3::Y,
        projection: Projection::Perspective { fov_y_deg: 60.0, near: 0.05, far: 200.0 },
    };
    let materials = vec![Material::default()];
    scene_of(meshes, materials, camera, Vec::new())
}

fn sponza() -> Option<Scene> {
    let path = Path::new(SPONZA);
    if !path.exists() {
        return None;
    }
    let (mut materials, mut textures) = (Vec::new(), Vec::new());
    let meshes = match hybrid_scene::load::load_model(path, &mut materials, &mut textures) {
        Ok(m) => m,
        Err(e) => {
            eprintln!("skipping Sponza: {e}");
            return None;
        }
    };
    // The classic interior view along the atrium (Sponza's long axis is X).
    let mut b = hybrid_scene::Aabb::EMPTY;
    meshes.iter().flat_map(|m| &m.positions).for_each(|p| b.grow(*p));
    let c = b.center();
    let ext = b.max - b.min;
    let camera = Camera {
        position: Vec3::new(b.min.x + ext.x * 0.15, b.min.y + ext.y * 0.25, c.z),
        target: Vec3::new(b.max.x, b.min.y + ext.y * 0.3, c.z),
        up: Vec3::Y,
        projection: Projection::Perspective { fov_y_deg: 60.0, near: 0.05, far: ext.length() * 2.0 },
    };
    Some(scene_of(meshes, materials, camera, textures))
}

/// Shadow rays (origin, unit dir, distance) towards a light and reflection rays from the hits.
struct Rays {
    shadow: Vec<(Vec3, Vec3, f32)>,
    reflection: Vec<(Vec3, Vec3)>,
}

fn rays(prepared: &PreparedScene, bvh: &SceneBvh, light: Vec3) -> Rays {
    let cam = &prepared.scene.camera;
    let g = rt_only_gbuffer(prepared, bvh, cam, WIDTH, HEIGHT);
    let bias = 1e-3;
    let mut shadow = Vec::new();
    let mut reflection = Vec::new();
    for i in 0..g.len() {
        if g.mask[i] == 0.0 {
            continue;
        }
        let (p, n) = (g.position[i], g.normal[i]);
        let i_dir = (p - cam.position).normalize();
        let n = if n.dot(i_dir) > 0.0 { -n } else { n };
        let o = p + n * bias;
        let to = light - o;
        shadow.push((o, to.normalize(), to.length()));
        reflection.push((o, reflect(i_dir, n)));
    }
    Rays { shadow, reflection }
}

fn bench_scene(c: &mut Criterion, name: &str, scene: &Scene, light: Vec3) {
    let prepared = PreparedScene::new(scene);
    let mut group = c.benchmark_group(format!("trace/{name}"));
    group.sample_size(10).warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(3));
    group.throughput(Throughput::Elements(prepared.triangles.len() as u64));
    group.bench_function(format!("bvh_build_{}k_tris", prepared.triangles.len() / 1000), |b| b.iter(|| SceneBvh::build(&prepared)));

    let bvh = SceneBvh::build(&prepared);
    let r = rays(&prepared, &bvh, light);
    group.throughput(Throughput::Elements(r.shadow.len() as u64));
    group.bench_function("shadow_rays", |b| {
        b.iter(|| {
            r.shadow
                .par_chunks(256)
                .with_max_len(1)
                .map(|c| c.iter().map(|&(o, d, t)| bvh.any_hit_attenuation(&prepared, o, d, t)).sum::<f32>())
                .sum::<f32>()
        })
    });
    group.throughput(Throughput::Elements(r.reflection.len() as u64));
    group.bench_function("reflection_rays", |b| {
        b.iter(|| {
            r.reflection
                .par_chunks(256)
                .with_max_len(1)
                .map(|c| c.iter().filter_map(|&(o, d)| bvh.closest_hit(o, d, 0.0, f32::INFINITY)).map(|h| h.t).sum::<f32>())
                .sum::<f32>()
        })
    });
    group.bench_function("primary_rays_gbuffer", |b| b.iter(|| rt_only_gbuffer(&prepared, &bvh, &scene.camera, WIDTH, HEIGHT)));
    group.finish();
}

/// The benchmark scenes with their light positions.
fn scenes() -> Vec<(&'static str, Scene, Vec3)> {
    let mut v = vec![("synthetic", synthetic(), Vec3::new(3.0, 10.0, 2.0))];
    if let Some(sp) = sponza() {
        let mut b = hybrid_scene::Aabb::EMPTY;
        sp.objects[0].meshes.iter().flat_map(|m| &m.positions).for_each(|p| b.grow(*p));
        let light = Vec3::new(b.center().x, b.min.y + (b.max.y - b.min.y) * 0.8, b.center().z);
        v.push(("sponza", sp, light));
    }
    v
}

fn benches(c: &mut Criterion) {
    for (name, scene, light) in scenes() {
        bench_scene(c, name, &scene, light);
    }
}

criterion_group!(trace_benches, benches);

fn main() {
    if std::env::var_os("TRACE_CPU_TIME").is_some() {
        cpu_time_report();
        return;
    }
    trace_benches();
    Criterion::default().configure_from_args().final_summary();
}

/// CPU time of the calling thread in seconds (`/proc/thread-self/schedstat`, ns on the CPU).
fn thread_cpu_seconds() -> f64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next().and_then(|t| t.parse::<u64>().ok()))
        .map_or(f64::NAN, |ns| ns as f64 * 1e-9)
}

fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg").map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" ")).unwrap_or_default()
}

/// Best CPU time (1-thread pool) and best wall time (global pool) of `f` over a few passes.
fn measure(one: &rayon::ThreadPool, mut f: impl FnMut() + Send) -> (f64, f64) {
    let passes = std::env::var("TRACE_PASSES").ok().and_then(|p| p.parse().ok()).unwrap_or(5);
    let mut cpu = f64::INFINITY;
    for _ in 0..passes {
        cpu = cpu.min(one.install(|| {
            let t0 = thread_cpu_seconds();
            f();
            thread_cpu_seconds() - t0
        }));
    }
    let mut wall = f64::INFINITY;
    for _ in 0..passes {
        let t0 = std::time::Instant::now();
        f();
        wall = wall.min(t0.elapsed().as_secs_f64());
    }
    (cpu, wall)
}

fn report(name: &str, what: &str, items: usize, unit: &str, (cpu, wall): (f64, f64)) {
    let m = items as f64 * 1e-6;
    println!(
        "{name:>10} {what:<22} {:>9.2} ms CPU  {:>7.2} M{unit}/CPU-s  (x2 = {:>6.2})  wall 2 threads {:>8.2} ms = {:>6.2} M{unit}/s  [load {}]",
        cpu * 1e3,
        m / cpu,
        2.0 * m / cpu,
        wall * 1e3,
        m / wall,
        load_average()
    );
}

fn cpu_time_report() {
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("1-thread pool");
    println!("threads in the global pool: {}", rayon::current_num_threads());
    let only = std::env::var("TRACE_SCENE").ok();
    for (name, mut scene, light) in scenes() {
        if only.as_deref().is_some_and(|o| o != name) {
            continue;
        }
        scene.lights = Lights {
            point: vec![PointLight {
                position: light,
                color: Vec3::ONE,
                intensity: 50.0,
                attenuation: Default::default(),
                casts_shadows: true,
            }],
            ..Default::default()
        };
        let prepared = PreparedScene::new(&scene);
        let tris = prepared.triangles.len();
        report(name, &format!("bvh build {}k tris", tris / 1000), tris, "tris", measure(&one, || drop(SceneBvh::build(&prepared))));
        let bvh = SceneBvh::build(&prepared);
        let r = rays(&prepared, &bvh, light);
        let shadow = || {
            r.shadow
                .par_chunks(256)
                .with_max_len(1)
                .map(|c| c.iter().map(|&(o, d, t)| bvh.any_hit_attenuation(&prepared, o, d, t)).sum::<f32>())
                .sum::<f32>()
        };
        report(
            name,
            "shadow rays",
            r.shadow.len(),
            "rays",
            measure(&one, || {
                std::hint::black_box(shadow());
            }),
        );
        let shadow_cached = || {
            r.shadow
                .par_chunks(256)
                .with_max_len(1)
                .map(|c| {
                    let mut cache = ShadowCache::default();
                    c.iter().map(|&(o, d, t)| bvh.any_hit_attenuation_cached(&prepared, o, d, t, &mut cache)).sum::<f32>()
                })
                .sum::<f32>()
        };
        // Both give the same attenuation for every ray.
        assert_eq!(shadow().to_bits(), shadow_cached().to_bits(), "{name}: the shadow cache changed a result");
        report(
            name,
            "shadow rays, cache",
            r.shadow.len(),
            "rays",
            measure(&one, || {
                std::hint::black_box(shadow_cached());
            }),
        );
        let reflection = || {
            r.reflection
                .par_chunks(256)
                .with_max_len(1)
                .map(|c| c.iter().filter_map(|&(o, d)| bvh.closest_hit(o, d, 0.0, f32::INFINITY)).map(|h| h.t).sum::<f32>())
                .sum::<f32>()
        };
        report(
            name,
            "reflection rays",
            r.reflection.len(),
            "rays",
            measure(&one, || {
                std::hint::black_box(reflection());
            }),
        );
        let shaded = || {
            r.reflection
                .par_chunks(256)
                .with_max_len(1)
                .map(|c| {
                    c.iter()
                        .filter_map(|&(o, d)| bvh.closest_hit(o, d, 0.0, f32::INFINITY).map(|h| (d, h)))
                        .map(|(d, h)| {
                            let s = prepared.surface_at(h.triangle, h.bary, 0.0);
                            local_lighting(&s, -d, &scene.lights, &scene.environment)
                        })
                        .sum::<Vec3>()
                })
                .sum::<Vec3>()
        };
        report(
            name,
            "reflection + shading",
            r.reflection.len(),
            "rays",
            measure(&one, || {
                std::hint::black_box(shaded());
            }),
        );
        let mut g: GBuffer = rt_only_gbuffer(&prepared, &bvh, &scene.camera, WIDTH, HEIGHT);
        g.mask.iter_mut().for_each(|m| *m = 1.0);
        let traced = trace(&prepared, &bvh, &g, &scene.camera).rays.total() as usize;
        report(name, "trace stage", traced, "rays", measure(&one, || drop(trace(&prepared, &bvh, &g, &scene.camera))));
    }
}
