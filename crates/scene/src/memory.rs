//! Memory limits (issue 22): byte sizes as flags write them, the default limit (a fraction of the
//! machine's memory) and what a scene's own data takes. The frame and the renderers' share of the
//! estimate live in `hybrid_core::memory`; the scene parser checks its geometry against the
//! limit as it tessellates and instantiates models (see [`crate::load_scene_or_model_within`]),
//! so a scene at the documented maxima is refused before it is built, not killed while building.

use std::fmt;
use std::mem::size_of;

use glam::{Vec2, Vec3, Vec4};

use crate::{Mesh, Scene};

const KIB: u64 = 1 << 10;
const MIB: u64 = 1 << 20;
const GIB: u64 = 1 << 30;
const TIB: u64 = 1 << 40;

/// Share of the machine's memory a run may plan to use by default: 3/4 of `MemTotal`.
pub const DEFAULT_FRACTION_PERCENT: u64 = 75;
/// The default limit where the machine's memory cannot be read (no `/proc/meminfo`).
pub const FALLBACK_LIMIT: u64 = 8 * GIB;

/// How much memory a run may plan to use, and where that number came from (for the error).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MemoryLimit {
    pub bytes: u64,
    /// E.g. "--max-memory", "75% of this machine's 23.4 GiB".
    pub origin: String,
}

impl MemoryLimit {
    /// An explicit limit (`--max-memory`).
    pub fn explicit(bytes: u64) -> Self {
        Self { bytes, origin: "--max-memory".into() }
    }

    /// The default: [`DEFAULT_FRACTION_PERCENT`] of `MemTotal` in `/proc/meminfo`, or
    /// [`FALLBACK_LIMIT`] where that cannot be read.
    pub fn machine_default() -> Self {
        let total = std::fs::read_to_string("/proc/meminfo").ok().and_then(|t| mem_total(&t));
        Self::default_for(total)
    }

    /// [`Self::machine_default`] for a machine with `total` bytes of memory (`None`: unknown).
    pub fn default_for(total: Option<u64>) -> Self {
        match total {
            Some(total) => Self {
                bytes: total / 100 * DEFAULT_FRACTION_PERCENT,
                origin: format!("the default, {DEFAULT_FRACTION_PERCENT}% of this machine's {}", Bytes(total)),
            },
            None => {
                Self { bytes: FALLBACK_LIMIT, origin: format!("the default, {} (this machine's memory is unknown)", Bytes(FALLBACK_LIMIT)) }
            }
        }
    }

    /// The limit in words for error messages: "12.0 GiB (the default, 75% of …)".
    pub fn describe(&self) -> String {
        format!("{} ({})", Bytes(self.bytes), self.origin)
    }
}

/// `MemTotal` of a `/proc/meminfo` text, in bytes.
fn mem_total(meminfo: &str) -> Option<u64> {
    let line = meminfo.lines().find(|l| l.starts_with("MemTotal:"))?;
    let mut parts = line["MemTotal:".len()..].split_whitespace();
    let n: u64 = parts.next()?.parse().ok()?;
    match parts.next() {
        Some("kB") => n.checked_mul(KIB),
        None => Some(n),
        Some(_) => None,
    }
}

/// A byte count shown with a binary unit ("1.50 GiB", "512 B").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Bytes(pub u64);

impl fmt::Display for Bytes {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let b = self.0;
        for (unit, name) in [(TIB, "TiB"), (GIB, "GiB"), (MIB, "MiB"), (KIB, "KiB")] {
            if b >= unit {
                return write!(f, "{:.2} {name}", b as f64 / unit as f64);
            }
        }
        write!(f, "{b} B")
    }
}

/// Parses a byte size as `--max-memory` takes it: a number (decimals allowed) and an optional
/// unit, `B`, `KiB`, `MiB`, `GiB`, `TiB` (powers of 1024) or `kB`, `MB`, `GB`, `TB` (powers of
/// 1000), case-insensitive, with or without a space: `4GiB`, `512 MiB`, `1.5GiB`, `1000000`.
/// Zero is refused (nothing would fit).
pub fn parse_byte_size(s: &str) -> Result<u64, String> {
    let t = s.trim();
    let split = t.find(|c: char| !(c.is_ascii_digit() || c == '.')).unwrap_or(t.len());
    let (number, unit) = (&t[..split], t[split..].trim());
    let scale = match unit.to_ascii_lowercase().as_str() {
        "" | "b" => 1,
        "kib" | "k" => KIB,
        "mib" | "m" => MIB,
        "gib" | "g" => GIB,
        "tib" | "t" => TIB,
        "kb" => 1_000,
        "mb" => 1_000_000,
        "gb" => 1_000_000_000,
        "tb" => 1_000_000_000_000,
        _ => return Err(format!("`{s}`: unknown unit `{unit}` (use B, KiB, MiB, GiB, TiB, or kB, MB, GB, TB), e.g. 4GiB")),
    };
    if number.is_empty() || number.matches('.').count() > 1 || number == "." {
        return Err(format!("`{s}` is not a size: give a number and a unit, e.g. 4GiB or 512MiB"));
    }
    let bytes = if number.contains('.') {
        let v: f64 = number.parse().map_err(|_| format!("`{s}` is not a size: e.g. 4GiB"))?;
        let b = v * scale as f64;
        if b >= u64::MAX as f64 {
            return Err(format!("`{s}` is too large"));
        }
        b.floor() as u64
    } else {
        let v: u64 = number.parse().map_err(|_| format!("`{s}` is too large"))?;
        v.checked_mul(scale).ok_or_else(|| format!("`{s}` is too large"))?
    };
    if bytes == 0 {
        return Err(format!("`{s}`: the limit must be more than 0 bytes"));
    }
    Ok(bytes)
}

