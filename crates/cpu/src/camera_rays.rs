//! `camera_rays`: every ray the CPU backend starts at the camera, by what it is for. The three
//! kinds differ in how they invert the camera, each for a reason that shows in the images, so
//! they are kept apart (and kept bit for bit, the GPU backend's WGSL mirrors each one):
//!
//! - [`ViewRays`]: the view basis and the field of view in `f32`. Deferred lighting's view
//!   direction per pixel and the sky behind empty pixels.
//! - [`PrimaryRays`]: the raster's inverse view-projection in `f64`, near plane to far plane, as
//!   the raster clips. `rt-only` primary rays (the G-buffer from rays), the sky behind the trace
//!   stage's empty pixels, texture footprints, and the RT layer's pixels unprojected into the
//!   G-buffer ([`PrimaryRays::point_at_depth`]).
//! - [`RayGen`] / [`PrimaryRay`]: paper 2's ray generation for the capsule, inverting the
//!   projection exactly (`x_ndc / P₀₀`) from the exact eye, so that block D's synthesized depth
//!   projects back onto the pixel centre even with a 1 cm near plane.

use glam::{DMat4, DVec3, Mat4, Vec3};
use hybrid_core::depth_merge::{synthesize_depth, synthesize_depth_orthographic, view_z_from_depth, view_z_from_depth_orthographic};
use hybrid_scene::{Camera, Projection};

/// Primary rays of a camera for a `width × height` image (row 0 at the top), through pixel
/// centres, matching the raster's view-projection exactly: the ray of pixel (x, y) projects onto
/// that pixel centre.
///
/// Perspective rays start at the eye (the camera position), so a hit at parameter `t` along the
/// unit direction lies at view depth `t · (dir · forward)`; orthographic rays start on the plane
/// through the camera position, all along `forward`. Neither is clipped at the near plane:
/// callers who want the raster's near clipping start at `t = near / (dir · forward)`.
#[derive(Debug, Clone, Copy)]
pub struct ViewRays {
    pub(crate) origin: Vec3,
    pub(crate) right: Vec3,
    pub(crate) up: Vec3,
    pub(crate) forward: Vec3,
    /// Half extents of the image at unit distance (perspective) or in world units (ortho).
    pub(crate) half_w: f32,
    pub(crate) half_h: f32,
    pub(crate) width: f32,
    pub(crate) height: f32,
    pub(crate) orthographic: bool,
}

impl ViewRays {
    pub fn new(camera: &Camera, width: u32, height: u32) -> Self {
        // The basis of the view matrix itself, so rays and raster share one camera frame.
        let inv_view = camera.view().inverse();
        let aspect = width as f32 / height.max(1) as f32;
        let (half_h, orthographic) = match camera.projection {
            Projection::Perspective { fov_y_deg, .. } => ((fov_y_deg.to_radians() * 0.5).tan(), false),
            Projection::Orthographic { height, .. } => (height * 0.5, true),
        };
        Self {
            origin: inv_view.w_axis.truncate(),
            right: inv_view.x_axis.truncate(),
            up: inv_view.y_axis.truncate(),
            forward: -inv_view.z_axis.truncate(),
            half_w: half_h * aspect,
            half_h,
            width: width as f32,
            height: height as f32,
            orthographic,
        }
    }

    /// Ray through the continuous image position (sx, sy) in pixels ((0, 0) = top-left corner of
    /// the image; pixel centres are at +0.5). Returns (origin, unit direction).
    #[inline]
    pub fn ray_at(&self, sx: f32, sy: f32) -> (Vec3, Vec3) {
        let nx = sx / self.width * 2.0 - 1.0;
        let ny = 1.0 - sy / self.height * 2.0;
        let offset = self.right * (nx * self.half_w) + self.up * (ny * self.half_h);
        if self.orthographic {
            (self.origin + offset, self.forward)
        } else {
            (self.origin, (self.forward + offset).normalize_or(self.forward))
        }
    }

    /// Ray through the centre of pixel (px, py).
    #[inline]
    pub fn ray(&self, px: u32, py: u32) -> (Vec3, Vec3) {
        self.ray_at(px as f32 + 0.5, py as f32 + 0.5)
    }

    /// Unit direction from a surface point towards the viewer (−forward for orthographic).
    #[inline]
    pub fn view_dir(&self, point: Vec3) -> Vec3 {
        if self.orthographic { -self.forward } else { (self.origin - point).normalize_or(-self.forward) }
    }
}

