//! Stage 2, `heuristic` (design §4), on the GPU: a compute pass counts A (pixels per object id,
//! atomics) → a small read-back → the shared heuristic code on the CPU (`hybrid_heuristic`, as
//! the CPU backend runs it) → the selected flags go back up → a compute pass writes the mask.
//!
//! wgpu's occlusion queries are boolean only, so they cannot give A: the object-id target does
//! (design §2), for all objects in one pass.

use hybrid_core::Stage;
use wgpu::util::DeviceExt;

use crate::context::{GpuContext, GpuError};
use crate::readback::read_buffer;
use crate::targets::{FrameTargets, MASK_FORMAT};
use crate::timing::StageTimer;

/// Which pixels the mask marks for tracing (design §1 modes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MaskSelection<'a> {
    /// `hybrid` / `all`: 1 where the pixel's object is selected (`selected[id]`), as
    /// `hybrid_heuristic::write_mask`; ids at or beyond `selected.len()` (sky, RT-scene) get 0.
    Objects(&'a [bool]),
    /// `rt-only`: 1 on every pixel with an object id (id ≠ `NO_OBJECT`), RT-scene pixels
    /// included, as the CPU frame's rt-only rule.
    AllCovered,
    /// `raster`: 0 everywhere.
    Nothing,
}

impl MaskSelection<'_> {
    /// The shader's mode constant (mask.wgsl).
    fn mode(&self) -> u32 {
        match self {
            MaskSelection::Objects(_) => 0,
            MaskSelection::AllCovered => 1,
            MaskSelection::Nothing => 2,
        }
    }
}

/// Pixels one count invocation walks along its row (count.wgsl `SPAN`).
pub(crate) const COUNT_SPAN: u32 = 16;
/// Count workgroup width (count.wgsl `@workgroup_size(64, 1, 1)`).
const COUNT_GROUP: u32 = 64;
/// Mask workgroup side (mask.wgsl `@workgroup_size(8, 8, 1)`).
const MASK_GROUP: u32 = 8;

/// The count and mask passes, with their buffers (made for one object count).
pub struct HeuristicPasses {
    /// For the per-frame bind groups (`encode_count` gets no context).
    device: wgpu::Device,
    object_count: u32,
    count_pipeline: wgpu::ComputePipeline,
    count_layout: wgpu::BindGroupLayout,
    mask_pipeline: wgpu::ComputePipeline,
    mask_layout: wgpu::BindGroupLayout,
    /// One atomic u32 per object (at least one word, so the binding is never empty).
    counts: wgpu::Buffer,
    /// `counts` copied here for the read-back.
    counts_readback: wgpu::Buffer,
    /// count.wgsl's `CountParams`.
    count_params: wgpu::Buffer,
}

fn texture_entry(binding: u32, sample_type: wgpu::TextureSampleType) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Texture { sample_type, view_dimension: wgpu::TextureViewDimension::D2, multisampled: false },
        count: None,
    }
}

fn buffer_entry(binding: u32, ty: wgpu::BufferBindingType) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer { ty, has_dynamic_offset: false, min_binding_size: None },
        count: None,
    }
}

/// A compute pipeline from a standalone shader (no common/*.wgsl: these passes need no scene; the
/// generated constants header only).
pub(crate) fn compute_pipeline(
    device: &wgpu::Device,
    label: &str,
    source: &str,
    entry_point: &str,
    layout: &wgpu::BindGroupLayout,
) -> wgpu::ComputePipeline {
    let source = format!("{}\n{source}", crate::shaders::constants());
    let module =
        device.create_shader_module(wgpu::ShaderModuleDescriptor { label: Some(label), source: wgpu::ShaderSource::Wgsl(source.into()) });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(label),
        bind_group_layouts: &[Some(layout)],
        immediate_size: 0,
    });
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: Some(&pipeline_layout),
        module: &module,
        entry_point: Some(entry_point),
        compilation_options: Default::default(),
        cache: None,
    })
}

pub(crate) const COUNT_WGSL: &str = include_str!("shaders/count.wgsl");
pub(crate) const MASK_WGSL: &str = include_str!("shaders/mask.wgsl");

