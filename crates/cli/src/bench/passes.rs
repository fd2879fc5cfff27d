//! Running the bench: one pass is one mode over a list of cameras with a fresh renderer, after
//! warm-up frames; FLIP against the rt-only reference.

use super::*;

/// What one pass produced: its records and the RGB images of the frames asked for.
pub(super) struct Pass {
    pub(super) records: Vec<FrameRecord>,
    pub(super) images: BTreeMap<usize, Vec<u8>>,
    /// Resident memory after the pass's frame [`RSS_FRAME`] and after its last frame, for
    /// passes that long (a soak: growth after the first frames is a leak).
    pub(super) rss: Option<RssSample>,
}

/// The frame after which a pass's resident memory is first sampled.
pub(super) const RSS_FRAME: usize = 100;

/// Resident memory (`VmRSS`, KiB) of a pass after frame [`RSS_FRAME`] and at its end.
#[derive(Debug, Clone, Copy, Serialize)]
pub(super) struct RssSample {
    pub(super) frame_100_kib: u64,
    pub(super) end_kib: u64,
    pub(super) frames: usize,
    /// What the bench itself kept after frame 100 by design: one [`FrameRecord`] per frame and
    /// the RGB images kept for FLIP, in bytes.
    pub(super) kept_bytes: u64,
}

impl RssSample {
    /// Growth from frame 100 to the end, as a fraction.
    pub(super) fn growth(&self) -> f64 {
        self.end_kib as f64 / self.frame_100_kib.max(1) as f64 - 1.0
    }

    /// [`Self::growth`] less what the bench kept by design ([`Self::kept_bytes`]): the part a
    /// leak would show in.
    pub(super) fn growth_beyond_kept(&self) -> f64 {
        (self.end_kib as f64 - self.kept_bytes as f64 / 1024.0) / self.frame_100_kib.max(1) as f64 - 1.0
    }
}

/// This process's resident memory in KiB (`VmRSS` of `/proc/self/status`; `None` elsewhere).
pub(super) fn vm_rss_kib() -> Option<u64> {
    parse_vm_rss(&std::fs::read_to_string("/proc/self/status").ok()?)
}

fn parse_vm_rss(status: &str) -> Option<u64> {
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    let mut parts = line["VmRSS:".len()..].split_whitespace();
    let kib = parts.next()?.parse().ok()?;
    (parts.next() == Some("kB")).then_some(kib)
}

pub(super) struct Bench {
    pub(super) scene_name: String,
    pub(super) size: (u32, u32),
    pub(super) quiet: bool,
    pub(super) backend: Backend,
    /// The render options of every pass (a cell: the budget sweep switches `--fallback`).
    pub(super) options: std::cell::Cell<RenderOptions>,
    /// One bar over every frame of the run (warm-ups included): set, mode, frame n of N, ETA.
    /// Hidden with `--quiet` and when stderr is not a terminal.
    pub(super) progress: ProgressBar,
}

