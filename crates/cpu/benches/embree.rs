//! Our triangle BVH against Embree 3's single-ray API, on the trace bench's scenes and rays, in
//! one run (issue 3: "trace-stage throughput per ray kind ≥ 1.0× Embree single-ray").
//!
//! Optional: it links Debian's Embree (`apt-get install libembree-dev`, 3.13) and is built only
//! with the `embree` feature:
//!
//! ```text
//! cargo bench -p hybrid-cpu --features embree --bench embree
//! ```
//!
//! For each scene of `trace_scenes` (the synthetic ~255K-triangle room and Dabrovic Sponza) it
//! builds both BVHs (Embree: one triangle geometry per mesh, `RTC_BUILD_QUALITY_MEDIUM`, the
//! default), then traces the same rays with both, alternating passes so both see the same
//! moments of a shared machine:
//! - shadow rays: ours `any_hit_attenuation_cached` (the trace stage's path) and without the
//!   cache, Embree `rtcOccluded1`;
//! - reflection rays and diffuse-bounce rays (cosine-weighted about the normal): ours
//!   `closest_hit`, Embree `rtcIntersect1`;
//! - primary rays of the scene's camera (640×360, in 4×4 pixel tiles): ours `closest_hit` one
//!   ray at a time, then ours `closest_hits` one 16-ray packet per tile (every answer checked to
//!   be the single ray's), against Embree `rtcIntersect16`, one 16-ray packet per tile;
//! - shadow rays again, ours as ray streams of `STREAM` rays (`any_hit_attenuation_stream`),
//!   with a cache (the trace stage's path: blocked runs one ray at a time) and without;
//! - reflection and diffuse-bounce rays again, ours as ray streams of `STREAM` rays
//!   (`closest_hits_stream`, the trace stage's path for first reflection and refraction rays),
//!   against Embree `rtcIntersect1` as above; it prints how many answers are not bit for bit
//!   the single ray's (rays through shared edges may keep the neighbouring triangle).
//!
//! Rays go out in chunks of 256 on rayon's pool (2 threads here), for both. Each line gives the
//! best of `TRACE_PASSES` (default 5) wall-clock passes, and the ratio ours / Embree. The answers
//! are compared ray by ray (blocked or not; closest distance within 1e-3 relative), so the two
//! trace the same work.
//!
//! `EMBREE_CONFIG` is passed to `rtcNewDevice` (default `threads=2`): `verbose=1` prints the
//! ISA Embree picked, `isa=sse2` (or `sse4.2`, `avx`, `avx2`) forces one. `EMBREE_QUALITY=2`
//! builds with `RTC_BUILD_QUALITY_HIGH` (spatial splits) instead of medium (1).

mod trace_scenes;

use std::ffi::{CString, c_char, c_uint, c_void};
use std::time::Instant;

use glam::Vec3;
use hybrid_core::PreparedScene;
use hybrid_cpu::bvh::{Hit, STREAM, SceneBvh, ShadowCache};
use rayon::prelude::*;
use trace_scenes::{load_average, primary_hits, primary_tiles, rays, scenes, trace_closest_hits, trace_primary, trace_shadow_rays};

// --- Embree 3.13 C API (rtcore.h), the parts used here ---------------------------------------

type RtcDevice = *mut c_void;
type RtcScene = *mut c_void;
type RtcGeometry = *mut c_void;

const RTC_GEOMETRY_TYPE_TRIANGLE: c_uint = 0;
const RTC_BUFFER_TYPE_INDEX: c_uint = 0;
const RTC_BUFFER_TYPE_VERTEX: c_uint = 1;
const RTC_FORMAT_UINT3: c_uint = 0x5003;
const RTC_FORMAT_FLOAT3: c_uint = 0x9003;
const RTC_BUILD_QUALITY_MEDIUM: c_uint = 1;
const RTC_INVALID_GEOMETRY_ID: c_uint = u32::MAX;

/// `struct RTCRay` (16-byte aligned).
#[repr(C, align(16))]
#[derive(Clone, Copy)]
struct RtcRay {
    org: [f32; 3],
    tnear: f32,
    dir: [f32; 3],
    time: f32,
    tfar: f32,
    mask: c_uint,
    id: c_uint,
    flags: c_uint,
}

