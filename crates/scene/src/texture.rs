//! Textures: 8-bit RGBA with a full mip chain, decoded sRGB → linear when sampled (as a GPU's
//! `Rgba8UnormSrgb` does), so dark values keep their precision and GPU upload is a copy.

use std::sync::OnceLock;

use glam::{Vec2, Vec4};

/// Index into [`crate::Scene::textures`].
pub type TextureId = usize;

/// Whether texel values are sRGB-encoded colour or linear data (normal maps, optical maps).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ColorSpace {
    Srgb,
    Linear,
}

#[derive(Debug, Clone, PartialEq)]
pub struct MipLevel {
    pub width: u32,
    pub height: u32,
    /// Row-major RGBA8 texels, `width * height` of them.
    pub texels: Vec<[u8; 4]>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Texture {
    pub name: String,
    pub color_space: ColorSpace,
    /// Level 0 is the full image; each next level halves both sizes (min 1) down to 1×1.
    pub levels: Vec<MipLevel>,
}

/// sRGB transfer function, decode (IEC 61966-2-1).
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }
}

/// sRGB transfer function, encode.
pub fn linear_to_srgb(c: f32) -> f32 {
    let c = c.clamp(0.0, 1.0);
    if c <= 0.003_130_8 { c * 12.92 } else { 1.055 * c.powf(1.0 / 2.4) - 0.055 }
}

/// An sRGB-encoded byte decoded to linear: exactly `srgb_to_linear(b as f32 / 255.0)`, from a
/// table.
#[inline]
pub fn srgb_byte_to_linear(b: u8) -> f32 {
    srgb_lut()[b as usize]
}

fn srgb_lut() -> &'static [f32; 256] {
    static LUT: OnceLock<[f32; 256]> = OnceLock::new();
    LUT.get_or_init(|| std::array::from_fn(|i| srgb_to_linear(i as f32 / 255.0)))
}

impl Texture {
    /// Builds a texture from level-0 RGBA8 texels and generates the mip chain (2×2 box filter,
    /// averaged in linear space for sRGB textures).
    pub fn new(name: impl Into<String>, width: u32, height: u32, texels: Vec<[u8; 4]>, color_space: ColorSpace) -> Self {
        assert_eq!(texels.len(), (width as usize) * (height as usize), "texel count must be width*height");
        assert!(width > 0 && height > 0, "texture must not be empty");
        let mut levels = vec![MipLevel { width, height, texels }];
        while let Some(last) = levels.last() {
            if last.width == 1 && last.height == 1 {
                break;
            }
            let next = downsample(last, color_space);
            levels.push(next);
        }
        Self { name: name.into(), color_space, levels }
    }

    /// A 1×1 texture of one colour (sRGB bytes if `color_space` is sRGB).
    pub fn solid(name: impl Into<String>, rgba: [u8; 4], color_space: ColorSpace) -> Self {
        Self::new(name, 1, 1, vec![rgba], color_space)
    }

    pub fn width(&self) -> u32 {
        self.levels[0].width
    }
    pub fn height(&self) -> u32 {
        self.levels[0].height
    }

    /// Decoded texel (linear RGBA; alpha is always linear).
    #[inline]
    pub fn texel(&self, level: usize, x: u32, y: u32) -> Vec4 {
        let l = &self.levels[level];
        let t = l.texels[(y * l.width + x) as usize];
        match self.color_space {
            ColorSpace::Srgb => {
                let lut = srgb_lut();
                Vec4::new(lut[t[0] as usize], lut[t[1] as usize], lut[t[2] as usize], t[3] as f32 / 255.0)
            }
            ColorSpace::Linear => Vec4::new(t[0] as f32, t[1] as f32, t[2] as f32, t[3] as f32) / 255.0,
        }
    }

    /// Bilinear sample of one mip level with wrap-around (repeat) addressing. `uv` (0,0) is the
    /// top-left corner of the image.
    pub fn sample_bilinear(&self, uv: Vec2, level: usize) -> Vec4 {
        let level = level.min(self.levels.len() - 1);
        let l = &self.levels[level];
        if !uv.x.is_finite() || !uv.y.is_finite() {
            return self.texel(level, 0, 0);
        }
        // Repeat addressing: keep only the fractional part (cheap), then integer wrap of the
        // neighbour texel.
        let x = (uv.x - uv.x.floor()) * l.width as f32 - 0.5;
        let y = (uv.y - uv.y.floor()) * l.height as f32 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let wrap = |i: i64, n: u32| -> u32 {
            let n = n as i64;
            (if i < 0 {
                i + n
            } else if i >= n {
                i - n
            } else {
                i
            })
            .clamp(0, n - 1) as u32
        };
        let (ix0, iy0) = (wrap(x0 as i64, l.width), wrap(y0 as i64, l.height));
        let (ix1, iy1) = (wrap(x0 as i64 + 1, l.width), wrap(y0 as i64 + 1, l.height));
        let a = self.texel(level, ix0, iy0).lerp(self.texel(level, ix1, iy0), fx);
        let b = self.texel(level, ix0, iy1).lerp(self.texel(level, ix1, iy1), fx);
        a.lerp(b, fy)
    }

