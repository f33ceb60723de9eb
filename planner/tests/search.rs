//! Search layer: A* optimality against brute force, the deadline contract, determinism.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use embodied_planner::PlanError;
use embodied_planner::deadline::{Deadline, Interrupt};
use embodied_planner::search::grid::GridWorld;
use embodied_planner::search::{Cost, SearchOutcome, SearchProblem, Successor, solve, solve_astar};
use proptest::prelude::*;

/// A directed graph with weighted edges; the operator is the edge index.
#[derive(Debug, Clone)]
struct Graph {
    n: usize,
    edges: Vec<(usize, usize, f64)>,
    start: usize,
    goal: usize,
    /// Per-node heuristic (admissible by construction, maybe inconsistent).
    h: Vec<f64>,
}

impl SearchProblem for Graph {
    type State = usize;
    type Operator = usize;
    fn initial(&self) -> usize {
        self.start
    }
    fn successors(&self, s: &usize, out: &mut Vec<Successor<usize, usize>>) {
        for (i, &(a, b, w)) in self.edges.iter().enumerate() {
            if a == *s {
                out.push(Successor { operator: i, state: b, cost: Cost::new(w).expect("test weights are valid") });
            }
        }
    }
    fn is_goal(&self, s: &usize) -> bool {
        *s == self.goal
    }
    fn heuristic(&self, s: &usize) -> f64 {
        self.h[*s]
    }
}

/// Bellman-Ford distances from `source` over `edges` (reversed if `reverse`).
fn bellman_ford(n: usize, edges: &[(usize, usize, f64)], source: usize, reverse: bool) -> Vec<f64> {
    let mut d = vec![f64::INFINITY; n];
    d[source] = 0.0;
    for _ in 0..n {
        for &(a, b, w) in edges {
            let (a, b) = if reverse { (b, a) } else { (a, b) };
            if d[a] + w < d[b] {
                d[b] = d[a] + w;
            }
        }
    }
    d
}

fn graph_strategy() -> impl Strategy<Value = (Graph, f64, bool)> {
    (2usize..14).prop_flat_map(|n| {
        let weight = prop_oneof![Just(0.0), Just(1.0), 0.0f64..10.0];
        let edges = proptest::collection::vec((0..n, 0..n, weight), 0..(n * 3));
        let factors = proptest::collection::vec(0.0f64..=1.0, n);
        (Just(n), edges, 0..n, 0..n, factors, 0.0f64..=1.0, any::<bool>()).prop_map(
            |(n, edges, start, goal, factors, scale, per_node)| {
                let exact = bellman_ford(n, &edges, goal, true);
                // Admissible: a fraction of the true remaining cost (per-node fractions make it
                // inconsistent, which forces reopening). Unreachable nodes get +inf (pruned).
                let h = (0..n)
                    .map(|v| {
                        if exact[v].is_infinite() {
                            f64::INFINITY
                        } else {
                            exact[v] * if per_node { factors[v] } else { scale }
                        }
                    })
                    .collect();
                (Graph { n, edges, start, goal, h }, scale, per_node)
            },
        )
    })
}

fn check_plan(g: &Graph, states: &[usize], ops: &[usize], cost: f64) {
    assert_eq!(states.len(), ops.len() + 1);
    assert_eq!(states[0], g.start);
    assert_eq!(*states.last().expect("non-empty"), g.goal);
    let mut total = 0.0;
    for (i, &op) in ops.iter().enumerate() {
        let (a, b, w) = g.edges[op];
        assert_eq!((a, b), (states[i], states[i + 1]), "operator does not connect the states");
        total += w;
    }
    assert!((total - cost).abs() < 1e-9, "plan cost {cost} != sum of its edges {total}");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    #[test]
    fn astar_cost_equals_brute_force((g, _, _) in graph_strategy()) {
        let truth = bellman_ford(g.n, &g.edges, g.start, false)[g.goal];
        let report = solve(&g, &Deadline::none());
        let reference = solve_astar(&g);
        match report.outcome {
            SearchOutcome::Solved(plan) => {
                prop_assert!(truth.is_finite());
                prop_assert!((plan.cost - truth).abs() < 1e-9, "solve {} vs brute force {}", plan.cost, truth);
                check_plan(&g, &plan.states, &plan.operators, plan.cost);
                let reference = reference.expect("pathfinding finds it too");
                prop_assert!((reference.cost - plan.cost).abs() < 1e-9);
                check_plan(&g, &reference.states, &reference.operators, reference.cost);
            }
            SearchOutcome::Infeasible => {
                prop_assert!(truth.is_infinite(), "declared infeasible but brute force found {}", truth);
                prop_assert!(reference.is_none());
            }
            SearchOutcome::OutOfTime { .. } => prop_assert!(false, "no deadline, yet out of time"),
        }
    }

    #[test]
    fn zero_heuristic_also_optimal((mut g, _, _) in graph_strategy()) {
        g.h = vec![0.0; g.n];
        let truth = bellman_ford(g.n, &g.edges, g.start, false)[g.goal];
        match solve(&g, &Deadline::none()).outcome {
            SearchOutcome::Solved(plan) => prop_assert!((plan.cost - truth).abs() < 1e-9),
            SearchOutcome::Infeasible => prop_assert!(truth.is_infinite()),
            SearchOutcome::OutOfTime { .. } => prop_assert!(false),
        }
    }

    #[test]
    fn expansion_budget_is_deterministic((g, _, _) in graph_strategy(), budget in 0u64..20) {
        let a = solve(&g, &Deadline::expansions(budget));
        let b = solve(&g, &Deadline::expansions(budget));
        prop_assert_eq!(&a.outcome, &b.outcome);
        prop_assert_eq!(a.stats.expansions, b.stats.expansions);
        prop_assert_eq!(a.stats.generated, b.stats.generated);
        prop_assert!(a.stats.expansions <= budget);
        if let SearchOutcome::OutOfTime { best: best_so_far, cause } = &a.outcome {
            prop_assert_eq!(*cause, Interrupt::ExpansionBudget);
            prop_assert_eq!(a.stats.expansions, budget);
            if let Some(partial) = best_so_far {
                // A partial plan must be a valid path from the start.
                prop_assert_eq!(partial.plan.states[0], g.start);
                prop_assert_eq!(partial.plan.states.len(), partial.plan.operators.len() + 1);
            }
        }
    }
}

