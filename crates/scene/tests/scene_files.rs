//! Scene files: every bad input gives an error that names the file, the `line:column` (for
//! TOML) and what is wrong; the demo and every shipped scene parse.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use hybrid_scene::{Budget, ObjectSource, PointColoring, Projection, Skybox, demo_scene, load_scene, parse_scene};

/// Writes `text` as `scene.toml` in a fresh temp dir and loads it.
fn load(text: &str) -> (tempfile::TempDir, Result<hybrid_scene::Scene, hybrid_scene::SceneError>) {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("scene.toml");
    std::fs::write(&path, text).expect("write scene");
    let r = load_scene(&path);
    (dir, r)
}

/// Loads `text`, expects an error at `line` (1-based) whose message contains every `needle`.
#[track_caller]
fn expect_error(text: &str, line: usize, needles: &[&str]) -> String {
    let (dir, r) = load(text);
    let e = match r {
        Ok(_) => panic!("scene should have been rejected:\n{text}"),
        Err(e) => e,
    };
    let msg = e.to_string();
    let file = dir.path().join("scene.toml");
    assert!(msg.starts_with(&format!("{}:{line}:", file.display())), "error should start with `{}:{line}:col`: {msg}", file.display());
    let (l, c) = e.location.expect("TOML errors have a location");
    assert_eq!(l, line, "{msg}");
    assert!(c >= 1);
    assert!(msg.contains(&format!(":{l}:{c}: ")), "{msg}");
    for n in needles {
        assert!(msg.contains(n), "error should mention `{n}`: {msg}");
    }
    msg
}

const CAMERA: &str = "[camera]\nposition = [0, 1, 5]\ntarget = [0, 0, 0]\n";
const MATERIAL: &str = "[[material]]\nname = \"white\"\n";

#[test]
fn toml_syntax_error() {
    // The unclosed array is noticed where the next key starts.
    expect_error("[camera]\nposition = [0, 1, 5\ntarget = [0, 0, 0]\n", 3, &["missing comma between array elements"]);
    expect_error("[camera\nfov = 60\n", 1, &["unclosed table"]);
}

#[test]
fn unknown_key() {
    expect_error("[camera]\nposition = [0, 1, 5]\nfield_of_view = 60\n", 3, &["unknown field `field_of_view`"]);
}

#[test]
fn unknown_key_in_material() {
    expect_error(&format!("{MATERIAL}diffuse = [1, 1, 1]\nrefl = 0.5\n"), 4, &["unknown field `refl`", "reflectivity"]);
}

#[test]
fn wrong_type() {
    expect_error("[camera]\nfov = \"wide\"\n", 2, &["invalid type", "string"]);
}

#[test]
fn wrong_enum_value() {
    expect_error("[[light]]\ntype = \"sun\"\ndirection = [0, -1, 0]\n", 2, &["unknown variant `sun`", "directional"]);
}

#[test]
fn missing_required_field() {
    // A material without a name.
    expect_error("[[material]]\ndiffuse = [1, 0, 0]\n", 1, &["missing field `name`"]);
}

#[test]
fn missing_light_direction() {
    expect_error("[[light]]\ntype = \"directional\"\ncolor = [1, 1, 1]\n", 2, &["directional light needs `direction`"]);
}

#[test]
fn negative_radius() {
    let text = "[[point_cloud]]\nfile = \"points.ply\"\nradius = -0.5\n";
    expect_error(text, 3, &["`radius` must be > 0", "-0.5"]);
}

#[test]
fn fov_of_180_or_more() {
    for fov in ["180", "181.5"] {
        expect_error(&format!("{CAMERA}fov = {fov}\n"), 4, &["`fov` must be between 0 and 180", fov]);
    }
    expect_error(&format!("{CAMERA}fov = 0\n"), 4, &["`fov`"]);
}

#[test]
fn near_not_below_far() {
    expect_error(&format!("{CAMERA}near = 10\nfar = 10\n"), 5, &["`near` must be less than `far`"]);
    expect_error(&format!("{CAMERA}near = 0\n"), 4, &["`near` must be > 0"]);
}

#[test]
fn nan_is_rejected() {
    expect_error(&format!("{CAMERA}near = nan\n"), 4, &["`near` is NaN"]);
    expect_error("[environment]\nambient = [0.1, nan, 0.1]\n", 2, &["`ambient` is NaN"]);
}

