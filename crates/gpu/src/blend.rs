//! Stage 4, `blend` (paper listing 10, eq. 4–6; design §3), on the GPU: one compute pass from
//! lighting, shadow, reflection, refraction, the G-buffer's optical target and the mask to the
//! final 8-bit sRGB image, byte for byte as `hybrid_core::blend::{blend_pixel, encode_srgb}`
//! (the shader rounds to the byte itself; the Rgba8Unorm store keeps it).

use hybrid_core::Stage;

use crate::context::GpuContext;
use crate::heuristic::compute_pipeline;
use crate::targets::{FINAL_FORMAT, FrameTargets, Target};
use crate::timing::StageTimer;

/// The blend pass's WGSL after eq. 4–6 (`blend_equations.wgsl`, which fallback.wgsl shares; the
/// constants header is prepended).
pub(crate) const BLEND_WGSL: &str = concat!(include_str!("shaders/blend_equations.wgsl"), "\n", include_str!("shaders/blend.wgsl"));

/// Blend workgroup side (blend.wgsl `@workgroup_size(8, 8, 1)`).
const GROUP: u32 = 8;

/// The blend pass (pipeline and layout; the bind group is made per frame).
pub struct BlendPass {
    device: wgpu::Device,
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    /// With the raster fallbacks (`blend_fallback`): group 1 is the object ids and the three
    /// fallback targets.
    fallback_pipeline: wgpu::ComputePipeline,
    fallback_layout: wgpu::BindGroupLayout,
}

impl BlendPass {
    pub fn new(ctx: &GpuContext) -> Self {
        let device = &ctx.device;
        let input = |binding: u32, filterable: bool| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Float { filterable },
                view_dimension: wgpu::TextureViewDimension::D2,
                multisampled: false,
            },
            count: None,
        };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("blend"),
            entries: &[
                input(0, true),  // lighting
                input(1, true),  // shadow
                input(2, true),  // reflection
                input(3, true),  // refraction
                input(4, true),  // optical
                input(5, false), // mask (R32Float is not filterable)
                wgpu::BindGroupLayoutEntry {
                    binding: 6,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::StorageTexture {
                        access: wgpu::StorageTextureAccess::WriteOnly,
                        format: FINAL_FORMAT,
                        view_dimension: wgpu::TextureViewDimension::D2,
                    },
                    count: None,
                },
            ],
        });
        let pipeline = compute_pipeline(device, "blend", BLEND_WGSL, "blend", &layout);
        let mut fallback_inputs = vec![wgpu::BindGroupLayoutEntry {
            binding: 0,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Uint,
                view_dimension: wgpu::TextureViewDimension::D2,
                multisampled: false,
            },
            count: None,
        }];
        fallback_inputs.extend((1..4).map(|b| input(b, true)));
        let fallback_layout =
            device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some("blend.fallback"), entries: &fallback_inputs });
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("blend.fallback"),
            source: wgpu::ShaderSource::Wgsl(format!("{}\n{BLEND_WGSL}", crate::shaders::constants()).into()),
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("blend.fallback"),
            bind_group_layouts: &[Some(&layout), Some(&fallback_layout)],
            immediate_size: 0,
        });
        let fallback_pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("blend.fallback"),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some("blend_fallback"),
            compilation_options: Default::default(),
            cache: None,
        });
        Self { device: device.clone(), pipeline, layout, fallback_pipeline, fallback_layout }
    }

    /// Records the blend pass: eq. 4–6 where the mask is set (≥ 1e-4), the lighting elsewhere,
    /// sRGB-encoded into `targets.final_image` (alpha 255). With `fallback` (the shadow,
    /// reflection and refraction fallback targets), untraced polygon pixels take those terms
    /// (`hybrid_core::blend::blend_pixel_with_fallback`).
    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        targets: &FrameTargets,
        fallback: Option<&[Target; 3]>,
        timer: &mut StageTimer,
    ) {
        let views = [
            &targets.lighting.view,
            &targets.shadow.view,
            &targets.reflection.view,
            &targets.refraction.view,
            &targets.optical.view,
            &targets.mask.view,
            &targets.final_image.view,
        ];
        let entries: Vec<wgpu::BindGroupEntry> = views
            .iter()
            .enumerate()
            .map(|(i, view)| wgpu::BindGroupEntry { binding: i as u32, resource: wgpu::BindingResource::TextureView(view) })
            .collect();
        let bind_group =
            self.device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some("blend"), layout: &self.layout, entries: &entries });
        let mut pass = encoder
            .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("blend"), timestamp_writes: timer.compute(Stage::Blend) });
        match fallback {
            Some(fb) => {
                let views = [&targets.object_id.view, &fb[0].view, &fb[1].view, &fb[2].view];
                let entries: Vec<wgpu::BindGroupEntry> = views
                    .iter()
                    .enumerate()
                    .map(|(i, view)| wgpu::BindGroupEntry { binding: i as u32, resource: wgpu::BindingResource::TextureView(view) })
                    .collect();
                let fallback_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("blend.fallback"),
                    layout: &self.fallback_layout,
                    entries: &entries,
                });
                pass.set_pipeline(&self.fallback_pipeline);
                pass.set_bind_group(0, &bind_group, &[]);
                pass.set_bind_group(1, &fallback_group, &[]);
            }
            None => {
                pass.set_pipeline(&self.pipeline);
                pass.set_bind_group(0, &bind_group, &[]);
            }
        }
        pass.dispatch_workgroups(targets.width.div_ceil(GROUP), targets.height.div_ceil(GROUP), 1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shaders::validate;

    #[test]
    fn blend_wgsl_is_valid() {
        if let Err(e) = validate(&format!("{}\n{BLEND_WGSL}", crate::shaders::constants())) {
            panic!("{e}");
        }
    }

    #[test]
    fn shader_constants_match_rust() {
        assert!(BLEND_WGSL.contains(&format!("@workgroup_size({GROUP}, {GROUP}, 1)")));
        // Listing 10's threshold, as the CPU's.
        assert_eq!(hybrid_core::blend::MASK_EPSILON, 1e-4);
        // Used by the pass, defined only by the generated header (`shaders::constants`).
        assert!(BLEND_WGSL.contains("MASK_EPSILON") && !BLEND_WGSL.contains("const MASK_EPSILON"));
    }
}
