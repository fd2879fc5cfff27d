//! The heuristic stage at 1280×720: counting A from the id buffer, the selection (second and
//! third phases, report included) and the mask, for 50 and 10,000 objects.
//!
//! Run with `cargo bench -p hybrid-heuristic`.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use glam::Vec3;
use hybrid_heuristic::{Budget, FrameInput, Heuristic, HeuristicSettings, ObjectInput, Policy, SKY_ID, count_visible_pixels, write_mask};
use hybrid_scene::Camera;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

const WIDTH: usize = 1280;
const HEIGHT: usize = 720;

/// An id image with `cols × rows` objects, each a disc in its grid cell (sky between), like a
/// rasterised scene of many objects: runs of equal ids along each row, of varying lengths, that
/// do not line up with the 16-pixel chunks of the fast paths.
fn id_image(cols: usize, rows: usize) -> Vec<u32> {
    let (cell_w, cell_h) = (WIDTH as f32 / cols as f32, HEIGHT as f32 / rows as f32);
    let radius = 0.48 * cell_w.min(cell_h);
    let mut ids = vec![SKY_ID; WIDTH * HEIGHT];
    for y in 0..HEIGHT {
        for x in 0..WIDTH {
            let (fx, fy) = (x as f32 + 0.5, y as f32 + 0.5);
            let (cx, cy) = ((fx / cell_w) as usize, (fy / cell_h) as usize);
            let centre = ((cx as f32 + 0.5) * cell_w, (cy as f32 + 0.5) * cell_h);
            if cx < cols && cy < rows && (fx - centre.0).hypot(fy - centre.1) <= radius {
                ids[y * WIDTH + x] = (cy * cols + cx) as u32;
            }
        }
    }
    ids
}

fn objects(count: usize) -> Vec<ObjectInput> {
    let mut rng = StdRng::seed_from_u64(1);
    (0..count)
        .map(|i| ObjectInput {
            name: format!("object {i}"),
            area: 0,
            bbox_center: Vec3::new(rng.random_range(-20.0..20.0), rng.random_range(-5.0..5.0), rng.random_range(-40.0..-2.0)),
            reflective: rng.random_bool(0.5),
            refractive: rng.random_bool(0.2),
            relevance: rng.random_range(0.5..2.0),
            cost: rng.random_range(0.5..2.0),
        })
        .collect()
}

struct Setup {
    ids: Vec<u32>,
    objects: Vec<ObjectInput>,
    frame: FrameInput,
    heuristic: Heuristic,
    mask: Vec<f32>,
}

fn setup(cols: usize, rows: usize, policy: Policy) -> Setup {
    let ids = id_image(cols, rows);
    let mut objects = objects(cols * rows);
    let area = count_visible_pixels(&ids, objects.len());
    for (object, a) in objects.iter_mut().zip(&area) {
        object.area = *a;
    }
    let camera = Camera::default();
    let frame = FrameInput { view_proj: camera.view_projection(16.0 / 9.0), camera_position: camera.position, light_count: 3 };
    // A budget that selects about half: find the total cost with an unlimited run.
    let mut probe = Heuristic::new(HeuristicSettings { budget: Budget::Unlimited, importance: 1.0, policy });
    let total = probe.run(&objects, &frame).report.spent;
    let heuristic = Heuristic::new(HeuristicSettings { budget: Budget::Cost(total * 0.5), importance: 1.0, policy });
    Setup { mask: vec![0.0; ids.len()], ids, objects, frame, heuristic }
}

/// The whole stage as a backend runs it: A, selection (+ report), mask.
fn stage(s: &mut Setup) {
    let area = count_visible_pixels(&s.ids, s.objects.len());
    for (object, a) in s.objects.iter_mut().zip(&area) {
        object.area = *a;
    }
    let selection = s.heuristic.run(&s.objects, &s.frame);
    write_mask(&s.ids, &selection.selected, &mut s.mask);
    black_box(&s.mask);
}

fn benches(c: &mut Criterion) {
    let mut group = c.benchmark_group("heuristic 1280x720");
    for (name, cols, rows, policy) in [
        ("stage/50 paper", 10, 5, Policy::Paper),
        ("stage/10000 paper", 125, 80, Policy::Paper),
        ("stage/10000 knapsack", 125, 80, Policy::Knapsack),
    ] {
        let mut s = setup(cols, rows, policy);
        group.bench_function(name, |b| b.iter(|| stage(&mut s)));
    }

    let s = setup(10, 5, Policy::Paper);
    group.bench_function("count A/50", |b| b.iter(|| count_visible_pixels(black_box(&s.ids), 50)));
    let s = setup(125, 80, Policy::Paper);
    group.bench_function("count A/10000", |b| b.iter(|| count_visible_pixels(black_box(&s.ids), 10_000)));
    let mut s = setup(125, 80, Policy::Paper);
    let selected: Vec<bool> = (0..10_000).map(|i| i % 2 == 0).collect();
    group.bench_function("mask/10000", |b| b.iter(|| write_mask(black_box(&s.ids), &selected, &mut s.mask)));

    let mut s = setup(10, 5, Policy::Paper);
    group.bench_function("select/50 paper", |b| b.iter(|| s.heuristic.run(black_box(&s.objects), &s.frame)));
    let mut s = setup(125, 80, Policy::Paper);
    group.bench_function("select/10000 paper", |b| b.iter(|| s.heuristic.run(black_box(&s.objects), &s.frame)));
    group.finish();
}

criterion_group!(heuristic, benches);
criterion_main!(heuristic);
