//! `accel`: the hardware ray-tracing path (paper 1 traces with OptiX, paper 2 with Vulkan RT
//! cores): wgpu ray queries over acceleration structures, where the adapter offers them
//! (`GpuContext::ray_query`). The software BVH2 traversal (`bvh`, `spheres`) stays the portable
//! path; [`RtChoice`] picks one per renderer.
//!
//! [`RtScene`] builds, once per scene:
//! - one bottom-level structure (BLAS) per mesh over its world-space triangles (the prepared
//!   meshes are already in world space, so every instance has the identity transform; the
//!   instance's custom data is the mesh index). A triangle with a non-finite corner points at an
//!   extra vertex of NaNs, which makes it inactive (never hit), as the software test never hits it;
//! - one BLAS of AABB (procedural) geometry over every sphere of every point cloud, in the
//!   sphere BVH's slot order (primitive index = slot), intersected in the shader by the software
//!   path's own sphere test (`shaders/spheres_rq.wgsl`, paper 2's intersection shader as a ray
//!   query);
//! - the top-level structure (TLAS) of those instances, masked: [`RT_MASK_SHADOW_CASTERS`] for
//!   meshes whose material casts shadows, [`RT_MASK_NO_SHADOW`] for the others,
//!   [`RT_MASK_SPHERES`] for the spheres; the triangle queries use [`RT_MASK_TRIANGLES`].
//!
//! Bound as group 3 (`shaders/rq.wgsl`) with each mesh's shadow transparency. The passes' hardware
//! variants (`trace`, `primary`, `capsule`) swap `bvh.wgsl` for `bvh_rq.wgsl` and the spheres'
//! traversal for `spheres_rq.wgsl`: the same functions, so the passes' own WGSL is unchanged.

use std::time::Instant;

use hybrid_core::PreparedScene;

use crate::context::{GpuContext, GpuError, ray_query_missing};
use crate::scene::SceneGpu;
use crate::spheres::SpheresGpu;

/// Group 3's declarations and the hardware triangle traversal (after common/*.wgsl; the module
/// starts with `enable wgpu_ray_query;`, see `shaders::module_rq`).
pub const RQ_WGSL: &str = concat!(include_str!("shaders/rq.wgsl"), include_str!("shaders/bvh_rq.wgsl"));

/// Instance mask of meshes that cast shadows (shadow queries see only these).
pub const RT_MASK_SHADOW_CASTERS: u32 = 1;
/// Instance mask of the spheres.
pub const RT_MASK_SPHERES: u32 = 2;
/// Instance mask of meshes that cast no shadows (transparency 1: ignored by shadow rays).
pub const RT_MASK_NO_SHADOW: u32 = 4;
/// Cull mask of closest-hit triangle queries: every mesh.
pub const RT_MASK_TRIANGLES: u32 = RT_MASK_SHADOW_CASTERS | RT_MASK_NO_SHADOW;

/// Which traversal the GPU backend traces with (`--rt`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RtChoice {
    /// Hardware where the adapter has ray queries, else software.
    #[default]
    Auto,
    /// Hardware; an adapter without ray queries is an error.
    Hardware,
    /// The software BVH2 traversal in WGSL (every adapter).
    Software,
}

impl RtChoice {
    /// `auto`, `hw` or `sw`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "auto" => Some(Self::Auto),
            "hw" => Some(Self::Hardware),
            "sw" => Some(Self::Software),
            _ => None,
        }
    }

    /// Whether `ctx` traces in hardware under this choice: `Ok(None)` for software, with the
    /// reason where `auto` fell back; `Err` when `hw` was asked of an adapter without ray queries.
    ///
    /// `auto` leaves a CPU adapter (lavapipe, SwiftShader, WARP) on the software path even when it
    /// offers ray queries: there they are a traversal on the same CPU, measured 1.1-31x slower
    /// than the WGSL BVH on lavapipe (BENCHMARKS.md); `--rt hw` still uses them.
    pub fn resolve(self, ctx: &GpuContext) -> Result<RtPath, GpuError> {
        let missing = if ctx.ray_query { None } else { Some(ray_query_missing(&ctx.adapter).unwrap_or_else(|| "no ray queries".into())) };
        let cpu_adapter = ctx.adapter.get_info().device_type == wgpu::DeviceType::Cpu;
        self.decide(missing, cpu_adapter).map_err(|why| GpuError::Unsupported { adapter: ctx.summary.name.clone(), why })
    }

    /// [`RtChoice::resolve`]'s rule: `missing` is why the adapter has no ray queries (`None`
    /// when it has them), `cpu_adapter` whether it is a software adapter running on the CPU.
    fn decide(self, missing: Option<String>, cpu_adapter: bool) -> Result<RtPath, String> {
        match (self, missing) {
            (Self::Software, _) => Ok(RtPath { hardware: false, why: "--rt sw".into() }),
            (Self::Auto, None) if cpu_adapter => Ok(RtPath {
                hardware: false,
                why: "a CPU adapter's ray queries run on the CPU and are slower than the software BVH; --rt hw uses them".into(),
            }),
            (_, None) => Ok(RtPath { hardware: true, why: "the adapter has ray queries".into() }),
            (Self::Auto, Some(why)) => Ok(RtPath { hardware: false, why }),
            (Self::Hardware, Some(why)) => Err(format!("no hardware ray tracing: {why}")),
        }
    }
}

