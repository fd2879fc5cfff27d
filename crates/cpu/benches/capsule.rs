//! The RT-scene capsule on the 1,046,843-point forest scan at 1920×1080: sphere-BVH build, trace +
//! pack (Mrays/s), bytes per point, clipped vs unclipped against a wall, and a 10M-point cloud.
//!
//! `cargo bench -p hybrid-cpu --bench capsule` (criterion measurements, then a one-shot report).
//! `CAPSULE_BENCH_10M=0` skips the 10-million-point part. `CAPSULE_BENCH_RUNS=n` sets the one-shot
//! report's runs per measurement (default 5; 3 for 10M). Give criterion a filter that matches
//! nothing (`-- nomatch`) to get the one-shot report alone. The report also gives CPU-seconds
//! (all threads) per build and per frame, fairer on a loaded machine than wall time, and an FNV-1a
//! checksum of each frame's texels: it must not change when only speed work was done. Frames are
//! traced with the default `PrimaryVisibility::Auto`, then the same frames the other way
//! (projection or BVH traversal), which must give the same checksums.

use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

use criterion::{Criterion, criterion_group};
use glam::Vec3;
use hybrid_core::depth_merge::{PackedRtFrame, encode_hit, synthesize_depth};
use hybrid_cpu::camera_rays::RayGen;
use hybrid_cpu::capsule::{CapsuleRequest, PointCloudCapsule, PrimaryVisibility, RtCapsule};
use hybrid_cpu::spheres::SphereBvh;
use hybrid_scene::{Camera, DirectionalLight, Environment, Lights, PointCloud, PointColoring, Projection};

const SCAN: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/assets/tree-pointcloud/rtls_tls_scan_1m.ply");
const W: u32 = 1920;
const H: u32 = 1080;
const RADIUS: f32 = 0.01;

/// A tiny binary-little-endian PLY vertex reader (x, y, z floats plus any scalar properties),
/// Z-up → Y-up.
fn read_ply_points(path: &Path) -> Result<Vec<Vec3>, String> {
    let bytes = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let end = bytes.windows(11).position(|w| w == b"end_header\n").ok_or("no end_header")? + 11;
    let header = std::str::from_utf8(&bytes[..end]).map_err(|e| e.to_string())?;
    if !header.contains("format binary_little_endian") {
        return Err("only binary_little_endian PLY".into());
    }
    let (mut count, mut stride, mut offs) = (0usize, 0usize, [usize::MAX; 3]);
    let mut in_vertex = false;
    for line in header.lines() {
        let f: Vec<&str> = line.split_whitespace().collect();
        match f.as_slice() {
            ["element", "vertex", n] => {
                count = n.parse().map_err(|_| "bad vertex count")?;
                in_vertex = true;
            }
            ["element", ..] => in_vertex = false,
            ["property", ty, name] if in_vertex => {
                let size = match *ty {
                    "char" | "uchar" | "int8" | "uint8" => 1,
                    "short" | "ushort" | "int16" | "uint16" => 2,
                    "int" | "uint" | "float" | "int32" | "uint32" | "float32" => 4,
                    "double" | "float64" => 8,
                    _ => return Err(format!("unknown type {ty}")),
                };
                if let Some(k) = ["x", "y", "z"].iter().position(|a| a == name) {
                    offs[k] = stride;
                }
                stride += size;
            }
            _ => {}
        }
    }
    if offs.contains(&usize::MAX) || bytes.len() < end + count * stride {
        return Err("missing x/y/z or truncated".into());
    }
    let f = |b: &[u8], o: usize| f32::from_le_bytes([b[o], b[o + 1], b[o + 2], b[o + 3]]);
    Ok(bytes[end..end + count * stride].chunks_exact(stride).map(|v| Vec3::new(f(v, offs[0]), f(v, offs[2]), -f(v, offs[1]))).collect())
}

fn scan() -> Vec<Vec3> {
    match read_ply_points(Path::new(SCAN)) {
        Ok(p) => p,
        Err(e) => panic!("cannot read {SCAN}: {e}"),
    }
}

fn lights() -> Lights {
    Lights {
        directional: vec![DirectionalLight {
            direction: Vec3::new(-0.4, -1.0, -0.3).normalize(),
            color: Vec3::ONE,
            intensity: 2.5,
            casts_shadows: false,
        }],
        ..Lights::default()
    }
}

