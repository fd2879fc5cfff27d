//! `prepare`: the scene in world space, once per scene (not per frame). Raster, trace and the
//! capsule all read this; it also evaluates a material at a point of a triangle, so the G-buffer
//! (raster) and secondary hits (trace) see exactly the same surface.

use glam::{Mat3, Vec2, Vec3, Vec4};
use hybrid_core::Surface;
use hybrid_scene::model::normal_matrix;
use hybrid_scene::{Aabb, Material, Scene, Texture};

/// One mesh of one object, transformed to world space.
#[derive(Debug, Clone)]
pub struct WorldMesh {
    /// Index of the object in `Scene::objects` (the object id written to the G-buffer).
    pub object: u32,
    pub material: usize,
    pub positions: Vec<Vec3>,
    /// World normals; empty = flat shading.
    pub normals: Vec<Vec3>,
    pub uvs: Vec<Vec2>,
    /// World tangents with bitangent sign; empty = no normal mapping possible.
    pub tangents: Vec<Vec4>,
    pub colors: Vec<Vec3>,
    pub indices: Vec<[u32; 3]>,
}

/// A triangle of the whole scene: which mesh, which triangle in it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TriangleRef {
    pub mesh: u32,
    pub triangle: u32,
}

/// The scene prepared for the CPU backend.
#[derive(Debug)]
pub struct PreparedScene<'s> {
    pub scene: &'s Scene,
    pub meshes: Vec<WorldMesh>,
    /// World bounds per object (index = object id); empty boxes for objects without geometry.
    pub object_bounds: Vec<Aabb>,
    /// Every triangle of every mesh, in mesh order (the trace stage's primitive list).
    pub triangles: Vec<TriangleRef>,
}

impl<'s> PreparedScene<'s> {
    pub fn new(scene: &'s Scene) -> Self {
        let mut meshes = Vec::new();
        let mut object_bounds = Vec::with_capacity(scene.objects.len());
        for (oi, obj) in scene.objects.iter().enumerate() {
            let m = obj.transform.matrix();
            let nm: Mat3 = normal_matrix(&m);
            let m3 = Mat3::from_mat4(m);
            let mut bounds = Aabb::EMPTY;
            for mesh in &obj.meshes {
                let positions: Vec<Vec3> = mesh.positions.iter().map(|p| m.transform_point3(*p)).collect();
                positions.iter().for_each(|p| bounds.grow(*p));
                let normals = mesh.normals.iter().map(|n| (nm * *n).normalize_or(Vec3::Y)).collect();
                let tangents = mesh.tangents.iter().map(|t| (m3 * t.truncate()).normalize_or(Vec3::X).extend(t.w)).collect();
                meshes.push(WorldMesh {
                    object: oi as u32,
                    material: mesh.material,
                    positions,
                    normals,
                    uvs: mesh.uvs.clone(),
                    tangents,
                    colors: mesh.colors.clone(),
                    indices: mesh.indices.clone(),
                });
            }
            object_bounds.push(bounds);
        }
        let triangles = meshes
            .iter()
            .enumerate()
            .flat_map(|(mi, m)| (0..m.indices.len() as u32).map(move |t| TriangleRef { mesh: mi as u32, triangle: t }))
            .collect();
        Self { scene, meshes, object_bounds, triangles }
    }

    /// The three world-space corners of a triangle.
    #[inline]
    pub fn triangle(&self, t: TriangleRef) -> [Vec3; 3] {
        let m = &self.meshes[t.mesh as usize];
        m.indices[t.triangle as usize].map(|i| m.positions[i as usize])
    }

    pub fn material(&self, t: TriangleRef) -> &Material {
        &self.scene.materials[self.meshes[t.mesh as usize].material]
    }

    /// The surface at barycentric coordinates `bary` (weights of the three corners, summing to 1)
    /// of triangle `t`. `uv_footprint` is the UV change per pixel for mip selection (0 = finest).
    pub fn surface_at(&self, t: TriangleRef, bary: Vec3, uv_footprint: f32) -> Surface {
        let mesh = &self.meshes[t.mesh as usize];
        let [i0, i1, i2] = mesh.indices[t.triangle as usize].map(|i| i as usize);
        let lerp3 = |a: Vec3, b: Vec3, c: Vec3| a * bary.x + b * bary.y + c * bary.z;
        let position = lerp3(mesh.positions[i0], mesh.positions[i1], mesh.positions[i2]);
        let geometric = (mesh.positions[i1] - mesh.positions[i0]).cross(mesh.positions[i2] - mesh.positions[i0]).normalize_or(Vec3::Y);
        let mut normal = if mesh.normals.is_empty() {
            geometric
        } else {
            lerp3(mesh.normals[i0], mesh.normals[i1], mesh.normals[i2]).normalize_or(geometric)
        };
        let uv = if mesh.uvs.is_empty() { Vec2::ZERO } else { mesh.uvs[i0] * bary.x + mesh.uvs[i1] * bary.y + mesh.uvs[i2] * bary.z };
        let color = if mesh.colors.is_empty() { Vec3::ONE } else { lerp3(mesh.colors[i0], mesh.colors[i1], mesh.colors[i2]) };
        let mat = &self.scene.materials[mesh.material];
        let tex = &self.scene.textures;
        let uv = mat.offset + uv * mat.tiling;
        let footprint = uv_footprint * mat.tiling.abs().max_element();
        let sample = |id: Option<usize>| -> Vec4 {
            match id {
                Some(id) => sample_texture(&tex[id], uv, footprint),
                None => Vec4::ONE,
            }
        };
        if let Some(nm) = mat.normal_map
            && !mesh.tangents.is_empty()
        {
            let t4 = mesh.tangents[i0] * bary.x + mesh.tangents[i1] * bary.y + mesh.tangents[i2] * bary.z;
            let tangent = (t4.truncate() - normal * normal.dot(t4.truncate())).normalize_or_zero();
            if tangent != Vec3::ZERO {
                let sign = if mesh.tangents[i0].w < 0.0 { -1.0 } else { 1.0 };
                let bitangent = normal.cross(tangent) * sign;
                let n_ts = sample_texture(&tex[nm], uv, footprint).truncate() * 2.0 - Vec3::ONE;
                normal = (tangent * n_ts.x + bitangent * n_ts.y + normal * n_ts.z).normalize_or(normal);
            }
        }
        let d = sample(mat.diffuse_map);
        let s = sample(mat.specular_map);
        let o = sample(mat.optical_map);
        Surface {
            position,
            normal,
            emission: mat.emission * sample(mat.emission_map).truncate(),
            ambient: mat.ambient * sample(mat.ambient_map).truncate(),
            diffuse: mat.diffuse * d.truncate() * color,
            // Opacity: material × diffuse-map alpha × optical-map B (Table 1).
            opacity: (mat.opacity * d.w * o.z).clamp(0.0, 1.0),
            specular: mat.specular * s.truncate(),
            shininess: (mat.shininess * s.w).clamp(0.0, 1.0),
            reflectivity: (mat.reflectivity * o.x).clamp(0.0, 1.0),
            ior: mat.ior * o.y,
        }
    }
}

/// Trilinear texture sample for a UV footprint (UV units per pixel).
#[inline]
pub fn sample_texture(t: &Texture, uv: Vec2, footprint: f32) -> Vec4 {
    t.sample(uv, t.lod_for_footprint(footprint))
}
