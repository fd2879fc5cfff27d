//! The third phase: which nodes (visible objects with cost C and relevance R) get ray traced under
//! a cost budget.
//!
//! All functions return the chosen nodes' indices **in the order they were selected**. A budget
//! that is ≤ 0 or NaN selects nothing; `f64::INFINITY` is allowed. A NaN cost is treated as
//! infinite (such a node never fits). Ties are broken by index, so every function is
//! deterministic: "costlier" means higher cost, then lower index; "more relevant" means higher
//! relevance (by [`f64::total_cmp`]), then lower index.

use std::cmp::Ordering;

use hybrid_scene::Policy;

/// One node of the heuristic's graph.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidate {
    /// C = A·Q·E.
    pub cost: f64,
    /// R = (S·I + V)·K.
    pub relevance: f64,
}

impl Candidate {
    fn cost(&self) -> f64 {
        if self.cost.is_nan() { f64::INFINITY } else { self.cost }
    }
}

/// Runs the third phase with `policy`.
pub fn select(policy: Policy, nodes: &[Candidate], budget: f64) -> Vec<usize> {
    match policy {
        Policy::Paper => select_paper(nodes, budget),
        Policy::Knapsack => select_knapsack(nodes, budget),
    }
}

/// A u64 whose unsigned order is [`f64::total_cmp`]'s order of `x` (so that sorting plain
/// integer pairs, which is fast, gives the same order as the comparators).
fn total_order_key(x: f64) -> u64 {
    let bits = x.to_bits();
    if bits >> 63 == 1 { !bits } else { bits | (1 << 63) }
}

/// Node indices sorted by `key` descending, ties by index ascending.
fn sorted_descending(n: usize, key: impl Fn(usize) -> f64) -> Vec<usize> {
    // One u128 per node, key in the high half and index in the low half: a single integer
    // comparison per step of the sort.
    let mut keyed: Vec<u128> = (0..n).map(|i| (u128::from(!total_order_key(key(i))) << 64) | i as u128).collect();
    keyed.sort_unstable();
    keyed.into_iter().map(|k| k as u64 as usize).collect()
}

/// `Less` when node `a` is more relevant than node `b` (sorts by relevance descending).
fn more_relevant(nodes: &[Candidate], a: usize, b: usize) -> Ordering {
    nodes[b].relevance.total_cmp(&nodes[a].relevance).then(a.cmp(&b))
}

/// Policy `paper`: Walewski et al. 2019, §3.2 and listing 6, in the paper's form.
///
/// The graph (end of the second phase): nodes sorted by cost descending, each node pointing to
/// the cheaper-or-equal nodes that are more relevant, those pointers sorted by relevance
/// descending. The loop (third phase):
///
/// ```text
/// while costLeftForRT > 0 and visible_objects > 0:
///     obj_cur ← remaining object with the highest cost
///     if obj_cur.cost > costLeftForRT:  mark not selected, remove it
///     else if obj_cur points to a more relevant object: obj_cur ← the most relevant one
///         select obj_cur, costLeftForRT −= obj_cur.cost, remove it
///     else: select obj_cur, costLeftForRT −= obj_cur.cost, remove it
/// ```
///
/// O(n log n): two sorts, then a loop in which two cursors only move forward. The per-node
/// pointer lists are not built (that would be O(n²)); see the comment in the loop for why one
/// shared relevance-sorted list answers "the most relevant remaining node obj_cur points to".
pub fn select_paper(nodes: &[Candidate], budget: f64) -> Vec<usize> {
    let n = nodes.len();

    // Second phase, the graph. `by_cost` is the cost chain: each node points to the next one,
    // which costs the same or less.
    let by_cost = sorted_descending(n, |i| nodes[i].cost());
    // Node i's relevance pointers, sorted by relevance descending, are the entries of
    // `by_relevance` before i that come after i in `by_cost`.
    let by_relevance = sorted_descending(n, |i| nodes[i].relevance);

    // Third phase.
    let mut removed = vec![false; n];
    let mut next_by_cost = 0; // every entry of `by_cost` before this is removed
    let mut next_by_relevance = 0; // every entry of `by_relevance` before this is removed
    let mut cost_left = budget;
    let mut selected = Vec::new();
    while cost_left > 0.0 {
        // obj_cur ← the remaining object with the highest cost.
        while by_cost.get(next_by_cost).is_some_and(|&i| removed[i]) {
            next_by_cost += 1;
        }
        let Some(&current) = by_cost.get(next_by_cost) else {
            break; // visible_objects = 0
        };

        // if obj_cur.cost > costLeftForRT: mark it not selected and remove it (cost() is never NaN).
        if nodes[current].cost() > cost_left {
            removed[current] = true;
            continue;
        }

        // else if obj_cur points to a more relevant object: obj_cur ← the most relevant one.
        // obj_cur's pointers go to cheaper-or-equal, more relevant nodes. Every remaining node is
        // cheaper-or-equal (obj_cur is the costliest remaining), so among the remaining nodes the
        // pointer targets are exactly those more relevant than obj_cur, and the most relevant of
        // them is the first remaining entry of the relevance order, unless that entry is obj_cur
        // itself (then obj_cur points to no remaining node and is selected itself).
        while removed[by_relevance[next_by_relevance]] {
            // Cannot run past the end: `current` is remaining, so it is found at the latest.
            next_by_relevance += 1;
        }
        let chosen = by_relevance[next_by_relevance];

        // Select it, pay for it, remove it from the graph.
        cost_left -= nodes[chosen].cost();
        removed[chosen] = true;
        selected.push(chosen);
    }
    // Nodes still in the graph when the budget ran out are not selected.
    selected
}

