//! Shared by the fuzz targets: the loaders take paths, so each input is written to a file with
//! the extension the loader dispatches on (in /dev/shm where it exists, a RAM disk) and loaded.

use std::path::PathBuf;

/// A per-process file named `input.EXT` holding `data`.
pub fn as_file(data: &[u8], ext: &str) -> PathBuf {
    let dir = if std::path::Path::new("/dev/shm").is_dir() { PathBuf::from("/dev/shm") } else { std::env::temp_dir() };
    let path = dir.join(format!("hybrid-fuzz-{}.{ext}", std::process::id()));
    std::fs::write(&path, data).expect("write the fuzz input");
    path
}
