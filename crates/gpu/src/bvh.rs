//! `bvh`: the scene's triangle BVH for the GPU trace stage (and the rt-only primary rays).
//!
//! Built on the CPU with obvhs (a PLOC BVH2, `fast_build`, up to 8 triangles a leaf) over
//! `SceneGpu::host_triangles`, then flattened for WGSL: two storage buffers bound at group 1,
//! bindings 0 and 1 (`shaders/bvh.wgsl`, which declares them and holds the traversal):
//! - nodes: `min.xyz, bits(first)` / `max.xyz, bits(count)`; an inner node (count 0) has its two
//!   children at `first` and `first + 1`, a leaf its triangles at slots `first..first + count`;
//! - triangle slots in leaf order, as precomputed Möller–Trumbore data (`v0`, `e1`, `e2`, the
//!   CPU BVH's form): `v0.w` = the triangle's index in `SceneGpu::triangles`, `e1.w` = its shadow
//!   transparency (listing 8b) from the same material classes as `hybrid_cpu::bvh`: 1 = ignored by
//!   shadow rays (casts no shadows, or fully transparent), a constant `1 − opacity`, or
//!   [`SHADOW_EVALUATE`] (opacity varies over a texture: evaluated with the surface at the hit).
//!
//! WGSL has fixed-size stacks, so the build checks the tree's depth against [`STACK_SIZE`].

use bytemuck::{Pod, Zeroable};
use glam::Vec3A;
use hybrid_core::PreparedScene;

use crate::context::{GpuContext, GpuError};
use crate::scene::{GpuTriangle, GpuVertex, SceneGpu};

/// The traversal WGSL (needs common/*.wgsl before it; declares group 1 bindings 0 and 1).
pub const BVH_WGSL: &str = include_str!("shaders/bvh.wgsl");

/// Entries of the traversal stack in `bvh.wgsl` (`BVH_STACK`): the deepest tree it can walk.
pub const STACK_SIZE: usize = 64;

/// Shadow classes per material, shared with the CPU backend's BVH (1, a constant transparency, or
/// [`SHADOW_EVALUATE`]: opacity varies over a texture, evaluated with the surface at the hit).
pub use hybrid_core::prepare::{SHADOW_EVALUATE, material_shadow};

/// `struct BvhNode` in bvh.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct GpuBvhNode {
    /// xyz box minimum, w = bits of `first` (first child, or first triangle slot).
    pub min: [f32; 4],
    /// xyz box maximum, w = bits of `count` (0 = inner node).
    pub max: [f32; 4],
}

/// `struct BvhTri` in bvh.wgsl: one triangle slot.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct GpuBvhTri {
    /// Corner 0; w = bits of the triangle index.
    pub v0: [f32; 4],
    /// Corner 1 − corner 0; w = shadow transparency (1, a constant, or [`SHADOW_EVALUATE`]).
    pub e1: [f32; 4],
    /// Corner 2 − corner 0.
    pub e2: [f32; 4],
}

/// The flattened BVH on the GPU.
pub struct TriangleBvhGpu {
    pub nodes: wgpu::Buffer,
    pub tris: wgpu::Buffer,
    pub node_count: u32,
    pub triangle_count: u32,
    /// Levels from the root to the deepest leaf (root alone = 1).
    pub depth: u32,
}

/// The flattened tree on the host (what [`TriangleBvhGpu`] uploads).
#[derive(Debug, Clone)]
pub struct FlatBvh {
    pub nodes: Vec<GpuBvhNode>,
    pub tris: Vec<GpuBvhTri>,
    pub depth: u32,
}

