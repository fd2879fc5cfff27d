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
//! (`trace::trace`, one point light, every pixel masked); primary rays in 4×4 tiles one at a time
//! and as 16-ray packets (`closest_hits`).

mod trace_scenes;

use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group};
use glam::Vec3;
use hybrid_core::GBuffer;
use hybrid_core::PreparedScene;
use hybrid_core::shading::local_lighting;
use hybrid_cpu::bvh::SceneBvh;
use hybrid_cpu::trace::{rt_only_gbuffer, trace};
use hybrid_scene::{Lights, PointLight, Scene};
use rayon::prelude::*;
use trace_scenes::{
    HEIGHT, WIDTH, measure, primary_hits, primary_tiles, rays, report, scenes, trace_closest_hits, trace_primary, trace_shadow_rays,
};

fn bench_scene(c: &mut Criterion, name: &str, scene: &Scene, light: Vec3) {
    let prepared = PreparedScene::new(scene);
    let mut group = c.benchmark_group(format!("trace/{name}"));
    group.sample_size(10).warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(3));
    group.throughput(Throughput::Elements(prepared.triangles.len() as u64));
    group.bench_function(format!("bvh_build_{}k_tris", prepared.triangles.len() / 1000), |b| b.iter(|| SceneBvh::build(&prepared)));

    let bvh = SceneBvh::build(&prepared);
    let r = rays(&prepared, &bvh, light);
    group.throughput(Throughput::Elements(r.shadow.len() as u64));
    group.bench_function("shadow_rays", |b| b.iter(|| trace_shadow_rays(&prepared, &bvh, &r.shadow, false)));
    group.throughput(Throughput::Elements(r.reflection.len() as u64));
    group.bench_function("reflection_rays", |b| b.iter(|| trace_closest_hits(&bvh, &r.reflection)));
    group.bench_function("primary_rays_gbuffer", |b| b.iter(|| rt_only_gbuffer(&prepared, &bvh, &scene.camera, WIDTH, HEIGHT)));
    group.finish();
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
        let shadow = || trace_shadow_rays(&prepared, &bvh, &r.shadow, false);
        report(
            name,
            "shadow rays",
            r.shadow.len(),
            "rays",
            measure(&one, || {
                std::hint::black_box(shadow());
            }),
        );
        let shadow_cached = || trace_shadow_rays(&prepared, &bvh, &r.shadow, true);
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
        // Primary rays in 4×4 tiles: one at a time, and as 16-ray packets (the same hits).
        let primary = primary_tiles(&prepared);
        let bits = |packets| primary_hits(&bvh, &primary, packets).into_iter().map(|t| t.map(f32::to_bits)).collect::<Vec<_>>();
        assert_eq!(bits(false), bits(true), "{name}: packets and single rays disagree");
        for (what, packets) in [("primary rays", false), ("primary rays, packets", true)] {
            report(
                name,
                what,
                primary.len(),
                "rays",
                measure(&one, || {
                    std::hint::black_box(trace_primary(&bvh, &primary, packets));
                }),
            );
        }
        let reflection = || trace_closest_hits(&bvh, &r.reflection);
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
