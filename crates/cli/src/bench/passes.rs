//! Running the bench: one pass is one mode over a list of cameras with a fresh renderer, after
//! warm-up frames; FLIP against the rt-only reference.

use super::*;

/// What one pass produced: its records and the RGB images of the frames asked for.
pub(super) struct Pass {
    pub(super) records: Vec<FrameRecord>,
    pub(super) images: BTreeMap<usize, Vec<u8>>,
}

pub(super) struct Bench {
    pub(super) scene_name: String,
    pub(super) size: (u32, u32),
    pub(super) quiet: bool,
    pub(super) backend: Backend,
    pub(super) options: RenderOptions,
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
        let mut renderer = AnyRenderer::new(&self.backend, scene, &self.scene_name, self.options)?;
        if let Some(first) = shots.first() {
            for _ in 0..WARMUP_FRAMES {
                let frame = renderer.render(&first.camera, settings, &mut |_| {})?;
                renderer.recycle(frame);
                self.progress.inc(1);
            }
        }
        let mut records = Vec::with_capacity(shots.len());
        let mut images = BTreeMap::new();
        for (i, shot) in shots.iter().enumerate() {
            let frame = renderer.render(&shot.camera, settings, &mut |_| {})?;
            records.push(FrameRecord::new(set, i, shot, &frame.report));
            if keep(i) {
                images.insert(i, frame.buffers.final_srgb.iter().flat_map(|p| [p[0], p[1], p[2]]).collect());
            }
            renderer.recycle(frame);
            self.progress.inc(1);
        }
        if !self.quiet {
            let m = mean(records.iter().map(|r| r.timings.frame)).unwrap_or(0.0);
            // Above the bar (printed even where the bar is hidden).
            self.progress.suspend(|| eprintln!("  {what}: {} frames, mean {m:.1} ms", records.len()));
        }
        Ok(Pass { records, images })
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
