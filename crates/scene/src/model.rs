//! The in-memory scene: what a scene file (or the built-in demo) describes, with every model,
//! texture and point cloud already loaded. Backend-free: the CPU and GPU backends both prepare
//! their own acceleration structures from this.
//!
//! Conventions: right-handed, Y up, metres; colours are **linear** RGB (textures marked as
//! colour are decoded from sRGB on sampling); angles in the model are radians unless a field
//! name says `_deg`.

use std::path::PathBuf;

use glam::{EulerRot, Mat3, Mat4, Quat, Vec2, Vec3, Vec4};

use crate::camera::{Camera, CameraPath};
use crate::texture::{Texture, TextureId};

/// Index into [`Scene::materials`].
pub type MaterialId = usize;

/// A complete, loaded scene.
#[derive(Debug, Clone)]
pub struct Scene {
    /// The scene file this came from (`None` for scenes built in code).
    pub source: Option<PathBuf>,
    pub camera: Camera,
    pub environment: Environment,
    pub heuristic: HeuristicSettings,
    pub trace: TraceSettings,
    pub materials: Vec<Material>,
    pub textures: Vec<Texture>,
    pub objects: Vec<Object>,
    pub lights: Lights,
    pub point_clouds: Vec<PointCloud>,
    pub camera_path: Option<CameraPath>,
}

impl Scene {
    /// An empty scene seen from `camera`, with default environment, heuristic and trace
    /// settings: no materials, objects, lights or point clouds (for scenes built in code).
    pub fn new(camera: Camera) -> Self {
        Self {
            source: None,
            camera,
            environment: Environment::default(),
            heuristic: HeuristicSettings::default(),
            trace: TraceSettings::default(),
            materials: Vec::new(),
            textures: Vec::new(),
            objects: Vec::new(),
            lights: Lights::default(),
            point_clouds: Vec::new(),
            camera_path: None,
        }
    }

    /// Adds an object made of one mesh (already in world space: identity transform), with
    /// relevance K = 1 and cost E = 1. Returns its object id.
    pub fn push_mesh_object(&mut self, name: impl Into<String>, mesh: Mesh) -> usize {
        self.objects.push(Object {
            name: name.into(),
            source: ObjectSource::Plane,
            transform: Transform::default(),
            meshes: vec![mesh],
            relevance: 1.0,
            cost: 1.0,
        });
        self.objects.len() - 1
    }
}

/// Global environment (paper §3: global ambient colour, environment IOR, skybox).
#[derive(Debug, Clone)]
pub struct Environment {
    /// Multiplies each material's ambient colour (listing 5: `emission + env_ambient * ambient`).
    pub ambient: Vec3,
    /// Index of refraction of the medium the camera is in (air = 1.0).
    pub ior: f32,
    pub skybox: Skybox,
}

impl Default for Environment {
    fn default() -> Self {
        Self { ambient: Vec3::splat(0.1), ior: 1.0, skybox: Skybox::Color(Vec3::ZERO) }
    }
}

/// What rays that leave the scene see, and what the raster shows where nothing is drawn.
#[derive(Debug, Clone)]
pub enum Skybox {
    /// One linear colour in every direction.
    Color(Vec3),
    /// Vertical gradient: `zenith` straight up, `horizon` at the horizon, `ground` straight down
    /// (linear interpolation in the sine of the elevation).
    Gradient { zenith: Vec3, horizon: Vec3, ground: Vec3 },
    /// Six sRGB face images in the order +X, −X, +Y, −Y, +Z, −Z (OpenGL cube-map convention).
    Cube { faces: [TextureId; 6] },
}

/// Heuristic globals (paper Table 3: T and I) and the selection policy.
#[derive(Debug, Clone, PartialEq)]
pub struct HeuristicSettings {
    pub budget: Budget,
    /// I: importance of keeping last frame's choice (0 = none). Higher values make the selection
    /// more stable as the camera moves, at the cost of reacting later to what became relevant.
    pub importance: f32,
    pub policy: Policy,
}

impl Default for HeuristicSettings {
    fn default() -> Self {
        Self { budget: Budget::Unlimited, importance: 1.0, policy: Policy::Paper }
    }
}

/// T: what the ray-tracing stage may spend per frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Budget {
    /// No limit: every visible object is selected (the default when a scene sets no budget).
    Unlimited,
    /// In the paper's cost units (C = A·Q·E summed over selected objects).
    Cost(f64),
    /// In milliseconds of trace-stage time; converted to cost units with the measured time per
    /// unit of cost, updated every frame.
    Millis(f64),
}

