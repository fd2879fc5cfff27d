//! Paper 2 (design §5): the depth merge of a ray-traced RT-scene into the raster frame.
//!
//! - Block D ([`synthesize_depth`], [`synthesize_depth_orthographic`]): the reversed-Z window depth
//!   the rasterizer would write for the point at parameter `t` along a pixel's primary ray.
//! - Block P ([`pack_texel`], [`encode_hit`]): colour (sRGB-encoded, `packUnorm4x8`) and the depth's
//!   bits in one RGBA16UI texel.
//! - Block U ([`unpack`], [`decode_texel`]): back to linear colour and depth; alpha ≤ 0.1 is
//!   discarded (depth 0 = nothing drawn).
//!
//! Backend-free: the GPU backend mirrors these functions in WGSL (`pack4x8unorm` rounds as
//! [`pack_unorm4x8`] does: `floor(0.5 + 255·clamp(c, 0, 1))`).

use glam::Vec3;
use hybrid_scene::texture::srgb_byte_to_linear;

use crate::blend::encode_srgb_channel;
use serde::Serialize;

use crate::buffers::RtLayer;

/// Alpha at or below this is discarded by block U (the paper's `glAlphaFunc(GL_GREATER, 0.1)`).
pub const ALPHA_DISCARD: f32 = 0.1;

/// GLSL `packUnorm4x8` / WGSL `pack4x8unorm`: each component clamped to [0, 1], scaled by 255 and
/// rounded to nearest (halves up); `c[0]` lands in the low byte. NaN packs as 0.
#[inline]
pub fn pack_unorm4x8(c: [f32; 4]) -> u32 {
    let q = |v: f32| -> u32 {
        // NaN stays NaN through `clamp` and casts to 0.
        (0.5 + 255.0 * v.clamp(0.0, 1.0)).floor() as u32
    };
    q(c[0]) | (q(c[1]) << 8) | (q(c[2]) << 16) | (q(c[3]) << 24)
}

/// GLSL `unpackUnorm4x8`: byte / 255, low byte first.
#[inline]
pub fn unpack_unorm4x8(a: u32) -> [f32; 4] {
    std::array::from_fn(|i| ((a >> (8 * i)) & 0xFF) as f32 / 255.0)
}

/// The four 8-bit channels of a packed colour word, low byte first.
#[inline]
pub fn unorm4x8_bytes(a: u32) -> [u8; 4] {
    a.to_le_bytes()
}

/// Block P (paper Fig. 3): `A` = the colour bytes (r in the low byte), `B` = the bits of the
/// depth; texel = (A & 0xFFFF, A >> 16, B & 0xFFFF, B >> 16).
#[inline]
pub fn pack_texel(rgba8: [u8; 4], depth: f32) -> [u16; 4] {
    let a = u32::from_le_bytes(rgba8);
    let b = depth.to_bits();
    [(a & 0xFFFF) as u16, (a >> 16) as u16, (b & 0xFFFF) as u16, (b >> 16) as u16]
}

/// Inverse of [`pack_texel`], bit-exact: (A, B) = (r | g << 16, b | a << 16).
#[inline]
pub fn unpack_texel(t: [u16; 4]) -> ([u8; 4], f32) {
    let a = t[0] as u32 | ((t[1] as u32) << 16);
    let b = t[2] as u32 | ((t[3] as u32) << 16);
    (a.to_le_bytes(), f32::from_bits(b))
}

/// Block P for one hit: linear colour → sRGB-encoded 8-bit (8 bits keep the darks that way),
/// alpha 1, with the reversed-Z depth.
#[inline]
pub fn encode_hit(linear: Vec3, depth: f32) -> [u16; 4] {
    pack_texel([srgb_unorm8(linear.x), srgb_unorm8(linear.y), srgb_unorm8(linear.z), 255], depth)
}

/// One colour byte of [`encode_hit`]: `packUnorm4x8`'s `⌊0.5 + 255·linear_to_srgb(v)⌋`, which for
/// every finite or NaN `v` is the blend's [`encode_srgb_channel`] (the same operations), taken from
/// its exact tables instead of a `powf`; +infinity clamps to 255 here (the blend counts it as 0).
#[inline]
fn srgb_unorm8(v: f32) -> u8 {
    if v == f32::INFINITY { 255 } else { encode_srgb_channel(v) }
}

