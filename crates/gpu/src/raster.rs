//! `raster`: stage 1 (paper 1 §3.1, listings 1–3), the G-buffer fill, as one render pass — the
//! GPU twin of `hybrid_cpu::raster`.
//!
//! Vertex pulling: no vertex buffers, `draw(0..3 · triangle_count)`; the vertex shader reads
//! corner `vi % 3` of triangle `vi / 3` from group 0. The fragment shader evaluates the surface
//! with common.wgsl's `evaluate_surface` (the CPU's `TriangleSurface::at`), its UV footprint from
//! the fine screen derivatives of the UV, and writes the eight G-buffer targets
//! ([`GBUFFER_COLOR_FORMATS`]) and reversed-Z depth (Greater, write on). No face culling: the
//! CPU rasteriser draws both sides too.

use crate::context::GpuContext;
use crate::scene::SceneGpu;
use crate::shaders;
use crate::targets::{DEPTH_FORMAT, FrameTargets, GBUFFER_COLOR_FORMATS};
use crate::timing::{Stage, StageTimer};

/// WGSL of the pass (common.wgsl is prepended).
pub const SOURCE: &str = include_str!("shaders/raster.wgsl");

/// The G-buffer render pipeline.
pub struct RasterPass {
    pipeline: wgpu::RenderPipeline,
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
        let targets: Vec<Option<wgpu::ColorTargetState>> = GBUFFER_COLOR_FORMATS
            .iter()
            .map(|&format| Some(wgpu::ColorTargetState { format, blend: None, write_mask: wgpu::ColorWrites::ALL }))
            .collect();
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("raster"),
            layout: Some(&layout),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: wgpu::PrimitiveState {
                topology: wgpu::PrimitiveTopology::TriangleList,
                front_face: wgpu::FrontFace::Ccw,
                cull_mode: None,
                ..Default::default()
            },
            depth_stencil: Some(wgpu::DepthStencilState {
                format: DEPTH_FORMAT,
                depth_write_enabled: Some(true),
                depth_compare: Some(wgpu::CompareFunction::Greater),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs_main"),
                compilation_options: Default::default(),
                targets: &targets,
            }),
            multiview_mask: None,
            cache: None,
        });
        Self { pipeline }
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
        let color_ops = |clear_value: wgpu::Color| wgpu::Operations {
            load: if clear { wgpu::LoadOp::Clear(clear_value) } else { wgpu::LoadOp::Load },
            store: wgpu::StoreOp::Store,
        };
        let views = targets.gbuffer_color_views();
        let attachments: Vec<Option<wgpu::RenderPassColorAttachment>> = views
            .iter()
            .enumerate()
            .map(|(i, view)| {
                // Target 7 is the object id (R32Uint): cleared to NO_OBJECT = u32::MAX (exact in f64).
                let value = if i == 7 { wgpu::Color { r: f64::from(u32::MAX), g: 0.0, b: 0.0, a: 0.0 } } else { wgpu::Color::TRANSPARENT };
                Some(wgpu::RenderPassColorAttachment { view, depth_slice: None, resolve_target: None, ops: color_ops(value) })
            })
            .collect();
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("raster"),
            color_attachments: &attachments,
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &targets.depth.view,
                depth_ops: Some(wgpu::Operations {
                    load: if clear { wgpu::LoadOp::Clear(0.0) } else { wgpu::LoadOp::Load },
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: timer.render(Stage::Raster),
            occlusion_query_set: None,
            multiview_mask: None,
        });
        if scene.triangle_count > 0 {
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &scene.bind_group, &[]);
            pass.draw(0..3 * scene.triangle_count, 0..1);
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
