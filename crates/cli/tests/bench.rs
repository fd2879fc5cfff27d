//! `hybrid bench` end to end: a tiny bench of the demo scene writes every output with the expected
//! columns and keys and sane numbers; bad input exits with code 2 and writes nothing.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn hybrid(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hybrid")).args(args).output().expect("run hybrid")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn scene(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes").join(name).to_string_lossy().into_owned()
}

fn files_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

const TINY: [&str; 10] = ["--size", "64x36", "--frames", "2", "--path-seconds", "0.2", "--fps", "10", "--flip-every", "1"];

fn tiny_bench(out: &Path, extra: &[&str]) -> Output {
    let demo = scene("demo.toml");
    let mut args = vec!["bench", demo.as_str(), "--quiet", "--out", out.to_str().unwrap()];
    args.extend_from_slice(&TINY);
    args.extend_from_slice(extra);
    hybrid(&args)
}

fn csv(path: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<String> = lines.next().unwrap().split(',').map(String::from).collect();
    let rows: Vec<Vec<String>> = lines.map(|l| l.split(',').map(String::from).collect()).collect();
    for r in &rows {
        assert_eq!(r.len(), header.len(), "row {r:?} of {}", path.display());
    }
    (header, rows)
}

fn col(header: &[String], name: &str) -> usize {
    header.iter().position(|h| h == name).unwrap_or_else(|| panic!("no column `{name}` in {header:?}"))
}

#[test]
fn tiny_bench_of_the_demo_writes_every_output() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bench");
    let o = tiny_bench(&out, &["--sweep-budget"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(files_in(&out), ["bench.json", "frame_times.png", "frames.csv", "sweep.csv", "sweep.png"]);

    // The Markdown tables on stdout.
    let md = String::from_utf8_lossy(&o.stdout);
    for needle in ["Static set (Table 5)", "| FRAME |", "| RAST |", "| HEUR |", "| RAYT |", "| BLEND |", "| RAYT ONLY FRAME |"] {
        assert!(md.contains(needle), "stdout lacks `{needle}`:\n{md}");
    }
    for needle in ["Path set (Table 6)", "with heuristic", "no heuristic", "Mean FLIP vs rt-only", "Selection churn", "Budget sweep"] {
        assert!(md.contains(needle), "stdout lacks `{needle}`:\n{md}");
    }

    // bench.json: every set, the machine, sane numbers.
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("bench.json")).unwrap()).unwrap();
    assert_eq!(json["size"], serde_json::json!([64, 36]));
    assert_eq!(json["machine"]["backend"], "cpu");
    assert!(json["machine"]["cores"].as_u64().unwrap() >= 1);
    assert!(json["machine"].get("cpu_model").is_some());
    assert_eq!(json["machine"]["cpu_isa"], hybrid_cpu::isa::Isa::best().name());
    for mode in ["hybrid", "all", "rt-only"] {
        let st = &json["static"][mode];
        assert_eq!(st["frames"], 2, "static {mode}");
        for stage in ["raster", "heuristic", "trace", "blend", "frame"] {
            let s = &st["stages"][stage];
            let (m, p95) = (s["mean"].as_f64().unwrap(), s["p95"].as_f64().unwrap());
            assert!(m >= 0.0 && p95 >= m * 0.5, "static {mode} {stage}: {s}");
        }
        let frame = st["stages"]["frame"]["mean"].as_f64().unwrap();
        assert!(frame > 0.0 && frame < 60_000.0, "static {mode} frame {frame}");
    }
    // Path: 0.2 s at 10 fps = 2 frames, FLIP on both.
    for mode in ["hybrid", "all"] {
        let p = &json["path"][mode];
        assert_eq!(p["frames"], 2, "path {mode}");
        assert_eq!(p["flip_frames"], 2, "path {mode}");
        let flip = p["mean_flip"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&flip), "path {mode} FLIP {flip}");
    }
    assert!(json["path"]["hybrid"]["mean_churn"].as_f64().is_some());
    // The demo has no budget: hybrid selects everything, like `all`, so it matches rt-only closely.
    assert!(json["path"]["hybrid"]["mean_flip"].as_f64().unwrap() <= 0.05);
    let sweep = json["sweep"].as_array().unwrap();
    assert_eq!(sweep.len(), 20);
    let flip_of = |fallback: &str, policy: &str, fraction: f64| {
        sweep
            .iter()
            .find(|p| p["fallback"] == fallback && p["policy"] == policy && p["fraction"].as_f64() == Some(fraction))
            .unwrap()["mean_flip"]
            .as_f64()
            .unwrap()
    };
    for policy in ["paper", "knapsack"] {
        // A tenth of the cost drops most effects: clearly worse than the full budget.
        assert!(flip_of("none", policy, 0.1) > flip_of("none", policy, 1.0), "{policy}: {sweep:?}");
        // The raster fallbacks bring a small budget's image closer to the reference (issue 18).
        assert!(flip_of("raster", policy, 0.1) < flip_of("none", policy, 0.1), "{policy}: {sweep:?}");
    }

    // frames.csv: static frames of every mode, path frames of hybrid and all, rt-only on FLIP frames.
    let (header, rows) = csv(&out.join("frames.csv"));
    for c in [
        "set",
        "mode",
        "frame",
        "time_s",
        "frame_ms",
        "raster_ms",
        "heuristic_ms",
        "trace_ms",
        "blend_ms",
        "spent",
        "churn",
        "flip",
        "fallback_ms",
        "shadow_map_renders",
        "probe_renders",
        "see_through_renders",
    ] {
        col(&header, c);
    }
    let (set, mode, frame_ms, flip) = (col(&header, "set"), col(&header, "mode"), col(&header, "frame_ms"), col(&header, "flip"));
    let count = |s: &str, m: &str| rows.iter().filter(|r| r[set] == s && r[mode] == m).count();
    assert_eq!((count("static", "hybrid"), count("static", "all"), count("static", "rt-only")), (2, 2, 2));
    assert_eq!((count("path", "hybrid"), count("path", "all"), count("path", "rt-only")), (2, 2, 2));
    for r in &rows {
        let ms: f64 = r[frame_ms].parse().unwrap();
        assert!(ms > 0.0, "{r:?}");
        if r[set] == "path" && r[mode] != "rt-only" {
            let f: f64 = r[flip].parse().unwrap_or_else(|_| panic!("no FLIP in {r:?}"));
            assert!((0.0..=1.0).contains(&f));
        }
    }
    let (sh, srows) = csv(&out.join("sweep.csv"));
    for c in ["policy", "fraction", "budget", "mean_frame_ms", "mean_flip"] {
        col(&sh, c);
    }
    assert_eq!(srows.len(), 20);
    let (fb, fb_ms) = (col(&sh, "fallback"), col(&sh, "mean_fallback_ms"));
    for r in &srows {
        let ms: f64 = r[fb_ms].parse().unwrap();
        // `none` runs no fallback stage: only its timer's own microsecond.
        assert!(if r[fb] == "none" { ms < 0.05 } else { ms >= 0.0 }, "{r:?}");
    }

    for png in ["frame_times.png", "sweep.png"] {
        let img = image::open(out.join(png)).unwrap();
        assert!(img.width() >= 320 && img.height() >= 200, "{png}");
    }
}

