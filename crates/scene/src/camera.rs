//! Cameras (perspective or orthographic, **reversed-Z**: near → depth 1, far → depth 0) and
//! camera paths for benchmarks.

use glam::{Mat4, Vec3, Vec4};

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Projection {
    /// `fov_y_deg`: full vertical field of view in degrees (0 < fov < 180).
    Perspective { fov_y_deg: f32, near: f32, far: f32 },
    /// `height`: height of the view volume in scene units.
    Orthographic { height: f32, near: f32, far: f32 },
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    pub position: Vec3,
    pub target: Vec3,
    pub up: Vec3,
    pub projection: Projection,
}

impl Default for Camera {
    fn default() -> Self {
        Self {
            position: Vec3::new(0.0, 1.0, 5.0),
            target: Vec3::ZERO,
            up: Vec3::Y,
            projection: Projection::Perspective { fov_y_deg: 60.0, near: 0.05, far: 1000.0 },
        }
    }
}

impl Camera {
    pub fn near_far(&self) -> (f32, f32) {
        match self.projection {
            Projection::Perspective { near, far, .. } | Projection::Orthographic { near, far, .. } => (near, far),
        }
    }

    /// World → view (right-handed, camera looks down −Z).
    pub fn view(&self) -> Mat4 {
        look_at_rh(self.position, self.target, self.up)
    }

    /// View → clip with reversed-Z depth in [0, 1]: near plane → 1, far plane → 0.
    ///
    /// For perspective this is `z_w = n·f / ((f − n)·(−z_e)) − n/(f − n)` (design §5).
    pub fn projection(&self, aspect: f32) -> Mat4 {
        match self.projection {
            Projection::Perspective { fov_y_deg, near: n, far: f } => {
                let sy = 1.0 / (fov_y_deg.to_radians() * 0.5).tan();
                // clip.z = n/(f−n)·z_e + n·f/(f−n), clip.w = −z_e.
                Mat4::from_cols(
                    Vec4::new(sy / aspect, 0.0, 0.0, 0.0),
                    Vec4::new(0.0, sy, 0.0, 0.0),
                    Vec4::new(0.0, 0.0, n / (f - n), -1.0),
                    Vec4::new(0.0, 0.0, n * f / (f - n), 0.0),
                )
            }
            Projection::Orthographic { height, near: n, far: f } => {
                let h = height * 0.5;
                let w = h * aspect;
                // z_ndc = z_e/(f−n) + f/(f−n): −n → 1, −f → 0.
                Mat4::from_cols(
                    Vec4::new(1.0 / w, 0.0, 0.0, 0.0),
                    Vec4::new(0.0, 1.0 / h, 0.0, 0.0),
                    Vec4::new(0.0, 0.0, 1.0 / (f - n), 0.0),
                    Vec4::new(0.0, 0.0, f / (f - n), 1.0),
                )
            }
        }
    }

    pub fn view_projection(&self, aspect: f32) -> Mat4 {
        self.projection(aspect) * self.view()
    }

    pub fn is_orthographic(&self) -> bool {
        matches!(self.projection, Projection::Orthographic { .. })
    }

    /// Unit forward direction.
    pub fn forward(&self) -> Vec3 {
        (self.target - self.position).normalize_or(Vec3::NEG_Z)
    }

    /// Unit direction of the view ray that reaches world point `p` (from the camera towards it):
    /// the forward direction for an orthographic camera (or `p` at the eye).
    #[inline]
    pub fn incident_towards(&self, p: Vec3) -> Vec3 {
        // `normalize_or(self.forward())`, with the forward direction (a normalisation of its
        // own) made only when it is needed: this runs once per pixel in the trace and fallbacks.
        if self.is_orthographic() { self.forward() } else { (p - self.position).try_normalize().unwrap_or_else(|| self.forward()) }
    }
}

/// A camera keyframe: where the camera is and what it looks at, at `time` seconds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Keyframe {
    pub time: f32,
    pub position: Vec3,
    pub target: Vec3,
}

/// A camera path through keyframes (sorted by time, at least two). Position and target are
/// interpolated with a centripetal-free uniform Catmull–Rom spline, so the motion is smooth (C¹)
/// through every keyframe. Times before the first / after the last keyframe clamp.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraPath {
    pub keyframes: Vec<Keyframe>,
}

impl CameraPath {
    pub fn duration(&self) -> f32 {
        match (self.keyframes.first(), self.keyframes.last()) {
            (Some(a), Some(b)) => b.time - a.time,
            _ => 0.0,
        }
    }

    /// Position and target at `time` seconds.
    pub fn sample(&self, time: f32) -> (Vec3, Vec3) {
        let k = &self.keyframes;
        match k.len() {
            0 => (Vec3::ZERO, Vec3::NEG_Z),
            1 => (k[0].position, k[0].target),
            _ => {
                let t = time.clamp(k[0].time, k[k.len() - 1].time);
                let i = k.partition_point(|f| f.time <= t).clamp(1, k.len() - 1) - 1;
                let (a, b) = (&k[i], &k[i + 1]);
                let span = (b.time - a.time).max(1e-9);
                let u = ((t - a.time) / span).clamp(0.0, 1.0);
                let prev = if i == 0 { a } else { &k[i - 1] };
                let next = if i + 2 < k.len() { &k[i + 2] } else { b };
                (
                    catmull_rom(prev.position, a.position, b.position, next.position, u),
                    catmull_rom(prev.target, a.target, b.target, next.target, u),
                )
            }
        }
    }

