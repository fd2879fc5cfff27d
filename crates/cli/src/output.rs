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
