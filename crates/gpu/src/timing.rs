//! `timing`: per-stage GPU times from timestamp queries written at pass boundaries (the start
//! and end of each pass, never inside one: lavapipe gets those wrong). A stage's time runs from
//! the start of its first pass to the end of its last.

use hybrid_core::Stage;
use hybrid_core::report::StageTimings;

use crate::context::{GpuContext, GpuError};
use crate::readback::read_buffer;

/// Most passes one frame may time (two queries each).
const MAX_PASSES: u32 = 32;

/// Hands out timestamp writes for each pass of a frame and turns them into stage times.
pub struct StageTimer {
    query_set: Option<wgpu::QuerySet>,
    resolve: Option<wgpu::Buffer>,
    readback: Option<wgpu::Buffer>,
    period_ns: f32,
    /// Which stage each handed-out pass belongs to (pass k uses queries 2k and 2k + 1).
    passes: Vec<Stage>,
}

impl StageTimer {
    /// A timer; without timestamp support every write is `None` and [`Self::read`] gives `None`.
    pub fn new(ctx: &GpuContext) -> Self {
        if !ctx.timestamps {
            return Self { query_set: None, resolve: None, readback: None, period_ns: 1.0, passes: Vec::new() };
        }
        let count = MAX_PASSES * 2;
        let query_set = ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("stage timestamps"),
            ty: wgpu::QueryType::Timestamp,
            count,
        });
        let size = count as u64 * 8;
        let resolve = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("timestamps.resolve"),
            size,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let readback = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("timestamps.readback"),
            size,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        Self {
            query_set: Some(query_set),
            resolve: Some(resolve),
            readback: Some(readback),
            period_ns: ctx.queue.get_timestamp_period(),
            passes: Vec::new(),
        }
    }

    /// A timer that times nothing (passes recorded outside the frame's timing, e.g. the
    /// fallbacks' probe faces, which run in their own submissions).
    pub fn disabled() -> Self {
        Self { query_set: None, resolve: None, readback: None, period_ns: 1.0, passes: Vec::new() }
    }

    /// Forgets the previous frame's passes (call at the start of each frame).
    pub fn begin_frame(&mut self) {
        self.passes.clear();
    }

    fn next(&mut self, stage: Stage) -> Option<(&wgpu::QuerySet, u32)> {
        let qs = self.query_set.as_ref()?;
        if self.passes.len() as u32 >= MAX_PASSES {
            tracing::warn!("more than {MAX_PASSES} timed passes in one frame; the rest are not timed");
            return None;
        }
        self.passes.push(stage);
        Some((qs, (self.passes.len() as u32 - 1) * 2))
    }

    /// Timestamp writes for the next compute pass of `stage` (`None` without timestamps).
    pub fn compute(&mut self, stage: Stage) -> Option<wgpu::ComputePassTimestampWrites<'_>> {
        self.next(stage).map(|(query_set, i)| wgpu::ComputePassTimestampWrites {
            query_set,
            beginning_of_pass_write_index: Some(i),
            end_of_pass_write_index: Some(i + 1),
        })
    }

    /// Timestamp writes for the next render pass of `stage` (`None` without timestamps).
    pub fn render(&mut self, stage: Stage) -> Option<wgpu::RenderPassTimestampWrites<'_>> {
        self.next(stage).map(|(query_set, i)| wgpu::RenderPassTimestampWrites {
            query_set,
            beginning_of_pass_write_index: Some(i),
            end_of_pass_write_index: Some(i + 1),
        })
    }

    /// Records the copy of this frame's timestamps (after the frame's last pass).
    pub fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        if let (Some(qs), Some(resolve), Some(readback)) = (&self.query_set, &self.resolve, &self.readback)
            && !self.passes.is_empty()
        {
            let n = self.passes.len() as u32 * 2;
            encoder.resolve_query_set(qs, 0..n, resolve, 0);
            encoder.copy_buffer_to_buffer(resolve, 0, readback, 0, n as u64 * 8);
        }
    }

    /// Stage times in ms (after the frame's submission; waits for the GPU). `frame` is the time
    /// from the first pass's start to the last pass's end.
    pub fn read(&self, ctx: &GpuContext) -> Result<Option<StageTimings>, GpuError> {
        let Some(readback) = &self.readback else { return Ok(None) };
        if self.passes.is_empty() {
            return Ok(Some(StageTimings::default()));
        }
        let bytes = read_buffer(ctx, readback)?;
        let ticks: Vec<u64> = bytemuck::pod_collect_to_vec(&bytes[..self.passes.len() * 16]);
        Ok(Some(stage_times(&self.passes, &ticks, self.period_ns)))
    }
}

/// Stage times from pass `k`'s start/end ticks (`ticks[2k]`, `ticks[2k+1]`).
fn stage_times(passes: &[Stage], ticks: &[u64], period_ns: f32) -> StageTimings {
    let ms = |t: u64| t as f64 * period_ns as f64 * 1e-6;
    // The passes of `stages` (all passes when empty), from the first start to the last end.
    let span = |stages: &[Stage]| -> f64 {
        let mut lo = u64::MAX;
        let mut hi = 0u64;
        for (k, s) in passes.iter().enumerate() {
            if stages.is_empty() || stages.contains(s) {
                lo = lo.min(ticks[2 * k]);
                hi = hi.max(ticks[2 * k + 1]);
            }
        }
        if hi > lo { ms(hi - lo) } else { 0.0 }
    };
    // As the CPU backend reports it: `raster` is stage 1 whole (G-buffer + deferred lighting),
    // `lighting` its deferred-lighting part.
    StageTimings {
        capsule: span(&[Stage::Capsule]),
        raster: span(&[Stage::Raster, Stage::Lighting]),
        lighting: span(&[Stage::Lighting]),
        heuristic: span(&[Stage::Heuristic]),
        trace: span(&[Stage::Trace]),
        fallback: span(&[Stage::Fallback]),
        blend: span(&[Stage::Blend]),
        frame: span(&[]),
        build_as: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stage_spans_from_first_start_to_last_end() {
        // Capsule 0..10, raster 12..20, lighting 21..23, trace passes 25..30 and 31..45.
        let passes = [Stage::Capsule, Stage::Raster, Stage::Lighting, Stage::Trace, Stage::Trace];
        let ticks = [0, 10, 12, 20, 21, 23, 25, 30, 31, 45];
        let t = stage_times(&passes, &ticks, 1e6); // 1 tick = 1 ms
        assert_eq!((t.capsule, t.raster, t.lighting, t.trace, t.blend), (10.0, 11.0, 2.0, 20.0, 0.0));
        assert_eq!(t.frame, 45.0);
    }
}
