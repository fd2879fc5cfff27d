//! Writing output files without ever leaving a partial one: every file is written to a
//! temporary name in the same folder and renamed into place only when complete.

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::CliError;

/// A temporary sibling path of `path` (same folder, so the final rename is atomic).
fn temp_path(path: &Path) -> PathBuf {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "out".into());
    path.with_file_name(format!(".{name}.partial-{}", std::process::id()))
}

/// Writes a file by calling `write` on a temporary path, then renaming it to `path`.
pub fn write_atomically(path: &Path, write: impl FnOnce(&Path) -> Result<(), String>) -> Result<(), CliError> {
    let tmp = temp_path(path);
    match write(&tmp) {
        Ok(()) => fs::rename(&tmp, path).map_err(|e| {
            let _ = fs::remove_file(&tmp);
            CliError::failure(format!("{}: cannot write: {e}", path.display()))
        }),
        Err(e) => {
            let _ = fs::remove_file(&tmp);
            Err(CliError::failure(format!("{}: cannot write: {e}", path.display())))
        }
    }
}

pub fn write_bytes(path: &Path, bytes: &[u8]) -> Result<(), CliError> {
    write_atomically(path, |tmp| {
        let mut f = fs::File::create(tmp).map_err(|e| e.to_string())?;
        f.write_all(bytes).map_err(|e| e.to_string())?;
        f.sync_all().map_err(|e| e.to_string())
    })
}

/// 8-bit RGBA PNG.
pub fn write_png_rgba8(path: &Path, width: u32, height: u32, rgba: &[[u8; 4]]) -> Result<(), CliError> {
    let bytes: Vec<u8> = rgba.iter().flatten().copied().collect();
    write_atomically(path, |tmp| {
        image::save_buffer_with_format(tmp, &bytes, width, height, image::ExtendedColorType::Rgba8, image::ImageFormat::Png)
            .map_err(|e| e.to_string())
    })
}

/// 16-bit PNG with `channels` (1 = grey, 4 = RGBA) samples per pixel, stored verbatim.
pub fn write_png16(path: &Path, width: u32, height: u32, channels: usize, samples: &[u16]) -> Result<(), CliError> {
    write_atomically(path, |tmp| {
        let file = fs::File::create(tmp).map_err(|e| e.to_string())?;
        let mut enc = png::Encoder::new(std::io::BufWriter::new(file), width, height);
        enc.set_color(if channels == 1 { png::ColorType::Grayscale } else { png::ColorType::Rgba });
        enc.set_depth(png::BitDepth::Sixteen);
        let mut w = enc.write_header().map_err(|e| e.to_string())?;
        // PNG samples are big-endian.
        let data: Vec<u8> = samples.iter().flat_map(|s| s.to_be_bytes()).collect();
        w.write_image_data(&data).map_err(|e| e.to_string())?;
        w.finish().map_err(|e| e.to_string())
    })
}

/// Float image as OpenEXR (f32, lossless): channel names and one value per channel per pixel,
/// row-major.
pub fn write_exr(path: &Path, width: u32, height: u32, channels: &[(&str, Vec<f32>)]) -> Result<(), CliError> {
    use exr::prelude::*;
    write_atomically(path, |tmp| {
        let size = (width as usize, height as usize);
        let list: SmallVec<[AnyChannel<FlatSamples>; 4]> =
            channels.iter().map(|(name, values)| AnyChannel::new(*name, FlatSamples::F32(values.clone()))).collect();
        let layer = Layer::new(size, LayerAttributes::default(), Encoding::SMALL_LOSSLESS, AnyChannels::sort(list));
        Image::from_layer(layer).write().to_file(tmp).map_err(|e| e.to_string())
    })
}

/// Checks up front that `dir` exists (or can be created) and is writable, so a render does not
/// run for nothing.
pub fn ensure_dir(dir: &Path) -> Result<(), CliError> {
    fs::create_dir_all(dir).map_err(|e| CliError::bad_input(format!("{}: cannot create output folder: {e}", dir.display())))?;
    let probe = dir.join(format!(".hybrid-write-test-{}", std::process::id()));
    fs::write(&probe, b"").map_err(|e| CliError::bad_input(format!("{}: output folder is not writable: {e}", dir.display())))?;
    let _ = fs::remove_file(probe);
    Ok(())
}

/// Checks that the folder of an output file exists and is writable.
pub fn ensure_parent(file: &Path) -> Result<(), CliError> {
    let parent = match file.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    if !parent.is_dir() {
        return Err(CliError::bad_input(format!("{}: folder `{}` does not exist", file.display(), parent.display())));
    }
    let probe = parent.join(format!(".hybrid-write-test-{}", std::process::id()));
    fs::write(&probe, b"").map_err(|e| CliError::bad_input(format!("{}: folder is not writable: {e}", file.display())))?;
    let _ = fs::remove_file(probe);
    Ok(())
}