    /// The camera `base` moved to this path's pose at `time` (projection and up kept).
    pub fn camera_at(&self, base: &Camera, time: f32) -> Camera {
        let (position, target) = self.sample(time);
        Camera { position, target, ..*base }
    }
}

/// Right-handed look-at view matrix (camera looks down −Z, `up` is +Y on screen).
pub fn look_at_rh(eye: Vec3, target: Vec3, up: Vec3) -> Mat4 {
    let f = (target - eye).normalize_or(Vec3::NEG_Z);
    let s = f.cross(up).normalize_or(f.any_orthonormal_vector());
    let u = s.cross(f);
    Mat4::from_cols(
        Vec4::new(s.x, u.x, -f.x, 0.0),
        Vec4::new(s.y, u.y, -f.y, 0.0),
        Vec4::new(s.z, u.z, -f.z, 0.0),
        Vec4::new(-s.dot(eye), -u.dot(eye), f.dot(eye), 1.0),
    )
}

fn catmull_rom(p0: Vec3, p1: Vec3, p2: Vec3, p3: Vec3, t: f32) -> Vec3 {
    let t2 = t * t;
    let t3 = t2 * t;
    0.5 * ((2.0 * p1) + (-p0 + p2) * t + (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) * t2 + (-p0 + 3.0 * p1 - 3.0 * p2 + p3) * t3)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam() -> Camera {
        Camera {
            position: Vec3::new(1.0, 2.0, 3.0),
            target: Vec3::ZERO,
            up: Vec3::Y,
            projection: Projection::Perspective { fov_y_deg: 60.0, near: 0.1, far: 100.0 },
        }
    }

    #[test]
    fn reversed_z_maps_near_to_one_and_far_to_zero() {
        let p = cam().projection(1.5);
        let near = p.project_point3(Vec3::new(0.0, 0.0, -0.1));
        let far = p.project_point3(Vec3::new(0.0, 0.0, -100.0));
        assert!((near.z - 1.0).abs() < 1e-6, "{near}");
        assert!(far.z.abs() < 1e-6, "{far}");
    }

    #[test]
    fn reversed_z_is_monotonic_decreasing_with_distance() {
        let p = cam().projection(1.0);
        let mut last = f32::INFINITY;
        for i in 0..1000 {
            let d = 0.1 + i as f32 * 0.0999;
            let z = p.project_point3(Vec3::new(0.0, 0.0, -d)).z;
            assert!(z < last, "depth not decreasing at {d}: {z} >= {last}");
            last = z;
        }
    }

    #[test]
    fn perspective_depth_matches_closed_form() {
        let (n, f) = (0.1f32, 100.0f32);
        let p = cam().projection(1.0);
        for ze in [-0.1f32, -0.5, -1.0, -7.3, -50.0, -100.0] {
            let z = p.project_point3(Vec3::new(0.3, -0.2, ze)).z;
            let closed = n * f / ((f - n) * -ze) - n / (f - n);
            assert!((z - closed).abs() <= 1e-6 * closed.abs().max(1e-3), "{ze}: {z} vs {closed}");
        }
    }

    #[test]
    fn orthographic_reversed_z() {
        let c = Camera { projection: Projection::Orthographic { height: 4.0, near: 1.0, far: 11.0 }, ..cam() };
        let p = c.projection(1.0);
        assert!((p.project_point3(Vec3::new(0.0, 0.0, -1.0)).z - 1.0).abs() < 1e-6);
        assert!(p.project_point3(Vec3::new(0.0, 0.0, -11.0)).z.abs() < 1e-6);
        assert!((p.project_point3(Vec3::new(0.0, 0.0, -6.0)).z - 0.5).abs() < 1e-6);
        assert!((p.project_point3(Vec3::new(0.0, 2.0, -6.0)).y - 1.0).abs() < 1e-6);
    }

    #[test]
    fn camera_path_passes_through_keyframes_and_clamps() {
        let path = CameraPath {
            keyframes: vec![
                Keyframe { time: 0.0, position: Vec3::ZERO, target: Vec3::X },
                Keyframe { time: 1.0, position: Vec3::new(1.0, 0.0, 0.0), target: Vec3::Y },
                Keyframe { time: 3.0, position: Vec3::new(1.0, 2.0, 0.0), target: Vec3::Z },
            ],
        };
        assert_eq!(path.duration(), 3.0);
        for k in &path.keyframes {
            let (p, t) = path.sample(k.time);
            assert!(p.distance(k.position) < 1e-5 && t.distance(k.target) < 1e-5);
        }
        assert_eq!(path.sample(-5.0).0, Vec3::ZERO);
        assert!(path.sample(10.0).0.distance(Vec3::new(1.0, 2.0, 0.0)) < 1e-6);
        // Continuous: small time steps give small moves.
        let mut last = path.sample(0.0).0;
        for i in 1..=300 {
            let p = path.sample(i as f32 * 0.01).0;
            assert!(p.distance(last) < 0.05);
            last = p;
        }
    }
}
