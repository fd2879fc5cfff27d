//! Smooth vertex normals for meshes that come without them (issue 23: the Stanford bunny OBJ and
//! dragon PLY have none and rendered faceted).
//!
//! Each corner of each triangle gets the sum of the face normals around its position, weighted by
//! the triangle's area and by its angle at that corner, over the faces whose normal is within the
//! crease angle of its own face's normal. Corners are grouped by position (not by vertex index), so
//! vertices that a file duplicates along a texture seam are smoothed across it. A vertex whose
//! corners end up with different normals (it lies on a crease: an edge sharper than the crease
//! angle) is split, one copy per normal, so hard edges stay hard.

use std::collections::HashMap;

use glam::Vec3;
use rayon::prelude::*;

use crate::Mesh;

/// The crease angle used when a scene does not set one, degrees.
pub const DEFAULT_CREASE_ANGLE_DEG: f32 = 60.0;

/// Fills `mesh.normals` with smooth vertex normals (see the module documentation), splitting
/// vertices on creases sharper than `crease_angle_deg` (0..=180; 180 smooths every edge, 0 keeps
/// every face flat). The mesh's original vertices keep their indices; split copies (with all of
/// the vertex's attributes) are appended. A mesh that already has normals is left as it is.
pub fn compute_smooth_normals(mesh: &mut Mesh, crease_angle_deg: f32) {
    if !mesh.normals.is_empty() || mesh.positions.is_empty() {
        return;
    }
    let cos_crease = crease_angle_deg.clamp(0.0, 180.0).to_radians().cos();
    let smooth_all = crease_angle_deg >= 180.0;

    // Face normals (unit) and per-corner weights (twice the area times the corner's angle).
    let positions = &mesh.positions;
    let (face_normals, weights): (Vec<Vec3>, Vec<[f32; 3]>) = mesh
        .indices
        .par_iter()
        .map(|tri| {
            let p = tri.map(|i| positions[i as usize]);
            let cross = (p[1] - p[0]).cross(p[2] - p[0]);
            // |e1 × e2| is twice the area at every corner, so the angles are atan2(2A, e1 · e2),
            // and the third is what the first two leave of π.
            let double_area = cross.length();
            if !(double_area > 0.0 && double_area.is_finite()) {
                return (Vec3::ZERO, [0.0; 3]);
            }
            let a0 = double_area.atan2((p[1] - p[0]).dot(p[2] - p[0]));
            let a1 = double_area.atan2((p[2] - p[1]).dot(p[0] - p[1]));
            let a2 = (std::f32::consts::PI - a0 - a1).max(0.0);
            (cross / double_area, [a0, a1, a2].map(|a| a * double_area))
        })
        .unzip();

    // Corners grouped by the exact position of their vertex (CSR layout: `start[g]..start[g+1]`
    // of `corners` are group g's corners, as triangle * 3 + corner, in triangle order).
    let mut group_of_pos: HashMap<[u32; 3], u32> = HashMap::with_capacity(positions.len());
    let vertex_group: Vec<u32> = positions
        .iter()
        .map(|p| {
            // +0.0 turns -0.0 into 0.0, so both signs of zero are one position.
            let key = (*p + Vec3::ZERO).to_array().map(f32::to_bits);
            let next = group_of_pos.len() as u32;
            *group_of_pos.entry(key).or_insert(next)
        })
        .collect();
    let groups = group_of_pos.len();
    drop(group_of_pos);
    let mut start = vec![0u32; groups + 1];
    for tri in &mesh.indices {
        for &v in tri {
            start[vertex_group[v as usize] as usize + 1] += 1;
        }
    }
    for g in 0..groups {
        start[g + 1] += start[g];
    }
    let mut fill = start.clone();
    let mut corners = vec![0u32; mesh.indices.len() * 3];
    for (t, tri) in mesh.indices.iter().enumerate() {
        for (k, &v) in tri.iter().enumerate() {
            let g = vertex_group[v as usize] as usize;
            corners[fill[g] as usize] = (t * 3 + k) as u32;
            fill[g] += 1;
        }
    }

    // The normal of each corner (triangle * 3 + corner), summed over its position's corners in
    // one order, so corners with the same faces in range get bit-identical normals.
    let corner_normals: Vec<Vec3> = (0..mesh.indices.len() * 3)
        .into_par_iter()
        .map(|c| {
            let g = vertex_group[mesh.indices[c / 3][c % 3] as usize] as usize;
            let own = face_normals[c / 3];
            let mut sum = Vec3::ZERO;
            for &o in &corners[start[g] as usize..start[g + 1] as usize] {
                let o = o as usize;
                let n = face_normals[o / 3];
                // A degenerate face (zero normal) takes every face around it.
                if smooth_all || own == Vec3::ZERO || o == c || own.dot(n) >= cos_crease {
                    sum += n * weights[o / 3][o % 3];
                }
            }
            sum.normalize_or(if own == Vec3::ZERO { Vec3::Y } else { own })
        })
        .collect();

    // One vertex per (original vertex, normal): the first normal a vertex gets keeps its index,
    // others get copies appended.
    let original = mesh.positions.len();
    let mut normals = vec![Vec3::Y; original];
    let mut assigned = vec![false; original];
    let mut copies: HashMap<(u32, [u32; 3]), u32> = HashMap::new();
    let mut copied_from: Vec<u32> = Vec::new();
    for (t, tri) in mesh.indices.iter_mut().enumerate() {
        for (k, v) in tri.iter_mut().enumerate() {
            let n = corner_normals[t * 3 + k];
            let vi = *v as usize;
            if !assigned[vi] {
                assigned[vi] = true;
                normals[vi] = n;
            } else if normals[vi].to_array().map(f32::to_bits) != n.to_array().map(f32::to_bits) {
                let key = (*v, n.to_array().map(f32::to_bits));
                let next = (original + copied_from.len()) as u32;
                *v = *copies.entry(key).or_insert_with(|| {
                    copied_from.push(key.0);
                    normals.push(n);
                    next
                });
            }
        }
    }
    // A vertex no triangle uses takes the normal of the first corner at its position, if any.
    for (vi, done) in assigned.iter().enumerate() {
        let g = vertex_group[vi] as usize;
        if !done && start[g] < start[g + 1] {
            normals[vi] = corner_normals[corners[start[g] as usize] as usize];
        }
    }
    for &from in &copied_from {
        let from = from as usize;
        mesh.positions.push(mesh.positions[from]);
        if !mesh.uvs.is_empty() {
            mesh.uvs.push(mesh.uvs[from]);
        }
        if !mesh.tangents.is_empty() {
            mesh.tangents.push(mesh.tangents[from]);
        }
        if !mesh.colors.is_empty() {
            mesh.colors.push(mesh.colors[from]);
        }
    }
    mesh.normals = normals;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::primitives;

    fn without_normals(mut m: Mesh) -> Mesh {
        m.normals.clear();
        m
    }

    /// Largest angle (degrees) between a vertex normal and `expected(position)`.
    fn worst_angle_deg(m: &Mesh, expected: impl Fn(Vec3) -> Vec3) -> f32 {
        m.positions
            .iter()
            .zip(&m.normals)
            .map(|(p, n)| n.dot(expected(*p).normalize()).clamp(-1.0, 1.0).acos().to_degrees())
            .fold(0.0, f32::max)
    }

    #[test]
    fn sphere_normals_match_the_analytic_ones_within_a_degree() {
        for (slices, stacks) in [(32, 16), (64, 32)] {
            let reference = primitives::sphere(slices, stacks);
            let mut m = without_normals(reference.clone());
            compute_smooth_normals(&mut m, DEFAULT_CREASE_ANGLE_DEG);
            assert_eq!(m.normals.len(), m.positions.len());
            // No vertex needed splitting: the mesh is the same apart from its normals.
            assert_eq!(m.positions, reference.positions, "{slices}x{stacks}");
            assert_eq!(m.indices, reference.indices);
            let worst = worst_angle_deg(&m, |p| p);
            assert!(worst < 1.0, "{slices}x{stacks}: worst vertex normal is {worst}° off the sphere's");
            // Across the texture seam (duplicated vertices) the normals agree.
            for (i, p) in m.positions.iter().enumerate() {
                for (j, q) in m.positions.iter().enumerate().skip(i + 1) {
                    if p == q {
                        assert_eq!(m.normals[i], m.normals[j], "seam vertices {i} and {j}");
                    }
                }
            }
        }
    }

    /// A cube of 8 shared corners and 12 triangles (no duplicated vertices), counter-clockwise
    /// seen from outside.
    fn shared_cube() -> Mesh {
        let positions = (0..8).map(|i| Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32) * 2.0 - 1.0).collect();
        let quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
        let indices = quads.iter().flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]).collect();
        Mesh { positions, indices, ..Mesh::default() }
    }

    #[test]
    fn a_cube_keeps_its_hard_edges_at_the_default_crease() {
        let mut m = shared_cube();
        compute_smooth_normals(&mut m, DEFAULT_CREASE_ANGLE_DEG);
        // Every corner is on three faces at 90°: three copies of each of the 8 vertices.
        assert_eq!(m.positions.len(), 24);
        assert_eq!(m.normals.len(), 24);
        for tri in &m.indices {
            let p = tri.map(|i| m.positions[i as usize]);
            let face = (p[1] - p[0]).cross(p[2] - p[0]).normalize();
            assert!(face.abs().max_element() == 1.0, "an axis-aligned face");
            for &i in tri {
                assert_eq!(m.normals[i as usize], face, "flat face, vertex {i}");
            }
        }
    }

    #[test]
    fn crease_180_smooths_everything_and_0_keeps_faces_flat() {
        let mut m = shared_cube();
        compute_smooth_normals(&mut m, 180.0);
        assert_eq!(m.positions.len(), 8, "no vertex split");
        // Each corner's normal points out along the diagonal (the cube is symmetric).
        assert!(worst_angle_deg(&m, |p| p) < 1e-3);

        let mut sphere = without_normals(primitives::sphere(16, 8));
        compute_smooth_normals(&mut sphere, 0.0);
        for tri in &sphere.indices {
            let p = tri.map(|i| sphere.positions[i as usize]);
            let face = (p[1] - p[0]).cross(p[2] - p[0]);
            if face.length() > 1e-6 {
                for &i in tri {
                    assert!(sphere.normals[i as usize].dot(face.normalize()) > 0.99999, "flat at crease 0");
                }
            }
        }
    }

    #[test]
    fn split_vertices_keep_their_attributes_and_meshes_with_normals_are_untouched() {
        let mut m = shared_cube();
        m.uvs = (0..8).map(|i| glam::Vec2::new(i as f32, 0.5)).collect();
        m.colors = (0..8).map(|i| Vec3::splat(i as f32)).collect();
        let before = m.clone();
        compute_smooth_normals(&mut m, 30.0);
        assert_eq!(m.uvs.len(), m.positions.len());
        assert_eq!(m.colors.len(), m.positions.len());
        for (t, tri) in m.indices.iter().enumerate() {
            for (k, &i) in tri.iter().enumerate() {
                let o = before.indices[t][k] as usize;
                let i = i as usize;
                assert_eq!((m.positions[i], m.uvs[i], m.colors[i]), (before.positions[o], before.uvs[o], before.colors[o]));
            }
        }

        let sphere = primitives::sphere(8, 4);
        let mut again = sphere.clone();
        compute_smooth_normals(&mut again, 180.0);
        assert_eq!(again, sphere);
    }

    #[test]
    fn degenerate_triangles_get_a_unit_normal() {
        let mut m = Mesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(2.0, 0.0, 0.0)],
            indices: vec![[0, 1, 2], [0, 1, 3]],
            ..Mesh::default()
        };
        compute_smooth_normals(&mut m, DEFAULT_CREASE_ANGLE_DEG);
        for n in &m.normals {
            assert!((n.length() - 1.0).abs() < 1e-6, "{n}");
        }
        assert_eq!(m.normals[2], Vec3::Z);
    }
}
