//! Fuzz target: scene-file TOML through the parser (files it names do not exist next to the
//! input, so model and texture references fail with errors). Any panic is a bug.
fn main() {
    afl::fuzz!(|data: &[u8]| {
        if let Ok(text) = std::str::from_utf8(data) {
            let _ = hybrid_scene::parse_scene(text, std::path::Path::new("/nonexistent/fuzz.toml"));
        }
    });
}
