//! `raster`: stage 1 (paper 1 §3.1, listings 1–3), the G-buffer fill, as one render pass — the
//! GPU twin of `hybrid_cpu::raster`.
//!
//! Vertex pulling: no vertex buffers, `draw(0..3 · triangle_count)`; the vertex shader reads
//! corner `vi % 3` of triangle `vi / 3` from group 0. The fragment shader evaluates the surface
//! with common/*.wgsl's `evaluate_surface` (the CPU's `TriangleSurface::at`), its UV footprint from
//! the fine screen derivatives of the UV, and writes the eight G-buffer targets
//! ([`GBUFFER_COLOR_FORMATS`](crate::targets::GBUFFER_COLOR_FORMATS)) and reversed-Z depth (Greater, write on). No face culling: the
//! CPU rasteriser draws both sides too.

use std::sync::OnceLock;

use hybrid_core::Stage;

use crate::context::GpuContext;
use crate::scene::SceneGpu;
use crate::shaders;
use crate::targets::{FrameTargets, begin_gbuffer_pass, gbuffer_pipeline};
use crate::timing::StageTimer;

/// WGSL of the pass (common/*.wgsl is prepended).
pub const SOURCE: &str = include_str!("shaders/raster.wgsl");

/// The G-buffer render pipeline (and, made on first use, its level-0 twin for the fallbacks'
/// layers).
pub struct RasterPass {
    pipeline: wgpu::RenderPipeline,
    device: wgpu::Device,
    layout: wgpu::PipelineLayout,
    module: wgpu::ShaderModule,
    level0: OnceLock<wgpu::RenderPipeline>,
}

impl RasterPass {
    pub fn new(ctx: &GpuContext, scene: &SceneGpu) -> Self {
        let device = &ctx.device;
        let module = shaders::module(device, "raster", SOURCE);
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("raster"),
            bind_group_layouts: &[Some(&scene.layout)],
            immediate_size: 0,
        });
        let pipeline = gbuffer_pipeline(device, "raster", &layout, &module, "vs_main", "fs_main");
        Self { pipeline, device: device.clone(), layout, module, level0: OnceLock::new() }
    }

    /// Stage 1: one render pass over every triangle of the scene into the G-buffer targets and
    /// depth. `clear = true` clears everything first (object id to `NO_OBJECT`, depth to 0 = far,
    /// the rest to 0); `clear = false` loads what is there (the capsule's unpack pass wrote the
    /// RT-scene pixels and their depth; polygons must be nearer to win).
    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        scene: &SceneGpu,
        targets: &FrameTargets,
        clear: bool,
        timer: &mut StageTimer,
    ) {
        let mut pass = begin_gbuffer_pass(encoder, targets, clear, "raster", timer.render(Stage::Raster));
        if scene.triangle_count > 0 {
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &scene.bind_group, &[]);
            pass.draw(0..3 * scene.triangle_count, 0..1);
        }
    }
}

impl RasterPass {
    /// As [`Self::encode`], drawing only the triangles in `ranges` (indices into group 0's
    /// triangles), with textures sampled at level 0 (`fs_level0`), as secondary rays sample
    /// them: the fallbacks' layers (probe faces leave their own object out, the see-through
    /// layer the planar refractive objects), as `hybrid_cpu::raster::rasterize_meshes`.
    pub fn encode_triangles(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        scene: &SceneGpu,
        targets: &FrameTargets,
        clear: bool,
        ranges: &[std::ops::Range<u32>],
        timer: &mut StageTimer,
    ) {
        let pipeline = self
            .level0
            .get_or_init(|| gbuffer_pipeline(&self.device, "raster (level 0)", &self.layout, &self.module, "vs_main", "fs_level0"));
        let mut pass = begin_gbuffer_pass(encoder, targets, clear, "raster (triangle ranges)", timer.render(Stage::Raster));
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, &scene.bind_group, &[]);
        for r in ranges {
            pass.draw(3 * r.start..3 * r.end, 0..1);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn raster_wgsl_is_valid() {
        if let Err(e) = shaders::validate(&shaders::with_common(SOURCE)) {
            panic!("{e}");
        }
    }
}
