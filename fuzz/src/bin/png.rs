//! Fuzz target: a `.png` file through its loader. Any panic, hang or abort is a bug; errors are fine.
fn main() {
    afl::fuzz!(|data: &[u8]| {
        let path = hybrid_fuzz::as_file(data, "png");
        let _ = hybrid_scene::load::load_texture(&path, hybrid_scene::ColorSpace::Srgb);
    });
}
