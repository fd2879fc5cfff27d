//! Loaders for model files, point clouds and textures. STUB: being written.

use std::path::Path;

use glam::Vec3;

use crate::{ColorSpace, Material, Mesh, SceneError, Texture};

/// Meshes of a model file (object space; glTF node transforms applied), with the file's
/// materials appended to `materials` and its textures to `textures`.
pub fn load_model(path: &Path, _materials: &mut Vec<Material>, _textures: &mut Vec<Texture>) -> Result<Vec<Mesh>, SceneError> {
    Err(SceneError::new(path, "model loading is not implemented yet"))
}

/// Points (and per-point sRGB colours if the file has them, else empty) of a PLY or LAS/LAZ file.
pub fn load_point_cloud(path: &Path) -> Result<(Vec<Vec3>, Vec<[u8; 3]>), SceneError> {
    Err(SceneError::new(path, "point clouds are not implemented yet"))
}

/// A PNG or JPEG texture with its mip chain.
pub fn load_texture(path: &Path, _color_space: ColorSpace) -> Result<Texture, SceneError> {
    Err(SceneError::new(path, "textures are not implemented yet"))
}
