//! `spheres`: the RT-scene's spheres on the GPU (paper 2, design §5) as bind group 2: every
//! point of every point cloud as a sphere of its cloud's radius, coloured by the rule both
//! backends share (`hybrid_core::point_colors`: file colours, the cloud's colour or the height
//! colour map, evaluated on the host, so albedos are bit-identical), under an obvhs BVH2 built on the CPU over
//! the spheres' boxes and flattened to storage buffers.
//!
//! `shaders/spheres.wgsl` declares the group and traces it (`sphere_closest_hit`,
//! `sphere_any_hit`, `sphere_surface`): the capsule's primary rays, and the trace stage's shadow,
//! reflection and refraction rays. One BVH holds all clouds; spheres keep a global index (cloud
//! offset + point index) and ties in `t` go to the lower one, as the CPU's per-cloud loop does.

use std::time::Instant;

use bytemuck::{Pod, Zeroable};
use glam::Vec3A;
use hybrid_core::point_colors::PointColors;
use hybrid_scene::PointCloud;
use obvhs::BvhBuildParams;
use obvhs::aabb::Aabb;
use obvhs::bvh2::builder::build_bvh2;
use wgpu::util::DeviceExt;

use crate::context::{GpuContext, GpuError};

/// The WGSL of group 2 with the software traversal (include it after common/*.wgsl:
/// `shaders::with_common(&format!("{SPHERES_WGSL}\n{pass}"))`).
pub const SPHERES_WGSL: &str = concat!(include_str!("shaders/spheres.wgsl"), include_str!("shaders/spheres_bvh.wgsl"));

/// The WGSL of group 2 with the hardware traversal (after common/*.wgsl and `accel::RQ_WGSL`).
pub const SPHERES_RQ_WGSL: &str = concat!(include_str!("shaders/spheres.wgsl"), include_str!("shaders/spheres_rq.wgsl"));

/// Traversal stack entries in spheres.wgsl (`SPHERE_STACK`); the tree's depth must stay below it.
pub const STACK: u32 = 64;

/// `struct SphereInfo`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct GpuSphereInfo {
    pub count: u32,
    pub nodes: u32,
    pub clouds: u32,
    pub _pad: u32,
}

/// `struct SphereNode`: inner when `count` is 0 (children at `first`, `first + 1`), else a leaf
/// of `count` spheres from slot `first`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable, PartialEq)]
pub struct GpuSphereNode {
    pub min: [f32; 3],
    pub first: u32,
    pub max: [f32; 3],
    pub count: u32,
}

/// `struct Sphere`: centre, radius, linear albedo, cloud index.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable, PartialEq)]
pub struct GpuSphere {
    pub center: [f32; 3],
    pub radius: f32,
    pub albedo: [f32; 3],
    pub cloud: u32,
}

/// The spheres on the GPU: bind group 2 of the capsule and trace passes.
pub struct SpheresGpu {
    pub layout: wgpu::BindGroupLayout,
    pub bind_group: wgpu::BindGroup,
    /// Spheres (points over all clouds).
    pub count: u32,
    pub info: wgpu::Buffer,
    pub nodes: wgpu::Buffer,
    pub spheres: wgpu::Buffer,
    pub ids: wgpu::Buffer,
    pub clouds: wgpu::Buffer,
    /// BVH nodes.
    pub node_count: u32,
    /// Levels of the tree (root = 1).
    pub depth: u32,
    /// Host time to colour the spheres, build the BVH and flatten it (not the upload).
    pub build_ms: f64,
    /// Bytes uploaded (nodes, spheres, ids, clouds).
    pub bytes: u64,
    /// Where the device has ray queries: each sphere's box in slot order (min xyz, max xyz, padded
    /// by [`AABB_PAD`]), the AABB geometry of the hardware path's acceleration structure.
    pub aabbs: Option<wgpu::Buffer>,
}

/// Relative padding of the spheres' boxes in the acceleration structure (of radius + |centre|):
/// the hardware's box test may cull a ray that only grazes a box; a padded box only adds
/// candidates, which the exact sphere test then refuses.
pub const AABB_PAD: f32 = 1e-4;

/// The spheres' padded boxes in slot order, six floats each (what `SpheresGpu::aabbs` holds).
pub fn sphere_boxes(spheres: &[GpuSphere]) -> Vec<[f32; 6]> {
    spheres
        .iter()
        .map(|s| {
            let c = s.center;
            let pad = s.radius + AABB_PAD * (s.radius + c[0].abs().max(c[1].abs()).max(c[2].abs()));
            [c[0] - pad, c[1] - pad, c[2] - pad, c[0] + pad, c[1] + pad, c[2] + pad]
        })
        .collect()
}

/// The spheres in leaf order with their global ids, the flattened BVH, and per-cloud constants:
/// what [`SpheresGpu::new`] uploads (host side, testable without a device).
#[derive(Debug, Clone, Default)]
pub struct SphereData {
    pub nodes: Vec<GpuSphereNode>,
    pub spheres: Vec<GpuSphere>,
    pub ids: Vec<u32>,
    pub clouds: Vec<[f32; 4]>,
    pub depth: u32,
}

