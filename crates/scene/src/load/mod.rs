//! Loaders for model files (glTF 2.0, OBJ+MTL, PLY), point clouds (PLY, LAS/LAZ) and textures
//! (PNG, JPEG). The format is chosen by the file extension (case-insensitive).
//!
//! Every failure is a [`SceneError`] naming the file and what is wrong; no input file makes these
//! functions panic, hang or allocate more than the file can hold (pre-allocation is capped by
//! the file size). See `docs/loaders.md` for the material mappings.

// The public API returns the crate's `SceneError` by value (it carries miette source context);
// errors are rare and per file, so their size does not matter here.
#![allow(clippy::result_large_err)]

mod gltf;
mod gltf_check;
mod image;
mod las;
mod obj;
mod ply;

use std::path::Path;

use glam::Vec3;

use crate::{ColorSpace, Material, Mesh, SceneError, Texture};

/// Lower-case extension of `path` (empty if none).
pub(crate) fn extension(path: &Path) -> String {
    path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase()
}

/// Meshes of a model file (object space; glTF node transforms applied), with the file's
/// materials appended to `materials` and its textures to `textures`. One mesh per glTF
/// primitive / OBJ group and material / PLY file. The meshes' `material` indices point into
/// `materials` (after the append). A file without materials gets one default material appended.
///
/// On error, `materials` and `textures` are left as they were.
pub fn load_model(path: &Path, materials: &mut Vec<Material>, textures: &mut Vec<Texture>) -> Result<Vec<Mesh>, SceneError> {
    let (m0, t0) = (materials.len(), textures.len());
    let result = match extension(path).as_str() {
        "gltf" | "glb" => gltf::load(path, materials, textures),
        "obj" => obj::load(path, materials, textures),
        "ply" => ply::load_mesh(path, materials),
        "" => Err(SceneError::new(path, "model file has no extension (expected .gltf, .glb, .obj or .ply)")),
        other => Err(SceneError::new(path, format!("unsupported model format `.{other}` (expected .gltf, .glb, .obj or .ply)"))),
    };
    match result {
        Ok(meshes) => {
            debug_assert!(meshes.iter().all(|m| m.material < materials.len()));
            Ok(meshes)
        }
        Err(e) => {
            materials.truncate(m0);
            textures.truncate(t0);
            Err(e)
        }
    }
}

/// Points (and per-point sRGB colours if the file has them, else empty) of a PLY or LAS/LAZ file,
/// in the file's own coordinates (scans are often Z-up: rotate them in the scene file).
pub fn load_point_cloud(path: &Path) -> Result<(Vec<Vec3>, Vec<[u8; 3]>), SceneError> {
    match extension(path).as_str() {
        "ply" => ply::load_points(path),
        "las" | "laz" => las::load(path),
        "" => Err(SceneError::new(path, "point-cloud file has no extension (expected .ply, .las or .laz)")),
        other => Err(SceneError::new(path, format!("unsupported point-cloud format `.{other}` (expected .ply, .las or .laz)"))),
    }
}

/// A PNG or JPEG texture with its mip chain.
pub fn load_texture(path: &Path, color_space: ColorSpace) -> Result<Texture, SceneError> {
    image::load(path, color_space)
}

/// Largest scene (TOML) file read: scene files are hand-written text.
pub const MAX_SCENE_FILE_BYTES: u64 = 16 << 20;
/// Largest OBJ material library (MTL) read.
pub const MAX_MTL_BYTES: u64 = 64 << 20;
/// Largest model or point-cloud file (glTF/GLB, OBJ, PLY, LAS/LAZ) and glTF buffer read.
pub const MAX_MODEL_BYTES: u64 = 4 << 30;
/// Largest texture file (PNG, JPEG) read.
pub const MAX_TEXTURE_FILE_BYTES: u64 = 512 << 20;

/// Checks that `path` is a regular file (not a folder, pipe or device such as `/dev/zero`, which
/// would be read until memory runs out) of at most `max` bytes; returns its length. `what` names
/// the kind of file in the message.
pub(crate) fn check_file(path: &Path, what: &str, max: u64) -> Result<u64, SceneError> {
    let meta = std::fs::metadata(path).map_err(|e| SceneError::new(path, format!("cannot open {what}: {e}")))?;
    if !meta.is_file() {
        return Err(SceneError::new(path, format!("{what} is not a regular file")));
    }
    if meta.len() > max {
        return Err(SceneError::new(path, format!("{what} is {} bytes, above the limit of {max} bytes for a {what}", meta.len())));
    }
    Ok(meta.len())
}