impl Bench {
    /// Renders `shots` in `mode` with a fresh renderer (after the warm-up), keeping the images of
    /// the frames for which `keep` is true.
    pub(super) fn pass(
        &self,
        scene: &Scene,
        set: &'static str,
        mode: Mode,
        shots: &[Shot],
        keep: &dyn Fn(usize) -> bool,
    ) -> Result<Pass, CliError> {
        let what = if set == "sweep" {
            let budget = match scene.heuristic.budget {
                Budget::Unlimited => "unlimited".to_string(),
                Budget::Cost(c) => format!("{c:.0}"),
                Budget::Millis(ms) => format!("{ms} ms"),
            };
            format!("sweep {mode} (budget {budget}, policy {})", policy_name(scene.heuristic.policy))
        } else {
            format!("{set} {mode}")
        };
        self.progress.set_message(what.clone());
        let (width, height) = self.size;
        let settings = FrameSettings { width, height, mode };
        let mut renderer = AnyRenderer::new(&self.backend, scene, &self.scene_name, self.options.get())?;
        if let Some(first) = shots.first() {
            for _ in 0..WARMUP_FRAMES {
                let frame = renderer.render(&first.camera, settings, &mut |_| {})?;
                renderer.recycle(frame);
                self.progress.inc(1);
            }
        }
        let mut records = Vec::with_capacity(shots.len());
        let mut images: BTreeMap<usize, Vec<u8>> = BTreeMap::new();
        let mut rss_at_frame = None;
        for (i, shot) in shots.iter().enumerate() {
            let frame = renderer.render(&shot.camera, settings, &mut |_| {})?;
            records.push(FrameRecord::new(set, i, shot, &frame.report));
            if keep(i) {
                images.insert(i, frame.buffers.final_srgb.iter().flat_map(|p| [p[0], p[1], p[2]]).collect());
            }
            renderer.recycle(frame);
            self.progress.inc(1);
            if i + 1 == RSS_FRAME {
                rss_at_frame = vm_rss_kib();
            }
        }
        let kept_bytes = (shots.len().saturating_sub(RSS_FRAME) * std::mem::size_of::<FrameRecord>()) as u64
            + images.iter().filter(|(i, _)| **i >= RSS_FRAME).map(|(_, img)| img.len() as u64).sum::<u64>();
        let rss = rss_at_frame.zip(vm_rss_kib()).map(|(frame_100_kib, end_kib)| RssSample {
            frame_100_kib,
            end_kib,
            frames: shots.len(),
            kept_bytes,
        });
        if !self.quiet {
            let m = mean(records.iter().map(|r| r.timings.frame)).unwrap_or(0.0);
            // Above the bar (printed even where the bar is hidden).
            let memory = rss.map_or(String::new(), |r| {
                format!(
                    ", VmRSS {:.2} MiB after frame {RSS_FRAME}, {:.2} MiB at the end ({:+.2}%; {:+.2}% beyond the {:.2} MiB of records and images the bench keeps)",
                    r.frame_100_kib as f64 / 1024.0,
                    r.end_kib as f64 / 1024.0,
                    100.0 * r.growth(),
                    100.0 * r.growth_beyond_kept(),
                    r.kept_bytes as f64 / (1 << 20) as f64
                )
            });
            self.progress.suspend(|| eprintln!("  {what}: {} frames, mean {m:.1} ms{memory}", records.len()));
        }
        Ok(Pass { records, images, rss })
    }

    pub(super) fn flip(&self, reference: &[u8], test: &[u8]) -> f32 {
        let (w, h) = self.size;
        let a = nv_flip::FlipImageRgb8::with_data(w, h, reference);
        let b = nv_flip::FlipImageRgb8::with_data(w, h, test);
        let err = nv_flip::flip(a, b, nv_flip::DEFAULT_PIXELS_PER_DEGREE);
        nv_flip::FlipPool::from_image(&err).mean()
    }

    /// Fills in `flip` of every record that has an image and a reference image.
    pub(super) fn add_flip(&self, pass: &mut Pass, reference: &BTreeMap<usize, Vec<u8>>) {
        for (i, img) in &pass.images {
            if let Some(r) = reference.get(i) {
                pass.records[*i].flip = Some(self.flip(r, img));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vm_rss_is_read_from_proc_status() {
        assert_eq!(parse_vm_rss("Name:\thybrid\nVmPeak:\t  99 kB\nVmRSS:\t   45120 kB\n"), Some(45_120));
        assert_eq!(parse_vm_rss("VmRSS: 12 MB\n"), None);
        assert_eq!(parse_vm_rss("Name: x\n"), None);
        let r = RssSample { frame_100_kib: 1000, end_kib: 1049, frames: 10_000, kept_bytes: 40 * 1024 };
        assert!((r.growth() - 0.049).abs() < 1e-12);
        assert!((r.growth_beyond_kept() - 0.009).abs() < 1e-12);
        if cfg!(target_os = "linux") {
            assert!(vm_rss_kib().is_some_and(|k| k > 0));
        }
    }
}