/// How the heuristic's third phase picks objects.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Policy {
    /// Walewski et al. 2019 listing 6: cost-sorted graph with pointers to more relevant nodes.
    #[default]
    Paper,
    /// Greedy by relevance per cost (Funkhouser & Séquin 1993 style knapsack).
    Knapsack,
}

/// Ray-tracing stage settings (paper listing 8c).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TraceSettings {
    /// Maximum recursion depth of reflection/refraction rays (paper: 10). Higher values show
    /// deeper inter-reflections at the cost of more rays per pixel.
    pub max_depth: u32,
    /// A secondary ray is traced only while importance × luminance exceeds this. Lower values
    /// trace dimmer contributions at the cost of more rays.
    pub importance_cutoff: f32,
    /// Offset of secondary ray origins along the surface normal, in scene units.
    pub ray_bias: f32,
}

impl Default for TraceSettings {
    fn default() -> Self {
        Self { max_depth: 10, importance_cutoff: 0.01, ray_bias: 1e-3 }
    }
}

/// A material with every property of the paper's Table 1. Each property is a constant and,
/// optionally, a texture multiplied with it (the paper's `tex(..) * uniform`).
#[derive(Debug, Clone, PartialEq)]
pub struct Material {
    pub name: String,
    pub emission: Vec3,
    pub emission_map: Option<TextureId>,
    pub ambient: Vec3,
    pub ambient_map: Option<TextureId>,
    pub diffuse: Vec3,
    /// Diffuse map: RGB multiplies `diffuse`, A multiplies `opacity`.
    pub diffuse_map: Option<TextureId>,
    pub specular: Vec3,
    /// 0..1, mapped linearly onto the Blinn–Phong exponent 1..255 (Table 1, note a).
    pub shininess: f32,
    /// Specular map: RGB multiplies `specular`, A multiplies `shininess`.
    pub specular_map: Option<TextureId>,
    /// Tangent-space normal map (linear data, not sRGB).
    pub normal_map: Option<TextureId>,
    /// 0..1: how much of the surface is mirror reflection.
    pub reflectivity: f32,
    /// Index of refraction of the material (≥ 1 for real materials).
    pub ior: f32,
    /// 0..1: 1 = opaque, 0 = fully transparent (refractive).
    pub opacity: f32,
    /// Optical map (linear data): R multiplies reflectivity, G multiplies IOR, B multiplies opacity.
    pub optical_map: Option<TextureId>,
    /// Texture-coordinate transform: `uv' = offset + uv * tiling` (listing 2).
    pub tiling: Vec2,
    pub offset: Vec2,
    /// Whether surfaces with this material block shadow rays.
    pub casts_shadows: bool,
}

impl Default for Material {
    fn default() -> Self {
        Self {
            name: "default".into(),
            emission: Vec3::ZERO,
            emission_map: None,
            ambient: Vec3::ONE,
            ambient_map: None,
            diffuse: Vec3::splat(0.8),
            diffuse_map: None,
            specular: Vec3::ZERO,
            shininess: 0.0,
            specular_map: None,
            normal_map: None,
            reflectivity: 0.0,
            ior: 1.5,
            opacity: 1.0,
            optical_map: None,
            tiling: Vec2::ONE,
            offset: Vec2::ZERO,
            casts_shadows: true,
        }
    }
}

impl Material {
    /// Reflective objects get reflection rays (heuristic Q adds `1 + lights`).
    pub fn is_reflective(&self) -> bool {
        self.reflectivity > 0.0
    }
    /// Refractive objects get refraction rays (heuristic Q adds `4 + lights`).
    pub fn is_refractive(&self) -> bool {
        self.opacity < 1.0
    }
}

/// Table 1, note a: shininess 0 → exponent 1, 1 → 255, linear in between.
pub fn specular_exponent(shininess: f32) -> f32 {
    1.0 + shininess.clamp(0.0, 1.0) * 254.0
}

/// Object placement: position, Euler rotation in degrees (applied X, then Y, then Z), scale.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transform {
    pub position: Vec3,
    pub rotation_deg: Vec3,
    pub scale: Vec3,
}

impl Default for Transform {
    fn default() -> Self {
        Self { position: Vec3::ZERO, rotation_deg: Vec3::ZERO, scale: Vec3::ONE }
    }
}

