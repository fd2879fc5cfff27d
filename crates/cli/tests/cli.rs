//! The `hybrid` binary end to end: exit codes, error messages, and that bad input never leaves
//! an output file behind.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn hybrid(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hybrid")).args(args).output().expect("run hybrid")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn scenes() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes")
}

fn files_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

#[test]
fn renders_the_demo_scene_with_report_and_dump() {
    render_demo_with_report_and_dump("cpu");
}

/// `--backend gpu` on whatever adapter wgpu finds (lavapipe in CI): the same outputs, file names
/// and report keys as the CPU backend, plus `gpu_timings_ms` and the adapter.
#[test]
fn gpu_backend_renders_the_demo_scene_with_report_and_dump() {
    let json = render_demo_with_report_and_dump("gpu");
    for key in ["capsule", "raster", "lighting", "heuristic", "trace", "blend", "frame"] {
        assert!(json["gpu_timings_ms"][key].is_number(), "gpu_timings_ms lacks `{key}`: {json}");
    }
    assert!(json["gpu_timings_ms"]["frame"].as_f64().unwrap() > 0.0, "{json}");
    assert!(json["adapter"]["name"].as_str().is_some_and(|n| !n.is_empty()), "{json}");
    assert!(json["adapter"]["backend"].is_string(), "{json}");
}