    /// Trilinear sample: `lod` is log2 of the texel footprint at level 0 (0 = full resolution).
    pub fn sample(&self, uv: Vec2, lod: f32) -> Vec4 {
        let max = (self.levels.len() - 1) as f32;
        let lod = if lod.is_finite() { lod.clamp(0.0, max) } else { 0.0 };
        let l0 = lod.floor();
        let f = lod - l0;
        let a = self.sample_bilinear(uv, l0 as usize);
        if f <= 1e-4 { a } else { a.lerp(self.sample_bilinear(uv, l0 as usize + 1), f) }
    }

    /// The level of detail for a UV footprint: `duv` is the change of UV per pixel (the larger
    /// of the screen-space derivatives' lengths).
    pub fn lod_for_footprint(&self, duv: f32) -> f32 {
        let texels = duv * self.width().max(self.height()) as f32;
        if texels <= 1.0 { 0.0 } else { texels.log2() }
    }
}

fn downsample(l: &MipLevel, cs: ColorSpace) -> MipLevel {
    let w = (l.width / 2).max(1);
    let h = (l.height / 2).max(1);
    let lut = srgb_lut();
    let mut texels = Vec::with_capacity((w * h) as usize);
    for y in 0..h {
        for x in 0..w {
            let mut acc = [0f32; 4];
            let mut n = 0.0;
            for dy in 0..2 {
                for dx in 0..2 {
                    let sx = (2 * x + dx).min(l.width - 1);
                    let sy = (2 * y + dy).min(l.height - 1);
                    let t = l.texels[(sy * l.width + sx) as usize];
                    for c in 0..4 {
                        acc[c] += if cs == ColorSpace::Srgb && c < 3 { lut[t[c] as usize] } else { t[c] as f32 / 255.0 };
                    }
                    n += 1.0;
                }
            }
            let px = std::array::from_fn(|c| {
                let v = acc[c] / n;
                let v = if cs == ColorSpace::Srgb && c < 3 { linear_to_srgb(v) } else { v };
                (v * 255.0 + 0.5).clamp(0.0, 255.0) as u8
            });
            texels.push(px);
        }
    }
    MipLevel { width: w, height: h, texels }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_roundtrip_and_known_values() {
        assert!((srgb_to_linear(0.5) - 0.214_041).abs() < 1e-5);
        assert!((linear_to_srgb(0.214_041) - 0.5).abs() < 1e-5);
        for i in 0..=255 {
            let v = i as f32 / 255.0;
            assert!((linear_to_srgb(srgb_to_linear(v)) - v).abs() < 1e-5);
        }
    }

    #[test]
    fn mip_chain_goes_to_one_texel_and_keeps_the_average() {
        let texels: Vec<[u8; 4]> = (0..8 * 4).map(|i| if i % 2 == 0 { [255, 255, 255, 255] } else { [0, 0, 0, 255] }).collect();
        let t = Texture::new("checker", 8, 4, texels, ColorSpace::Linear);
        assert_eq!(t.levels.len(), 4); // 8x4, 4x2, 2x1, 1x1
        assert_eq!((t.levels[3].width, t.levels[3].height), (1, 1));
        let avg = t.texel(3, 0, 0);
        assert!((avg.x - 0.5).abs() < 0.01, "{avg}");
    }

    #[test]
    fn bilinear_wraps_and_hits_texel_centres() {
        let t = Texture::new("2x1", 2, 1, vec![[0, 0, 0, 255], [255, 255, 255, 255]], ColorSpace::Linear);
        assert!((t.sample_bilinear(Vec2::new(0.25, 0.5), 0).x - 0.0).abs() < 1e-6);
        assert!((t.sample_bilinear(Vec2::new(0.75, 0.5), 0).x - 1.0).abs() < 1e-6);
        assert!((t.sample_bilinear(Vec2::new(0.5, 0.5), 0).x - 0.5).abs() < 1e-6);
        // Repeat addressing: 1.25 is the same as 0.25.
        assert!((t.sample_bilinear(Vec2::new(1.25, 0.5), 0).x - 0.0).abs() < 1e-6);
        assert!((t.sample_bilinear(Vec2::new(-0.75, 0.5), 0).x - 0.0).abs() < 1e-6);
        assert!((t.sample_bilinear(Vec2::new(-3.25, 0.5), 0).x - 1.0).abs() < 1e-6);
        // Between the last and the first texel (wraps around the edge).
        assert!((t.sample_bilinear(Vec2::new(0.0, 0.5), 0).x - 0.5).abs() < 1e-6);
        assert!(t.sample(Vec2::new(f32::NAN, 0.0), 0.0).is_finite());
    }
}