impl Transform {
    pub fn rotation(&self) -> Quat {
        let r = self.rotation_deg * (std::f32::consts::PI / 180.0);
        // Extrinsic X, then Y, then Z  ==  R = Rz · Ry · Rx.
        Quat::from_euler(EulerRot::ZYX, r.z, r.y, r.x)
    }
    /// Object-to-world matrix: translate · rotate · scale.
    pub fn matrix(&self) -> Mat4 {
        Mat4::from_scale_rotation_translation(self.scale, self.rotation(), self.position)
    }
}

/// One scene object: the unit the heuristic selects (it has one A, P, D, V, Q, C, R, S).
#[derive(Debug, Clone)]
pub struct Object {
    pub name: String,
    /// Where the geometry came from (for `inspect` and error messages).
    pub source: ObjectSource,
    pub transform: Transform,
    /// Geometry in object space; `transform` places it in the world.
    pub meshes: Vec<Mesh>,
    /// K: static relevance (paper Table 3). Higher values make the heuristic prefer this object.
    pub relevance: f32,
    /// E: estimated cost factor (paper Table 3). Higher values make the object look costlier.
    pub cost: f32,
}

#[derive(Debug, Clone, PartialEq)]
pub enum ObjectSource {
    Plane,
    Cube,
    Sphere { slices: u32, stacks: u32 },
    Model(PathBuf),
}

impl Object {
    pub fn triangle_count(&self) -> usize {
        self.meshes.iter().map(|m| m.indices.len()).sum()
    }
    pub fn vertex_count(&self) -> usize {
        self.meshes.iter().map(|m| m.positions.len()).sum()
    }
    pub fn is_reflective(&self, materials: &[Material]) -> bool {
        self.meshes.iter().any(|m| materials[m.material].is_reflective())
    }
    pub fn is_refractive(&self, materials: &[Material]) -> bool {
        self.meshes.iter().any(|m| materials[m.material].is_refractive())
    }
    /// World-space axis-aligned bounds of the object's geometry (`None` if it has no vertices).
    pub fn world_bounds(&self) -> Option<Aabb> {
        let m = self.transform.matrix();
        let mut b = Aabb::EMPTY;
        for mesh in &self.meshes {
            for p in &mesh.positions {
                b.grow(m.transform_point3(*p));
            }
        }
        (!b.is_empty()).then_some(b)
    }
}

/// An indexed triangle mesh with one material. Attribute arrays are either empty or as long
/// as `positions`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Mesh {
    pub positions: Vec<Vec3>,
    /// Per-vertex normals; empty = flat shading from the triangle's geometric normal.
    pub normals: Vec<Vec3>,
    /// Per-vertex texture coordinates; empty = (0, 0) everywhere.
    pub uvs: Vec<Vec2>,
    /// Per-vertex tangents (xyz) with bitangent sign (w); empty = derived from UVs when needed.
    pub tangents: Vec<Vec4>,
    /// Per-vertex linear colours multiplying the diffuse colour; empty = white.
    pub colors: Vec<Vec3>,
    pub indices: Vec<[u32; 3]>,
    pub material: MaterialId,
}

impl Mesh {
    /// Fills `tangents` from positions, normals and UVs (per-triangle tangents accumulated per
    /// vertex, Gram–Schmidt orthogonalised). No-op without normals or UVs.
    pub fn compute_tangents(&mut self) {
        if self.normals.len() != self.positions.len() || self.uvs.len() != self.positions.len() {
            return;
        }
        let n = self.positions.len();
        let mut tan = vec![Vec3::ZERO; n];
        let mut bit = vec![Vec3::ZERO; n];
        for tri in &self.indices {
            let [a, b, c] = tri.map(|i| i as usize);
            let (p0, p1, p2) = (self.positions[a], self.positions[b], self.positions[c]);
            let (w0, w1, w2) = (self.uvs[a], self.uvs[b], self.uvs[c]);
            let (e1, e2) = (p1 - p0, p2 - p0);
            let (d1, d2) = (w1 - w0, w2 - w0);
            let det = d1.x * d2.y - d2.x * d1.y;
            if det.abs() < 1e-12 || !det.is_finite() {
                continue;
            }
            let r = 1.0 / det;
            let t = (e1 * d2.y - e2 * d1.y) * r;
            let bt = (e2 * d1.x - e1 * d2.x) * r;
            for i in [a, b, c] {
                tan[i] += t;
                bit[i] += bt;
            }
        }
        self.tangents = (0..n)
            .map(|i| {
                let nrm = self.normals[i];
                let t = (tan[i] - nrm * nrm.dot(tan[i])).normalize_or_zero();
                let t = if t == Vec3::ZERO { nrm.any_orthonormal_vector() } else { t };
                let w = if nrm.cross(t).dot(bit[i]) < 0.0 { -1.0 } else { 1.0 };
                t.extend(w)
            })
            .collect();
    }
}