impl HeuristicPasses {
    pub fn new(ctx: &GpuContext, object_count: u32) -> Self {
        let device = &ctx.device;
        let uint = wgpu::TextureSampleType::Uint;
        let count_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("heuristic.count"),
            entries: &[
                texture_entry(0, uint),
                buffer_entry(1, wgpu::BufferBindingType::Storage { read_only: false }),
                buffer_entry(2, wgpu::BufferBindingType::Uniform),
            ],
        });
        let mask_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("heuristic.mask"),
            entries: &[
                texture_entry(0, uint),
                buffer_entry(1, wgpu::BufferBindingType::Storage { read_only: true }),
                buffer_entry(2, wgpu::BufferBindingType::Uniform),
                wgpu::BindGroupLayoutEntry {
                    binding: 3,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::StorageTexture {
                        access: wgpu::StorageTextureAccess::WriteOnly,
                        format: MASK_FORMAT,
                        view_dimension: wgpu::TextureViewDimension::D2,
                    },
                    count: None,
                },
            ],
        });
        let count_pipeline = compute_pipeline(device, "heuristic.count", COUNT_WGSL, "count_pixels", &count_layout);
        let mask_pipeline = compute_pipeline(device, "heuristic.mask", MASK_WGSL, "write_mask", &mask_layout);
        let size = object_count.max(1) as u64 * 4;
        let counts = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("heuristic.counts"),
            size,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let counts_readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("heuristic.counts.readback"),
            size,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let count_params = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("heuristic.count.params"),
            contents: bytemuck::cast_slice(&[object_count, 0, 0, 0]),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        Self {
            device: device.clone(),
            object_count,
            count_pipeline,
            count_layout,
            mask_pipeline,
            mask_layout,
            counts,
            counts_readback,
            count_params,
        }
    }

    /// The object count the passes were made for (`read_counts`' length).
    pub fn object_count(&self) -> u32 {
        self.object_count
    }

    /// Records: clear the counts, the count pass over `targets.object_id` (ids ≥ object count,
    /// `NO_OBJECT` and `RT_SCENE_OBJECT` are not counted), and the copy for [`Self::read_counts`].
    pub fn encode_count(&self, encoder: &mut wgpu::CommandEncoder, targets: &FrameTargets, timer: &mut StageTimer) {
        encoder.clear_buffer(&self.counts, 0, None);
        let bind_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("heuristic.count"),
            layout: &self.count_layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::TextureView(&targets.object_id.view) },
                wgpu::BindGroupEntry { binding: 1, resource: self.counts.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: self.count_params.as_entire_binding() },
            ],
        });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("heuristic.count"),
                timestamp_writes: timer.compute(Stage::Heuristic),
            });
            pass.set_pipeline(&self.count_pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            let spans = targets.width.div_ceil(COUNT_SPAN);
            pass.dispatch_workgroups(spans.div_ceil(COUNT_GROUP), targets.height, 1);
        }
        encoder.copy_buffer_to_buffer(&self.counts, 0, &self.counts_readback, 0, self.counts.size());
    }

    /// A per object (length = object count), as `hybrid_heuristic::count_visible_pixels` returns
    /// it. Call after the encoder holding [`Self::encode_count`] was submitted; waits for the GPU.
    pub fn read_counts(&self, ctx: &GpuContext) -> Result<Vec<u64>, GpuError> {
        let bytes = read_buffer(ctx, &self.counts_readback)?;
        let words: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes);
        Ok(words.into_iter().take(self.object_count as usize).map(u64::from).collect())
    }

    /// Uploads the selection and records the pass that writes `targets.mask` (1.0 = trace this
    /// pixel, else 0.0) from `targets.object_id`. Each call has its own small flags buffer, so
    /// several calls may be recorded before one submission.
    pub fn encode_mask(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        targets: &FrameTargets,
        selection: MaskSelection<'_>,
        timer: &mut StageTimer,
    ) {
        let device = &ctx.device;
        let (flags, count): (Vec<u32>, u32) = match selection {
            MaskSelection::Objects(selected) => (selected.iter().map(|&on| u32::from(on)).collect(), selected.len() as u32),
            _ => (Vec::new(), 0),
        };
        // Never an empty binding: one unused word when there are no flags.
        let flags = if flags.is_empty() { vec![0u32] } else { flags };
        let flags = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("heuristic.mask.selected"),
            contents: bytemuck::cast_slice(&flags),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let params = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("heuristic.mask.params"),
            contents: bytemuck::cast_slice(&[selection.mode(), count, 0, 0]),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("heuristic.mask"),
            layout: &self.mask_layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::TextureView(&targets.object_id.view) },
                wgpu::BindGroupEntry { binding: 1, resource: flags.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: params.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 3, resource: wgpu::BindingResource::TextureView(&targets.mask.view) },
            ],
        });
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("heuristic.mask"),
            timestamp_writes: timer.compute(Stage::Heuristic),
        });
        pass.set_pipeline(&self.mask_pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups(targets.width.div_ceil(MASK_GROUP), targets.height.div_ceil(MASK_GROUP), 1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shaders::validate;

    #[test]
    fn count_wgsl_is_valid() {
        if let Err(e) = validate(&format!("{}\n{COUNT_WGSL}", crate::shaders::constants())) {
            panic!("{e}");
        }
    }

    #[test]
    fn mask_wgsl_is_valid() {
        if let Err(e) = validate(&format!("{}\n{MASK_WGSL}", crate::shaders::constants())) {
            panic!("{e}");
        }
    }

    #[test]
    fn shader_constants_match_rust() {
        assert!(crate::shaders::constants().contains(&format!("const SPAN: u32 = {COUNT_SPAN}u;")));
        assert!(COUNT_WGSL.contains(&format!("@workgroup_size({COUNT_GROUP}, 1, 1)")));
        assert!(MASK_WGSL.contains(&format!("@workgroup_size({MASK_GROUP}, {MASK_GROUP}, 1)")));
        assert!(MASK_WGSL.contains("NO_OBJECT") && !MASK_WGSL.contains("const NO_OBJECT"), "NO_OBJECT comes from the generated header");
        for (selection, mode) in [(MaskSelection::Objects(&[]), 0), (MaskSelection::AllCovered, 1), (MaskSelection::Nothing, 2)] {
            assert_eq!(selection.mode(), mode);
        }
        assert!(MASK_WGSL.contains("const MODE_OBJECTS: u32 = 0u;") && MASK_WGSL.contains("const MODE_ALL_COVERED: u32 = 1u;"));
    }
}
