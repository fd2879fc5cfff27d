//! LAS / LAZ point clouds via the `las` crate (LAZ through its `laz` feature).

use std::path::Path;

use glam::Vec3;

use crate::SceneError;

/// Points are decoded in batches of this many (bounded memory for the raw records).
const BATCH: u64 = 1 << 16;

pub(super) fn load(path: &Path) -> Result<(Vec<Vec3>, Vec<[u8; 3]>), SceneError> {
    let file_len = super::check_file(path, "LAS file", super::MAX_MODEL_BYTES)?;
    let mut reader = ::las::Reader::from_path(path).map_err(|e| SceneError::new(path, format!("cannot read LAS header: {e}")))?;
    let header = reader.header();
    let declared = header.number_of_points();
    let format = *header.point_format();
    let has_color = format.has_color;
    // Compressed records take at least ~1 byte; uncompressed ones their record length.
    let min_bytes = if format.is_compressed { 1 } else { format.len().max(1) as usize };
    let cap = super::capped_capacity(usize::try_from(declared).unwrap_or(usize::MAX), min_bytes, file_len);
    let mut points = Vec::with_capacity(cap);
    let mut colors = if has_color { Vec::with_capacity(cap) } else { Vec::new() };
    let mut data = ::las::PointDataBuilder::new().for_header(reader.header()).build();
    // The las crate allocates a batch's raw records up front: a batch never asks for more records
    // than the file's bytes can hold, so a header declaring billions of long records costs
    // nothing before the body runs out (found by fuzzing: 1.8 GB allocated for a 371-byte file).
    let batch = BATCH.min((file_len / min_bytes as u64).max(1));
    let mut read = 0u64;
    while read < declared {
        let n = reader
            .fill_points(batch.min(declared - read), &mut data)
            .map_err(|e| SceneError::new(path, format!("cannot read LAS point {read} of {declared}: {e}")))?;
        if n == 0 {
            return Err(SceneError::new(path, format!("file ends early: {read} of {declared} points")));
        }
        for (i, ((x, y), z)) in data.x().zip(data.y()).zip(data.z()).enumerate() {
            let p = Vec3::new(x as f32, y as f32, z as f32);
            super::check_finite("point", read as usize + i, p).map_err(|m| SceneError::new(path, m))?;
            points.push(p);
        }
        if let Some(rgb) = data.rgb().filter(|_| has_color) {
            // LAS colours are 16-bit; files written by 8-bit tools store 0..255 (detected below).
            colors.extend(rgb.map(|(r, g, b)| [r, g, b]));
        }
        read += n;
    }
    let colors = if has_color { to_8bit(colors) } else { Vec::new() };
    Ok((points, colors))
}

/// 16-bit LAS colours to 8 bits: the high byte, unless no channel exceeds 255 (8-bit writers).
fn to_8bit(c: Vec<[u16; 3]>) -> Vec<[u8; 3]> {
    let eight_bit = c.iter().all(|p| p.iter().all(|&v| v <= 255));
    c.into_iter().map(|p| p.map(|v| if eight_bit { v as u8 } else { (v >> 8) as u8 })).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colors_use_the_high_byte_unless_the_file_is_8_bit() {
        assert_eq!(to_8bit(vec![[65_535, 256, 0]]), vec![[255, 1, 0]]);
        assert_eq!(to_8bit(vec![[255, 17, 0]]), vec![[255, 17, 0]]);
    }

    #[test]
    fn garbage_is_an_error_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("junk.las");
        std::fs::write(&p, b"LASF but not really").unwrap();
        let e = load(&p).unwrap_err();
        assert!(e.to_string().contains("junk.las"), "{e}");
    }
}