/// `struct RTCHit` with `RTC_MAX_INSTANCE_LEVEL_COUNT` = 1 (Debian's build).
#[repr(C, align(16))]
#[derive(Clone, Copy)]
struct RtcHit {
    ng: [f32; 3],
    u: f32,
    v: f32,
    prim_id: c_uint,
    geom_id: c_uint,
    inst_id: [c_uint; 1],
}

#[repr(C)]
#[derive(Clone, Copy)]
struct RtcRayHit {
    ray: RtcRay,
    hit: RtcHit,
}

/// `struct RTCRayHit16` (`RTCRay16` then `RTCHit16`, SoA, 64-byte aligned), flattened.
#[repr(C, align(64))]
struct RtcRayHit16 {
    org: [[f32; 16]; 3],
    tnear: [f32; 16],
    dir: [[f32; 16]; 3],
    time: [f32; 16],
    tfar: [f32; 16],
    mask: [c_uint; 16],
    id: [c_uint; 16],
    flags: [c_uint; 16],
    ng: [[f32; 16]; 3],
    u: [f32; 16],
    v: [f32; 16],
    prim_id: [c_uint; 16],
    geom_id: [c_uint; 16],
    inst_id: [[c_uint; 16]; 1],
}

/// The `valid` mask of `rtcIntersect16` (-1 = active lane), 64-byte aligned as Embree requires.
#[repr(C, align(64))]
struct Valid16([i32; 16]);

/// `struct RTCIntersectContext` with one instance level and no minimum width (Debian's build:
/// `RTC_MAX_INSTANCE_LEVEL_COUNT 1`, `RTC_MIN_WIDTH 0` in `rtcore_config.h`).
#[repr(C)]
struct RtcIntersectContext {
    flags: c_uint,
    filter: *const c_void,
    inst_id: [c_uint; 1],
}

impl RtcIntersectContext {
    /// `rtcInitIntersectContext` (an inline function in the header).
    fn new() -> Self {
        Self { flags: 0, filter: std::ptr::null(), inst_id: [RTC_INVALID_GEOMETRY_ID] }
    }
}

#[link(name = "embree3")]
unsafe extern "C" {
    fn rtcNewDevice(config: *const c_char) -> RtcDevice;
    fn rtcReleaseDevice(device: RtcDevice);
    fn rtcGetDeviceError(device: RtcDevice) -> c_uint;
    fn rtcNewScene(device: RtcDevice) -> RtcScene;
    fn rtcSetSceneBuildQuality(scene: RtcScene, quality: c_uint);
    fn rtcCommitScene(scene: RtcScene);
    fn rtcReleaseScene(scene: RtcScene);
    fn rtcNewGeometry(device: RtcDevice, kind: c_uint) -> RtcGeometry;
    fn rtcSetNewGeometryBuffer(
        geometry: RtcGeometry,
        kind: c_uint,
        slot: c_uint,
        format: c_uint,
        byte_stride: usize,
        item_count: usize,
    ) -> *mut c_void;
    fn rtcCommitGeometry(geometry: RtcGeometry);
    fn rtcAttachGeometry(scene: RtcScene, geometry: RtcGeometry) -> c_uint;
    fn rtcReleaseGeometry(geometry: RtcGeometry);
    fn rtcIntersect1(scene: RtcScene, context: *mut RtcIntersectContext, rayhit: *mut RtcRayHit);
    fn rtcIntersect16(valid: *const Valid16, scene: RtcScene, context: *mut RtcIntersectContext, rayhit: *mut RtcRayHit16);
    fn rtcOccluded1(scene: RtcScene, context: *mut RtcIntersectContext, ray: *mut RtcRay);
}

/// An Embree device (owned; released on drop).
struct Device(RtcDevice);

impl Device {
    fn new(config: &str) -> Device {
        let config = CString::new(config).expect("EMBREE_CONFIG holds a NUL byte");
        // SAFETY: FFI; `config` is a NUL-terminated string that outlives the call.
        let device = unsafe { rtcNewDevice(config.as_ptr()) };
        assert!(!device.is_null(), "rtcNewDevice failed (error {})", unsafe {
            // SAFETY: FFI; a null device asks for the thread's last device-creation error.
            rtcGetDeviceError(std::ptr::null_mut())
        });
        Device(device)
    }
}

