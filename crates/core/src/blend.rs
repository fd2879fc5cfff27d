//! The blend stage's formulas (paper listing 10, eq. 4–6) and the closest-hit combination of
//! listing 8c, which is the same average of eq. 5 and 6.

use glam::Vec3;

/// Eq. 5/6 averaged: reflection `m` with weight `reflectivity` (OM) and refraction `r` with
/// weight `transparency` (OR = 1 − opacity) over the base colour `c`.
///
/// CM = OM·M + (1 − OM)(OR·R + (1 − OR)·C);  CR = OR·R + (1 − OR)(OM·M + (1 − OM)·C);
/// result = (CM + CR) / 2.
#[inline]
pub fn combine(c: Vec3, m: Vec3, r: Vec3, reflectivity: f32, transparency: f32) -> Vec3 {
    let (om, or) = (reflectivity, transparency);
    let cm = om * m + (1.0 - om) * (or * r + (1.0 - or) * c);
    let cr = or * r + (1.0 - or) * (om * m + (1.0 - om) * c);
    (cm + cr) * 0.5
}

/// Eq. 4: lighting with shadows, C = L − (1 − S).
#[inline]
pub fn apply_shadow(lighting: Vec3, shadow: Vec3) -> Vec3 {
    lighting - (Vec3::ONE - shadow)
}

/// Threshold below which a mask value means "not traced" (listing 10: `heurVal < 0.0001`).
pub const MASK_EPSILON: f32 = 1e-4;

/// One pixel of the blend stage (listing 10), linear in, linear out (sRGB encoding follows).
/// `optical` is (reflectivity, IOR, opacity).
#[inline]
pub fn blend_pixel(lighting: Vec3, shadow: Vec3, reflection: Vec3, refraction: Vec3, optical: Vec3, mask: f32) -> Vec3 {
    if mask < MASK_EPSILON {
        return lighting;
    }
    let c = apply_shadow(lighting, shadow);
    combine(c, reflection, refraction, optical.x, 1.0 - optical.z)
}

/// [`blend_pixel`] with the raster fallbacks (issue 18): a polygon pixel the trace stage left
/// out (mask < ε) takes the fallback terms `[shadow, reflection, refraction]` instead, through
/// the same equations; without fallbacks (`None`) it stays the lighting, as in the paper.
#[inline]
pub fn blend_pixel_with_fallback(
    lighting: Vec3,
    traced: [Vec3; 3],
    fallback: Option<[Vec3; 3]>,
    object_id: u32,
    optical: Vec3,
    mask: f32,
) -> Vec3 {
    match fallback {
        Some([s, m, r]) if mask < MASK_EPSILON && crate::buffers::is_polygon(object_id) => blend_pixel(lighting, s, m, r, optical, 1.0),
        _ => blend_pixel(lighting, traced[0], traced[1], traced[2], optical, mask),
    }
}

/// Linear colour → 8-bit sRGB (the blend stage's gamma correction): each channel
/// `(linear_to_srgb(v) · 255 + 0.5)` truncated, non-finite values as 0, computed by
/// [`encode_srgb_channel`].
#[inline]
pub fn encode_srgb(c: Vec3) -> [u8; 4] {
    let t = srgb_encode_tables();
    [t.encode(c.x), t.encode(c.y), t.encode(c.z), 255]
}

/// The definition of one [`encode_srgb`] channel, with a `powf` per call.
#[inline]
fn encode_srgb_channel_reference(v: f32) -> u8 {
    (hybrid_scene::texture::linear_to_srgb(if v.is_finite() { v } else { 0.0 }) * 255.0 + 0.5) as u8
}

/// Tables that give [`encode_srgb_channel_reference`] without `powf`.
struct SrgbEncodeTables {
    /// `first[k]`: bits of the smallest f32 in (0, 1) whose code is ≥ k (`first[0]` unused,
    /// `first[256]` = `u32::MAX`).
    first: [u32; 257],
    /// Code of the smallest f32 of each bucket of 2¹⁶ bit patterns (`bits >> 16`) below 1.0.
    bucket: Vec<u8>,
}

fn srgb_encode_tables() -> &'static SrgbEncodeTables {
    static TABLES: std::sync::OnceLock<SrgbEncodeTables> = std::sync::OnceLock::new();
    TABLES.get_or_init(|| {
        let code = |bits: u32| encode_srgb_channel_reference(f32::from_bits(bits));
        let one = 1.0f32.to_bits();
        // The code never decreases as the value grows (tested over all of [0, 1]), so each
        // threshold is found by bisection over the bit patterns (positive floats order as their bits).
        let first = std::array::from_fn(|k| {
            if k == 256 {
                return u32::MAX;
            }
            let (mut lo, mut hi) = (0u32, one);
            while lo < hi {
                let mid = lo + (hi - lo) / 2;
                if code(mid) as usize >= k { hi = mid } else { lo = mid + 1 }
            }
            lo
        });
        let bucket = (0..=one >> 16).map(|j| code(j << 16)).collect();
        SrgbEncodeTables { first, bucket }
    })
}

/// One channel of [`encode_srgb`]: exactly `(linear_to_srgb(v) · 255 + 0.5) as u8` (non-finite
/// values as 0), without its `powf`: a table gives the code at the start of the value's bucket of
/// 2¹⁶ float bit patterns, and one comparison with the next exact threshold finishes it (no
/// bucket spans two thresholds: the test over every f32 of [0, 1] would fail). The blend stage
/// encodes every pixel, and `powf` was most of its time.
#[inline]
pub fn encode_srgb_channel(v: f32) -> u8 {
    srgb_encode_tables().encode(v)
}

