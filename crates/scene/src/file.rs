//! TOML scene files (design §6; the reference is `docs/scene-format.md`).
//!
//! Two steps: serde reads the text into the `*Toml` structs below (every table rejects unknown
//! keys, and the values that are validated later keep their byte span), then [`Builder`] checks
//! every value, resolves and loads the files the scene refers to, and assembles the [`Scene`].
//! Every error is a [`SceneError`] naming the scene file and the `line:column` of the offending
//! value, and saying what is wrong.

// `SceneError` carries the source text and span for miette reports; it is large, and only built on
// the (cold) error path, so results keep it unboxed like the public `parse_scene` signature.
#![allow(clippy::result_large_err)]

use std::collections::HashMap;
use std::fmt;
use std::ops::Range;
use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};
use serde::Deserialize;
use serde::de::{self, Deserializer, SeqAccess, Visitor};
use toml::Spanned;

use crate::camera::{Camera, CameraPath, Keyframe, Projection};
use crate::load::{load_model, load_point_cloud, load_texture};
use crate::memory::{Bytes, MemoryLimit, mesh_bytes, sphere_bytes};
use crate::model::{
    Attenuation, Budget, DirectionalLight, Environment, HeuristicSettings, Lights, MAX_DIRECTIONAL_LIGHTS, MAX_POINT_LIGHTS,
    MAX_SPOT_LIGHTS, Material, MaterialId, Mesh, Object, ObjectSource, PointCloud, PointColoring, PointLight, Policy, Skybox, SpotLight,
    TraceSettings, Transform,
};
use crate::normals::{DEFAULT_CREASE_ANGLE_DEG, compute_smooth_normals};
use crate::primitives;
use crate::texture::{ColorSpace, Texture, TextureId};
use crate::{Scene, SceneError};

/// The built-in demo scene's TOML (also `scenes/demo.toml`). Refers to no external file.
pub const DEMO_SCENE_TOML: &str = include_str!("../../../scenes/demo.toml");

/// Largest accepted `trace.max_depth`.
pub const MAX_TRACE_DEPTH: u32 = 64;

/// The deepest level either backend traces, whatever `trace.max_depth` says (above it the value
/// is accepted and traced to this depth): the GPU's pending-ray stack holds 32 rays, and the CPU
/// stops at the same depth so both give the same image (issue 22).
pub const MAX_TRACED_DEPTH: u32 = 32;

/// Most secondary rays one ray tree may trace: the ray leaving the G-buffer surface and every
/// reflection and refraction below it (issue 22). Depth alone does not bound the work: glass in
/// a mirror box spawns two rays per hit, 2^depth of them. Children are admitted in the order
/// both backends visit the tree (refraction subtree first), so the cut is the same on both; a
/// child over the budget is untraced, as one below the importance cutoff (it contributes 0).
pub const TRACE_RAY_BUDGET: u32 = 64;

/// Loads and validates a scene file; relative paths inside are relative to the file. Its data
/// must fit this machine's default memory limit ([`MemoryLimit::machine_default`]).
pub fn load_scene(path: &Path) -> Result<Scene, SceneError> {
    load_scene_within(path, &MemoryLimit::machine_default())
}

/// [`load_scene`] with the scene's own data (meshes as instantiated, textures, points) checked
/// against `limit` as it is built: a primitive or model that would take it above the limit is an
/// error at its line, before its memory is allocated.
pub fn load_scene_within(path: &Path, limit: &MemoryLimit) -> Result<Scene, SceneError> {
    let bytes = crate::load::read_capped(path, "scene file", crate::load::MAX_SCENE_FILE_BYTES)?;
    let text = String::from_utf8(bytes).map_err(|e| SceneError::new(path, format!("cannot read scene file: not UTF-8 text ({e})")))?;
    parse_scene_within(&text, path, limit)
}

/// Parses scene TOML `text`; `path` names it in errors and is the base of relative paths.
pub fn parse_scene(text: &str, path: &Path) -> Result<Scene, SceneError> {
    parse_scene_within(text, path, &MemoryLimit::machine_default())
}

/// [`parse_scene`] with the scene's data checked against `limit` (see [`load_scene_within`]).
pub fn parse_scene_within(text: &str, path: &Path, limit: &MemoryLimit) -> Result<Scene, SceneError> {
    parse_scene_preloaded(text, path, limit, None)
}

/// A model or point-cloud file already loaded (the bare-model path loads it for its bounds),
/// handed to the scene parser so that the file is not read a second time.
pub(crate) enum Preloaded {
    /// [`load_model`]'s result, its materials and textures loaded into vectors of their own.
    Model { path: PathBuf, meshes: Vec<Mesh>, materials: Vec<Material>, textures: Vec<Texture> },
    /// [`load_point_cloud`]'s result.
    Points { path: PathBuf, points: Vec<Vec3>, colors: Vec<[u8; 3]> },
}

/// Whether `a` and `b` name the same existing file.
fn same_file(a: &Path, b: &Path) -> bool {
    matches!((a.canonicalize(), b.canonicalize()), (Ok(x), Ok(y)) if x == y)
}

/// [`parse_scene_within`], with the first model or point cloud that names `preloaded`'s file
/// taken from it instead of loading the file.
pub(crate) fn parse_scene_preloaded(
    text: &str,
    path: &Path,
    limit: &MemoryLimit,
    preloaded: Option<Preloaded>,
) -> Result<Scene, SceneError> {
    let file: SceneFile = toml::from_str(text).map_err(|e| match e.span() {
        Some(span) => SceneError::at(path, text, span, e.message().trim_end()),
        None => SceneError::new(path, e.message().trim_end()),
    })?;
    let base = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mut b = Builder {
        path,
        text,
        base,
        materials: Vec::new(),
        textures: Vec::new(),
        texture_cache: HashMap::new(),
        model_cache: HashMap::new(),
        preloaded,
        limit,
        held: 0,
    };
    b.build(file)
}

/// The built-in demo scene.
pub fn demo_scene() -> Scene {
    let mut scene = parse_scene(DEMO_SCENE_TOML, Path::new("<built-in demo.toml>")).expect("the built-in demo scene is valid (tested)");
    scene.source = None;
    scene
}

// ---------------------------------------------------------------------------------------------
// The file as serde reads it.