/// Reads a whole file after [`check_file`], never more than `max` bytes (the file may grow
/// between the check and the read).
pub(crate) fn read_capped(path: &Path, what: &str, max: u64) -> Result<Vec<u8>, SceneError> {
    use std::io::Read;
    let len = check_file(path, what, max)?;
    let file = std::fs::File::open(path).map_err(|e| SceneError::new(path, format!("cannot read {what}: {e}")))?;
    let mut bytes = Vec::with_capacity(usize::try_from(len).unwrap_or(0));
    file.take(max + 1).read_to_end(&mut bytes).map_err(|e| SceneError::new(path, format!("cannot read {what}: {e}")))?;
    if bytes.len() as u64 > max {
        return Err(SceneError::new(path, format!("{what} grew above the limit of {max} bytes while being read")));
    }
    Ok(bytes)
}

/// Capacity to reserve for `declared` records of at least `min_bytes` each when `available`
/// bytes remain: never more than the file could hold, so a lying header cannot make us allocate.
pub(crate) fn capped_capacity(declared: usize, min_bytes: usize, available: u64) -> usize {
    let fit = available / (min_bytes.max(1) as u64);
    declared.min(usize::try_from(fit).unwrap_or(usize::MAX))
}

/// The first non-finite component of a vertex, as an error message, if any.
pub(crate) fn check_finite(what: &str, index: usize, v: Vec3) -> Result<(), String> {
    if v.is_finite() { Ok(()) } else { Err(format!("{what} {index} is not finite ({}, {}, {})", v.x, v.y, v.z)) }
}

/// Checks that every index of `indices` is below `vertex_count`.
pub(crate) fn check_indices(indices: &[[u32; 3]], vertex_count: usize) -> Result<(), String> {
    for (t, tri) in indices.iter().enumerate() {
        for &i in tri {
            if i as usize >= vertex_count {
                return Err(format!("triangle {t} uses vertex index {i}, but there are only {vertex_count} vertices"));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn capacity_is_capped_by_the_bytes_left() {
        assert_eq!(capped_capacity(35_947, 12, 0), 0);
        assert_eq!(capped_capacity(35_947, 12, 120), 10);
        assert_eq!(capped_capacity(10, 12, 1_000_000), 10);
        assert_eq!(capped_capacity(usize::MAX, 0, 5), 5);
    }

    #[test]
    fn special_and_oversized_files_are_refused() {
        let e = read_capped(Path::new("/dev/zero"), "model file", MAX_MODEL_BYTES).unwrap_err();
        assert!(e.to_string().contains("/dev/zero") && e.message.contains("not a regular file"), "{e}");
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("big.mtl");
        std::fs::write(&f, vec![b'#'; 100]).unwrap();
        let e = read_capped(&f, "material library", 10).unwrap_err();
        assert!(e.message.contains("limit of 10 bytes"), "{e}");
        assert_eq!(read_capped(&f, "material library", 100).unwrap().len(), 100);
        assert!(check_file(dir.path(), "scene file", 100).unwrap_err().message.contains("not a regular file"));
    }

    #[test]
    fn index_check_names_the_triangle() {
        assert!(check_indices(&[[0, 1, 2]], 3).is_ok());
        let e = check_indices(&[[0, 1, 2], [0, 2, 3]], 3).unwrap_err();
        assert!(e.contains("triangle 1") && e.contains("index 3"), "{e}");
    }

    #[test]
    fn unknown_extensions_are_rejected_with_the_file_name() {
        let mut m = Vec::new();
        let mut t = Vec::new();
        let e = load_model(Path::new("thing.fbx"), &mut m, &mut t).unwrap_err();
        assert!(e.to_string().contains("thing.fbx") && e.message.contains(".fbx"), "{e}");
        let e = load_point_cloud(Path::new("cloud.xyz")).unwrap_err();
        assert!(e.to_string().contains("cloud.xyz"), "{e}");
        assert!(m.is_empty() && t.is_empty());
    }
}
