//! `trace`: stage 3 on the GPU (paper 1 listings 8a–d, design §3), the twin of hybrid-cpu's
//! `trace.rs`: three compute passes (shadow, reflection, refraction) over the masked pixels of
//! the G-buffer, each writing its buffer (shadow 1, reflection and refraction 0 where nothing is
//! traced), with rays traversing the triangle BVH of [`crate::bvh`]. `shaders/trace.wgsl` turns
//! listing 8c's recursion into a loop over a stack of pending rays, each carrying its weight in
//! the (linear) eq. 5/6 combination. Rays are counted with atomics. The RT-scene's spheres
//! ([`crate::spheres`], group 2) are geometry too, as in the CPU's `trace_with_spheres`: opaque
//! shadow casters, and seen (shaded as the capsule shades them) by secondary rays.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};
use hybrid_core::PreparedScene;
use hybrid_core::Stage;
use hybrid_core::report::RayCounts;
use wgpu::util::DeviceExt;

use crate::accel::{RQ_WGSL, RtScene};
use crate::bvh::{BVH_WGSL, TriangleBvhGpu};
use crate::context::{GpuContext, GpuError};
use crate::readback::read_buffer;
use crate::scene::SceneGpu;
use crate::shaders;
use crate::spheres::{SPHERES_RQ_WGSL, SPHERES_WGSL, SpheresGpu};
use crate::targets::{COLOR_FORMAT, FrameTargets};
use crate::timing::StageTimer;

/// The pass's own WGSL (after common/*.wgsl, bvh.wgsl and spheres.wgsl).
pub const TRACE_WGSL: &str = include_str!("shaders/trace.wgsl");

/// Pending secondary rays per pixel in trace.wgsl (`TRACE_STACK`, generated from this): the walk
/// is depth first, so at most one pending sibling per level.
pub const TRACE_STACK: u32 = 32;

/// The deepest secondary ray the GPU traces: `hybrid_scene::MAX_TRACED_DEPTH`, as the CPU (the
/// depth-first walk keeps at most one pending sibling per level, so the stack holds it).
pub const GPU_MAX_TRACE_DEPTH: u32 = hybrid_scene::MAX_TRACED_DEPTH;
const _: () = assert!(TRACE_STACK >= GPU_MAX_TRACE_DEPTH, "the pending-ray stack must hold the deepest tree");

/// `struct TraceParams` in trace.wgsl (the scene's `[trace]` settings).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub(crate) struct TraceParams {
    pub(crate) ray_bias: f32,
    pub(crate) importance_cutoff: f32,
    pub(crate) max_depth: u32,
    pub(crate) _pad: u32,
}

/// The three trace passes and what they share.
pub struct TracePasses {
    device: wgpu::Device,
    spheres: wgpu::BindGroup,
    /// Group 3 of the hardware variant (the acceleration structure); `None`: software traversal.
    rt: Option<wgpu::BindGroup>,
    /// Shared with the frame's other trace passes (with/without spheres) and the primary pass.
    bvh: Arc<TriangleBvhGpu>,
    layout: wgpu::BindGroupLayout,
    shadow: wgpu::ComputePipeline,
    reflection: wgpu::ComputePipeline,
    refraction: wgpu::ComputePipeline,
    params: wgpu::Buffer,
    counts: wgpu::Buffer,
    counts_readback: wgpu::Buffer,
}

const WORKGROUP: u32 = 8;

impl TracePasses {
    /// `spheres`: the RT-scene's spheres (`SpheresGpu::empty` when the scene has no point clouds).
    pub fn new(ctx: &GpuContext, scene: &SceneGpu, prepared: &PreparedScene, spheres: &SpheresGpu) -> Result<Self, GpuError> {
        let bvh = Arc::new(TriangleBvhGpu::new(ctx, scene, prepared)?);
        Self::with_bvh(ctx, scene, prepared, bvh, spheres)
    }

    /// As [`TracePasses::new`], on a triangle BVH already built and uploaded (one BVH serves the
    /// trace stage with and without the spheres).
    pub fn with_bvh(
        ctx: &GpuContext,
        scene: &SceneGpu,
        prepared: &PreparedScene,
        bvh: Arc<TriangleBvhGpu>,
        spheres: &SpheresGpu,
    ) -> Result<Self, GpuError> {
        Self::with_bvh_rt(ctx, scene, prepared, bvh, spheres, None)
    }