impl Drop for Device {
    fn drop(&mut self) {
        // SAFETY: FFI; the device was created by `rtcNewDevice` and every scene made from it has
        // been released (scenes borrow the device).
        unsafe { rtcReleaseDevice(self.0) }
    }
}

/// A committed Embree scene (released on drop).
struct Scene<'d> {
    scene: RtcScene,
    _device: &'d Device,
}

// SAFETY: Embree documents `rtcIntersect1`/`rtcOccluded1` on a committed scene as thread-safe;
// nothing here changes the scene after `rtcCommitScene`.
unsafe impl Send for Scene<'_> {}
// SAFETY: as for `Send`.
unsafe impl Sync for Scene<'_> {}

impl<'d> Scene<'d> {
    /// One triangle geometry per world-space mesh, build quality medium (Embree's default).
    fn build(device: &'d Device, prepared: &PreparedScene) -> Scene<'d> {
        // SAFETY: FFI on a live device. The buffers Embree returns are sized by us (`itemCount`
        // items of `byteStride` bytes, Embree pads them for its SIMD loads) and written only within
        // that size, through slices made from them; each geometry is committed before it is
        // attached and released after (the scene keeps its own reference).
        unsafe {
            let scene = rtcNewScene(device.0);
            let quality = std::env::var("EMBREE_QUALITY").ok().and_then(|q| q.parse().ok()).unwrap_or(RTC_BUILD_QUALITY_MEDIUM);
            rtcSetSceneBuildQuality(scene, quality);
            for mesh in prepared.meshes.iter().filter(|m| !m.indices.is_empty()) {
                let geometry = rtcNewGeometry(device.0, RTC_GEOMETRY_TYPE_TRIANGLE);
                let v = rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 12, mesh.positions.len())
                    as *mut [f32; 3];
                let i =
                    rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 12, mesh.indices.len()) as *mut [u32; 3];
                assert!(!v.is_null() && !i.is_null(), "rtcSetNewGeometryBuffer failed");
                let (v, i) =
                    (std::slice::from_raw_parts_mut(v, mesh.positions.len()), std::slice::from_raw_parts_mut(i, mesh.indices.len()));
                v.iter_mut().zip(&mesh.positions).for_each(|(d, p)| *d = p.to_array());
                i.copy_from_slice(&mesh.indices);
                rtcCommitGeometry(geometry);
                rtcAttachGeometry(scene, geometry);
                rtcReleaseGeometry(geometry);
            }
            rtcCommitScene(scene);
            assert_eq!(rtcGetDeviceError(device.0), 0, "Embree reported an error building the scene");
            Scene { scene, _device: device }
        }
    }

    /// `rtcOccluded1` on `origin + t·dir`, `0 < t < t_max`.
    fn occluded(&self, origin: Vec3, dir: Vec3, t_max: f32) -> bool {
        let mut ray =
            RtcRay { org: origin.to_array(), tnear: 0.0, dir: dir.to_array(), time: 0.0, tfar: t_max, mask: u32::MAX, id: 0, flags: 0 };
        let mut context = RtcIntersectContext::new();
        // SAFETY: FFI on a committed scene with a valid, aligned context and ray.
        unsafe { rtcOccluded1(self.scene, &mut context, &mut ray) };
        // Embree sets tfar to −inf when the ray is blocked.
        ray.tfar < 0.0
    }

    /// `rtcIntersect1`: the closest hit distance, if any.
    fn closest_hit(&self, origin: Vec3, dir: Vec3) -> Option<f32> {
        let mut rh = RtcRayHit {
            ray: RtcRay {
                org: origin.to_array(),
                tnear: 0.0,
                dir: dir.to_array(),
                time: 0.0,
                tfar: f32::INFINITY,
                mask: u32::MAX,
                id: 0,
                flags: 0,
            },
            hit: RtcHit { ng: [0.0; 3], u: 0.0, v: 0.0, prim_id: 0, geom_id: RTC_INVALID_GEOMETRY_ID, inst_id: [RTC_INVALID_GEOMETRY_ID] },
        };
        let mut context = RtcIntersectContext::new();
        // SAFETY: FFI on a committed scene with a valid, aligned context and ray/hit.
        unsafe { rtcIntersect1(self.scene, &mut context, &mut rh) };
        (rh.hit.geom_id != RTC_INVALID_GEOMETRY_ID).then_some(rh.ray.tfar)
    }

    /// `rtcIntersect16` on up to 16 rays `(origin, unit dir, t_far)` as one packet: each ray's
    /// closest hit distance (`None`: a miss), lanes past `rays.len()` `None`.
    fn closest_hits16(&self, rays: &[(Vec3, Vec3, f32)]) -> [Option<f32>; 16] {
        assert!(rays.len() <= 16);
        let mut valid = Valid16([0; 16]);
        let mut rh = RtcRayHit16 {
            org: [[0.0; 16]; 3],
            tnear: [0.0; 16],
            dir: [[0.0; 16]; 3],
            time: [0.0; 16],
            tfar: [0.0; 16],
            mask: [u32::MAX; 16],
            id: [0; 16],
            flags: [0; 16],
            ng: [[0.0; 16]; 3],
            u: [0.0; 16],
            v: [0.0; 16],
            prim_id: [0; 16],
            geom_id: [RTC_INVALID_GEOMETRY_ID; 16],
            inst_id: [[RTC_INVALID_GEOMETRY_ID; 16]],
        };
        for (k, &(o, d, far)) in rays.iter().enumerate() {
            valid.0[k] = -1;
            for a in 0..3 {
                rh.org[a][k] = o[a];
                rh.dir[a][k] = d[a];
            }
            rh.tfar[k] = far;
        }
        let mut context = RtcIntersectContext::new();
        // SAFETY: FFI on a committed scene with a valid context, and a 64-byte aligned valid mask
        // and ray/hit packet of 16 lanes.
        unsafe { rtcIntersect16(&valid, self.scene, &mut context, &mut rh) };
        std::array::from_fn(|k| (k < rays.len() && rh.geom_id[k] != RTC_INVALID_GEOMETRY_ID).then_some(rh.tfar[k]))
    }
}