/// `--backend gpu --mode raster`: the raster fallbacks (issue 18) on the GPU: the fallback
/// buffers and each light's shadow maps in the dump, and the report's fallback keys.
#[test]
fn gpu_backend_dumps_the_raster_fallbacks() {
    let dir = tempfile::tempdir().unwrap();
    let (out, report, dump) = (dir.path().join("demo.png"), dir.path().join("report.json"), dir.path().join("dump"));
    let o = hybrid(&[
        "render",
        "--backend",
        "gpu",
        "--mode",
        "raster",
        "--size",
        "64x36",
        "--quiet",
        "-o",
        out.to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
        "--dump",
        dump.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let names = files_in(&dump);
    // The demo's three shadow-casting lights: directional (0), point (1), spot (2).
    for f in [
        "shadow_fallback.exr",
        "reflection_fallback.exr",
        "refraction_fallback.exr",
        "shadow_map_0.exr",
        "shadow_map_1.exr",
        "shadow_map_2.exr",
    ] {
        assert!(names.contains(&f.to_string()), "dump lacks {f}: {names:?}");
    }
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    assert_eq!(json["fallback"], "raster", "{json}");
    // Three cascades, six cube faces, one spot map; the demo's mirror and glass objects' probes.
    assert_eq!(json["fallback_renders"]["shadow_maps"], 10, "{json}");
    assert!(json["fallback_renders"]["probes"].as_u64().is_some_and(|p| p > 0), "{json}");
    let effects = json["effects"].as_array().expect("effects");
    assert!(!effects.is_empty() && effects.iter().all(|e| e["shadow"] == "raster"), "{json}");
    assert!(json["gpu_timings_ms"]["fallback"].as_f64().is_some_and(|t| t > 0.0), "{json}");
}

/// Renders the demo at 64×36 on `backend` with `--report` and `--dump`; checks the files and
/// returns the report.
fn render_demo_with_report_and_dump(backend: &str) -> serde_json::Value {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo.png");
    let report = dir.path().join("report.json");
    let dump = dir.path().join("dump");
    let o = hybrid(&[
        "render",
        "--backend",
        backend,
        "--size",
        "64x36",
        "--quiet",
        "-o",
        out.to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
        "--dump",
        dump.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let img = image::open(&out).unwrap();
    assert_eq!((img.width(), img.height()), (64, 36));
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    for key in ["backend", "size", "mode", "timings_ms", "rays", "triangles", "objects", "heuristic"] {
        assert!(json.get(key).is_some(), "report lacks `{key}`");
    }
    for key in ["raster", "heuristic", "trace", "blend", "frame"] {
        assert!(json["timings_ms"][key].is_number(), "timings_ms lacks `{key}`");
    }
    for key in ["primary", "shadow", "reflection", "refraction"] {
        assert!(json["rays"][key].is_number(), "rays lacks `{key}`");
    }
    assert_eq!(json["backend"], backend);
    assert_eq!(json["size"], serde_json::json!([64, 36]));
    let names = files_in(&dump);
    for b in [
        "position",
        "normal",
        "emission",
        "ambient",
        "diffuse",
        "specular",
        "optical",
        "mask",
        "depth",
        "lighting",
        "shadow",
        "reflection",
        "refraction",
        "final",
        "object_id",
    ] {
        assert!(names.contains(&format!("{b}.png")), "dump lacks {b}.png: {names:?}");
    }
    for b in ["position", "normal", "depth", "lighting", "shadow", "reflection", "refraction", "mask"] {
        assert!(names.contains(&format!("{b}.exr")), "dump lacks {b}.exr: {names:?}");
    }
    // object_id.png is 16-bit grey holding id + 1.
    let ids = image::open(dump.join("object_id.png")).unwrap();
    assert!(matches!(ids, image::DynamicImage::ImageLuma16(_)), "object_id.png must be 16-bit grey");
    // The final dump equals the output image.
    assert_eq!(image::open(dump.join("final.png")).unwrap().to_rgba8(), img.to_rgba8());
    // No temporary files are left behind.
    assert!(files_in(dir.path()).iter().all(|n| !n.contains("partial")), "{:?}", files_in(dir.path()));
    json
}

/// Runs a render that must fail with exit code 2, a message containing every `needle`, and no
/// output image.
fn assert_bad_input(extra: &[&str], needles: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.png");
    let mut args = vec!["render", "--quiet", "--size", "32x18", "-o", out.to_str().unwrap()];
    args.extend_from_slice(extra);
    let o = hybrid(&args);
    assert_eq!(o.status.code(), Some(2), "args {args:?}: {}", stderr(&o));
    let err = stderr(&o);
    for n in needles {
        assert!(err.contains(n), "message lacks `{n}`: {err}");
    }
    assert!(!err.contains("panicked"), "{err}");
    assert!(files_in(dir.path()).is_empty(), "bad input left files: {:?}", files_in(dir.path()));
}

#[test]
fn bad_scene_files_exit_2_naming_the_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "[camera]\nfov = 200\n").unwrap();
    assert_bad_input(&[bad.to_str().unwrap()], &["bad.toml", ":2:", "fov"]);
    std::fs::write(&bad, "[camera\n").unwrap();
    assert_bad_input(&[bad.to_str().unwrap()], &["bad.toml", ":1:"]);
    assert_bad_input(&["/nonexistent/scene.toml"], &["/nonexistent/scene.toml"]);
}

#[test]
fn broken_model_referenced_by_a_scene_exits_2_naming_the_model() {
    let dir = tempfile::tempdir().unwrap();
    let assets = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/assets/broken-models/ply/truncated_binary_dragon_res4.ply");
    let scene = dir.path().join("s.toml");
    std::fs::write(&scene, format!("[[object]]\nmodel = {:?}\n", assets.to_str().unwrap())).unwrap();
    assert_bad_input(&[scene.to_str().unwrap()], &["truncated_binary_dragon_res4.ply"]);
}

#[test]
fn bad_flags_exit_2() {
    assert_bad_input(&["--size", "0x10"], &["size"]);
    assert_bad_input(&["--mode", "fastest"], &["mode"]);
    assert_bad_input(&["--time", "nan"], &["--time"]);
    assert_bad_input(&["--budget=-5"], &["--budget"]);
}

#[test]
fn time_without_camera_path_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("nopath.toml");
    std::fs::write(&scene, "[[material]]\nname = \"m\"\n[[object]]\nprimitive = \"cube\"\nmaterial = \"m\"\n").unwrap();
    assert_bad_input(&[scene.to_str().unwrap(), "--time", "1.0"], &["camera_path"]);
}

/// `--backend gpu` without a usable adapter (here: none matches HYBRID_ADAPTER) is a clear
/// error with exit code 2 and no output file.
#[test]
fn gpu_backend_without_an_adapter_exits_2() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.png");
    let o = Command::new(env!("CARGO_BIN_EXE_hybrid"))
        .args(["render", "--quiet", "--backend", "gpu", "--size", "32x18", "-o", out.to_str().unwrap()])
        .env("HYBRID_ADAPTER", "no-such-adapter-anywhere")
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--backend gpu") && stderr(&o).contains("no-such-adapter-anywhere"), "{}", stderr(&o));
    assert!(files_in(dir.path()).is_empty());
}