impl FlatBvh {
    /// Builds and flattens the BVH over `triangles` (as `SceneGpu::host_triangles`, indexing
    /// `vertices`); `prepared` gives the materials and textures for the shadow classes.
    pub fn build(triangles: &[GpuTriangle], vertices: &[GpuVertex], prepared: &PreparedScene) -> FlatBvh {
        let corners: Vec<[Vec3A; 3]> =
            triangles.iter().map(|t| t.v.map(|i| Vec3A::from_slice(&vertices[i as usize].position[..3]))).collect();
        let mesh_shadow: Vec<f32> = (0..prepared.meshes.len()).map(|m| prepared.mesh_shadow(m)).collect();
        if corners.is_empty() {
            // One leaf over one degenerate triangle (never hit, ignored by shadow rays).
            let node = GpuBvhNode { min: [0.0, 0.0, 0.0, f32::from_bits(0)], max: [0.0, 0.0, 0.0, f32::from_bits(1)] };
            let tri = GpuBvhTri { v0: [0.0; 4], e1: [0.0, 0.0, 0.0, 1.0], e2: [0.0; 4] };
            return FlatBvh { nodes: vec![node], tris: vec![tri], depth: 1 };
        }
        let aabbs: Vec<obvhs::aabb::Aabb> = corners
            .iter()
            .map(|c| {
                if c.iter().all(|p| p.is_finite()) {
                    obvhs::aabb::Aabb::from_points(c)
                } else {
                    // Never hit (the intersection test fails on non-finite data): a point box.
                    obvhs::aabb::Aabb::from_point(Vec3A::ZERO)
                }
            })
            .collect();
        let mut build_time = std::time::Duration::ZERO;
        let bvh = obvhs::bvh2::builder::build_bvh2(&aabbs, obvhs::BvhBuildParams::fast_build(), &mut build_time);

        // Re-laid out depth-first from the root, children side by side.
        let mut nodes = vec![GpuBvhNode::zeroed()];
        let mut tris = Vec::with_capacity(corners.len());
        let mut todo = vec![(0usize, 0usize, 1u32)]; // (obvhs node, our slot, level)
        let mut depth = 1;
        while let Some((src, dst, level)) = todo.pop() {
            depth = depth.max(level);
            let n = &bvh.nodes[src];
            let (lo, hi) = (n.aabb.min, n.aabb.max);
            let (first, count) = if n.prim_count == 0 {
                let first = nodes.len();
                nodes.push(GpuBvhNode::zeroed());
                nodes.push(GpuBvhNode::zeroed());
                todo.push((n.first_index as usize + 1, first + 1, level + 1));
                todo.push((n.first_index as usize, first, level + 1));
                (first as u32, 0)
            } else {
                let first = tris.len() as u32;
                for k in 0..n.prim_count {
                    let tri = bvh.primitive_indices[(n.first_index + k) as usize] as usize;
                    let [a, b, c] = corners[tri];
                    let (e1, e2) = (b - a, c - a);
                    let mesh = triangles[tri].mesh as usize;
                    tris.push(GpuBvhTri {
                        v0: [a.x, a.y, a.z, f32::from_bits(tri as u32)],
                        e1: [e1.x, e1.y, e1.z, mesh_shadow.get(mesh).copied().unwrap_or(1.0)],
                        e2: [e2.x, e2.y, e2.z, 0.0],
                    });
                }
                (first, n.prim_count)
            };
            nodes[dst] = GpuBvhNode { min: [lo.x, lo.y, lo.z, f32::from_bits(first)], max: [hi.x, hi.y, hi.z, f32::from_bits(count)] };
        }
        FlatBvh { nodes, tris, depth }
    }
}

impl TriangleBvhGpu {
    pub fn new(ctx: &GpuContext, scene: &SceneGpu, prepared: &PreparedScene) -> Result<Self, GpuError> {
        let flat = FlatBvh::build(&scene.host_triangles, &scene.host_vertices, prepared);
        if flat.depth as usize > STACK_SIZE {
            return Err(GpuError::TooLarge {
                adapter: ctx.summary.name.clone(),
                why: format!("the triangle BVH is {} levels deep, the GPU traversal stack holds {STACK_SIZE}", flat.depth),
            });
        }
        Ok(Self {
            nodes: ctx.storage_buffer("BVH nodes", bytemuck::cast_slice(&flat.nodes))?,
            tris: ctx.storage_buffer("BVH triangles", bytemuck::cast_slice(&flat.tris))?,
            node_count: flat.nodes.len() as u32,
            triangle_count: scene.triangle_count,
            depth: flat.depth,
        })
    }