impl Drop for Scene<'_> {
    fn drop(&mut self) {
        // SAFETY: FFI; the scene was made by `rtcNewScene` and no query is running.
        unsafe { rtcReleaseScene(self.scene) }
    }
}

// --- the comparison ------------------------------------------------------------------------

/// Best wall-clock seconds of `ours` and `theirs` over `passes`, run alternately.
fn race(passes: usize, mut ours: impl FnMut(), mut theirs: impl FnMut()) -> (f64, f64) {
    let (mut a, mut b) = (f64::INFINITY, f64::INFINITY);
    for _ in 0..passes {
        let t = Instant::now();
        ours();
        a = a.min(t.elapsed().as_secs_f64());
        let t = Instant::now();
        theirs();
        b = b.min(t.elapsed().as_secs_f64());
    }
    (a, b)
}

fn line(scene: &str, what: &str, items: usize, unit: &str, (ours, theirs): (f64, f64)) {
    let m = items as f64 * 1e-6;
    println!(
        "{scene:>10} {what:<24} ours {:>8.2} ms = {:>6.2} M{unit}/s   Embree {:>8.2} ms = {:>6.2} M{unit}/s   ours/Embree {:>5.2}×  [load {}]",
        ours * 1e3,
        m / ours,
        theirs * 1e3,
        m / theirs,
        theirs / ours,
        load_average()
    );
}