#[test]
fn inf_is_rejected() {
    expect_error(&format!("{CAMERA}far = inf\n"), 4, &["`far` is infinite"]);
    expect_error(
        &format!("{MATERIAL}[[object]]\nprimitive = \"cube\"\nmaterial = \"white\"\nposition = [-inf, 0, 0]\n"),
        6,
        &["`position` is infinite"],
    );
    // Finite in TOML but not in f32.
    expect_error(&format!("{CAMERA}far = 1e300\n"), 4, &["`far` is infinite"]);
}

fn lights(kind: &str, extra: &str, n: usize) -> String {
    let mut s = String::new();
    for _ in 0..n {
        write!(s, "[[light]]\ntype = \"{kind}\"\n{extra}").unwrap();
    }
    s
}

#[test]
fn nine_directional_lights() {
    let text = lights("directional", "direction = [0, -1, 0]\n", 9);
    // The ninth light's `type` is on line 8*3 + 2.
    expect_error(&text, 26, &["too many directional lights", "9", "limit is 8"]);
    assert!(load(&lights("directional", "direction = [0, -1, 0]\n", 8)).1.is_ok());
}

#[test]
fn thirty_three_point_lights() {
    let text = lights("point", "position = [0, 1, 0]\n", 33);
    expect_error(&text, 32 * 3 + 2, &["too many point lights", "33", "limit is 32"]);
    assert!(load(&lights("point", "position = [0, 1, 0]\n", 32)).1.is_ok());
}

#[test]
fn thirty_three_spot_lights() {
    let text = lights("spot", "position = [0, 1, 0]\ndirection = [0, -1, 0]\n", 33);
    expect_error(&text, 32 * 4 + 2, &["too many spot lights", "33", "limit is 32"]);
}

#[test]
fn spot_inner_wider_than_outer() {
    let text = "[[light]]\ntype = \"spot\"\nposition = [0, 1, 0]\ndirection = [0, -1, 0]\ninner_angle = 40\nouter_angle = 30\n";
    expect_error(text, 5, &["`inner_angle` (40) must not exceed `outer_angle` (30)"]);
    let text = "[[light]]\ntype = \"spot\"\nposition = [0, 1, 0]\ndirection = [0, -1, 0]\nouter_angle = 90\n";
    expect_error(text, 5, &["`outer_angle` must be in (0, 90)"]);
}

#[test]
fn missing_model_file() {
    let msg = expect_error(
        "[[object]]\nname = \"statue\"\nmodel = \"models/statue.glb\"\n",
        3,
        &["model file `models/statue.glb` not found", "resolved to"],
    );
    assert!(msg.contains(&Path::new("models").join("statue.glb").display().to_string()));
}

#[test]
fn missing_texture_file() {
    expect_error(
        &format!("{MATERIAL}diffuse_map = \"textures/brick.png\"\n"),
        3,
        &["texture file `textures/brick.png` not found", "resolved to"],
    );
}

#[test]
fn missing_skybox_face() {
    let text = "[environment.skybox]\npx = \"sky/px.png\"\nnx = \"sky/nx.png\"\n";
    expect_error(text, 2, &["texture file `sky/px.png` not found"]);
}

#[test]
fn missing_point_cloud_file() {
    expect_error(
        "[[point_cloud]]\nfile = \"scans/forest.laz\"\nradius = 0.02\n",
        2,
        &["point-cloud file `scans/forest.laz` not found", "resolved to"],
    );
}

#[test]
fn undefined_material() {
    let text = format!("{MATERIAL}[[object]]\nname = \"ball\"\nprimitive = \"sphere\"\nmaterial = \"whit\"\n");
    expect_error(&text, 6, &["object `ball`", "material `whit`", "not defined", "white"]);
}

#[test]
fn duplicate_material() {
    expect_error(&format!("{MATERIAL}{MATERIAL}"), 4, &["material `white` is defined twice", "line 2"]);
}

#[test]
fn primitive_without_material() {
    expect_error("[[object]]\nprimitive = \"plane\"\n", 2, &["primitives need a `material`"]);
}

