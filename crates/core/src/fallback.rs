//! Raster fallbacks (issue 18, beyond paper 1): what an object the heuristic did not select gets
//! instead of ray-traced effects. Shadows come from **shadow maps** (directional: cascades fitted
//! to the view; spot: one perspective map; point: a cube of six), reflections and refractions
//! from a **probe** per reflective or refractive object (a cube map of the lit scene rendered
//! with the raster path from the object's centre, box-projected where the object is room-sized).
//!
//! Everything here is backend-free: which views each light's maps have ([`plan_light_views`]),
//! where each probe sits ([`plan_probes`]), and the per-pixel lookups ([`FallbackScene::pixel`]).
//! Each backend renders the depth maps and the probes' faces with its own raster and runs the
//! same lookups (the GPU's WGSL mirrors them).
//!
//! Conventions: every map is reversed-Z (near 1, far 0, 0 where nothing was drawn), row 0 at the
//! top, texel `(x, y)` centred at `((x + 0.5)/size, (y + 0.5)/size)` in UV.

use glam::{Mat4, Vec2, Vec3, Vec4, Vec4Swizzles};
use hybrid_scene::{Aabb, Camera, Projection, Scene};

use crate::lanes::{V3, dot3, soa};
use crate::prepare::{PreparedScene, floor};
use crate::shading::{FrameLights, Light, facing, lights, reflect, refract_or_reflect, sky};
use crate::{GBuffer, Surface};

/// What pixels of objects the heuristic did not select get (`--fallback`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Fallback {
    /// Shadow maps and probes: effects degrade instead of switching off, at the cost of
    /// rendering the maps (cached) and a lookup per pixel.
    #[default]
    Raster,
    /// Nothing: unselected objects get neither shadows, reflections nor refractions (paper 1
    /// exactly, for reproducing its tables).
    None,
}

impl Fallback {
    pub const NAMES: [&'static str; 2] = ["raster", "none"];

    pub fn as_str(self) -> &'static str {
        match self {
            Fallback::Raster => "raster",
            Fallback::None => "none",
        }
    }

    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "raster" => Some(Fallback::Raster),
            "none" => Some(Fallback::None),
            _ => None,
        }
    }
}

impl std::fmt::Display for Fallback {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// The fallbacks' resolution knobs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FallbackSettings {
    /// Texels per side of each directional cascade and of a spot light's map. Higher values give
    /// sharper, less blocky shadow edges at the cost of memory (4 bytes per texel) and of the
    /// time to render each map.
    pub shadow_map_size: u32,
    /// Texels per side of each of a point light's six cube faces (six maps per light: kept
    /// smaller for the same reason).
    pub cube_shadow_size: u32,
    /// Cascades per directional light (1–4). More cascades keep near shadows sharp over a long
    /// view at the cost of one map each.
    pub cascades: u32,
    /// PCF kernel radius in taps: 0 = one bilinear comparison (2×2 texels, the sharpest edge),
    /// r = (2r + 1)² bilinear comparisons a texel apart (softer edges, hides aliasing, at the
    /// cost of (2r + 1)² times the lookups).
    pub pcf_radius: u32,
    /// Texels per side of each probe face. Higher values sharpen mirror reflections at the cost
    /// of rendering six faces of that size per reflective or refractive object (once: cached).
    pub probe_size: u32,
}

impl Default for FallbackSettings {
    fn default() -> Self {
        Self { shadow_map_size: 1024, cube_shadow_size: 512, cascades: 3, pcf_radius: 0, probe_size: 128 }
    }
}

/// Constant depth bias, in texels of world size at the receiver.
pub const SHADOW_BIAS_TEXELS: f32 = 1.0;
/// Slope-scaled bias: texels per unit of tan(angle between normal and light).
pub const SHADOW_SLOPE_BIAS_TEXELS: f32 = 1.5;
/// Normal offset of the receiver before projecting, in texels of world size.
pub const SHADOW_NORMAL_OFFSET_TEXELS: f32 = 1.0;
/// The slope term's tangent is clamped to this (grazing light would push the bias to infinity).
pub const SHADOW_MAX_SLOPE: f32 = 8.0;

/// One depth map of a light: world → clip (reversed-Z, looking from the light).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShadowView {
    pub view_proj: Mat4,
    /// Texels per side (square).
    pub size: u32,
    pub orthographic: bool,
    pub near: f32,
    pub far: f32,
    /// Orthographic: a texel's world size. Perspective: a texel's world size at unit distance.
    pub texel_world: f32,
    /// Cascades: the camera view distance up to which this cascade is used (the last one covers
    /// everything); ∞ for the other kinds.
    pub split_far: f32,
    /// Cascades: the far distance and grid cell it was fitted with (`cascades`, to keep it).
    pub cascade: Option<CascadeFit>,
}

/// Where a cascade's map was fitted: the cascades' far distance and the cell of the grid its
/// centre was snapped to (in steps of a quarter of its slice's radius, in the light's plane).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CascadeFit {
    pub far: f32,
    pub cell: [i32; 2],
}

impl ShadowView {
    fn new(camera: &Camera, size: u32, split_far: f32, cascade: Option<CascadeFit>) -> Self {
        let (near, far) = camera.near_far();
        let (orthographic, texel_world) = match camera.projection {
            Projection::Orthographic { height, .. } => (true, height / size as f32),
            Projection::Perspective { fov_y_deg, .. } => (false, 2.0 * (fov_y_deg.to_radians() * 0.5).tan() / size as f32),
        };
        Self { view_proj: camera.view_projection(1.0), size, orthographic, near, far, texel_world, split_far, cascade }
    }

    /// Distance along the view axis for reversed-Z depth `z` of this view.
    #[inline]
    pub fn linear_depth(&self, z: f32) -> f32 {
        let (n, f) = (self.near, self.far);
        if self.orthographic { f - z * (f - n) } else { n * f / ((f - n) * z + n) }
    }

    /// Reversed-Z depth of distance `d` along the view axis (inverse of [`Self::linear_depth`]).
    #[inline]
    pub fn depth_of(&self, d: f32) -> f32 {
        let (n, f) = (self.near, self.far);
        if self.orthographic { (f - d) / (f - n) } else { n * f / ((f - n) * d.max(1e-6)) - n / (f - n) }
    }
}

/// Which light a set of views belongs to, and how a point picks its view.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShadowKind {
    /// Cascades, nearest first; a point picks by its camera view distance.
    Directional,
    /// One perspective map.
    Spot,
    /// Six faces in the order +X, −X, +Y, −Y, +Z, −Z; a point picks by the major axis of its
    /// direction from the light.
    Point,
}

/// The views of one shadow-casting light (index `light` in [`lights`] order).
#[derive(Debug, Clone, PartialEq)]
pub struct LightViews {
    pub light: usize,
    pub kind: ShadowKind,
    pub views: Vec<ShadowView>,
}

/// A mesh casts into the shadow maps when its material lets through less than this share of
/// the light (glass does not: the ray-traced shadow of a 10%-opaque sphere is 10% dark, a map can
/// only say all or nothing).
pub const CASTER_MAX_TRANSMITTANCE: f32 = 0.5;

/// Per mesh of `prepared`: whether it casts into the shadow maps (its material's shadow
/// transmittance is below [`CASTER_MAX_TRANSMITTANCE`]; textured opacity counts as opaque).
pub fn caster_meshes(prepared: &PreparedScene) -> Vec<bool> {
    (0..prepared.meshes.len()).map(|m| prepared.mesh_shadow(m) < CASTER_MAX_TRANSMITTANCE).collect()
}

/// The polygons' world bounds (every object with geometry) and, when given, the point clouds'.
pub fn scene_bounds(prepared: &PreparedScene, with_point_clouds: bool) -> Aabb {
    let mut b = prepared.object_bounds.iter().filter(|b| !b.is_empty()).fold(Aabb::EMPTY, |a, b| a.union(b));
    if with_point_clouds {
        for c in &prepared.scene.point_clouds {
            let cb = c.bounds();
            if !cb.is_empty() {
                b = b.union(&cb);
            }
        }
    }
    b
}

fn corners(b: &Aabb) -> [Vec3; 8] {
    std::array::from_fn(|i| {
        Vec3::new(
            if i & 1 == 0 { b.min.x } else { b.max.x },
            if i & 2 == 0 { b.min.y } else { b.max.y },
            if i & 4 == 0 { b.min.z } else { b.max.z },
        )
    })
}

/// An up vector not parallel to `dir`.
fn up_for(dir: Vec3) -> Vec3 {
    if dir.y.abs() > 0.99 { Vec3::Z } else { Vec3::Y }
}

/// The six cube-face directions (+X, −X, +Y, −Y, +Z, −Z) and their up vectors.
pub const CUBE_FACES: [(Vec3, Vec3); 6] = [
    (Vec3::X, Vec3::NEG_Y),
    (Vec3::NEG_X, Vec3::NEG_Y),
    (Vec3::Y, Vec3::Z),
    (Vec3::NEG_Y, Vec3::NEG_Z),
    (Vec3::Z, Vec3::NEG_Y),
    (Vec3::NEG_Z, Vec3::NEG_Y),
];

/// The cube face (index into [`CUBE_FACES`]) a direction falls on: its major axis.
#[inline]
pub fn cube_face(d: Vec3) -> usize {
    let a = d.abs();
    if a.x >= a.y && a.x >= a.z {
        if d.x > 0.0 { 0 } else { 1 }
    } else if a.y >= a.z {
        if d.y > 0.0 { 2 } else { 3 }
    } else if d.z > 0.0 {
        4
    } else {
        5
    }
}

/// The 90° camera of cube face `face` at `position`.
pub fn cube_face_camera(position: Vec3, face: usize, near: f32, far: f32) -> Camera {
    let (dir, up) = CUBE_FACES[face];
    Camera { position, target: position + dir, up, projection: Projection::Perspective { fov_y_deg: 90.0, near, far } }
}

/// Near and far planes for a perspective map from `from` that must see all of `bounds`.
fn perspective_range(from: Vec3, bounds: &Aabb) -> (f32, f32) {
    let far = corners(bounds).iter().map(|c| c.distance(from)).fold(0.0f32, f32::max).max(1e-3) * 1.01;
    (far * 1e-4, far)
}

/// The views of every shadow-casting light for a frame seen by `camera` at `aspect`. Spot and
/// point views depend only on the light and the scene; directional cascades also on the camera
/// (see [`cascades`]). `previous(light, k)` is the view light `light`'s map `k` was last
/// rendered with, if any: a cascade keeps it while it still covers its slice of the view, so
/// along a camera path the cascades are re-rendered only now and then, not every frame.
pub fn plan_light_views(
    scene: &Scene,
    bounds: &Aabb,
    camera: &Camera,
    aspect: f32,
    settings: &FallbackSettings,
    previous: &dyn Fn(usize, usize) -> Option<ShadowView>,
) -> Vec<LightViews> {
    let mut out = Vec::new();
    if bounds.is_empty() {
        return out;
    }
    for (k, light) in lights(&scene.lights).enumerate() {
        if !light.casts_shadows() {
            continue;
        }
        let (kind, views) = match light {
            Light::Directional(l) => {
                (ShadowKind::Directional, cascades(l.direction, bounds, camera, aspect, settings, &|c| previous(k, c)))
            }
            Light::Spot(l) => {
                let (near, far) = perspective_range(l.position, bounds);
                let fov = (2.0 * l.outer_angle.to_degrees() + 2.0).clamp(1.0, 170.0);
                let cam = Camera {
                    position: l.position,
                    target: l.position + l.direction,
                    up: up_for(l.direction),
                    projection: Projection::Perspective { fov_y_deg: fov, near, far },
                };
                (ShadowKind::Spot, vec![ShadowView::new(&cam, settings.shadow_map_size, f32::INFINITY, None)])
            }
            Light::Point(l) => {
                let (near, far) = perspective_range(l.position, bounds);
                let views = (0..6)
                    .map(|f| ShadowView::new(&cube_face_camera(l.position, f, near, far), settings.cube_shadow_size, f32::INFINITY, None))
                    .collect();
                (ShadowKind::Point, views)
            }
        };
        if !views.is_empty() {
            out.push(LightViews { light: k, kind, views });
        }
    }
    out
}

