//! Issue 23: a bare model file renders in a default scene, `--save-scene` writes that scene so it
//! loads back to the same image, and a file that is neither a scene nor a model is refused.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn hybrid(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hybrid")).args(args).env("XDG_RUNTIME_DIR", std::env::temp_dir()).output().expect("run hybrid")
}

fn asset(rel: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/assets").join(rel).to_string_lossy().into_owned()
}

/// Renders `model` on the CPU at 96×72 and checks exit 0 and an image that is not one colour.
fn renders_non_uniform(model: &str, out: &Path, extra: &[&str]) -> Vec<u8> {
    let o = out.to_str().unwrap();
    let mut args = vec!["render", model, "--backend", "cpu", "--size", "96x72", "-o", o, "--quiet"];
    args.extend_from_slice(extra);
    let r = hybrid(&args);
    assert!(r.status.success(), "{model}: {}", String::from_utf8_lossy(&r.stderr));
    let img = image::open(out).unwrap().to_rgb8();
    let first = *img.get_pixel(0, 0);
    let differing = img.pixels().filter(|p| **p != first).count();
    assert!(differing > img.len() / 30, "{model}: image is (nearly) uniform: {differing} pixels differ from the first");
    img.into_raw()
}

#[test]
fn bare_obj_glb_and_ply_render_non_uniform_images() {
    let dir = tempfile::tempdir().unwrap();
    for (i, model) in [
        asset("stanford-bunny/stanford-bunny.obj"),
        asset("broken-models/gltf/control-valid-BoxTextured/BoxTextured.glb"),
        asset("stanford-dragon/dragon_vrip_res2.ply"),
        asset("tree-pointcloud/treels_pine.laz"),
    ]
    .iter()
    .enumerate()
    {
        renders_non_uniform(model, &dir.path().join(format!("{i}.png")), &[]);
    }
}

#[test]
fn saved_scene_loads_back_to_the_same_image() {
    let dir = tempfile::tempdir().unwrap();
    // In a subfolder, so the model path written must be relative to the scene file, not the cwd.
    let sub: PathBuf = dir.path().join("edit");
    std::fs::create_dir(&sub).unwrap();
    let toml = sub.join("bunny.toml");
    let model = asset("stanford-bunny/stanford-bunny.obj");
    let a = renders_non_uniform(&model, &dir.path().join("a.png"), &["--save-scene", toml.to_str().unwrap()]);
    let text = std::fs::read_to_string(&toml).unwrap();
    assert!(text.contains("model = \"../"), "model path should be relative to the scene file:\n{text}");
    assert!(text.contains("casts_shadows = true") && text.contains("primitive = \"plane\""), "{text}");
    let b = renders_non_uniform(toml.to_str().unwrap(), &dir.path().join("b.png"), &[]);
    assert!(a == b, "the saved scene renders differently from the model's default scene");
}

#[test]
fn unknown_file_types_exit_2_saying_what_is_accepted() {
    let dir = tempfile::tempdir().unwrap();
    let notes = dir.path().join("notes.txt");
    std::fs::write(&notes, "hello").unwrap();
    let out = dir.path().join("x.png");
    for cmd in ["render", "inspect", "bench"] {
        let mut args = vec![cmd, notes.to_str().unwrap()];
        if cmd == "render" {
            args.extend(["-o", out.to_str().unwrap()]);
        }
        let r = hybrid(&args);
        let err = String::from_utf8_lossy(&r.stderr);
        assert_eq!(r.status.code(), Some(2), "{cmd}: {err}");
        assert!(err.contains("notes.txt") && err.contains(".toml") && err.contains(".obj") && err.contains(".glb"), "{cmd}: {err}");
    }
    assert!(!out.exists());
}

