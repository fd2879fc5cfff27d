//! `action`: everything the viewer can be asked to do besides flying the camera — from a key, an
//! overlay control, a dropped file or a `--script` line. One type, applied in one place
//! (`App::apply`), so a scripted test exercises the same code as a click.

use std::path::PathBuf;

use hybrid_core::Mode;
use hybrid_core::buffer_view::BufferKind;
use hybrid_cpu::capsule::PrimaryVisibility;
use hybrid_scene::{Budget, Policy};

#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    SetMode(Mode),
    /// The buffer shown full-window (`Final`: the frame itself).
    SetBuffer(BufferKind),
    SetBudget(Budget),
    SetPolicy(Policy),
    /// The heuristic's I.
    SetImportance(f32),
    /// Object `id`'s K (static relevance) and E (estimated cost), in place of the scene file's.
    SetObjectWeights(usize, f32, f32),
    /// Tint and outline the object with this id (index in the scene's object list).
    Highlight(Option<u32>),
    SetClipCapsule(bool),
    SetSphereEffects(bool),
    /// `--fallback`: what unselected objects get (raster fallbacks or nothing).
    SetFallback(hybrid_core::fallback::Fallback),
    SetPrimaryVisibility(PrimaryVisibility),
    /// Light `i` (directional, then point, then spot lights, in the scene file's order) on or off.
    SetLight(usize, bool),
    /// `F`: frame the scene's bounds.
    FrameBounds,
    /// `R`: back to the scene file's camera.
    Home,
    /// `O`: orbit around the point under the cursor (or leave orbiting).
    ToggleOrbit,
    /// `P`: play the scene's `[camera_path]` (or stop).
    PlayPath,
    /// `K`: a keyframe at the current camera.
    AddKeyframe,
    /// `Ctrl+S`: write the recorded keyframes beside the scene.
    SavePath,
    /// `F12` (a numbered file in the current folder) or a script's path.
    Screenshot(Option<PathBuf>),
    /// `Tab`.
    ToggleOverlay,
    /// A dropped file: a scene or a bare model.
    Open(PathBuf),
}

/// Parses the value of a `--budget`-style setting: `unlimited`, a cost (`250`) or milliseconds
/// (`4ms`).
pub fn parse_budget(s: &str) -> Result<Budget, String> {
    let bad = || format!("`{s}` is not a budget (unlimited, a cost such as 250, or milliseconds such as 4ms)");
    if s.eq_ignore_ascii_case("unlimited") {
        return Ok(Budget::Unlimited);
    }
    let (num, ms) = match s.strip_suffix("ms") {
        Some(n) => (n, true),
        None => (s, false),
    };
    let v: f64 = num.parse().map_err(|_| bad())?;
    if !v.is_finite() || v < 0.0 || (ms && v == 0.0) {
        return Err(bad());
    }
    Ok(if ms { Budget::Millis(v) } else { Budget::Cost(v) })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn budgets_parse() {
        assert_eq!(parse_budget("unlimited"), Ok(Budget::Unlimited));
        assert_eq!(parse_budget("250"), Ok(Budget::Cost(250.0)));
        assert_eq!(parse_budget("0"), Ok(Budget::Cost(0.0)));
        assert_eq!(parse_budget("4.5ms"), Ok(Budget::Millis(4.5)));
        for bad in ["-1", "ms", "0ms", "x", "nan", "inf"] {
            assert!(parse_budget(bad).is_err(), "{bad}");
        }
    }
}
