//! The trace benchmarks' scenes and rays, shared by `trace.rs` and the Embree comparison
//! (`embree.rs`), so both trace exactly the same rays.

#![allow(dead_code)] // each bench uses its own part

use std::path::Path;

use glam::{Vec2, Vec3};
use hybrid_core::PreparedScene;
use hybrid_core::shading::reflect;
use hybrid_cpu::bvh::{SceneBvh, ShadowCache};
use hybrid_cpu::camera_rays::PrimaryRays;
use hybrid_cpu::trace::rt_only_gbuffer;
use hybrid_scene::{Camera, Material, Mesh, Object, ObjectSource, Projection, Scene, Transform};
use rayon::prelude::*;

pub const SPONZA: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/assets/sponza-dabrovic/sponza_dabrovic.obj");
pub const WIDTH: u32 = 640;
pub const HEIGHT: u32 = 360;

pub fn scene_of(meshes: Vec<Mesh>, materials: Vec<Material>, camera: Camera, textures: Vec<hybrid_scene::Texture>) -> Scene {
    let object =
        Object { name: "all".into(), source: ObjectSource::Plane, transform: Transform::default(), meshes, relevance: 1.0, cost: 1.0 };
    let mut scene = Scene::new(camera);
    scene.materials = materials;
    scene.textures = textures;
    scene.objects.push(object);
    scene
}

/// A UV sphere of radius `r` at `c` (the scene crate's unit-diameter primitive, placed).
pub fn sphere(c: Vec3, r: f32, slices: u32, stacks: u32) -> Mesh {
    let mut m = hybrid_scene::primitives::sphere(slices, stacks);
    m.positions.iter_mut().for_each(|p| *p = c + *p * (2.0 * r));
    m
}

/// A grid-subdivided quad (n×n cells) centred at `c` spanned by half-edges `u`, `v`.
pub fn grid(c: Vec3, u: Vec3, v: Vec3, n: u32) -> Mesh {
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
pub fn synthetic() -> Scene {
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

pub fn sponza() -> Option<Scene> {
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

/// Shadow rays (origin, unit dir, distance) towards a light, reflection rays and diffuse-bounce
/// rays (cosine-weighted about the normal, the most incoherent kind) from the hits.
pub struct Rays {
    pub shadow: Vec<(Vec3, Vec3, f32)>,
    pub reflection: Vec<(Vec3, Vec3)>,
    pub diffuse: Vec<(Vec3, Vec3)>,
}

/// Two numbers in [0, 1) from an integer (a fixed hash, so every run traces the same rays).
fn hash2(i: u32) -> (f32, f32) {
    let mut x = u64::from(i).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0xD1B5_4A32_D192_ED03;
    x ^= x >> 29;
    x = x.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x ^= x >> 32;
    ((x >> 40) as f32 / (1u64 << 24) as f32, ((x >> 16) & 0xFF_FFFF) as f32 / (1u64 << 24) as f32)
}

/// A cosine-weighted direction about the unit normal `n`.
fn cosine_direction(n: Vec3, (u1, u2): (f32, f32)) -> Vec3 {
    let (t, b) = n.any_orthonormal_pair();
    let r = u1.sqrt();
    let phi = std::f32::consts::TAU * u2;
    (t * (r * phi.cos()) + b * (r * phi.sin()) + n * (1.0 - u1).max(0.0).sqrt()).normalize()
}

pub fn rays(prepared: &PreparedScene, bvh: &SceneBvh, light: Vec3) -> Rays {
    let cam = &prepared.scene.camera;
    let g = rt_only_gbuffer(prepared, bvh, cam, WIDTH, HEIGHT);
    let bias = 1e-3;
    let mut shadow = Vec::new();
    let mut reflection = Vec::new();
    let mut diffuse = Vec::new();
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
        diffuse.push((o, cosine_direction(n, hash2(i as u32))));
    }
    Rays { shadow, reflection, diffuse }
}

/// Primary rays `(origin, unit dir, t_max)` of the scene's camera at `WIDTH × HEIGHT`, in 4×4
/// pixel tiles of 16 consecutive rays (the coherent groups a packet tracer wants).
pub fn primary_tiles(prepared: &PreparedScene) -> Vec<(Vec3, Vec3, f32)> {
    let cam = PrimaryRays::new(&prepared.scene.camera, WIDTH, HEIGHT);
    (0..HEIGHT / 4)
        .flat_map(|ty| (0..WIDTH / 4).map(move |tx| (tx, ty)))
        .flat_map(|(tx, ty)| (0..16).map(move |k| (tx * 4 + k % 4, ty * 4 + k / 4)))
        .map(|(x, y)| cam.ray(x, y))
        .collect()
}

/// The closest-hit distance of each ray `(origin, dir, t_max)`, in order, one ray at a time
/// (`packets` false) or in packets of 16 consecutive rays: the two must be equal bit for bit.
pub fn primary_hits(bvh: &SceneBvh, rays: &[(Vec3, Vec3, f32)], packets: bool) -> Vec<Option<f32>> {
    if packets {
        rays.chunks(16).flat_map(|c| bvh.closest_hits(c, 0.0).into_iter().take(c.len())).map(|h| h.map(|h| h.t)).collect()
    } else {
        rays.iter().map(|&(o, d, far)| bvh.closest_hit(o, d, 0.0, far).map(|h| h.t)).collect()
    }
}

/// Closest hits of rays `(origin, dir, t_max)` in parallel chunks, one ray at a time
/// (`packets` false) or in packets of 16 consecutive rays; returns the sum of the hit distances.
pub fn trace_primary(bvh: &SceneBvh, rays: &[(Vec3, Vec3, f32)], packets: bool) -> f32 {
    rays.par_chunks(CHUNK)
        .with_max_len(1)
        .map(|c| {
            if packets {
                c.chunks(16).map(|p| bvh.closest_hits(p, 0.0).iter().flatten().map(|h| h.t).sum::<f32>()).sum::<f32>()
            } else {
                c.iter().filter_map(|&(o, d, far)| bvh.closest_hit(o, d, 0.0, far)).map(|h| h.t).sum::<f32>()
            }
        })
        .sum()
}

/// The benchmark scenes with their light positions.
pub fn scenes() -> Vec<(&'static str, Scene, Vec3)> {
    let mut v = vec![("synthetic", synthetic(), Vec3::new(3.0, 10.0, 2.0))];
    if let Some(sp) = sponza() {
        let mut b = hybrid_scene::Aabb::EMPTY;
        sp.objects[0].meshes.iter().flat_map(|m| &m.positions).for_each(|p| b.grow(*p));
        let light = Vec3::new(b.center().x, b.min.y + (b.max.y - b.min.y) * 0.8, b.center().z);
        v.push(("sponza", sp, light));
    }
    v
}

/// CPU time of the calling thread in seconds (`/proc/thread-self/schedstat`, ns on the CPU).
pub fn thread_cpu_seconds() -> f64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next().and_then(|t| t.parse::<u64>().ok()))
        .map_or(f64::NAN, |ns| ns as f64 * 1e-9)
}

