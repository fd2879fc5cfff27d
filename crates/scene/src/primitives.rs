//! Built-in primitives (paper §3): plane, cube, sphere with slices and stacks.
//!
//! All are unit-sized and centred on the origin, so an object's `scale` is its size:
//! - [`plane`]: 1 × 1 in the XZ plane, normal +Y (one-sided).
//! - [`cube`]: 1 × 1 × 1, 24 vertices (flat faces, each face has its own UVs 0..1).
//! - [`sphere`]: radius 0.5, `slices` around Y, `stacks` from pole to pole.
//!
//! Triangles wind counter-clockwise seen from outside (the side the normals point to).
//! Texture coordinates: (0, 0) is the image's top-left corner.

use glam::{Vec2, Vec3};

use crate::Mesh;

/// Fewest slices / stacks a sphere can have.
pub const MIN_SPHERE_SLICES: u32 = 3;
pub const MIN_SPHERE_STACKS: u32 = 2;
/// Most slices / stacks accepted (keeps a typo from asking for billions of triangles).
pub const MAX_SPHERE_SEGMENTS: u32 = 4096;

/// Appends one square face of side 1 centred at `normal * offset`, spanned by `u` (texture
/// right) and `v` (texture up); `u × v` must equal `normal` so the winding is CCW from outside.
fn push_face(m: &mut Mesh, normal: Vec3, u: Vec3, v: Vec3, offset: f32) {
    debug_assert!(u.cross(v).distance(normal) < 1e-6);
    let base = m.positions.len() as u32;
    let centre = normal * offset;
    for (s, t) in [(-0.5f32, -0.5f32), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)] {
        m.positions.push(centre + u * s + v * t);
        m.normals.push(normal);
        m.uvs.push(Vec2::new(s + 0.5, 0.5 - t));
    }
    m.indices.push([base, base + 1, base + 2]);
    m.indices.push([base, base + 2, base + 3]);
}

/// A 1 × 1 plane in XZ, centred, facing +Y. UV u runs along +X, v along +Z.
pub fn plane() -> Mesh {
    let mut m = Mesh::default();
    push_face(&mut m, Vec3::Y, Vec3::X, Vec3::NEG_Z, 0.0);
    m.compute_tangents();
    m
}

/// A 1 × 1 × 1 cube, centred, with 24 vertices (4 per face) so every face is flat.
pub fn cube() -> Mesh {
    let mut m = Mesh::default();
    // (normal, texture right, texture up) with right × up = normal.
    let faces = [
        (Vec3::X, Vec3::NEG_Z, Vec3::Y),
        (Vec3::NEG_X, Vec3::Z, Vec3::Y),
        (Vec3::Y, Vec3::X, Vec3::NEG_Z),
        (Vec3::NEG_Y, Vec3::X, Vec3::Z),
        (Vec3::Z, Vec3::X, Vec3::Y),
        (Vec3::NEG_Z, Vec3::NEG_X, Vec3::Y),
    ];
    for (n, u, v) in faces {
        push_face(&mut m, n, u, v, 0.5);
    }
    m.compute_tangents();
    m
}

/// A quad centred at `c` spanned by the half-edges `u` and `v`: corners `c ± u ± v`, normal
/// `u × v` (normalised), UVs 0..1 from corner `c − u − v`, assigned `material`. For scenes built
/// in code (tests, benchmarks).
pub fn quad(c: Vec3, u: Vec3, v: Vec3, material: usize) -> Mesh {
    let n = u.cross(v).normalize();
    Mesh {
        positions: vec![c - u - v, c + u - v, c + u + v, c - u + v],
        normals: vec![n; 4],
        uvs: vec![Vec2::ZERO, Vec2::X, Vec2::ONE, Vec2::Y],
        indices: vec![[0, 1, 2], [0, 2, 3]],
        material,
        ..Default::default()
    }
}

/// The axis-aligned box from `min` to `max`: six [`quad`]s with outward normals, assigned
/// `material`.
pub fn cuboid(min: Vec3, max: Vec3, material: usize) -> Mesh {
    let c = (min + max) * 0.5;
    let h = (max - min) * 0.5;
    let faces = [
        (Vec3::X, Vec3::Y, Vec3::Z),
        (-Vec3::X, Vec3::Z, Vec3::Y),
        (Vec3::Y, Vec3::Z, Vec3::X),
        (-Vec3::Y, Vec3::X, Vec3::Z),
        (Vec3::Z, Vec3::X, Vec3::Y),
        (-Vec3::Z, Vec3::Y, Vec3::X),
    ];
    let mut mesh = Mesh { material, ..Default::default() };
    for (n, a, b) in faces {
        let q = quad(c + n * h, a * h, b * h, material);
        let base = mesh.positions.len() as u32;
        mesh.positions.extend(q.positions);
        mesh.normals.extend(q.normals);
        mesh.uvs.extend(q.uvs);
        mesh.indices.extend(q.indices.iter().map(|t| t.map(|i| i + base)));
    }
    mesh
}

