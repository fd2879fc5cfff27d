//! `--dump DIR`: every buffer of a frame as a viewable PNG (the paper's Figures 2, 3, 5; the
//! images come from [`hybrid_core::buffer_view`], which the viewer's buffer view shows too),
//! float buffers also as EXR, the object ids as a 16-bit PNG, and the packed RT frame of paper 2.

use std::path::Path;

use glam::Vec3;
use hybrid_core::buffer_view::{self, BufferKind, FrameView};
use hybrid_core::fallback::LightShadowMaps;
use hybrid_core::{NO_OBJECT, RT_SCENE_OBJECT};

use crate::CliError;
use crate::output::{write_exr, write_png_rgba8, write_png16};

/// What a frame hands to the dump.
pub type DumpInput<'a> = FrameView<'a>;

fn xyz(v: &[Vec3]) -> [(&'static str, Vec<f32>); 3] {
    [("R", v.iter().map(|c| c.x).collect()), ("G", v.iter().map(|c| c.y).collect()), ("B", v.iter().map(|c| c.z).collect())]
}

/// Each light's shadow maps as `shadow_map_<light>.exr` (`<light>`: its index among the scene's
/// lights, directional first, then point, then spot), channel `Z` the reversed-Z depth (0: no
/// caster). A light with several maps (cascades nearest first, cube faces +X −X +Y −Y +Z −Z) has
/// them side by side, left to right.
pub fn write_shadow_maps(dir: &Path, maps: &[LightShadowMaps]) -> Result<(), CliError> {
    for light in maps {
        let h = light.maps.iter().map(|m| m.view.size).max().unwrap_or(0);
        let w: u32 = light.maps.iter().map(|m| m.view.size).sum();
        if w == 0 || h == 0 {
            continue;
        }
        let mut z = vec![0.0f32; w as usize * h as usize];
        let mut x0 = 0usize;
        for m in &light.maps {
            let n = m.view.size as usize;
            for y in 0..n {
                z[y * w as usize + x0..y * w as usize + x0 + n].copy_from_slice(&m.depth[y * n..(y + 1) * n]);
            }
            x0 += n;
        }
        write_exr(&dir.join(format!("shadow_map_{}.exr", light.light)), w, h, &[("Z", z)])?;
    }
    Ok(())
}

/// Writes all buffers into `dir` (which must exist and be writable).
pub fn write_all(dir: &Path, d: &DumpInput) -> Result<(), CliError> {
    let g = d.gbuffer;
    let (w, h) = (g.width, g.height);
    let exr3 = |name: &str, v: &[Vec3]| write_exr(&dir.join(format!("{name}.exr")), w, h, &xyz(v));
    let exr1 = |name: &str, v: Vec<f32>| write_exr(&dir.join(format!("{name}.exr")), w, h, &[("Y", v)]);

    // One PNG per viewable buffer (the object ids are written as ids below, the RT depths as EXR).
    for kind in BufferKind::ALL {
        if matches!(kind, BufferKind::ObjectId | BufferKind::RtDepth | BufferKind::MergedDepth) {
            continue;
        }
        if let Some(img) = buffer_view::view(kind, d) {
            write_png_rgba8(&dir.join(format!("{}.png", kind.name())), img.width, img.height, &img.pixels)?;
        }
    }
    exr3("position", &g.position)?;
    exr3("normal", &g.normal)?;
    exr3("optical", &g.optical)?;
    exr1("mask", g.mask.clone())?;
    exr1("depth", g.depth.clone())?;
    let b = d.buffers;
    for (name, v) in [("lighting", &b.lighting), ("shadow", &b.shadow), ("reflection", &b.reflection), ("refraction", &b.refraction)] {
        exr3(name, v)?;
    }
    for (name, v) in [
        ("shadow_fallback", &b.shadow_fallback),
        ("reflection_fallback", &b.reflection_fallback),
        ("refraction_fallback", &b.refraction_fallback),
    ] {
        if !v.is_empty() {
            exr3(name, v)?;
        }
    }
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
        // The synthesized depth, exactly the packed bits.
        write_exr(&dir.join("rt_depth.exr"), rt.width, rt.height, &[("Z", buffer_view::rt_depth(rt))])?;
        write_exr(&dir.join("merged_depth.exr"), w, h, &[("Z", g.depth.clone())])?;
    }
    Ok(())
}