/// The texel of a pixel whose ray hit nothing: all zero (alpha 0 → discarded).
pub const MISS_TEXEL: [u16; 4] = [0; 4];

/// Whether block U keeps a fragment of this alpha (`alpha > 0.1`).
#[inline]
pub fn alpha_kept(alpha: f32) -> bool {
    alpha > ALPHA_DISCARD
}

/// Block U for one texel: `Some((linear colour, depth))`, or `None` where alpha ≤ 0.1.
#[inline]
pub fn decode_texel(t: [u16; 4]) -> Option<(Vec3, f32)> {
    let (rgba, depth) = unpack_texel(t);
    let alpha = rgba[3] as f32 / 255.0;
    if !alpha_kept(alpha) {
        return None;
    }
    let lin = srgb_byte_to_linear;
    Some((Vec3::new(lin(rgba[0]), lin(rgba[1]), lin(rgba[2])), depth))
}

/// The capsule's output: one RGBA16UI texel per pixel, row-major, row 0 at the top
/// (the wgpu texture's layout). A miss is all zero.
#[derive(Debug, Clone, PartialEq)]
pub struct PackedRtFrame {
    pub width: u32,
    pub height: u32,
    pub texels: Vec<[u16; 4]>,
}

impl PackedRtFrame {
    /// A frame of misses.
    pub fn new(width: u32, height: u32) -> Self {
        Self { width, height, texels: vec![MISS_TEXEL; width as usize * height as usize] }
    }

    /// Resizes to `width × height` and clears every texel to a miss (keeps the allocation).
    pub fn reset(&mut self, width: u32, height: u32) {
        self.width = width;
        self.height = height;
        self.texels.clear();
        self.texels.resize(width as usize * height as usize, MISS_TEXEL);
    }

    /// The frame as 16-bit RGBA samples (e.g. for a 16-bit PNG dump), row-major.
    pub fn as_u16_samples(&self) -> Vec<u16> {
        self.texels.iter().flatten().copied().collect()
    }
}

/// Block U on the CPU: the unpacked RT layer (linear colour, reversed-Z depth; depth 0 where
/// alpha ≤ 0.1 was discarded).
pub fn unpack(frame: &PackedRtFrame) -> RtLayer {
    let mut layer = RtLayer::new(frame.width, frame.height);
    unpack_into(&frame.texels, &mut layer.color, &mut layer.depth);
    layer
}

/// Block U over a run of texels into the matching run of an [`RtLayer`] (for a caller that
/// splits the frame into parallel parts, or reuses a layer): every pixel is written, discarded
/// texels as colour 0 and depth 0.
pub fn unpack_into(texels: &[[u16; 4]], color: &mut [Vec3], depth: &mut [f32]) {
    for ((t, c), d) in texels.iter().zip(color).zip(depth) {
        (*c, *d) = decode_texel(*t).unwrap_or((Vec3::ZERO, 0.0));
    }
}

/// Block D, perspective, reversed-Z: `t` is the hit parameter along a ray from the camera whose
/// unit direction has view-space z `dir_view_z` (< 0 looking forward). `z_e = t·d_z` and
/// `z_w = n·f/((f − n)·(−z_e)) − n/(f − n)`, evaluated as `n·(f + z_e)/((f − n)·(−z_e))`, which
/// is the same quantity without the cancellation near the far plane.
#[inline]
pub fn synthesize_depth(t: f32, dir_view_z: f32, near: f32, far: f32) -> f32 {
    let z_e = t * dir_view_z;
    near * (far + z_e) / ((far - near) * -z_e)
}

/// Block D, orthographic, reversed-Z: rays start in the camera plane (view z = 0), so
/// `z_e = t·d_z` and `z_w = (f + z_e)/(f − n)`.
#[inline]
pub fn synthesize_depth_orthographic(t: f32, dir_view_z: f32, near: f32, far: f32) -> f32 {
    let z_e = t * dir_view_z;
    (far + z_e) / (far - near)
}