#[test]
fn millisecond_budget_is_reported_per_frame() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("b");
    let o = tiny_bench(&out, &["--budget-ms", "0.5", "--modes", "hybrid"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("bench.json")).unwrap()).unwrap();
    let rate = json["path"]["hybrid"]["budget_hit_rate"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&rate));
    assert!(json["static"].get("all").is_none());
    assert_eq!(json["settings"]["budget"]["ms"], 0.5);
    // Paper 2's defaults: unclipped capsule, spheres in the trace stage.
    assert_eq!(json["settings"]["clip_capsule"], false);
    assert_eq!(json["settings"]["sphere_effects"], true);
    assert_eq!(json["settings"]["capsule_visibility"], "auto");
    let (header, rows) = csv(&out.join("frames.csv"));
    let b = col(&header, "budget_ms");
    assert!(rows.iter().filter(|r| r[col(&header, "mode")] == "hybrid").all(|r| r[b] == "0.5"));
}

#[test]
fn capsule_options_are_taken_and_recorded() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bench");
    let o = tiny_bench(&out, &["--modes", "hybrid", "--clip-capsule", "--no-sphere-effects", "--capsule-visibility", "bvh"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("bench.json")).unwrap()).unwrap();
    assert_eq!(json["settings"]["clip_capsule"], true);
    assert_eq!(json["settings"]["sphere_effects"], false);
    assert_eq!(json["settings"]["capsule_visibility"], "bvh");
}

fn assert_bad_input(args: &[&str], out: &Path, needle: &str) {
    let o = hybrid(args);
    assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
    assert!(stderr(&o).contains(needle), "{args:?}: stderr lacks `{needle}`: {}", stderr(&o));
    assert!(!out.exists() || files_in(out).is_empty(), "{args:?} wrote {:?}", files_in(out));
}

