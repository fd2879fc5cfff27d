//! Selection behaviour through the public API: listing 6 against its restatement, temporal
//! stability (I), knapsack, the mask and the JSON report.

use glam::Vec3;
use hybrid_heuristic::{
    Budget, Candidate, FrameInput, Heuristic, HeuristicSettings, ObjectInput, Policy, SKY_ID, count_visible_pixels, select_knapsack,
    select_paper, select_restatement, write_mask,
};
use hybrid_scene::{Camera, Projection};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

fn random_value(rng: &mut StdRng) -> f64 {
    // Mostly small integers (many ties, including zero), sometimes continuous.
    if rng.random_bool(0.7) { f64::from(rng.random_range(0u32..12)) * 10.0 } else { rng.random_range(0.0..120.0) }
}

#[test]
fn paper_form_equals_restatement_on_random_graphs() {
    let mut rng = StdRng::seed_from_u64(0x5eed_2019);
    let mut nonempty = 0;
    let mut partial = 0;
    for _ in 0..10_000 {
        let n = rng.random_range(0..=24);
        let nodes: Vec<Candidate> = (0..n).map(|_| Candidate { cost: random_value(&mut rng), relevance: random_value(&mut rng) }).collect();
        let total: f64 = nodes.iter().map(|c| c.cost).sum();
        let budget = match rng.random_range(0..10) {
            0 => 0.0,
            1 => total,
            _ => rng.random_range(0.0..=total.max(1.0) * 0.8),
        };
        let paper = select_paper(&nodes, budget);
        let restatement = select_restatement(&nodes, budget);
        assert_eq!(paper, restatement, "nodes {nodes:?}, budget {budget}");

        // Sanity of the selection itself: distinct nodes, within budget.
        let spent: f64 = paper.iter().map(|&i| nodes[i].cost).sum();
        assert!(spent <= budget + 1e-9, "spent {spent} > budget {budget}");
        let mut sorted = paper.clone();
        sorted.sort_unstable();
        sorted.dedup();
        assert_eq!(sorted.len(), paper.len());
        if !paper.is_empty() {
            nonempty += 1;
        }
        if !paper.is_empty() && paper.len() < n {
            partial += 1;
        }
    }
    // The instances exercise real choices, not only "nothing" or "everything".
    assert!(nonempty > 7_000 && partial > 5_000, "nonempty {nonempty}, partial {partial}");
}

#[test]
fn knapsack_stays_within_budget_and_prefers_density() {
    let mut rng = StdRng::seed_from_u64(7);
    for _ in 0..1_000 {
        let n = rng.random_range(1..=20);
        let nodes: Vec<Candidate> =
            (0..n).map(|_| Candidate { cost: rng.random_range(1.0..100.0), relevance: rng.random_range(0.0..10.0) }).collect();
        let budget = rng.random_range(0.0..500.0);
        let chosen = select_knapsack(&nodes, budget);
        let spent: f64 = chosen.iter().map(|&i| nodes[i].cost).sum();
        assert!(spent <= budget + 1e-9);
        // Greedy order: relevance per cost never increases along the selection.
        for pair in chosen.windows(2) {
            let density = |i: usize| nodes[i].relevance / nodes[i].cost;
            assert!(density(pair[0]) >= density(pair[1]));
        }
        // Nothing left out would still fit.
        for i in (0..n).filter(|i| !chosen.contains(i)) {
            assert!(nodes[i].cost > budget - spent || budget - spent <= 0.0);
        }
    }
}

fn camera_at(x: f32) -> FrameInput {
    let camera = Camera {
        position: Vec3::new(x, 0.0, 0.0),
        target: Vec3::new(x, 0.0, -1.0),
        up: Vec3::Y,
        projection: Projection::Perspective { fov_y_deg: 60.0, near: 0.1, far: 100.0 },
    };
    FrameInput { view_proj: camera.view_projection(16.0 / 9.0), camera_position: camera.position, light_count: 1 }
}

/// Two equal objects left and right of the view axis; the budget pays for one of them.
fn twins(area_left: u64, area_right: u64) -> Vec<ObjectInput> {
    let twin = |name: &str, area, x| ObjectInput {
        name: name.into(),
        area,
        bbox_center: Vec3::new(x, 0.0, -5.0),
        reflective: false,
        refractive: false,
        relevance: 1.0,
        cost: 1.0,
    };
    vec![twin("left", area_left, -1.0), twin("right", area_right, 1.0)]
}

fn run_two_frames(importance: f32) -> (Vec<bool>, Vec<bool>) {
    let settings = HeuristicSettings { budget: Budget::Cost(1500.0), importance, policy: Policy::Paper };
    let mut heuristic = Heuristic::new(settings);
    // Frame 1: the camera is a little left, so "left" is nearer the centre and closer.
    let first = heuristic.run(&twins(1010, 990), &camera_at(-0.1)).selected;
    // Frame 2: a small move to the right; now "right" has the slightly larger V.
    let second = heuristic.run(&twins(990, 1010), &camera_at(0.1)).selected;
    (first, second)
}

#[test]
fn importance_keeps_the_selection_under_small_moves() {
    // Without I the choice flips with the tiny change of A, P and D.
    let (first, second) = run_two_frames(0.0);
    assert_eq!(first, vec![true, false]);
    assert_eq!(second, vec![false, true]);
    // With a large I, last frame's choice wins.
    let (first, second) = run_two_frames(1000.0);
    assert_eq!(first, vec![true, false]);
    assert_eq!(second, vec![true, false]);
}

