//! The memory a render will take, estimated before anything is allocated (issue 22), so a size
//! or scene that does not fit is refused with a clear error (exit 2) instead of the process
//! aborting on a failed allocation. The frame's share is exact per pixel (the buffers each
//! backend allocates, tied to their types by tests); the scene's share counts the data the
//! scene holds and what a renderer builds from it (world-space copy, BVHs, GPU upload), with
//! per-triangle and per-point sizes measured on this code (peak resident memory, see
//! `BENCHMARKS.md`, "Memory estimate").
//!
//! [`estimate`] is what `hybrid render` and `hybrid bench` check against `--max-memory`; the
//! viewer can call it the same way for its window size.

use std::mem::size_of;

use glam::{Vec3, Vec4};
use hybrid_scene::memory::scene_bytes;
use hybrid_scene::{Bytes, MemoryLimit, Scene};

/// Which backend's buffers to count.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Backend {
    Cpu,
    Gpu,
}

/// [`crate::GBuffer`]: position, normal, emission, ambient (Vec3), diffuse, specular (Vec4),
/// optical (Vec3), object id (u32), mask and depth (f32).
pub const GBUFFER_BYTES_PER_PIXEL: u64 = (5 * size_of::<Vec3>() + 2 * size_of::<Vec4>() + 3 * 4) as u64;
/// [`crate::FrameBuffers`]: lighting, shadow, reflection, refraction (Vec3) and the final
/// sRGB image (4 bytes).
pub const FRAME_BUFFERS_BYTES_PER_PIXEL: u64 = (4 * size_of::<Vec3>() + 4) as u64;
/// With point clouds: the unpacked [`crate::RtLayer`] (Vec3 colour, f32 depth) and the packed
/// RGBA16UI frame (8 bytes).
pub const POINT_CLOUD_BYTES_PER_PIXEL: u64 = (size_of::<Vec3>() + 4 + 8) as u64;
/// Writing the PNG: the final image as a flat byte copy.
pub const OUTPUT_BYTES_PER_PIXEL: u64 = 4;
/// `--dump`: the largest buffer's conversion for writing (an EXR's three f32 channels, copied
/// once more by the encoder, and its PNG's bytes).
pub const DUMP_BYTES_PER_PIXEL: u64 = 2 * 3 * 4 + 2 * 4;
/// GPU backend: its frame textures (`hybrid_gpu::targets::FrameTargets`, a test ties the two):
/// position Rgba32Float 16, six Rgba16Float G-buffer targets 6 × 8, object id, mask, depth
/// 3 × 4, lighting/shadow/reflection/refraction Rgba16Float 4 × 8, final 4, packed 8.
pub const GPU_TARGET_BYTES_PER_PIXEL: u64 = 16 + 6 * 8 + 3 * 4 + 4 * 8 + 4 + 8;
/// GPU backend: reading one Rgba32Float target back at a time: the mapped staging buffer,
/// its copy, the rows unpadded, the f32 texels, the `Vec4`s (16 bytes each).
pub const GPU_READBACK_BYTES_PER_PIXEL: u64 = 5 * 16;

/// The CPU backend's preparation per triangle: the world-space index triple (12) and
/// `TriangleRef` (8), the BVH's triangle packs, slot tables and nodes, and its build's
/// temporaries (corners, primitives, order). Measured 140 on a 8.4M-triangle sphere.
pub const CPU_PREPARE_BYTES_PER_TRIANGLE: u64 = 200;
/// (The world-space copy of each mesh's vertex and index arrays is counted exactly, from the
/// scene's meshes.)
/// The capsule per point: the sphere BVH (centres, indices, nodes), its build's temporaries and
/// the projected path's bins. Measured 82 on the 1M-point tree scan; about 112 since the sphere
/// BVH is built by the BVH core (32-byte box primitives and a boxed binary tree: the process's
/// peak on `scenes/tree-merge.toml` rose by 31 MB).
pub const CPU_PREPARE_BYTES_PER_POINT: u64 = 128;
/// The GPU backend per triangle: its upload's host-side arrays and the device buffers (on a
/// software adapter those are host memory too). Measured 38 on lavapipe (8.4M-triangle sphere).
pub const GPU_PREPARE_BYTES_PER_TRIANGLE: u64 = 128;
/// The GPU backend per point. Measured 106 on lavapipe (the 1M-point tree scan).
pub const GPU_PREPARE_BYTES_PER_POINT: u64 = 160;
/// The GPU backend per texel: its texture pages (host copy and device buffer).
pub const GPU_PREPARE_BYTES_PER_TEXEL: u64 = 2 * 4;
/// Fixed overhead of a process that renders on the CPU (code, allocator, thread stacks).
pub const CPU_BASE_BYTES: u64 = 64 << 20;
/// Fixed overhead with the GPU backend (the driver, compiled pipelines; lavapipe took 270 MB for
/// the demo at 64×36).
pub const GPU_BASE_BYTES: u64 = 384 << 20;