/// design §4's restatement of listing 6, written for clarity (O(n²)), used to test
/// [`select_paper`]: while budget is left, drop every remaining node costlier than the budget
/// left, then select the most relevant remaining node.
pub fn select_restatement(nodes: &[Candidate], budget: f64) -> Vec<usize> {
    let mut remaining: Vec<usize> = (0..nodes.len()).collect();
    let mut cost_left = budget;
    let mut selected = Vec::new();
    while cost_left > 0.0 {
        remaining.retain(|&i| nodes[i].cost() <= cost_left);
        let Some(position) = (0..remaining.len()).min_by(|&a, &b| more_relevant(nodes, remaining[a], remaining[b])) else {
            break;
        };
        let chosen = remaining.swap_remove(position);
        cost_left -= nodes[chosen].cost();
        selected.push(chosen);
    }
    selected
}

/// Policy `knapsack`: greedy by relevance per cost (R/C descending; a zero-cost node comes first),
/// selecting each node that fits in the budget left (a node that does not fit is skipped and the
/// next one is tried), until the budget left is ≤ 0 — the greedy fractional-knapsack rule of
/// Funkhouser & Séquin 1993.
///
/// Trade-off against `paper`: `paper` always spends on the most relevant affordable object, so one
/// very relevant but large object (a mirror filling the screen) can take the whole budget;
/// `knapsack` maximises relevance per unit of cost, so it usually buys more total relevance for
/// the same budget (many small objects), but may leave out the single most relevant object
/// because it is expensive.
pub fn select_knapsack(nodes: &[Candidate], budget: f64) -> Vec<usize> {
    let ratio = |i: usize| {
        let cost = nodes[i].cost();
        if cost > 0.0 { nodes[i].relevance / cost } else { f64::INFINITY }
    };
    let order = sorted_descending(nodes.len(), ratio);
    let mut cost_left = budget;
    let mut selected = Vec::new();
    for i in order {
        if cost_left.is_nan() || cost_left <= 0.0 {
            break;
        }
        if nodes[i].cost() <= cost_left {
            cost_left -= nodes[i].cost();
            selected.push(i);
        }
    }
    selected
}

#[cfg(test)]
mod tests {
    use super::*;

    fn nodes(list: &[(f64, f64)]) -> Vec<Candidate> {
        list.iter().map(|&(cost, relevance)| Candidate { cost, relevance }).collect()
    }

    /// A graph in the spirit of the paper's Figure 4 (budget 400), already in cost order.
    /// Nodes 0–2 cost more than 400; node 3 fits and points to 5 and 6 (more relevant, cheaper),
    /// 5 being the most relevant of them.
    fn figure4() -> Vec<Candidate> {
        nodes(&[(1000.0, 8.0), (700.0, 4.0), (500.0, 9.0), (300.0, 3.0), (200.0, 1.0), (150.0, 7.0), (100.0, 5.0)])
    }

    #[test]
    fn total_order_key_matches_total_cmp() {
        let values = [f64::NEG_INFINITY, -1e300, -2.5, -0.0, 0.0, 1e-310, 3.0, 1e300, f64::INFINITY, f64::NAN, -f64::NAN];
        for a in values {
            for b in values {
                assert_eq!(total_order_key(a).cmp(&total_order_key(b)), a.total_cmp(&b), "{a} vs {b}");
            }
        }
    }

