//! `hybrid inspect`: scene statistics — the paper's Table 4 row (triangles, objects, reflective
//! and refractive objects, lights, points) plus vertices and world-space bounds.
//!
//! Serialised as JSON with exactly the keys `vertices, triangles, objects, reflective_objects,
//! refractive_objects, lights {directional, point, spot}, points, bounds {min, max}`.

use std::fmt;

use serde::Serialize;

use crate::model::{Aabb, Scene};

/// Counts for `hybrid inspect`.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct SceneStats {
    /// Scene name (the scene file's stem, or "scene"); shown by `Display`, not serialised.
    #[serde(skip)]
    pub name: String,
    pub vertices: usize,
    pub triangles: usize,
    pub objects: usize,
    pub reflective_objects: usize,
    pub refractive_objects: usize,
    pub lights: LightCounts,
    /// Points over all point clouds.
    pub points: usize,
    /// World-space bounds of every object and point cloud (zeros for an empty scene).
    pub bounds: Bounds,
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct LightCounts {
    pub directional: usize,
    pub point: usize,
    pub spot: usize,
}

impl LightCounts {
    pub fn total(&self) -> usize {
        self.directional + self.point + self.spot
    }
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Bounds {
    pub min: [f32; 3],
    pub max: [f32; 3],
}

impl SceneStats {
    pub fn of(scene: &Scene) -> Self {
        let name =
            scene.source.as_ref().and_then(|p| p.file_stem()).map_or_else(|| "scene".to_owned(), |s| s.to_string_lossy().into_owned());
        let mut bounds = Aabb::EMPTY;
        for o in &scene.objects {
            if let Some(b) = o.world_bounds() {
                bounds = bounds.union(&b);
            }
        }
        for pc in &scene.point_clouds {
            let b = pc.bounds();
            if !b.is_empty() {
                bounds = bounds.union(&b);
            }
        }
        let finite = !bounds.is_empty() && bounds.min.is_finite() && bounds.max.is_finite();
        let mats = &scene.materials;
        // A mesh whose material index is out of range counts as neither reflective nor refractive.
        let has = |o: &crate::Object, f: fn(&crate::Material) -> bool| o.meshes.iter().any(|m| mats.get(m.material).is_some_and(f));
        Self {
            name,
            vertices: scene.objects.iter().map(|o| o.vertex_count()).sum(),
            triangles: scene.objects.iter().map(|o| o.triangle_count()).sum(),
            objects: scene.objects.len(),
            reflective_objects: scene.objects.iter().filter(|o| has(o, crate::Material::is_reflective)).count(),
            refractive_objects: scene.objects.iter().filter(|o| has(o, crate::Material::is_refractive)).count(),
            lights: LightCounts {
                directional: scene.lights.directional.len(),
                point: scene.lights.point.len(),
                spot: scene.lights.spot.len(),
            },
            points: scene.point_clouds.iter().map(|p| p.points.len()).sum(),
            bounds: if finite { Bounds { min: bounds.min.to_array(), max: bounds.max.to_array() } } else { Bounds::default() },
        }
    }
}

/// `1234567` → `1,234,567`.
fn thousands(n: usize) -> String {
    let s = n.to_string();
    let mut out = String::with_capacity(s.len() + s.len() / 3);
    for (i, c) in s.chars().enumerate() {
        if i > 0 && (s.len() - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(c);
    }
    out
}

impl fmt::Display for SceneStats {
    /// The paper's Table 4 row, then vertices, light kinds and bounds.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "{:<24} {:>12} {:>8} {:>11} {:>11} {:>7} {:>12}",
            "Scene", "Triangles", "Objects", "Reflective", "Refractive", "Lights", "Points"
        )?;
        writeln!(
            f,
            "{:<24} {:>12} {:>8} {:>11} {:>11} {:>7} {:>12}",
            self.name,
            thousands(self.triangles),
            thousands(self.objects),
            thousands(self.reflective_objects),
            thousands(self.refractive_objects),
            self.lights.total(),
            thousands(self.points)
        )?;
        writeln!(f, "vertices: {}", thousands(self.vertices))?;
        writeln!(f, "lights: {} directional, {} point, {} spot", self.lights.directional, self.lights.point, self.lights.spot)?;
        let [a, b, c] = self.bounds.min;
        let [x, y, z] = self.bounds.max;
        write!(f, "bounds: ({a:.3}, {b:.3}, {c:.3}) – ({x:.3}, {y:.3}, {z:.3})")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thousands_separators() {
        assert_eq!(thousands(0), "0");
        assert_eq!(thousands(999), "999");
        assert_eq!(thousands(1000), "1,000");
        assert_eq!(thousands(1_046_843), "1,046,843");
    }
}