    /// Layout entries of group 1, bindings 0 (nodes) and 1 (triangle slots), for `visibility`.
    pub fn layout_entries(visibility: wgpu::ShaderStages) -> [wgpu::BindGroupLayoutEntry; 2] {
        [0, 1].map(|binding| wgpu::BindGroupLayoutEntry {
            binding,
            visibility,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only: true },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        })
    }

    /// Bind group entries for [`Self::layout_entries`].
    pub fn bind_entries(&self) -> [wgpu::BindGroupEntry<'_>; 2] {
        [
            wgpu::BindGroupEntry { binding: 0, resource: self.nodes.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 1, resource: self.tris.as_entire_binding() },
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shaders::{validate, with_common};

    #[test]
    fn bvh_wgsl_is_valid() {
        let probe = r#"
@compute @workgroup_size(1)
fn probe() {
    let h = closest_hit(vec3<f32>(0.0), vec3<f32>(0.0, 0.0, -1.0), 0.0, FAR_AWAY);
    let a = shadow_attenuation(vec3<f32>(0.0), vec3<f32>(0.0, 1.0, 0.0), 10.0);
    _ = h.t + a + h.bary.x + f32(h.tri);
}
"#;
        if let Err(e) = validate(&with_common(&format!("{BVH_WGSL}\n{probe}"))) {
            panic!("{e}");
        }
    }

    #[test]
    fn flattened_tree_holds_every_triangle_once_inside_its_boxes() {
        let scene = hybrid_scene::file::demo_scene();
        let prepared = PreparedScene::new(&scene);
        let (mut vertices, mut triangles) = (Vec::new(), Vec::new());
        for (mi, m) in prepared.meshes.iter().enumerate() {
            let base = vertices.len() as u32;
            vertices.extend(m.positions.iter().map(|p| GpuVertex { position: p.extend(1.0).to_array(), ..GpuVertex::zeroed() }));
            triangles.extend(m.indices.iter().map(|t| GpuTriangle { v: t.map(|i| base + i), mesh: mi as u32 }));
        }
        let flat = FlatBvh::build(&triangles, &vertices, &prepared);
        assert!(flat.depth as usize <= STACK_SIZE && triangles.len() > 100);
        let mut seen = vec![0u32; triangles.len()];
        let mut todo = vec![(0usize, [f32::NEG_INFINITY; 3], [f32::INFINITY; 3])];
        let inside = |lo: &[f32], hi: &[f32], p: &[f32]| (0..3).all(|a| lo[a] <= p[a] && p[a] <= hi[a]);
        while let Some((i, plo, phi)) = todo.pop() {
            let n = flat.nodes[i];
            let (lo, hi) = (&n.min[..3], &n.max[..3]);
            assert!(inside(&plo, &phi, lo) && inside(&plo, &phi, hi), "node {i} leaves its parent's box");
            let (first, count) = (n.min[3].to_bits() as usize, n.max[3].to_bits() as usize);
            if count == 0 {
                todo.push((first, [lo[0], lo[1], lo[2]], [hi[0], hi[1], hi[2]]));
                todo.push((first + 1, [lo[0], lo[1], lo[2]], [hi[0], hi[1], hi[2]]));
                continue;
            }
            for t in &flat.tris[first..first + count] {
                let tri = t.v0[3].to_bits() as usize;
                seen[tri] += 1;
                let corners = triangles[tri].v.map(|v| vertices[v as usize].position);
                assert!(corners.iter().all(|c| inside(lo, hi, &c[..3])), "triangle {tri} outside its leaf");
                let material = prepared.meshes[triangles[tri].mesh as usize].material;
                assert_eq!(t.e1[3], material_shadow(&scene.materials[material], &scene.textures));
            }
        }
        assert!(seen.iter().all(|&k| k == 1), "every triangle in exactly one leaf");
    }
}
