//! LAS / LAZ point clouds via the `las` crate (LAZ through its `laz` feature).

use std::path::Path;

use glam::Vec3;

use crate::SceneError;

/// Points are decoded in batches of this many (bounded memory for the raw records).
const BATCH: u64 = 1 << 16;

pub(super) fn load(path: &Path) -> Result<(Vec<Vec3>, Vec<[u8; 3]>), SceneError> {
    let file_len = super::check_file(path, "LAS file", super::MAX_MODEL_BYTES)?;
    check_header_extents(path, file_len).map_err(|m| SceneError::new(path, m))?;
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

/// What the header says lies where, checked against the file before the las crate reads it: las
/// 0.11 computes the end of the points as `offset + count × record length` unchecked (an overflow)
/// and allocates an extended VLR's declared length (a `u64`) before reading it, which aborted the
/// process on a few-hundred-byte file (both found by fuzzing). Short or foreign files are left to
/// the las crate's own errors.
fn check_header_extents(path: &Path, file_len: u64) -> Result<(), String> {
    use std::io::{Read, Seek, SeekFrom};
    let mut file = std::fs::File::open(path).map_err(|e| format!("cannot open LAS file: {e}"))?;
    let mut head = Vec::with_capacity(255);
    (&mut file).take(255).read_to_end(&mut head).map_err(|e| format!("cannot read LAS header: {e}"))?;
    let u16_at = |i: usize| head.get(i..i + 2).map(|b| u16::from_le_bytes([b[0], b[1]]) as u64);
    let u32_at = |i: usize| head.get(i..i + 4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as u64);
    let u64_at = |i: usize| head.get(i..i + 8).map(|b| u64::from_le_bytes(b.try_into().unwrap()));
    let (true, Some(&major), Some(&minor)) = (head.starts_with(b"LASF"), head.get(24), head.get(25)) else { return Ok(()) };
    let (Some(offset), Some(record_len), Some(legacy_count)) = (u32_at(96), u16_at(105), u32_at(107)) else { return Ok(()) };
    // LAS 1.4 adds the extended VLRs (start, count) and a 64-bit point count, used when the legacy one is 0.
    let v14 = (major, minor) >= (1, 4);
    let count = match u64_at(247) {
        Some(large) if v14 && legacy_count == 0 => large,
        _ => legacy_count,
    };
    count.checked_mul(record_len).and_then(|b| b.checked_add(offset)).ok_or_else(|| {
        format!("the header declares {count} points of {record_len} bytes after byte {offset}: more than any file can hold")
    })?;
    let (Some(evlr_start), Some(evlr_count)) = (u64_at(235), u32_at(243)) else { return Ok(()) };
    if !v14 || evlr_start == 0 || evlr_count == 0 {
        return Ok(());
    }
    // The first extended VLR's header: 60 bytes, its data length at byte 20.
    const EVLR_HEADER: u64 = 60;
    let mut evlr = [0u8; 8];
    if evlr_start.checked_add(EVLR_HEADER).is_none_or(|end| end > file_len)
        || file.seek(SeekFrom::Start(evlr_start + 20)).and_then(|_| file.read_exact(&mut evlr)).is_err()
    {
        return Err(format!("the first extended VLR starts at byte {evlr_start}, past the end of the {file_len}-byte file"));
    }
    let data_len = u64::from_le_bytes(evlr);
    if (evlr_start + EVLR_HEADER).checked_add(data_len).is_none_or(|end| end > file_len) {
        return Err(format!(
            "the extended VLR at byte {evlr_start} declares {data_len} bytes of data, past the end of the {file_len}-byte file"
        ));
    }
    Ok(())
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

    /// A LAS 1.4 header (375 bytes) with `count` points of 20 bytes and one extended VLR at
    /// `evlr_start` declaring `evlr_len` bytes, followed by `body` bytes of zeros.
    fn las14(count: u64, evlr_start: u64, evlr_len: u64, body: usize) -> Vec<u8> {
        let mut h = vec![0u8; 375];
        h[..4].copy_from_slice(b"LASF");
        (h[24], h[25]) = (1, 4);
        h[94..96].copy_from_slice(&375u16.to_le_bytes());
        h[96..100].copy_from_slice(&375u32.to_le_bytes());
        h[105..107].copy_from_slice(&20u16.to_le_bytes());
        h[235..243].copy_from_slice(&evlr_start.to_le_bytes());
        h[243..247].copy_from_slice(&1u32.to_le_bytes());
        h[247..255].copy_from_slice(&count.to_le_bytes());
        h.resize(375 + body, 0);
        if let Some(at) = (evlr_start > 0 && evlr_start as usize + 28 <= h.len()).then_some(evlr_start as usize + 20) {
            h[at..at + 8].copy_from_slice(&evlr_len.to_le_bytes());
        }
        h
    }

    #[test]
    fn header_extents_beyond_the_file_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("h.las");
        let check = |bytes: Vec<u8>| {
            std::fs::write(&p, &bytes).unwrap();
            check_header_extents(&p, bytes.len() as u64)
        };
        // Two points, then an extended VLR of 4 bytes: all inside the file.
        assert_eq!(check(las14(2, 415, 4, 40 + 64)), Ok(()));
        let e = check(las14(u64::MAX / 4, 0, 0, 0)).unwrap_err();
        assert!(e.contains("more than any file can hold"), "{e}");
        let e = check(las14(2, 415, 1 << 50, 40 + 64)).unwrap_err();
        assert!(e.contains("declares 1125899906842624 bytes") && e.contains("past the end"), "{e}");
        let e = check(las14(2, 1 << 40, 4, 40)).unwrap_err();
        assert!(e.contains("starts at byte 1099511627776"), "{e}");
        // Not a LAS file, or too short to say: left to the las crate.
        assert_eq!(check(b"PLY and more".to_vec()), Ok(()));
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