/// The primary ray (origin, unit direction) through the centre of pixel (px, py) of a
/// `width × height` image; see [`ViewRays`] (build one of those for many rays).
pub fn primary_ray(camera: &Camera, width: u32, height: u32, px: u32, py: u32) -> (Vec3, Vec3) {
    ViewRays::new(camera, width, height).ray(px, py)
}

/// Primary rays through pixel centres (row 0 at the top), from the inverse of the raster's
/// view-projection, so a hit projects back onto its pixel centre. Each ray starts on the near
/// plane and ends on the far plane, as the raster clips.
#[derive(Debug, Clone, Copy)]
pub struct PrimaryRays {
    inv_view_proj: DMat4,
    width: u32,
    height: u32,
    /// World size of one pixel at unit distance (perspective) or everywhere (orthographic).
    pixel_size: f32,
    orthographic: bool,
    camera: Vec3,
    /// −forward: the view direction of orthographic cameras and the fallback of perspective ones.
    back: Vec3,
}

impl PrimaryRays {
    pub fn new(camera: &Camera, width: u32, height: u32) -> Self {
        let (w, h) = (width.max(1), height.max(1));
        let aspect = w as f32 / h as f32;
        let vp = camera.view_projection(aspect).as_dmat4();
        let pixel_size = match camera.projection {
            Projection::Perspective { fov_y_deg, .. } => 2.0 * (fov_y_deg.to_radians() * 0.5).tan() / h as f32,
            Projection::Orthographic { height, .. } => height / h as f32,
        };
        Self {
            inv_view_proj: vp.inverse(),
            width: w,
            height: h,
            pixel_size,
            orthographic: camera.is_orthographic(),
            camera: camera.position,
            back: -camera.forward(),
        }
    }

    /// `(origin on the near plane, unit direction, distance to the far plane)` for pixel (x, y).
    pub fn ray(&self, x: u32, y: u32) -> (Vec3, Vec3, f32) {
        let nx = (x as f64 + 0.5) / self.width as f64 * 2.0 - 1.0;
        let ny = 1.0 - (y as f64 + 0.5) / self.height as f64 * 2.0;
        let near = self.inv_view_proj.project_point3(DVec3::new(nx, ny, 1.0));
        let far = self.inv_view_proj.project_point3(DVec3::new(nx, ny, 0.0));
        let d = far - near;
        let len = d.length();
        if len <= 0.0 || !len.is_finite() {
            return (near.as_vec3(), Vec3::NEG_Z, 0.0);
        }
        (near.as_vec3(), (d / len).as_vec3(), len as f32)
    }

    /// The world point at reversed-Z `depth` on pixel (x, y)'s centre (the RT layer's pixels
    /// put back where they were hit).
    pub fn point_at_depth(&self, x: u32, y: u32, depth: f32) -> Vec3 {
        let ndc =
            DVec3::new((x as f64 + 0.5) / self.width as f64 * 2.0 - 1.0, 1.0 - (y as f64 + 0.5) / self.height as f64 * 2.0, depth as f64);
        self.inv_view_proj.project_point3(ndc).as_vec3()
    }

    /// Unit vector from `point` towards the camera (−forward for orthographic cameras).
    pub fn towards_camera(&self, point: Vec3) -> Vec3 {
        if self.orthographic { self.back } else { (self.camera - point).normalize_or(self.back) }
    }

    /// World size of one pixel at `point` (for texture footprints).
    pub(crate) fn pixel_world_size(&self, point: Vec3) -> f32 {
        if self.orthographic { self.pixel_size } else { self.pixel_size * point.distance(self.camera) }
    }
}

/// One pixel's primary ray (ray generation, paper eq. 3–5): world origin, unit world direction,
/// the direction's view-space z (for block D) and the frustum's `t` range (near to far plane).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrimaryRay {
    pub origin: Vec3,
    pub dir: Vec3,
    pub dir_view_z: f32,
    pub t_min: f32,
    pub t_max: f32,
}

/// Ray generation for a camera and image size: pixel centres, row 0 at the top. The view-space
/// direction inverts the camera's projection exactly (`x_ndc / P₀₀`, `y_ndc / P₁₁`), so a hit
/// projects back onto its pixel centre with the raster's view-projection.
#[derive(Debug, Clone, Copy)]
pub struct RayGen {
    /// View → world rotation (the transpose of the view matrix's rotation).
    pub(crate) view_inv: Mat4,
    /// The camera position, exactly (not through the inverse matrix, whose rounding is ~1e-7 of the
    /// camera's distance from the origin: too much for a 1 cm near plane).
    pub(crate) eye: Vec3,
    pub(crate) sx: f32,
    pub(crate) sy: f32,
    pub(crate) width: f32,
    pub(crate) height: f32,
    pub(crate) near: f32,
    pub(crate) far: f32,
    pub(crate) ortho: bool,
}