    /// As [`TracePasses::with_bvh`]; with `rt`, the hardware variant: rays traverse `rt`'s
    /// acceleration structures by ray queries (group 3) instead of the BVHs (still bound, unread).
    pub fn with_bvh_rt(
        ctx: &GpuContext,
        scene: &SceneGpu,
        prepared: &PreparedScene,
        bvh: Arc<TriangleBvhGpu>,
        spheres: &SpheresGpu,
        rt: Option<&RtScene>,
    ) -> Result<Self, GpuError> {
        let device = &ctx.device;
        let settings = &prepared.scene.trace;
        let params = TraceParams {
            ray_bias: settings.ray_bias,
            importance_cutoff: settings.importance_cutoff,
            max_depth: settings.max_depth.min(GPU_MAX_TRACE_DEPTH),
            _pad: 0,
        };
        let params = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("trace.params"),
            contents: bytemuck::bytes_of(&params),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let counts = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("trace.ray_counts"),
            size: 16,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let counts_readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("trace.ray_counts.readback"),
            size: 16,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });

        let vis = wgpu::ShaderStages::COMPUTE;
        let mut entries = TriangleBvhGpu::layout_entries(vis).to_vec();
        entries.push(wgpu::BindGroupLayoutEntry {
            binding: 2,
            visibility: vis,
            ty: wgpu::BindingType::Buffer { ty: wgpu::BufferBindingType::Uniform, has_dynamic_offset: false, min_binding_size: None },
            count: None,
        });
        let texture = |binding, sample_type| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: vis,
            ty: wgpu::BindingType::Texture { sample_type, view_dimension: wgpu::TextureViewDimension::D2, multisampled: false },
            count: None,
        };
        let float = wgpu::TextureSampleType::Float { filterable: false };
        for binding in 3..=7 {
            entries.push(texture(binding, float));
        }
        entries.push(texture(8, wgpu::TextureSampleType::Uint));
        entries.push(texture(9, float));
        for binding in 10..=12 {
            entries.push(wgpu::BindGroupLayoutEntry {
                binding,
                visibility: vis,
                ty: wgpu::BindingType::StorageTexture {
                    access: wgpu::StorageTextureAccess::WriteOnly,
                    format: COLOR_FORMAT,
                    view_dimension: wgpu::TextureViewDimension::D2,
                },
                count: None,
            });
        }
        entries.push(wgpu::BindGroupLayoutEntry {
            binding: 13,
            visibility: vis,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only: false },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some("trace"), entries: &entries });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("trace"),
            bind_group_layouts: &[Some(&scene.layout), Some(&layout), Some(&spheres.layout), rt.map(|rt| &rt.layout)],
            immediate_size: 0,
        });
        let module = match rt {
            None => shaders::module(device, "trace", &format!("{BVH_WGSL}\n{SPHERES_WGSL}\n{TRACE_WGSL}")),
            Some(_) => shaders::module_rq(device, "trace.hw", &format!("{RQ_WGSL}\n{SPHERES_RQ_WGSL}\n{TRACE_WGSL}")),
        };
        let pipeline = |entry: &str| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: Some(&pipeline_layout),
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        Ok(Self {
            device: device.clone(),
            rt: rt.map(|rt| rt.bind_group.clone()),
            spheres: spheres.bind_group.clone(),
            shadow: pipeline("shadow_rays"),
            reflection: pipeline("reflection_ray"),
            refraction: pipeline("refraction_ray"),
            bvh,
            layout,
            params,
            counts,
            counts_readback,
        })
    }

    /// Whether the passes trace by ray queries (the hardware variant).
    pub fn hardware(&self) -> bool {
        self.rt.is_some()
    }

    /// The BVH the passes traverse (the rt-only primary pass shares it).
    pub fn bvh(&self) -> &TriangleBvhGpu {
        &self.bvh
    }

    /// The triangle BVH, to share with another [`TracePasses::with_bvh`].
    pub fn shared_bvh(&self) -> Arc<TriangleBvhGpu> {
        self.bvh.clone()
    }

    /// Stage 3: the shadow, reflection and refraction passes over `targets` (reads the G-buffer
    /// and mask; writes `targets.shadow`, `.reflection`, `.refraction`), counting rays.
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, scene: &SceneGpu, targets: &FrameTargets, timer: &mut StageTimer) {
        let [b0, b1] = self.bvh.bind_entries();
        fn view(binding: u32, t: &crate::targets::Target) -> wgpu::BindGroupEntry<'_> {
            wgpu::BindGroupEntry { binding, resource: wgpu::BindingResource::TextureView(&t.view) }
        }
        let entries = [
            b0,
            b1,
            wgpu::BindGroupEntry { binding: 2, resource: self.params.as_entire_binding() },
            view(3, &targets.position),
            view(4, &targets.normal),
            view(5, &targets.diffuse),
            view(6, &targets.specular),
            view(7, &targets.optical),
            view(8, &targets.object_id),
            view(9, &targets.mask),
            view(10, &targets.shadow),
            view(11, &targets.reflection),
            view(12, &targets.refraction),
            wgpu::BindGroupEntry { binding: 13, resource: self.counts.as_entire_binding() },
        ];
        // Bind groups reference the frame's targets, which change with the frame size.
        let bind_group =
            self.device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some("trace"), layout: &self.layout, entries: &entries });
        encoder.clear_buffer(&self.counts, 0, None);
        let groups = (targets.width.div_ceil(WORKGROUP), targets.height.div_ceil(WORKGROUP));
        for (label, pipeline) in
            [("trace.shadow", &self.shadow), ("trace.reflection", &self.reflection), ("trace.refraction", &self.refraction)]
        {
            let mut pass = encoder
                .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some(label), timestamp_writes: timer.compute(Stage::Trace) });
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, &scene.bind_group, &[]);
            pass.set_bind_group(1, &bind_group, &[]);
            pass.set_bind_group(2, &self.spheres, &[]);
            if let Some(rt) = &self.rt {
                pass.set_bind_group(3, rt, &[]);
            }
            pass.dispatch_workgroups(groups.0, groups.1, 1);
        }
        encoder.copy_buffer_to_buffer(&self.counts, 0, &self.counts_readback, 0, 16);
    }

    /// Rays traced by the last submitted [`Self::encode`] (waits for the GPU).
    pub fn read_ray_counts(&self, ctx: &GpuContext) -> Result<RayCounts, GpuError> {
        let bytes = read_buffer(ctx, &self.counts_readback)?;
        let c: [u32; 4] = bytemuck::pod_read_unaligned(&bytes[..16]);
        Ok(RayCounts { primary: 0, shadow: c[0] as u64, reflection: c[1] as u64, refraction: c[2] as u64 })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shaders::{validate, with_common};

    #[test]
    fn trace_wgsl_is_valid() {
        if let Err(e) = validate(&with_common(&format!("{BVH_WGSL}\n{SPHERES_WGSL}\n{TRACE_WGSL}"))) {
            panic!("{e}");
        }
    }
}
