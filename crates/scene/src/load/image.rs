//! PNG / JPEG textures via the `image` crate.

use std::path::Path;

use crate::{ColorSpace, SceneError, Texture};

/// Largest accepted texture side (a 16K texture is already 1 GiB of RGBA8 with mips).
pub(crate) const MAX_TEXTURE_SIDE: u32 = 16_384;

pub(super) fn load(path: &Path, color_space: ColorSpace) -> Result<Texture, SceneError> {
    let bytes = super::read_capped(path, "texture file", super::MAX_TEXTURE_FILE_BYTES)?;
    let reader = ::image::ImageReader::new(std::io::Cursor::new(&bytes[..]));
    let reader = reader.with_guessed_format().map_err(|e| SceneError::new(path, format!("cannot read texture: {e}")))?;
    match reader.format() {
        Some(::image::ImageFormat::Png) => {}
        Some(::image::ImageFormat::Jpeg) => {
            check_jpeg_complete(&bytes).and_then(|()| check_jpeg_data_covers_frame(&bytes)).map_err(|e| SceneError::new(path, e))?
        }
        Some(f) => return Err(SceneError::new(path, format!("unsupported texture format {f:?} (expected PNG or JPEG)"))),
        None => return Err(SceneError::new(path, "not a PNG or JPEG image (unrecognised contents)")),
    }
    let mut limits = ::image::Limits::default();
    limits.max_image_width = Some(MAX_TEXTURE_SIDE);
    limits.max_image_height = Some(MAX_TEXTURE_SIDE);
    let mut reader = reader;
    reader.limits(limits);
    // The checks above cover the decoder panics fuzzing found; one left in the decoder is still
    // its bug, turned into an error naming the file rather than taking the caller down.
    let decoded = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| reader.decode()))
        .map_err(|_| SceneError::new(path, "the image decoder failed on this file"))?;
    let img = decoded.map_err(|e| SceneError::new(path, format!("cannot decode texture: {e}")))?;
    let rgba = img.into_rgba8();
    let (w, h) = rgba.dimensions();
    if w == 0 || h == 0 {
        return Err(SceneError::new(path, "texture has no pixels"));
    }
    let texels: Vec<[u8; 4]> = rgba.as_raw().chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]).collect();
    Ok(Texture::new(texture_name(path), w, h, texels, color_space))
}

/// Strict JPEG check: the decoder fills a truncated scan with grey and reports success, so the
/// file must end its last scan (SOS, `FF DA`) with an end-of-image marker (`FF D9`). Inside a
/// scan's entropy-coded data every `FF` byte is followed by `00` or a restart marker, so an EOI
/// found after the last SOS really ends that scan.
pub(crate) fn check_jpeg_complete(bytes: &[u8]) -> Result<(), String> {
    let find_last = |marker: u8| bytes.windows(2).rposition(|w| w[0] == 0xFF && w[1] == marker);
    let sos = find_last(0xDA).ok_or("JPEG has no image data (no start-of-scan marker)")?;
    match find_last(0xD9) {
        Some(eoi) if eoi > sos => Ok(()),
        _ => Err("JPEG is truncated (its last scan has no end-of-image marker)".into()),
    }
}

/// A Huffman-coded JPEG (baseline, extended or progressive: what the decoder reads) codes every
/// 8×8 block's DC coefficient with at least one bit, so its scans hold at least one bit per block
/// of the frame. A file with less declares a frame its data cannot fill: the decoder would fill
/// it with grey, taking seconds and hundreds of MiB for a few hundred bytes (found by fuzzing:
/// 300-byte progressive JPEGs declaring 8212×3860 pixels). The check allows half that minimum.
pub(crate) fn check_jpeg_data_covers_frame(bytes: &[u8]) -> Result<(), String> {
    let u16_at = |i: usize| bytes.get(i..i + 2).map(|b| u16::from_be_bytes([b[0], b[1]]) as usize);
    let mut frame = None;
    let mut i = 2;
    // Marker segments up to the first scan, skipping stray bytes between them as decoders do;
    // a stream that ends first is left to the decoder.
    let first_scan = loop {
        let (Some(&byte), Some(&marker)) = (bytes.get(i), bytes.get(i + 1)) else { return Ok(()) };
        if byte != 0xFF {
            i += 1;
            continue;
        }
        match marker {
            0xFF => i += 1,
            0x01 | 0xD0..=0xD8 => i += 2,
            0xDA => break i,
            _ => {
                let Some(len) = u16_at(i + 2) else { return Ok(()) };
                if matches!(marker, 0xC0..=0xC2) {
                    frame = u16_at(i + 5).zip(u16_at(i + 7));
                    check_jpeg_sampling(bytes.get(i + 9..).unwrap_or_default())?;
                }
                i += 2 + len;
            }
        }
    };
    let Some((height, width)) = frame else { return Ok(()) };
    let blocks = width.div_ceil(8) as u64 * height.div_ceil(8) as u64;
    let data_bits = (bytes.len() - first_scan) as u64 * 8;
    if data_bits * 2 < blocks {
        return Err(format!(
            "JPEG declares {width}x{height} pixels ({blocks} blocks) but holds only {} bytes of image data: a valid file needs at least one bit per block",
            bytes.len() - first_scan
        ));
    }
    Ok(())
}

