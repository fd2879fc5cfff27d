//! Stage 4, `blend` (paper listing 10, eq. 4–6): lighting, shadow, reflection and refraction
//! combined under the mask and the optical properties, then sRGB-encoded.

use glam::Vec3;
use hybrid_core::GBuffer;
use hybrid_core::blend::{blend_pixel_with_fallback, encode_srgb};
use rayon::prelude::*;

/// Inputs: the P-buffer (`lighting`), the trace outputs and the G-buffer's optical + mask
/// targets. Output: the final 8-bit sRGB image.
pub fn blend(gbuffer: &GBuffer, lighting: &[Vec3], shadow: &[Vec3], reflection: &[Vec3], refraction: &[Vec3]) -> Vec<[u8; 4]> {
    let mut out = Vec::new();
    blend_into(gbuffer, lighting, [shadow, reflection, refraction], None, &mut out);
    out
}

/// [`blend`] into `out` (resized to the G-buffer; every pixel written), reusing its memory, with
/// the raster fallbacks' `[shadow, reflection, refraction]` for the polygon pixels the trace
/// stage left out (`None`: those pixels keep their lighting, as in the paper).
pub fn blend_into(gbuffer: &GBuffer, lighting: &[Vec3], traced: [&[Vec3]; 3], fallback: Option<[&[Vec3]; 3]>, out: &mut Vec<[u8; 4]>) {
    out.resize(gbuffer.len(), [0; 4]);
    let fallback = fallback.filter(|f| f.iter().all(|b| b.len() == gbuffer.len()));
    out.par_iter_mut().enumerate().with_min_len(4096).for_each(|(i, px)| {
        let t = [traced[0][i], traced[1][i], traced[2][i]];
        let f = fallback.map(|f| [f[0][i], f[1][i], f[2][i]]);
        *px = encode_srgb(blend_pixel_with_fallback(lighting[i], t, f, gbuffer.object_id[i], gbuffer.optical[i], gbuffer.mask[i]));
    });
}
