//! `script`: `--script FILE`, a text file of input events for tests and demos, one per line
//! (`#` starts a comment). Events run in order; `wait N` lets N frames pass. Key and mouse
//! events go through the same input handling as the window's own events.
//!
//! ```text
//! key-down W          # key names: W A S D Q E R F O P K Shift Tab F12 Ctrl+S (case-insensitive)
//! key-up W
//! press R             # down then up
//! mouse-move X Y      # the cursor to window pixel (X, Y) (the point `O` orbits)
//! mouse-drag DX DY    # right-button drag (look, or orbit in orbit mode) by DX, DY pixels
//! scroll N            # N wheel notches (speed)
//! wait N              # let N frames render
//! wait-ms N           # let frames render for N milliseconds of wall-clock time
//! resize W H          # ask the window for a new inner size
//! screenshot PATH     # the frame at full window size (no overlay) as PNG, report JSON beside it
//! set mode hybrid     # what the overlay's controls set: mode hybrid|all|rt-only|raster,
//! set budget 250      #   budget unlimited|COST|MSms, policy paper|knapsack, importance I,
//! set buffer mask     #   buffer NAME (a --dump name), clip on|off, sphere-effects on|off, fallback raster|none,
//!                     #   primary-visibility auto|projected|bvh, light N on|off (N from 1)
//! weights N K E       # object N's K (static relevance) and E (estimated cost), as in the table
//! highlight N         # tint object N (index in the scene's object list), or `highlight none`
//! open PATH           # open a scene or model, as dropping it on the window does
//! print-selection     # prints `selection: budget B spent S selected [ids]` of the last frame
//! print-camera        # prints `camera: position X Y Z target X Y Z`
//! print-memory        # prints `memory: VmRSS N kB frame F`
//! print-frame         # prints the backend, the CPU backend's moving scale, mean and last frame time and size
//! quit
//! ```

use std::path::{Path, PathBuf};

use hybrid_core::Mode;
use hybrid_core::buffer_view::BufferKind;
use hybrid_cpu::capsule::PrimaryVisibility;
use hybrid_scene::Policy;

use crate::action::{Action, parse_budget};

#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    KeyDown(String),
    KeyUp(String),
    Press(String),
    /// The cursor's position in the window (pixels), for `O`.
    MouseMove(f32, f32),
    MouseDrag(f32, f32),
    Scroll(f32),
    Wait(u32),
    /// Frames pass until this many milliseconds of wall-clock time have (for tests that drive
    /// the window from outside, e.g. with xdotool).
    WaitMs(u32),
    Resize(u32, u32),
    Screenshot(PathBuf),
    PrintCamera,
    PrintMemory,
    PrintFrame,
    PrintSelection,
    /// What an overlay control, `highlight` or `open` does.
    Do(Action),
    Quit,
}

/// Key names scripts may use.
pub const KEYS: &[&str] = &["w", "a", "s", "d", "q", "e", "r", "f", "o", "p", "k", "shift", "tab", "f12", "ctrl+s"];

