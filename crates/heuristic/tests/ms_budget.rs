//! The millisecond budget's closed loop, driven by a mocked trace stage (no wall-clock timing):
//! trace time = overhead + k·spent, with noise, and k changing mid-way.

use glam::Vec3;
use hybrid_heuristic::{Budget, FrameInput, Heuristic, HeuristicSettings, ObjectInput, Policy};
use hybrid_scene::Camera;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

fn scene(rng: &mut StdRng, count: usize) -> Vec<ObjectInput> {
    (0..count)
        .map(|i| ObjectInput {
            name: format!("object {i}"),
            area: rng.random_range(100..5000),
            bbox_center: Vec3::new(rng.random_range(-20.0..20.0), rng.random_range(-5.0..5.0), rng.random_range(-40.0..-2.0)),
            reflective: rng.random_bool(0.5),
            refractive: rng.random_bool(0.2),
            relevance: rng.random_range(0.5..2.0),
            cost: rng.random_range(0.5..2.0),
        })
        .collect()
}

struct MockTrace {
    overhead_ms: f64,
    ms_per_cost: f64,
    noise: f64,
}

impl MockTrace {
    fn trace_ms(&self, spent: f64, rng: &mut StdRng) -> f64 {
        (self.overhead_ms + self.ms_per_cost * spent) * (1.0 + rng.random_range(-self.noise..=self.noise))
    }
}

/// Drives `frames` frames; `model(frame)` is the trace stage's behaviour at that frame. Returns
/// the trace time of every frame.
fn drive(policy: Policy, target_ms: f64, frames: usize, model: impl Fn(usize) -> MockTrace) -> Vec<f64> {
    let mut rng = StdRng::seed_from_u64(42);
    let mut objects = scene(&mut rng, 300);
    let camera = Camera::default();
    let frame = FrameInput { view_proj: camera.view_projection(16.0 / 9.0), camera_position: camera.position, light_count: 2 };
    let mut heuristic = Heuristic::new(HeuristicSettings { budget: Budget::Millis(target_ms), importance: 1.0, policy });
    let mut times = Vec::new();
    for f in 0..frames {
        // The view changes a little every frame: visible areas drift.
        for object in &mut objects {
            object.area = (object.area as f64 * rng.random_range(0.97..1.03)).round() as u64;
        }
        let selection = heuristic.run(&objects, &frame);
        let spent = selection.report.spent;
        let trace_ms = model(f).trace_ms(spent, &mut rng);
        heuristic.record_trace(spent, trace_ms);
        times.push(trace_ms);
    }
    times
}

fn assert_within(times: &[f64], range: std::ops::Range<usize>, target: f64, tolerance: f64) {
    for f in range {
        let error = (times[f] - target).abs() / target;
        assert!(
            error <= tolerance,
            "frame {f}: trace {:.3} ms vs target {target} ms ({:.1}% off); all: {times:.2?}",
            times[f],
            error * 100.0
        );
    }
}

#[test]
fn converges_and_follows_a_change_of_speed() {
    let target = 8.0;
    for policy in [Policy::Paper, Policy::Knapsack] {
        // 5% noise; the trace stage gets 2.5× slower at frame 30 (e.g. a costlier part of the scene).
        let times =
            drive(policy, target, 60, |f| MockTrace { overhead_ms: 0.0, ms_per_cost: if f < 30 { 1e-5 } else { 2.5e-5 }, noise: 0.05 });
        // Frame 0 traces everything (no estimate yet): far over the target, which is the point
        // of the test scene (the budget must really limit the selection).
        assert!(times[0] > 2.0 * target, "{times:?}");
        assert_within(&times, 3..30, target, 0.15);
        // The change overshoots once, then the loop catches up within a few frames.
        assert!(times[30] > 1.5 * target);
        assert_within(&times, 34..60, target, 0.15);
    }
}

#[test]
fn converges_with_a_fixed_overhead() {
    // trace = 1.5 ms + k·spent: the loop settles where the total equals the target.
    let target = 8.0;
    let times = drive(Policy::Paper, target, 40, |_| MockTrace { overhead_ms: 1.5, ms_per_cost: 1e-5, noise: 0.03 });
    assert_within(&times, 6..40, target, 0.15);
}

#[test]
fn recovers_after_nothing_fits() {
    // An estimate far too pessimistic makes every object too costly; the relaxation brings the
    // budget back and the loop converges.
    let target = 8.0;
    let mut rng = StdRng::seed_from_u64(3);
    let objects = scene(&mut rng, 100);
    let camera = Camera::default();
    let frame = FrameInput { view_proj: camera.view_projection(1.0), camera_position: camera.position, light_count: 1 };
    let mut heuristic = Heuristic::new(HeuristicSettings { budget: Budget::Millis(target), importance: 0.0, policy: Policy::Paper });
    heuristic.set_ms_per_cost(Some(1.0)); // budget = 8 cost units: nothing fits
    let model = MockTrace { overhead_ms: 0.0, ms_per_cost: 2e-5, noise: 0.0 };
    let mut times = Vec::new();
    for _ in 0..60 {
        let selection = heuristic.run(&objects, &frame);
        let trace = model.trace_ms(selection.report.spent, &mut rng);
        heuristic.record_trace(selection.report.spent, trace);
        times.push(trace);
    }
    assert_eq!(times[0], 0.0);
    assert_within(&times, 50..60, target, 0.15);
}
