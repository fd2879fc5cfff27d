//! `script`: `--script FILE`, a text file of input events for tests and demos, one per line
//! (`#` starts a comment). Events run in order; `wait N` lets N frames pass. Key and mouse
//! events go through the same input handling as the window's own events.
//!
//! ```text
//! key-down W          # key names: W A S D Q E R F Shift Tab F12 (case-insensitive)
//! key-up W
//! press R             # down then up
//! mouse-drag DX DY    # right-button drag (look) by DX, DY pixels
//! scroll N            # N wheel notches (speed)
//! wait N              # let N frames render
//! resize W H          # ask the window for a new inner size
//! screenshot PATH     # the frame at full window size (no overlay) as PNG, report JSON beside it
//! print-camera        # prints `camera: position X Y Z target X Y Z`
//! print-memory        # prints `memory: VmRSS N kB frame F`
//! print-frame         # prints the backend, the CPU backend's moving scale, mean and last frame time and size
//! quit
//! ```

use std::path::{Path, PathBuf};

#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    KeyDown(String),
    KeyUp(String),
    Press(String),
    MouseDrag(f32, f32),
    Scroll(f32),
    Wait(u32),
    Resize(u32, u32),
    Screenshot(PathBuf),
    PrintCamera,
    PrintMemory,
    PrintFrame,
    Quit,
}

/// Key names scripts may use.
pub const KEYS: &[&str] = &["w", "a", "s", "d", "q", "e", "r", "f", "shift", "tab", "f12"];

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
    fn reads_resident_memory() {
        assert!(resident_kb().unwrap_or(1) > 0);
    }
}