    #[test]
    fn figure4_worked_example() {
        // Hand trace, budget 400:
        //  0 (1000) > 400 → dropped; 1 (700) → dropped; 2 (500) → dropped.
        //  3 (300) fits; it points to 5 (R 7) and 6 (R 5): select 5, left 250.
        //  3 (300) > 250 → dropped.
        //  4 (200) fits; it points to 6 (R 5): select 6, left 150.
        //  4 (200) > 150 → dropped. Graph empty: done. Spent 250.
        let graph = figure4();
        assert_eq!(select_paper(&graph, 400.0), vec![5, 6]);
        assert_eq!(select_restatement(&graph, 400.0), vec![5, 6]);
        // Budget 1000: 0 fits but 2 (R 9) is more relevant and cheaper: select 2, left 500;
        // 0, 1 dropped; 2 gone; 3 fits, most relevant remaining is 5 (R 7): left 350; 3 fits,
        // 6 (R 5): left 250; 3 > 250 dropped; 4 fits and nothing remaining is more relevant:
        // 4 itself, left 50. Graph empty.
        assert_eq!(select_paper(&graph, 1000.0), vec![2, 5, 6, 4]);
        // A node selected for itself: budget 120 → only 6 (100) fits.
        assert_eq!(select_paper(&graph, 120.0), vec![6]);
    }

    #[test]
    fn order_of_input_does_not_matter() {
        // The figure-4 graph shuffled: same objects chosen, same order.
        let graph = figure4();
        let permutation = [4, 0, 6, 2, 5, 1, 3];
        let shuffled: Vec<Candidate> = permutation.iter().map(|&i| graph[i]).collect();
        let chosen: Vec<usize> = select_paper(&shuffled, 400.0).into_iter().map(|j| permutation[j]).collect();
        assert_eq!(chosen, vec![5, 6]);
    }

    #[test]
    fn budget_edge_cases() {
        let graph = figure4();
        assert!(select_paper(&graph, 0.0).is_empty());
        assert!(select_paper(&graph, -5.0).is_empty());
        assert!(select_paper(&graph, f64::NAN).is_empty());
        assert!(select_paper(&[], 100.0).is_empty());
        let mut all = select_paper(&graph, f64::INFINITY);
        all.sort_unstable();
        assert_eq!(all, (0..7).collect::<Vec<_>>());
        // A NaN cost never fits.
        let odd = nodes(&[(f64::NAN, 100.0), (10.0, 1.0)]);
        assert_eq!(select_paper(&odd, 1e9), vec![1]);
        assert_eq!(select_restatement(&odd, 1e9), vec![1]);
        assert_eq!(select_knapsack(&odd, 1e9), vec![1]);
    }

    #[test]
    fn exact_fit_spends_everything_and_stops() {
        // 100 + 300 = 400 exactly: the budget reaches 0 and the zero-cost node is not reached.
        let graph = nodes(&[(300.0, 5.0), (100.0, 9.0), (0.0, 1.0)]);
        assert_eq!(select_paper(&graph, 400.0), vec![1, 0]);
    }

    #[test]
    fn knapsack_prefers_relevance_per_cost() {
        // One big relevant object against two small ones.
        let graph = nodes(&[(100.0, 10.0), (40.0, 6.0), (40.0, 6.0)]);
        assert_eq!(select_paper(&graph, 100.0), vec![0]); // relevance 10
        assert_eq!(select_knapsack(&graph, 100.0), vec![1, 2]); // relevance 12
        // Items that do not fit are skipped, later ones still taken.
        let graph = nodes(&[(50.0, 50.0), (60.0, 30.0), (30.0, 6.0)]);
        assert_eq!(select_knapsack(&graph, 85.0), vec![0, 2]);
        // Zero-cost nodes come first.
        let graph = nodes(&[(10.0, 100.0), (0.0, 1.0)]);
        assert_eq!(select_knapsack(&graph, 10.0), vec![1, 0]);
        assert!(select_knapsack(&graph, 0.0).is_empty());
        assert_eq!(select(Policy::Knapsack, &graph, 10.0), vec![1, 0]);
        assert_eq!(select(Policy::Paper, &graph, 10.0), vec![0]);
    }
}
