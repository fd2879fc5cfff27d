//! `point_colors`: the colour of each point-cloud sphere, one rule for both backends — the file's
//! colours when it has one per point, else the cloud's uniform colour or a colour map over height
//! (the shipped tree scans have no colours).

use glam::Vec3;
use hybrid_scene::texture::srgb_to_linear;
use hybrid_scene::{PointCloud, PointColoring};

/// Colour map over height: brown at the cloud's lowest point, green at its highest (linear).
pub const HEIGHT_LOW: Vec3 = Vec3::new(0.20, 0.11, 0.04);
pub const HEIGHT_HIGH: Vec3 = Vec3::new(0.12, 0.42, 0.08);

/// How one cloud's spheres get their (linear) albedo.
#[derive(Debug, Clone)]
pub enum PointColors {
    /// sRGB colours from the file, by original point index.
    File(Vec<[u8; 3]>),
    /// One linear colour for every point.
    Uniform(Vec3),
    /// [`HEIGHT_LOW`] at `y_min` to [`HEIGHT_HIGH`] at the top (`inv_range` = 1 / height span).
    Height { y_min: f32, inv_range: f32 },
}

impl PointColors {
    /// The rule for `pc`: its coloring setting, with file colours only when there is one per point.
    pub fn of(pc: &PointCloud) -> Self {
        let height = || {
            let (lo, hi) = pc.points.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), p| (lo.min(p.y), hi.max(p.y)));
            let range = hi - lo;
            Self::Height { y_min: lo, inv_range: if range > 0.0 { 1.0 / range } else { 0.0 } }
        };
        match &pc.coloring {
            PointColoring::Uniform(c) => Self::Uniform(*c),
            PointColoring::Height => height(),
            PointColoring::FileOrHeight if pc.colors.len() == pc.points.len() && !pc.colors.is_empty() => Self::File(pc.colors.clone()),
            PointColoring::FileOrHeight => height(),
        }
    }

    /// Linear albedo of point `index` (its index in the file), whose centre is `center`.
    #[inline]
    pub fn albedo(&self, index: usize, center: Vec3) -> Vec3 {
        match self {
            Self::Uniform(c) => *c,
            Self::Height { y_min, inv_range } => {
                let h = ((center.y - y_min) * inv_range).clamp(0.0, 1.0);
                HEIGHT_LOW.lerp(HEIGHT_HIGH, h)
            }
            Self::File(colors) => match colors.get(index) {
                Some(c) => {
                    Vec3::new(srgb_to_linear(c[0] as f32 / 255.0), srgb_to_linear(c[1] as f32 / 255.0), srgb_to_linear(c[2] as f32 / 255.0))
                }
                None => HEIGHT_LOW,
            },
        }
    }

    /// Linear albedo of every point of `pc`, in file order.
    pub fn albedos(pc: &PointCloud) -> Vec<Vec3> {
        let colors = Self::of(pc);
        pc.points.iter().enumerate().map(|(i, &p)| colors.albedo(i, p)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud(points: Vec<Vec3>, colors: Vec<[u8; 3]>, coloring: PointColoring) -> PointCloud {
        PointCloud {
            name: "test".into(),
            source: "test.ply".into(),
            points,
            colors,
            radius: 0.1,
            coloring,
            specular: Vec3::ZERO,
            shininess: 0.0,
        }
    }

    #[test]
    fn height_map_runs_from_low_to_high() {
        let pc =
            cloud(vec![Vec3::new(0.0, 1.0, 0.0), Vec3::new(0.0, 3.0, 0.0), Vec3::new(0.0, 2.0, 0.0)], vec![], PointColoring::FileOrHeight);
        let a = PointColors::albedos(&pc);
        assert_eq!(a[0], HEIGHT_LOW);
        assert_eq!(a[1], HEIGHT_HIGH);
        assert!((a[2] - (HEIGHT_LOW + HEIGHT_HIGH) * 0.5).abs().max_element() < 1e-6);
    }

    #[test]
    fn file_colours_only_when_one_per_point() {
        let points = vec![Vec3::ZERO, Vec3::Y];
        let full = cloud(points.clone(), vec![[255, 0, 0], [0, 0, 255]], PointColoring::FileOrHeight);
        assert_eq!(PointColors::albedos(&full), vec![Vec3::X, Vec3::Z]);
        // One colour short: the height map instead.
        let short = cloud(points.clone(), vec![[255, 0, 0]], PointColoring::FileOrHeight);
        assert_eq!(PointColors::albedos(&short), vec![HEIGHT_LOW, HEIGHT_HIGH]);
        let uniform = cloud(points, vec![[255, 0, 0], [0, 0, 255]], PointColoring::Uniform(Vec3::splat(0.5)));
        assert_eq!(PointColors::albedos(&uniform), vec![Vec3::splat(0.5); 2]);
    }
}
