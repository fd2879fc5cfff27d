//! `path_record`: camera paths recorded in the viewer (`K` adds a keyframe at the current camera,
//! `Ctrl+S` writes them) as a `[camera_path]` block of the scene format, to paste into a scene
//! file for `hybrid bench` or `P`.

use std::io::Write;
use std::path::{Path, PathBuf};

use hybrid_scene::{Camera, Keyframe};

/// Shortest time between two recorded keyframes (s).
pub const MIN_KEY_GAP_S: f32 = 0.5;

/// Keyframes recorded so far.
#[derive(Debug, Default, Clone)]
pub struct PathRecorder {
    pub keyframes: Vec<Keyframe>,
}

impl PathRecorder {
    /// Adds a keyframe at `camera`. Its time follows the previous one by the time the fly camera
    /// takes to travel between them at `speed` (units per second), at least [`MIN_KEY_GAP_S`],
    /// so the path plays back at the speed it was flown.
    pub fn add(&mut self, camera: &Camera, speed: f32) -> &Keyframe {
        let time = match self.keyframes.last() {
            None => 0.0,
            Some(k) => {
                let dist = (camera.position - k.position).length();
                k.time + (dist / speed.max(1e-6)).max(MIN_KEY_GAP_S)
            }
        };
        self.keyframes.push(Keyframe { time, position: camera.position, target: camera.target });
        self.keyframes.last().expect("just pushed")
    }

    /// The keyframes as `[[camera_path.keyframe]]` tables.
    pub fn toml(&self) -> String {
        let v = |v: glam::Vec3| format!("[{:?}, {:?}, {:?}]", v.x, v.y, v.z);
        let mut t = String::new();
        for k in &self.keyframes {
            t.push_str(&format!(
                "[[camera_path.keyframe]]\ntime = {:?}\nposition = {}\ntarget = {}\n\n",
                k.time,
                v(k.position),
                v(k.target)
            ));
        }
        t
    }

    /// Writes the path into a new file beside `scene` (the current folder for the built-in demo):
    /// `<scene stem>-path.toml`, or `-path-2.toml`, `-path-3.toml`, … when taken. Never
    /// overwrites a file (the scene file included). Returns the file written.
    pub fn save_beside(&self, scene: Option<&Path>) -> Result<PathBuf, String> {
        if self.keyframes.len() < 2 {
            return Err(format!(
                "a camera path needs at least 2 keyframes, {} recorded: press K at each point of the path first",
                self.keyframes.len()
            ));
        }
        let (dir, stem) = match scene {
            Some(p) => (
                p.parent().map(Path::to_path_buf).unwrap_or_default(),
                p.file_stem().map_or("scene".into(), |s| s.to_string_lossy().into_owned()),
            ),
            None => (PathBuf::new(), "demo".to_string()),
        };
        let header = format!(
            "# Camera path recorded in `hybrid view` ({} keyframes, {:.1} s). Paste this block into\n# {} to play it with P or measure it with `hybrid bench`.\n\n",
            self.keyframes.len(),
            self.keyframes.last().map_or(0.0, |k| k.time),
            scene.map_or("a scene file".to_string(), |p| p.display().to_string()),
        );
        for n in 1..1000 {
            let name = if n == 1 { format!("{stem}-path.toml") } else { format!("{stem}-path-{n}.toml") };
            let path = dir.join(name);
            match std::fs::OpenOptions::new().write(true).create_new(true).open(&path) {
                Ok(mut f) => {
                    f.write_all(header.as_bytes())
                        .and_then(|_| f.write_all(self.toml().as_bytes()))
                        .map_err(|e| format!("{}: cannot write the camera path: {e}", path.display()))?;
                    return Ok(path);
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
                Err(e) => return Err(format!("{}: cannot create the camera path file: {e}", path.display())),
            }
        }
        Err(format!("{}: 999 camera path files already exist beside it", dir.join(stem).display()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn cam(p: Vec3) -> Camera {
        Camera { position: p, target: p + Vec3::NEG_Z, ..Camera::default() }
    }

    #[test]
    fn keyframe_times_follow_the_flying_speed() {
        let mut r = PathRecorder::default();
        assert_eq!(r.add(&cam(Vec3::ZERO), 2.0).time, 0.0);
        // 6 units at 2 units/s: 3 s later.
        assert_eq!(r.add(&cam(Vec3::new(6.0, 0.0, 0.0)), 2.0).time, 3.0);
        // Standing still: the minimum gap.
        assert_eq!(r.add(&cam(Vec3::new(6.0, 0.0, 0.0)), 2.0).time, 3.0 + MIN_KEY_GAP_S);
    }

    #[test]
    fn saved_block_parses_back_as_the_scene_files_camera_path_and_never_overwrites() {
        let dir = tempfile::tempdir().unwrap();
        let scene = dir.path().join("room.toml");
        std::fs::write(&scene, "# the scene\n").unwrap();
        let mut r = PathRecorder::default();
        assert!(r.save_beside(Some(&scene)).is_err(), "one keyframe is not a path");
        r.add(&cam(Vec3::new(0.0, 1.0, 5.0)), 1.0);
        r.add(&cam(Vec3::new(0.25, 1.5, 2.0)), 1.0);
        let first = r.save_beside(Some(&scene)).unwrap();
        let second = r.save_beside(Some(&scene)).unwrap();
        assert_eq!(first, dir.path().join("room-path.toml"));
        assert_eq!(second, dir.path().join("room-path-2.toml"));
        assert_eq!(std::fs::read_to_string(&scene).unwrap(), "# the scene\n");
        // The block, appended to a scene, is read back as the same keyframes.
        let text = format!("[camera]\nposition = [0, 1, 5]\ntarget = [0, 0, 0]\n\n{}", std::fs::read_to_string(&first).unwrap());
        let parsed = hybrid_scene::parse_scene(&text, &first).unwrap();
        let path = parsed.camera_path.expect("camera path");
        assert_eq!(path.keyframes.len(), 2);
        for (a, b) in path.keyframes.iter().zip(&r.keyframes) {
            assert_eq!((a.time, a.position, a.target), (b.time, b.position, b.target));
        }
    }
}