/// Checks an output file flag (`-o`, `--report`) before any work: it must not name a folder,
/// its extension must be one of `extensions` (case-insensitive; empty = any), and its folder must
/// exist and be writable.
pub fn check_output_file(file: &Path, flag: &str, extensions: &[&str]) -> Result<(), CliError> {
    if file.is_dir() {
        return Err(CliError::bad_input(format!("{}: {flag} names a folder; give a file name", file.display())));
    }
    if !extensions.is_empty() {
        let ext = file.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
        if !extensions.contains(&ext.as_str()) {
            let want: Vec<String> = extensions.iter().map(|e| format!(".{e}")).collect();
            let got = if ext.is_empty() { "no extension".to_string() } else { format!("`.{ext}`") };
            return Err(CliError::bad_input(format!(
                "{}: {flag} has {got}, but only {} is written (the format follows the extension)",
                file.display(),
                want.join(", ")
            )));
        }
    }
    ensure_parent(file)
}

/// An output folder (`--dump`, `bench --out`) prepared before rendering: created (and probed)
/// now, and removed again on drop unless [`OutputDir::keep`] is called — from the outermost
/// folder this run created, so a failing run leaves neither an empty or half-filled folder nor
/// the new folders above it (`--out new/sub` removes `new`). A folder that existed is never
/// removed.
pub struct OutputDir {
    /// The outermost folder this run created, if any.
    created: Option<PathBuf>,
    keep: bool,
}

impl OutputDir {
    /// `dir` for `flag` (named in errors).
    pub fn prepare(dir: &Path, flag: &str) -> Result<Self, CliError> {
        if dir.exists() && !dir.is_dir() {
            return Err(CliError::bad_input(format!("{}: {flag} names a file; give a folder", dir.display())));
        }
        // The outermost missing ancestor (or `dir` itself) is what this run creates.
        let created = dir.ancestors().take_while(|a| !a.as_os_str().is_empty() && !a.exists()).last().map(Path::to_path_buf);
        // Remove what we create if the checks below fail.
        let guard = Self { created, keep: false };
        ensure_dir(dir)?;
        Ok(guard)
    }

    /// The run succeeded: keep the folder.
    pub fn keep(mut self) {
        self.keep = true;
    }
}

impl Drop for OutputDir {
    fn drop(&mut self) {
        if let Some(created) = &self.created
            && !self.keep
        {
            let _ = fs::remove_dir_all(created);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn output_file_checks() {
        let dir = tempfile::tempdir().unwrap();
        let e = check_output_file(dir.path(), "-o", &["png"]).unwrap_err();
        assert!(e.message.contains("names a folder") && e.code == crate::EXIT_BAD_INPUT, "{}", e.message);
        let e = check_output_file(&dir.path().join("x.jpg"), "-o", &["png"]).unwrap_err();
        assert!(e.message.contains("`.jpg`") && e.message.contains(".png"), "{}", e.message);
        assert!(check_output_file(&dir.path().join("x.PNG"), "-o", &["png"]).is_ok());
        assert!(check_output_file(&dir.path().join("r.json"), "--report", &["json"]).is_ok());
        let e = check_output_file(&dir.path().join("r.txt"), "--report", &["json"]).unwrap_err();
        assert!(e.message.contains("--report has `.txt`, but only .json is written"), "{}", e.message);
    }

    #[test]
    fn output_dir_created_by_a_failed_run_is_removed() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path().join("new");
        drop(OutputDir::prepare(&d, "--dump").unwrap());
        assert!(!d.exists());
        OutputDir::prepare(&d, "--dump").unwrap().keep();
        assert!(d.is_dir());
        // An existing folder is never removed, nor what it held.
        std::fs::write(d.join("old.png"), b"x").unwrap();
        drop(OutputDir::prepare(&d, "--dump").unwrap());
        assert!(d.join("old.png").is_file());
        // New folders above the output folder go too, up to the first that existed.
        let nested = d.join("a/b/c");
        let guard = OutputDir::prepare(&nested, "--out").unwrap();
        assert!(nested.is_dir());
        std::fs::write(nested.join("bench.json"), b"{}").unwrap();
        drop(guard);
        assert!(!d.join("a").exists());
        assert!(d.join("old.png").is_file());
        // A relative path in the current folder.
        assert_eq!(OutputDir::prepare(Path::new("."), "--out").unwrap().created, None);
        // A file is not a folder.
        let e = OutputDir::prepare(&d.join("old.png"), "--out").err().unwrap();
        assert!(e.message.contains("--out names a file"), "{}", e.message);
    }
}