#[test]
fn bad_input_exits_with_2_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out: PathBuf = dir.path().join("out");
    let o = out.to_str().unwrap();
    let demo = scene("demo.toml");
    let d = demo.as_str();
    assert_bad_input(&["bench", d, "--out", o, "--modes", "hybrid,fast"], &out, "unknown mode `fast`");
    assert_bad_input(&["bench", d, "--out", o, "--size", "0x36"], &out, "between 1");
    assert_bad_input(&["bench", d, "--out", o, "--frames", "0"], &out, "--frames");
    assert_bad_input(&["bench", d, "--out", o, "--fps", "0"], &out, "--fps");
    assert_bad_input(&["bench", d, "--out", o, "--flip-every", "0"], &out, "--flip-every");
    assert_bad_input(&["bench", d, "--out", o, "--path-seconds", "999"], &out, "only");
    assert_bad_input(&["bench", d, "--out", o, "--path-seconds=-1"], &out, "--path-seconds");
    assert_bad_input(&["bench", d, "--out", o, "--modes", "rt-only", "--sweep-budget"], &out, "--sweep-budget");
    assert_bad_input(&["bench", "/nonexistent/scene.toml", "--out", o], &out, "/nonexistent/scene.toml");
    // Issue 22: sizes and scenes above --max-memory are refused before anything is rendered.
    assert_bad_input(
        &["bench", d, "--out", o, "--backend", "cpu", "--size", "16384x16384", "--max-memory", "8GiB"],
        &out,
        "above the limit",
    );
    assert_bad_input(&["bench", d, "--out", o, "--backend", "cpu", "--size", "64x36", "--max-memory", "65MiB"], &out, "this render needs");
    assert_bad_input(&["bench", d, "--out", o, "--max-memory", "4 parsecs"], &out, "--max-memory");
    // A scene without a camera path, asked for one.
    let no_path = dir.path().join("no-path.toml");
    let text = std::fs::read_to_string(&demo).unwrap();
    let cut = text.find("[[camera_path.keyframe]]").unwrap();
    std::fs::write(&no_path, &text[..cut]).unwrap();
    assert_bad_input(&["bench", no_path.to_str().unwrap(), "--out", o, "--path-seconds", "1"], &out, "no [camera_path]");
    // An output folder that cannot be created (inside a file).
    let blocker = dir.path().join("file");
    std::fs::write(&blocker, b"").unwrap();
    let inside = blocker.join("out");
    let o = hybrid(&["bench", d, "--quiet", "--out", inside.to_str().unwrap(), "--size", "8x8", "--frames", "1"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("cannot create output folder"), "{}", stderr(&o));
    assert!(!out.exists());
}

/// `--out NEW/sub`: a run that fails leaves neither folder behind (the folders a run creates are
/// removed again unless it succeeds, as `render --dump` does); one that succeeds keeps both.
#[test]
fn a_failing_bench_leaves_no_new_folder() {
    let dir = tempfile::tempdir().unwrap();
    let top = dir.path().join("new");
    let nested = top.join("sub");
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "[[object]]\nmodel = \"missing.ply\"\n").unwrap();
    for args in [
        vec!["bench", bad.to_str().unwrap(), "--quiet", "--out", nested.to_str().unwrap(), "--size", "8x8", "--frames", "1"],
        vec!["bench", "/nonexistent.toml", "--quiet", "--out", nested.to_str().unwrap()],
    ] {
        let o = hybrid(&args);
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        assert!(!top.exists(), "{args:?} left {}", top.display());
    }
    let o = tiny_bench(&nested, &["--modes", "raster"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(nested.join("bench.json").is_file());
}

/// `--threads` sets the pool before the scene is loaded: loading a glTF scene uses rayon, and
/// setting the pool afterwards failed with "The global thread pool has already been initialized"
/// (exit 1) on the pavilion and both Sponza scenes.
#[test]
fn threads_apply_to_scenes_whose_loading_uses_rayon() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bench");
    let pavilion = scene("pavilion.toml");
    let args = [
        "bench",
        pavilion.as_str(),
        "--quiet",
        "--backend",
        "cpu",
        "--out",
        out.to_str().unwrap(),
        "--size",
        "16x9",
        "--frames",
        "1",
        "--threads",
        "1",
        "--modes",
        "raster",
        "--path-seconds",
        "0.1",
        "--fps",
        "10",
    ];
    let o = hybrid(&args);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("bench.json")).unwrap()).unwrap();
    assert_eq!(json["machine"]["threads"], 1, "{}", json["machine"]);
}
