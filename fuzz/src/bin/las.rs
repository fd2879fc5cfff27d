//! Fuzz target: a `.las` file through its loader. Any panic, hang or abort is a bug; errors are fine.
fn main() {
    afl::fuzz!(|data: &[u8]| {
        let path = hybrid_fuzz::as_file(data, "las");
        let _ = hybrid_scene::load::load_point_cloud(&path);
    });
}