/// A UV sphere of radius 0.5 centred on the origin. `slices` (≥ 3) segments around the Y axis,
/// `stacks` (≥ 2) from the +Y pole to the −Y pole; values are clamped into
/// [`MIN_SPHERE_SLICES`]/[`MIN_SPHERE_STACKS`]..=[`MAX_SPHERE_SEGMENTS`] (scene files reject
/// values outside that range before getting here).
///
/// The seam and the poles have duplicated vertices (with their own UVs); the surface is still
/// closed. UV u goes once around (from +Z towards +X), v from the top pole (0) to the bottom (1).
pub fn sphere(slices: u32, stacks: u32) -> Mesh {
    let slices = slices.clamp(MIN_SPHERE_SLICES, MAX_SPHERE_SEGMENTS);
    let stacks = stacks.clamp(MIN_SPHERE_STACKS, MAX_SPHERE_SEGMENTS);
    let mut m = Mesh::default();
    let cols = slices + 1;
    for i in 0..=stacks {
        let v = i as f32 / stacks as f32;
        let phi = v * std::f32::consts::PI;
        let (sp, cp) = phi.sin_cos();
        for j in 0..=slices {
            let u = j as f32 / slices as f32;
            let theta = u * std::f32::consts::TAU;
            let (st, ct) = theta.sin_cos();
            // Exact poles and seam, so welded positions match.
            let (sp, cp) = if i == 0 {
                (0.0, 1.0)
            } else if i == stacks {
                (0.0, -1.0)
            } else {
                (sp, cp)
            };
            let (st, ct) = if j == slices { (0.0, 1.0) } else { (st, ct) };
            let n = Vec3::new(sp * st, cp, sp * ct);
            m.positions.push(n * 0.5);
            m.normals.push(n);
            m.uvs.push(Vec2::new(u, v));
        }
    }
    for i in 0..stacks {
        for j in 0..slices {
            let a = i * cols + j; // top-left (seen from outside)
            let b = a + cols; // bottom-left
            let c = b + 1; // bottom-right
            let d = a + 1; // top-right
            if i + 1 < stacks {
                m.indices.push([a, b, c]);
            }
            if i > 0 {
                m.indices.push([a, c, d]);
            }
        }
    }
    m.compute_tangents();
    m
}

#[cfg(test)]
mod tests {
    use std::collections::HashMap;

    use super::*;

    #[test]
    fn cuboid_faces_point_outwards_and_cover_the_box() {
        let (min, max) = (Vec3::new(-1.0, 0.0, 2.0), Vec3::new(3.0, 1.0, 2.5));
        let m = cuboid(min, max, 7);
        assert_eq!((m.positions.len(), m.indices.len(), m.material), (24, 12, 7));
        let centre = (min + max) * 0.5;
        for t in &m.indices {
            let [a, b, c] = t.map(|i| m.positions[i as usize]);
            let n = (b - a).cross(c - a);
            assert!(n.dot((a + b + c) / 3.0 - centre) > 0.0, "triangle {t:?} winds inwards");
            assert!(n.normalize().dot(m.normals[t[0] as usize]) > 0.999, "normal disagrees with winding");
        }
        assert!(m.positions.iter().all(|p| p.cmpge(min).all() && p.cmple(max).all()));
        // A quad's corners are c ± u ± v.
        let q = quad(Vec3::ZERO, Vec3::X, Vec3::Y, 0);
        assert_eq!(q.positions[2], Vec3::new(1.0, 1.0, 0.0));
        assert_eq!(q.normals[0], Vec3::Z);
    }