/// Split distances of `count` cascades over [near, far]: the practical split (half logarithmic,
/// half uniform).
pub fn cascade_splits(near: f32, far: f32, count: u32) -> Vec<f32> {
    let count = count.clamp(1, 4);
    (1..=count)
        .map(|i| {
            let t = i as f32 / count as f32;
            let log = near * (far / near).powf(t);
            let uni = near + (far - near) * t;
            0.5 * (log + uni)
        })
        .collect()
}

/// The cascades' farthest distance is rounded up to one of these steps per doubling, so that
/// it stays the same while the view's reach changes a little (a new far distance moves every
/// split and re-renders every cascade).
pub const CASCADE_FAR_STEPS_PER_OCTAVE: f32 = 4.0;

/// A directional light's cascades for `camera`: the view, up to the farthest scene point in front
/// of it, split into `settings.cascades` slices (the practical split), each covered by an
/// orthographic map around the slice's bounding sphere.
///
/// What makes them re-render rarely along a camera path:
/// - the far distance is rounded up to a step of [`CASCADE_FAR_STEPS_PER_OCTAVE`] (and the last
///   frame's, one step further, is kept), so the splits and the spheres' radii stay fixed;
/// - a slice's sphere depends only on the slice, not on the camera's rotation, and its centre is
///   snapped to a grid of a quarter of its radius, the map grown by √2 grid steps;
/// - a map from `previous` is kept while the slice's sphere still lies inside it, i.e. until its
///   centre has moved √2 grid steps from the map's: where a freshly snapped map would move every
///   time the centre crosses a grid line.
fn cascades(
    direction: Vec3,
    bounds: &Aabb,
    camera: &Camera,
    aspect: f32,
    settings: &FallbackSettings,
    previous: &dyn Fn(usize) -> Option<ShadowView>,
) -> Vec<ShadowView> {
    let dir = direction.normalize_or(Vec3::NEG_Y);
    let forward = camera.forward();
    let (cam_near, cam_far) = camera.near_far();
    // Shadows are needed up to the farthest scene point in front of the camera.
    let reach = corners(bounds).iter().map(|c| (*c - camera.position).dot(forward)).fold(0.0f32, f32::max);
    let needed_far = reach.min(cam_far).max(cam_near * 2.0);
    let far_of_step = |step: f32| 2f32.powf(step / CASCADE_FAR_STEPS_PER_OCTAVE).min(cam_far).max(cam_near * 2.0);
    let far_step = (needed_far.log2() * CASCADE_FAR_STEPS_PER_OCTAVE).ceil();
    let kept_far = previous(0).and_then(|v| v.cascade).map(|c| c.far);
    let far = if kept_far == Some(far_of_step(far_step + 1.0)) { far_of_step(far_step + 1.0) } else { far_of_step(far_step) };
    let near = cam_near.max(far * 1e-4);
    // Light basis, as look_at_rh builds it.
    let up = up_for(dir);
    let s = dir.cross(up).normalize();
    let u = s.cross(dir);
    // Scene extent along the light: every caster lies between these.
    let along: Vec<f32> = corners(bounds).iter().map(|c| c.dot(dir)).collect();
    let (d_min, d_max) = along.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
    let margin = (d_max - d_min) * 0.01 + 1e-3;
    // Half width and height of the view at distance d.
    let half = |d: f32| match camera.projection {
        Projection::Perspective { fov_y_deg, .. } => {
            let t = (fov_y_deg.to_radians() * 0.5).tan() * d;
            (t * aspect, t)
        }
        Projection::Orthographic { height, .. } => (height * 0.5 * aspect, height * 0.5),
    };
    let mut start = near;
    cascade_splits(near, far, settings.cascades)
        .into_iter()
        .enumerate()
        .map(|(k, end)| {
            // The slice's bounding sphere, in the camera's frame: centred on the view axis
            // halfway through the slice, through its farthest corner. Its radius depends only on
            // the slice (bit for bit, whatever the camera's pose).
            let mid = 0.5 * (start + end);
            let corner_distance = |d: f32| {
                let (hx, hy) = half(d);
                (hx * hx + hy * hy + (d - mid) * (d - mid)).sqrt()
            };
            let radius = corner_distance(start).max(corner_distance(end)).max(1e-3);
            let centre = camera.position + forward * mid;
            let (x, y) = (centre.dot(s), centre.dot(u));
            let step = radius * 0.25;
            let slack = step * std::f32::consts::SQRT_2;
            let view_at = |cell: [i32; 2]| {
                let r = radius + slack;
                let eye = s * (cell[0] as f32 * step) + u * (cell[1] as f32 * step) + dir * (d_min - margin);
                let cam = Camera {
                    position: eye,
                    target: eye + dir,
                    up,
                    projection: Projection::Orthographic { height: 2.0 * r, near: 0.0, far: d_max - d_min + 2.0 * margin },
                };
                ShadowView::new(&cam, settings.shadow_map_size, end, Some(CascadeFit { far, cell }))
            };
            start = end;
            // Last frame's map, while the sphere still lies inside it (and nothing else changed).
            let kept = previous(k).filter(|v| {
                v.cascade.is_some_and(|c| {
                    let inside =
                        (x - c.cell[0] as f32 * step).abs() <= slack * 0.999 && (y - c.cell[1] as f32 * step).abs() <= slack * 0.999;
                    c.far == far && inside && view_at(c.cell) == *v
                })
            });
            kept.unwrap_or_else(|| view_at([(x / step).round() as i32, (y / step).round() as i32]))
        })
        .collect()
}

/// A rendered depth map: [`ShadowView`] and its texels (reversed-Z, row 0 at the top).
#[derive(Debug, Clone, PartialEq)]
pub struct ShadowMap {
    pub view: ShadowView,
    pub depth: Vec<f32>,
}

/// UV and reversed-Z depth of a world point in a view (`None` behind a perspective view).
#[inline]
pub fn project(view_proj: &Mat4, p: Vec3) -> Option<(Vec2, f32)> {
    let c = *view_proj * p.extend(1.0);
    if c.w <= 0.0 {
        return None;
    }
    let ndc = c.xyz() / c.w;
    Some((Vec2::new(ndc.x * 0.5 + 0.5, 0.5 - ndc.y * 0.5), ndc.z))
}

impl ShadowMap {
    /// 1 where texel `(x, y)` (clamped to the map) is no nearer than `z_ref`, else 0.
    #[inline(always)]
    fn lit(&self, x: i32, y: i32, z_ref: f32) -> f32 {
        let n = self.view.size as i32;
        let (x, y) = (x.clamp(0, n - 1), y.clamp(0, n - 1));
        if self.depth[(y * n + x) as usize] <= z_ref { 1.0 } else { 0.0 }
    }

    /// A bilinear comparison (hardware-style PCF): the four texels around `uv` compared with
    /// `z_ref`, weighted by their bilinear weights.
    #[inline(always)]
    pub fn compare_bilinear(&self, uv: Vec2, z_ref: f32) -> f32 {
        let n = self.view.size as f32;
        let t = uv * n - Vec2::splat(0.5);
        let (x0, y0) = (floor(t.x), floor(t.y));
        let (fx, fy) = (t.x - x0, t.y - y0);
        let (x0, y0) = (x0 as i32, y0 as i32);
        let size = self.view.size as i32;
        // Inside the map (nearly every lookup) the four texels are two pairs of neighbours, read
        // without clamping; at the border each is clamped. The same texels either way.
        let [l00, l10, l01, l11] = if x0 >= 0 && y0 >= 0 && x0 < size - 1 && y0 < size - 1 {
            let i = (y0 * size + x0) as usize;
            let rows = &self.depth[i..i + size as usize + 2];
            let lit = |d: f32| if d <= z_ref { 1.0 } else { 0.0 };
            [lit(rows[0]), lit(rows[1]), lit(rows[size as usize]), lit(rows[size as usize + 1])]
        } else {
            [self.lit(x0, y0, z_ref), self.lit(x0 + 1, y0, z_ref), self.lit(x0, y0 + 1, z_ref), self.lit(x0 + 1, y0 + 1, z_ref)]
        };
        let a = l00 * (1.0 - fx) + l10 * fx;
        let b = l01 * (1.0 - fx) + l11 * fx;
        a * (1.0 - fy) + b * fy
    }

    /// Visibility (0 shadowed … 1 lit) of surface point `p` with normal `n` (facing the light),
    /// `to_light` the unit direction towards the light: normal offset, slope-scaled bias, PCF.
    /// Points outside the map are lit.
    #[inline(always)]
    pub fn visibility(&self, p: Vec3, n: Vec3, to_light: Vec3, pcf_radius: u32) -> f32 {
        let v = &self.view;
        let m = &v.view_proj;
        // One projection: the receiver's clip position, then its normal offset added through
        // the matrix's linear part (the offset is a direction).
        let c = *m * p.extend(1.0);
        // The texel's world size at the receiver (perspective: clip w is the view distance).
        let texel = if v.orthographic { v.texel_world } else { v.texel_world * c.w.max(v.near) };
        let cos = n.dot(to_light).clamp(1e-3, 1.0);
        let tan = ((1.0 - cos * cos).max(0.0).sqrt() / cos).min(SHADOW_MAX_SLOPE);
        let o = n * (texel * SHADOW_NORMAL_OFFSET_TEXELS);
        let c = c + m.x_axis * o.x + m.y_axis * o.y + m.z_axis * o.z;
        if c.w <= 0.0 {
            return 1.0;
        }
        let inv_w = 1.0 / c.w;
        let (uv, z) = (Vec2::new(c.x * inv_w * 0.5 + 0.5, 0.5 - c.y * inv_w * 0.5), c.z * inv_w);
        if !(0.0..=1.0).contains(&uv.x) || !(0.0..=1.0).contains(&uv.y) || z > 1.0 {
            return 1.0;
        }
        let bias = texel * (SHADOW_BIAS_TEXELS + SHADOW_SLOPE_BIAS_TEXELS * tan);
        // depth_of(linear_depth(z) − bias), without the round trip: orthographic depth is affine
        // in distance, a perspective view's distance is clip w.
        let z_ref = if v.orthographic { z + bias / (v.far - v.near) } else { v.depth_of(c.w - bias) };
        self.filtered(uv, z_ref, pcf_radius)
    }

