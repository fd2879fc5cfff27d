//! The CPU kernels' instruction-set paths (`hybrid_cpu::isa`, forced with `HYBRID_ISA`) give the
//! same frames: every scene of `scenes/` in the hybrid and rt-only modes (and the tree's capsule
//! both ways) is rendered with every path this machine has, and the PNG and every `--dump` file
//! (G-buffer, ids, masks, packed capsule frame, EXR depths) must equal the baseline path's byte
//! for byte, with one stated tolerance: the AVX2 and AVX-512 paths' ray streams test boxes with
//! fused multiply–subtracts (`hybrid_cpu::bvh`, `stream.rs`), so a ray that grazes a box
//! boundary may find another hit there, and the images the trace stage's rays make (and the
//! frame) may differ in at most [`GRAZING_PIXELS_PER_MILLE`] per mille of their pixels, the
//! report's ray counts by as many rays. (None do in these renders today; pavilion's rt-only
//! frame at 1280×720 has one such pixel.) Each render also reports the path it ran (`cpu_isa`).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use hybrid_cpu::isa::Isa;

/// The outputs that secondary rays make: where a ray grazes a box boundary, their pixels may
/// differ between paths (see the module notes); every other output must be equal byte for byte.
const TRACED: [&str; 10] = [
    "frame.png",
    "final.png",
    "lighting.png",
    "lighting.exr",
    "shadow.png",
    "shadow.exr",
    "reflection.png",
    "reflection.exr",
    "refraction.png",
    "refraction.exr",
];

/// Most pixels of a traced image (per mille, at least one) that may differ between paths.
const GRAZING_PIXELS_PER_MILLE: usize = 1;

/// A decoded image's pixels, each as the bits of all its channels.
fn pixels(name: &str, bytes: &[u8]) -> Vec<Vec<u32>> {
    if name.ends_with(".png") {
        let img = image::load_from_memory(bytes).unwrap_or_else(|e| panic!("{name}: {e}")).to_rgba16();
        img.pixels().map(|p| p.0.iter().map(|&c| u32::from(c)).collect()).collect()
    } else {
        use exr::prelude::*;
        let image = read()
            .no_deep_data()
            .largest_resolution_level()
            .all_channels()
            .first_valid_layer()
            .all_attributes()
            .from_buffered(std::io::Cursor::new(bytes))
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let channels: Vec<Vec<f32>> = image.layer_data.channel_data.list.iter().map(|c| c.sample_data.values_as_f32().collect()).collect();
        (0..channels[0].len()).map(|i| channels.iter().map(|c| c[i].to_bits()).collect()).collect()
    }
}

/// How many pixels of the traced image `name` differ between `a` and `b` (same size).
fn differing_pixels(name: &str, a: &[u8], b: &[u8]) -> (usize, usize) {
    let (a, b) = (pixels(name, a), pixels(name, b));
    assert_eq!(a.len(), b.len(), "{name}: sizes differ");
    (a.iter().zip(&b).filter(|(p, q)| p != q).count(), a.len())
}

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
/// without its timings and ray counts, dump), the report's `cpu_isa` and its ray counts.
fn render(isa: &str, scene: &Path, extra: &[&str]) -> (Vec<(String, Vec<u8>)>, String, serde_json::Value) {
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
    for key in ["timings_ms", "cpu_isa", "capsule", "rays"] {
        map.remove(key);
    }
    if let Some(h) = map.get_mut("heuristic").and_then(|h| h.as_object_mut()) {
        h.retain(|k, _| !k.contains("ms"));
    }
    got.push(("report (no timings, no ray counts)".into(), serde_json::to_vec(&json_same).unwrap()));
    (got, json["cpu_isa"].as_str().unwrap_or_default().to_string(), json["rays"].clone())
}

#[test]
fn every_isa_path_renders_every_scene_alike() {
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
        let (base, base_isa, base_rays) = render(Isa::Baseline.name(), scene, extra);
        assert_eq!(base_isa, Isa::Baseline.name());
        for isa in &paths[1..] {
            let (got, got_isa, got_rays) = render(isa.name(), scene, extra);
            let case = format!("{} {extra:?}, {} against {}", scene.display(), isa.name(), Isa::Baseline.name());
            assert_eq!(got_isa, isa.name(), "the report names the path");
            assert_eq!(got.len(), base.len());
            let mut grazing = 0;
            for ((name, a), (name_b, b)) in base.iter().zip(&got) {
                assert_eq!(name, name_b);
                if a == b {
                    continue;
                }
                assert!(TRACED.contains(&name.as_str()), "{case}: `{name}` differs");
                let (differ, of) = differing_pixels(name, a, b);
                assert!(differ <= (of * GRAZING_PIXELS_PER_MILLE / 1000).max(1), "{case}: `{name}` differs in {differ} of {of} pixels");
                grazing = grazing.max(differ);
            }
            // Each grazing ray may change which rays follow it, one or two per pixel.
            let counts = |r: &serde_json::Value| -> Vec<(String, i64)> {
                let mut v: Vec<_> = r.as_object().into_iter().flatten().map(|(k, n)| (k.clone(), n.as_i64().unwrap())).collect();
                v.sort();
                v
            };
            let (base_counts, got_counts) = (counts(&base_rays), counts(&got_rays));
            assert_eq!(base_counts.len(), got_counts.len(), "{case}: ray kinds");
            for ((kind, a), (kind_b, b)) in base_counts.iter().zip(&got_counts) {
                assert_eq!(kind, kind_b);
                assert!((a - b).unsigned_abs() as usize <= 2 * grazing, "{case}: {kind} rays {a} against {b}");
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
