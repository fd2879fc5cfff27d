//! `buffer_view`: every buffer of a frame as a viewable 8-bit RGBA image — the PNGs `--dump`
//! writes (the paper's Figures 2, 3, 5) and the viewer's buffer view show the same pixels.
//!
//! Colour buffers are sRGB-encoded; vectors are mapped to [0, 1] (positions over the bounds of
//! what is covered, normals as `n * 0.5 + 0.5`); depths are stretched over the covered range
//! (reversed-Z: near is bright); the mask is red where ray traced; object ids get a false colour
//! per id.

use glam::Vec3;

use crate::blend::encode_srgb;
use crate::depth_merge::{PackedRtFrame, unorm4x8_bytes};
use crate::{FrameBuffers, GBuffer, NO_OBJECT, RT_SCENE_OBJECT};

/// One viewable buffer. [`BufferKind::name`] is its file name in `--dump` (without extension).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum BufferKind {
    Final,
    Position,
    Normal,
    Emission,
    Ambient,
    Diffuse,
    Specular,
    Optical,
    Mask,
    Depth,
    Lighting,
    Shadow,
    Reflection,
    Refraction,
    /// Issue 18: the raster fallbacks' terms (frames with fallbacks).
    ShadowFallback,
    ReflectionFallback,
    RefractionFallback,
    /// Object ids in false colour (the dump's `object_id.png` holds the ids themselves).
    ObjectId,
    /// Paper 2: the packed RT frame's colour (scenes with point clouds).
    RtColor,
    /// Paper 2: the packed RT frame's synthesized depth.
    RtDepth,
    /// Paper 2: the depth after the merge (the G-buffer's depth, with the RT layer in it).
    MergedDepth,
}

impl BufferKind {
    /// Every buffer, in the order the viewer lists them.
    pub const ALL: [BufferKind; 21] = [
        BufferKind::Final,
        BufferKind::Position,
        BufferKind::Normal,
        BufferKind::Emission,
        BufferKind::Ambient,
        BufferKind::Diffuse,
        BufferKind::Specular,
        BufferKind::Optical,
        BufferKind::Mask,
        BufferKind::Depth,
        BufferKind::Lighting,
        BufferKind::Shadow,
        BufferKind::Reflection,
        BufferKind::Refraction,
        BufferKind::ShadowFallback,
        BufferKind::ReflectionFallback,
        BufferKind::RefractionFallback,
        BufferKind::ObjectId,
        BufferKind::RtColor,
        BufferKind::RtDepth,
        BufferKind::MergedDepth,
    ];

    pub fn name(self) -> &'static str {
        match self {
            BufferKind::Final => "final",
            BufferKind::Position => "position",
            BufferKind::Normal => "normal",
            BufferKind::Emission => "emission",
            BufferKind::Ambient => "ambient",
            BufferKind::Diffuse => "diffuse",
            BufferKind::Specular => "specular",
            BufferKind::Optical => "optical",
            BufferKind::Mask => "mask",
            BufferKind::Depth => "depth",
            BufferKind::Lighting => "lighting",
            BufferKind::Shadow => "shadow",
            BufferKind::Reflection => "reflection",
            BufferKind::Refraction => "refraction",
            BufferKind::ShadowFallback => "shadow_fallback",
            BufferKind::ReflectionFallback => "reflection_fallback",
            BufferKind::RefractionFallback => "refraction_fallback",
            BufferKind::ObjectId => "object_id",
            BufferKind::RtColor => "rt_color",
            BufferKind::RtDepth => "rt_depth",
            BufferKind::MergedDepth => "merged_depth",
        }
    }

    /// The buffer named `name` ([`BufferKind::name`]), if any.
    pub fn from_name(name: &str) -> Option<BufferKind> {
        BufferKind::ALL.into_iter().find(|k| k.name() == name)
    }

    /// Only frames of scenes with point clouds have it.
    pub fn needs_point_clouds(self) -> bool {
        matches!(self, BufferKind::RtColor | BufferKind::RtDepth | BufferKind::MergedDepth)
    }

    /// Only frames with raster fallbacks (`--fallback raster`, not `rt-only`) have it.
    pub fn needs_fallback(self) -> bool {
        matches!(self, BufferKind::ShadowFallback | BufferKind::ReflectionFallback | BufferKind::RefractionFallback)
    }
}

/// A frame's buffers, as handed to [`view`].
pub struct FrameView<'a> {
    pub gbuffer: &'a GBuffer,
    pub buffers: &'a FrameBuffers,
    /// The capsule's packed frame, when the scene has point clouds.
    pub rt_packed: Option<&'a PackedRtFrame>,
}