    /// Welds vertices by position and counts directed edges: a closed, consistently wound
    /// surface has every edge exactly once in each direction.
    fn assert_closed(m: &Mesh) {
        let key = |p: Vec3| ((p.x * 1e5).round() as i64, (p.y * 1e5).round() as i64, (p.z * 1e5).round() as i64);
        let mut ids = HashMap::new();
        let weld: Vec<usize> = m
            .positions
            .iter()
            .map(|p| {
                let n = ids.len();
                *ids.entry(key(*p)).or_insert(n)
            })
            .collect();
        let mut edges: HashMap<(usize, usize), i32> = HashMap::new();
        for t in &m.indices {
            let w = t.map(|i| weld[i as usize]);
            for k in 0..3 {
                let (a, b) = (w[k], w[(k + 1) % 3]);
                assert_ne!(a, b, "degenerate triangle {t:?}");
                *edges.entry((a, b)).or_default() += 1;
            }
        }
        for (&(a, b), &n) in &edges {
            assert_eq!(n, 1, "directed edge {a}->{b} used {n} times");
            assert_eq!(edges.get(&(b, a)), Some(&1), "edge {a}-{b} is not shared by two triangles");
        }
    }

    /// Normals unit length, pointing away from the centre (or +Y for the plane), and every
    /// triangle's winding (CCW) agrees with its vertex normals.
    fn assert_normals_and_winding(m: &Mesh, outward: impl Fn(Vec3) -> Vec3) {
        assert_eq!(m.normals.len(), m.positions.len());
        assert_eq!(m.uvs.len(), m.positions.len());
        assert_eq!(m.tangents.len(), m.positions.len());
        for (p, n) in m.positions.iter().zip(&m.normals) {
            assert!((n.length() - 1.0).abs() < 1e-5, "normal {n} not unit");
            assert!(n.dot(outward(*p)) > 0.0, "normal {n} at {p} points inwards");
        }
        for t in &m.tangents {
            assert!((t.truncate().length() - 1.0).abs() < 1e-4 && t.w.abs() == 1.0, "tangent {t}");
        }
        for t in &m.indices {
            let [a, b, c] = t.map(|i| m.positions[i as usize]);
            let geo = (b - a).cross(c - a);
            assert!(geo.length() > 0.0, "degenerate triangle {t:?}");
            let avg: Vec3 = t.iter().map(|&i| m.normals[i as usize]).sum();
            assert!(geo.dot(avg) > 0.0, "triangle {t:?} winds against its normals");
        }
    }

    fn bounds(m: &Mesh) -> (Vec3, Vec3) {
        m.positions.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| (lo.min(*p), hi.max(*p)))
    }

    #[test]
    fn plane_is_unit_square_facing_up() {
        let m = plane();
        assert_eq!((m.positions.len(), m.indices.len()), (4, 2));
        assert_normals_and_winding(&m, |_| Vec3::Y);
        assert_eq!(bounds(&m), (Vec3::new(-0.5, 0.0, -0.5), Vec3::new(0.5, 0.0, 0.5)));
        for t in &m.tangents {
            assert!(t.truncate().distance(Vec3::X) < 1e-5, "plane tangent should be +X: {t}");
        }
    }

    #[test]
    fn cube_is_closed_unit_box_with_flat_faces() {
        let m = cube();
        assert_eq!((m.positions.len(), m.indices.len()), (24, 12));
        assert_normals_and_winding(&m, |p| p);
        assert_closed(&m);
        assert_eq!(bounds(&m), (Vec3::splat(-0.5), Vec3::splat(0.5)));
        // Flat: every vertex normal is the axis of its face.
        for (p, n) in m.positions.iter().zip(&m.normals) {
            assert!((p.dot(*n) - 0.5).abs() < 1e-6, "{p} not on the face with normal {n}");
        }
        for uv in &m.uvs {
            assert!(uv.min_element() >= 0.0 && uv.max_element() <= 1.0);
        }
    }

    #[test]
    fn sphere_counts_radius_and_closedness() {
        for (slices, stacks) in [(3, 2), (8, 5), (32, 16)] {
            let m = sphere(slices, stacks);
            let (s, k) = (slices as usize, stacks as usize);
            assert_eq!(m.positions.len(), (s + 1) * (k + 1));
            assert_eq!(m.indices.len(), 2 * s * (k - 1), "{slices}x{stacks}");
            for p in &m.positions {
                assert!((p.length() - 0.5).abs() < 1e-6, "{p} not on the radius-0.5 sphere");
            }
            assert_normals_and_winding(&m, |p| p);
            assert_closed(&m);
        }
        let (lo, hi) = bounds(&sphere(32, 16));
        assert!(lo.distance(Vec3::splat(-0.5)) < 1e-3 && hi.distance(Vec3::splat(0.5)) < 1e-3, "{lo} {hi}");
    }

    #[test]
    fn sphere_clamps_too_few_segments() {
        let m = sphere(0, 1);
        // Clamped to 3 slices × 2 stacks: 2·slices·(stacks − 1) = 6 triangles.
        assert_eq!(m.indices.len(), 6);
        assert_closed(&m);
    }
}
