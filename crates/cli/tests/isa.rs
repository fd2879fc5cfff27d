//! The CPU kernels' instruction-set paths (`hybrid_cpu::isa`, forced with `HYBRID_ISA`) give the
//! same frames bit for bit: every scene of `scenes/` in the hybrid and rt-only modes (and the
//! tree's capsule both ways) is rendered with every path this machine has, and the PNG and every
//! `--dump` file (G-buffer, ids, masks, packed capsule frame, EXR depths) must equal the
//! baseline path's byte for byte. Each render also reports the path it ran (`cpu_isa`).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use hybrid_cpu::isa::Isa;

fn hybrid(isa: Option<&str>, args: &[&str]) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_hybrid"));
    c.args(args);
    match isa {
        Some(isa) => c.env("HYBRID_ISA", isa),
        None => c.env_remove("HYBRID_ISA"),
    };
    c.output().expect("run hybrid")
}

fn scenes() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes")
}

/// Every file under `dir` (name, bytes), sorted by name.
fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut v: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let e = e.unwrap();
            (e.file_name().to_string_lossy().into_owned(), std::fs::read(e.path()).unwrap())
        })
        .collect();
    v.sort();
    v
}

/// Renders `scene` at 160×90 with `extra` flags on `isa`: the output files (image, report
/// without its timings, dump) and the report's `cpu_isa`.
fn render(isa: &str, scene: &Path, extra: &[&str]) -> (Vec<(String, Vec<u8>)>, String) {
    let dir = tempfile::tempdir().unwrap();
    let (out, report, dump) = (dir.path().join("frame.png"), dir.path().join("report.json"), dir.path().join("dump"));
    let mut args = vec!["render", scene.to_str().unwrap(), "--backend", "cpu", "--size", "160x90", "--quiet", "--threads", "2"];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["-o", out.to_str().unwrap(), "--report", report.to_str().unwrap(), "--dump", dump.to_str().unwrap()]);
    let o = hybrid(Some(isa), &args);
    assert!(o.status.success(), "{isa} {}: {}", scene.display(), String::from_utf8_lossy(&o.stderr));
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    let mut got = files(&dump);
    got.push(("frame.png".into(), std::fs::read(&out).unwrap()));
    // The report's ray counts and heuristic choices must agree too; its timings cannot.
    let mut json_same = json.clone();
    let map = json_same.as_object_mut().unwrap();
    for key in ["timings_ms", "cpu_isa", "capsule"] {
        map.remove(key);
    }
    if let Some(h) = map.get_mut("heuristic").and_then(|h| h.as_object_mut()) {
        h.retain(|k, _| !k.contains("ms"));
    }
    got.push(("report (no timings)".into(), serde_json::to_vec(&json_same).unwrap()));
    (got, json["cpu_isa"].as_str().unwrap_or_default().to_string())
}

#[test]
fn every_isa_path_renders_every_scene_bit_for_bit() {
    let paths = Isa::available();
    eprintln!("paths on this machine: {:?}", paths.iter().map(|i| i.name()).collect::<Vec<_>>());
    let mut cases: Vec<(PathBuf, Vec<&str>)> = Vec::new();
    let mut names: Vec<PathBuf> = std::fs::read_dir(scenes()).unwrap().map(|e| e.unwrap().path()).collect();
    names.sort();
    for scene in names.into_iter().filter(|p| p.extension().is_some_and(|e| e == "toml")) {
        for mode in ["hybrid", "rt-only"] {
            cases.push((scene.clone(), vec!["--mode", mode]));
        }
        if scene.file_stem().is_some_and(|s| s == "tree-merge") {
            // The capsule's two primary-visibility paths (at 160×90 `auto` picks the BVH's).
            cases.push((scene.clone(), vec!["--mode", "hybrid", "--capsule-visibility", "projected"]));
            cases.push((scene.clone(), vec!["--mode", "hybrid", "--clip-capsule", "--capsule-visibility", "projected"]));
        }
    }
    assert!(cases.len() >= 12, "expected the six scenes of scenes/");
    for (scene, extra) in &cases {
        let (base, base_isa) = render(Isa::Baseline.name(), scene, extra);
        assert_eq!(base_isa, Isa::Baseline.name());
        for isa in &paths[1..] {
            let (got, got_isa) = render(isa.name(), scene, extra);
            assert_eq!(got_isa, isa.name(), "the report names the path");
            assert_eq!(got.len(), base.len());
            for ((name, a), (name_b, b)) in base.iter().zip(&got) {
                assert_eq!(name, name_b);
                assert!(a == b, "{} {extra:?}: `{name}` differs between {} and {}", scene.display(), Isa::Baseline.name(), isa.name());
            }
        }
    }
}

#[test]
fn the_default_path_is_the_best_and_bad_values_exit_2() {
    let dir = tempfile::tempdir().unwrap();
    let (out, report) = (dir.path().join("f.png"), dir.path().join("r.json"));
    let args = ["render", "--backend", "cpu", "--size", "16x9", "-o", out.to_str().unwrap(), "--report", report.to_str().unwrap()];
    let o = hybrid(None, &args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    assert_eq!(json["cpu_isa"], Isa::best().name());
    // The one-line summary names it too.
    assert!(String::from_utf8_lossy(&o.stderr).contains(&format!("[cpu kernels: {}]", Isa::best().name())));

    std::fs::remove_file(&out).unwrap();
    let o = hybrid(Some("avx9"), &args);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("HYBRID_ISA=avx9") && err.contains(Isa::Baseline.name()), "{err}");
    assert!(!out.exists(), "nothing is written on bad input");
}