/// Bytes of a mesh's arrays as the scene holds them (length × element size of each).
pub fn mesh_bytes(m: &Mesh) -> u64 {
    let per_vertex = m.positions.len() * size_of::<Vec3>()
        + m.normals.len() * size_of::<Vec3>()
        + m.uvs.len() * size_of::<Vec2>()
        + m.tangents.len() * size_of::<Vec4>()
        + m.colors.len() * size_of::<Vec3>();
    (per_vertex + m.indices.len() * size_of::<[u32; 3]>()) as u64
}

/// Bytes of a primitive sphere's mesh with `slices` × `stacks` before it is built:
/// (slices+1)(stacks+1) vertices with position, normal, UV and tangent (and the tangent pass's
/// two temporary vectors per vertex), 2·slices·(stacks−1) index triples.
pub fn sphere_bytes(slices: u32, stacks: u32) -> u64 {
    let vertices = (slices as u64 + 1) * (stacks as u64 + 1);
    let triangles = 2 * slices as u64 * (stacks as u64).saturating_sub(1);
    let vertex = (4 * size_of::<Vec3>() + size_of::<Vec2>() + size_of::<Vec4>()) as u64;
    vertices * vertex + triangles * size_of::<[u32; 3]>() as u64
}

/// Bytes of what a loaded scene holds: every object's meshes, every texture's mip levels, every
/// point cloud's centres and colours.
pub fn scene_bytes(scene: &Scene) -> u64 {
    let meshes: u64 = scene.objects.iter().flat_map(|o| &o.meshes).map(mesh_bytes).sum();
    let texels: u64 = scene.textures.iter().flat_map(|t| &t.levels).map(|l| l.texels.len() as u64 * 4).sum();
    let points: u64 = scene.point_clouds.iter().map(|c| (c.points.len() * size_of::<Vec3>() + c.colors.len() * 3) as u64).sum();
    meshes + texels + points
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::primitives;

    #[test]
    fn byte_sizes_parse() {
        assert_eq!(parse_byte_size("4GiB"), Ok(4 << 30));
        assert_eq!(parse_byte_size("4 gib"), Ok(4 << 30));
        assert_eq!(parse_byte_size("512MiB"), Ok(512 << 20));
        assert_eq!(parse_byte_size("64KiB"), Ok(64 << 10));
        assert_eq!(parse_byte_size("1000"), Ok(1000));
        assert_eq!(parse_byte_size("1000B"), Ok(1000));
        assert_eq!(parse_byte_size("1.5GiB"), Ok(3 << 29));
        assert_eq!(parse_byte_size("2GB"), Ok(2_000_000_000));
        assert_eq!(parse_byte_size("1TiB"), Ok(1 << 40));
        for bad in ["", "GiB", "4XB", "-1GiB", "0", "0GiB", "1.2.3GiB", ".", "99999999999999999999", "20000000TiB", "4 GiB extra"] {
            assert!(parse_byte_size(bad).is_err(), "{bad:?} accepted");
        }
        assert!(parse_byte_size("4XB").unwrap_err().contains("unknown unit `XB`"));
    }

    #[test]
    fn meminfo_total() {
        let text = "MemTotal:       24522124 kB\nMemFree:        17000000 kB\n";
        assert_eq!(mem_total(text), Some(24_522_124 * 1024));
        assert_eq!(mem_total("MemFree: 10 kB\n"), None);
        let l = MemoryLimit::default_for(Some(16 << 30));
        assert_eq!(l.bytes, (16u64 << 30) / 100 * 75);
        assert!(l.describe().contains("75% of this machine's 16.00 GiB"), "{}", l.describe());
        assert_eq!(MemoryLimit::default_for(None).bytes, FALLBACK_LIMIT);
    }

    #[test]
    fn bytes_display() {
        assert_eq!(Bytes(512).to_string(), "512 B");
        assert_eq!(Bytes(3 << 29).to_string(), "1.50 GiB");
        assert_eq!(Bytes(10 << 20).to_string(), "10.00 MiB");
    }

    #[test]
    fn sphere_estimate_matches_the_built_mesh() {
        // The estimate before building is the built mesh's size plus the tangent pass's two
        // temporary vectors per vertex.
        for (slices, stacks) in [(3, 2), (32, 16), (100, 7)] {
            let m = primitives::sphere(slices, stacks);
            let temporaries = m.positions.len() as u64 * 2 * 12;
            assert_eq!(sphere_bytes(slices, stacks), mesh_bytes(&m) + temporaries, "{slices}x{stacks}");
        }
        // Hand-computed: 4 × 3 vertices × 72 bytes + 2 · 3 · 1 triangles × 12 bytes.
        assert_eq!(sphere_bytes(3, 2), 12 * 72 + 6 * 12);
    }
}