impl SrgbEncodeTables {
    /// [`encode_srgb_channel`], on the bits: positive floats order as their bits.
    #[inline]
    fn encode(&self, v: f32) -> u8 {
        const ONE: u32 = 0x3F80_0000;
        const INFINITY: u32 = 0x7F80_0000;
        let bits = v.to_bits();
        if bits as i32 <= 0 || bits >= INFINITY {
            // Zero, negative (the sign bit set), +infinity and NaN: non-finite values count as 0.
            0
        } else if bits >= ONE {
            255
        } else {
            let k = self.bucket[(bits >> 16) as usize];
            k + (bits >= self.first[k as usize + 1]) as u8
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).abs().max_element() < 1e-6
    }

    #[test]
    fn unmasked_pixels_are_the_lighting() {
        let l = Vec3::new(0.2, 0.4, 0.6);
        assert_eq!(blend_pixel(l, Vec3::ZERO, Vec3::ONE, Vec3::ONE, Vec3::new(1.0, 1.5, 0.0), 0.0), l);
    }

    #[test]
    fn opaque_diffuse_pixel_gets_only_its_shadow() {
        // OM = 0, OR = 0 → CM = CR = C = L − (1 − S).
        let l = Vec3::splat(0.8);
        let s = Vec3::splat(0.7); // 0.3 of light blocked
        let out = blend_pixel(l, s, Vec3::ONE, Vec3::ONE, Vec3::new(0.0, 1.0, 1.0), 1.0);
        assert!(close(out, Vec3::splat(0.5)), "{out}");
    }

    #[test]
    fn fallback_terms_apply_to_untraced_polygons_only() {
        let l = Vec3::splat(0.8);
        let traced = [Vec3::splat(0.9), Vec3::ZERO, Vec3::ZERO];
        let fb = Some([Vec3::splat(0.7), Vec3::ZERO, Vec3::ZERO]);
        let opaque = Vec3::new(0.0, 1.0, 1.0);
        // Untraced polygon: the fallback shadow, L − (1 − 0.7) = 0.5.
        assert!(close(blend_pixel_with_fallback(l, traced, fb, 3, opaque, 0.0), Vec3::splat(0.5)));
        // Traced: the traced shadow, 0.8 − 0.1.
        assert!(close(blend_pixel_with_fallback(l, traced, fb, 3, opaque, 1.0), Vec3::splat(0.7)));
        // Sky, the RT-scene, or no fallbacks: the lighting.
        assert_eq!(blend_pixel_with_fallback(l, traced, fb, crate::NO_OBJECT, opaque, 0.0), l);
        assert_eq!(blend_pixel_with_fallback(l, traced, fb, crate::RT_SCENE_OBJECT, opaque, 0.0), l);
        assert_eq!(blend_pixel_with_fallback(l, traced, None, 3, opaque, 0.0), l);
    }

    #[test]
    fn hand_computed_mixed_pixel() {
        // OM = 0.5, OR = 0.25, C = 0.4, M = 1.0, R = 0.2 (one channel):
        // CM = 0.5·1 + 0.5·(0.25·0.2 + 0.75·0.4) = 0.5 + 0.5·0.35 = 0.675
        // CR = 0.25·0.2 + 0.75·(0.5·1 + 0.5·0.4) = 0.05 + 0.75·0.7 = 0.575
        // final = 0.625
        let out = combine(Vec3::splat(0.4), Vec3::ONE, Vec3::splat(0.2), 0.5, 0.25);
        assert!(close(out, Vec3::splat(0.625)), "{out}");
        // The same through blend_pixel: L = 0.4, S = 1 (no shadow), opacity 0.75.
        let out = blend_pixel(Vec3::splat(0.4), Vec3::ONE, Vec3::ONE, Vec3::splat(0.2), Vec3::new(0.5, 1.5, 0.75), 1.0);
        assert!(close(out, Vec3::splat(0.625)));
    }

    #[test]
    fn perfect_mirror_and_perfect_glass() {
        let c = Vec3::splat(0.3);
        let m = Vec3::new(1.0, 0.0, 0.0);
        let r = Vec3::new(0.0, 0.0, 1.0);
        assert!(close(combine(c, m, r, 1.0, 0.0), m)); // mirror: CM = M, CR = M
        assert!(close(combine(c, m, r, 0.0, 1.0), r)); // glass: CM = R, CR = R
        // Both 1: CM = M, CR = R → average.
        assert!(close(combine(c, m, r, 1.0, 1.0), (m + r) * 0.5));
    }

    #[test]
    fn srgb_channel_tables_equal_the_definition() {
        // Every f32 in [0, 1] (about 3 s), and the values outside.
        for b in 0..=1.0f32.to_bits() {
            let v = f32::from_bits(b);
            assert_eq!(encode_srgb_channel(v), encode_srgb_channel_reference(v), "{v:e}");
        }
        for v in [-0.0, -1e-45, -1.0, 1.5, f32::MAX, f32::NAN, -f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            assert_eq!(encode_srgb_channel(v), encode_srgb_channel_reference(v), "{v:e}");
        }
    }

    #[test]
    fn srgb_encoding_hand_values() {
        assert_eq!(encode_srgb(Vec3::ZERO), [0, 0, 0, 255]);
        assert_eq!(encode_srgb(Vec3::ONE), [255, 255, 255, 255]);
        // sRGB code 128 decodes to 0.215861 linear; encoding it gives 128 back.
        assert_eq!(encode_srgb(Vec3::splat(0.215_861)), [128, 128, 128, 255]);
        assert_eq!(encode_srgb(Vec3::splat(f32::NAN)), [0, 0, 0, 255]);
    }
}
