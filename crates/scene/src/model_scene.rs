//! Default scenes around a bare model file (issue 23): `hybrid render bunny.obj` builds a scene
//! with a camera framing the model's bounds, a sun that casts shadows, a sky, and a ground plane
//! under the model. The scene is made as TOML text (see [`model_scene_toml`]) and loaded through
//! the ordinary scene-file parser, so `--save-scene` writes exactly the scene that is rendered.
//! The model file is read once: what was loaded to find its bounds is handed to the parser, which
//! takes it instead of loading the file named in the text again.

// The public API returns the crate's `SceneError` by value, like `load_scene`.
#![allow(clippy::result_large_err)]

use std::io::{BufRead, BufReader, Read};
use std::path::{Component, Path, PathBuf};

use glam::Vec3;

use crate::file::{Preloaded, parse_scene_preloaded};
use crate::load::{MAX_MODEL_BYTES, check_file, load_model, load_point_cloud};
use crate::memory::MemoryLimit;
use crate::model::Aabb;
use crate::{Scene, SceneError, load_scene_within};

/// What `render`, `bench` and `inspect` accept, for error messages.
pub const ACCEPTED_INPUTS: &str = "a scene file (.toml) or a model file (.gltf, .glb, .obj, .ply; point clouds .ply, .las, .laz)";

/// Vertical field of view of the default camera, degrees.
const FOV_DEG: f32 = 45.0;

/// What kind of input a path names, by its extension (and, for PLY, by its header).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InputKind {
    /// A TOML scene file.
    Scene,
    /// A mesh model (glTF, OBJ, PLY with faces).
    Model,
    /// A point cloud (PLY with only vertices, LAS, LAZ).
    PointCloud,
}

/// Classifies `path`. A `.ply` is a point cloud when its header declares no faces.
pub fn input_kind(path: &Path) -> Result<InputKind, SceneError> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    match ext.as_str() {
        "toml" => Ok(InputKind::Scene),
        "gltf" | "glb" | "obj" => Ok(InputKind::Model),
        "las" | "laz" => Ok(InputKind::PointCloud),
        "ply" => Ok(if ply_has_faces(path)? { InputKind::Model } else { InputKind::PointCloud }),
        "" => Err(SceneError::new(path, format!("the file has no extension; expected {ACCEPTED_INPUTS}"))),
        other => Err(SceneError::new(path, format!("`.{other}` is not a scene or model format; expected {ACCEPTED_INPUTS}"))),
    }
}

/// Largest PLY header read while looking for its face element.
const MAX_PLY_HEADER_BYTES: u64 = 64 << 10;

/// Whether a PLY file's header declares at least one face. The file is checked as the loaders
/// check it (a regular file within the model size limit: `/dev/zero` behind a `.ply` name is
/// refused, not read), and at most [`MAX_PLY_HEADER_BYTES`] of it are read.
fn ply_has_faces(path: &Path) -> Result<bool, SceneError> {
    check_file(path, "PLY file", MAX_MODEL_BYTES)?;
    let file = std::fs::File::open(path).map_err(|e| SceneError::new(path, format!("cannot read PLY file: {e}")))?;
    let mut reader = BufReader::new(file.take(MAX_PLY_HEADER_BYTES));
    let mut line = Vec::new();
    // A header is a few hundred bytes; stop after 1000 lines (or the byte cap) on a garbage file.
    for _ in 0..1000 {
        line.clear();
        let n = reader.read_until(b'\n', &mut line).map_err(|e| SceneError::new(path, format!("cannot read PLY file: {e}")))?;
        if n == 0 {
            break;
        }
        let text = String::from_utf8_lossy(&line);
        let words: Vec<&str> = text.split_whitespace().collect();
        match words.as_slice() {
            ["end_header"] => return Ok(false),
            ["element", "face", count] => return Ok(count.parse::<u64>().is_ok_and(|c| c > 0)),
            _ => {}
        }
    }
    Err(SceneError::new(path, "not a PLY file: no `end_header` line in its header"))
}

