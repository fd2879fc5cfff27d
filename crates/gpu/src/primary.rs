//! `primary`: the `rt-only` mode's G-buffer from primary rays instead of the raster (the twin of
//! hybrid-cpu's `trace::rt_only_gbuffer`). One render pass draws a full-screen triangle whose
//! fragment shader (`shaders/primary.wgsl`) traces its pixel centre's ray through the triangle
//! BVH and writes the raster pass's 8 colour targets plus the hit's depth (projected with the
//! frame's view-projection, reversed-Z, depth-tested Greater so an RT-scene layer already in the
//! depth buffer is merged as the raster would); misses are discarded.

use hybrid_core::Stage;

use crate::accel::{RQ_WGSL, RtScene};
use crate::bvh::{BVH_WGSL, TriangleBvhGpu};
use crate::context::GpuContext;
use crate::scene::SceneGpu;
use crate::shaders;
use crate::targets::{FrameTargets, begin_gbuffer_pass, gbuffer_pipeline};
use crate::timing::StageTimer;

/// The pass's own WGSL (after common/*.wgsl and bvh.wgsl).
pub const PRIMARY_WGSL: &str = include_str!("shaders/primary.wgsl");

/// The primary-ray G-buffer pass.
pub struct PrimaryPass {
    pipeline: wgpu::RenderPipeline,
    bind_group: wgpu::BindGroup,
    /// Group 3 of the hardware variant.
    rt: Option<wgpu::BindGroup>,
}

impl PrimaryPass {
    pub fn new(ctx: &GpuContext, scene: &SceneGpu, bvh: &TriangleBvhGpu) -> Self {
        Self::new_rt(ctx, scene, bvh, None)
    }

    /// As [`PrimaryPass::new`]; with `rt`, the hardware variant (ray queries over `rt`'s
    /// acceleration structure, group 3; the BVH stays bound, unread).
    pub fn new_rt(ctx: &GpuContext, scene: &SceneGpu, bvh: &TriangleBvhGpu, rt: Option<&RtScene>) -> Self {
        let device = &ctx.device;
        let entries = TriangleBvhGpu::layout_entries(wgpu::ShaderStages::FRAGMENT);
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some("primary"), entries: &entries });
        let bind_group =
            device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some("primary"), layout: &layout, entries: &bvh.bind_entries() });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("primary"),
            bind_group_layouts: &[Some(&scene.layout), Some(&layout), None, rt.map(|rt| &rt.layout)],
            immediate_size: 0,
        });
        let module = match rt {
            None => shaders::module(device, "primary", &format!("{BVH_WGSL}\n{PRIMARY_WGSL}")),
            Some(_) => shaders::module_rq(device, "primary.hw", &format!("{RQ_WGSL}\n{PRIMARY_WGSL}")),
        };
        let pipeline = gbuffer_pipeline(device, "primary", &pipeline_layout, &module, "primary_vs", "primary_fs");
        Self { pipeline, bind_group, rt: rt.map(|rt| rt.bind_group.clone()) }
    }

    /// The G-buffer (8 colour targets + depth) of `targets` from primary rays. `clear`: clear
    /// everything first (object id to `NO_OBJECT`, depth to 0 = far, the rest to 0); else load
    /// what is there (the RT-scene layer) and depth-test against it.
    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        scene: &SceneGpu,
        targets: &FrameTargets,
        clear: bool,
        timer: &mut StageTimer,
    ) {
        let mut pass = begin_gbuffer_pass(encoder, targets, clear, "primary", timer.render(Stage::Raster));
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &scene.bind_group, &[]);
        pass.set_bind_group(1, &self.bind_group, &[]);
        if let Some(rt) = &self.rt {
            pass.set_bind_group(3, rt, &[]);
        }
        pass.draw(0..3, 0..1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shaders::{validate, with_common};

    #[test]
    fn primary_wgsl_is_valid() {
        if let Err(e) = validate(&with_common(&format!("{BVH_WGSL}\n{PRIMARY_WGSL}"))) {
            panic!("{e}");
        }
    }
}