/// Axis-aligned bounding box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    pub min: Vec3,
    pub max: Vec3,
}

impl Aabb {
    pub const EMPTY: Aabb = Aabb { min: Vec3::splat(f32::INFINITY), max: Vec3::splat(f32::NEG_INFINITY) };
    pub fn grow(&mut self, p: Vec3) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }
    pub fn union(&self, o: &Aabb) -> Aabb {
        Aabb { min: self.min.min(o.min), max: self.max.max(o.max) }
    }
    pub fn is_empty(&self) -> bool {
        self.min.x > self.max.x
    }
    pub fn center(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }
}

/// All lights. Limits (paper §3): 8 directional, 32 point, 32 spot.
#[derive(Debug, Clone, Default)]
pub struct Lights {
    pub directional: Vec<DirectionalLight>,
    pub point: Vec<PointLight>,
    pub spot: Vec<SpotLight>,
}

pub const MAX_DIRECTIONAL_LIGHTS: usize = 8;
pub const MAX_POINT_LIGHTS: usize = 32;
pub const MAX_SPOT_LIGHTS: usize = 32;

impl Lights {
    /// Number of lights of all kinds (the heuristic's `lights_count`).
    pub fn count(&self) -> usize {
        self.directional.len() + self.point.len() + self.spot.len()
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DirectionalLight {
    /// Direction the light travels (from the light towards the scene), normalised.
    pub direction: Vec3,
    pub color: Vec3,
    pub intensity: f32,
    pub casts_shadows: bool,
}

/// Distance attenuation `1 / (constant + linear·d + quadratic·d²)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Attenuation {
    pub constant: f32,
    pub linear: f32,
    pub quadratic: f32,
}

impl Default for Attenuation {
    fn default() -> Self {
        Self { constant: 1.0, linear: 0.0, quadratic: 1.0 }
    }
}

impl Attenuation {
    pub fn factor(&self, distance: f32) -> f32 {
        1.0 / (self.constant + self.linear * distance + self.quadratic * distance * distance).max(1e-12)
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointLight {
    pub position: Vec3,
    pub color: Vec3,
    pub intensity: f32,
    pub attenuation: Attenuation,
    pub casts_shadows: bool,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpotLight {
    pub position: Vec3,
    /// Direction the cone points, normalised.
    pub direction: Vec3,
    pub color: Vec3,
    pub intensity: f32,
    pub attenuation: Attenuation,
    /// Full intensity inside this half-angle (radians).
    pub inner_angle: f32,
    /// No light outside this half-angle (radians); smooth falloff between inner and outer.
    pub outer_angle: f32,
    pub casts_shadows: bool,
}

/// A point cloud rendered as spheres by the RT-scene capsule (paper 2).
#[derive(Debug, Clone)]
pub struct PointCloud {
    pub name: String,
    pub source: PathBuf,
    /// World-space sphere centres (the cloud's placement already applied).
    pub points: Vec<Vec3>,
    /// Per-point sRGB 8-bit colours from the file; empty when the file has none.
    pub colors: Vec<[u8; 3]>,
    /// Sphere radius in scene units.
    pub radius: f32,
    /// How points are coloured.
    pub coloring: PointColoring,
    /// Phong-style material response of the spheres.
    pub specular: Vec3,
    pub shininess: f32,
}

#[derive(Debug, Clone, PartialEq)]
pub enum PointColoring {
    /// Colours from the file when it has them, else the height colour map.
    FileOrHeight,
    /// One linear colour for every point (overrides the file's colours).
    Uniform(Vec3),
    /// A colour map over height (world Y) from the cloud's lowest to its highest point.
    Height,
}

impl PointCloud {
    pub fn bounds(&self) -> Aabb {
        let mut b = Aabb::EMPTY;
        for p in &self.points {
            b.grow(*p);
        }
        if !b.is_empty() {
            b.min -= Vec3::splat(self.radius);
            b.max += Vec3::splat(self.radius);
        }
        b
    }
}

/// Normal matrix of an object-to-world matrix (inverse transpose of its 3×3 part).
pub fn normal_matrix(m: &Mat4) -> Mat3 {
    Mat3::from_mat4(*m).inverse().transpose()
}