#[test]
fn bad_material_values() {
    expect_error(&format!("{MATERIAL}opacity = 1.5\n"), 3, &["`opacity` must be between 0 and 1", "1.5"]);
    expect_error(&format!("{MATERIAL}reflectivity = -0.1\n"), 3, &["`reflectivity` must be between 0 and 1"]);
    expect_error(&format!("{MATERIAL}shininess = 2\n"), 3, &["`shininess` must be between 0 and 1"]);
    expect_error(&format!("{MATERIAL}ior = 0\n"), 3, &["`ior` must be > 0"]);
    expect_error(&format!("{MATERIAL}diffuse = [0.5, -0.1, 0.5]\n"), 3, &["`diffuse` is a colour", "≥ 0"]);
}

#[test]
fn zero_scale_and_bad_sphere_segments() {
    let obj = format!("{MATERIAL}[[object]]\nprimitive = \"sphere\"\nmaterial = \"white\"\n");
    expect_error(&format!("{obj}scale = [1, 0, 1]\n"), 6, &["`scale` must not be zero"]);
    expect_error(&format!("{obj}scale = 0\n"), 6, &["`scale` must not be zero"]);
    expect_error(&format!("{obj}scale = \"big\"\n"), 6, &["a number or an array of 3 numbers"]);
    expect_error(&format!("{obj}slices = 2\n"), 6, &["`slices` must be between 3"]);
    expect_error(&format!("{obj}stacks = 1\n"), 6, &["`stacks` must be between 2"]);
}

#[test]
fn budget_and_budget_ms_together() {
    expect_error("[heuristic]\nbudget = 1000\nbudget_ms = 4\n", 3, &["either `budget`", "not both"]);
}

#[test]
fn camera_path_needs_increasing_times() {
    let k = |t: f32| format!("[[camera_path.keyframe]]\ntime = {t:?}\nposition = [0, 1, 5]\ntarget = [0, 0, 0]\n");
    expect_error(&format!("{}{}", k(0.0), k(0.0)), 6, &["strictly", "0 follows 0"]);
    let text = format!("[camera_path]\n{}", k(0.0));
    expect_error(&text, 1, &["at least 2", "got 1"]);
}

#[test]
fn syntax_error_without_file_still_names_the_file() {
    let e = parse_scene("a = [", Path::new("dir/x.toml")).expect_err("invalid");
    assert!(e.to_string().starts_with("dir/x.toml:1:"), "{e}");
}

#[test]
fn empty_file_is_an_empty_scene_with_defaults() {
    let s = parse_scene("", Path::new("empty.toml")).expect("empty scene is valid");
    assert!(s.objects.is_empty() && s.lights.count() == 0 && s.camera_path.is_none());
    assert_eq!(s.trace.max_depth, 10);
    assert_eq!(s.heuristic.budget, Budget::Unlimited);
}

#[test]
fn values_reach_the_scene() {
    let text = r#"
[camera]
projection = "orthographic"
height = 8
position = [0, 5, 10]
target = [0, 0, 0]
near = 0.5
far = 50

[environment]
ambient = [0.2, 0.2, 0.2]
ior = 1.33
skybox = { color = [0.5, 0.6, 0.7] }

[heuristic]
budget_ms = 3.5
importance = 0.5
policy = "knapsack"

[[material]]
name = "glass"
opacity = 0.1
ior = 1.5
reflectivity = 0.2

[[object]]
name = "ball"
primitive = "sphere"
slices = 12
stacks = 6
scale = [2, 2, 2]
material = "glass"
relevance = 3
cost = 2

[[light]]
type = "spot"
position = [0, 4, 0]
direction = [0, -2, 0]
inner_angle = 10
outer_angle = 20
attenuation = { quadratic = 0.5 }
casts_shadows = false
"#;
    let s = parse_scene(text, Path::new("v.toml")).expect("valid");
    assert_eq!(s.camera.projection, Projection::Orthographic { height: 8.0, near: 0.5, far: 50.0 });
    assert!((s.environment.ior - 1.33).abs() < 1e-6);
    assert!(matches!(s.environment.skybox, Skybox::Color(c) if (c.y - 0.6).abs() < 1e-6));
    assert_eq!(s.heuristic.budget, Budget::Millis(3.5));
    let o = &s.objects[0];
    assert_eq!(o.source, ObjectSource::Sphere { slices: 12, stacks: 6 });
    assert_eq!((o.relevance, o.cost), (3.0, 2.0));
    assert_eq!(o.meshes[0].material, 0);
    assert!(s.materials[0].is_refractive() && s.materials[0].is_reflective());
    let spot = &s.lights.spot[0];
    assert!((spot.direction.y + 1.0).abs() < 1e-6, "direction normalised");
    assert!((spot.inner_angle - 10f32.to_radians()).abs() < 1e-6);
    assert_eq!((spot.attenuation.constant, spot.attenuation.quadratic), (1.0, 0.5));
    assert!(!spot.casts_shadows);
}