/// The scene for `path`: a `.toml` scene file is loaded as it is; a model or point-cloud file gets
/// the default scene of [`model_scene_toml`]. Any other file is an error that says what is accepted.
pub fn load_scene_or_model(path: &Path) -> Result<Scene, SceneError> {
    load_scene_or_model_within(path, &MemoryLimit::machine_default())
}

/// [`load_scene_or_model`] with the scene's data checked against `limit` as it is built
/// ([`crate::load_scene_within`]).
pub fn load_scene_or_model_within(path: &Path, limit: &MemoryLimit) -> Result<Scene, SceneError> {
    match input_kind(path)? {
        InputKind::Scene => load_scene_within(path, limit),
        _ => {
            // Paths in the scene are relative to a (virtual) scene file beside the model.
            let dir = path.parent().unwrap_or(Path::new(""));
            let stem = path.file_stem().map_or("model".into(), |s| s.to_string_lossy().into_owned());
            let virtual_file = dir.join(format!("{stem}.scene.toml"));
            // The model is loaded once: for the bounds the scene frames, then handed to the parser.
            let (text, preloaded) = model_scene(path, &virtual_file)?;
            let mut scene = parse_scene_preloaded(&text, &virtual_file, limit, Some(preloaded))?;
            scene.source = Some(path.to_path_buf());
            Ok(scene)
        }
    }
}

/// Largest coordinate a bare model may have for its default scene to be computed in f32.
const MAX_FRAMED_COORDINATE: f32 = 1e18;

/// The default scene around the model or point cloud `model` as scene-file TOML, with the
/// model's path written relative to the directory of `scene_file` (where the text will be saved).
pub fn model_scene_toml(model: &Path, scene_file: &Path) -> Result<String, SceneError> {
    model_scene(model, scene_file).map(|(text, _)| text)
}

/// [`model_scene_toml`], and the model or point cloud it loaded to find the bounds.
fn model_scene(model: &Path, scene_file: &Path) -> Result<(String, Preloaded), SceneError> {
    let kind = input_kind(model)?;
    let mut bounds = Aabb::EMPTY;
    let preloaded = match kind {
        InputKind::Scene => return Err(SceneError::new(model, "is a scene file, not a model")),
        InputKind::Model => {
            let (mut materials, mut textures) = (Vec::new(), Vec::new());
            let meshes = load_model(model, &mut materials, &mut textures)?;
            meshes.iter().flat_map(|m| m.positions.iter()).for_each(|p| bounds.grow(*p));
            Preloaded::Model { path: model.to_path_buf(), meshes, materials, textures }
        }
        InputKind::PointCloud => {
            let (points, colors) = load_point_cloud(model)?;
            points.iter().for_each(|p| bounds.grow(*p));
            Preloaded::Points { path: model.to_path_buf(), points, colors }
        }
    };
    if bounds.is_empty() {
        return Err(SceneError::new(model, "the model has no vertices, so there is nothing to frame"));
    }
    // The camera, far plane and ground are computed from the bounds (their diagonal squared
    // included): far beyond 1e18 units they overflow to infinity.
    let reach = bounds.min.abs().max(bounds.max.abs()).max_element();
    if reach > MAX_FRAMED_COORDINATE {
        return Err(SceneError::new(
            model,
            format!(
                "the model reaches {reach:e} units from the origin, too far to frame in a default scene (at most {MAX_FRAMED_COORDINATE:e}); \
                 write a scene file for it with its own camera"
            ),
        ));
    }
    let rel = relative_path(model, scene_file.parent().unwrap_or(Path::new("")));
    Ok((scene_text(&rel, kind, bounds), preloaded))
}

/// `target` relative to `base` (both made absolute against the working directory first), with
/// `/` separators so the TOML is the same on every platform.
fn relative_path(target: &Path, base: &Path) -> String {
    let cwd = std::env::current_dir().unwrap_or_default();
    let abs = |p: &Path| normalize(&if p.is_absolute() { p.to_path_buf() } else { cwd.join(p) });
    let (t, b) = (abs(target), abs(base));
    let tc: Vec<Component> = t.components().collect();
    let bc: Vec<Component> = b.components().collect();
    let common = tc.iter().zip(&bc).take_while(|(x, y)| x == y).count();
    if common == 0 {
        return t.to_string_lossy().replace('\\', "/");
    }
    let mut out = PathBuf::new();
    for _ in common..bc.len() {
        out.push("..");
    }
    for c in &tc[common..] {
        out.push(c.as_os_str());
    }
    out.to_string_lossy().replace('\\', "/")
}