/// The traversal a renderer uses, and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RtPath {
    pub hardware: bool,
    pub why: String,
}

impl RtPath {
    /// "hw" or "sw" (reports).
    pub fn name(&self) -> &'static str {
        if self.hardware { "hw" } else { "sw" }
    }
}

/// The scene's acceleration structures and group 3.
pub struct RtScene {
    pub layout: wgpu::BindGroupLayout,
    pub bind_group: wgpu::BindGroup,
    /// Milliseconds from the first BLAS created to the build's completion on the device (the
    /// build's own submission, waited for).
    pub build_ms: f64,
    /// Instances in the TLAS (meshes with triangles, plus one for the spheres).
    pub instances: u32,
    // Kept alive while the bind group refers to them.
    _tlas: wgpu::Tlas,
    _blases: Vec<wgpu::Blas>,
    _buffers: Vec<wgpu::Buffer>,
}

impl RtScene {
    /// Builds every BLAS and the TLAS for `scene` (its meshes) and `spheres` (their AABBs, built
    /// by `SpheresGpu` on devices with ray queries), submits the build and waits for it.
    pub fn new(ctx: &GpuContext, scene: &SceneGpu, prepared: &PreparedScene, spheres: &SpheresGpu) -> Result<Self, GpuError> {
        use wgpu::util::DeviceExt;
        let device = &ctx.device;
        let start = Instant::now();
        let too_large = |why: String| GpuError::TooLarge { adapter: ctx.summary.name.clone(), why };
        let limits = device.limits();

        // Positions (Float32x3) with one vertex of NaNs at the end for inactive triangles.
        let vertices = &scene.host_vertices;
        let nan_vertex = vertices.len() as u32;
        let mut positions: Vec<[f32; 3]> = vertices.iter().map(|v| [v.position[0], v.position[1], v.position[2]]).collect();
        positions.push([f32::NAN; 3]);
        let indices: Vec<u32> = scene
            .host_triangles
            .iter()
            .flat_map(|t| {
                let finite = t.v.iter().all(|&i| vertices[i as usize].position[..3].iter().all(|c| c.is_finite()));
                if finite { t.v } else { [nan_vertex; 3] }
            })
            .collect();
        let blas_input = |label, contents: &[u8]| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::BLAS_INPUT,
            })
        };
        let position_buffer = blas_input("rt.positions", bytemuck::cast_slice(&positions));
        let index_buffer = blas_input("rt.indices", bytemuck::cast_slice(if indices.is_empty() { &[0u32; 3][..] } else { &indices }));

        // Per mesh: its triangles' range and its shadow class.
        let mesh_count = prepared.meshes.len();
        if mesh_count >= 1 << 24 {
            return Err(too_large(format!("{mesh_count} meshes: an instance's custom index holds 24 bits")));
        }
        let mut ranges = vec![(0u32, 0u32); mesh_count];
        for (i, t) in scene.host_triangles.iter().enumerate() {
            let r = &mut ranges[t.mesh as usize];
            if r.1 == 0 {
                r.0 = i as u32;
            }
            r.1 += 1;
        }
        let mesh_shadow: Vec<f32> = (0..mesh_count).map(|m| prepared.mesh_shadow(m)).collect();

        let flags = wgpu::AccelerationStructureGeometryFlags::NO_DUPLICATE_ANY_HIT_INVOCATION;
        let blas_desc = |label| wgpu::CreateBlasDescriptor {
            label: Some(label),
            flags: wgpu::AccelerationStructureFlags::PREFER_FAST_TRACE,
            update_mode: wgpu::AccelerationStructureUpdateMode::Build,
        };
        // (mesh, size) of every mesh with triangles.
        let mut sizes = Vec::new();
        for (mesh, &(_, count)) in ranges.iter().enumerate() {
            if count == 0 {
                continue;
            }
            if count > limits.max_blas_primitive_count {
                return Err(too_large(format!(
                    "mesh {mesh} has {count} triangles, a BLAS holds at most {}",
                    limits.max_blas_primitive_count
                )));
            }
            let size = wgpu::BlasTriangleGeometrySizeDescriptor {
                vertex_format: wgpu::VertexFormat::Float32x3,
                vertex_count: positions.len() as u32,
                index_format: Some(wgpu::IndexFormat::Uint32),
                index_count: Some(count * 3),
                flags,
            };
            sizes.push((mesh, size));
        }
        let mesh_blases: Vec<wgpu::Blas> = sizes
            .iter()
            .map(|(_, size)| {
                device.create_blas(&blas_desc("rt.mesh"), wgpu::BlasGeometrySizeDescriptors::Triangles { descriptors: vec![size.clone()] })
            })
            .collect();

        let sphere_size = match &spheres.aabbs {
            Some(_) if spheres.count > limits.max_blas_primitive_count => {
                return Err(too_large(format!("{} spheres, a BLAS holds at most {}", spheres.count, limits.max_blas_primitive_count)));
            }
            Some(_) => Some(wgpu::BlasAABBGeometrySizeDescriptor { primitive_count: spheres.count, flags }),
            None => None,
        };
        let sphere_blas = sphere_size.as_ref().map(|size| {
            device.create_blas(&blas_desc("rt.spheres"), wgpu::BlasGeometrySizeDescriptors::AABBs { descriptors: vec![size.clone()] })
        });

        let instances = mesh_blases.len() + usize::from(sphere_blas.is_some());
        if instances as u64 > limits.max_tlas_instance_count as u64 {
            return Err(too_large(format!("{instances} instances, a TLAS holds at most {}", limits.max_tlas_instance_count)));
        }
        let mut tlas = device.create_tlas(&wgpu::CreateTlasDescriptor {
            label: Some("rt.tlas"),
            max_instances: instances.max(1) as u32,
            flags: wgpu::AccelerationStructureFlags::PREFER_FAST_TRACE,
            update_mode: wgpu::AccelerationStructureUpdateMode::Build,
        });
        const IDENTITY: [f32; 12] = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0];
        for (k, ((mesh, _), blas)) in sizes.iter().zip(&mesh_blases).enumerate() {
            let mask = if mesh_shadow[*mesh] == 1.0 { RT_MASK_NO_SHADOW } else { RT_MASK_SHADOW_CASTERS };
            tlas[k] = Some(wgpu::TlasInstance::new(blas, IDENTITY, *mesh as u32, mask as u8));
        }
        if let Some(blas) = &sphere_blas {
            tlas[mesh_blases.len()] = Some(wgpu::TlasInstance::new(blas, IDENTITY, 0, RT_MASK_SPHERES as u8));
        }

        let mut entries: Vec<wgpu::BlasBuildEntry<'_>> = sizes
            .iter()
            .zip(&mesh_blases)
            .map(|((mesh, size), blas)| wgpu::BlasBuildEntry {
                blas,
                geometry: wgpu::BlasGeometries::TriangleGeometries(vec![wgpu::BlasTriangleGeometry {
                    size,
                    vertex_buffer: &position_buffer,
                    first_vertex: 0,
                    vertex_stride: 12,
                    index_buffer: Some(&index_buffer),
                    first_index: Some(ranges[*mesh].0 * 3),
                    transform_buffer: None,
                    transform_buffer_offset: None,
                }]),
            })
            .collect();
        if let (Some(blas), Some(size), Some(aabbs)) = (&sphere_blas, &sphere_size, &spheres.aabbs) {
            entries.push(wgpu::BlasBuildEntry {
                blas,
                geometry: wgpu::BlasGeometries::AabbGeometries(vec![wgpu::BlasAabbGeometry {
                    size,
                    stride: wgpu::AABB_GEOMETRY_MIN_STRIDE,
                    aabb_buffer: aabbs,
                    primitive_offset: 0,
                }]),
            });
        }
        let mut encoder =
            device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("rt: build acceleration structures") });
        encoder.build_acceleration_structures(entries.iter(), [&tlas]);
        ctx.queue.submit([encoder.finish()]);
        ctx.wait()?;
        let build_ms = start.elapsed().as_secs_f64() * 1e3;

        let shadow_buffer = ctx.storage_buffer("rt.mesh_shadow", bytemuck::cast_slice(&mesh_shadow))?;
        let layout = Self::create_layout(device);
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("rt"),
            layout: &layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::AccelerationStructure(&tlas) },
                wgpu::BindGroupEntry { binding: 1, resource: shadow_buffer.as_entire_binding() },
            ],
        });
        let mut blases = mesh_blases;
        blases.extend(sphere_blas);
        Ok(Self {
            layout,
            bind_group,
            build_ms,
            instances: instances as u32,
            _tlas: tlas,
            _blases: blases,
            _buffers: vec![position_buffer, index_buffer, shadow_buffer],
        })
    }

    /// Group 3: binding 0 the TLAS, 1 the meshes' shadow transparencies (compute and fragment).
    pub fn create_layout(device: &wgpu::Device) -> wgpu::BindGroupLayout {
        let visibility = wgpu::ShaderStages::COMPUTE | wgpu::ShaderStages::FRAGMENT;
        device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("rt"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility,
                    ty: wgpu::BindingType::AccelerationStructure { vertex_return: false },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only: true },
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
            ],
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bvh::BVH_WGSL;
    use crate::primary::PRIMARY_WGSL;
    use crate::shaders::{validate, with_common_rq};
    use crate::spheres::{SPHERES_RQ_WGSL, SPHERES_WGSL};
    use crate::trace::TRACE_WGSL;

    /// The hardware variants of every pass that traces parse and validate with naga (as wgpu
    /// would on a device with ray queries).
    #[test]
    fn hardware_variants_are_valid() {
        let sources = [
            ("trace", format!("{RQ_WGSL}\n{SPHERES_RQ_WGSL}\n{TRACE_WGSL}")),
            ("primary", format!("{RQ_WGSL}\n{PRIMARY_WGSL}")),
            ("capsule", format!("{RQ_WGSL}\n{SPHERES_RQ_WGSL}\n{}", crate::capsule::CAPSULE_WGSL)),
        ];
        for (name, source) in sources {
            if let Err(e) = validate(&with_common_rq(&source)) {
                panic!("{name}: {e}");
            }
        }
    }

    /// The software variants never see ray-query code (adapters without the feature compile
    /// them), and the hardware ones never the software traversal they replace.
    #[test]
    fn variants_stay_apart() {
        for sw in [BVH_WGSL, SPHERES_WGSL, TRACE_WGSL, PRIMARY_WGSL, crate::capsule::CAPSULE_WGSL] {
            assert!(!sw.contains("ray_query") && !sw.contains("rayQuery") && !sw.contains("acceleration_structure"));
        }
        assert!(!SPHERES_RQ_WGSL.contains("sphere_nodes[") && !RQ_WGSL.contains("bvh_nodes"));
        assert!(SPHERES_RQ_WGSL.contains("rayQueryGenerateIntersection") && RQ_WGSL.contains("rayQueryProceed"));
    }

    #[test]
    fn masks_split_casters_spheres_and_the_rest() {
        assert_eq!(RT_MASK_SHADOW_CASTERS & RT_MASK_SPHERES, 0);
        assert_eq!(RT_MASK_NO_SHADOW & (RT_MASK_SHADOW_CASTERS | RT_MASK_SPHERES), 0);
        assert_eq!(RT_MASK_TRIANGLES & RT_MASK_SPHERES, 0);
        assert_eq!(RtChoice::parse("hw"), Some(RtChoice::Hardware));
        assert_eq!(RtChoice::parse("auto"), Some(RtChoice::Auto));
        assert_eq!(RtChoice::parse("sw"), Some(RtChoice::Software));
        assert_eq!(RtChoice::parse("rtx"), None);
    }

    #[test]
    fn auto_takes_ray_queries_on_gpus_only() {
        // hw takes ray queries anywhere, sw never, auto on a GPU only (not a CPU adapter).
        let has = || None::<String>;
        let lacks = || Some("no ray queries".to_string());
        assert!(RtChoice::Auto.decide(has(), false).unwrap().hardware);
        assert!(!RtChoice::Auto.decide(has(), true).unwrap().hardware);
        assert!(RtChoice::Auto.decide(has(), true).unwrap().why.contains("CPU adapter"));
        assert!(!RtChoice::Auto.decide(lacks(), false).unwrap().hardware);
        assert!(RtChoice::Hardware.decide(has(), true).unwrap().hardware);
        assert!(RtChoice::Hardware.decide(lacks(), false).unwrap_err().contains("no ray queries"));
        assert!(!RtChoice::Software.decide(has(), false).unwrap().hardware);
    }
}