/// Bytes per pixel of one frame on `backend`, plus `extra_per_pixel` (e.g.
/// [`DUMP_BYTES_PER_PIXEL`]).
pub fn frame_bytes_per_pixel(backend: Backend, point_clouds: bool) -> u64 {
    let host = GBUFFER_BYTES_PER_PIXEL + FRAME_BUFFERS_BYTES_PER_PIXEL + OUTPUT_BYTES_PER_PIXEL;
    match backend {
        Backend::Cpu => host + if point_clouds { POINT_CLOUD_BYTES_PER_PIXEL } else { 0 },
        // The packed frame is read back only with point clouds; the targets exist always.
        Backend::Gpu => host + GPU_TARGET_BYTES_PER_PIXEL + GPU_READBACK_BYTES_PER_PIXEL + if point_clouds { 8 } else { 0 },
    }
}

/// What a render is expected to take, by part.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Estimate {
    /// The loaded scene's data (meshes, textures, points).
    pub scene: u64,
    /// What the backend builds from it (world-space copy, BVHs, GPU upload).
    pub prepared: u64,
    /// The frame's buffers (width × height × bytes per pixel).
    pub frame: u64,
    /// The process's fixed overhead ([`CPU_BASE_BYTES`], [`GPU_BASE_BYTES`]).
    pub base: u64,
}

impl Estimate {
    pub fn total(&self) -> u64 {
        self.scene.saturating_add(self.prepared).saturating_add(self.frame).saturating_add(self.base)
    }

    /// `Err` with a message that names the limit, the estimate by part and how to change it
    /// when the total is above `limit`.
    pub fn check(&self, limit: &MemoryLimit) -> Result<(), String> {
        if self.total() <= limit.bytes {
            return Ok(());
        }
        let needs = if self.scene == 0 && self.prepared == 0 {
            format!("this render's frame alone needs about {} of memory", Bytes(self.total()))
        } else {
            format!(
                "this render needs about {} of memory (frame {}, scene {}, prepared scene {})",
                Bytes(self.total()),
                Bytes(self.frame),
                Bytes(self.scene),
                Bytes(self.prepared)
            )
        };
        Err(format!(
            "{needs}, above the limit of {}; use a smaller --size or scene, or raise the limit with --max-memory (e.g. --max-memory {})",
            limit.describe(),
            suggest(self.total())
        ))
    }
}

/// A `--max-memory` value above `bytes`: whole GiB, rounded up.
fn suggest(bytes: u64) -> String {
    format!("{}GiB", bytes.div_ceil(1 << 30).max(1))
}

/// The frame alone (no scene): `width` × `height` × [`frame_bytes_per_pixel`] + `extra_per_pixel`.
pub fn frame_bytes(backend: Backend, width: u32, height: u32, point_clouds: bool, extra_per_pixel: u64) -> u64 {
    let pixels = width as u64 * height as u64;
    pixels.saturating_mul(frame_bytes_per_pixel(backend, point_clouds) + extra_per_pixel)
}

/// The estimate for rendering `scene` at `width` × `height` on `backend`, with `extra_per_pixel`
/// bytes per pixel beyond the frame (`--dump`, a benchmark's reference images).
pub fn estimate(scene: &Scene, backend: Backend, width: u32, height: u32, extra_per_pixel: u64) -> Estimate {
    let triangles: u64 = scene.objects.iter().flat_map(|o| &o.meshes).map(|m| m.indices.len() as u64).sum();
    let points: u64 = scene.point_clouds.iter().map(|c| c.points.len() as u64).sum();
    let texels: u64 = scene.textures.iter().flat_map(|t| &t.levels).map(|l| l.texels.len() as u64).sum();
    let held = scene_bytes(scene);
    let prepared = match backend {
        // The world-space copy of every mesh is as large as the scene's meshes.
        Backend::Cpu => {
            let meshes: u64 = scene.objects.iter().flat_map(|o| &o.meshes).map(hybrid_scene::memory::mesh_bytes).sum();
            meshes + triangles * CPU_PREPARE_BYTES_PER_TRIANGLE + points * CPU_PREPARE_BYTES_PER_POINT
        }
        Backend::Gpu => {
            // The GPU backend prepares the CPU's world-space scene too (heuristic, BVH build).
            let meshes: u64 = scene.objects.iter().flat_map(|o| &o.meshes).map(hybrid_scene::memory::mesh_bytes).sum();
            meshes
                + triangles * GPU_PREPARE_BYTES_PER_TRIANGLE
                + points * GPU_PREPARE_BYTES_PER_POINT
                + texels * GPU_PREPARE_BYTES_PER_TEXEL
        }
    };
    let point_clouds = !scene.point_clouds.is_empty();
    let prepared = prepared.saturating_add(fallback_bytes(scene, backend, width, height));
    Estimate { scene: held, prepared, frame: frame_bytes(backend, width, height, point_clouds, extra_per_pixel), base: base_bytes(backend) }
}