impl SphereData {
    /// Colours every point and builds the BVH (obvhs BVH2, `fast_build`) over the spheres' boxes.
    pub fn build(clouds: &[PointCloud]) -> Result<Self, String> {
        let total: usize = clouds.iter().map(|c| c.points.len()).sum();
        if total >= u32::MAX as usize {
            return Err(format!("{total} spheres: at most {} fit", u32::MAX - 1));
        }
        let mut all = Vec::with_capacity(total);
        let mut aabbs = Vec::with_capacity(total);
        let mut cloud_consts = Vec::with_capacity(clouds.len());
        for (ci, pc) in clouds.iter().enumerate() {
            if !(pc.radius.is_finite() && pc.radius > 0.0) {
                return Err(format!("point cloud `{}`: sphere radius {} must be finite and > 0", pc.name, pc.radius));
            }
            if let Some(i) = pc.points.iter().position(|p| !p.is_finite()) {
                return Err(format!("point cloud `{}`: point {i} has a non-finite centre", pc.name));
            }
            cloud_consts.push(pc.specular.extend(pc.shininess).to_array());
            let r = Vec3A::splat(pc.radius);
            for (p, a) in pc.points.iter().zip(PointColors::albedos(pc)) {
                all.push(GpuSphere { center: p.to_array(), radius: pc.radius, albedo: a.to_array(), cloud: ci as u32 });
                let c = Vec3A::from(*p);
                aabbs.push(Aabb::new(c - r, c + r));
            }
        }
        if all.is_empty() {
            return Ok(Self { clouds: cloud_consts, ..Default::default() });
        }
        let mut core = std::time::Duration::ZERO;
        let bvh = build_bvh2(&aabbs, BvhBuildParams::fast_build(), &mut core);
        // Spheres in leaf order: each leaf's primitives become a contiguous run of slots.
        let mut nodes = Vec::with_capacity(bvh.nodes.len());
        let mut spheres = Vec::with_capacity(all.len());
        let mut ids = Vec::with_capacity(all.len());
        for n in &bvh.nodes {
            let (first, count) = if n.is_leaf() {
                let start = spheres.len() as u32;
                for k in 0..n.prim_count {
                    let orig = bvh.primitive_indices[(n.first_index + k) as usize];
                    spheres.push(all[orig as usize]);
                    ids.push(orig);
                }
                (start, n.prim_count)
            } else {
                (n.first_index, 0)
            };
            nodes.push(GpuSphereNode { min: n.aabb.min.to_array(), first, max: n.aabb.max.to_array(), count });
        }
        if spheres.len() != all.len() {
            return Err(format!("the sphere BVH holds {} of {} spheres", spheres.len(), all.len()));
        }
        let depth = tree_depth(&nodes);
        if depth > STACK {
            return Err(format!("the sphere BVH is {depth} levels deep; the GPU traversal stack holds {STACK}"));
        }
        Ok(Self { nodes, spheres, ids, clouds: cloud_consts, depth })
    }
}

/// Levels of the tree rooted at node 0.
fn tree_depth(nodes: &[GpuSphereNode]) -> u32 {
    let mut max = 0;
    let mut stack = vec![(0u32, 1u32)];
    while let Some((i, d)) = stack.pop() {
        max = max.max(d);
        let n = nodes[i as usize];
        if n.count == 0 {
            stack.push((n.first, d + 1));
            stack.push((n.first + 1, d + 1));
        }
    }
    max
}

impl SpheresGpu {
    /// Every point of every cloud as a sphere, under a BVH built on the CPU, uploaded.
    pub fn new(ctx: &GpuContext, clouds: &[PointCloud]) -> Result<Self, GpuError> {
        let start = Instant::now();
        let data = SphereData::build(clouds).map_err(|why| GpuError::TooLarge { adapter: ctx.summary.name.clone(), why })?;
        let build_ms = start.elapsed().as_secs_f64() * 1e3;
        Self::upload(ctx, &data, build_ms)
    }

    /// No spheres (bound when the scene has no point clouds).
    pub fn empty(ctx: &GpuContext) -> Self {
        Self::upload(ctx, &SphereData::default(), 0.0).expect("empty buffers fit every device")
    }