/// The frame header's sampling factors (`components` starts at its component count): the first
/// component (luma) must sample at least as finely as every other in both directions, as in
/// every 4:4:4, 4:2:2, 4:2:0, 4:4:0 and 4:1:1 file. zune-jpeg 0.5 asserts (a panic) on chroma
/// sampled more finely than luma in one direction (found by fuzzing: Y 1x2 with Cr 2x1).
fn check_jpeg_sampling(components: &[u8]) -> Result<(), String> {
    let Some((&count, rest)) = components.split_first() else { return Ok(()) };
    let factors: Vec<(u8, u8)> = rest.chunks_exact(3).take(count as usize).map(|c| (c[1] >> 4, c[1] & 15)).collect();
    let Some(&(h0, v0)) = factors.first() else { return Ok(()) };
    match factors.iter().enumerate().skip(1).find(|(_, f)| f.0 > h0 || f.1 > v0) {
        Some((k, &(h, v))) => {
            Err(format!("unsupported JPEG sampling: component {} samples {h}x{v}, more finely than the first component's {h0}x{v0}", k + 1))
        }
        None => Ok(()),
    }
}

/// The texture's name: its file name.
pub(crate) fn texture_name(path: &Path) -> String {
    path.file_name().map_or_else(|| path.display().to_string(), |n| n.to_string_lossy().into_owned())
}

/// Whether an RGBA8 image looks like a tangent-space normal map: blue dominant on average
/// (flat normals are (128, 128, 255)), as opposed to a grey-scale bump/height map.
pub(crate) fn looks_like_normal_map(texels: &[[u8; 4]]) -> bool {
    if texels.is_empty() {
        return false;
    }
    let mut sum = [0u64; 3];
    for t in texels {
        for c in 0..3 {
            sum[c] += t[c] as u64;
        }
    }
    let n = texels.len() as f64;
    let [r, g, b] = sum.map(|s| s as f64 / n);
    b > 160.0 && b > r + 40.0 && b > g + 40.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn truncated_jpeg_is_rejected_and_a_whole_one_accepted() {
        let img = ::image::RgbImage::from_fn(32, 32, |x, y| ::image::Rgb([(x * 8) as u8, (y * 8) as u8, 99]));
        let mut bytes = Vec::new();
        ::image::DynamicImage::ImageRgb8(img).write_to(&mut std::io::Cursor::new(&mut bytes), ::image::ImageFormat::Jpeg).unwrap();
        assert!(check_jpeg_complete(&bytes).is_ok());
        let e = check_jpeg_complete(&bytes[..bytes.len() - 10]).unwrap_err();
        assert!(e.contains("truncated"), "{e}");
        assert!(check_jpeg_complete(&bytes[..bytes.len() / 2]).is_err());
        assert!(check_jpeg_complete(&bytes[..20]).is_err());
    }

    #[test]
    fn jpeg_data_must_cover_its_frame() {
        let img = ::image::RgbImage::from_pixel(256, 128, ::image::Rgb([90, 90, 90]));
        let mut bytes = Vec::new();
        ::image::DynamicImage::ImageRgb8(img).write_to(&mut std::io::Cursor::new(&mut bytes), ::image::ImageFormat::Jpeg).unwrap();
        // Even a flat grey image spends more than a bit per block.
        assert_eq!(check_jpeg_data_covers_frame(&bytes), Ok(()));
        // The same data under a frame header claiming 16384x16384: 4M blocks from a few hundred bytes.
        let sof = bytes.windows(2).position(|w| w == [0xFF, 0xC0]).unwrap();
        bytes[sof + 5..sof + 9].copy_from_slice(&[0x40, 0x00, 0x40, 0x00]);
        let e = check_jpeg_data_covers_frame(&bytes).unwrap_err();
        assert!(e.contains("16384x16384") && e.contains("4194304 blocks"), "{e}");
        // Chroma sampled more finely than luma in one direction (zune-jpeg panicked on it).
        assert_eq!(check_jpeg_sampling(&[3, 1, 0x22, 0, 2, 0x11, 1, 3, 0x11, 1]), Ok(()));
        let e = check_jpeg_sampling(&[3, 1, 0x12, 0, 2, 0x11, 1, 3, 0x21, 1]).unwrap_err();
        assert!(e.contains("component 3 samples 2x1") && e.contains("first component's 1x2"), "{e}");
        // Malformed marker streams are left to the decoder.
        assert_eq!(check_jpeg_data_covers_frame(&[0xFF, 0xD8, 0x12]), Ok(()));
        assert_eq!(check_jpeg_data_covers_frame(&[0xFF, 0xD8, 0xFF, 0xC0, 0xFF]), Ok(()));
    }

    #[test]
    fn normal_map_detection() {
        assert!(looks_like_normal_map(&[[128, 128, 255, 255]; 4]));
        assert!(!looks_like_normal_map(&[[200, 200, 200, 255]; 4]));
        assert!(!looks_like_normal_map(&[]));
    }

    #[test]
    fn png_roundtrip_and_bad_files() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("t.png");
        let img = ::image::RgbaImage::from_fn(4, 2, |x, y| ::image::Rgba([x as u8 * 60, y as u8 * 100, 7, 255]));
        img.save(&p).unwrap();
        let t = load(&p, ColorSpace::Srgb).unwrap();
        assert_eq!((t.width(), t.height()), (4, 2));
        assert_eq!(t.levels[0].texels[4 + 3], [180, 100, 7, 255]);
        assert_eq!(t.name, "t.png");

        let bad = dir.path().join("bad.png");
        std::fs::write(&bad, b"not an image at all").unwrap();
        let e = load(&bad, ColorSpace::Srgb).unwrap_err();
        assert!(e.to_string().contains("bad.png"), "{e}");
        let e = load(&dir.path().join("missing.jpg"), ColorSpace::Linear).unwrap_err();
        assert!(e.to_string().contains("missing.jpg") && e.message.contains("cannot open"), "{e}");
    }
}