/// The raster fallbacks' share (issue 18, counted with the prepared scene; an upper bound: it
/// assumes `--fallback raster` and every map and probe rendered): the three fallback buffers
/// per pixel (GPU: their targets too), each shadow-casting light's maps (directional: its
/// cascades; spot: one map; point: six cube faces; 4 bytes a texel), each reflective or
/// refractive object's probe (colour and distance per texel), and with refractive objects the
/// see-through layer (a G-buffer and lighting over the widened view).
pub fn fallback_bytes(scene: &Scene, backend: Backend, width: u32, height: u32) -> u64 {
    use crate::fallback::{FallbackSettings, SEE_THROUGH_GUARD};
    let s = FallbackSettings::default();
    let pixels = width as u64 * height as u64;
    let per_pixel = 3 * size_of::<Vec3>() as u64 + if backend == Backend::Gpu { 3 * 8 } else { 0 };
    let map = |n: u32| n as u64 * n as u64 * 4;
    let l = &scene.lights;
    let maps = l.directional.iter().filter(|d| d.casts_shadows).count() as u64 * s.cascades as u64 * map(s.shadow_map_size)
        + l.spot.iter().filter(|d| d.casts_shadows).count() as u64 * map(s.shadow_map_size)
        + l.point.iter().filter(|d| d.casts_shadows).count() as u64 * 6 * map(s.cube_shadow_size);
    let probe = 6 * s.probe_size as u64 * s.probe_size as u64 * (size_of::<Vec3>() as u64 + 4);
    let probes =
        scene.objects.iter().filter(|o| o.is_reflective(&scene.materials) || o.is_refractive(&scene.materials)).count() as u64 * probe;
    // Any refractive object may be seen through the layer (`fallback::see_through_objects`:
    // planar ones and convex polyhedra).
    let see_through = if scene.objects.iter().any(|o| o.is_refractive(&scene.materials)) {
        let layer_pixels = (pixels as f64 * (SEE_THROUGH_GUARD * SEE_THROUGH_GUARD) as f64).ceil() as u64;
        layer_pixels.saturating_mul(GBUFFER_BYTES_PER_PIXEL + size_of::<Vec3>() as u64)
    } else {
        0
    };
    pixels.saturating_mul(per_pixel).saturating_add(maps).saturating_add(probes).saturating_add(see_through)
}

/// The fixed overhead on `backend`.
pub fn base_bytes(backend: Backend) -> u64 {
    match backend {
        Backend::Cpu => CPU_BASE_BYTES,
        Backend::Gpu => GPU_BASE_BYTES,
    }
}

