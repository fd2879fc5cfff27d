//! The second phase's per-object quantities (paper §3.2, eq. 1–3, Table 3; design §4).

use glam::{Mat4, Vec3};

/// What the heuristic needs to know about one scene object this frame.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectInput {
    /// For the report only.
    pub name: String,
    /// A: visible pixels with this object's id (see [`crate::count_visible_pixels`]).
    pub area: u64,
    /// Centre of the object's world-space bounding box.
    pub bbox_center: Vec3,
    /// The object's material reflects (reflectivity > 0): it needs reflection rays.
    pub reflective: bool,
    /// The object's material refracts (opacity < 1): it needs refraction rays.
    pub refractive: bool,
    /// K: static relevance (user-set, ≥ 0).
    pub relevance: f32,
    /// E: estimated cost factor (user-set, ≥ 0).
    pub cost: f32,
}

/// What the heuristic needs to know about the frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameInput {
    /// World → clip (e.g. `Camera::view_projection(aspect)`); only clip x, y and w are used, so
    /// the depth convention (reversed-Z) does not matter.
    pub view_proj: Mat4,
    /// World-space camera position.
    pub camera_position: Vec3,
    /// Number of lights in the scene (all kinds).
    pub light_count: usize,
}

/// D is clamped to at least this (world units) so that an object whose bounding-box centre sits
/// exactly at the camera gets a huge but finite V instead of a division by zero.
pub const MIN_DISTANCE: f64 = 1e-4;

/// The second phase's quantities for one object (Table 3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Terms {
    /// P: centre weight in [0.01, 1].
    pub p: f64,
    /// D: distance camera → bounding-box centre (≥ [`MIN_DISTANCE`]).
    pub d: f64,
    /// V = A·P/D (eq. 1).
    pub v: f64,
    /// Q: estimated rays per pixel.
    pub q: u64,
    /// C = A·Q·E (eq. 2).
    pub c: f64,
    /// R = (S·I + V)·K (eq. 3).
    pub r: f64,
}

/// P: `max(1 − √(x² + y²), 0)·0.99 + 0.01` with (x, y) the world point `center` in NDC; 0.01
/// when the point is off screen (|x| > 1 or |y| > 1) or not in front of the camera (clip w ≤ 0).
pub fn center_weight(view_proj: Mat4, center: Vec3) -> f64 {
    const OFF_SCREEN: f64 = 0.01;
    let clip = view_proj.as_dmat4() * center.as_dvec3().extend(1.0);
    if clip.w.is_nan() || clip.w <= 0.0 {
        return OFF_SCREEN;
    }
    let (x, y) = (clip.x / clip.w, clip.y / clip.w);
    // Written so that NaN (a degenerate matrix) also counts as off screen.
    if !(x.abs() <= 1.0 && y.abs() <= 1.0) {
        return OFF_SCREEN;
    }
    (1.0 - (x * x + y * y).sqrt()).max(0.0) * 0.99 + 0.01
}

/// D: distance from the camera to `center`, at least [`MIN_DISTANCE`].
pub fn distance(camera_position: Vec3, center: Vec3) -> f64 {
    (center.as_dvec3() - camera_position.as_dvec3()).length().max(MIN_DISTANCE)
}

/// Q: one ray per light (shadows); + 1 + lights if reflective (the reflection ray and shadow rays
/// at its hit); + 4 + lights if refractive (paper §3.2).
pub fn ray_count(light_count: usize, reflective: bool, refractive: bool) -> u64 {
    let lights = light_count as u64;
    let mut q = lights;
    if reflective {
        q += 1 + lights;
    }
    if refractive {
        q += 4 + lights;
    }
    q
}