fn main() {
    // `cargo bench` passes `--bench`; there is nothing to filter.
    let passes = std::env::var("TRACE_PASSES").ok().and_then(|p| p.parse().ok()).unwrap_or(5);
    let config = std::env::var("EMBREE_CONFIG").unwrap_or_else(|_| "threads=2".into());
    let device = Device::new(&config);
    // Our kernels' instruction-set path (`HYBRID_ISA` forces one).
    let isa = hybrid_cpu::isa::init_from_env().unwrap_or_else(|e| {
        eprintln!("error: {e}");
        std::process::exit(2)
    });
    println!(
        "rayon threads {}, our kernels {}, Embree config {config:?}, best of {passes} alternating passes",
        rayon::current_num_threads(),
        isa.name()
    );
    for (name, scene, light) in scenes() {
        let prepared = PreparedScene::new(&scene);
        let tris = prepared.triangles.len();
        let build = race(passes, || drop(SceneBvh::build(&prepared)), || drop(Scene::build(&device, &prepared)));
        line(name, &format!("build {}K triangles", tris / 1000), tris, "tris", build);

        let bvh = SceneBvh::build(&prepared);
        let embree = Scene::build(&device, &prepared);
        let r = rays(&prepared, &bvh, light);

        // The same answers, ray by ray.
        let blocked: Vec<(bool, bool)> =
            r.shadow.par_iter().map(|&(o, d, t)| (bvh.any_hit_attenuation(&prepared, o, d, t) < 1.0, embree.occluded(o, d, t))).collect();
        let differ = blocked.iter().filter(|(a, b)| a != b).count();
        println!(
            "{name:>10} shadow rays: {} blocked by ours, {} by Embree, {differ} differ",
            blocked.iter().filter(|p| p.0).count(),
            blocked.iter().filter(|p| p.1).count()
        );
        for (kind, rays) in [("reflection", &r.reflection), ("diffuse", &r.diffuse)] {
            let hits: Vec<(Option<f32>, Option<f32>)> =
                rays.par_iter().map(|&(o, d)| (bvh.closest_hit(o, d, 0.0, f32::INFINITY).map(|h| h.t), embree.closest_hit(o, d))).collect();
            let differ = hits
                .iter()
                .filter(|(a, b)| match (a, b) {
                    (Some(a), Some(b)) => (a - b).abs() > 1e-3 * a.abs().max(b.abs()),
                    (a, b) => a.is_some() != b.is_some(),
                })
                .count();
            println!(
                "{name:>10} {kind} rays: {} hit by ours, {} by Embree, {differ} differ",
                hits.iter().filter(|p| p.0.is_some()).count(),
                hits.iter().filter(|p| p.1.is_some()).count()
            );
        }

        let chunks = |f: &(dyn Fn(Vec3, Vec3, f32) -> f32 + Sync)| -> f32 {
            r.shadow.par_chunks(256).with_max_len(1).map(|c| c.iter().map(|&(o, d, t)| f(o, d, t)).sum::<f32>()).sum()
        };
        let shadow_cached = || {
            std::hint::black_box(trace_shadow_rays(&prepared, &bvh, &r.shadow, true));
        };
        let shadow_embree = || {
            std::hint::black_box(chunks(&|o, d, t| if embree.occluded(o, d, t) { 0.0 } else { 1.0 }));
        };
        line(name, "shadow rays, cache", r.shadow.len(), "rays", race(passes, shadow_cached, shadow_embree));
        let shadow_plain = || {
            std::hint::black_box(trace_shadow_rays(&prepared, &bvh, &r.shadow, false));
        };
        line(name, "shadow rays, no cache", r.shadow.len(), "rays", race(passes, shadow_plain, shadow_embree));
        // Ours as ray streams of `STREAM` rays: without a cache (every ray in the stream), and
        // as the trace stage sends them (with a cache: blocked runs one ray at a time).
        let single: Vec<u32> = r.shadow.par_iter().map(|&(o, d, t)| bvh.any_hit_attenuation(&prepared, o, d, t).to_bits()).collect();
        for cached in [false, true] {
            let streamed: Vec<u32> = r
                .shadow
                .par_chunks(STREAM)
                .flat_map_iter(|c| {
                    let mut cache = ShadowCache::default();
                    bvh.any_hit_attenuation_stream(&prepared, c, cached.then_some(&mut cache)).into_iter().map(f32::to_bits)
                })
                .collect();
            let differ = single.iter().zip(&streamed).filter(|(a, b)| a != b).count();
            println!(
                "{name:>10} shadow rays in streams{}: {differ} of {} attenuations not bit for bit the single ray's",
                if cached { ", cache" } else { "" },
                r.shadow.len()
            );
        }
        let (shadow, bvh_ref, prepared_ref) = (&r.shadow, &bvh, &prepared);
        let streams = |cached: bool| {
            move || {
                std::hint::black_box(
                    shadow
                        .par_chunks(STREAM)
                        .with_max_len(1)
                        .map(|c| {
                            let mut cache = ShadowCache::default();
                            bvh_ref.any_hit_attenuation_stream(prepared_ref, c, cached.then_some(&mut cache)).iter().sum::<f32>()
                        })
                        .sum::<f32>(),
                );
            }
        };
        line(name, "shadow rays, cache, streams", r.shadow.len(), "rays", race(passes, streams(true), shadow_embree));
        let shadow_streams = streams(false);
        line(name, "shadow rays, no cache, streams", r.shadow.len(), "rays", race(passes, shadow_streams, shadow_embree));

        for (kind, rays) in [("reflection rays", &r.reflection), ("diffuse-bounce rays", &r.diffuse)] {
            let ours = || {
                std::hint::black_box(trace_closest_hits(&bvh, rays));
            };
            let theirs = || {
                std::hint::black_box(
                    rays.par_chunks(256)
                        .with_max_len(1)
                        .map(|c| c.iter().filter_map(|&(o, d)| embree.closest_hit(o, d)).sum::<f32>())
                        .sum::<f32>(),
                );
            };
            line(name, kind, rays.len(), "rays", race(passes, ours, theirs));

            // Ours as ray streams of `STREAM` rays: the same answers as one at a time (a ray
            // through a shared edge may find the neighbouring triangle, within rounding).
            let bits = |h: Option<Hit>| h.map(|h| (h.t.to_bits(), h.triangle, h.bary.to_array().map(f32::to_bits)));
            let single: Vec<_> = rays.par_iter().map(|&(o, d)| bits(bvh.closest_hit(o, d, 0.0, f32::INFINITY))).collect();
            let streamed: Vec<_> =
                rays.par_chunks(STREAM).flat_map_iter(|c| bvh.closest_hits_stream(c, 0.0, f32::INFINITY).into_iter().map(bits)).collect();
            let differ = single.iter().zip(&streamed).filter(|(a, b)| a != b).count();
            println!("{name:>10} {kind} in streams: {differ} of {} answers not bit for bit the single ray's", rays.len());
            let ours = || {
                std::hint::black_box(
                    rays.par_chunks(STREAM)
                        .with_max_len(1)
                        .map(|c| bvh.closest_hits_stream(c, 0.0, f32::INFINITY).iter().flatten().map(|h| h.t).sum::<f32>())
                        .sum::<f32>(),
                );
            };
            line(name, &format!("{kind}, streams"), rays.len(), "rays", race(passes, ours, theirs));
        }

        // Primary rays of the scene's camera at WIDTH × HEIGHT, in 4×4 pixel tiles (the coherent
        // groups a packet tracer wants): ours one ray at a time, Embree 16-wide packets, one
        // per tile; 256 rays (16 tiles) per rayon chunk for both. Same answers first.
        let primary = primary_tiles(&prepared);
        let ours_hits = primary_hits(&bvh, &primary, false);
        let theirs_hits: Vec<Option<f32>> = primary.chunks(16).flat_map(|c| embree.closest_hits16(c)).collect();
        let differ = ours_hits
            .iter()
            .zip(&theirs_hits)
            .filter(|(a, b)| match (a, b) {
                (Some(a), Some(b)) => (a - b).abs() > 1e-3 * a.abs().max(b.abs()),
                (a, b) => a.is_some() != b.is_some(),
            })
            .count();
        println!(
            "{name:>10} primary rays: {} hit by ours, {} by Embree's packets, {differ} differ",
            ours_hits.iter().flatten().count(),
            theirs_hits.iter().flatten().count()
        );
        let ours = || {
            std::hint::black_box(trace_primary(&bvh, &primary, false));
        };
        let theirs = || {
            std::hint::black_box(
                primary
                    .par_chunks(256)
                    .with_max_len(1)
                    .map(|c| c.chunks(16).map(|p| embree.closest_hits16(p).iter().flatten().sum::<f32>()).sum::<f32>())
                    .sum::<f32>(),
            );
        };
        line(name, "primary rays, 16-packets", primary.len(), "rays", race(passes, ours, theirs));

        // Ours in packets too: one `closest_hits` per tile, every answer bit for bit the
        // single ray's.
        let bits = |hits: Vec<Option<f32>>| hits.into_iter().map(|t| t.map(f32::to_bits)).collect::<Vec<_>>();
        assert_eq!(bits(primary_hits(&bvh, &primary, true)), bits(ours_hits), "{name}: packets and single rays disagree");
        let ours = || {
            std::hint::black_box(trace_primary(&bvh, &primary, true));
        };
        line(name, "primary, both 16-packets", primary.len(), "rays", race(passes, ours, theirs));
    }
}
