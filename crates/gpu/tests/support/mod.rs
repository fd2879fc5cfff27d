//! Shared by the GPU integration tests: buffers turned into 8-bit images and compared with FLIP.

#![allow(dead_code)]

use std::fmt;

use glam::Vec3;
use hybrid_core::blend::encode_srgb;
use hybrid_core::{Frame, GBuffer, NO_OBJECT};
use hybrid_gpu::{AdapterChoice, GpuContext};

/// The adapter the GPU tests run on (lavapipe in CI). No adapter fails the test, loudly.
pub fn context() -> GpuContext {
    match GpuContext::new(AdapterChoice::Any) {
        Ok(ctx) => {
            eprintln!("adapter: {} ({}, {})", ctx.summary.name, ctx.summary.backend, ctx.summary.device_type);
            ctx
        }
        Err(e) => panic!("these tests need a GPU adapter (lavapipe is enough): {e}"),
    }
}

/// Linear RGB → 8-bit sRGB exactly as the final image is encoded (clamped), row-major.
pub fn srgb8(values: &[Vec3]) -> Vec<u8> {
    values.iter().flat_map(|&c| encode_srgb(c)[..3].to_vec()).collect()
}

/// RGBA8 pixels → RGB bytes.
pub fn rgb8(image: &[[u8; 4]]) -> Vec<u8> {
    image.iter().flat_map(|p| [p[0], p[1], p[2]]).collect()
}

/// Values in [-1, 1] (normals) → 8-bit, 0.5 = 0.
pub fn signed8(values: &[Vec3]) -> Vec<u8> {
    values.iter().flat_map(|c| c.to_array().map(|x| ((x.clamp(-1.0, 1.0) * 0.5 + 0.5) * 255.0 + 0.5) as u8)).collect()
}

/// Mean FLIP between two 8-bit RGB images.
pub fn mean_flip(w: u32, h: u32, reference: &[u8], test: &[u8]) -> f32 {
    let a = nv_flip::FlipImageRgb8::with_data(w, h, reference);
    let b = nv_flip::FlipImageRgb8::with_data(w, h, test);
    let err = nv_flip::flip(a, b, nv_flip::DEFAULT_PIXELS_PER_DEGREE);
    nv_flip::FlipPool::from_image(&err).mean()
}

/// Mean FLIP of two linear RGB buffers shown as sRGB images.
pub fn mean_flip_linear(w: u32, h: u32, reference: &[Vec3], test: &[Vec3]) -> f32 {
    mean_flip(w, h, &srgb8(reference), &srgb8(test))
}

/// How a GPU frame differs from the CPU's, buffer by buffer.
#[derive(Debug, Default)]
pub struct BufferComparison {
    /// (buffer, mean FLIP) for every image-like buffer.
    pub flip: Vec<(&'static str, f32)>,
    pub object_id_mismatches: usize,
    pub mask_mismatches: usize,
    /// Largest depth difference where both backends drew the same object.
    pub max_depth_diff: f32,
    /// Pixels there whose world positions differ by more than 1e-3 relative (to the distance
    /// from the origin, at least 1): grazing surfaces, where a sub-pixel difference in where the
    /// pixel centre lands on the triangle moves the point far.
    pub position_outliers: usize,
}

impl fmt::Display for BufferComparison {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "ids differ {}, mask differs {}, max depth diff {:.2e}, position outliers {}; FLIP",
            self.object_id_mismatches, self.mask_mismatches, self.max_depth_diff, self.position_outliers
        )?;
        for (name, v) in &self.flip {
            write!(f, " {name} {v:.4}")?;
        }
        Ok(())
    }
}

fn gbuffer_flips(w: u32, h: u32, c: &GBuffer, g: &GBuffer, out: &mut Vec<(&'static str, f32)>) {
    let rgb = |v: &[glam::Vec4]| v.iter().map(|x| x.truncate()).collect::<Vec<_>>();
    out.push(("normal", mean_flip(w, h, &signed8(&c.normal), &signed8(&g.normal))));
    out.push(("emission", mean_flip_linear(w, h, &c.emission, &g.emission)));
    out.push(("ambient", mean_flip_linear(w, h, &c.ambient, &g.ambient)));
    out.push(("diffuse", mean_flip_linear(w, h, &rgb(&c.diffuse), &rgb(&g.diffuse))));
    out.push(("specular", mean_flip_linear(w, h, &rgb(&c.specular), &rgb(&g.specular))));
    // Reflectivity, IOR (÷ 3, into 0..1 for IORs up to 3) and opacity as an image.
    let optical = |v: &[Vec3]| v.iter().map(|o| Vec3::new(o.x, o.y / 3.0, o.z)).collect::<Vec<_>>();
    out.push(("optical", mean_flip_linear(w, h, &optical(&c.optical), &optical(&g.optical))));
}

/// Compares every buffer of two frames of the same size.
pub fn compare_frames(c: &Frame, g: &Frame) -> BufferComparison {
    let (w, h) = (c.settings.width, c.settings.height);
    let mut flip = Vec::new();
    gbuffer_flips(w, h, &c.gbuffer, &g.gbuffer, &mut flip);
    let b = (&c.buffers, &g.buffers);
    flip.push(("lighting", mean_flip_linear(w, h, &b.0.lighting, &b.1.lighting)));
    flip.push(("shadow", mean_flip_linear(w, h, &b.0.shadow, &b.1.shadow)));
    flip.push(("reflection", mean_flip_linear(w, h, &b.0.reflection, &b.1.reflection)));
    flip.push(("refraction", mean_flip_linear(w, h, &b.0.refraction, &b.1.refraction)));
    flip.push(("final", mean_flip(w, h, &rgb8(&b.0.final_srgb), &rgb8(&b.1.final_srgb))));
    let (cg, gg) = (&c.gbuffer, &g.gbuffer);
    let object_id_mismatches = cg.object_id.iter().zip(&gg.object_id).filter(|(a, b)| a != b).count();
    let mask_mismatches = cg.mask.iter().zip(&gg.mask).filter(|(a, b)| (**a > 0.0) != (**b > 0.0)).count();
    let same: Vec<usize> = (0..cg.len()).filter(|&i| cg.object_id[i] == gg.object_id[i] && cg.object_id[i] != NO_OBJECT).collect();
    let max_depth_diff = same.iter().map(|&i| (cg.depth[i] - gg.depth[i]).abs()).fold(0.0, f32::max);
    let position_outliers =
        same.iter().filter(|&&i| (cg.position[i] - gg.position[i]).length() > 1e-3 * cg.position[i].length().max(1.0)).count();
    BufferComparison { flip, object_id_mismatches, mask_mismatches, max_depth_diff, position_outliers }
}