/// An 8-bit RGBA image of one buffer.
pub struct BufferImage {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<[u8; 4]>,
}

fn grey(v: f32) -> [u8; 4] {
    let b = (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
    [b, b, b, 255]
}

fn unit_to_rgba(v: Vec3) -> [u8; 4] {
    let c = |x: f32| (x.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
    [c(v.x), c(v.y), c(v.z), 255]
}

fn srgb(v: &[Vec3]) -> Vec<[u8; 4]> {
    v.iter().map(|c| encode_srgb(*c)).collect()
}

/// Reversed-Z depth (0 = nothing) stretched over the covered range: near bright, nothing black.
pub fn depth_to_rgba(depth: &[f32]) -> Vec<[u8; 4]> {
    let (dmin, dmax) = depth.iter().filter(|&&z| z > 0.0).fold((f32::INFINITY, 0.0f32), |(a, b), &z| (a.min(z), b.max(z)));
    let dspan = (dmax - dmin).max(1e-12);
    depth.iter().map(|&z| if z > 0.0 { grey(0.1 + 0.9 * (z - dmin) / dspan) } else { grey(0.0) }).collect()
}

/// A distinct, stable colour per object id (black: no object; white: the RT-scene).
pub fn object_id_color(id: u32) -> [u8; 4] {
    match id {
        NO_OBJECT => [0, 0, 0, 255],
        RT_SCENE_OBJECT => [255, 255, 255, 255],
        id => {
            // Golden-ratio hue steps keep neighbouring ids apart; saturation and value vary a
            // little with the id so that ids far apart in the sequence differ too.
            let hue = (id as f32 * 0.618_034).fract();
            let sat = 0.55 + 0.35 * ((id / 7) % 2) as f32;
            let val = 0.95 - 0.25 * ((id / 3) % 2) as f32;
            let rgb = hsv_to_rgb(hue, sat, val);
            unit_to_rgba(rgb)
        }
    }
}

fn hsv_to_rgb(h: f32, s: f32, v: f32) -> Vec3 {
    let i = (h * 6.0).floor();
    let f = h * 6.0 - i;
    let (p, q, t) = (v * (1.0 - s), v * (1.0 - f * s), v * (1.0 - (1.0 - f) * s));
    match i as i32 % 6 {
        0 => Vec3::new(v, t, p),
        1 => Vec3::new(q, v, p),
        2 => Vec3::new(p, v, t),
        3 => Vec3::new(p, q, v),
        4 => Vec3::new(t, p, v),
        _ => Vec3::new(v, p, q),
    }
}

/// The image of buffer `kind`; `None` for the point-cloud buffers of a frame without them.
pub fn view(kind: BufferKind, f: &FrameView) -> Option<BufferImage> {
    let g = f.gbuffer;
    let b = f.buffers;
    let covered = |i: usize| g.object_id[i] != NO_OBJECT;
    let full = |pixels: Vec<[u8; 4]>| Some(BufferImage { width: g.width, height: g.height, pixels });
    match kind {
        BufferKind::Final => full(b.final_srgb.clone()),
        BufferKind::Position => {
            // World coordinates normalised to the bounds of what is covered (Fig. 2a).
            let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
            for i in (0..g.len()).filter(|&i| covered(i)) {
                lo = lo.min(g.position[i]);
                hi = hi.max(g.position[i]);
            }
            let span = (hi - lo).max(Vec3::splat(1e-6));
            full((0..g.len()).map(|i| if covered(i) { unit_to_rgba((g.position[i] - lo) / span) } else { [0, 0, 0, 255] }).collect())
        }
        // [-1, 1] → [0, 1] as the paper stores it; black where nothing is drawn.
        BufferKind::Normal => {
            full((0..g.len()).map(|i| if covered(i) { unit_to_rgba(g.normal[i] * 0.5 + 0.5) } else { [0, 0, 0, 255] }).collect())
        }
        BufferKind::Emission => full(srgb(&g.emission)),
        BufferKind::Ambient => full(srgb(&g.ambient)),
        BufferKind::Diffuse => full(g.diffuse.iter().map(|v| encode_srgb(v.truncate())).collect()),
        BufferKind::Specular => full(g.specular.iter().map(|v| encode_srgb(v.truncate())).collect()),
        // R reflectivity, G (IOR − 1)/2 (so 1..3 fits), B opacity.
        BufferKind::Optical => full(g.optical.iter().map(|o| unit_to_rgba(Vec3::new(o.x, (o.y - 1.0) * 0.5, o.z))).collect()),
        // Red where ray traced, as in the paper's Figure 2h.
        BufferKind::Mask => full(g.mask.iter().map(|&m| if m > 0.0 { [255, 0, 0, 255] } else { [0, 0, 0, 255] }).collect()),
        BufferKind::Depth => full(depth_to_rgba(&g.depth)),
        BufferKind::Lighting => full(srgb(&b.lighting)),
        BufferKind::Shadow => full(srgb(&b.shadow)),
        BufferKind::Reflection => full(srgb(&b.reflection)),
        BufferKind::Refraction => full(srgb(&b.refraction)),
        BufferKind::ShadowFallback => (!b.shadow_fallback.is_empty()).then(|| full(srgb(&b.shadow_fallback))).flatten(),
        BufferKind::ReflectionFallback => (!b.reflection_fallback.is_empty()).then(|| full(srgb(&b.reflection_fallback))).flatten(),
        BufferKind::RefractionFallback => (!b.refraction_fallback.is_empty()).then(|| full(srgb(&b.refraction_fallback))).flatten(),
        BufferKind::ObjectId => full(g.object_id.iter().map(|&id| object_id_color(id)).collect()),
        BufferKind::RtColor => f.rt_packed.map(|rt| BufferImage {
            width: rt.width,
            height: rt.height,
            // The colour bytes exactly as packed (sRGB-encoded, alpha 0 on misses).
            pixels: rt.texels.iter().map(|t| unorm4x8_bytes(t[0] as u32 | (t[1] as u32) << 16)).collect(),
        }),
        BufferKind::RtDepth => {
            f.rt_packed.map(|rt| BufferImage { width: rt.width, height: rt.height, pixels: depth_to_rgba(&rt_depth(rt)) })
        }
        BufferKind::MergedDepth => f.rt_packed.and_then(|_| full(depth_to_rgba(&g.depth))),
    }
}

/// The packed frame's synthesized depth, exactly the packed bits.
pub fn rt_depth(rt: &PackedRtFrame) -> Vec<f32> {
    rt.texels.iter().map(|t| f32::from_bits(t[2] as u32 | (t[3] as u32) << 16)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_are_unique() {
        for k in BufferKind::ALL {
            assert_eq!(BufferKind::from_name(k.name()), Some(k));
        }
        let mut names: Vec<_> = BufferKind::ALL.iter().map(|k| k.name()).collect();
        names.sort();
        names.dedup();
        assert_eq!(names.len(), BufferKind::ALL.len());
    }

    #[test]
    fn depth_is_stretched_over_the_covered_range() {
        // Nothing → black; the farthest covered depth → 0.1 grey (26); the nearest → white.
        let px = depth_to_rgba(&[0.0, 0.2, 0.6, 0.4]);
        assert_eq!(px[0], [0, 0, 0, 255]);
        assert_eq!(px[1], [26, 26, 26, 255]);
        assert_eq!(px[2], [255, 255, 255, 255]);
        // 0.4 is halfway: 0.1 + 0.9 * 0.5 = 0.55 → 140.
        assert_eq!(px[3], [140, 140, 140, 255]);
    }

    #[test]
    fn object_colours_are_distinct_for_neighbouring_ids() {
        assert_eq!(object_id_color(NO_OBJECT), [0, 0, 0, 255]);
        assert_eq!(object_id_color(RT_SCENE_OBJECT), [255, 255, 255, 255]);
        for id in 0..64 {
            assert_ne!(object_id_color(id), object_id_color(id + 1), "ids {id} and {}", id + 1);
            assert_ne!(object_id_color(id), [0, 0, 0, 255]);
        }
    }

    #[test]
    fn point_cloud_buffers_need_a_packed_frame() {
        let g = GBuffer::new(2, 1);
        let b = FrameBuffers::new(2, 1);
        let f = FrameView { gbuffer: &g, buffers: &b, rt_packed: None };
        for k in BufferKind::ALL {
            assert_eq!(view(k, &f).is_some(), !k.needs_point_clouds() && !k.needs_fallback(), "{}", k.name());
        }
        let with = FrameBuffers {
            shadow_fallback: vec![Vec3::ONE; 2],
            reflection_fallback: vec![Vec3::ZERO; 2],
            refraction_fallback: vec![Vec3::ZERO; 2],
            ..b
        };
        let f = FrameView { gbuffer: &g, buffers: &with, rt_packed: None };
        for k in BufferKind::ALL {
            assert_eq!(view(k, &f).is_some(), !k.needs_point_clouds(), "{}", k.name());
        }
    }
}