/// The least any render at `width` × `height` takes (the CPU backend's frame without point
/// clouds, no scene): checked before a scene is loaded, so an impossible `--size` fails at once.
pub fn frame_only(width: u32, height: u32, extra_per_pixel: u64) -> Estimate {
    Estimate { scene: 0, prepared: 0, frame: frame_bytes(Backend::Cpu, width, height, false, extra_per_pixel), base: CPU_BASE_BYTES }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{FrameBuffers, GBuffer, RtLayer};

    fn vec_bytes<T>(v: &[T]) -> u64 {
        std::mem::size_of_val(v) as u64
    }

    #[test]
    fn per_pixel_sizes_are_the_buffers_allocated() {
        let (w, h) = (5, 3);
        let n = (w * h) as u64;
        let g = GBuffer::new(w, h);
        let gbuffer = vec_bytes(&g.position)
            + vec_bytes(&g.normal)
            + vec_bytes(&g.emission)
            + vec_bytes(&g.ambient)
            + vec_bytes(&g.diffuse)
            + vec_bytes(&g.specular)
            + vec_bytes(&g.optical)
            + vec_bytes(&g.object_id)
            + vec_bytes(&g.mask)
            + vec_bytes(&g.depth);
        assert_eq!(gbuffer, n * GBUFFER_BYTES_PER_PIXEL);
        let b = FrameBuffers::new(w, h);
        let buffers =
            vec_bytes(&b.lighting) + vec_bytes(&b.shadow) + vec_bytes(&b.reflection) + vec_bytes(&b.refraction) + vec_bytes(&b.final_srgb);
        assert_eq!(buffers, n * FRAME_BUFFERS_BYTES_PER_PIXEL);
        let l = RtLayer::new(w, h);
        let packed = crate::depth_merge::PackedRtFrame::new(w, h);
        assert_eq!(vec_bytes(&l.color) + vec_bytes(&l.depth) + vec_bytes(&packed.texels), n * POINT_CLOUD_BYTES_PER_PIXEL);
    }

    #[test]
    fn frame_estimate_by_hand() {
        // 104 (G-buffer: 5 × 12 + 2 × 16 + 3 × 4) + 52 (4 × 12 + 4) + 4 (PNG bytes) = 160.
        assert_eq!(frame_bytes_per_pixel(Backend::Cpu, false), 160);
        // + 16 (RT layer) + 8 (packed).
        assert_eq!(frame_bytes_per_pixel(Backend::Cpu, true), 184);
        // 160 + 120 (targets) + 80 (read-back).
        assert_eq!(frame_bytes_per_pixel(Backend::Gpu, false), 360);
        assert_eq!(frame_bytes(Backend::Cpu, 64, 36, false, 0), 64 * 36 * 160);
        assert_eq!(frame_bytes(Backend::Cpu, 10, 10, true, DUMP_BYTES_PER_PIXEL), 100 * (184 + 32));
        // The largest size flags accept does not overflow.
        assert_eq!(frame_bytes(Backend::Gpu, 16384, 16384, true, 0), 16384 * 16384 * 368);
    }

    #[test]
    fn estimate_of_a_scene_and_its_check() {
        let scene = hybrid_scene::demo_scene();
        let e = estimate(&scene, Backend::Cpu, 64, 36, 0);
        assert_eq!(e.frame, 64 * 36 * 160);
        assert_eq!(e.scene, hybrid_scene::memory::scene_bytes(&scene));
        let triangles: u64 = scene.objects.iter().flat_map(|o| &o.meshes).map(|m| m.indices.len() as u64).sum();
        assert!(e.prepared >= triangles * CPU_PREPARE_BYTES_PER_TRIANGLE + fallback_bytes(&scene, Backend::Cpu, 64, 36));
        // The demo's fallbacks: a sun (3 cascades of 1024²), a point light (6 faces of 512²) and a
        // spot light (1024²) casting shadows, 4 bytes a texel, and the 36 bytes a pixel of the
        // three fallback buffers; its probes and see-through layer on top.
        assert!(fallback_bytes(&scene, Backend::Cpu, 64, 36) >= (3 << 22) + (6 << 20) + (1 << 22) + 64 * 36 * 36);
        assert_eq!(e.total(), e.scene + e.prepared + e.frame + CPU_BASE_BYTES);
        assert_eq!(frame_only(64, 36, 0).total(), 64 * 36 * 160 + CPU_BASE_BYTES);
        assert!(e.check(&MemoryLimit::explicit(e.total())).is_ok());
        let err = e.check(&MemoryLimit::explicit(e.total() - 1)).unwrap_err();
        assert!(err.contains("above the limit of") && err.contains("--max-memory"), "{err}");
        let huge = estimate(&scene, Backend::Cpu, 16384, 16384, 0);
        let err = huge.check(&MemoryLimit::explicit(8 << 30)).unwrap_err();
        // Frame 40 GiB; with the prepared scene the fallback buffers, 9 GiB (36 bytes a pixel),
        // and the see-through layer for the glass cube, 65 GiB (2.25 × 16384² pixels of a
        // G-buffer and its lighting).
        assert!(err.contains("frame 40.00 GiB") && err.contains("8.00 GiB (--max-memory)") && err.contains("--max-memory 115GiB"), "{err}");
        let err = frame_only(16384, 16384, 0).check(&MemoryLimit::explicit(8 << 30)).unwrap_err();
        assert!(err.starts_with("this render's frame alone needs about 40.06 GiB"), "{err}");
    }
}