/// All of Table 3's heuristic variables for one object. `was_selected` is S, `importance` is I.
pub fn terms(object: &ObjectInput, frame: &FrameInput, was_selected: bool, importance: f32) -> Terms {
    let a = object.area as f64;
    let p = center_weight(frame.view_proj, object.bbox_center);
    let d = distance(frame.camera_position, object.bbox_center);
    let v = a * p / d;
    let q = ray_count(frame.light_count, object.reflective, object.refractive);
    let c = a * q as f64 * f64::from(object.cost);
    let s = if was_selected { 1.0 } else { 0.0 };
    let r = (s * f64::from(importance) + v) * f64::from(object.relevance);
    Terms { p, d, v, q, c, r }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1.0)
    }

    /// An orthographic-like "projection" that maps world x, y to NDC directly with w = −z
    /// (a camera at the origin looking down −Z with a 90° field of view and aspect 1).
    fn simple_view_proj() -> Mat4 {
        Mat4::from_cols_array(&[1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 1.0, 0.0])
    }

    #[test]
    fn p_on_screen_off_screen_behind() {
        let vp = simple_view_proj();
        // Dead centre: 1.0.
        assert!(close(center_weight(vp, Vec3::new(0.0, 0.0, -5.0)), 1.0));
        // (3, 4, −10) → NDC (0.3, 0.4), radius 0.5 → 0.5·0.99 + 0.01 = 0.505.
        assert!(close(center_weight(vp, Vec3::new(3.0, 4.0, -10.0)), 0.505));
        // (0.8, 0.8) on screen but radius > 1 → max(…, 0) → 0.01.
        assert!(close(center_weight(vp, Vec3::new(8.0, 8.0, -10.0)), 0.01));
        // Off screen: x = 1.5.
        assert!(close(center_weight(vp, Vec3::new(15.0, 0.0, -10.0)), 0.01));
        // Behind the camera: w = −z < 0, although x/w, y/w would be on screen.
        assert!(close(center_weight(vp, Vec3::new(0.0, 0.0, 5.0)), 0.01));
        // In the camera plane: w = 0.
        assert!(close(center_weight(vp, Vec3::new(1.0, 0.0, 0.0)), 0.01));
        // Degenerate matrix: NaN → off screen.
        assert!(close(center_weight(Mat4::NAN, Vec3::ONE), 0.01));
    }

    #[test]
    fn p_with_a_real_camera() {
        // A camera looking at the point gives P = 1 whatever the projection details.
        let camera = hybrid_scene::Camera::default();
        let vp = camera.view_projection(16.0 / 9.0);
        assert!(close(center_weight(vp, camera.target), 1.0));
        // Straight behind the camera.
        let behind = camera.position - (camera.target - camera.position);
        assert!(close(center_weight(vp, behind), 0.01));
    }

    #[test]
    fn d_and_its_guard() {
        assert!(close(distance(Vec3::new(1.0, 2.0, 3.0), Vec3::new(4.0, 6.0, 3.0)), 5.0));
        assert_eq!(distance(Vec3::ONE, Vec3::ONE), MIN_DISTANCE);
    }

    #[test]
    fn q_counts_rays() {
        assert_eq!(ray_count(0, false, false), 0);
        assert_eq!(ray_count(3, false, false), 3);
        assert_eq!(ray_count(3, true, false), 3 + 4);
        assert_eq!(ray_count(3, false, true), 3 + 7);
        assert_eq!(ray_count(3, true, true), 3 + 4 + 7);
        assert_eq!(ray_count(0, true, true), 1 + 4);
    }

    #[test]
    fn hand_computed_terms() {
        let frame = FrameInput { view_proj: simple_view_proj(), camera_position: Vec3::ZERO, light_count: 2 };
        // Centre (3, 4, −10): P = 0.505, D = √125.
        let object = ObjectInput {
            name: "mirror".into(),
            area: 1000,
            bbox_center: Vec3::new(3.0, 4.0, -10.0),
            reflective: true,
            refractive: true,
            relevance: 2.0,
            cost: 1.5,
        };
        let d = 125f64.sqrt();
        let v = 1000.0 * 0.505 / d; // ≈ 45.1685
        let q = 2 + 3 + 6; // lights, + 1 + lights, + 4 + lights
        let t = terms(&object, &frame, false, 10.0);
        assert!(close(t.p, 0.505));
        assert!(close(t.d, d));
        assert!(close(t.v, v));
        assert_eq!(t.q, q);
        assert!(close(t.c, 1000.0 * 11.0 * 1.5));
        assert!(close(t.r, v * 2.0));
        // Selected last frame: R gains S·I before K multiplies.
        let t = terms(&object, &frame, true, 10.0);
        assert!(close(t.r, (10.0 + v) * 2.0));

        // The same object off screen and not reflective: P = 0.01.
        let off = ObjectInput { bbox_center: Vec3::new(30.0, 0.0, -10.0), reflective: false, ..object };
        let t = terms(&off, &frame, false, 10.0);
        let d = (900f64 + 100.0).sqrt();
        assert!(close(t.v, 1000.0 * 0.01 / d));
        assert_eq!(t.q, 2 + 6);
        assert!(close(t.c, 1000.0 * 8.0 * 1.5));
        assert!(close(t.r, 1000.0 * 0.01 / d * 2.0));
    }
}