/// Issue 23: `--time` beyond the camera path's end says that it was clamped.
#[test]
fn time_past_the_camera_path_says_it_was_clamped() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("path.toml");
    std::fs::write(
        &scene,
        "[[material]]\nname = \"m\"\n[[object]]\nprimitive = \"cube\"\nmaterial = \"m\"\n\
         [[camera_path.keyframe]]\ntime = 0.0\nposition = [0.0, 0.0, 5.0]\ntarget = [0.0, 0.0, 0.0]\n\
         [[camera_path.keyframe]]\ntime = 2.0\nposition = [5.0, 0.0, 0.0]\ntarget = [0.0, 0.0, 0.0]\n",
    )
    .unwrap();
    let out = dir.path().join("o.png");
    let run = |t: &str| {
        hybrid(&["render", scene.to_str().unwrap(), "--backend", "cpu", "--size", "32x24", "-o", out.to_str().unwrap(), "--time", t])
    };
    let r = run("9");
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(r.status.success(), "{err}");
    assert!(err.contains("past the end") && err.contains("rendering at 2 s"), "{err}");
    let r = run("1.5");
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(r.status.success() && !err.contains("clamp") && !err.contains("warning"), "{err}");
}

/// Issue 23: a successful `--backend auto` run prints no line starting `error:` (the Vulkan
/// loader's window-system probe used to print two when XDG_RUNTIME_DIR was unset).
#[test]
fn auto_backend_prints_no_error_lines_on_success() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o.png");
    let r = Command::new(env!("CARGO_BIN_EXE_hybrid"))
        .args(["render", "--backend", "auto", "--size", "32x24", "-o", out.to_str().unwrap()])
        .env_remove("XDG_RUNTIME_DIR")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(r.status.success(), "{err}");
    assert!(!err.lines().any(|l| l.trim_start().starts_with("error")), "{err}");
}

/// Mean squared difference (0..255 per channel, summed over RGB) between horizontally
/// neighbouring pixels of the dumped normal buffer where both show object 0 (the model), and how
/// many pairs there were. Squared, so that a flat mesh's jumps at its edges count for more than
/// the small steady changes of a smooth one.
fn normal_roughness(dump: &Path) -> (f64, usize) {
    let normal = image::open(dump.join("normal.png")).unwrap().to_rgb8();
    let ids = image::open(dump.join("object_id.png")).unwrap().to_luma16();
    let (mut sum, mut pairs) = (0u64, 0usize);
    for y in 0..normal.height() {
        for x in 0..normal.width() - 1 {
            if ids.get_pixel(x, y).0[0] == 1 && ids.get_pixel(x + 1, y).0[0] == 1 {
                let (a, b) = (normal.get_pixel(x, y).0, normal.get_pixel(x + 1, y).0);
                sum += (0..3).map(|c| (a[c].abs_diff(b[c]) as u64).pow(2)).sum::<u64>();
                pairs += 1;
            }
        }
    }
    (sum as f64 / pairs.max(1) as f64, pairs)
}

/// Issue 23: the bunny (an OBJ without normals) is shaded with smooth vertex normals: its normal
/// buffer changes less from pixel to pixel than with `crease_angle = 0` (every face flat, as it
/// rendered before).
#[test]
fn a_model_without_normals_is_shaded_smooth() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let toml = d.join("bunny.toml");
    let (smooth, flat) = (d.join("smooth"), d.join("flat"));
    let model = asset("stanford-bunny/stanford-bunny.obj");
    let size = ["--size", "640x480", "--backend", "cpu", "--quiet"];
    let run = |args: &[&str]| {
        let r = hybrid(&[args, &size[..]].concat());
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    };
    let out = d.join("o.png");
    let out = out.to_str().unwrap();
    run(&["render", &model, "-o", out, "--save-scene", toml.to_str().unwrap(), "--dump", smooth.to_str().unwrap()]);
    let text = std::fs::read_to_string(&toml).unwrap();
    let model_line = text.lines().find(|l| l.starts_with("model = ")).expect("the model's line").to_string();
    std::fs::write(&toml, text.replace(&model_line, &format!("{model_line}\ncrease_angle = 0"))).unwrap();
    run(&["render", toml.to_str().unwrap(), "-o", out, "--dump", flat.to_str().unwrap()]);
    let (s, s_pairs) = normal_roughness(&smooth);
    let (f, f_pairs) = normal_roughness(&flat);
    eprintln!("normal change between neighbouring pixels: smooth {s:.2} ({s_pairs} pairs), flat {f:.2} ({f_pairs} pairs)");
    assert!(s_pairs > 2000 && s_pairs == f_pairs, "the bunny covers {s_pairs} / {f_pairs} pixel pairs");
    assert!(s < 0.6 * f, "smooth normals should change less between pixels: smooth {s:.2}, flat {f:.2}");
}