    /// [`Self::visibility`] of four receivers (lanes) at once, each lane bit for bit the
    /// one-receiver value: the projection, normal offset and bias four at a time (the same
    /// operations in the same order), then each lane's texels. Lanes not in `active` give 1.
    #[inline(always)]
    pub fn visibility4(&self, p: V3, n: V3, to_light: V3, active: [bool; 4], pcf_radius: u32) -> [f32; 4] {
        let v = &self.view;
        let m = &v.view_proj;
        // `Mat4 * Vec4`, a row at a time: ((x·px + y·py) + z·pz) + w·1.
        let row = |j: usize, p: V3| -> Vec4 {
            Vec4::splat(m.x_axis[j]) * p[0] + Vec4::splat(m.y_axis[j]) * p[1] + Vec4::splat(m.z_axis[j]) * p[2] + Vec4::splat(m.w_axis[j])
        };
        let c = [row(0, p), row(1, p), row(2, p), row(3, p)];
        let texel = if v.orthographic { Vec4::splat(v.texel_world) } else { Vec4::splat(v.texel_world) * c[3].max(Vec4::splat(v.near)) };
        let cos = dot3(n, to_light).max(Vec4::splat(1e-3)).min(Vec4::ONE);
        let tan = ((Vec4::ONE - cos * cos).max(Vec4::ZERO).sqrt() / cos).min(Vec4::splat(SHADOW_MAX_SLOPE));
        let scale = texel * SHADOW_NORMAL_OFFSET_TEXELS;
        let o = [n[0] * scale, n[1] * scale, n[2] * scale];
        let axes = [m.x_axis, m.y_axis, m.z_axis];
        let c: [Vec4; 4] = std::array::from_fn(|j| {
            let mut cj = c[j];
            for (a, ok) in axes.iter().zip(o) {
                cj += Vec4::splat(a[j]) * ok;
            }
            cj
        });
        let inv_w = Vec4::ONE / c[3];
        let (u, w, z) = (c[0] * inv_w * 0.5 + 0.5, Vec4::splat(0.5) - c[1] * inv_w * 0.5, c[2] * inv_w);
        let bias = texel * (Vec4::splat(SHADOW_BIAS_TEXELS) + Vec4::splat(SHADOW_SLOPE_BIAS_TEXELS) * tan);
        let z_ref = if v.orthographic {
            z + bias / (v.far - v.near)
        } else {
            // `depth_of(c.w − bias)`.
            let (near, far) = (v.near, v.far);
            Vec4::splat(near * far) / (Vec4::splat(far - near) * (c[3] - bias).max(Vec4::splat(1e-6))) - Vec4::splat(near / (far - near))
        };
        let (cw, u, w, z, z_ref) = (c[3].to_array(), u.to_array(), w.to_array(), z.to_array(), z_ref.to_array());
        std::array::from_fn(|l| {
            // The one-receiver tests, NaN included (it fails `contains`, and is not beyond).
            let outside = !(0.0..=1.0).contains(&u[l]) || !(0.0..=1.0).contains(&w[l]) || z[l] > 1.0;
            if !active[l] || cw[l] <= 0.0 || outside { 1.0 } else { self.filtered(Vec2::new(u[l], w[l]), z_ref[l], pcf_radius) }
        })
    }

    /// PCF: one bilinear comparison at `uv` (radius 0) or (2r + 1)² of them a texel apart.
    #[inline(always)]
    fn filtered(&self, uv: Vec2, z_ref: f32, pcf_radius: u32) -> f32 {
        let v = &self.view;
        let r = pcf_radius as i32;
        if r == 0 {
            return self.compare_bilinear(uv, z_ref);
        }
        let step = 1.0 / v.size as f32;
        let mut sum = 0.0;
        for j in -r..=r {
            for i in -r..=r {
                sum += self.compare_bilinear(uv + Vec2::new(i as f32, j as f32) * step, z_ref);
            }
        }
        sum / ((2 * r + 1) * (2 * r + 1)) as f32
    }
}

/// A light's rendered maps.
#[derive(Debug, Clone, PartialEq)]
pub struct LightShadowMaps {
    pub light: usize,
    pub kind: ShadowKind,
    pub maps: Vec<ShadowMap>,
}

impl LightShadowMaps {
    /// The map a point uses: the cascade of its camera view distance `view_distance`, the spot
    /// map, or the cube face of its direction from the light at `light_position`.
    #[inline]
    pub fn map_for(&self, p: Vec3, view_distance: f32, light_position: Vec3) -> Option<&ShadowMap> {
        match self.kind {
            ShadowKind::Directional => self.maps.iter().find(|m| view_distance <= m.view.split_far).or(self.maps.last()),
            ShadowKind::Spot => self.maps.first(),
            ShadowKind::Point => self.maps.get(cube_face(p - light_position)),
        }
    }
}

/// Where a probe sits and how it is sampled.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProbePlan {
    /// The object it serves (left out of its own faces).
    pub object: u32,
    /// The object's bounds centre: where the six faces are rendered from.
    pub centre: Vec3,
    /// Box-projected parallax correction against this box (the scene's bounds) where the object
    /// is room-sized; `None`: directions are looked up as if the scene were infinitely far.
    pub parallax_box: Option<Aabb>,
    pub near: f32,
    pub far: f32,
}

/// An object counts as room-sized (a floor, a wall, a pool) when it spans at least this share
/// of the scene's extent along two axes and is thin (at most [`ROOM_SIZED_THICKNESS`] of the
/// scene's extent) along the third: a flat surface of the room, which the room's box encloses
/// (a ball that is the whole scene is not).
pub const ROOM_SIZED_SHARE: f32 = 0.5;
pub const ROOM_SIZED_THICKNESS: f32 = 0.1;

/// One probe per object that reflects or refracts (and has geometry).
pub fn plan_probes(prepared: &PreparedScene, bounds: &Aabb) -> Vec<ProbePlan> {
    let scene = prepared.scene;
    let extent = bounds.max - bounds.min;
    scene
        .objects
        .iter()
        .enumerate()
        .filter(|(i, o)| !prepared.object_bounds[*i].is_empty() && (o.is_reflective(&scene.materials) || o.is_refractive(&scene.materials)))
        .map(|(i, _)| {
            let ob = prepared.object_bounds[i];
            let e = ob.max - ob.min;
            let spans = (0..3).filter(|&a| extent[a] > 0.0 && e[a] >= ROOM_SIZED_SHARE * extent[a]).count();
            let thin = (0..3).any(|a| e[a] <= ROOM_SIZED_THICKNESS * extent[a]);
            let centre = ob.center();
            let (near, far) = perspective_range(centre, bounds);
            ProbePlan { object: i as u32, centre, parallax_box: (spans >= 2 && thin).then_some(*bounds), near, far }
        })
        .collect()
}

/// Steps of a probe's depth-based parallax correction ([`Probe::lookup_direction`]): a march
/// along the ray at quadratically spaced distances up to the probe's far plane, then a
/// bisection between the last step in front of the seen surface and the first behind it. More
/// steps find thinner surfaces and land closer, at the cost of a distance lookup each.
pub const PROBE_MARCH_STEPS: u32 = 8;
pub const PROBE_REFINE_STEPS: u32 = 5;

/// A rendered probe: six faces of `size`², face after face in [`CUBE_FACES`] order, row-major,
/// linear RGB of the lit scene (the skybox where nothing was drawn), and per texel the distance
/// from the centre to the surface seen (`plan.far` where nothing was drawn).
#[derive(Debug, Clone, PartialEq)]
pub struct Probe {
    pub plan: ProbePlan,
    pub size: u32,
    pub texels: Vec<Vec3>,
    pub distance: Vec<f32>,
}

impl Probe {
    /// An unrendered probe (black faces) of `size`; the backend fills [`Probe::texels`] face by
    /// face from [`Probe::face_camera`].
    pub fn new(plan: ProbePlan, size: u32) -> Self {
        let n = 6 * size as usize * size as usize;
        Self { plan, size, texels: vec![Vec3::ZERO; n], distance: vec![plan.far; n] }
    }

    /// The face and UV a direction from the centre falls on: the face camera's projection
    /// (90°, looking along the face's axis with its up vector), in closed form.
    #[inline]
    fn face_uv(&self, d: Vec3) -> Option<(usize, Vec2)> {
        let face = cube_face(d);
        // `d · forward`, `d · right` and `d · up` of the face (`right = forward × up`): the axes of
        // `CUBE_FACES` are signed unit axes, so each product is a signed component of `d`, the
        // same value for finite `d` (only a zero's sign can differ, and it moves neither the
        // `z ≤ 0` test nor the UV).
        let (z, right, up) = match face {
            0 => (d.x, -d.z, -d.y),
            1 => (-d.x, d.z, -d.y),
            2 => (d.y, d.x, d.z),
            3 => (-d.y, d.x, -d.z),
            4 => (d.z, d.x, -d.y),
            _ => (-d.z, -d.x, -d.y),
        };
        if z <= 0.0 {
            return None;
        }
        Some((face, Vec2::new(0.5 + 0.5 * right / z, 0.5 - 0.5 * up / z)))
    }

    /// The distance the probe saw along `d` (nearest texel; `plan.far` for nothing).
    #[inline]
    pub fn distance_along(&self, d: Vec3) -> f32 {
        let Some((face, uv)) = self.face_uv(d) else { return self.plan.far };
        let n = self.size as i32;
        let (x, y) = (((uv.x * n as f32) as i32).clamp(0, n - 1), ((uv.y * n as f32) as i32).clamp(0, n - 1));
        self.distance[face * (n * n) as usize + (y * n + x) as usize]
    }

    pub fn face_camera(&self, face: usize) -> Camera {
        cube_face_camera(self.plan.centre, face, self.plan.near, self.plan.far)
    }

    /// The direction to look up for a ray from `p` along unit `dir`, from the probe's centre to
    /// where the ray meets the scene: with the parallax box, where the ray leaves the box; else
    /// where it first goes behind the surface the probe saw (|y| > D(y), y = p + t·dir − centre,
    /// D the distance the probe saw along y), marched in [`PROBE_MARCH_STEPS`] and refined in
    /// [`PROBE_REFINE_STEPS`]; `dir` itself when it never does (it leaves towards the sky).
    #[inline(always)]
    pub fn lookup_direction(&self, p: Vec3, dir: Vec3) -> Vec3 {
        match self.plan.parallax_box {
            Some(b) => {
                let inv = dir.recip();
                let t1 = (b.min - p) * inv;
                let t2 = (b.max - p) * inv;
                let t_exit = t1.max(t2).min_element();
                if t_exit.is_finite() && t_exit > 0.0 { p + dir * t_exit - self.plan.centre } else { dir }
            }
            None => {
                let c = self.plan.centre;
                let far = self.plan.far;
                // Behind the seen surface (where the probe saw one: not the sky).
                let behind = |t: f32| {
                    let y = p + dir * t - c;
                    let (len, seen) = (y.length(), self.distance_along(y));
                    len > 0.0 && seen < far * 0.999 && len > seen
                };
                let mut front = 0.0f32;
                for k in 1..=PROBE_MARCH_STEPS {
                    let s = k as f32 / PROBE_MARCH_STEPS as f32;
                    let t = far * s * s;
                    if behind(t) {
                        let mut back = t;
                        for _ in 0..PROBE_REFINE_STEPS {
                            let mid = 0.5 * (front + back);
                            if behind(mid) { back = mid } else { front = mid }
                        }
                        let y = p + dir * back - c;
                        return if y.length_squared() > 0.0 { y } else { dir };
                    }
                    front = t;
                }
                dir
            }
        }
    }