#[test]
fn demo_scene_has_the_expected_content() {
    let s = demo_scene();
    assert!(s.source.is_none());
    assert_eq!(s.objects.len(), 9);
    assert_eq!((s.lights.directional.len(), s.lights.point.len(), s.lights.spot.len()), (1, 1, 1));
    assert!(s.lights.directional.iter().all(|l| l.casts_shadows) && s.lights.point[0].casts_shadows && s.lights.spot[0].casts_shadows);
    assert!(s.textures.is_empty() && s.point_clouds.is_empty());
    assert!(matches!(s.environment.skybox, Skybox::Gradient { .. }));
    let by_name = |n: &str| s.objects.iter().find(|o| o.name == n).unwrap_or_else(|| panic!("no object {n}"));
    let mat = |n: &str| &s.materials[by_name(n).meshes[0].material];
    assert!(mat("mirror-sphere").reflectivity >= 0.85);
    assert!(mat("glass-sphere").opacity <= 0.15 && (mat("glass-sphere").ior - 1.5).abs() < 1e-6);
    assert!(mat("glass-cube").is_refractive() && by_name("glass-cube").source == ObjectSource::Cube);
    let path = s.camera_path.as_ref().expect("camera path");
    assert!(path.keyframes.len() >= 2 && path.duration() > 0.0);
    // The demo file on disk is the embedded one.
    let on_disk = std::fs::read_to_string(scenes_dir().join("demo.toml")).expect("scenes/demo.toml");
    assert_eq!(on_disk, hybrid_scene::DEMO_SCENE_TOML);
}

fn scenes_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes")
}

