//! TOML scene files (DESIGN §6, reference: docs/scene-format.md). STUB: being written.

use std::path::Path;

use crate::{Scene, SceneError};

/// The built-in demo scene's TOML (also `scenes/demo.toml`). Refers to no external file.
pub const DEMO_SCENE_TOML: &str = include_str!("../../../scenes/demo.toml");

/// Loads and validates a scene file; relative paths inside are relative to the file.
pub fn load_scene(path: &Path) -> Result<Scene, SceneError> {
    let text = std::fs::read_to_string(path).map_err(|e| SceneError::new(path, format!("cannot read scene file: {e}")))?;
    parse_scene(&text, path)
}

/// Parses scene TOML `text`; `path` names it in errors and is the base of relative paths.
pub fn parse_scene(_text: &str, path: &Path) -> Result<Scene, SceneError> {
    Err(SceneError::new(path, "scene files are not implemented yet"))
}

/// The built-in demo scene.
pub fn demo_scene() -> Scene {
    parse_scene(DEMO_SCENE_TOML, Path::new("<built-in demo.toml>")).expect("the built-in demo scene is valid")
}
