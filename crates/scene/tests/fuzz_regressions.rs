//! Every input the fuzzers (fuzz/, cargo afl) ever crashed on, replayed through the loader of its
//! kind: `tests/fuzz-regressions/<target>/<file>`, where `<target>` is the fuzz target (the
//! file's extension as the loader sees it, or `scene` for scene TOML). Each must be refused with
//! an error naming the file, without a panic; where `<file>.expect` exists, the error must also
//! contain its text (the check that catches the input before the dependency's arithmetic wraps:
//! release builds have no overflow checks, so a plain "refused" could hide the old path).

use std::path::Path;

fn replay(target: &str, file: &Path) -> Result<(), String> {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join(format!("input.{target}"));
    std::fs::copy(file, &input).unwrap();
    let result = std::panic::catch_unwind(|| -> Result<(), String> {
        let loaded = match target {
            "obj" | "gltf" | "glb" => hybrid_scene::load::load_model(&input, &mut Vec::new(), &mut Vec::new()).map(|_| ()),
            "ply" => hybrid_scene::load::load_model(&input, &mut Vec::new(), &mut Vec::new())
                .map(|_| ())
                .and(hybrid_scene::load::load_point_cloud(&input).map(|_| ())),
            "las" | "laz" => hybrid_scene::load::load_point_cloud(&input).map(|_| ()),
            "png" | "jpg" => hybrid_scene::load::load_texture(&input, hybrid_scene::ColorSpace::Srgb).map(|_| ()),
            "scene" => {
                let text = std::fs::read_to_string(&input).unwrap_or_default();
                hybrid_scene::parse_scene(&text, &input).map(|_| ())
            }
            other => panic!("unknown fuzz target folder `{other}`"),
        };
        loaded.map_err(|e| e.to_string())
    });
    match result {
        Err(_) => Err(format!("{}: the loader panicked", file.display())),
        Ok(Ok(())) => Err(format!("{}: accepted; a crash input must be refused", file.display())),
        Ok(Err(e)) if !e.contains("input.") => Err(format!("{}: the error does not name the file: {e}", file.display())),
        Ok(Err(e)) => {
            let expect = file.with_file_name(format!("{}.expect", file.file_name().unwrap().to_string_lossy()));
            match std::fs::read_to_string(&expect) {
                Ok(want) if !e.contains(want.trim()) => Err(format!("{}: the error does not say `{}`: {e}", file.display(), want.trim())),
                _ => Ok(()),
            }
        }
    }
}

#[test]
fn every_fuzz_crash_is_refused_without_a_panic() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fuzz-regressions");
    let mut replayed = 0;
    let mut failures = Vec::new();
    for target in std::fs::read_dir(&root).unwrap() {
        let target = target.unwrap().path();
        let name = target.file_name().unwrap().to_string_lossy().into_owned();
        for file in std::fs::read_dir(&target).unwrap() {
            let file = file.unwrap().path();
            if file.extension().is_some_and(|e| e == "expect") {
                continue;
            }
            if let Err(e) = replay(&name, &file) {
                failures.push(e);
            }
            replayed += 1;
        }
    }
    assert!(replayed > 0, "no regression inputs found under {}", root.display());
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