type S<T> = Spanned<T>;
type F = S<f32>;
type V2 = S<[f32; 2]>;
type V3 = S<[f32; 3]>;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneFile {
    camera: Option<CameraToml>,
    environment: Option<EnvironmentToml>,
    heuristic: Option<HeuristicToml>,
    trace: Option<TraceToml>,
    #[serde(default)]
    material: Vec<MaterialToml>,
    #[serde(default)]
    object: Vec<ObjectToml>,
    #[serde(default)]
    light: Vec<LightToml>,
    #[serde(default)]
    point_cloud: Vec<PointCloudToml>,
    camera_path: Option<S<CameraPathToml>>,
}

#[derive(Deserialize, Clone, Copy, PartialEq)]
#[serde(rename_all = "lowercase")]
enum ProjectionKind {
    Perspective,
    Orthographic,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraToml {
    position: Option<V3>,
    target: Option<V3>,
    up: Option<V3>,
    projection: Option<S<ProjectionKind>>,
    fov: Option<F>,
    height: Option<F>,
    near: Option<F>,
    far: Option<F>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct EnvironmentToml {
    ambient: Option<V3>,
    ior: Option<F>,
    skybox: Option<S<SkyboxToml>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SkyboxToml {
    color: Option<V3>,
    zenith: Option<V3>,
    horizon: Option<V3>,
    ground: Option<V3>,
    px: Option<S<String>>,
    nx: Option<S<String>>,
    py: Option<S<String>>,
    ny: Option<S<String>>,
    pz: Option<S<String>>,
    nz: Option<S<String>>,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(rename_all = "lowercase")]
enum PolicyToml {
    Paper,
    Knapsack,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct HeuristicToml {
    budget: Option<S<f64>>,
    budget_ms: Option<S<f64>>,
    importance: Option<F>,
    policy: Option<PolicyToml>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TraceToml {
    max_depth: Option<S<u32>>,
    importance_cutoff: Option<F>,
    ray_bias: Option<F>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MaterialToml {
    name: S<String>,
    emission: Option<V3>,
    emission_map: Option<S<String>>,
    ambient: Option<V3>,
    ambient_map: Option<S<String>>,
    diffuse: Option<V3>,
    diffuse_map: Option<S<String>>,
    opacity: Option<F>,
    specular: Option<V3>,
    specular_map: Option<S<String>>,
    shininess: Option<F>,
    reflectivity: Option<F>,
    ior: Option<F>,
    optical_map: Option<S<String>>,
    normal_map: Option<S<String>>,
    tiling: Option<V2>,
    offset: Option<V2>,
    casts_shadows: Option<bool>,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(rename_all = "lowercase")]
enum PrimitiveKind {
    Plane,
    Cube,
    Sphere,
}

/// `scale = 2` or `scale = [1, 2, 1]`.
enum ScaleToml {
    Uniform(f32),
    Axes([f32; 3]),
}

impl<'de> Deserialize<'de> for ScaleToml {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = ScaleToml;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a number or an array of 3 numbers")
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> Result<ScaleToml, E> {
                Ok(ScaleToml::Uniform(v as f32))
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<ScaleToml, E> {
                Ok(ScaleToml::Uniform(v as f32))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<ScaleToml, E> {
                Ok(ScaleToml::Uniform(v as f32))
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<ScaleToml, A::Error> {
                let mut out = [0f32; 3];
                for (i, o) in out.iter_mut().enumerate() {
                    *o = seq.next_element()?.ok_or_else(|| de::Error::invalid_length(i, &self))?;
                }
                if seq.next_element::<de::IgnoredAny>()?.is_some() {
                    return Err(de::Error::invalid_length(4, &self));
                }
                Ok(ScaleToml::Axes(out))
            }
        }
        d.deserialize_any(V)
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ObjectToml {
    name: Option<S<String>>,
    primitive: Option<S<PrimitiveKind>>,
    slices: Option<S<u32>>,
    stacks: Option<S<u32>>,
    model: Option<S<String>>,
    split: Option<S<bool>>,
    crease_angle: Option<F>,
    position: Option<V3>,
    rotation: Option<V3>,
    scale: Option<S<ScaleToml>>,
    material: Option<S<String>>,
    relevance: Option<F>,
    cost: Option<F>,
}

#[derive(Deserialize, Clone, Copy, PartialEq, Debug)]
#[serde(rename_all = "lowercase")]
enum LightKind {
    Directional,
    Point,
    Spot,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct AttenuationToml {
    constant: Option<F>,
    linear: Option<F>,
    quadratic: Option<F>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LightToml {
    #[serde(rename = "type")]
    kind: S<LightKind>,
    color: Option<V3>,
    intensity: Option<F>,
    direction: Option<V3>,
    position: Option<V3>,
    attenuation: Option<S<AttenuationToml>>,
    inner_angle: Option<F>,
    outer_angle: Option<F>,
    casts_shadows: Option<bool>,
}

#[derive(Deserialize, Clone, Copy, PartialEq)]
#[serde(rename_all = "lowercase")]
enum ColoringToml {
    File,
    Height,
    Uniform,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct PointCloudToml {
    name: Option<S<String>>,
    file: S<String>,
    radius: Option<F>,
    color: Option<V3>,
    coloring: Option<S<ColoringToml>>,
    position: Option<V3>,
    rotation: Option<V3>,
    scale: Option<S<ScaleToml>>,
    specular: Option<V3>,
    shininess: Option<F>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraPathToml {
    #[serde(default)]
    keyframe: Vec<KeyframeToml>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct KeyframeToml {
    time: F,
    position: V3,
    target: V3,
}

// ---------------------------------------------------------------------------------------------
// Defaults (documented in docs/scene-format.md; keep both in step).

const DEFAULT_FOV_DEG: f32 = 60.0;
const DEFAULT_ORTHO_HEIGHT: f32 = 10.0;
const DEFAULT_NEAR: f32 = 0.05;
const DEFAULT_FAR: f32 = 1000.0;
const DEFAULT_SLICES: u32 = 32;
const DEFAULT_STACKS: u32 = 16;
const DEFAULT_SPOT_INNER_DEG: f32 = 20.0;
const DEFAULT_SPOT_OUTER_DEG: f32 = 30.0;
const DEFAULT_POINT_RADIUS: f32 = 0.01;

// ---------------------------------------------------------------------------------------------
// Validation and assembly.

type Res<T> = std::result::Result<T, SceneError>;

struct Builder<'a> {
    path: &'a Path,
    text: &'a str,
    /// Directory of the scene file: relative paths start here.
    base: PathBuf,
    materials: Vec<Material>,
    textures: Vec<Texture>,
    /// (resolved path, is sRGB) → texture, so each image is decoded once per colour space.
    texture_cache: HashMap<(PathBuf, bool), TextureId>,
    /// resolved model path → meshes (materials already appended once).
    model_cache: HashMap<PathBuf, Vec<Mesh>>,
    /// A file the caller already loaded; taken by the first entry that names it.
    preloaded: Option<Preloaded>,
    /// The memory the scene's data may take.
    limit: &'a MemoryLimit,
    /// Bytes of data built so far (meshes as instantiated, model cache, textures, points).
    held: u64,
}

fn v3(a: [f32; 3]) -> Vec3 {
    Vec3::from_array(a)
}

impl Builder<'_> {
    /// Counts `bytes` more of scene data for `what` (at `span`), refusing them when the total
    /// would pass the memory limit.
    fn reserve(&mut self, span: Range<usize>, what: &str, bytes: u64) -> Res<()> {
        let total = self.held.saturating_add(bytes);
        if total > self.limit.bytes {
            return Err(self.err(
                span,
                format!(
                    "{what} needs {} more, which would bring the scene's data to {}, above the memory limit of {}; \
                     raise the limit with --max-memory or make the scene smaller",
                    Bytes(bytes),
                    Bytes(total),
                    self.limit.describe()
                ),
            ));
        }
        self.held = total;
        Ok(())
    }

    fn err(&self, span: Range<usize>, msg: impl Into<String>) -> SceneError {
        SceneError::at(self.path, self.text, span, msg)
    }

    fn line_of(&self, span: &Range<usize>) -> usize {
        self.text[..span.start.min(self.text.len())].matches('\n').count() + 1
    }

    fn finite(&self, x: f32, span: Range<usize>, key: &str) -> Res<f32> {
        if x.is_nan() {
            Err(self.err(span, format!("`{key}` is NaN; every number must be finite")))
        } else if x.is_infinite() {
            Err(self.err(span, format!("`{key}` is infinite (or too large for a 32-bit float); every number must be finite")))
        } else {
            Ok(x)
        }
    }

    fn num(&self, v: &F, key: &str) -> Res<f32> {
        self.finite(*v.get_ref(), v.span(), key)
    }

    fn num_or(&self, v: &Option<F>, key: &str, default: f32) -> Res<f32> {
        v.as_ref().map_or(Ok(default), |v| self.num(v, key))
    }

    /// A number with a range check: `ok(x)` must hold, else "`key` must be {what}, got x".
    fn num_in(&self, v: &Option<F>, key: &str, default: f32, what: &str, ok: impl Fn(f32) -> bool) -> Res<f32> {
        let Some(v) = v else { return Ok(default) };
        let x = self.num(v, key)?;
        if ok(x) { Ok(x) } else { Err(self.err(v.span(), format!("`{key}` must be {what}, got {x}"))) }
    }

    fn unit(&self, v: &Option<F>, key: &str, default: f32) -> Res<f32> {
        self.num_in(v, key, default, "between 0 and 1", |x| (0.0..=1.0).contains(&x))
    }

    fn vec3(&self, v: &V3, key: &str) -> Res<Vec3> {
        for x in v.get_ref() {
            self.finite(*x, v.span(), key)?;
        }
        Ok(v3(*v.get_ref()))
    }

    fn vec3_or(&self, v: &Option<V3>, key: &str, default: Vec3) -> Res<Vec3> {
        v.as_ref().map_or(Ok(default), |v| self.vec3(v, key))
    }

    fn vec2_or(&self, v: &Option<V2>, key: &str, default: Vec2) -> Res<Vec2> {
        let Some(v) = v else { return Ok(default) };
        for x in v.get_ref() {
            self.finite(*x, v.span(), key)?;
        }
        Ok(Vec2::from_array(*v.get_ref()))
    }

    /// A linear RGB colour: finite, every component ≥ 0.
    fn color_or(&self, v: &Option<V3>, key: &str, default: Vec3) -> Res<Vec3> {
        let Some(v) = v else { return Ok(default) };
        let c = self.vec3(v, key)?;
        if c.min_element() < 0.0 {
            return Err(self.err(v.span(), format!("`{key}` is a colour: every component must be ≥ 0, got {c}")));
        }
        Ok(c)
    }

    /// A direction: finite and not zero; normalised.
    fn direction(&self, v: &V3, key: &str) -> Res<Vec3> {
        let d = self.vec3(v, key)?;
        d.try_normalize().ok_or_else(|| self.err(v.span(), format!("`{key}` must be a non-zero vector, got {d}")))
    }

    fn scale_or(&self, v: &Option<S<ScaleToml>>) -> Res<Vec3> {
        let Some(v) = v else { return Ok(Vec3::ONE) };
        let s = match v.get_ref() {
            ScaleToml::Uniform(x) => Vec3::splat(self.finite(*x, v.span(), "scale")?),
            ScaleToml::Axes(a) => {
                for x in a {
                    self.finite(*x, v.span(), "scale")?;
                }
                v3(*a)
            }
        };
        if s.x == 0.0 || s.y == 0.0 || s.z == 0.0 {
            return Err(self.err(v.span(), format!("`scale` must not be zero on any axis, got {s}")));
        }
        Ok(s)
    }

    fn transform(&self, position: &Option<V3>, rotation: &Option<V3>, scale: &Option<S<ScaleToml>>) -> Res<Transform> {
        Ok(Transform {
            position: self.vec3_or(position, "position", Vec3::ZERO)?,
            rotation_deg: self.vec3_or(rotation, "rotation", Vec3::ZERO)?,
            scale: self.scale_or(scale)?,
        })
    }

    /// A key that does not apply in this context (e.g. `fov` on an orthographic camera).
    fn forbid(&self, span: Option<Range<usize>>, msg: impl FnOnce() -> String) -> Res<()> {
        match span {
            Some(s) => Err(self.err(s, msg())),
            None => Ok(()),
        }
    }

    /// Resolves a file path relative to the scene file and checks that the file exists.
    fn file(&self, v: &S<String>, what: &str) -> Res<PathBuf> {
        let written = v.get_ref();
        if written.trim().is_empty() {
            return Err(self.err(v.span(), format!("{what} file name is empty")));
        }
        let resolved = self.base.join(written);
        if !resolved.is_file() {
            let why = if resolved.exists() { "is not a file" } else { "not found" };
            return Err(self.err(v.span(), format!("{what} file `{written}` {why} (resolved to `{}`)", resolved.display())));
        }
        Ok(resolved)
    }

    /// The preloaded model at `resolved`, if there is one: its textures and materials are appended
    /// to the scene's (texture and material ids shifted to match), as [`load_model`] would have.
    fn take_preloaded_model(&mut self, resolved: &Path) -> Option<Vec<Mesh>> {
        if !matches!(&self.preloaded, Some(Preloaded::Model { path, .. }) if same_file(path, resolved)) {
            return None;
        }
        let Some(Preloaded::Model { meshes, materials, textures, .. }) = self.preloaded.take() else { return None };
        let (m0, t0) = (self.materials.len(), self.textures.len());
        self.textures.extend(textures);
        for mut m in materials {
            for id in
                [&mut m.emission_map, &mut m.ambient_map, &mut m.diffuse_map, &mut m.specular_map, &mut m.normal_map, &mut m.optical_map]
                    .into_iter()
                    .flatten()
            {
                *id += t0;
            }
            self.materials.push(m);
        }
        Some(meshes.into_iter().map(|mesh| Mesh { material: mesh.material + m0, ..mesh }).collect())
    }

    /// The preloaded point cloud at `resolved`, if there is one.
    fn take_preloaded_points(&mut self, resolved: &Path) -> Option<(Vec<Vec3>, Vec<[u8; 3]>)> {
        if !matches!(&self.preloaded, Some(Preloaded::Points { path, .. }) if same_file(path, resolved)) {
            return None;
        }
        let Some(Preloaded::Points { points, colors, .. }) = self.preloaded.take() else { return None };
        Some((points, colors))
    }

    fn texture(&mut self, v: &S<String>, cs: ColorSpace) -> Res<TextureId> {
        let resolved = self.file(v, "texture")?;
        let key = (resolved.clone(), cs == ColorSpace::Srgb);
        if let Some(&id) = self.texture_cache.get(&key) {
            return Ok(id);
        }
        let tex = load_texture(&resolved, cs).map_err(|e| self.err(v.span(), format!("cannot load texture `{}`: {e}", v.get_ref())))?;
        let texels: u64 = tex.levels.iter().map(|l| l.texels.len() as u64 * 4).sum();
        self.reserve(v.span(), &format!("texture `{}`", v.get_ref()), texels)?;
        let id = self.textures.len();
        self.textures.push(tex);
        self.texture_cache.insert(key, id);
        Ok(id)
    }

    fn texture_opt(&mut self, v: &Option<S<String>>, cs: ColorSpace) -> Res<Option<TextureId>> {
        v.as_ref().map(|v| self.texture(v, cs)).transpose()
    }

    fn build(&mut self, f: SceneFile) -> Res<Scene> {
        let camera = match &f.camera {
            Some(c) => self.camera(c)?,
            None => Camera::default(),
        };
        let environment = match &f.environment {
            Some(e) => self.environment(e)?,
            None => Environment::default(),
        };
        let heuristic = match &f.heuristic {
            Some(h) => self.heuristic(h)?,
            None => HeuristicSettings::default(),
        };
        let trace = match &f.trace {
            Some(t) => self.trace(t)?,
            None => TraceSettings::default(),
        };
        let mut names: HashMap<String, (MaterialId, usize)> = HashMap::new();
        for m in &f.material {
            let name = m.name.get_ref();
            if name.trim().is_empty() {
                return Err(self.err(m.name.span(), "material `name` must not be empty"));
            }
            if let Some(&(_, line)) = names.get(name) {
                return Err(self.err(m.name.span(), format!("material `{name}` is defined twice (first on line {line})")));
            }
            let mat = self.material(m)?;
            names.insert(name.clone(), (self.materials.len(), self.line_of(&m.name.span())));
            self.materials.push(mat);
        }
        let mut objects = Vec::new();
        for (i, o) in f.object.iter().enumerate() {
            self.object(o, i, &names, &mut objects)?;
        }
        let mut seen: HashMap<&str, usize> = HashMap::new();
        for (i, o) in objects.iter().enumerate() {
            if let Some(first) = seen.insert(&o.name, i) {
                let span = f.object.iter().filter_map(|t| t.name.as_ref()).find(|n| n.get_ref() == &o.name).map(|n| n.span());
                let msg = format!("object name `{}` is used by more than one object (objects {} and {})", o.name, first + 1, i + 1);
                return Err(match span {
                    Some(s) => self.err(s, msg),
                    None => SceneError::new(self.path, msg),
                });
            }
        }
        let lights = self.lights(&f.light)?;
        let mut point_clouds = Vec::new();
        for (i, p) in f.point_cloud.iter().enumerate() {
            point_clouds.push(self.point_cloud(p, i)?);
        }
        let camera_path = f.camera_path.as_ref().map(|p| self.camera_path(p)).transpose()?;
        Ok(Scene {
            source: Some(self.path.to_path_buf()),
            camera,
            environment,
            heuristic,
            trace,
            materials: std::mem::take(&mut self.materials),
            textures: std::mem::take(&mut self.textures),
            objects,
            lights,
            point_clouds,
            camera_path,
        })
    }

    fn camera(&self, c: &CameraToml) -> Res<Camera> {
        let d = Camera::default();
        let position = self.vec3_or(&c.position, "position", d.position)?;
        let target = self.vec3_or(&c.target, "target", d.target)?;
        if position.distance(target) <= 1e-6 {
            let span = c.target.as_ref().or(c.position.as_ref()).map_or(0..0, |v| v.span());
            return Err(self.err(span, "camera `target` must differ from `position`"));
        }
        let up = match &c.up {
            Some(u) => self.direction(u, "up")?,
            None => Vec3::Y,
        };
        if up.cross((target - position).normalize()).length() < 1e-4 {
            let span = c.up.as_ref().or(c.target.as_ref()).map_or(0..0, |v| v.span());
            return Err(self.err(span, "camera `up` must not be parallel to the view direction (target − position)"));
        }
        let kind = c.projection.as_ref().map_or(ProjectionKind::Perspective, |p| *p.get_ref());
        let near = self.num_in(&c.near, "near", DEFAULT_NEAR, "> 0", |x| x > 0.0)?;
        let far = self.num_or(&c.far, "far", DEFAULT_FAR)?;
        if far <= near {
            let span = c.far.as_ref().or(c.near.as_ref()).map_or(0..0, |v| v.span());
            return Err(self.err(span, format!("camera `near` must be less than `far`, got near = {near}, far = {far}")));
        }
        let projection = match kind {
            ProjectionKind::Perspective => {
                self.forbid(c.height.as_ref().map(|h| h.span()), || {
                    "`height` applies to orthographic cameras only (perspective cameras use `fov`)".into()
                })?;
                let fov_y_deg =
                    self.num_in(&c.fov, "fov", DEFAULT_FOV_DEG, "between 0 and 180 degrees (exclusive)", |x| x > 0.0 && x < 180.0)?;
                Projection::Perspective { fov_y_deg, near, far }
            }
            ProjectionKind::Orthographic => {
                self.forbid(c.fov.as_ref().map(|h| h.span()), || {
                    "`fov` applies to perspective cameras only (orthographic cameras use `height`)".into()
                })?;
                let height = self.num_in(&c.height, "height", DEFAULT_ORTHO_HEIGHT, "> 0", |x| x > 0.0)?;
                Projection::Orthographic { height, near, far }
            }
        };
        Ok(Camera { position, target, up, projection })
    }

    fn environment(&mut self, e: &EnvironmentToml) -> Res<Environment> {
        let d = Environment::default();
        let ambient = self.color_or(&e.ambient, "ambient", d.ambient)?;
        let ior = self.num_in(&e.ior, "ior", d.ior, "> 0", |x| x > 0.0)?;
        let skybox = match &e.skybox {
            Some(s) => self.skybox(s)?,
            None => d.skybox,
        };
        Ok(Environment { ambient, ior, skybox })
    }

    fn skybox(&mut self, s: &S<SkyboxToml>) -> Res<Skybox> {
        let t = s.get_ref();
        let gradient = [("zenith", &t.zenith), ("horizon", &t.horizon), ("ground", &t.ground)];
        let faces = [("px", &t.px), ("nx", &t.nx), ("py", &t.py), ("ny", &t.ny), ("pz", &t.pz), ("nz", &t.nz)];
        let has_gradient = gradient.iter().any(|g| g.1.is_some());
        let has_faces = faces.iter().any(|g| g.1.is_some());
        let forms = usize::from(t.color.is_some()) + usize::from(has_gradient) + usize::from(has_faces);
        if forms != 1 {
            let msg = if forms == 0 {
                "`skybox` needs `color`, or `zenith` + `horizon` + `ground`, or the six faces `px nx py ny pz nz`"
            } else {
                "`skybox` mixes forms: give either `color`, or `zenith` + `horizon` + `ground`, or the six faces, not several"
            };
            return Err(self.err(s.span(), msg));
        }
        if let Some(c) = &t.color {
            return Ok(Skybox::Color(self.color_or(&Some(c.clone()), "color", Vec3::ZERO)?));
        }
        if has_gradient {
            let mut cols = [Vec3::ZERO; 3];
            for (c, (key, v)) in cols.iter_mut().zip(gradient) {
                match v {
                    Some(_) => *c = self.color_or(v, key, Vec3::ZERO)?,
                    None => {
                        return Err(
                            self.err(s.span(), format!("gradient `skybox` needs `zenith`, `horizon` and `ground`; `{key}` is missing"))
                        );
                    }
                }
            }
            return Ok(Skybox::Gradient { zenith: cols[0], horizon: cols[1], ground: cols[2] });
        }
        let mut ids = [0; 6];
        for (id, (key, v)) in ids.iter_mut().zip(faces) {
            match v {
                Some(v) => *id = self.texture(v, ColorSpace::Srgb)?,
                None => {
                    return Err(
                        self.err(s.span(), format!("cube-map `skybox` needs all six faces `px nx py ny pz nz`; `{key}` is missing"))
                    );
                }
            }
        }
        Ok(Skybox::Cube { faces: ids })
    }

    fn heuristic(&self, h: &HeuristicToml) -> Res<HeuristicSettings> {
        let d = HeuristicSettings::default();
        let positive = |v: &S<f64>, key: &str| -> Res<f64> {
            let x = *v.get_ref();
            if !x.is_finite() {
                return Err(self.err(v.span(), format!("`{key}` must be a finite number, got {x}")));
            }
            if x <= 0.0 {
                return Err(self.err(v.span(), format!("`{key}` must be > 0, got {x} (leave it out for no limit)")));
            }
            Ok(x)
        };
        let budget = match (&h.budget, &h.budget_ms) {
            (Some(_), Some(ms)) => {
                return Err(self.err(ms.span(), "give either `budget` (cost units) or `budget_ms` (milliseconds), not both"));
            }
            (Some(b), None) => Budget::Cost(positive(b, "budget")?),
            (None, Some(ms)) => Budget::Millis(positive(ms, "budget_ms")?),
            (None, None) => d.budget,
        };
        let importance = self.num_in(&h.importance, "importance", d.importance, "≥ 0", |x| x >= 0.0)?;
        let policy = match h.policy {
            Some(PolicyToml::Paper) => Policy::Paper,
            Some(PolicyToml::Knapsack) => Policy::Knapsack,
            None => d.policy,
        };
        Ok(HeuristicSettings { budget, importance, policy })
    }

    fn trace(&self, t: &TraceToml) -> Res<TraceSettings> {
        let d = TraceSettings::default();
        let max_depth = match &t.max_depth {
            Some(m) if *m.get_ref() > MAX_TRACE_DEPTH => {
                return Err(self.err(m.span(), format!("`max_depth` must be at most {MAX_TRACE_DEPTH}, got {}", m.get_ref())));
            }
            Some(m) => *m.get_ref(),
            None => d.max_depth,
        };
        Ok(TraceSettings {
            max_depth,
            importance_cutoff: self.num_in(&t.importance_cutoff, "importance_cutoff", d.importance_cutoff, "≥ 0", |x| x >= 0.0)?,
            ray_bias: self.num_in(&t.ray_bias, "ray_bias", d.ray_bias, "≥ 0", |x| x >= 0.0)?,
        })
    }

    fn material(&mut self, m: &MaterialToml) -> Res<Material> {
        let d = Material::default();
        let diffuse = self.color_or(&m.diffuse, "diffuse", d.diffuse)?;
        let diffuse_map = self.texture_opt(&m.diffuse_map, ColorSpace::Srgb)?;
        // Ambient follows the diffuse colour (and map) unless given: lit by the environment's
        // ambient, a surface then keeps its colour in the shade.
        let ambient = self.color_or(&m.ambient, "ambient", diffuse)?;
        let ambient_map = match &m.ambient_map {
            Some(t) => Some(self.texture(t, ColorSpace::Srgb)?),
            None if m.ambient.is_none() => diffuse_map,
            None => None,
        };
        Ok(Material {
            name: m.name.get_ref().clone(),
            emission: self.color_or(&m.emission, "emission", d.emission)?,
            emission_map: self.texture_opt(&m.emission_map, ColorSpace::Srgb)?,
            ambient,
            ambient_map,
            diffuse,
            diffuse_map,
            specular: self.color_or(&m.specular, "specular", d.specular)?,
            shininess: self.unit(&m.shininess, "shininess", d.shininess)?,
            specular_map: self.texture_opt(&m.specular_map, ColorSpace::Srgb)?,
            normal_map: self.texture_opt(&m.normal_map, ColorSpace::Linear)?,
            reflectivity: self.unit(&m.reflectivity, "reflectivity", d.reflectivity)?,
            ior: self.num_in(&m.ior, "ior", d.ior, "> 0", |x| x > 0.0)?,
            opacity: self.unit(&m.opacity, "opacity", d.opacity)?,
            optical_map: self.texture_opt(&m.optical_map, ColorSpace::Linear)?,
            tiling: self.vec2_or(&m.tiling, "tiling", d.tiling)?,
            offset: self.vec2_or(&m.offset, "offset", d.offset)?,
            casts_shadows: m.casts_shadows.unwrap_or(d.casts_shadows),
        })
    }

    fn material_ref(&self, v: &S<String>, object: &str, names: &HashMap<String, (MaterialId, usize)>) -> Res<MaterialId> {
        match names.get(v.get_ref()) {
            Some(&(id, _)) => Ok(id),
            None => {
                let mut known: Vec<&str> = names.keys().map(String::as_str).collect();
                known.sort_unstable();
                let known = if known.is_empty() { "none are defined".to_string() } else { format!("defined: {}", known.join(", ")) };
                Err(self.err(v.span(), format!("object `{object}` uses material `{}`, which is not defined ({known})", v.get_ref())))
            }
        }
    }

    fn object(&mut self, o: &ObjectToml, index: usize, names: &HashMap<String, (MaterialId, usize)>, out: &mut Vec<Object>) -> Res<()> {
        let transform = self.transform(&o.position, &o.rotation, &o.scale)?;
        let relevance = self.num_in(&o.relevance, "relevance", 1.0, "≥ 0", |x| x >= 0.0)?;
        let cost = self.num_in(&o.cost, "cost", 1.0, "≥ 0", |x| x >= 0.0)?;
        if let Some(n) = &o.name
            && n.get_ref().trim().is_empty()
        {
            return Err(self.err(n.span(), "object `name` must not be empty"));
        }
        match (&o.primitive, &o.model) {
            (Some(_), Some(m)) => Err(self.err(m.span(), "an object is either a `primitive` or a `model`, not both")),
            (None, None) => {
                let span = o.name.as_ref().map_or(0..0, |n| n.span());
                Err(self.err(span, format!("object {} needs `primitive = \"plane\"|\"cube\"|\"sphere\"` or `model = \"file\"`", index + 1)))
            }
            (Some(p), None) => {
                self.forbid(o.split.as_ref().map(|s| s.span()), || "`split` applies to `model` objects only".into())?;
                self.forbid(o.crease_angle.as_ref().map(|s| s.span()), || "`crease_angle` applies to `model` objects only".into())?;
                let kind = *p.get_ref();
                let kind_name = match kind {
                    PrimitiveKind::Plane => "plane",
                    PrimitiveKind::Cube => "cube",
                    PrimitiveKind::Sphere => "sphere",
                };
                let name = o.name.as_ref().map_or_else(|| format!("{kind_name}-{}", index + 1), |n| n.get_ref().clone());
                if !matches!(kind, PrimitiveKind::Sphere)
                    && let Some(v) = o.slices.as_ref().or(o.stacks.as_ref())
                {
                    return Err(self.err(v.span(), "`slices` and `stacks` apply to sphere primitives only"));
                }
                let Some(mat) = &o.material else {
                    return Err(self.err(p.span(), format!("object `{name}`: primitives need a `material`")));
                };
                let material = self.material_ref(mat, &name, names)?;
                let (mut mesh, source) = match kind {
                    PrimitiveKind::Plane => (primitives::plane(), ObjectSource::Plane),
                    PrimitiveKind::Cube => (primitives::cube(), ObjectSource::Cube),
                    PrimitiveKind::Sphere => {
                        let seg = |v: &Option<S<u32>>, key: &str, min: u32, default: u32| -> Res<u32> {
                            let Some(v) = v else { return Ok(default) };
                            let x = *v.get_ref();
                            if x < min || x > primitives::MAX_SPHERE_SEGMENTS {
                                let max = primitives::MAX_SPHERE_SEGMENTS;
                                return Err(self.err(v.span(), format!("`{key}` must be between {min} and {max}, got {x}")));
                            }
                            Ok(x)
                        };
                        let slices = seg(&o.slices, "slices", primitives::MIN_SPHERE_SLICES, DEFAULT_SLICES)?;
                        let stacks = seg(&o.stacks, "stacks", primitives::MIN_SPHERE_STACKS, DEFAULT_STACKS)?;
                        self.reserve(
                            p.span(),
                            &format!("sphere `{name}` ({slices} slices × {stacks} stacks)"),
                            sphere_bytes(slices, stacks),
                        )?;
                        (primitives::sphere(slices, stacks), ObjectSource::Sphere { slices, stacks })
                    }
                };
                mesh.material = material;
                out.push(Object { name, source, transform, meshes: vec![mesh], relevance, cost });
                Ok(())
            }
            (None, Some(m)) => {
                if let Some(v) = o.slices.as_ref().or(o.stacks.as_ref()) {
                    return Err(self.err(v.span(), "`slices` and `stacks` apply to sphere primitives only"));
                }
                let resolved = self.file(m, "model")?;
                let stem = Path::new(m.get_ref()).file_stem().map_or("model".into(), |s| s.to_string_lossy().into_owned());
                let name = o.name.as_ref().map_or_else(|| format!("{stem}-{}", index + 1), |n| n.get_ref().clone());
                let override_material = o.material.as_ref().map(|v| self.material_ref(v, &name, names)).transpose()?;
                // Smooth normals for meshes without them: OBJ and PLY at the default crease angle;
                // glTF only when the scene asks (its specification wants flat shading there).
                let is_gltf = matches!(crate::load::extension(&resolved).as_str(), "gltf" | "glb");
                let crease = match &o.crease_angle {
                    Some(_) => Some(
                        self.num_in(&o.crease_angle, "crease_angle", 0.0, "between 0 and 180 (degrees)", |x| (0.0..=180.0).contains(&x))?,
                    ),
                    None if is_gltf => None,
                    None => Some(DEFAULT_CREASE_ANGLE_DEG),
                };
                if !self.model_cache.contains_key(&resolved) {
                    let textures_before = self.textures.len();
                    let meshes = match self.take_preloaded_model(&resolved) {
                        Some(meshes) => meshes,
                        None => load_model(&resolved, &mut self.materials, &mut self.textures)
                            .map_err(|e| self.err(m.span(), format!("cannot load model `{}`: {e}", m.get_ref())))?,
                    };
                    // The cached copy and the model's own textures.
                    let texels: u64 =
                        self.textures[textures_before..].iter().flat_map(|t| &t.levels).map(|l| l.texels.len() as u64 * 4).sum();
                    let cached: u64 = meshes.iter().map(mesh_bytes).sum();
                    self.reserve(m.span(), &format!("model `{}`", m.get_ref()), cached + texels)?;
                    self.model_cache.insert(resolved.clone(), meshes);
                }
                let cached = &self.model_cache[&resolved];
                // Each object is a copy of the model's meshes.
                let copy: u64 = cached.iter().map(mesh_bytes).sum();
                self.reserve(m.span(), &format!("object `{name}` (a copy of model `{}`)", m.get_ref()), copy)?;
                let mut meshes = self.model_cache[&resolved].clone();
                if meshes.is_empty() {
                    return Err(self.err(m.span(), format!("model `{}` contains no triangle meshes", m.get_ref())));
                }
                if let Some(bad) = meshes.iter().find(|mesh| mesh.material >= self.materials.len()) {
                    return Err(self.err(
                        m.span(),
                        format!("model `{}`: a mesh refers to material {} which does not exist", m.get_ref(), bad.material),
                    ));
                }
                if let Some(id) = override_material {
                    for mesh in &mut meshes {
                        mesh.material = id;
                    }
                }
                if let Some(crease) = crease {
                    for mesh in meshes.iter_mut().filter(|m| m.normals.is_empty()) {
                        compute_smooth_normals(mesh, crease);
                        // Normal maps need tangents, which the loaders derive only from normals.
                        if self.materials[mesh.material].normal_map.is_some() && !mesh.uvs.is_empty() {
                            mesh.compute_tangents();
                        }
                    }
                }
                let source = ObjectSource::Model(resolved);
                if o.split.as_ref().is_some_and(|s| *s.get_ref()) {
                    for (i, mesh) in meshes.into_iter().enumerate() {
                        out.push(Object {
                            name: format!("{name}/{i}"),
                            source: source.clone(),
                            transform,
                            meshes: vec![mesh],
                            relevance,
                            cost,
                        });
                    }
                } else {
                    out.push(Object { name, source, transform, meshes, relevance, cost });
                }
                Ok(())
            }
        }
    }

    fn lights(&self, lights: &[LightToml]) -> Res<Lights> {
        let mut out = Lights::default();
        for l in lights {
            let kind = *l.kind.get_ref();
            let kind_name = format!("{kind:?}").to_lowercase();
            let color = self.color_or(&l.color, "color", Vec3::ONE)?;
            let intensity = self.num_in(&l.intensity, "intensity", 1.0, "≥ 0", |x| x >= 0.0)?;
            let casts_shadows = l.casts_shadows.unwrap_or(true);
            let not_for = |key: &str| format!("`{key}` does not apply to a {kind_name} light");
            let need = |v: &Option<V3>, key: &str| -> Res<V3> {
                v.clone().ok_or_else(|| self.err(l.kind.span(), format!("a {kind_name} light needs `{key}`")))
            };
            if kind != LightKind::Spot {
                for (v, key) in [(&l.inner_angle, "inner_angle"), (&l.outer_angle, "outer_angle")] {
                    self.forbid(v.as_ref().map(|v| v.span()), || not_for(key))?;
                }
            }
            let attenuation = || -> Res<Attenuation> {
                let d = Attenuation::default();
                let Some(a) = &l.attenuation else { return Ok(d) };
                let t = a.get_ref();
                let att = Attenuation {
                    constant: self.num_in(&t.constant, "constant", d.constant, "≥ 0", |x| x >= 0.0)?,
                    linear: self.num_in(&t.linear, "linear", d.linear, "≥ 0", |x| x >= 0.0)?,
                    quadratic: self.num_in(&t.quadratic, "quadratic", d.quadratic, "≥ 0", |x| x >= 0.0)?,
                };
                if att.constant + att.linear + att.quadratic <= 0.0 {
                    return Err(self.err(a.span(), "`attenuation` must have at least one term > 0"));
                }
                Ok(att)
            };
            match kind {
                LightKind::Directional => {
                    self.forbid(l.position.as_ref().map(|v| v.span()), || not_for("position"))?;
                    self.forbid(l.attenuation.as_ref().map(|v| v.span()), || not_for("attenuation"))?;
                    let direction = self.direction(&need(&l.direction, "direction")?, "direction")?;
                    out.directional.push(DirectionalLight { direction, color, intensity, casts_shadows });
                    self.limit(out.directional.len(), MAX_DIRECTIONAL_LIGHTS, &kind_name, lights, kind)?;
                }
                LightKind::Point => {
                    self.forbid(l.direction.as_ref().map(|v| v.span()), || not_for("direction"))?;
                    let position = self.vec3(&need(&l.position, "position")?, "position")?;
                    out.point.push(PointLight { position, color, intensity, attenuation: attenuation()?, casts_shadows });
                    self.limit(out.point.len(), MAX_POINT_LIGHTS, &kind_name, lights, kind)?;
                }
                LightKind::Spot => {
                    let position = self.vec3(&need(&l.position, "position")?, "position")?;
                    let direction = self.direction(&need(&l.direction, "direction")?, "direction")?;
                    let inner = self.num_in(&l.inner_angle, "inner_angle", DEFAULT_SPOT_INNER_DEG, "in [0, 90) degrees", |x| {
                        (0.0..90.0).contains(&x)
                    })?;
                    let outer =
                        self.num_in(&l.outer_angle, "outer_angle", DEFAULT_SPOT_OUTER_DEG, "in (0, 90) degrees", |x| x > 0.0 && x < 90.0)?;
                    if inner > outer {
                        let span = l.inner_angle.as_ref().or(l.outer_angle.as_ref()).map_or(l.kind.span(), |v| v.span());
                        return Err(self.err(span, format!("spot light `inner_angle` ({inner}) must not exceed `outer_angle` ({outer})")));
                    }
                    out.spot.push(SpotLight {
                        position,
                        direction,
                        color,
                        intensity,
                        attenuation: attenuation()?,
                        inner_angle: inner.to_radians(),
                        outer_angle: outer.to_radians(),
                        casts_shadows,
                    });
                    self.limit(out.spot.len(), MAX_SPOT_LIGHTS, &kind_name, lights, kind)?;
                }
            }
        }
        Ok(out)
    }

    /// Called after each light is added: errors at the first light past the limit, with the
    /// total count of that kind in the file.
    fn limit(&self, n: usize, max: usize, kind_name: &str, lights: &[LightToml], kind: LightKind) -> Res<()> {
        if n <= max {
            return Ok(());
        }
        let of_kind: Vec<&LightToml> = lights.iter().filter(|l| *l.kind.get_ref() == kind).collect();
        Err(self.err(of_kind[max].kind.span(), format!("too many {kind_name} lights: the scene has {}, the limit is {max}", of_kind.len())))
    }

    fn point_cloud(&mut self, p: &PointCloudToml, index: usize) -> Res<PointCloud> {
        let transform = self.transform(&p.position, &p.rotation, &p.scale)?;
        let radius = self.num_in(&p.radius, "radius", DEFAULT_POINT_RADIUS, "> 0", |x| x > 0.0)?;
        let color = p.color.as_ref().map(|c| self.color_or(&Some(c.clone()), "color", Vec3::ONE)).transpose()?;
        let coloring = match (p.coloring.as_ref().map(|c| (*c.get_ref(), c.span())), color) {
            (None, Some(c)) | (Some((ColoringToml::Uniform, _)), Some(c)) => PointColoring::Uniform(c),
            (Some((ColoringToml::Uniform, s)), None) => return Err(self.err(s, "`coloring = \"uniform\"` needs a `color`")),
            (Some((_, _)), Some(_)) => {
                let span = p.color.as_ref().map_or(0..0, |c| c.span());
                return Err(self.err(span, "`color` applies only with `coloring = \"uniform\"`"));
            }
            (Some((ColoringToml::Height, _)), None) => PointColoring::Height,
            (Some((ColoringToml::File, _)), None) | (None, None) => PointColoring::FileOrHeight,
        };
        let specular = self.color_or(&p.specular, "specular", Vec3::splat(0.1))?;
        let shininess = self.unit(&p.shininess, "shininess", 0.2)?;
        let resolved = self.file(&p.file, "point-cloud")?;
        let (mut points, colors) = match self.take_preloaded_points(&resolved) {
            Some(loaded) => loaded,
            None => load_point_cloud(&resolved)
                .map_err(|e| self.err(p.file.span(), format!("cannot load point cloud `{}`: {e}", p.file.get_ref())))?,
        };
        let bytes = (points.len() * std::mem::size_of::<Vec3>() + colors.len() * 3) as u64;
        self.reserve(p.file.span(), &format!("point cloud `{}` ({} points)", p.file.get_ref(), points.len()), bytes)?;
        if !colors.is_empty() && colors.len() != points.len() {
            return Err(self
                .err(p.file.span(), format!("point cloud `{}`: {} colours for {} points", p.file.get_ref(), colors.len(), points.len())));
        }
        let m = transform.matrix();
        for q in &mut points {
            *q = m.transform_point3(*q);
        }
        let stem = Path::new(p.file.get_ref()).file_stem().map_or("points".into(), |s| s.to_string_lossy().into_owned());
        let name = p.name.as_ref().map_or_else(|| format!("{stem}-{}", index + 1), |n| n.get_ref().clone());
        Ok(PointCloud { name, source: resolved, points, colors, radius, coloring, specular, shininess })
    }

    fn camera_path(&self, p: &S<CameraPathToml>) -> Res<CameraPath> {
        let keys = &p.get_ref().keyframe;
        if keys.len() < 2 {
            return Err(self.err(p.span(), format!("`camera_path` needs at least 2 `[[camera_path.keyframe]]`s, got {}", keys.len())));
        }
        let mut keyframes = Vec::with_capacity(keys.len());
        for k in keys {
            let time = self.num(&k.time, "time")?;
            let position = self.vec3(&k.position, "position")?;
            let target = self.vec3(&k.target, "target")?;
            if let Some(prev) = keyframes.last().map(|k: &Keyframe| k.time)
                && time <= prev
            {
                return Err(self.err(k.time.span(), format!("keyframe times must increase strictly: {time} follows {prev}")));
            }
            if position.distance(target) <= 1e-6 {
                return Err(self.err(k.target.span(), "keyframe `target` must differ from `position`"));
            }
            keyframes.push(Keyframe { time, position, target });
        }
        Ok(CameraPath { keyframes })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn demo_scene_parses() {
        let s = demo_scene();
        assert_eq!(s.objects.len(), 9);
        assert_eq!((s.lights.directional.len(), s.lights.point.len(), s.lights.spot.len()), (1, 1, 1));
        assert!(s.camera_path.is_some());
    }

    #[test]
    fn scene_data_is_checked_against_the_memory_limit_before_it_is_built() {
        let text = "[[material]]\nname = \"m\"\n\n[[object]]\nprimitive = \"sphere\"\nmaterial = \"m\"\nslices = 64\nstacks = 32\n\n\
                    [[object]]\nprimitive = \"sphere\"\nmaterial = \"m\"\nslices = 64\nstacks = 32\n";
        let one = crate::memory::sphere_bytes(64, 32);
        let path = Path::new("limits.toml");
        // Room for exactly two spheres.
        let scene = parse_scene_within(text, path, &MemoryLimit::explicit(2 * one)).unwrap();
        assert_eq!(scene.objects.len(), 2);
        // One byte less: the second sphere is refused, at its line, naming the limit.
        let e = parse_scene_within(text, path, &MemoryLimit::explicit(2 * one - 1)).unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains("limits.toml:11:") && msg.contains("sphere `sphere-2` (64 slices × 32 stacks)"), "{msg}");
        assert!(msg.contains("above the memory limit of") && msg.contains("(--max-memory)"), "{msg}");
    }
}
