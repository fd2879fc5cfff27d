//! Fuzz target: a `.gltf` file through its loader. Any panic, hang or abort is a bug; errors are fine.
fn main() {
    afl::fuzz!(|data: &[u8]| {
        let path = hybrid_fuzz::as_file(data, "gltf");
        let mut materials = Vec::new();
        let mut textures = Vec::new();
        let _ = hybrid_scene::load::load_model(&path, &mut materials, &mut textures);
    });
}