    /// The probe's colour for a ray from `p` along unit `dir` (bilinear within the face).
    #[inline(always)]
    pub fn sample(&self, p: Vec3, dir: Vec3) -> Vec3 {
        let d = self.lookup_direction(p, dir);
        if d == Vec3::ZERO {
            return Vec3::ZERO;
        }
        let Some((face, uv)) = self.face_uv(d) else { return Vec3::ZERO };
        let n = self.size as i32;
        let t = uv * n as f32 - Vec2::splat(0.5);
        let (x0, y0) = (floor(t.x), floor(t.y));
        let (fx, fy) = (t.x - x0, t.y - y0);
        let base = face * (n * n) as usize;
        let at = |x: i32, y: i32| self.texels[base + (y.clamp(0, n - 1) * n + x.clamp(0, n - 1)) as usize];
        let (x0, y0) = (x0 as i32, y0 as i32);
        let a = at(x0, y0).lerp(at(x0 + 1, y0), fx);
        let b = at(x0, y0 + 1).lerp(at(x0 + 1, y0 + 1), fx);
        a.lerp(b, fy)
    }
}

/// Which path an effect of an object took this frame (the report's per-object `effects`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EffectPath {
    /// Ray traced (the heuristic selected the object).
    Traced,
    /// Shadow maps (shadows) or the object's probe (reflection, refraction).
    Raster,
    /// None: the object has no such effect, or `--fallback none` left it out.
    None,
}

/// Per visible object: which path each of its effects took.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ObjectEffects {
    pub id: usize,
    pub name: String,
    pub shadow: EffectPath,
    pub reflection: EffectPath,
    pub refraction: EffectPath,
}

/// The report's `effects`: one entry per object with covered pixels, from the per-object count
/// of traced (`traced[i]`) and untraced (`untraced[i]`) pixels.
pub fn object_effects(scene: &Scene, traced: &[u64], untraced: &[u64], fallback: Fallback) -> Vec<ObjectEffects> {
    let any_shadow_light = lights(&scene.lights).any(|l| l.casts_shadows());
    scene
        .objects
        .iter()
        .enumerate()
        .filter(|(i, _)| traced.get(*i).copied().unwrap_or(0) + untraced.get(*i).copied().unwrap_or(0) > 0)
        .map(|(i, o)| {
            // Traced where any pixel was traced; otherwise the fallback's path, or none.
            let path = |has: bool| match (has, traced[i] > 0, fallback) {
                (false, _, _) => EffectPath::None,
                (true, true, _) => EffectPath::Traced,
                (true, false, Fallback::Raster) => EffectPath::Raster,
                (true, false, Fallback::None) => EffectPath::None,
            };
            ObjectEffects {
                id: i,
                name: o.name.clone(),
                shadow: path(any_shadow_light),
                reflection: path(o.is_reflective(&scene.materials)),
                refraction: path(o.is_refractive(&scene.materials)),
            }
        })
        .collect()
}

/// [`object_effects`] counted from a frame's object ids and mask.
pub fn object_effects_of(scene: &Scene, object_id: &[u32], mask: &[f32], fallback: Fallback) -> Vec<ObjectEffects> {
    let n = scene.objects.len();
    let (mut traced, mut untraced) = (vec![0u64; n], vec![0u64; n]);
    for (&id, &m) in object_id.iter().zip(mask) {
        if crate::is_polygon(id) && (id as usize) < n {
            if m >= crate::blend::MASK_EPSILON { traced[id as usize] += 1 } else { untraced[id as usize] += 1 }
        }
    }
    object_effects(scene, &traced, &untraced, fallback)
}

/// A refractive object counts as planar (a pane of glass, a pool's water) when its smallest
/// extent is at most this share of its largest.
pub const PLANAR_THICKNESS: f32 = 0.05;

/// Per object: whether its refraction looks through the see-through layer ([`SeeThrough`])
/// instead of its probe: a refractive object that is planar ([`PLANAR_THICKNESS`]) or a convex
/// polyhedron ([`Refractor::Hull`]). A probe sees such an object's background (a pool's floor,
/// what lies behind a window) from one point and at grazing angles, blurred; the see-through
/// layer sees it from the camera, sharp.
pub fn see_through_objects(prepared: &PreparedScene, refractors: &[Option<Refractor>]) -> Vec<bool> {
    let scene = prepared.scene;
    scene
        .objects
        .iter()
        .enumerate()
        .map(|(i, o)| {
            let b = prepared.object_bounds[i];
            !b.is_empty()
                && o.is_refractive(&scene.materials)
                && (is_planar(&b) || matches!(refractors.get(i), Some(Some(Refractor::Hull(_)))))
        })
        .collect()
}

/// Most distinct face planes a refractive object may have to count as a convex polyhedron
/// ([`ConvexHull`]): boxes, panes and prisms pass; finely tessellated shapes are refracted once
/// (spheres excepted: [`Refractor::Sphere`]). Larger values let more shapes refract exactly, at
/// the cost of a longer exit search per pixel.
pub const CONVEX_MAX_PLANES: usize = 32;

/// A closed convex polyhedron, as its face planes (`xyz` the outward unit normal, `w` the offset:
/// inside where `n · x ≤ w`). A refractive object of this shape (a pane modelled as a thin box,
/// a glass cube) is refracted exactly through both of its faces: in at the pixel, out where the
/// refracted ray meets the face plane it leaves by ([`ConvexHull::exit`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ConvexHull {
    pub planes: Vec<Vec4>,
}

impl ConvexHull {
    /// The triangles as a closed convex polyhedron, if they are one: at most
    /// [`CONVEX_MAX_PLANES`] distinct face planes, every corner on the inner side of every plane,
    /// and a plane facing each of ±x, ±y, ±z (closed; a single sheet is not). Normals are
    /// oriented away from the corners' centroid, whatever the winding.
    pub fn of_triangles(triangles: &[[Vec3; 3]]) -> Option<Self> {
        let corners = triangles.iter().flatten();
        let n = (triangles.len() * 3) as f32;
        if triangles.is_empty() {
            return None;
        }
        let centroid = corners.clone().fold(Vec3::ZERO, |a, &c| a + c) / n;
        let extent = corners.clone().fold(0.0f32, |m, c| m.max((*c - centroid).abs().max_element()));
        let tolerance = 1e-4 * extent.max(1e-6);
        let mut planes: Vec<Vec4> = Vec::new();
        for [a, b, c] in triangles {
            let Some(normal) = (*b - *a).cross(*c - *a).try_normalize() else { continue };
            let normal = if normal.dot(centroid - *a) > 0.0 { -normal } else { normal };
            let plane = normal.extend(normal.dot(*a));
            if !planes.iter().any(|q| q.xyz().dot(normal) > 1.0 - 1e-5 && (q.w - plane.w).abs() <= tolerance) {
                if planes.len() == CONVEX_MAX_PLANES {
                    return None;
                }
                planes.push(plane);
            }
        }
        let convex = planes.iter().all(|q| corners.clone().all(|c| q.xyz().dot(*c) <= q.w + tolerance));
        let closed = [Vec3::X, Vec3::NEG_X, Vec3::Y, Vec3::NEG_Y, Vec3::Z, Vec3::NEG_Z]
            .iter()
            .all(|d| planes.iter().any(|q| q.xyz().dot(*d) > 1e-3));
        (convex && closed).then_some(Self { planes })
    }

    /// Where a ray inside the polyhedron, from `p` along unit `t`, leaves it: the exit point and
    /// the outward normal of the face it leaves by (`None` for a degenerate `t`).
    pub fn exit(&self, p: Vec3, t: Vec3) -> Option<(Vec3, Vec3)> {
        let mut best: Option<(f32, Vec3)> = None;
        for q in &self.planes {
            let n = q.xyz();
            let along = n.dot(t);
            if along > 1e-6 {
                let d = ((q.w - n.dot(p)) / along).max(0.0);
                if best.is_none_or(|(b, _)| d < b) {
                    best = Some((d, n));
                }
            }
        }
        best.map(|(d, n)| (p + t * d, n))
    }
}

/// The shape a refraction ray leaves a refractive object by, where the fallbacks know it: the
/// ray bent in at the pixel is bent again where it leaves, as the trace stage's ray is, before
/// the see-through layer or the probe is looked up. Objects of other shapes are refracted once.
#[derive(Debug, Clone, PartialEq)]
pub enum Refractor {
    /// A closed convex polyhedron (a pane modelled as a thin box, a glass cube).
    Hull(ConvexHull),
    /// A (tessellated) sphere: every corner at the radius from the bounds' centre.
    Sphere { centre: Vec3, radius: f32 },
}

/// Total internal reflections a ray is followed through inside a [`Refractor`] before the
/// fallback takes its last direction as the way out.
pub const REFRACTOR_BOUNCES: u32 = 4;

/// A tessellated sphere's corners lie within this share of its radius.
pub const SPHERE_TOLERANCE: f32 = 0.01;

impl Refractor {
    /// The object's triangles as a sphere or a convex hull, if they are one.
    pub fn of_triangles(triangles: &[[Vec3; 3]]) -> Option<Self> {
        let mut bounds = Aabb::EMPTY;
        triangles.iter().flatten().for_each(|c| bounds.grow(*c));
        if bounds.is_empty() {
            return None;
        }
        let (centre, half) = ((bounds.min + bounds.max) * 0.5, (bounds.max - bounds.min) * 0.5);
        let radius = half.max_element();
        let round = triangles.len() >= 32
            && half.min_element() >= radius * (1.0 - SPHERE_TOLERANCE)
            && triangles.iter().flatten().all(|c| (c.distance(centre) - radius).abs() <= radius * SPHERE_TOLERANCE);
        if round {
            return Some(Self::Sphere { centre, radius });
        }
        if triangles.len() > 4 * CONVEX_MAX_PLANES {
            return None;
        }
        ConvexHull::of_triangles(triangles).map(Self::Hull)
    }

    /// The ray refracted into the object at `p` along unit `t`, followed out: refracted where it
    /// meets the surface from inside, or on total internal reflection reflected and followed on,
    /// up to [`REFRACTOR_BOUNCES`] times. Returns where it leaves and its direction then (`p`,
    /// `t` if it cannot be followed).
    pub fn leave(&self, p: Vec3, t: Vec3, env_ior: f32, ior: f32) -> (Vec3, Vec3) {
        let (mut p, mut t) = (p, t);
        for _ in 0..REFRACTOR_BOUNCES {
            let Some((q, n)) = self.exit(p, t) else { break };
            let (out, tir) = refract_or_reflect(t, n, env_ior, ior);
            (p, t) = (q, out);
            if !tir {
                break;
            }
        }
        (p, t)
    }

    /// Where a ray inside the object, from `p` along unit `t`, leaves it: the exit point and
    /// the outward normal there.
    pub fn exit(&self, p: Vec3, t: Vec3) -> Option<(Vec3, Vec3)> {
        match self {
            Self::Hull(h) => h.exit(p, t),
            Self::Sphere { centre, radius } => {
                // The far root of |p + t·s − c|² = r².
                let o = p - *centre;
                let b = o.dot(t);
                let disc = b * b - (o.length_squared() - radius * radius);
                if disc < 0.0 {
                    return None;
                }
                let q = p + t * (-b + disc.sqrt()).max(0.0);
                Some((q, (q - *centre) / *radius))
            }
        }
    }
}

