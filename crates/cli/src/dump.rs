//! `--dump DIR`: every buffer of a frame as a viewable PNG (the paper's Figures 2, 3, 5), float
//! buffers also as EXR, the object ids as a 16-bit PNG, and the packed RT frame of paper 2.

use std::path::Path;

use glam::Vec3;
use hybrid_core::blend::encode_srgb;
use hybrid_core::depth_merge::{PackedRtFrame, unorm4x8_bytes};
use hybrid_core::{FrameBuffers, GBuffer, NO_OBJECT, RT_SCENE_OBJECT};

use crate::CliError;
use crate::output::{write_exr, write_png_rgba8, write_png16};

/// What a frame hands to the dump.
pub struct DumpInput<'a> {
    pub gbuffer: &'a GBuffer,
    pub buffers: &'a FrameBuffers,
    /// The capsule's packed frame, when the scene has point clouds.
    pub rt_packed: Option<&'a PackedRtFrame>,
}

fn grey(v: f32) -> [u8; 4] {
    let b = (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
    [b, b, b, 255]
}

fn unit_to_rgba(v: Vec3) -> [u8; 4] {
    let c = |x: f32| (x.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
    [c(v.x), c(v.y), c(v.z), 255]
}

fn xyz(v: &[Vec3]) -> [(&'static str, Vec<f32>); 3] {
    [("R", v.iter().map(|c| c.x).collect()), ("G", v.iter().map(|c| c.y).collect()), ("B", v.iter().map(|c| c.z).collect())]
}

/// Writes all buffers into `dir` (which must exist and be writable).
pub fn write_all(dir: &Path, d: &DumpInput) -> Result<(), CliError> {
    let g = d.gbuffer;
    let (w, h) = (g.width, g.height);
    let covered = |i: usize| g.object_id[i] != NO_OBJECT;
    let png = |name: &str, px: Vec<[u8; 4]>| write_png_rgba8(&dir.join(format!("{name}.png")), w, h, &px);
    let exr3 = |name: &str, v: &[Vec3]| write_exr(&dir.join(format!("{name}.exr")), w, h, &xyz(v));
    let exr1 = |name: &str, v: Vec<f32>| write_exr(&dir.join(format!("{name}.exr")), w, h, &[("Y", v)]);
    let srgb = |v: &[Vec3]| -> Vec<[u8; 4]> { v.iter().map(|c| encode_srgb(*c)).collect() };

    // Position: world coordinates normalised to the bounds of what is covered (Fig. 2a).
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for i in (0..g.len()).filter(|&i| covered(i)) {
        lo = lo.min(g.position[i]);
        hi = hi.max(g.position[i]);
    }
    let span = (hi - lo).max(Vec3::splat(1e-6));
    png("position", (0..g.len()).map(|i| if covered(i) { unit_to_rgba((g.position[i] - lo) / span) } else { [0, 0, 0, 255] }).collect())?;
    exr3("position", &g.position)?;
    // Normal: [-1, 1] → [0, 1] as the paper stores it; black where nothing is drawn.
    png("normal", (0..g.len()).map(|i| if covered(i) { unit_to_rgba(g.normal[i] * 0.5 + 0.5) } else { [0, 0, 0, 255] }).collect())?;
    exr3("normal", &g.normal)?;
    png("emission", srgb(&g.emission))?;
    png("ambient", srgb(&g.ambient))?;
    let diffuse: Vec<Vec3> = g.diffuse.iter().map(|v| v.truncate()).collect();
    png("diffuse", srgb(&diffuse))?;
    let specular: Vec<Vec3> = g.specular.iter().map(|v| v.truncate()).collect();
    png("specular", srgb(&specular))?;
    // Optical: R reflectivity, G (IOR − 1)/2 (so 1..3 fits), B opacity.
    png("optical", g.optical.iter().map(|o| unit_to_rgba(Vec3::new(o.x, (o.y - 1.0) * 0.5, o.z))).collect())?;
    exr3("optical", &g.optical)?;
    // Mask: red where ray traced, as in the paper's Figure 2h.
    png("mask", g.mask.iter().map(|&m| if m > 0.0 { [255, 0, 0, 255] } else { [0, 0, 0, 255] }).collect())?;
    exr1("mask", g.mask.clone())?;
    // Depth: reversed-Z (near bright), stretched over the covered range for viewing.
    let (dmin, dmax) = g.depth.iter().filter(|&&z| z > 0.0).fold((f32::INFINITY, 0.0f32), |(a, b), &z| (a.min(z), b.max(z)));
    let dspan = (dmax - dmin).max(1e-12);
    png("depth", g.depth.iter().map(|&z| if z > 0.0 { grey(0.1 + 0.9 * (z - dmin) / dspan) } else { grey(0.0) }).collect())?;
    exr1("depth", g.depth.clone())?;
    let b = d.buffers;
    for (name, v) in [("lighting", &b.lighting), ("shadow", &b.shadow), ("reflection", &b.reflection), ("refraction", &b.refraction)] {
        png(name, srgb(v))?;
        exr3(name, v)?;
    }
    png("final", b.final_srgb.clone())?;
    // Object ids as 16-bit grey: id + 1, 0 = no object (the RT-scene shows as 65535).
    let ids: Vec<u16> = g
        .object_id
        .iter()
        .map(|&id| match id {
            NO_OBJECT => 0,
            RT_SCENE_OBJECT => u16::MAX,
            id => (id + 1).min(u16::MAX as u32 - 1) as u16,
        })
        .collect();
    write_png16(&dir.join("object_id.png"), w, h, 1, &ids)?;

    if let Some(rt) = d.rt_packed {
        // The packed texels verbatim (RGBA16UI as a 16-bit RGBA PNG).
        write_png16(&dir.join("rt_packed.png"), rt.width, rt.height, 4, &rt.as_u16_samples())?;
        // The colour bytes exactly as packed (sRGB-encoded, alpha 0 on misses).
        let color: Vec<[u8; 4]> = rt.texels.iter().map(|t| unorm4x8_bytes(t[0] as u32 | (t[1] as u32) << 16)).collect();
        write_png_rgba8(&dir.join("rt_color.png"), rt.width, rt.height, &color)?;
        // The synthesized depth, exactly the packed bits.
        let depth: Vec<f32> = rt.texels.iter().map(|t| f32::from_bits(t[2] as u32 | (t[3] as u32) << 16)).collect();
        write_exr(&dir.join("rt_depth.exr"), rt.width, rt.height, &[("Z", depth)])?;
        write_exr(&dir.join("merged_depth.exr"), w, h, &[("Z", g.depth.clone())])?;
    }
    Ok(())
}
