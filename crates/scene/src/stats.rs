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

    use glam::Vec3;

    use crate::model::*;

    fn scene() -> Scene {
        let tri = |material| Mesh { positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y], indices: vec![[0, 1, 2]], material, ..Mesh::default() };
        let object = |name: &str, meshes, x: f32| Object {
            name: name.into(),
            source: ObjectSource::Plane,
            transform: Transform { position: Vec3::new(x, 0.0, 0.0), ..Transform::default() },
            meshes,
            relevance: 1.0,
            cost: 1.0,
        };
        let mirror = Material { reflectivity: 0.5, ..Material::default() };
        let glass = Material { opacity: 0.1, ..Material::default() };
        let light =
            PointLight { position: Vec3::ZERO, color: Vec3::ONE, intensity: 1.0, attenuation: Attenuation::default(), casts_shadows: true };
        Scene {
            source: Some("scenes/room.toml".into()),
            camera: crate::Camera::default(),
            environment: Environment::default(),
            heuristic: HeuristicSettings::default(),
            trace: TraceSettings::default(),
            materials: vec![Material::default(), mirror, glass],
            textures: Vec::new(),
            objects: vec![
                object("plain", vec![tri(0)], 0.0),
                object("mirror+glass", vec![tri(1), tri(2), tri(0)], 10.0),
                object("mirror", vec![tri(1)], -5.0),
            ],
            lights: Lights { directional: Vec::new(), point: vec![light; 2], spot: Vec::new() },
            point_clouds: vec![PointCloud {
                name: "c".into(),
                source: "c.ply".into(),
                points: vec![Vec3::new(0.0, 20.0, 0.0), Vec3::new(1.0, -3.0, 2.0)],
                colors: Vec::new(),
                radius: 0.5,
                coloring: PointColoring::Height,
                specular: Vec3::ZERO,
                shininess: 0.0,
            }],
            camera_path: None,
        }
    }

    #[test]
    fn counts_and_bounds() {
        let s = SceneStats::of(&scene());
        assert_eq!((s.vertices, s.triangles, s.objects), (15, 5, 3));
        assert_eq!((s.reflective_objects, s.refractive_objects), (2, 1));
        assert_eq!(s.lights, LightCounts { directional: 0, point: 2, spot: 0 });
        assert_eq!(s.points, 2);
        assert_eq!(s.bounds.min, [-5.0, -3.5, -0.5]);
        assert_eq!(s.bounds.max, [11.0, 20.5, 2.5]);
        assert_eq!(s.name, "room");
    }

    #[test]
    fn json_has_exactly_the_documented_keys() {
        let v = serde_json::to_value(SceneStats::of(&scene())).unwrap();
        let keys = |v: &serde_json::Value| {
            let mut k: Vec<String> = v.as_object().unwrap().keys().cloned().collect();
            k.sort();
            k
        };
        assert_eq!(
            keys(&v),
            ["bounds", "lights", "objects", "points", "reflective_objects", "refractive_objects", "triangles", "vertices"]
        );
        assert_eq!(keys(&v["lights"]), ["directional", "point", "spot"]);
        assert_eq!(keys(&v["bounds"]), ["max", "min"]);
        assert_eq!(v["bounds"]["min"], serde_json::json!([-5.0, -3.5, -0.5]));
        assert_eq!(v["triangles"], 5);
    }

    #[test]
    fn display_prints_the_table_4_row() {
        let text = SceneStats::of(&scene()).to_string();
        let row = text.lines().nth(1).unwrap();
        let cols: Vec<&str> = row.split_whitespace().collect();
        assert_eq!(cols, ["room", "5", "3", "2", "1", "2", "2"]);
        assert!(text.lines().next().unwrap().contains("Triangles"));
    }

    #[test]
    fn empty_scene_has_zero_bounds() {
        let mut sc = scene();
        sc.objects.clear();
        sc.point_clouds.clear();
        let s = SceneStats::of(&sc);
        assert_eq!(s.bounds, Bounds::default());
        assert_eq!(s.triangles, 0);
    }

    #[test]
    fn thousands_separators() {
        assert_eq!(thousands(0), "0");
        assert_eq!(thousands(999), "999");
        assert_eq!(thousands(1000), "1,000");
        assert_eq!(thousands(1_046_843), "1,046,843");
    }
}