#[test]
fn importance_enters_r_as_reported() {
    let settings = HeuristicSettings { budget: Budget::Cost(1500.0), importance: 50.0, policy: Policy::Paper };
    let mut heuristic = Heuristic::new(settings);
    let first = heuristic.run(&twins(1000, 1000), &camera_at(-0.1));
    let second = heuristic.run(&twins(1000, 1000), &camera_at(-0.1));
    let (a, b) = (&first.report.objects[0], &second.report.objects[0]);
    assert!(!a.s && b.s && a.selected && b.selected);
    assert!((b.r - (a.r + 50.0)).abs() < 1e-9, "R {} then {}", a.r, b.r);
    assert_eq!(first.report.objects[1].r, second.report.objects[1].r);
}

#[test]
fn knapsack_policy_through_the_heuristic() {
    // A big reflective object (expensive, most relevant) and two small diffuse ones.
    let mut objects = twins(300, 300);
    objects.push(ObjectInput {
        name: "mirror".into(),
        area: 2000,
        bbox_center: Vec3::new(0.0, 0.0, -5.0),
        reflective: true,
        refractive: false,
        relevance: 1.0,
        cost: 1.0,
    });
    // C: 300, 300, 2000·3 = 6000. Budget 6000.
    let frame = camera_at(0.0);
    let mut paper = Heuristic::new(HeuristicSettings { budget: Budget::Cost(6000.0), importance: 0.0, policy: Policy::Paper });
    let mut knapsack = Heuristic::new(HeuristicSettings { budget: Budget::Cost(6000.0), importance: 0.0, policy: Policy::Knapsack });
    let by_paper = paper.run(&objects, &frame);
    let by_knapsack = knapsack.run(&objects, &frame);
    assert_eq!(by_paper.selected, vec![false, false, true]);
    assert_eq!(by_paper.report.spent, 6000.0);
    assert_eq!(by_knapsack.selected, vec![true, true, false]);
    assert_eq!(by_knapsack.report.spent, 600.0);
    assert_eq!(by_knapsack.report.policy, "knapsack");
}

/// A 16×9 id image: three rectangles of objects 0, 1, 2 over sky, object 3 hidden.
fn id_image() -> Vec<u32> {
    let (w, h) = (16, 9);
    let mut ids = vec![SKY_ID; w * h];
    for y in 0..h {
        for x in 0..w {
            ids[y * w + x] = match (x, y) {
                (0..=5, 0..=3) => 0,
                (6..=11, 2..=7) => 1,
                (12..=15, 5..=8) => 2,
                _ => SKY_ID,
            };
        }
    }
    ids
}

#[test]
fn mask_marks_exactly_the_selected_objects() {
    let ids = id_image();
    let area = count_visible_pixels(&ids, 4);
    assert_eq!(area, vec![24, 36, 16, 0]);
    let objects: Vec<ObjectInput> = (0..4)
        .map(|i| ObjectInput {
            name: format!("o{i}"),
            area: area[i],
            bbox_center: Vec3::new(i as f32 - 1.5, 0.0, -4.0),
            reflective: i == 1,
            refractive: false,
            relevance: 1.0,
            cost: 1.0,
        })
        .collect();
    // C: 24, 36·3 = 108, 16. Budget 50: paper takes the most relevant affordable ones.
    let mut heuristic = Heuristic::new(HeuristicSettings { budget: Budget::Cost(50.0), importance: 0.0, policy: Policy::Paper });
    let selection = heuristic.run(&objects, &camera_at(0.0));
    assert_eq!(selection.selected, vec![true, false, true, false]);
    let mut mask = vec![0.5; ids.len()];
    write_mask(&ids, &selection.selected, &mut mask);
    for (&id, &m) in ids.iter().zip(&mask) {
        let expected = id == 0 || id == 2;
        assert_eq!(m, if expected { 1.0 } else { 0.0 }, "id {id}");
    }
    assert_eq!(mask.iter().filter(|&&m| m == 1.0).count(), 24 + 16);
}

#[test]
fn report_json_has_the_documented_keys() {
    let ids = id_image();
    let area = count_visible_pixels(&ids, 4);
    let objects: Vec<ObjectInput> = (0..4)
        .map(|i| ObjectInput {
            name: format!("o{i}"),
            area: area[i],
            bbox_center: Vec3::new(0.0, 0.0, -4.0),
            reflective: i == 1,
            refractive: i == 2,
            relevance: 2.0,
            cost: 0.5,
        })
        .collect();
    let mut heuristic = Heuristic::new(HeuristicSettings { budget: Budget::Millis(3.0), importance: 0.25, policy: Policy::Paper });
    let json = serde_json::to_value(heuristic.run(&objects, &camera_at(0.0)).report).expect("report serialises");
    let keys = |v: &serde_json::Value| {
        let mut keys: Vec<String> = v.as_object().map(|o| o.keys().cloned().collect()).unwrap_or_default();
        keys.sort();
        keys
    };
    assert_eq!(keys(&json), ["budget", "budget_ms", "importance", "lights", "ms_per_cost", "objects", "policy", "spent"]);
    assert_eq!(json["policy"], "paper");
    assert!(json["budget"].is_null() && json["ms_per_cost"].is_null());
    assert_eq!(json["budget_ms"], 3.0);
    let list = json["objects"].as_array().cloned().unwrap_or_default();
    assert_eq!(list.len(), 3, "only visible objects");
    assert_eq!(keys(&list[0]), ["A", "C", "D", "E", "K", "P", "Q", "R", "S", "V", "id", "name", "reflective", "refractive", "selected"]);
    assert_eq!(list[1]["A"], 36);
    assert_eq!(list[1]["Q"], 3);
    assert_eq!(list[2]["Q"], 6);
    assert_eq!(list[2]["C"], 16.0 * 6.0 * 0.5);
    assert_eq!(list[2]["id"], 2);
    assert_eq!(list[2]["D"], 4.0);
    assert_eq!(list[2]["refractive"], true);
}