/// Per object: its [`Refractor`] when it is refractive and a sphere or a closed convex
/// polyhedron.
pub fn refractors(prepared: &PreparedScene) -> Vec<Option<Refractor>> {
    let scene = prepared.scene;
    let mut triangles: Vec<Vec<[Vec3; 3]>> = vec![Vec::new(); scene.objects.len()];
    for mesh in &prepared.meshes {
        let o = mesh.object as usize;
        if scene.objects[o].is_refractive(&scene.materials) {
            triangles[o].extend(mesh.indices.iter().map(|t| t.map(|i| mesh.positions[i as usize])));
        }
    }
    triangles.iter().map(|t| Refractor::of_triangles(t)).collect()
}

/// Whether world bounds are planar: smallest extent at most [`PLANAR_THICKNESS`] of the largest.
pub fn is_planar(bounds: &Aabb) -> bool {
    let e = bounds.max - bounds.min;
    e.min_element() <= PLANAR_THICKNESS * e.max_element()
}

/// Steps of the see-through layer's ray intersection ([`SeeThrough::refraction`]).
pub const SEE_THROUGH_STEPS: u32 = 3;

/// The see-through layer's view is the frame's widened by this factor on each axis (at the same
/// pixel density), so that a refraction that bends towards the screen's edge (a pool's floor
/// seen at the bottom of the view) still lands inside it. Larger values cover stronger bends
/// at the cost of rendering factor² times the frame's pixels.
pub const SEE_THROUGH_GUARD: f32 = 1.5;

/// The see-through layer's camera and size for a frame of `width × height` seen by `camera`:
/// the same eye and orientation, the view widened by [`SEE_THROUGH_GUARD`].
pub fn see_through_view(camera: &Camera, width: u32, height: u32) -> (Camera, u32, u32) {
    let projection = match camera.projection {
        Projection::Perspective { fov_y_deg, near, far } => {
            let t = (fov_y_deg.to_radians() * 0.5).tan() * SEE_THROUGH_GUARD;
            Projection::Perspective { fov_y_deg: (2.0 * t.atan()).to_degrees().min(179.0), near, far }
        }
        Projection::Orthographic { height: h, near, far } => Projection::Orthographic { height: h * SEE_THROUGH_GUARD, near, far },
    };
    let size = |n: u32| ((n as f32 * SEE_THROUGH_GUARD).round() as u32).max(1);
    (Camera { projection, ..*camera }, size(width), size(height))
}

/// How far the view may turn from the see-through layer's, and move as seen from the nearest
/// see-through object that needs the layer, before the layer is rendered again (degrees). The
/// layer is a depth image of the scene, and its lookups intersect the refracted rays with its
/// surfaces, so a layer from a nearby viewpoint gives the same hits wherever the new viewpoint
/// sees the same surfaces. Larger values re-render the layer less often along a camera path at
/// the cost of refractions that miss what only the new viewpoint sees (and of guard band, which
/// turning uses up: 1.5× is about 9° on a 45° view).
pub const SEE_THROUGH_KEEP_DEGREES: f32 = 2.0;

/// Whether a see-through layer rendered with camera `layer` at `layer_size` can serve a frame
/// whose own layer would be `view` at `view_size` ([`see_through_view`]): the same size,
/// projection and up vector; the view direction turned at most [`SEE_THROUGH_KEEP_DEGREES`];
/// the eye moved at most that angle as seen from `nearest` away (the distance to the nearest
/// see-through object that needs the layer, [`nearest_see_through`]).
pub fn see_through_layer_kept(layer: &Camera, layer_size: (u32, u32), view: &Camera, view_size: (u32, u32), nearest: f32) -> bool {
    if layer_size != view_size || layer.projection != view.projection || layer.up != view.up {
        return false;
    }
    let angle = SEE_THROUGH_KEEP_DEGREES.to_radians();
    layer.forward().dot(view.forward()) >= angle.cos() && layer.position.distance(view.position) <= nearest * angle.tan()
}

/// Distance from `eye` to the nearest object's box among those that are see-through and
/// `needed` (0 from inside one; ∞ when there is none).
pub fn nearest_see_through(eye: Vec3, object_bounds: &[Aabb], see_through: &[bool], needed: &[bool]) -> f32 {
    object_bounds
        .iter()
        .zip(see_through.iter().zip(needed))
        .filter(|(b, (s, n))| **s && **n && !b.is_empty())
        .map(|(b, _)| (b.min - eye).max(eye - b.max).max(Vec3::ZERO).length())
        .fold(f32::INFINITY, f32::min)
}

/// The see-through layer: the frame's view, widened ([`see_through_view`]), rendered with the
/// raster path without the see-through objects ([`see_through_objects`]), lit. Such an
/// object's refraction ray from `p` along `t` is intersected with the layer's surfaces (each
/// step: with the tangent plane of the surface where the current guess lands on screen); the
/// texel it lands on is then shaded as the trace shades a secondary hit
/// ([`FallbackScene::through_layer`]): its lighting with its own reflection and refraction.
pub struct SeeThrough<'a> {
    pub view_proj: Mat4,
    /// The layer's G-buffer (its width and height are the layer's).
    pub layer: &'a GBuffer,
    /// The layer's lighting (listing 5, unshadowed).
    pub color: &'a [Vec3],
}

impl SeeThrough<'_> {
    /// The screen pixel a world point lands on, if on screen.
    #[inline]
    pub fn pixel_of(&self, x: Vec3) -> Option<usize> {
        let (w, h) = (self.layer.width, self.layer.height);
        let (uv, _) = project(&self.view_proj, x)?;
        ((0.0..1.0).contains(&uv.x) && (0.0..1.0).contains(&uv.y))
            .then(|| (uv.y * h as f32) as usize * w as usize + (uv.x * w as f32) as usize)
    }

    /// What the refraction along unit `t` from `p` meets in the layer. The distance starts as
    /// the surface's behind `p` and is refined [`SEE_THROUGH_STEPS`] times against the tangent
    /// plane of the surface where the point lands; a point that leaves the layer keeps the last
    /// pixel in it.
    pub fn hit_along(&self, p: Vec3, t: Vec3) -> LayerHit {
        let g = self.layer;
        let Some(i) = self.pixel_of(p) else { return LayerHit::Unknown };
        if g.object_id[i] == crate::NO_OBJECT {
            return LayerHit::Sky;
        }
        let mut d = g.position[i].distance(p);
        let mut j = i;
        for _ in 0..SEE_THROUGH_STEPS {
            let Some(k) = self.pixel_of(p + t * d) else { break };
            j = k;
            if g.object_id[k] == crate::NO_OBJECT {
                break;
            }
            let (q, n) = (g.position[k], g.normal[k]);
            let denom = t.dot(n);
            if denom.abs() < 1e-4 {
                break;
            }
            let next = (q - p).dot(n) / denom;
            if !(next > 0.0 && next.is_finite()) {
                // The ray turns away from the surface it was aimed at: what it meets is not in
                // the layer (above a floor, behind the camera).
                return LayerHit::Unknown;
            }
            d = next;
        }
        if let Some(k) = self.pixel_of(p + t * d) {
            j = k;
        }
        match g.object_id.get(j) {
            Some(&crate::NO_OBJECT) => LayerHit::Sky,
            Some(_) if j < self.color.len() => LayerHit::Texel(j),
            _ => LayerHit::Unknown,
        }
    }
}

/// What a ray looked up in the see-through layer meets ([`SeeThrough::hit_along`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LayerHit {
    /// The surface at this layer texel.
    Texel(usize),
    /// Nothing: the layer shows the sky behind the ray's start or where the ray lands.
    Sky,
    /// Not known from the layer (the start is off it, or the ray turns away from the surfaces
    /// it is aimed at): the object's probe answers.
    Unknown,
}

/// A light with shadow maps, as the per-pixel lookups read it ([`shadowed_lights`]).
#[derive(Debug, Clone, Copy)]
pub struct ShadowedLight<'a> {
    /// Index in [`lights`] order (and [`FrameLights`]').
    pub light: usize,
    /// Where a point or spot light sits (a point light's cube face is picked from it).
    pub position: Vec3,
    pub maps: &'a LightShadowMaps,
}

/// The lights that have maps (`maps` per light in [`lights`] order), with what the lookups need
/// of each, gathered once per frame.
pub fn shadowed_lights<'a>(scene: &Scene, maps: &[Option<&'a LightShadowMaps>]) -> Vec<ShadowedLight<'a>> {
    lights(&scene.lights)
        .enumerate()
        .filter_map(|(light, l)| {
            let maps = maps.get(light).copied().flatten()?;
            let position = match l {
                Light::Point(l) => l.position,
                Light::Spot(l) => l.position,
                Light::Directional(_) => Vec3::ZERO,
            };
            Some(ShadowedLight { light, position, maps })
        })
        .collect()
}

/// Everything the per-pixel fallback reads: the lights, their maps, the probes.
pub struct FallbackScene<'a> {
    pub scene: &'a Scene,
    pub frame_lights: &'a FrameLights,
    /// The lights that cast shadows and have maps ([`shadowed_lights`]).
    pub shadowed: Vec<ShadowedLight<'a>>,
    /// Per object: its probe, if it reflects or refracts.
    pub probes: Vec<Option<&'a Probe>>,
    pub camera: &'a Camera,
    /// `camera.forward()`, once per frame (the cascades are picked by distance along it).
    pub camera_forward: Vec3,
    pub pcf_radius: u32,
    /// Per object: whether its refraction uses `see_through` ([`see_through_objects`]).
    pub see_through_objects: &'a [bool],
    /// Per object: the shape a refraction ray leaves it by ([`refractors`]), bent a second time.
    pub refractors: &'a [Option<Refractor>],
    /// The see-through layer, when a see-through object needed it this frame.
    pub see_through: Option<SeeThrough<'a>>,
}