/// Parses a script; errors name the file and line.
pub fn parse(path: &Path, text: &str) -> Result<Vec<Event>, String> {
    let mut events = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = raw.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let err = |what: &str| format!("{}:{}: {what} (in `{line}`)", path.display(), i + 1);
        let mut words = line.split_whitespace();
        let cmd = words.next().unwrap_or("").to_ascii_lowercase();
        let args: Vec<&str> = words.collect();
        let want =
            |n: usize| if args.len() == n { Ok(()) } else { Err(err(&format!("`{cmd}` takes {n} argument(s), got {}", args.len()))) };
        let key = |s: &str| {
            let k = s.to_ascii_lowercase();
            if KEYS.contains(&k.as_str()) { Ok(k) } else { Err(err(&format!("unknown key `{s}` (known: {})", KEYS.join(" ")))) }
        };
        let num = |s: &str| s.parse::<f32>().ok().filter(|v| v.is_finite()).ok_or_else(|| err(&format!("`{s}` is not a number")));
        let count = |s: &str| s.parse::<u32>().map_err(|_| err(&format!("`{s}` is not a whole number ≥ 0")));
        events.push(match cmd.as_str() {
            "key-down" => {
                want(1)?;
                Event::KeyDown(key(args[0])?)
            }
            "key-up" => {
                want(1)?;
                Event::KeyUp(key(args[0])?)
            }
            "press" => {
                want(1)?;
                Event::Press(key(args[0])?)
            }
            "mouse-move" => {
                want(2)?;
                Event::MouseMove(num(args[0])?, num(args[1])?)
            }
            "mouse-drag" => {
                want(2)?;
                Event::MouseDrag(num(args[0])?, num(args[1])?)
            }
            "scroll" => {
                want(1)?;
                Event::Scroll(num(args[0])?)
            }
            "wait" => {
                want(1)?;
                Event::Wait(count(args[0])?)
            }
            "wait-ms" => {
                want(1)?;
                Event::WaitMs(count(args[0])?)
            }
            "resize" => {
                want(2)?;
                let (w, h) = (count(args[0])?, count(args[1])?);
                if w == 0 || h == 0 || w > 16384 || h > 16384 {
                    return Err(err("sizes must be between 1 and 16384"));
                }
                Event::Resize(w, h)
            }
            "screenshot" => {
                if args.is_empty() {
                    return Err(err("`screenshot` needs a PNG path"));
                }
                Event::Screenshot(PathBuf::from(args.join(" ")))
            }
            "print-camera" => {
                want(0)?;
                Event::PrintCamera
            }
            "print-frame" => {
                want(0)?;
                Event::PrintFrame
            }
            "print-memory" => {
                want(0)?;
                Event::PrintMemory
            }
            "print-selection" => {
                want(0)?;
                Event::PrintSelection
            }
            "weights" => {
                want(3)?;
                let (k, e) = (num(args[1])?, num(args[2])?);
                if k < 0.0 || e < 0.0 {
                    return Err(err("K and E must be ≥ 0"));
                }
                Event::Do(Action::SetObjectWeights(count(args[0])? as usize, k, e))
            }
            "highlight" => {
                want(1)?;
                Event::Do(Action::Highlight(if args[0].eq_ignore_ascii_case("none") { None } else { Some(count(args[0])?) }))
            }
            "open" => {
                if args.is_empty() {
                    return Err(err("`open` needs a scene or model path"));
                }
                Event::Do(Action::Open(PathBuf::from(args.join(" "))))
            }
            "set" => {
                let on_off = |v: &str| match v {
                    "on" => Ok(true),
                    "off" => Ok(false),
                    _ => Err(err(&format!("`{v}` is not on or off"))),
                };
                if args.first() == Some(&"light") {
                    if args.len() != 3 {
                        return Err(err("`set light` takes a light number (from 1) and on|off: `set light 1 off`"));
                    }
                    let n = count(args[1])?;
                    if n == 0 {
                        return Err(err("lights are numbered from 1"));
                    }
                    events.push(Event::Do(Action::SetLight(n as usize - 1, on_off(args[2])?)));
                    continue;
                }
                want(2)?;
                let v = args[1];
                Event::Do(match args[0] {
                    "mode" => {
                        Action::SetMode(Mode::ALL.into_iter().find(|m| m.name() == v).ok_or_else(|| err(&format!("unknown mode `{v}`")))?)
                    }
                    "budget" => Action::SetBudget(parse_budget(v).map_err(|e| err(&e))?),
                    "policy" => Action::SetPolicy(match v {
                        "paper" => Policy::Paper,
                        "knapsack" => Policy::Knapsack,
                        _ => return Err(err(&format!("unknown policy `{v}` (paper, knapsack)"))),
                    }),
                    "importance" => Action::SetImportance(num(v)?),
                    "buffer" => Action::SetBuffer(BufferKind::from_name(v).ok_or_else(|| {
                        let names: Vec<_> = BufferKind::ALL.iter().map(|k| k.name()).collect();
                        err(&format!("unknown buffer `{v}` (known: {})", names.join(" ")))
                    })?),
                    "clip" => Action::SetClipCapsule(on_off(v)?),
                    "sphere-effects" => Action::SetSphereEffects(on_off(v)?),
                    "fallback" => Action::SetFallback(
                        hybrid_core::fallback::Fallback::parse(v)
                            .ok_or_else(|| err(&format!("`fallback` takes raster or none, got `{v}`")))?,
                    ),
                    "primary-visibility" => Action::SetPrimaryVisibility(match v {
                        "auto" => PrimaryVisibility::Auto,
                        "projected" => PrimaryVisibility::Projected,
                        "bvh" => PrimaryVisibility::Bvh,
                        _ => return Err(err(&format!("unknown primary visibility `{v}` (auto, projected, bvh)"))),
                    }),
                    other => return Err(err(&format!("unknown setting `{other}`"))),
                })
            }
            "quit" => {
                want(0)?;
                Event::Quit
            }
            other => return Err(err(&format!("unknown event `{other}`"))),
        });
    }
    Ok(events)
}

/// Resident memory of this process in kB (`VmRSS` of /proc/self/status), where available.
pub fn resident_kb() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmRSS:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_events_and_names_bad_lines() {
        let p = Path::new("s.txt");
        let ev = parse(p, "# hi\nkey-down w\nwait 3 # frames\nscreenshot a b.png\nresize 64 48\nquit\n").unwrap();
        assert_eq!(
            ev,
            vec![
                Event::KeyDown("w".into()),
                Event::Wait(3),
                Event::Screenshot(PathBuf::from("a b.png")),
                Event::Resize(64, 48),
                Event::Quit
            ]
        );
        let e = parse(p, "wait\n").unwrap_err();
        assert!(e.starts_with("s.txt:1:"), "{e}");
        assert!(parse(p, "key-down z\n").unwrap_err().contains("unknown key"));
        assert!(parse(p, "jump\n").unwrap_err().contains("unknown event"));
        assert!(parse(p, "wait -1\n").is_err());
    }

    #[test]
    fn parses_settings_as_actions() {
        let p = Path::new("s.txt");
        let ev =
            parse(p, "set budget 12ms\nset buffer mask\nset light 2 off\nhighlight 3\nhighlight none\nset mode rt-only\npress ctrl+s\nset fallback none\nset buffer shadow_fallback\n")
                .unwrap();
        assert_eq!(
            ev,
            vec![
                Event::Do(Action::SetBudget(hybrid_scene::Budget::Millis(12.0))),
                Event::Do(Action::SetBuffer(BufferKind::Mask)),
                Event::Do(Action::SetLight(1, false)),
                Event::Do(Action::Highlight(Some(3))),
                Event::Do(Action::Highlight(None)),
                Event::Do(Action::SetMode(Mode::RtOnly)),
                Event::Press("ctrl+s".into()),
                Event::Do(Action::SetFallback(hybrid_core::fallback::Fallback::None)),
                Event::Do(Action::SetBuffer(BufferKind::ShadowFallback)),
            ]
        );
        for bad in [
            "set budget -3",
            "set buffer nope",
            "set light 0 on",
            "set light 1",
            "set clip maybe",
            "set speed 3",
            "set mode fast",
            "set fallback rays",
        ] {
            assert!(parse(p, bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn reads_resident_memory() {
        assert!(resident_kb().unwrap_or(1) > 0);
    }
}