/// Removes `.` and resolves `..` lexically.
fn normalize(p: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for c in p.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                if !out.pop() {
                    out.push("..");
                }
            }
            other => out.push(other.as_os_str()),
        }
    }
    out
}

/// TOML floats: always with a decimal point, short.
fn f(x: f32) -> String {
    let s = format!("{x:.4}");
    let s = s.trim_end_matches('0');
    if s.ends_with('.') { format!("{s}0") } else { s.to_string() }
}

fn v3(v: Vec3) -> String {
    format!("[{}, {}, {}]", f(v.x), f(v.y), f(v.z))
}

fn toml_string(s: &str) -> String {
    let mut out = String::from("\"");
    for ch in s.chars() {
        match ch {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if c.is_control() => out.push_str(&format!("\\u{:04X}", c as u32)),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

fn scene_text(model: &str, kind: InputKind, b: Aabb) -> String {
    let center = b.center();
    let size = b.max - b.min;
    let radius = (size.length() * 0.5).max(1e-3);
    // Distance at which the bounding sphere fills the vertical field of view, with a margin.
    let dist = radius / (FOV_DEG.to_radians() * 0.5).sin() * 1.1;
    let dir = Vec3::new(0.55, 0.35, 1.0).normalize();
    let eye = center + dir * dist;
    let ground_y = b.min.y - radius * 0.002;
    let ground = radius * 8.0;
    let far = (dist + radius * 10.0).max(1.0);
    let near = (dist - radius).max(far * 1e-4).min(radius * 0.05).max(1e-4);
    let mut t = String::new();
    t.push_str("# Default scene around a bare model (`hybrid render MODEL --save-scene FILE.toml`);\n");
    t.push_str("# edit it freely: docs/scene-format.md lists every key.\n\n");
    t.push_str(&format!(
        "[camera]\nposition = {}\ntarget = {}\nfov = {}\nnear = {}\nfar = {}\n\n",
        v3(eye),
        v3(center),
        f(FOV_DEG),
        f(near),
        f(far)
    ));
    t.push_str("[environment]\nambient = [0.25, 0.27, 0.3]\n\n[environment.skybox]\nzenith = [0.16, 0.34, 0.78]\nhorizon = [0.75, 0.84, 0.95]\nground = [0.33, 0.31, 0.28]\n\n");
    t.push_str("[[material]]\nname = \"ground\"\ndiffuse = [0.55, 0.55, 0.53]\nspecular = [0.05, 0.05, 0.05]\nshininess = 0.2\n\n");
    match kind {
        InputKind::PointCloud => {
            // Point radius: about a 500th of the bounds, so a scan reads as a surface.
            t.push_str(&format!(
                "[[point_cloud]]\nname = \"model\"\nfile = {}\nradius = {}\n\n",
                toml_string(model),
                f((radius * 0.004).max(1e-4))
            ));
        }
        _ => t.push_str(&format!("[[object]]\nname = \"model\"\nmodel = {}\n\n", toml_string(model))),
    }
    t.push_str(&format!(
        "[[object]]\nname = \"ground\"\nprimitive = \"plane\"\nposition = {}\nscale = [{}, 1.0, {}]\nmaterial = \"ground\"\n\n",
        v3(Vec3::new(center.x, ground_y, center.z)),
        f(ground),
        f(ground)
    ));
    t.push_str("[[light]]\ntype = \"directional\"\ndirection = [-0.5, -0.75, -0.45]\ncolor = [1.0, 0.95, 0.86]\nintensity = 1.5\ncasts_shadows = true\n");
    t
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn models_too_far_out_to_frame_are_refused_naming_the_model() {
        let dir = tempfile::tempdir().unwrap();
        let obj = |name: &str, x: f32| {
            let p = dir.path().join(name);
            std::fs::write(&p, format!("v 0 0 0\nv {x} 0 0\nv 0 1 0\nf 1 2 3\n")).unwrap();
            p
        };
        // 2^99: the diagonal's square overflowed and the camera was written at `[inf, inf, inf]`.
        let far = obj("far.obj", 2f32.powi(99));
        let e = model_scene_toml(&far, &dir.path().join("far.scene.toml")).unwrap_err();
        assert!(e.to_string().contains("far.obj") && e.message.contains("too far to frame"), "{e}");
        assert!(load_scene_or_model(&far).unwrap_err().message.contains("too far to frame"));
        // At the limit it frames, with finite numbers throughout.
        let edge = obj("edge.obj", 1e18);
        let text = model_scene_toml(&edge, &dir.path().join("edge.scene.toml")).unwrap();
        assert!(!text.contains("inf") && !text.contains("NaN"), "{text}");
        assert!(load_scene_or_model(&edge).is_ok());
    }

    #[test]
    fn relative_paths_walk_up_and_down() {
        assert_eq!(relative_path(Path::new("/a/b/m.obj"), Path::new("/a/c")), "../b/m.obj");
        assert_eq!(relative_path(Path::new("/a/b/m.obj"), Path::new("/a/b")), "m.obj");
        assert_eq!(relative_path(Path::new("/a/./b/../b/m.obj"), Path::new("/a/b/c/d")), "../../m.obj");
    }

    #[test]
    fn unknown_extensions_say_what_is_accepted() {
        let e = input_kind(Path::new("notes.txt")).unwrap_err();
        assert!(e.message.contains(".gltf") && e.message.contains(".toml") && e.to_string().contains("notes.txt"), "{e}");
    }

    #[test]
    fn the_preloaded_model_gives_the_scene_its_saved_text_gives() {
        // An OBJ with a textured material: the bare-model scene takes the model as it was loaded
        // for the bounds, so its material and texture ids must be shifted past the scene's own
        // (the ground material) exactly as loading the file from the saved text shifts them.
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        image::RgbaImage::from_fn(4, 4, |x, y| image::Rgba([(x * 60) as u8, (y * 60) as u8, 90, 255])).save(d.join("t.png")).unwrap();
        std::fs::write(d.join("m.mtl"), "newmtl red\nKd 0.8 0.1 0.1\nmap_Kd t.png\nnewmtl blue\nKd 0.1 0.1 0.8\n").unwrap();
        let obj = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n\
                   usemtl red\nf 1/1 2/2 3/3\nusemtl blue\nf 1/1 3/3 4/4\n";
        std::fs::write(d.join("m.obj"), obj).unwrap();
        let model = d.join("m.obj");
        let direct = load_scene_or_model(&model).unwrap();
        let saved = d.join("m.scene.toml");
        std::fs::write(&saved, model_scene_toml(&model, &saved).unwrap()).unwrap();
        let from_text = crate::load_scene(&saved).unwrap();
        assert_eq!(direct.materials, from_text.materials);
        assert_eq!(direct.textures, from_text.textures);
        assert_eq!(direct.objects.len(), from_text.objects.len());
        for (a, b) in direct.objects.iter().zip(&from_text.objects) {
            assert_eq!(a.meshes, b.meshes, "object {}", a.name);
        }
        let red = &direct.materials[direct.objects[0].meshes[0].material];
        assert_eq!((red.name.as_str(), red.diffuse_map), ("red", Some(0)));
        assert_eq!(direct.materials[0].name, "ground");

        // A point cloud (PLY without faces) too.
        std::fs::write(d.join("p.ply"), "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n1 0 0\n0 2 1\n").unwrap();
        let direct = load_scene_or_model(&d.join("p.ply")).unwrap();
        assert_eq!(direct.point_clouds.len(), 1);
        assert_eq!(direct.point_clouds[0].points, vec![Vec3::ZERO, Vec3::X, Vec3::new(0.0, 2.0, 1.0)]);
    }

    #[test]
    fn floats_are_toml_floats() {
        assert_eq!(f(1.0), "1.0");
        assert_eq!(f(-0.25), "-0.25");
        assert_eq!(toml_string("a\"b\\c"), "\"a\\\"b\\\\c\"");
    }
}