fn capsule_for(points: Vec<Vec3>) -> PointCloudCapsule {
    let pc = PointCloud {
        name: "scan".into(),
        source: SCAN.into(),
        points,
        colors: vec![],
        radius: RADIUS,
        coloring: PointColoring::Height,
        specular: Vec3::splat(0.05),
        shininess: 0.2,
    };
    match PointCloudCapsule::new(&[pc], lights(), Environment::default()) {
        Ok(c) => c,
        Err(e) => panic!("{e}"),
    }
}

/// A camera outside the cloud looking at its centre, framing it.
fn framing_camera(points: &[Vec3]) -> Camera {
    let (lo, hi) = points.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(a, b), p| (a.min(*p), b.max(*p)));
    let c = 0.5 * (lo + hi);
    let size = (hi - lo).max_element();
    Camera {
        position: c + Vec3::new(0.4, 0.25, 1.0).normalize() * size * 1.2,
        target: c,
        up: Vec3::Y,
        projection: Projection::Perspective { fov_y_deg: 50.0, near: 0.1, far: size * 4.0 },
    }
}

/// A wall facing the camera at the cloud's centre distance, over the left half of the image, as
/// raster depth (reversed-Z; 0 elsewhere).
fn wall_depth(camera: &Camera) -> Vec<f32> {
    let (n, f) = camera.near_far();
    let z = synthesize_depth(camera.position.distance(camera.target), -1.0, n, f);
    let mut d = vec![0.0; (W * H) as usize];
    for row in d.chunks_mut(W as usize) {
        row[..W as usize / 2].fill(z);
    }
    d
}

fn bench(c: &mut Criterion) {
    let points = scan();
    let camera = framing_camera(&points);
    let mut g = c.benchmark_group("capsule_1m");
    g.sample_size(10);
    g.bench_function("sphere_bvh_build", |b| b.iter(|| black_box(SphereBvh::build(black_box(&points), RADIUS).map(|b| b.len()))));
    let mut capsule = capsule_for(points);
    let mut frame = PackedRtFrame::new(W, H);
    g.bench_function("trace_pack_1080p", |b| {
        b.iter(|| capsule.render(&CapsuleRequest { camera, width: W, height: H, clip_depth: None }, &mut frame))
    });
    let wall = wall_depth(&camera);
    g.bench_function("trace_pack_1080p_clipped_wall", |b| {
        b.iter(|| capsule.render(&CapsuleRequest { camera, width: W, height: H, clip_depth: Some(&wall) }, &mut frame))
    });
    g.finish();
}

/// This process's CPU time (user + system) in seconds, from /proc (Linux; 0 elsewhere). On a
/// shared machine it is a fairer cost than wall time: Mrays per CPU-second.
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let after = stat.rsplit(')').next().unwrap_or("");
    let f: Vec<f64> = after.split_whitespace().filter_map(|x| x.parse().ok()).collect();
    // Fields after the command: state(skipped: not a number) ppid … utime is field 14 overall.
    if f.len() > 12 { (f[10] + f[11]) / 100.0 } else { 0.0 }
}