    /// Uploads host-side sphere data (`SphereData::build`).
    pub fn upload(ctx: &GpuContext, data: &SphereData, build_ms: f64) -> Result<Self, GpuError> {
        let device = &ctx.device;
        let nodes = ctx.storage_buffer("spheres.nodes", bytemuck::cast_slice(&data.nodes))?;
        let spheres = ctx.storage_buffer("spheres.spheres", bytemuck::cast_slice(&data.spheres))?;
        let ids = ctx.storage_buffer("spheres.ids", bytemuck::cast_slice(&data.ids))?;
        let clouds = ctx.storage_buffer("spheres.clouds", bytemuck::cast_slice(&data.clouds))?;
        let info_value =
            GpuSphereInfo { count: data.spheres.len() as u32, nodes: data.nodes.len() as u32, clouds: data.clouds.len() as u32, _pad: 0 };
        let info = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("spheres.info"),
            contents: bytemuck::bytes_of(&info_value),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let layout = Self::create_layout(device);
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("spheres"),
            layout: &layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: info.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: nodes.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: spheres.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 3, resource: ids.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 4, resource: clouds.as_entire_binding() },
            ],
        });
        let bytes = (std::mem::size_of_val(data.nodes.as_slice())
            + std::mem::size_of_val(data.spheres.as_slice())
            + std::mem::size_of_val(data.ids.as_slice())
            + std::mem::size_of_val(data.clouds.as_slice())) as u64;
        let aabbs = (ctx.ray_query && !data.spheres.is_empty()).then(|| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("spheres.aabbs"),
                contents: bytemuck::cast_slice(&sphere_boxes(&data.spheres)),
                usage: wgpu::BufferUsages::BLAS_INPUT,
            })
        });
        Ok(Self {
            aabbs,
            layout,
            bind_group,
            count: info_value.count,
            info,
            nodes,
            spheres,
            ids,
            clouds,
            node_count: info_value.nodes,
            depth: data.depth,
            build_ms,
            bytes,
        })
    }

    /// Group 2: binding 0 uniform info, 1..=4 read-only storage (nodes, spheres, ids, clouds);
    /// visible to compute and fragment stages.
    pub fn create_layout(device: &wgpu::Device) -> wgpu::BindGroupLayout {
        crate::scene::uniform_and_storage_layout(device, "spheres", wgpu::ShaderStages::FRAGMENT | wgpu::ShaderStages::COMPUTE, 4)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shaders::{validate, with_common};
    use glam::Vec3;
    use hybrid_scene::PointColoring;

    fn cloud(points: Vec<Vec3>, radius: f32, coloring: PointColoring) -> PointCloud {
        PointCloud {
            name: "test".into(),
            source: "synthetic".into(),
            points,
            colors: vec![],
            radius,
            coloring,
            specular: Vec3::splat(0.1),
            shininess: 0.3,
        }
    }

    #[test]
    fn spheres_wgsl_is_valid() {
        let probe = r#"
@compute @workgroup_size(1)
fn probe() {
    let h = sphere_closest_hit(vec3<f32>(0.0), vec3<f32>(0.0, 0.0, 1.0), 0.0, 10.0);
    let s = sphere_surface(h.index, vec3<f32>(0.0), vec3<f32>(0.0, 0.0, 1.0));
    _ = s.normal + vec3<f32>(select(0.0, 1.0, sphere_any_hit(vec3<f32>(0.0), vec3<f32>(1.0, 0.0, 0.0), 0.0, 1.0)));
}
"#;
        if let Err(e) = validate(&with_common(&format!("{SPHERES_WGSL}\n{probe}"))) {
            panic!("{e}");
        }
    }

    #[test]
    fn every_sphere_is_in_one_leaf_and_boxes_contain_their_spheres() {
        let mut pts = Vec::new();
        for i in 0..1000 {
            let f = i as f32;
            pts.push(Vec3::new((f * 0.37).sin() * 3.0, (f * 0.11).cos() * 2.0, (f * 0.07).sin()));
        }
        let clouds = [cloud(pts.clone(), 0.05, PointColoring::Height), cloud(pts[..10].to_vec(), 0.2, PointColoring::Uniform(Vec3::X))];
        let d = SphereData::build(&clouds).unwrap();
        assert_eq!(d.spheres.len(), 1010);
        let mut seen = d.ids.clone();
        seen.sort_unstable();
        assert_eq!(seen, (0..1010).collect::<Vec<u32>>());
        // Leaf boxes contain their spheres; inner boxes contain their children.
        let inside = |n: &GpuSphereNode, lo: Vec3, hi: Vec3| Vec3::from(n.min).cmple(lo).all() && Vec3::from(n.max).cmpge(hi).all();
        for n in &d.nodes {
            if n.count > 0 {
                for s in &d.spheres[n.first as usize..(n.first + n.count) as usize] {
                    let c = Vec3::from(s.center);
                    assert!(inside(n, c - s.radius, c + s.radius));
                }
            } else {
                for k in 0..2 {
                    let c = d.nodes[(n.first + k) as usize];
                    assert!(inside(n, Vec3::from(c.min), Vec3::from(c.max)));
                }
            }
        }
        // Colours follow the cloud's rule; cloud 1 (global ids from 1000) is uniform red.
        for (s, id) in d.spheres.iter().zip(&d.ids) {
            if *id >= 1000 {
                assert_eq!((s.albedo, s.cloud, s.radius), ([1.0, 0.0, 0.0], 1, 0.2));
            } else {
                assert_eq!(s.cloud, 0);
                assert_eq!(s.center, pts[*id as usize].to_array());
            }
        }
        assert!(d.depth >= 10 && d.depth <= STACK, "depth {}", d.depth);
        assert!(SphereData::build(&[cloud(vec![Vec3::NAN], 1.0, PointColoring::Height)]).is_err());
        assert!(SphereData::build(&[cloud(vec![Vec3::ZERO], 0.0, PointColoring::Height)]).is_err());
        assert!(SphereData::build(&[]).unwrap().nodes.is_empty());
    }
}
