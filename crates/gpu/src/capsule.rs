//! `capsule`: paper 2 on the GPU (design §5). Stage 0 is one compute pass (`capsule.wgsl`, 8×8
//! workgroups): per pixel the CPU capsule's primary ray (`hybrid_cpu::camera_rays::RayGen`, bit for
//! bit from the frame uniforms' `raygen_*`), the closest sphere (`spheres.wgsl`), Blinn–Phong with
//! the scene's lights and ambient, block D and block P into `targets.packed` (RGBA16UI). Block U
//! (`unpack.wgsl`) is a render pass that clears the G-buffer and depth and writes each kept RT
//! texel's surface and depth; the raster pass then depth-tests its polygons against it.
//!
//! Beyond the CPU capsule's options: `clip_depth` (rays stopping at the raster's depth) is not
//! used, since the frame runs the capsule before the raster pass (design §1 order), so there is no
//! polygon depth yet when the capsule traces.

use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

use hybrid_core::Stage;
use hybrid_core::report::CapsuleReport;

use crate::accel::{RQ_WGSL, RtScene};
use crate::context::{GpuContext, GpuError};
use crate::readback::read_buffer;
use crate::scene::SceneGpu;
use crate::shaders;
use crate::spheres::{SPHERES_RQ_WGSL, SPHERES_WGSL, SpheresGpu};
use crate::targets::{FrameTargets, PACKED_FORMAT, begin_gbuffer_pass, gbuffer_pipeline};
use crate::timing::StageTimer;

/// The capsule pass's WGSL (after common/*.wgsl and spheres.wgsl).
pub const CAPSULE_WGSL: &str = include_str!("shaders/capsule.wgsl");
/// The unpack pass's WGSL (after common/*.wgsl).
pub const UNPACK_WGSL: &str = include_str!("shaders/unpack.wgsl");

/// The capsule's full source: spheres.wgsl then capsule.wgsl (common/*.wgsl is prepended by
/// `shaders::module`).
pub fn capsule_source() -> String {
    format!("{SPHERES_WGSL}\n{CAPSULE_WGSL}")
}

/// Stage 0 (blocks D + P) and block U on the GPU.
pub struct GpuCapsule {
    device: wgpu::Device,
    /// Group 3 of the hardware variant; `None`: the software sphere BVH.
    rt: Option<wgpu::BindGroup>,
    trace_pipeline: wgpu::ComputePipeline,
    /// The same pass with rays stopped at the polygon depth (`CLIP = true`).
    clipped_pipeline: wgpu::ComputePipeline,
    trace_layout: wgpu::BindGroupLayout,
    unpack_pipeline: wgpu::RenderPipeline,
    unpack_layout: wgpu::BindGroupLayout,
    /// Per pixel the global id of the sphere the trace hit (u32::MAX: miss), grown with the frame.
    hit_ids: Mutex<Option<wgpu::Buffer>>,
    points: u64,
    build_ms: f64,
    /// Pixels (primary rays) of the last encoded frame.
    rays: AtomicU64,
}

impl GpuCapsule {
    pub fn new(ctx: &GpuContext, scene: &SceneGpu, spheres: &SpheresGpu) -> Self {
        Self::new_rt(ctx, scene, spheres, None)
    }