/// Every shipped scene parses (the asset scenes need the model/point-cloud/texture loaders and
/// the files under `shared/assets`).
#[test]
fn every_shipped_scene_loads() {
    let mut names: Vec<PathBuf> = std::fs::read_dir(scenes_dir())
        .expect("scenes/")
        .map(|e| e.expect("dir entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    names.sort();
    assert!(names.len() >= 6, "expected demo + 5 asset scenes, found {names:?}");
    let mut failures = Vec::new();
    for p in &names {
        match load_scene(p) {
            Ok(s) => {
                let path = s.camera_path.as_ref().unwrap_or_else(|| panic!("{} has no camera path", p.display()));
                assert!(path.keyframes.len() >= 4 || p.ends_with("demo.toml"), "{}", p.display());
                assert!(!s.objects.is_empty(), "{}", p.display());
            }
            Err(e) => failures.push(e.to_string()),
        }
    }
    assert!(failures.is_empty(), "scenes that do not load:\n{}", failures.join("\n"));
}

#[test]
fn tree_scene_point_cloud_is_y_up() {
    let s = load_scene(&scenes_dir().join("tree-merge.toml")).expect("tree-merge.toml loads");
    let pc = &s.point_clouds[0];
    assert!(pc.points.len() > 1_000_000);
    assert_eq!(pc.coloring, PointColoring::Height);
    let b = pc.bounds();
    // Trees up to ~13 m tall: after the Z-up → Y-up rotation, the tall axis is Y.
    assert!(b.max.y - b.min.y > 12.0, "{b:?}");
}

/// Every asset scene's camera path lasts 20 s and stays inside the scene's bounds (polygons and
/// point clouds), sampled every 0.1 s, so benchmarks never film the void.
#[test]
fn asset_camera_paths_stay_inside_the_scene() {
    for name in ["sponza-spheres", "sponza-armadillo", "dining-room", "pavilion", "tree-merge"] {
        let s = load_scene(&scenes_dir().join(format!("{name}.toml"))).unwrap_or_else(|e| panic!("{e}"));
        let mut b = hybrid_scene::Aabb::EMPTY;
        for o in &s.objects {
            if let Some(ob) = o.world_bounds() {
                b = b.union(&ob);
            }
        }
        for pc in &s.point_clouds {
            b = b.union(&pc.bounds());
        }
        let path = s.camera_path.as_ref().expect("camera path");
        assert!(path.keyframes.len() >= 4, "{name}: {} keyframes", path.keyframes.len());
        assert!((path.duration() - 20.0).abs() < 1e-3, "{name}: {} s", path.duration());
        let tris: usize = s.objects.iter().map(|o| o.triangle_count()).sum();
        let pts: usize = s.point_clouds.iter().map(|p| p.points.len()).sum();
        println!(
            "{name}: {} objects, {tris} triangles, {pts} points, {} materials, {} textures, bounds {b:?}",
            s.objects.len(),
            s.materials.len(),
            s.textures.len()
        );
        for i in 0..=200 {
            let (p, _) = path.sample(i as f32 * 0.1);
            assert!(p.cmpge(b.min).all() && p.cmple(b.max).all(), "{name}: camera at {p} (t = {}) leaves the scene {b:?}", i as f32 * 0.1);
        }
    }
}

/// A cube OBJ without normals (8 shared corners, 6 quads) and a scene using it as `model`.
fn cube_obj_scene(object_extra: &str) -> (tempfile::TempDir, Result<hybrid_scene::Scene, hybrid_scene::SceneError>) {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut obj = String::new();
    for i in 0..8 {
        writeln!(obj, "v {} {} {}", i & 1, (i >> 1) & 1, (i >> 2) & 1).unwrap();
    }
    for q in [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]] {
        writeln!(obj, "f {} {} {} {}", q[0] + 1, q[1] + 1, q[2] + 1, q[3] + 1).unwrap();
    }
    std::fs::write(dir.path().join("cube.obj"), obj).unwrap();
    let path = dir.path().join("scene.toml");
    std::fs::write(&path, format!("[[object]]\nmodel = \"cube.obj\"\n{object_extra}")).unwrap();
    let r = load_scene(&path);
    (dir, r)
}

#[test]
fn models_without_normals_get_smooth_normals_with_a_crease_angle() {
    // Default 60°: the cube's 90° edges stay hard (each corner split into one vertex per face).
    let (_d, s) = cube_obj_scene("");
    let mesh = &s.expect("cube scene").objects[0].meshes[0];
    assert_eq!((mesh.positions.len(), mesh.normals.len()), (24, 24));
    for tri in &mesh.indices {
        let n = tri.map(|i| mesh.normals[i as usize]);
        assert!(n[0] == n[1] && n[1] == n[2] && n[0].abs().max_element() == 1.0, "flat axis-aligned face: {n:?}");
    }
    // 180°: every edge smooth, no vertex split, normals along the diagonals.
    let (_d, s) = cube_obj_scene("crease_angle = 180\n");
    let mesh = &s.expect("cube scene").objects[0].meshes[0];
    assert_eq!(mesh.normals.len(), 8);
    for (p, n) in mesh.positions.iter().zip(&mesh.normals) {
        assert!(n.dot((*p - glam::Vec3::splat(0.5)).normalize()) > 0.99999, "{p} {n}");
    }
}

#[test]
fn crease_angle_is_validated() {
    for (value, what) in [("-1", "got -1"), ("180.5", "got 180.5"), ("nan", "NaN")] {
        let (dir, r) = cube_obj_scene(&format!("crease_angle = {value}\n"));
        let msg = r.expect_err("bad crease angle").to_string();
        let file = dir.path().join("scene.toml");
        assert!(msg.starts_with(&format!("{}:3:", file.display())), "{msg}");
        assert!(msg.contains("crease_angle") && msg.contains(what), "{msg}");
    }
    let (_d, r) = cube_obj_scene("crease_angle = 0\n");
    r.expect("0 is allowed");
    expect_error(
        &format!("{MATERIAL}[[object]]\nprimitive = \"sphere\"\nmaterial = \"white\"\ncrease_angle = 30\n"),
        6,
        &["`crease_angle` applies to `model` objects only"],
    );
    expect_error("[[object]]\nmodel = \"m.obj\"\ncrease_angle = \"soft\"\n", 3, &["invalid type"]);
}
