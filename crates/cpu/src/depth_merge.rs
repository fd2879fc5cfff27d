//! The depth merge's host side on the CPU (paper 2, block U after the fact): the RT layer's pixels
//! written into a finished G-buffer where they are nearer (reversed-Z Greater), as surfaces the
//! deferred lighting turns back into their colour. The raster does the same while it draws
//! (`raster::rasterize` with a layer), with the same surfaces ([`rt_surface`]).

use glam::Vec3;
use hybrid_core::depth_merge::{PackedRtFrame, unpack_into};
use hybrid_core::{GBuffer, RT_SCENE_OBJECT, RtLayer, Surface};
use hybrid_scene::Camera;
use rayon::prelude::*;

use crate::camera_rays::PrimaryRays;

/// Depth merge of the RT layer into a finished G-buffer (used where the G-buffer comes from
/// primary rays, `rt-only`): wherever the layer's depth is Greater than the G-buffer's, the pixel
/// becomes the RT-scene's ([`RT_SCENE_OBJECT`], [`rt_surface`]). Same result as passing the layer
/// to [`crate::raster::rasterize`]. A layer of another size is ignored (with a warning).
/// Block U over a whole packed frame into `layer` (the frame's size; every texel written), in
/// parallel runs of texels (each is independent).
pub fn unpack_layer_into(packed: &PackedRtFrame, layer: &mut RtLayer) {
    const RUN: usize = 16 * 1024;
    layer
        .color
        .par_chunks_mut(RUN)
        .zip(layer.depth.par_chunks_mut(RUN))
        .zip(packed.texels.par_chunks(RUN))
        .for_each(|((color, depth), texels)| unpack_into(texels, color, depth));
}

pub fn merge_rt_layer(gbuffer: &mut GBuffer, layer: &RtLayer, camera: &Camera) {
    let (w, h) = (gbuffer.width, gbuffer.height);
    if !layer_fits(layer, w, h) {
        return;
    }
    let rays = PrimaryRays::new(camera, w, h);
    // Runs of rows in parallel (each pixel is independent).
    let band_len = w as usize * MERGE_ROWS;
    gbuffer.bands_mut(band_len).into_par_iter().enumerate().for_each(|(band, mut rows)| {
        let base = band * band_len;
        for k in 0..rows.len() {
            let i = base + k;
            let d = layer.depth[i];
            if d > 0.0 && d > rows.depth[k] {
                let (x, y) = ((i % w as usize) as u32, (i / w as usize) as u32);
                let s = rt_surface_with(&rays, x, y, d, layer.color[i]);
                rows.write(k, RT_SCENE_OBJECT, d, &s);
            }
        }
    });
}

/// Rows per parallel task of [`merge_rt_layer`].
const MERGE_ROWS: usize = 16;

/// The G-buffer surface of an RT-layer pixel: emission = its colour (so deferred lighting
/// reproduces it), no other reflectance, opaque, IOR 1; position = the pixel centre at `depth`
/// unprojected with the inverse view-projection; normal = unit vector towards the camera.
pub fn rt_surface(camera: &Camera, width: u32, height: u32, x: u32, y: u32, depth: f32, color: Vec3) -> Surface {
    rt_surface_with(&PrimaryRays::new(camera, width, height), x, y, depth, color)
}

/// [`rt_surface`] with the frame's rays already set up.
pub(crate) fn rt_surface_with(rays: &PrimaryRays, x: u32, y: u32, depth: f32, color: Vec3) -> Surface {
    let position = rays.point_at_depth(x, y, depth);
    Surface {
        position,
        normal: rays.towards_camera(position),
        emission: color,
        ambient: Vec3::ZERO,
        diffuse: Vec3::ZERO,
        opacity: 1.0,
        specular: Vec3::ZERO,
        shininess: 0.0,
        reflectivity: 0.0,
        ior: 1.0,
    }
}

pub(crate) fn layer_fits(layer: &RtLayer, w: u32, h: u32) -> bool {
    let n = w as usize * h as usize;
    let ok = layer.width == w && layer.height == h && layer.depth.len() == n && layer.color.len() == n;
    if !ok {
        tracing::warn!(layer_w = layer.width, layer_h = layer.height, w, h, "RT layer size differs from the frame; ignored");
    }
    ok
}
