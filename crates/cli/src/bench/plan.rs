//! The bench's plan, checked before anything is rendered or written: the flags, and the
//! cameras of the path set.

use super::*;

/// One camera of a pass: where it is and, on a path, at what path time.
#[derive(Clone, Copy)]
pub(super) struct Shot {
    pub(super) time: Option<f32>,
    pub(super) camera: Camera,
}

/// The checked plan of a bench run: everything is validated before anything is rendered or written.
pub(super) struct Plan {
    pub(super) path_shots: Option<Vec<Shot>>,
    pub(super) path_seconds: Option<f32>,
}

/// FLIP's working memory per pixel: the two RGB8 images as floats, its colour and feature
/// pipelines' intermediate images and the error map (about six float RGB images).
pub(super) const FLIP_BYTES_PER_PIXEL: u64 = 6 * 12 + 4;

impl Plan {
    /// Memory per pixel beyond one frame: the RGB images kept for FLIP at once (the path's
    /// rt-only references and one pass's frames, every `flip_every`-th; the static set's last
    /// frame of up to four modes and its reference) at 3 bytes a pixel, and FLIP's own.
    pub(super) fn extra_bytes_per_pixel(&self, flip_every: u32) -> u64 {
        let path_frames = self.path_shots.as_ref().map_or(0, |s| s.len().div_ceil(flip_every.max(1) as usize)) as u64;
        3 * (2 * path_frames + 5) + FLIP_BYTES_PER_PIXEL
    }
}

pub(super) fn check_args(args: &BenchArgs) -> Result<(), CliError> {
    if !(args.fps.is_finite() && args.fps > 0.0 && args.fps <= 1000.0) {
        return Err(CliError::bad_input(format!("--fps must be a number of frames per second in (0, 1000], got {}", args.fps)));
    }
    if let Some(s) = args.path_seconds
        && !(s.is_finite() && s > 0.0)
    {
        return Err(CliError::bad_input(format!("--path-seconds must be a positive number of seconds, got {s}")));
    }
    if args.modes.is_empty() {
        return Err(CliError::bad_input("--modes needs at least one mode (hybrid, all, rt-only, raster)"));
    }
    args.heuristic.check()?;
    if args.threads == Some(0) {
        return Err(CliError::bad_input("--threads must be at least 1"));
    }
    if args.sweep_budget && !args.modes.iter().any(|m| matches!(m, Mode::Hybrid | Mode::All)) {
        return Err(CliError::bad_input("--sweep-budget needs `hybrid` or `all` in --modes (for the all-selected cost)"));
    }
    Ok(())
}

pub(super) fn plan(args: &BenchArgs, scene: &Scene, name: &str) -> Result<Plan, CliError> {
    let Some(path) = scene.camera_path.as_ref() else {
        if let Some(s) = args.path_seconds {
            return Err(CliError::bad_input(format!("--path-seconds {s}: {name} has no [camera_path]")));
        }
        return Ok(Plan { path_shots: None, path_seconds: None });
    };
    let duration = path.duration();
    let seconds = match args.path_seconds {
        Some(s) if s > duration + 1e-3 => {
            return Err(CliError::bad_input(format!("--path-seconds {s}: the camera path of {name} is only {duration} s long")));
        }
        Some(s) => s,
        None => DEFAULT_PATH_SECONDS.min(duration),
    };
    let start = path.keyframes.first().map_or(0.0, |k| k.time);
    let count = ((seconds * args.fps).round() as usize).max(1);
    let shots = (0..count)
        .map(|i| {
            let t = start + i as f32 / args.fps;
            Shot { time: Some(t), camera: path.camera_at(&scene.camera, t) }
        })
        .collect();
    Ok(Plan { path_shots: Some(shots), path_seconds: Some(seconds) })
}