/// `--backend auto` (the default) says which backend it chose.
#[test]
fn auto_backend_says_which_it_chose() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.png");
    let o = hybrid(&["render", "--size", "32x18", "-o", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("backend: cpu") || stderr(&o).contains("backend: gpu"), "{}", stderr(&o));
}

#[test]
fn unwritable_output_locations_fail_before_rendering() {
    let o = hybrid(&["render", "--quiet", "--size", "8x8", "-o", "/nonexistent-dir/out.png"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("/nonexistent-dir"), "{}", stderr(&o));
    let dir = tempfile::tempdir().unwrap();
    let blocker = dir.path().join("file");
    std::fs::write(&blocker, b"").unwrap();
    let dump = blocker.join("dump"); // a folder inside a file cannot be created
    let out = dir.path().join("o.png");
    let o = hybrid(&["render", "--quiet", "--size", "8x8", "-o", out.to_str().unwrap(), "--dump", dump.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(!out.exists());
}

#[test]
fn inspect_prints_table_4_json_keys() {
    let o = hybrid(&["inspect", "--json", scenes().join("demo.toml").to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let json: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    for key in ["vertices", "triangles", "objects", "reflective_objects", "refractive_objects", "lights", "points", "bounds"] {
        assert!(json.get(key).is_some(), "inspect --json lacks `{key}`");
    }
    for key in ["directional", "point", "spot"] {
        assert_eq!(json["lights"][key], 1, "the demo has one {key} light");
    }
    assert!(json["bounds"]["min"].is_array() && json["bounds"]["max"].is_array());
    let plain = hybrid(&["inspect", scenes().join("demo.toml").to_str().unwrap()]);
    assert!(plain.status.success());
}

/// `hybrid` with `WGPU_BACKEND=gl`: only OpenGL adapters are seen (llvmpipe's GL in CI, from
/// `libegl1` + `libgl1-mesa-dri`).
fn hybrid_on_gl(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hybrid")).args(args).env("WGPU_BACKEND", "gl").output().expect("run hybrid")
}

/// Issue 23: an OpenGL adapter cannot hold the frame's targets (llvmpipe's GL cannot render to
/// `Rgba32Float`): `--backend gpu` refuses it up front with exit 2, naming the adapter and what it
/// lacks (it used to fail inside wgpu with a validation error), and writes nothing.
/// Fails (does not skip) when there is no GL adapter at all: the refusal is what is tested.
#[test]
fn gpu_backend_on_an_opengl_adapter_is_refused_with_exit_2() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.png");
    let o = hybrid_on_gl(&["render", "--quiet", "--backend", "gpu", "--size", "32x18", "-o", out.to_str().unwrap()]);
    let err = stderr(&o);
    assert!(
        !err.contains("no GPU adapter found"),
        "no OpenGL adapter: install Mesa's GL (`apt-get install libegl1 libgl1-mesa-dri`) to run this test:\n{err}"
    );
    assert_eq!(o.status.code(), Some(2), "{err}");
    let line = err.lines().find(|l| l.starts_with("error: --backend gpu:")).unwrap_or_else(|| panic!("one error line: {err}"));
    assert!(line.contains("(Gl)") && line.contains("cannot run this backend") && line.contains("texture formats"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(files_in(dir.path()).is_empty());
}

/// With only an OpenGL adapter, `--backend auto` renders on the CPU, says so, and prints no
/// `error:` line.
#[test]
fn auto_backend_on_opengl_falls_back_to_the_cpu() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.png");
    let o = hybrid_on_gl(&["render", "--backend", "auto", "--size", "32x18", "-o", out.to_str().unwrap()]);
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("backend: cpu (auto:"), "{err}");
    assert!(!err.lines().any(|l| l.trim_start().starts_with("error")), "{err}");
    assert!(out.exists());
}

/// `--quiet` prints nothing on success (as its help says); without it the result line names the
/// stage times, with stage 1 called `primary rays` in rt-only (there is no raster there).
#[test]
fn quiet_prints_nothing_and_rt_only_has_no_raster_time() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.png");
    let o = out.to_str().unwrap();
    let q = hybrid(&["render", "--quiet", "--backend", "cpu", "--size", "32x18", "-o", o]);
    assert!(q.status.success() && q.stderr.is_empty() && q.stdout.is_empty(), "{}", stderr(&q));
    let help = String::from_utf8_lossy(&hybrid(&["render", "--help"]).stdout).into_owned();
    assert!(help.contains("no result line"), "{help}");

    let r = hybrid(&["render", "--backend", "cpu", "--size", "32x18", "--mode", "rt-only", "-o", o]);
    let err = stderr(&r);
    assert!(r.status.success(), "{err}");
    let line = err.lines().find(|l| l.contains(" rt-only in ")).unwrap_or_else(|| panic!("a result line: {err}"));
    assert!(line.contains("(primary rays ") && !line.contains("raster"), "{line}");
    let h = hybrid(&["render", "--backend", "cpu", "--size", "32x18", "-o", o]);
    let err = stderr(&h);
    assert!(err.lines().any(|l| l.contains(" hybrid in ") && l.contains("(raster ")), "{err}");
}

/// `hybrid bench --help` explains its terms in plain words.
#[test]
fn bench_help_explains_its_terms() {
    let o = hybrid(&["bench", "--help"]);
    let help = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success());
    for term in ["Table 4", "Table 5", "Table 6", "static set", "path set", "capsule", "FLIP", "rt-only", "primary rays"] {
        assert!(help.contains(term), "`bench --help` does not explain `{term}`:\n{help}");
    }
    // The one-line summary in `hybrid --help` stays one line.
    let top = String::from_utf8_lossy(&hybrid(&["--help"]).stdout).into_owned();
    let bench = top.lines().find(|l| l.trim_start().starts_with("bench")).expect("bench in hybrid --help");
    assert!(bench.contains("Tables 5 and 6") && !top.contains("Terms:"), "{top}");
}

/// [`assert_bad_input`] with `args` as they are (no `--size` added).
fn assert_bad_render(args: &[&str], needles: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.png");
    let mut all = vec!["render", "--quiet", "-o", out.to_str().unwrap()];
    all.extend_from_slice(args);
    let o = hybrid(&all);
    assert_eq!(o.status.code(), Some(2), "args {all:?}: {}", stderr(&o));
    let err = stderr(&o);
    for n in needles {
        assert!(err.contains(n), "message lacks `{n}`: {err}");
    }
    assert!(files_in(dir.path()).is_empty(), "bad input left files: {:?}", files_in(dir.path()));
}

/// Issue 22: a render estimated above `--max-memory` is refused before anything is allocated,
/// rendered or written (issue 22: very large `--size` values on the CPU aborted with exit 134).
#[test]
fn renders_that_do_not_fit_the_memory_limit_exit_2_before_rendering() {
    // 16384² × 160 bytes per pixel is 40 GiB for the frame alone.
    let needles = ["frame alone needs about 40.06 GiB", "above the limit of 8.00 GiB (--max-memory)", "--max-memory 41GiB"];
    assert_bad_render(&["--backend", "cpu", "--size", "16384x16384", "--max-memory", "8GiB"], &needles);
    // Also with a dump folder to create: it is not left behind.
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("dump");
    // (+ 32 bytes per pixel for writing the dump.)
    let needles = ["frame alone needs about 48.06 GiB", "above the limit of 8.00 GiB (--max-memory)"];
    assert_bad_render(&["--backend", "cpu", "--size", "16384x16384", "--max-memory", "8GiB", "--dump", dump.to_str().unwrap()], &needles);
    assert!(!dump.exists(), "the dump folder was left behind");
    // The whole estimate (scene and frame) against a limit the frame alone fits.
    assert_bad_render(
        &["--backend", "cpu", "--size", "64x36", "--max-memory", "65MiB"],
        &["this render needs about", "scene", "--max-memory"],
    );
    // A scene whose data passes the limit is refused while it is parsed, at the object's line.
    let scene = dir.path().join("spheres.toml");
    // (Each 2048 × 2048 sphere is 384 MiB: the first fits, the second does not.)
    let sphere = "[[object]]\nprimitive = \"sphere\"\nmaterial = \"m\"\nslices = 2048\nstacks = 2048\n";
    std::fs::write(&scene, format!("[[material]]\nname = \"m\"\n\n{sphere}\n{sphere}")).unwrap();
    assert_bad_render(
        &[scene.to_str().unwrap(), "--backend", "cpu", "--max-memory", "512MiB"],
        &["spheres.toml:11:", "sphere `sphere-2`", "--max-memory"],
    );
    // Bad values name the flag.
    assert_bad_render(&["--max-memory", "lots"], &["--max-memory", "lots"]);
    assert_bad_render(&["--max-memory", "0"], &["--max-memory"]);
    // A limit that fits renders.
    let out = dir.path().join("ok.png");
    let o = hybrid(&["render", "--quiet", "--backend", "cpu", "--size", "64x36", "--max-memory", "1GiB", "-o", out.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(out.is_file());
}

/// Issue 22: a scene at every documented maximum at once — `max_depth` 64, 8 directional, 32
/// point and 32 spot lights, glass in a mirror box — renders (the ray budget bounds each pixel's
/// work), and the same scene with a sphere at the maximum tessellation is refused up front under
/// a memory limit it does not fit, naming the limit.
#[test]
fn a_scene_at_the_documented_maxima_renders_or_is_refused_up_front() {
    let dir = tempfile::tempdir().unwrap();
    let mut text = String::from(
        "[camera]\nposition = [0.0, 0.0, 1.5]\ntarget = [0.0, 0.0, 0.0]\n\n[trace]\nmax_depth = 64\nimportance_cutoff = 0.0\n\n\
         [[material]]\nname = \"mirror\"\nreflectivity = 0.98\n\n\
         [[material]]\nname = \"glass\"\nreflectivity = 0.9\nopacity = 0.02\nior = 1.5\n\n\
         [[object]]\nprimitive = \"cube\"\nmaterial = \"mirror\"\nscale = [-4.0, -4.0, -4.0]\n\n",
    );
    for i in 0..8 {
        text += &format!("[[light]]\ntype = \"directional\"\ndirection = [{}, -1.0, -0.5]\nintensity = 0.1\n\n", i as f32 * 0.1 - 0.4);
    }
    for i in 0..32 {
        let x = (i % 8) as f32 * 0.4 - 1.4;
        text += &format!("[[light]]\ntype = \"point\"\nposition = [{x}, 1.5, {}]\nintensity = 0.05\n\n", (i / 8) as f32 * 0.5 - 1.0);
        text += &format!("[[light]]\ntype = \"spot\"\nposition = [{x}, -1.5, 1.0]\ndirection = [0.0, 1.0, -0.5]\nintensity = 0.05\n\n");
    }
    let sphere = |seg: u32| format!("[[object]]\nprimitive = \"sphere\"\nmaterial = \"glass\"\nslices = {seg}\nstacks = {seg}\n");
    let scene = dir.path().join("maxima.toml");
    std::fs::write(&scene, format!("{text}{}", sphere(32))).unwrap();
    let out = dir.path().join("maxima.png");
    let o = hybrid(&[
        "render",
        scene.to_str().unwrap(),
        "--quiet",
        "--backend",
        "cpu",
        "--size",
        "32x18",
        "--mode",
        "rt-only",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(out.is_file());
    // At the maximum tessellation (4096 × 4096: 33.5M triangles, 1.5 GiB of scene data).
    std::fs::write(&scene, format!("{text}{}", sphere(4096))).unwrap();
    assert_bad_render(&[scene.to_str().unwrap(), "--backend", "cpu", "--max-memory", "1GiB"], &["maxima.toml", "sphere-2", "--max-memory"]);
}

/// Issue 19: `--rt auto` (the default) says which path traced and why, and reports it. On
/// lavapipe, a CPU adapter, auto stays on the software BVH although Mesa 25 offers ray queries
/// (they run on the same CPU, and slower); `--rt hw` takes them and reports the acceleration
/// structures' build time; with the feature hidden (`HYBRID_RAY_QUERY=off`) auto says it is missing.
#[test]
fn rt_auto_says_and_reports_which_path_traced() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        ("auto", false, "sw", "(auto: a CPU adapter"),
        ("hw", false, "hw", "ray tracing: hardware"),
        ("auto", true, "sw", "(auto: HYBRID_RAY_QUERY=off hides"),
    ];
    for (i, (rt, hide, path, said)) in cases.into_iter().enumerate() {
        let out = dir.path().join(format!("{i}.png"));
        let report = dir.path().join(format!("{i}.json"));
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_hybrid"));
        cmd.args([
            "render",
            "--backend",
            "gpu",
            "--rt",
            rt,
            "--size",
            "64x36",
            "-o",
            out.to_str().unwrap(),
            "--report",
            report.to_str().unwrap(),
        ]);
        if hide {
            cmd.env("HYBRID_RAY_QUERY", "off");
        }
        let o = cmd.output().expect("run hybrid");
        assert!(o.status.success(), "{}", stderr(&o));
        assert!(stderr(&o).contains(said), "--rt {rt}, hidden {hide}: {}", stderr(&o));
        let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
        assert_eq!(json["adapter"]["ray_tracing"], path, "{json}");
        let build = &json["gpu_timings_ms"]["build_as"];
        assert_eq!(build.as_f64().is_some_and(|ms| ms > 0.0), path == "hw", "build_as: {json}");
    }
}

/// Issue 19: `--rt hw` on an adapter without ray queries (hidden with `HYBRID_RAY_QUERY=off`), or
/// on the CPU backend, is a clear error naming the flag (exit 2) and writes nothing.
#[test]
fn rt_hw_without_ray_queries_exits_2() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.png");
    let o = Command::new(env!("CARGO_BIN_EXE_hybrid"))
        .args(["render", "--quiet", "--backend", "gpu", "--rt", "hw", "--size", "32x18", "-o", out.to_str().unwrap()])
        .env("HYBRID_RAY_QUERY", "off")
        .output()
        .expect("run hybrid");
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--rt hw") && stderr(&o).contains("no hardware ray tracing"), "{}", stderr(&o));
    assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));
    let o = hybrid(&["render", "--quiet", "--backend", "cpu", "--rt", "hw", "--size", "32x18", "-o", out.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--rt hw: the CPU backend"), "{}", stderr(&o));
    let o = hybrid(&["render", "--quiet", "--rt", "rtx", "--size", "32x18", "-o", out.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(files_in(dir.path()).is_empty(), "{:?}", files_in(dir.path()));
}

/// Issue 22: a scene the GPU adapter cannot hold (a sphere tessellated into ~2M vertices, more
/// than one storage binding of lavapipe's 128 MiB) is a clear error naming the scene and the
/// adapter, exit 2, nothing written (it panicked with "Mismatched pop_error_scope" before).
#[test]
fn a_scene_too_large_for_the_gpu_adapter_exits_2() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("huge-sphere.toml");
    std::fs::write(
        &scene,
        "[camera]\nposition = [0.0, 0.0, 3.0]\ntarget = [0.0, 0.0, 0.0]\n\n[[material]]\nname = \"m\"\n\n\
         [[light]]\ntype = \"directional\"\ndirection = [0.0, -1.0, -0.5]\n\n\
         [[object]]\nprimitive = \"sphere\"\nmaterial = \"m\"\nslices = 1500\nstacks = 1500\n",
    )
    .unwrap();
    assert_bad_render(
        &[scene.to_str().unwrap(), "--backend", "gpu", "--size", "32x18"],
        &["huge-sphere.toml", "does not fit the GPU adapter", "scene.vertices needs", "the device binds at most"],
    );
}

/// Issue 22: a texture larger than the GPU adapter can bind (8192² RGBA8 is 256 MiB, lavapipe
/// binds 128 MiB) is rejected naming the texture and its size (not downscaled, so the GPU image
/// never differs from the CPU backend's); the CPU backend renders the same scene.
#[test]
fn a_texture_too_large_for_the_gpu_adapter_is_named() {
    let dir = tempfile::tempdir().unwrap();
    image::RgbaImage::from_pixel(8192, 8192, image::Rgba([200, 120, 40, 255])).save(dir.path().join("huge.png")).unwrap();
    let scene = dir.path().join("huge-texture.toml");
    std::fs::write(
        &scene,
        "[camera]\nposition = [0.0, 0.0, 3.0]\ntarget = [0.0, 0.0, 0.0]\n\n\
         [[material]]\nname = \"m\"\ndiffuse_map = \"huge.png\"\n\n\
         [[light]]\ntype = \"directional\"\ndirection = [0.0, -1.0, -0.5]\n\n\
         [[object]]\nprimitive = \"cube\"\nmaterial = \"m\"\n",
    )
    .unwrap();
    assert_bad_render(
        &[scene.to_str().unwrap(), "--backend", "gpu", "--size", "32x18"],
        &["huge-texture.toml", "does not fit the GPU adapter", "texture `huge.png` (8192x8192, mip level 0: 256 MiB)"],
    );
    let out = dir.path().join("cpu.png");
    let o = hybrid(&["render", scene.to_str().unwrap(), "--quiet", "--backend", "cpu", "--size", "32x18", "-o", out.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
}

/// `--fallback raster` (the default) reports each object's effect paths and dumps the fallback
/// buffers and the shadow maps; `--fallback none` has none of them; a bad value is exit 2.
#[test]
fn fallback_flag_reports_and_dumps() {
    let dir = tempfile::tempdir().unwrap();
    for fallback in ["raster", "none"] {
        let out = dir.path().join(format!("{fallback}.png"));
        let report = dir.path().join(format!("{fallback}.json"));
        let dump = dir.path().join(format!("dump-{fallback}"));
        let o = hybrid(&[
            "render",
            "--backend",
            "cpu",
            "--size",
            "64x36",
            "--mode",
            "raster",
            "--fallback",
            fallback,
            "--quiet",
            "-o",
            out.to_str().unwrap(),
            "--report",
            report.to_str().unwrap(),
            "--dump",
            dump.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
        assert_eq!(json["fallback"], fallback, "{json}");
        assert!(json["timings_ms"]["fallback"].is_number(), "{json}");
        let effects = json["effects"].as_array().unwrap();
        assert!(!effects.is_empty(), "{json}");
        for e in effects {
            for key in ["id", "name", "shadow", "reflection", "refraction"] {
                assert!(e.get(key).is_some(), "effects entry lacks `{key}`: {e}");
            }
            // Raster mode traces nothing: every effect is the fallback's or none.
            for key in ["shadow", "reflection", "refraction"] {
                assert!(e[key] == "raster" || e[key] == "none", "{e}");
            }
        }
        let names = files_in(&dump);
        let has = |n: &str| names.contains(&n.to_string());
        // The demo has a sun, a point light and a spot light casting shadows.
        let maps = ["shadow_map_0.exr", "shadow_map_1.exr", "shadow_map_2.exr"];
        let buffers = ["shadow_fallback.png", "reflection_fallback.png", "refraction_fallback.png", "shadow_fallback.exr"];
        if fallback == "raster" {
            assert!(effects.iter().any(|e| e["shadow"] == "raster"), "{json}");
            // Three cascades, six cube faces, one spot map.
            assert_eq!(json["fallback_renders"]["shadow_maps"].as_u64().unwrap(), 3 + 6 + 1, "{json}");
            for n in buffers.iter().chain(&maps) {
                assert!(has(n), "dump lacks {n}: {names:?}");
            }
        } else {
            assert!(effects.iter().all(|e| e["shadow"] == "none"), "{json}");
            for n in buffers.iter().chain(&maps) {
                assert!(!has(n), "--fallback none dumped {n}");
            }
        }
    }
    let o = hybrid(&["render", "--fallback", "rays", "-o", dir.path().join("x.png").to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--fallback"), "{}", stderr(&o));
}
