//! `lighting`: stage 1b, deferred lighting (paper listing 5), as one compute pass — the GPU twin
//! of `hybrid_cpu::lighting::deferred_lighting`. Every pixel with an object gets
//! `emission + env_ambient · ambient + Σ lights Blinn–Phong` (unshadowed; shadows are the trace
//! stage's) from the G-buffer, every other pixel the sky along its primary ray. Output:
//! `targets.lighting` (Rgba16Float, linear).

use hybrid_core::Stage;

use crate::context::GpuContext;
use crate::scene::SceneGpu;
use crate::shaders;
use crate::targets::{COLOR_FORMAT, FrameTargets};
use crate::timing::StageTimer;

/// WGSL of the pass (common/*.wgsl is prepended).
pub const SOURCE: &str = include_str!("shaders/lighting.wgsl");

/// Workgroup edge (8 × 8 invocations).
const GROUP: u32 = 8;

/// The deferred lighting compute pipeline.
pub struct LightingPass {
    pipeline: wgpu::ComputePipeline,
    /// Group 1: the G-buffer targets (sampled, `textureLoad`) and the lighting output (storage).
    layout: wgpu::BindGroupLayout,
    /// For the per-encode bind group (`encode` gets no context).
    device: wgpu::Device,
}

impl LightingPass {
    pub fn new(ctx: &GpuContext, scene: &SceneGpu) -> Self {
        let device = &ctx.device;
        let texture = |binding: u32, sample_type: wgpu::TextureSampleType| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Texture { sample_type, view_dimension: wgpu::TextureViewDimension::D2, multisampled: false },
            count: None,
        };
        // Rgba32Float is not filterable; textureLoad needs no filtering anyway.
        let float = wgpu::TextureSampleType::Float { filterable: false };
        let mut entries: Vec<wgpu::BindGroupLayoutEntry> = (0..6).map(|b| texture(b, float)).collect();
        entries.push(texture(6, wgpu::TextureSampleType::Uint));
        entries.push(wgpu::BindGroupLayoutEntry {
            binding: 7,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::StorageTexture {
                access: wgpu::StorageTextureAccess::WriteOnly,
                format: COLOR_FORMAT,
                view_dimension: wgpu::TextureViewDimension::D2,
            },
            count: None,
        });
        let layout =
            device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some("lighting.gbuffer"), entries: &entries });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("lighting"),
            bind_group_layouts: &[Some(&scene.layout), Some(&layout)],
            immediate_size: 0,
        });
        let module = shaders::module(device, "lighting", SOURCE);
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("lighting"),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some("cs_main"),
            compilation_options: Default::default(),
            cache: None,
        });
        Self { pipeline, layout, device: device.clone() }
    }

    /// Deferred Blinn–Phong over the G-buffer into `targets.lighting`; the sky where
    /// `object_id == NO_OBJECT`. The bind group is made here (targets change with the frame size).
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, scene: &SceneGpu, targets: &FrameTargets, timer: &mut StageTimer) {
        let views = [
            &targets.position.view,
            &targets.normal.view,
            &targets.emission.view,
            &targets.ambient.view,
            &targets.diffuse.view,
            &targets.specular.view,
            &targets.object_id.view,
            &targets.lighting.view,
        ];
        let entries: Vec<wgpu::BindGroupEntry> = views
            .iter()
            .enumerate()
            .map(|(i, view)| wgpu::BindGroupEntry { binding: i as u32, resource: wgpu::BindingResource::TextureView(view) })
            .collect();
        let bind_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("lighting.gbuffer"),
            layout: &self.layout,
            entries: &entries,
        });
        let mut pass = encoder
            .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("lighting"), timestamp_writes: timer.compute(Stage::Lighting) });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &scene.bind_group, &[]);
        pass.set_bind_group(1, &bind_group, &[]);
        pass.dispatch_workgroups(targets.width.div_ceil(GROUP), targets.height.div_ceil(GROUP), 1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lighting_wgsl_is_valid() {
        if let Err(e) = shaders::validate(&shaders::with_common(SOURCE)) {
            panic!("{e}");
        }
    }
}