pub fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg").map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" ")).unwrap_or_default()
}

/// Best CPU time (1-thread pool) and best wall time (global pool) of `f` over a few passes.
pub fn measure(one: &rayon::ThreadPool, mut f: impl FnMut() + Send) -> (f64, f64) {
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

pub fn report(name: &str, what: &str, items: usize, unit: &str, (cpu, wall): (f64, f64)) {
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

/// Rays per parallel work item, as the trace stage hands them out (one at a time: uneven costs).
const CHUNK: usize = 256;

/// Shadow rays `(origin, unit dir, distance)` traced in parallel chunks as the trace stage does
/// (`cached`: with one shadow cache per chunk, the stage's path); returns the sum of their
/// attenuations, so that no work can be optimised away.
pub fn trace_shadow_rays(prepared: &PreparedScene, bvh: &SceneBvh, rays: &[(Vec3, Vec3, f32)], cached: bool) -> f32 {
    rays.par_chunks(CHUNK)
        .with_max_len(1)
        .map(|c| {
            let mut cache = ShadowCache::default();
            c.iter()
                .map(|&(o, d, t)| {
                    if cached {
                        bvh.any_hit_attenuation_cached(prepared, o, d, t, &mut cache)
                    } else {
                        bvh.any_hit_attenuation(prepared, o, d, t)
                    }
                })
                .sum::<f32>()
        })
        .sum()
}

/// Closest hits of rays `(origin, dir)` in parallel chunks; returns the sum of the hit distances.
pub fn trace_closest_hits(bvh: &SceneBvh, rays: &[(Vec3, Vec3)]) -> f32 {
    rays.par_chunks(CHUNK)
        .with_max_len(1)
        .map(|c| c.iter().filter_map(|&(o, d)| bvh.closest_hit(o, d, 0.0, f32::INFINITY)).map(|h| h.t).sum::<f32>())
        .sum()
}