#[test]
fn grid_matches_pathfinding_and_repeats() {
    let world = GridWorld::random(120, 90, 0.25, 3);
    let ours = solve(&world, &Deadline::none());
    let reference = solve_astar(&world);
    match (&ours.outcome, &reference) {
        (SearchOutcome::Solved(plan), Some(r)) => {
            assert!((plan.cost - r.cost).abs() < 1e-9, "{} vs {}", plan.cost, r.cost)
        }
        (SearchOutcome::Infeasible, None) => {}
        (o, r) => panic!("disagreement: {o:?} vs {r:?}"),
    }
    let budget = ours.stats.expansions / 2;
    let a = solve(&world, &Deadline::expansions(budget));
    let b = solve(&world, &Deadline::expansions(budget));
    assert!(a.outcome.is_out_of_time());
    assert_eq!(a.outcome, b.outcome);
}

#[test]
fn zero_deadline_is_out_of_time_without_expanding() {
    let world = GridWorld::random(50, 50, 0.1, 1);
    for deadline in [Deadline::after(Duration::ZERO), Deadline::at(Instant::now()), Deadline::expansions(0)] {
        let report = solve(&world, &deadline);
        assert_eq!(report.stats.expansions, 0);
        assert_eq!(report.stats.generated, 0);
        match report.outcome {
            SearchOutcome::OutOfTime { best: None, .. } => {}
            other => panic!("expected OutOfTime with nothing, got {other:?}"),
        }
    }
}

#[test]
fn goal_at_start_is_solved_with_empty_plan() {
    let world = GridWorld::random(10, 10, 0.0, 1).with_goal((0, 0));
    let plan = solve(&world, &Deadline::expansions(1)).outcome.into_solved().expect("solved");
    assert!(plan.is_empty());
    assert_eq!(plan.cost, 0.0);
}

#[test]
fn wall_clock_deadline_is_honoured() {
    let world = GridWorld::random(2000, 2000, 0.2, 7).with_goal_walled_off();
    for budget_ms in [1u64, 5, 20] {
        let deadline = Deadline::after(Duration::from_millis(budget_ms));
        let at = deadline.instant().expect("wall clock");
        let report = solve(&world, &deadline);
        let late = Instant::now().saturating_duration_since(at);
        match &report.outcome {
            SearchOutcome::OutOfTime { cause: Interrupt::WallClock, best: best_so_far } => {
                assert!(best_so_far.is_some());
                assert!(report.stats.expansions > 0);
            }
            other => panic!("expected a wall-clock stop, got {:?}", other.solved().map(|p| p.cost)),
        }
        assert!(late < Duration::from_millis(50), "returned {late:?} after the deadline");
        let overshoot = report.stats.overshoot.expect("measured");
        assert!(overshoot <= late);
    }
}

#[test]
fn cancellation_flag_stops_the_search() {
    let world = GridWorld::random(2000, 2000, 0.2, 7).with_goal_walled_off();
    let flag = Arc::new(AtomicBool::new(false));
    let deadline = Deadline::none().with_cancel_flag(Arc::clone(&flag));
    let canceller = {
        let flag = Arc::clone(&flag);
        std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(5));
            flag.store(true, Ordering::Relaxed);
        })
    };
    let report = solve(&world, &deadline);
    canceller.join().expect("canceller thread");
    assert!(matches!(report.outcome, SearchOutcome::OutOfTime { cause: Interrupt::Cancelled, .. }));
    assert!(report.stats.overshoot.is_none());

    // Raised before the call: nothing is expanded.
    let report = solve(&world, &deadline);
    assert_eq!(report.stats.expansions, 0);
}

#[test]
fn infeasible_grid_is_infeasible() {
    let world = GridWorld::random(60, 60, 0.2, 5).with_goal_walled_off();
    assert_eq!(solve(&world, &Deadline::none()).outcome, SearchOutcome::Infeasible);
    assert!(solve_astar(&world).is_none());
}

#[test]
fn nan_and_negative_costs_are_rejected() {
    assert!(matches!(Cost::new(f64::NAN), Err(PlanError::NanCost { .. })));
    assert!(matches!(Cost::new(-1.0), Err(PlanError::NegativeCost { .. })));
    assert!(Cost::try_from(f64::NAN).is_err());
    let zero = Cost::new(-0.0).expect("negative zero is zero");
    assert_eq!(zero, Cost::ZERO);
    assert!(Cost::new(f64::INFINITY).expect("inf") > Cost::new(1e300).expect("big"));
}

#[test]
fn deadline_combinations() {
    let d = Deadline::expansions(10).and_expansions(3).and_after(Duration::from_secs(3600));
    assert_eq!(d.expansion_budget(), Some(3));
    assert!(!d.is_past(2));
    assert!(d.is_past(3));
    assert!(!Deadline::none().is_past(u64::MAX));
    assert!(Deadline::after(Duration::ZERO).is_past(0));
    assert!(Deadline::after(Duration::MAX).instant().is_none() || !Deadline::after(Duration::MAX).is_past(0));
}