    /// As [`GpuCapsule::new`]; with `rt`, the hardware variant: the spheres are found by ray
    /// queries over `rt`'s AABB geometry (group 3), hit by the same sphere test.
    pub fn new_rt(ctx: &GpuContext, scene: &SceneGpu, spheres: &SpheresGpu, rt: Option<&RtScene>) -> Self {
        let device = &ctx.device;
        let trace_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("capsule.targets"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::StorageTexture {
                        access: wgpu::StorageTextureAccess::WriteOnly,
                        format: PACKED_FORMAT,
                        view_dimension: wgpu::TextureViewDimension::D2,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only: false },
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
                // The polygons' reversed-Z depth, read only by the clipped pipeline.
                wgpu::BindGroupLayoutEntry {
                    binding: 2,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Depth,
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
            ],
        });
        let module = match rt {
            None => shaders::module(device, "capsule", &capsule_source()),
            Some(_) => shaders::module_rq(device, "capsule.hw", &format!("{RQ_WGSL}\n{SPHERES_RQ_WGSL}\n{CAPSULE_WGSL}")),
        };
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("capsule"),
            bind_group_layouts: &[Some(&scene.layout), Some(&trace_layout), Some(&spheres.layout), rt.map(|rt| &rt.layout)],
            immediate_size: 0,
        });
        let pipeline = |label: &str, clip: f64| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(label),
                layout: Some(&layout),
                module: &module,
                entry_point: Some("capsule_main"),
                compilation_options: wgpu::PipelineCompilationOptions { constants: &[("CLIP", clip)], ..Default::default() },
                cache: None,
            })
        };
        let trace_pipeline = pipeline("capsule", 0.0);
        let clipped_pipeline = pipeline("capsule.clipped", 1.0);

        let unpack_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("capsule.unpack"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Uint,
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                },
                count: None,
            }],
        });
        let unpack_module = shaders::module(device, "capsule.unpack", UNPACK_WGSL);
        let unpack_pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("capsule.unpack"),
            bind_group_layouts: &[Some(&scene.layout), Some(&unpack_layout)],
            immediate_size: 0,
        });
        let unpack_pipeline = gbuffer_pipeline(device, "capsule.unpack", &unpack_pl, &unpack_module, "unpack_vs", "unpack_fs");
        let points = spheres.count as u64;
        Self {
            device: device.clone(),
            rt: rt.map(|rt| rt.bind_group.clone()),
            trace_pipeline,
            clipped_pipeline,
            trace_layout,
            unpack_pipeline,
            unpack_layout,
            hit_ids: Mutex::new(None),
            points,
            build_ms: spheres.build_ms,
            rays: AtomicU64::new(0),
        }
    }

    /// The hit-id buffer, at least `pixels` long.
    fn hit_ids(&self, pixels: u64) -> wgpu::Buffer {
        let mut slot = self.hit_ids.lock().unwrap_or_else(|e| e.into_inner());
        let size = pixels.max(1) * 4;
        if let Some(b) = slot.as_ref().filter(|b| b.size() >= size) {
            return b.clone();
        }
        let b = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("capsule.hit_ids"),
            size,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        *slot = Some(b.clone());
        b
    }

    /// Stage 0, blocks D + P: traces one ray per pixel through the spheres and writes
    /// `targets.packed` (the frame uniforms must hold this frame's camera and size).
    /// `clip_at_depth` (beyond paper 2): each ray stops at the polygon depth already in
    /// `targets.depth` (the raster ran first), as the CPU capsule's `clip_depth`.
    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        scene: &SceneGpu,
        spheres: &SpheresGpu,
        targets: &FrameTargets,
        clip_at_depth: bool,
        timer: &mut StageTimer,
    ) {
        let pixels = targets.width as u64 * targets.height as u64;
        self.rays.store(pixels, Ordering::Relaxed);
        let ids = self.hit_ids(pixels);
        self.encode_with_ids(encoder, scene, spheres, targets, clip_at_depth, &ids, timer);
    }

    /// As [`Self::encode`], the hit ids into `ids` (at least 4 bytes per pixel of `targets`),
    /// leaving the frame's hit ids and ray count alone: the fallbacks' probe faces trace the
    /// capsule at their own size.
    #[allow(clippy::too_many_arguments)]
    pub fn encode_with_ids(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        scene: &SceneGpu,
        spheres: &SpheresGpu,
        targets: &FrameTargets,
        clip_at_depth: bool,
        ids: &wgpu::Buffer,
        timer: &mut StageTimer,
    ) {
        let bind_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("capsule.targets"),
            layout: &self.trace_layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::TextureView(&targets.packed.view) },
                wgpu::BindGroupEntry { binding: 1, resource: ids.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::TextureView(&targets.depth.view) },
            ],
        });
        let mut pass = encoder
            .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("capsule"), timestamp_writes: timer.compute(Stage::Capsule) });
        pass.set_pipeline(if clip_at_depth { &self.clipped_pipeline } else { &self.trace_pipeline });
        pass.set_bind_group(0, &scene.bind_group, &[]);
        pass.set_bind_group(1, &bind_group, &[]);
        pass.set_bind_group(2, &spheres.bind_group, &[]);
        if let Some(rt) = &self.rt {
            pass.set_bind_group(3, rt, &[]);
        }
        pass.dispatch_workgroups(targets.width.div_ceil(8), targets.height.div_ceil(8), 1);
    }

    /// Block U: writes every RT texel with alpha > 0.1 as the RT surface with its depth
    /// (compare Greater). `clear = true` (paper 2's order) clears the G-buffer (object id to
    /// `NO_OBJECT`, the rest 0) and the depth (0, reversed-Z far) first, and the raster pass follows
    /// with `clear = false`; `clear = false` merges into the polygons already drawn (clipped order).
    pub fn encode_unpack(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        scene: &SceneGpu,
        targets: &FrameTargets,
        clear: bool,
        timer: &mut StageTimer,
    ) {
        let bind_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("capsule.unpack"),
            layout: &self.unpack_layout,
            entries: &[wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::TextureView(&targets.packed.view) }],
        });
        let mut pass = begin_gbuffer_pass(encoder, targets, clear, "capsule.unpack", timer.render(Stage::Capsule));
        pass.set_pipeline(&self.unpack_pipeline);
        pass.set_bind_group(0, &scene.bind_group, &[]);
        pass.set_bind_group(1, &bind_group, &[]);
        pass.draw(0..3, 0..1);
    }

    /// Points, build time and the last frame's rays for the frame report (the GPU times come
    /// from the stage timer, so trace/pack/unpack ms are 0 here).
    pub fn report(&self) -> CapsuleReport {
        CapsuleReport {
            points: self.points,
            build_ms: self.build_ms,
            trace_ms: 0.0,
            pack_ms: 0.0,
            unpack_ms: 0.0,
            rays: self.rays.load(Ordering::Relaxed),
        }
    }

    /// Per pixel of the last traced frame (after its submission; waits for the GPU), the global
    /// id of the sphere hit (cloud offset + point index, clouds in scene order), `u32::MAX` on a
    /// miss: which sphere each packed texel shows (tests, debugging).
    pub fn read_hit_ids(&self, ctx: &GpuContext) -> Result<Vec<u32>, GpuError> {
        let pixels = self.rays.load(Ordering::Relaxed);
        let ids = self.hit_ids(pixels);
        let staging = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("capsule.hit_ids.readback"),
            size: pixels.max(1) * 4,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("capsule.hit_ids") });
        encoder.copy_buffer_to_buffer(&ids, 0, &staging, 0, pixels.max(1) * 4);
        ctx.queue.submit([encoder.finish()]);
        let bytes = read_buffer(ctx, &staging)?;
        let mut v: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes);
        v.truncate(pixels as usize);
        Ok(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shaders::{validate, with_common};

    #[test]
    fn capsule_wgsl_is_valid() {
        if let Err(e) = validate(&with_common(&capsule_source())) {
            panic!("{e}");
        }
    }

    #[test]
    fn unpack_wgsl_is_valid() {
        if let Err(e) = validate(&with_common(UNPACK_WGSL)) {
            panic!("{e}");
        }
    }
}