/// Inverse of block D (perspective): the view-space z of a reversed-Z depth `z_w` > 0,
/// `z_e = −n·f/((f − n)·z_w + n)`.
#[inline]
pub fn view_z_from_depth(z_w: f32, near: f32, far: f32) -> f32 {
    -near * far / ((far - near) * z_w + near)
}

/// Inverse of block D (orthographic): `z_e = z_w·(f − n) − f`.
#[inline]
pub fn view_z_from_depth_orthographic(z_w: f32, near: f32, far: f32) -> f32 {
    z_w * (far - near) - far
}

/// What one capsule frame cost (design §5; written to the frame report).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct CapsuleStats {
    /// Spheres in the RT-scene.
    pub points: u64,
    /// Time to build the sphere BVH(s) (the capsule's set-up; the same every frame).
    pub build_ms: f64,
    /// Ray generation + tracing + shading + block D of this frame.
    pub trace_ms: f64,
    /// Block P of this frame (when it is a separate pass; 0 when fused into the trace).
    pub pack_ms: f64,
    /// Primary rays traced (pixels).
    pub rays: u64,
    /// Rays that hit a sphere.
    pub hits: u64,
    /// Bytes of the RT-scene's acceleration structure and sphere data.
    pub bytes: u64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hit_colour_bytes_equal_pack_unorm4x8_of_srgb() {
        let definition = |v: f32| {
            let s = hybrid_scene::texture::linear_to_srgb(v);
            pack_unorm4x8([s, s, s, 1.0]).to_le_bytes()
        };
        let check = |v: f32| {
            let got = unpack_texel(encode_hit(Vec3::splat(v), 0.5)).0;
            assert_eq!(got, definition(v), "{v:e} ({:#x})", v.to_bits());
        };
        // Every 7th bit pattern of [0, 1] (150 million values; the blend's tables are tested on
        // all of them), and the values outside.
        (0..=1.0f32.to_bits()).step_by(7).for_each(|b| check(f32::from_bits(b)));
        for v in [-0.0, -1.0, 1.5, 1e30, f32::MAX, f32::NAN, -f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 0.003_130_8] {
            check(v);
        }
    }

    #[test]
    fn pack_unorm_rounds_to_nearest_and_clamps() {
        assert_eq!(pack_unorm4x8([0.0, 1.0, 0.5, 2.0]), 0xFF_80_FF_00);
        assert_eq!(pack_unorm4x8([-1.0, f32::NAN, 1.0 / 255.0, 0.499 / 255.0]), 0x00_01_00_00);
        assert_eq!(unpack_unorm4x8(0xFF_80_FF_00), [0.0, 1.0, 128.0 / 255.0, 1.0]);
        for b in 0..=255u32 {
            let v = b as f32 / 255.0;
            assert_eq!(pack_unorm4x8([v, v, v, v]), b * 0x0101_0101);
        }
    }

    #[test]
    fn texel_layout_matches_the_paper() {
        let t = pack_texel([0x11, 0x22, 0x33, 0x44], f32::from_bits(0xAABB_CCDD));
        assert_eq!(t, [0x2211, 0x4433, 0xCCDD, 0xAABB]);
        assert_eq!(unpack_texel(t), ([0x11, 0x22, 0x33, 0x44], f32::from_bits(0xAABB_CCDD)));
    }

    #[test]
    fn miss_is_discarded_hit_is_kept() {
        assert_eq!(decode_texel(MISS_TEXEL), None);
        let (c, d) = decode_texel(encode_hit(Vec3::new(0.2, 0.5, 0.9), 0.25)).unwrap();
        assert_eq!(d, 0.25);
        assert!((c - Vec3::new(0.2, 0.5, 0.9)).abs().max_element() < 0.01, "{c}");
    }

    #[test]
    fn depth_inverse_round_trips() {
        let (n, f) = (0.1, 100.0);
        for z_e in [-0.1f32, -1.0, -33.0, -99.0] {
            let zw = synthesize_depth(-z_e, -1.0, n, f);
            assert!((view_z_from_depth(zw, n, f) - z_e).abs() <= 1e-4 * -z_e);
            let zo = synthesize_depth_orthographic(-z_e, -1.0, n, f);
            assert!((view_z_from_depth_orthographic(zo, n, f) - z_e).abs() <= 1e-4 * -z_e);
        }
    }
}