impl RayGen {
    pub fn new(camera: &Camera, width: u32, height: u32) -> Self {
        let aspect = width.max(1) as f32 / height.max(1) as f32;
        let p = camera.projection(aspect);
        let (near, far) = camera.near_far();
        let view = camera.view();
        let rot = Mat4::from_mat3(glam::Mat3::from_mat4(view).transpose());
        Self {
            view_inv: rot,
            eye: camera.position,
            sx: p.x_axis.x,
            sy: p.y_axis.y,
            width: width as f32,
            height: height as f32,
            near,
            far,
            ortho: camera.is_orthographic(),
        }
    }

    #[inline]
    pub fn ray(&self, col: u32, row: u32) -> PrimaryRay {
        self.ray_at(self.view_x(col), self.view_y(row))
    }

    /// The view-plane x of column `col`'s centre (`x_ndc / P₀₀`); depends on the column only, so
    /// a frame computes it once per column for [`RayGen::ray_at`].
    #[inline]
    pub fn view_x(&self, col: u32) -> f32 {
        let x = 2.0 * (col as f32 + 0.5) / self.width - 1.0;
        x / self.sx
    }

    /// The view-plane y of row `row`'s centre (`y_ndc / P₁₁`), as [`RayGen::view_x`].
    #[inline]
    pub fn view_y(&self, row: u32) -> f32 {
        let y = 1.0 - 2.0 * (row as f32 + 0.5) / self.height;
        y / self.sy
    }

    /// The ray through view-plane point (`view_x(col)`, `view_y(row)`): `ray(col, row)`, bit for bit.
    #[inline]
    pub fn ray_at(&self, vx: f32, vy: f32) -> PrimaryRay {
        if self.ortho {
            let origin = self.eye + self.view_inv.transform_vector3(Vec3::new(vx, vy, 0.0));
            let dir = self.view_inv.transform_vector3(Vec3::NEG_Z).normalize();
            PrimaryRay { origin, dir, dir_view_z: -1.0, t_min: self.near, t_max: self.far }
        } else {
            let dv = Vec3::new(vx, vy, -1.0).normalize();
            let dir = self.view_inv.transform_vector3(dv);
            let origin = self.eye;
            PrimaryRay { origin, dir, dir_view_z: dv.z, t_min: self.near / -dv.z, t_max: self.far / -dv.z }
        }
    }

    /// Block D: reversed-Z window depth of the point at `t` along `ray`.
    #[inline]
    pub fn depth(&self, ray: &PrimaryRay, t: f32) -> f32 {
        if self.ortho {
            synthesize_depth_orthographic(t, ray.dir_view_z, self.near, self.far)
        } else {
            synthesize_depth(t, ray.dir_view_z, self.near, self.far)
        }
    }

    /// The `t` along `ray` at which it reaches reversed-Z depth `z_w` (inverse of block D).
    #[inline]
    pub fn t_at_depth(&self, ray: &PrimaryRay, z_w: f32) -> f32 {
        let z_e =
            if self.ortho { view_z_from_depth_orthographic(z_w, self.near, self.far) } else { view_z_from_depth(z_w, self.near, self.far) };
        z_e / ray.dir_view_z
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rays_project_onto_their_pixel_centres() {
        for projection in [
            Projection::Perspective { fov_y_deg: 70.0, near: 0.1, far: 100.0 },
            Projection::Orthographic { height: 6.0, near: 0.1, far: 100.0 },
        ] {
            let cam = Camera { position: Vec3::new(1.0, 2.0, 3.0), target: Vec3::new(-1.0, 0.5, -2.0), up: Vec3::Y, projection };
            let (w, h) = (64u32, 36u32);
            let vp = cam.view_projection(w as f32 / h as f32);
            let rays = ViewRays::new(&cam, w, h);
            for (x, y) in [(0u32, 0u32), (63, 35), (10, 30), (32, 18)] {
                let (o, d) = rays.ray(x, y);
                assert!((d.length() - 1.0).abs() < 1e-5);
                let p = vp.project_point3(o + d * 7.5);
                let sx = (p.x * 0.5 + 0.5) * w as f32;
                let sy = (0.5 - p.y * 0.5) * h as f32;
                assert!((sx - (x as f32 + 0.5)).abs() < 1e-3 && (sy - (y as f32 + 0.5)).abs() < 1e-3, "{x},{y} -> {sx},{sy}");
                assert_eq!(primary_ray(&cam, w, h, x, y), (o, d));
            }
        }
    }
}