/// FNV-1a over the frame's texels.
fn checksum(frame: &PackedRtFrame) -> u64 {
    frame.texels.iter().flatten().fold(0xcbf2_9ce4_8422_2325u64, |h, &v| (h ^ v as u64).wrapping_mul(0x100_0000_01b3))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// One-shot numbers for the report (medians of a few runs).
fn report(label: &str, points: Vec<Vec3>, runs: usize) {
    let n = points.len();
    let camera = framing_camera(&points);
    let cpu_b = cpu_seconds();
    let build = median(
        (0..runs)
            .map(|_| {
                let t = Instant::now();
                black_box(SphereBvh::build(&points, RADIUS).map(|b| b.len()).ok());
                t.elapsed().as_secs_f64() * 1e3
            })
            .collect(),
    );
    let build_cpu_ms = (cpu_seconds() - cpu_b) / runs as f64 * 1e3;
    let mut capsule = capsule_for(points);
    let bytes = capsule.bytes();
    let mut frame = PackedRtFrame::new(W, H);
    let wall = wall_depth(&camera);
    let mut trace = |clip: Option<&[f32]>| {
        let req = CapsuleRequest { camera, width: W, height: H, clip_depth: clip };
        let stats: Vec<_> = (0..runs).map(|_| capsule.render(&req, &mut frame)).collect();
        (median(stats.iter().map(|s| s.trace_ms).collect()), stats[0].hits, checksum(&frame))
    };
    let cpu0 = cpu_seconds();
    let (full_ms, hits, full_sum) = trace(None);
    let cpu_per_frame = (cpu_seconds() - cpu0) / runs as f64;
    let (clip_ms, clip_hits, clip_sum) = trace(Some(&wall));
    // The same frames the other way (projection or BVH traversal): the same checksums, other speed.
    let chosen = capsule.resolved_visibility(W, H);
    let other = if chosen == PrimaryVisibility::Projected { PrimaryVisibility::Bvh } else { PrimaryVisibility::Projected };
    capsule.primary_visibility = other;
    let mut trace = |clip: Option<&[f32]>| {
        let req = CapsuleRequest { camera, width: W, height: H, clip_depth: clip };
        let stats: Vec<_> = (0..runs).map(|_| capsule.render(&req, &mut frame)).collect();
        (median(stats.iter().map(|s| s.trace_ms).collect()), checksum(&frame))
    };
    let cpu1 = cpu_seconds();
    let (bvh_ms, bvh_sum) = trace(None);
    let other_cpu_ms = (cpu_seconds() - cpu1) / runs as f64 * 1e3;
    let (bvh_clip_ms, bvh_clip_sum) = trace(Some(&wall));
    let rays = (W * H) as f64;
    // Block P alone (it is fused into the trace): encode one frame's worth of hits.
    let raygen = RayGen::new(&camera, W, H);
    let t = Instant::now();
    let mut acc = 0u64;
    for i in 0..W * H {
        let ray = raygen.ray(i % W, i / W);
        acc = acc.wrapping_add(encode_hit(Vec3::splat((i % 255) as f32 / 255.0), raygen.depth(&ray, 3.0))[0] as u64);
    }
    black_box(acc);
    let pack_ms = t.elapsed().as_secs_f64() * 1e3;
    println!(
        "{label}: {n} points, {threads} threads | build {build:.0} ms | trace+pack 1920x1080 {full_ms:.1} ms = {:.2} Mrays/s ({hits} hits) | \
         clipped by wall {clip_ms:.1} ms = {:.2} Mrays/s ({clip_hits} hits), speed-up {:.2}x | ray gen + block D + P alone (1 thread) {pack_ms:.1} ms | \
         memory {:.1} MB = {:.1} B/point | unclipped: {:.2} Mrays per CPU-second | build {build_cpu_ms:.0} CPU-ms | \
         checksums {full_sum:016x} {clip_sum:016x} | primary visibility: auto chose {chosen:?}; {other:?} instead: {bvh_ms:.1} ms \
         = {other_cpu_ms:.0} CPU-ms ({:.2}x the time), clipped {bvh_clip_ms:.1} ms, checksums {bvh_sum:016x} {bvh_clip_sum:016x}",
        rays / full_ms / 1e3,
        rays / clip_ms / 1e3,
        full_ms / clip_ms,
        bytes as f64 / 1e6,
        bytes as f64 / n as f64,
        rays / cpu_per_frame / 1e6,
        bvh_ms / full_ms,
        threads = rayon::current_num_threads(),
    );
}

fn one_shot() {
    let points = scan();
    let runs = std::env::var("CAPSULE_BENCH_RUNS").ok().and_then(|v| v.parse().ok()).unwrap_or(5usize).max(1);
    report("tree scan 1M", points.clone(), runs);
    if std::env::var("CAPSULE_BENCH_10M").is_ok_and(|v| v == "0") {
        return;
    }
    // 10 copies on a 5 × 2 grid, 20 m apart.
    let mut many = Vec::with_capacity(points.len() * 10);
    for k in 0..10 {
        let off = Vec3::new((k % 5) as f32 * 20.0, 0.0, (k / 5) as f32 * 20.0);
        many.extend(points.iter().map(|p| *p + off));
    }
    drop(points);
    report("tree scan x10", many, runs.min(3));
}

criterion_group!(benches, bench);

fn main() {
    // Our kernels' instruction-set path (`HYBRID_ISA` forces one).
    let isa = hybrid_cpu::isa::init_from_env().unwrap_or_else(|e| {
        eprintln!("error: {e}");
        std::process::exit(2)
    });
    eprintln!("kernels: {}", isa.name());
    // `cargo bench` passes `--bench`; `cargo test --benches` does not (skip the heavy report there).
    if std::env::args().any(|a| a == "--bench") {
        one_shot();
    }
    benches();
    Criterion::default().configure_from_args().final_summary();
}