impl FallbackScene<'_> {
    /// The fallback terms of a pixel covered by object `object` with surface `s`:
    /// `(shadow, reflection, refraction)`, the same quantities the trace stage writes, from the
    /// shadow maps, the object's probe and (see-through objects) the see-through layer instead
    /// of rays.
    #[inline(always)]
    pub fn pixel(&self, object: u32, s: &Surface) -> (Vec3, Vec3, Vec3) {
        let incident = self.camera.incident_towards(s.position);
        let shadow = self.shadow(s, -incident);
        let (reflection, refraction) = self.reflection_refraction(object, s, incident, self.see_through.as_ref());
        (shadow, reflection, refraction)
    }

    /// [`Self::pixel`] of four pixels at once, bit for bit ([`Self::shadow4`]; reflections and
    /// refractions one by one).
    #[inline(always)]
    pub fn pixel4(&self, object: [u32; 4], s: &[Surface; 4]) -> [(Vec3, Vec3, Vec3); 4] {
        let incident: [Vec3; 4] = std::array::from_fn(|l| self.camera.incident_towards(s[l].position));
        let shadow = self.shadow4(s, incident.map(|i| -i));
        std::array::from_fn(|l| {
            let (reflection, refraction) = self.reflection_refraction(object[l], &s[l], incident[l], self.see_through.as_ref());
            (shadow[l], reflection, refraction)
        })
    }

    /// What a refraction ray along unit `t` sees through the see-through layer from `p`, shaded
    /// as the trace stage shades a secondary hit (unshadowed lighting, combined with the hit
    /// surface's reflection and refraction, here from its probe); the sky where nothing lies
    /// behind `p`; `None` off the layer (the probe answers then).
    pub fn through_layer(&self, st: &SeeThrough, p: Vec3, t: Vec3) -> Option<Vec3> {
        let j = match st.hit_along(p, t) {
            LayerHit::Texel(j) => j,
            // The sky along the ray (the layer's sky texels are along the camera's rays).
            LayerHit::Sky => return Some(sky(&self.scene.environment, &self.scene.textures, t)),
            LayerHit::Unknown => return None,
        };
        let (g, lit) = (st.layer, st.color[j]);
        let id = g.object_id[j];
        Some(match g.surface(j) {
            Some(s) if crate::is_polygon(id) && s.normal.length_squared() > 0.0 => {
                let (reflection, refraction) = self.reflection_refraction(id, &s, t, None);
                crate::blend::combine(lit, reflection, refraction, s.reflectivity, 1.0 - s.opacity)
            }
            _ => lit,
        })
    }

    /// The shadow term of surface `s` seen along `view` (towards the eye): 1 minus each
    /// light's Blinn–Phong share times its shadow maps' occlusion.
    #[inline(always)]
    pub fn shadow(&self, s: &Surface, view: Vec3) -> Vec3 {
        let mut shadow = Vec3::ONE;
        let unlit = s.diffuse == Vec3::ZERO && s.specular == Vec3::ZERO;
        if unlit {
            return shadow;
        }
        let view_distance = (s.position - self.camera.position).dot(self.camera_forward);
        let n = facing(s.normal, view);
        for light in &self.shadowed {
            let (dir, _dist, radiance) = self.frame_lights.incident_and_distance(light.light, s.position);
            if radiance == Vec3::ZERO || n.dot(dir) <= 0.0 {
                continue;
            }
            let Some(map) = light.maps.map_for(s.position, view_distance, light.position) else { continue };
            let vis = map.visibility(s.position, n, dir, self.pcf_radius);
            if vis < 1.0 {
                shadow -= self.frame_lights.blinn_phong_incident((dir, radiance), s, view) * (1.0 - vis);
            }
        }
        shadow
    }

    /// [`Self::shadow`] of four surfaces (lanes), each lane bit for bit the one-surface value:
    /// each light's direction and radiance four at a time, and where the four pick the same map
    /// (neighbouring pixels nearly always do) its projection and bias four at a time too.
    #[inline(always)]
    pub fn shadow4(&self, s: &[Surface; 4], view: [Vec3; 4]) -> [Vec3; 4] {
        let mut shadow = [Vec3::ONE; 4];
        let lit: [bool; 4] = std::array::from_fn(|l| !(s[l].diffuse == Vec3::ZERO && s[l].specular == Vec3::ZERO));
        if !lit.contains(&true) || self.shadowed.is_empty() {
            return shadow;
        }
        let view_distance: [f32; 4] = std::array::from_fn(|l| (s[l].position - self.camera.position).dot(self.camera_forward));
        let n: [Vec3; 4] = std::array::from_fn(|l| facing(s[l].normal, view[l]));
        let (p4, n4) = (soa([s[0].position, s[1].position, s[2].position, s[3].position]), soa(n));
        for light in &self.shadowed {
            let (dir4, radiance4) = self.frame_lights.incident4(light.light, p4);
            let n_dot_l = dot3(n4, dir4).to_array();
            let (dir, radiance) = (crate::lanes::aos(dir4), crate::lanes::aos(radiance4));
            let map: [Option<&ShadowMap>; 4] = std::array::from_fn(|l| {
                if !lit[l] || radiance[l] == Vec3::ZERO || n_dot_l[l] <= 0.0 {
                    return None;
                }
                light.maps.map_for(s[l].position, view_distance[l], light.position)
            });
            let Some(first) = map.iter().flatten().next() else { continue };
            let active = map.map(|m| m.is_some());
            let vis = if map.iter().flatten().all(|m| std::ptr::eq(*m, *first)) {
                first.visibility4(p4, n4, dir4, active, self.pcf_radius)
            } else {
                std::array::from_fn(|l| map[l].map_or(1.0, |m| m.visibility(s[l].position, n[l], dir[l], self.pcf_radius)))
            };
            for l in 0..4 {
                if map[l].is_some() && vis[l] < 1.0 {
                    shadow[l] -= self.frame_lights.blinn_phong_incident((dir[l], radiance[l]), &s[l], view[l]) * (1.0 - vis[l]);
                }
            }
        }
        shadow
    }

    /// The reflection and refraction terms of object `object`'s surface `s` hit along unit
    /// `incident`: its probe (the sky without one), or for a see-through object the see-through
    /// layer when given; a refraction is first followed out of the object's [`Refractor`].
    #[inline(always)]
    fn reflection_refraction(&self, object: u32, s: &Surface, incident: Vec3, see_through: Option<&SeeThrough>) -> (Vec3, Vec3) {
        let scene = self.scene;
        let probe = self.probes.get(object as usize).copied().flatten();
        let look = |from: Vec3, dir: Vec3| match probe {
            Some(p) => p.sample(from, dir),
            None => sky(&scene.environment, &scene.textures, dir),
        };
        let reflection = if s.reflectivity > 0.0 { look(s.position, reflect(incident, s.normal).normalize_or_zero()) } else { Vec3::ZERO };
        let refraction = if s.opacity < 1.0 {
            let (dir, _tir) = refract_or_reflect(incident, s.normal, scene.environment.ior, s.ior);
            // Bent in here; bent again where the ray leaves a sphere or a convex polyhedron (a
            // pane's parallel faces give the incident direction back); a sheet (a pool's water)
            // or another shape keeps it refracted once.
            let (from, along) = match self.refractors.get(object as usize).and_then(Option::as_ref) {
                Some(r) => r.leave(s.position, dir, scene.environment.ior, s.ior),
                None => (s.position, dir),
            };
            let through = match see_through {
                Some(st) if self.see_through_objects.get(object as usize).copied().unwrap_or(false) => self.through_layer(st, from, along),
                _ => None,
            };
            through.unwrap_or_else(|| look(from, along))
        } else {
            Vec3::ZERO
        };
        (reflection, refraction)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fallback_names_round_trip() {
        for n in Fallback::NAMES {
            assert_eq!(Fallback::parse(n).unwrap().as_str(), n);
        }
        assert_eq!(Fallback::parse("rays"), None);
        assert_eq!(Fallback::default(), Fallback::Raster);
    }

    #[test]
    fn linear_depth_inverts_depth_of() {
        for ortho in [true, false] {
            let v = ShadowView {
                view_proj: Mat4::IDENTITY,
                size: 64,
                orthographic: ortho,
                near: 0.1,
                far: 50.0,
                texel_world: 0.1,
                split_far: 1.0,
                cascade: None,
            };
            for d in [0.1f32, 0.5, 3.0, 20.0, 49.0] {
                let z = v.depth_of(d);
                assert!((0.0..=1.0001).contains(&z), "{z}");
                assert!((v.linear_depth(z) - d).abs() < 1e-3 * d.max(1.0), "{ortho} {d} {}", v.linear_depth(z));
            }
        }
    }

    #[test]
    fn practical_splits_by_hand() {
        // near 1, far 100, 2 cascades: t = 0.5: log 10, uniform 50.5 → 30.25; t = 1: 100.
        let s = cascade_splits(1.0, 100.0, 2);
        assert!((s[0] - 30.25).abs() < 1e-4 && (s[1] - 100.0).abs() < 1e-3, "{s:?}");
    }

    /// A camera walking and turning through a room-sized scene under a sun, frame after frame
    /// with last frame's views as `previous`: every cascade's map covers its whole slice of the
    /// view on every frame (kept or not), the last reaches the farthest scene point in front,
    /// and the maps are re-planned far less often than once per cascade per frame.
    #[test]
    fn cascades_are_kept_while_they_cover_their_slice() {
        let scene = hybrid_scene::demo_scene();
        let bounds = Aabb { min: Vec3::new(-12.0, -1.0, -12.0), max: Vec3::new(12.0, 8.0, 12.0) };
        let settings = FallbackSettings { cascades: 3, ..FallbackSettings::default() };
        let aspect = 16.0 / 9.0;
        let views_of = |camera: &Camera, previous: &[ShadowView]| {
            let lv = plan_light_views(&scene, &bounds, camera, aspect, &settings, &|light, k| {
                (light == 0).then(|| previous.get(k).copied()).flatten()
            });
            assert_eq!(lv[0].kind, ShadowKind::Directional, "the demo's first light is its sun");
            lv[0].views.clone()
        };
        let frames = 240;
        let mut previous: Vec<ShadowView> = Vec::new();
        let mut changed = 0;
        for f in 0..frames {
            // A sideways walk of 10 cm a frame (3 m/s at 30 frames per second) looking along −z,
            // which keeps the view's reach and so its splits the same: only the slices' moving
            // out of their maps re-plans them; then a turn on the spot, 0.5° a frame.
            let t = f.min(frames / 2) as f32;
            let position = Vec3::new(-6.0 + 0.1 * t, 1.7, 3.0);
            let yaw = (0.5 * (f - f.min(frames / 2)) as f32).to_radians();
            let camera = Camera { position, target: position + Vec3::new(yaw.sin(), -0.1, -yaw.cos()), ..scene.camera };
            let views = views_of(&camera, &previous);
            assert_eq!(views.len(), 3);
            if f == 0 {
                assert_eq!(views, views_of(&camera, &[]), "the first frame is planned afresh");
            }
            changed += views.iter().zip(&previous).filter(|(a, b)| a != b).count();
            // Each slice's eight corners lie inside its map.
            let forward = camera.forward();
            let right = camera.up.cross(-forward).normalize();
            let cam_up = (-forward).cross(right);
            let Projection::Perspective { fov_y_deg, near, .. } = camera.projection else { unreachable!() };
            let tan = (fov_y_deg.to_radians() * 0.5).tan();
            let mut start = near;
            for (k, v) in views.iter().enumerate() {
                for i in 0..8 {
                    let d = if i < 4 { start } else { v.split_far };
                    let sx = if i & 1 == 0 { -tan * d * aspect } else { tan * d * aspect };
                    let sy = if i & 2 == 0 { -tan * d } else { tan * d };
                    let p = camera.position + forward * d + right * sx + cam_up * sy;
                    let (uv, _) = project(&v.view_proj, p).unwrap();
                    assert!(uv.min_element() >= 0.0 && uv.max_element() <= 1.0, "frame {f}, cascade {k}: corner {i} at {uv}");
                }
                start = v.split_far;
            }
            let reach = corners(&bounds).iter().map(|c| (*c - camera.position).dot(forward)).fold(0.0f32, f32::max);
            assert!(views[2].split_far >= reach * 0.999, "frame {f}: the last split {} < reach {reach}", views[2].split_far);
            previous = views;
        }
        eprintln!("cascade maps re-planned: {changed} of {} cascade-frames", 3 * (frames - 1));
        assert!(changed * 10 < 3 * (frames - 1), "{changed} re-planned maps in {frames} frames");
    }

    /// The keep rule by hand: 2° of turn, and 2° of move as seen from the nearest see-through
    /// object's box.
    #[test]
    fn see_through_layer_is_kept_within_two_degrees() {
        let layer = Camera {
            position: Vec3::new(0.0, 1.0, 5.0),
            target: Vec3::new(0.0, 1.0, 0.0),
            up: Vec3::Y,
            projection: Projection::Perspective { fov_y_deg: 45.0, near: 0.1, far: 100.0 },
        };
        let size = (96, 54);
        let turned = |deg: f32| {
            let a = deg.to_radians();
            Camera { target: layer.position + Vec3::new(a.sin(), 0.0, -a.cos()), ..layer }
        };
        assert!(see_through_layer_kept(&layer, size, &layer, size, 0.0), "the same view, even from inside an object");
        assert!(see_through_layer_kept(&layer, size, &turned(1.9), size, 1.0));
        assert!(!see_through_layer_kept(&layer, size, &turned(2.1), size, 1.0));
        // From 4 away, 2° is a move of 4 tan 2° = 0.1397.
        let moved =
            |d: f32| Camera { position: layer.position + Vec3::new(d, 0.0, 0.0), target: layer.target + Vec3::new(d, 0.0, 0.0), ..layer };
        assert!(see_through_layer_kept(&layer, size, &moved(0.139), size, 4.0));
        assert!(!see_through_layer_kept(&layer, size, &moved(0.141), size, 4.0));
        assert!(!see_through_layer_kept(&layer, size, &layer, (96, 55), 4.0), "another size");
        let wider = Camera { projection: Projection::Perspective { fov_y_deg: 50.0, near: 0.1, far: 100.0 }, ..layer };
        assert!(!see_through_layer_kept(&layer, size, &wider, size, 4.0), "another projection");
        // Box [0, 1]³: from (2, 0.5, 3) the nearest point is (1, 0.5, 1), √5 away.
        let boxes = [Aabb { min: Vec3::ZERO, max: Vec3::ONE }, Aabb { min: Vec3::splat(10.0), max: Vec3::splat(11.0) }];
        let d = nearest_see_through(Vec3::new(2.0, 0.5, 3.0), &boxes, &[true, true], &[true, true]);
        assert!((d - 5f32.sqrt()).abs() < 1e-6, "{d}");
        assert_eq!(nearest_see_through(Vec3::splat(0.5), &boxes, &[true, true], &[true, true]), 0.0, "inside");
        let far = nearest_see_through(Vec3::new(2.0, 0.5, 3.0), &boxes, &[true, true], &[false, true]);
        assert!((far - Vec3::new(8.0, 9.5, 7.0).length()).abs() < 1e-5, "only the needed box: {far}");
        assert_eq!(nearest_see_through(Vec3::ZERO, &boxes, &[false, false], &[true, true]), f32::INFINITY);
    }

    #[test]
    fn cube_faces_see_their_own_axis() {
        for (f, (dir, _)) in CUBE_FACES.iter().enumerate() {
            let cam = cube_face_camera(Vec3::ZERO, f, 0.1, 10.0);
            let (uv, z) = project(&cam.view_projection(1.0), *dir).unwrap();
            assert!((uv - Vec2::splat(0.5)).length() < 1e-5 && z > 0.0 && z < 1.0, "face {f}: {uv} {z}");
            assert_eq!(cube_face(*dir), f);
            // A direction near a face's edge projects inside that face.
            let edge = *dir + (CUBE_FACES[(f + 2) % 6].0) * 0.99;
            let (uv, _) = project(&cam.view_projection(1.0), edge).unwrap();
            assert!(uv.min_element() >= 0.0 && uv.max_element() <= 1.0, "{uv}");
        }
    }

    #[test]
    fn face_uv_is_the_faces_dot_products() {
        let probe = Probe::new(ProbePlan { object: 0, centre: Vec3::ZERO, near: 0.1, far: 10.0, parallax_box: None }, 4);
        let mut rng = crate::test_rng::Rng(7);
        for k in 0..200_000 {
            let d = if k % 4 == 0 {
                // On the faces' edges and axes, zeros included.
                Vec3::new((rng.next_u64() % 5) as f32 - 2.0, (rng.next_u64() % 5) as f32 - 2.0, (rng.next_u64() % 5) as f32 - 2.0)
            } else {
                Vec3::new(rng.f() * 2.0 - 1.0, rng.f() * 2.0 - 1.0, rng.f() * 2.0 - 1.0) * 100.0
            };
            let face = cube_face(d);
            let (forward, up) = CUBE_FACES[face];
            let right = forward.cross(up);
            let z = d.dot(forward);
            let by_dots = (z > 0.0).then(|| (face, Vec2::new(0.5 + 0.5 * d.dot(right) / z, 0.5 - 0.5 * d.dot(up) / z)));
            assert_eq!(probe.face_uv(d), by_dots, "{d}");
        }
    }

    /// The demo scene's lights (a sun's cascades, a point light's cube, a spot map) over maps
    /// of random depth, and random surfaces in and around them: [`FallbackScene::shadow4`] is
    /// [`FallbackScene::shadow`] lane by lane, bit for bit, whether the four pick one map or
    /// several, with and without PCF, with unlit and back-facing lanes.
    #[test]
    fn four_lane_shadows_are_the_one_pixel_shadows() {
        use rand::{Rng, SeedableRng};
        let scene = hybrid_scene::demo_scene();
        let camera = scene.camera;
        let bounds = Aabb { min: camera.target - Vec3::splat(8.0), max: camera.target + Vec3::splat(8.0) };
        let settings = FallbackSettings { shadow_map_size: 64, cube_shadow_size: 32, ..FallbackSettings::default() };
        let mut rng = rand::rngs::StdRng::seed_from_u64(18);
        let maps: Vec<Option<LightShadowMaps>> = {
            let mut maps = vec![None; lights(&scene.lights).count()];
            for lv in plan_light_views(&scene, &bounds, &camera, 16.0 / 9.0, &settings, &|_, _| None) {
                let maps_of_light = lv
                    .views
                    .iter()
                    .map(|view| ShadowMap { view: *view, depth: (0..view.size * view.size).map(|_| rng.random_range(0.0..1.0)).collect() })
                    .collect();
                maps[lv.light] = Some(LightShadowMaps { light: lv.light, kind: lv.kind, maps: maps_of_light });
            }
            maps
        };
        assert!(maps.iter().flatten().count() >= 3, "the demo's sun, point and spot light cast shadows");
        let frame_lights = FrameLights::new(&scene.lights, &scene.environment);
        let map_refs: Vec<Option<&LightShadowMaps>> = maps.iter().map(Option::as_ref).collect();
        let mut fb = FallbackScene {
            scene: &scene,
            frame_lights: &frame_lights,
            shadowed: shadowed_lights(&scene, &map_refs),
            probes: Vec::new(),
            camera: &camera,
            camera_forward: camera.forward(),
            pcf_radius: 0,
            see_through_objects: &[],
            refractors: &[],
            see_through: None,
        };
        let random_surface = |rng: &mut rand::rngs::StdRng, near: Option<Vec3>| {
            let position = match near {
                // A neighbour: the same map nearly always.
                Some(p) => p + Vec3::new(rng.random_range(-0.05..0.05), rng.random_range(-0.05..0.05), rng.random_range(-0.05..0.05)),
                None => bounds.min + (bounds.max - bounds.min) * Vec3::new(rng.random(), rng.random(), rng.random()),
            };
            let normal =
                Vec3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)).normalize_or(Vec3::Y);
            let unlit = rng.random_range(0..10) == 0;
            Surface {
                position,
                normal,
                emission: Vec3::ZERO,
                ambient: Vec3::splat(0.2),
                diffuse: if unlit { Vec3::ZERO } else { Vec3::new(rng.random(), rng.random(), rng.random()) },
                opacity: 1.0,
                specular: if unlit || rng.random() { Vec3::ZERO } else { Vec3::splat(rng.random()) },
                shininess: rng.random(),
                reflectivity: 0.0,
                ior: 1.0,
            }
        };
        let (mut shadowed_lanes, mut mixed_quads) = (0, 0);
        for pcf in [0, 1] {
            fb.pcf_radius = pcf;
            for quad in 0..4000 {
                let first = random_surface(&mut rng, None);
                let neighbours = quad % 2 == 0;
                let s: [Surface; 4] = std::array::from_fn(|l| {
                    if l == 0 {
                        first
                    } else if neighbours {
                        random_surface(&mut rng, Some(first.position))
                    } else {
                        random_surface(&mut rng, None)
                    }
                });
                let view: [Vec3; 4] = std::array::from_fn(|l| -(s[l].position - camera.position).normalize());
                let four = fb.shadow4(&s, view);
                for l in 0..4 {
                    let one = fb.shadow(&s[l], view[l]);
                    assert_eq!(
                        four[l].to_array().map(f32::to_bits),
                        one.to_array().map(f32::to_bits),
                        "quad {quad} lane {l}: {} vs {one}",
                        four[l]
                    );
                    shadowed_lanes += usize::from(one != Vec3::ONE);
                }
                mixed_quads += usize::from(!neighbours);
            }
        }
        assert!(shadowed_lanes > 1000 && mixed_quads > 1000, "{shadowed_lanes} shadowed lanes, {mixed_quads} quads over several maps");
    }

    #[test]
    fn bilinear_comparison_by_hand() {
        // 2×2 map: left column depth 0.8 (an occluder near the light), right column 0.2.
        let view = ShadowView {
            view_proj: Mat4::IDENTITY,
            size: 2,
            orthographic: true,
            near: 0.0,
            far: 1.0,
            texel_world: 0.5,
            split_far: 1.0,
            cascade: None,
        };
        let map = ShadowMap { view, depth: vec![0.8, 0.2, 0.8, 0.2] };
        // A receiver at depth 0.5: lit by the right texels only. Half-way between the texel
        // centres (u = 0.5) the weights are ½ each.
        assert!((map.compare_bilinear(Vec2::new(0.5, 0.5), 0.5) - 0.5).abs() < 1e-6);
        // A quarter of the way (u = 0.375, 0.25 of a texel past the left centre): 0.25 lit.
        assert!((map.compare_bilinear(Vec2::new(0.375, 0.5), 0.5) - 0.25).abs() < 1e-6);
        // Beyond the right centre, clamped: fully lit.
        assert_eq!(map.compare_bilinear(Vec2::new(0.9, 0.5), 0.5), 1.0);
    }

    #[test]
    fn box_projection_looks_from_the_centre_to_the_exit_point() {
        let b = Aabb { min: Vec3::splat(-10.0), max: Vec3::splat(10.0) };
        let plan = ProbePlan { object: 0, centre: Vec3::ZERO, parallax_box: Some(b), near: 0.1, far: 40.0 };
        let probe = Probe::new(plan, 4);
        // From (5, 0, 0) straight up: leaves the box at (5, 10, 0).
        let d = probe.lookup_direction(Vec3::new(5.0, 0.0, 0.0), Vec3::Y);
        assert!((d - Vec3::new(5.0, 10.0, 0.0)).length() < 1e-5, "{d}");
        let far = Probe::new(ProbePlan { parallax_box: None, ..plan }, 4);
        assert_eq!(far.lookup_direction(Vec3::new(5.0, 0.0, 0.0), Vec3::Y), Vec3::Y);
    }

    #[test]
    fn depth_parallax_finds_the_wall_the_ray_meets() {
        // A probe at the origin inside a cube room of half-size 4 (distances: the exact distance
        // to the wall along each texel's direction). A ray from (2, 0, 0) along +Z meets the
        // wall z = 4 at (2, 0, 4): the lookup must point there, not along +Z.
        let plan = ProbePlan { object: 0, centre: Vec3::ZERO, parallax_box: None, near: 0.01, far: 100.0 };
        let mut probe = Probe::new(plan, 64);
        for f in 0..6 {
            let cam = probe.face_camera(f);
            let inv = cam.view_projection(1.0).inverse();
            for y in 0..64 {
                for x in 0..64 {
                    let ndc = Vec3::new((x as f32 + 0.5) / 32.0 - 1.0, 1.0 - (y as f32 + 0.5) / 32.0, 0.5);
                    let d = (inv.project_point3(ndc)).normalize();
                    probe.distance[f * 4096 + y * 64 + x] = 4.0 / d.abs().max_element();
                }
            }
        }
        let d = probe.lookup_direction(Vec3::new(2.0, 0.0, 0.0), Vec3::Z);
        let want = Vec3::new(2.0, 0.0, 4.0);
        assert!(d.normalize().angle_between(want.normalize()) < 0.03, "{d} vs {want}");
        // Nothing seen (sky): the direction itself.
        let sky = Probe::new(plan, 4);
        assert_eq!(sky.lookup_direction(Vec3::new(2.0, 0.0, 0.0), Vec3::Z), Vec3::Z);
    }

    #[test]
    fn closed_form_face_uv_is_the_face_cameras_projection() {
        let plan = ProbePlan { object: 0, centre: Vec3::new(1.0, -2.0, 0.5), parallax_box: None, near: 0.1, far: 40.0 };
        let probe = Probe::new(plan, 8);
        let mut rng = 0x1234_5678u32;
        let mut next = || {
            rng ^= rng << 13;
            rng ^= rng >> 17;
            rng ^= rng << 5;
            rng as f32 / u32::MAX as f32 * 2.0 - 1.0
        };
        for _ in 0..1000 {
            let d = Vec3::new(next(), next(), next());
            if d.length() < 1e-3 {
                continue;
            }
            let (face, uv) = probe.face_uv(d).unwrap();
            let (want, _) = project(&probe.face_camera(face).view_projection(1.0), plan.centre + d).unwrap();
            assert!((uv - want).abs().max_element() < 1e-4, "{d}: {uv} vs {want}");
        }
    }

    #[test]
    fn see_through_follows_the_refracted_ray_to_the_floor() {
        // An orthographic camera looking straight down at a floor y = 0 over x, z ∈ [−2, 2]:
        // 8 × 8 pixels of 0.5 units, each layer pixel's colour its column. A ray from (0.1, 1, 0)
        // along (1, −1, 0)/√2 meets the floor at (1.1, 0, 0): column 6 (x ∈ [1, 1.5)).
        let camera = Camera {
            position: Vec3::new(0.0, 5.0, 0.0),
            target: Vec3::ZERO,
            up: Vec3::NEG_Z,
            projection: Projection::Orthographic { height: 4.0, near: 0.1, far: 10.0 },
        };
        let n = 8usize;
        let (mut position, mut color) = (Vec::new(), Vec::new());
        for y in 0..n {
            for x in 0..n {
                position.push(Vec3::new(-2.0 + 0.5 * (x as f32 + 0.5), 0.0, -2.0 + 0.5 * (y as f32 + 0.5)));
                color.push(Vec3::splat(x as f32));
            }
        }
        let mut layer = GBuffer::new(8, 8);
        layer.position = position;
        layer.normal = vec![Vec3::Y; n * n];
        layer.object_id = vec![0u32; n * n];
        let st = SeeThrough { view_proj: camera.view_projection(1.0), layer: &layer, color: &color };
        let LayerHit::Texel(j) = st.hit_along(Vec3::new(0.1, 1.0, 0.0), Vec3::new(1.0, -1.0, 0.0).normalize()) else { panic!() };
        assert_eq!(color[j], Vec3::splat(6.0));
        // Up, away from the floor it starts above: not in the layer.
        assert_eq!(st.hit_along(Vec3::new(0.1, 1.0, 0.0), Vec3::new(1.0, 1.0, 0.0).normalize()), LayerHit::Unknown);
        // Nothing behind: the sky.
        let empty = GBuffer::new(8, 8);
        let st = SeeThrough { layer: &empty, ..st };
        assert_eq!(st.hit_along(Vec3::new(0.1, 1.0, 0.0), Vec3::NEG_Y), LayerHit::Sky);
        // The widened view keeps the eye and orientation and grows by the guard factor.
        let (wide, w, h) = see_through_view(&camera, 64, 32);
        assert_eq!((wide.position, w, h), (camera.position, 96, 48));
    }

    /// The 12 triangles of the box `min`–`max`, wound outward or, with `flip`, inward.
    fn box_triangles(min: Vec3, max: Vec3, flip: bool) -> Vec<[Vec3; 3]> {
        let c = |i: usize| Vec3::new([min.x, max.x][i & 1], [min.y, max.y][(i >> 1) & 1], [min.z, max.z][(i >> 2) & 1]);
        let quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
        quads
            .iter()
            .flat_map(|q| [[c(q[0]), c(q[1]), c(q[2])], [c(q[0]), c(q[2]), c(q[3])]])
            .map(|[a, b, d]| if flip { [a, d, b] } else { [a, b, d] })
            .collect()
    }

    #[test]
    fn a_box_is_a_convex_hull_and_a_sheet_is_not() {
        for flip in [false, true] {
            let hull = ConvexHull::of_triangles(&box_triangles(Vec3::splat(-0.5), Vec3::splat(0.5), flip)).unwrap();
            assert_eq!(hull.planes.len(), 6);
            // From the centre along +x: out at x = 0.5 through the +x face, whatever the winding.
            let (q, n) = hull.exit(Vec3::ZERO, Vec3::X).unwrap();
            assert!((q - Vec3::new(0.5, 0.0, 0.0)).length() < 1e-6 && (n - Vec3::X).length() < 1e-6, "{q} {n}");
            // Along (1, 1, 0)/√2 from (0, −0.25, 0): the +x face at x = 0.5 (y = 0.25) comes first.
            let (q, n) = hull.exit(Vec3::new(0.0, -0.25, 0.0), Vec3::new(1.0, 1.0, 0.0).normalize()).unwrap();
            assert!((q - Vec3::new(0.5, 0.25, 0.0)).length() < 1e-5 && n == Vec3::X, "{q} {n}");
        }
        // One quad (a pool's water) is not closed.
        let sheet = &box_triangles(Vec3::splat(-0.5), Vec3::splat(0.5), false)[..2];
        assert_eq!(ConvexHull::of_triangles(sheet), None);
        // Two boxes side by side in an L are not convex.
        let mut l = box_triangles(Vec3::ZERO, Vec3::new(2.0, 1.0, 1.0), false);
        l.extend(box_triangles(Vec3::ZERO, Vec3::new(1.0, 2.0, 1.0), false));
        assert_eq!(ConvexHull::of_triangles(&l), None);
    }

    #[test]
    fn a_tessellated_sphere_is_a_sphere_refractor() {
        // A UV sphere of radius 2 at (1, 0, 0): its corners all lie on the sphere.
        let (c, r) = (Vec3::new(1.0, 0.0, 0.0), 2.0);
        let at = |i: u32, j: u32| {
            let (theta, phi) = (std::f32::consts::PI * i as f32 / 8.0, std::f32::consts::TAU * j as f32 / 16.0);
            c + r * Vec3::new(theta.sin() * phi.cos(), theta.cos(), theta.sin() * phi.sin())
        };
        let tris: Vec<[Vec3; 3]> = (0..8)
            .flat_map(|i| {
                (0..16).flat_map(move |j| [[at(i, j), at(i + 1, j), at(i + 1, j + 1)], [at(i, j), at(i + 1, j + 1), at(i, j + 1)]])
            })
            .collect();
        let Some(Refractor::Sphere { centre, radius }) = Refractor::of_triangles(&tris) else { panic!("not a sphere") };
        assert!((centre - c).length() < 1e-5 && (radius - r).abs() < 1e-5, "{centre} {radius}");
        // From the top pole straight down: out at the bottom pole, normal −y.
        let sphere = Refractor::Sphere { centre, radius };
        let (q, n) = sphere.exit(c + Vec3::Y * r, Vec3::NEG_Y).unwrap();
        assert!((q - (c - Vec3::Y * r)).length() < 1e-5 && (n - Vec3::NEG_Y).length() < 1e-5, "{q} {n}");
        // A chord at 60° to the radius: length 2r·cos 60° = r, and the way out is the way in
        // mirrored (refracted in and out by the same angle).
        let p = c + Vec3::Y * r;
        let t = Vec3::new(60f32.to_radians().sin(), -60f32.to_radians().cos(), 0.0);
        let (q, _) = sphere.exit(p, t).unwrap();
        assert!((q.distance(p) - r).abs() < 1e-4, "{}", q.distance(p));
        let (inside, _) = refract_or_reflect(Vec3::new(0.5, -1.0, 0.0).normalize(), Vec3::Y, 1.0, 1.5);
        let (from, out) = sphere.leave(p, inside, 1.0, 1.5);
        assert!(((from - c).length() - r).abs() < 1e-4);
        // Symmetric about the chord's perpendicular bisector: the exit angle equals the entry's.
        let n_out = (from - c) / r;
        assert!((out.dot(n_out) - Vec3::new(0.5, -1.0, 0.0).normalize().dot(-Vec3::Y)).abs() < 1e-4);
    }

    #[test]
    fn a_pane_gives_the_incident_direction_back() {
        // A pane 0.03 thick across z, IOR 1.5: a ray at 40° bends in at the front face and
        // leaves the back face parallel to where it came from, shifted sideways by
        // d·sin(θ − θt)/cos θt (Snell: sin θt = sin 40° / 1.5).
        let hull = ConvexHull::of_triangles(&box_triangles(Vec3::new(-1.0, -1.0, 0.0), Vec3::new(1.0, 1.0, 0.03), false)).unwrap();
        let theta = 40f32.to_radians();
        let incident = Vec3::new(theta.sin(), 0.0, theta.cos());
        let front = Vec3::ZERO;
        let (t, tir) = refract_or_reflect(incident, Vec3::NEG_Z, 1.0, 1.5);
        assert!(!tir);
        let (q, n) = hull.exit(front, t).unwrap();
        assert_eq!(n, Vec3::Z);
        let (out, tir) = refract_or_reflect(t, n, 1.0, 1.5);
        assert!(!tir && (out - incident).length() < 1e-5, "{out} vs {incident}");
        let theta_t = (theta.sin() / 1.5).asin();
        let shift = 0.03 * (theta - theta_t).sin() / theta_t.cos();
        // The exit point's distance from the incident line through the entry point.
        let off_line = (q - incident * q.dot(incident)).length();
        assert!((off_line - shift).abs() < 1e-5, "{off_line} vs {shift}");
    }

    #[test]
    fn probe_faces_sample_what_was_written() {
        let plan = ProbePlan { object: 0, centre: Vec3::new(1.0, 2.0, 3.0), parallax_box: None, near: 0.1, far: 40.0 };
        let mut probe = Probe::new(plan, 8);
        for f in 0..6 {
            for t in &mut probe.texels[f * 64..(f + 1) * 64] {
                *t = Vec3::splat(f as f32);
            }
        }
        for (f, (dir, _)) in CUBE_FACES.iter().enumerate() {
            assert_eq!(probe.sample(Vec3::ZERO, *dir), Vec3::splat(f as f32));
        }
    }
}
