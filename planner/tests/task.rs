//! Task-level deliberation for the two-IRp-6 cell: found, minimal, valid, refinable.

use std::collections::{BTreeSet, HashSet, VecDeque};

use embodied_planner::PlanError;
use embodied_planner::deadline::Deadline;
use embodied_planner::search::{SearchOutcome, solve};
use embodied_planner::task::{
    GroundAction, Refiner, Rule, RuleId, TaskHeuristic, TaskProblem, TwoIrp6Cell, refine_plan,
};

/// Breadth-first enumeration over string fact sets, independent of the bitset engine:
/// the least number of actions to reach the goal, or `None`.
fn bfs_length(initial: &[String], rules: &[Rule], goal: &[String]) -> Option<usize> {
    let start: BTreeSet<String> = initial.iter().cloned().collect();
    let mut seen = HashSet::from([start.clone()]);
    let mut queue = VecDeque::from([(start, 0usize)]);
    while let Some((state, depth)) = queue.pop_front() {
        if goal.iter().all(|g| state.contains(g)) {
            return Some(depth);
        }
        for rule in rules {
            if rule.preconditions.iter().all(|p| state.contains(p)) {
                let mut next = state.clone();
                rule.delete.iter().for_each(|d| {
                    next.remove(d);
                });
                next.extend(rule.add.iter().cloned());
                if seen.insert(next.clone()) {
                    queue.push_back((next, depth + 1));
                }
            }
        }
    }
    None
}

/// Simulates a plan over string facts: every precondition must hold when its action runs.
fn simulate(initial: &[String], rules: &[&Rule]) -> BTreeSet<String> {
    let mut state: BTreeSet<String> = initial.iter().cloned().collect();
    for (step, rule) in rules.iter().enumerate() {
        for p in &rule.preconditions {
            assert!(state.contains(p), "step {step} `{}`: precondition `{p}` does not hold", rule.action);
        }
        for d in &rule.delete {
            state.remove(d);
        }
        state.extend(rule.add.iter().cloned());
    }
    state
}

fn plan_rules<'a>(problem: &'a TaskProblem, ops: &[RuleId]) -> Vec<&'a Rule> {
    ops.iter().map(|&id| problem.rule(id).expect("rule of this problem")).collect()
}

#[test]
fn transfer_needs_a_handover_and_is_minimal() {
    let cell = TwoIrp6Cell::new();
    for heuristic in [TaskHeuristic::GoalCount, TaskHeuristic::Zero] {
        let problem = cell.transfer_to_table_b("cube").expect("valid task").with_heuristic(heuristic);
        let plan = solve(&problem, &Deadline::none()).outcome.into_solved().expect("a plan exists");
        let actions = problem.actions(&plan).expect("own operators");
        let names: Vec<String> = actions.iter().map(|a| a.to_string()).collect();
        assert!(actions.iter().any(|a| a.name == "handover"), "no handover in {names:?}");

        let goal = vec!["on(cube,table_b)".to_string()];
        let shortest = bfs_length(&cell.initial_facts(), &cell.rules(), &goal).expect("reachable");
        assert_eq!(plan.len(), shortest, "plan {names:?} is not minimal");
        assert_eq!(plan.cost, shortest as f64);

        let end = simulate(&cell.initial_facts(), &plan_rules(&problem, &plan.operators));
        assert!(end.contains("on(cube,table_b)"));
        assert_eq!(problem.fact_names(plan.last_state().expect("non-empty")), end);
    }
}

#[test]
fn two_objects_both_ways_minimal() {
    let mut cell = TwoIrp6Cell::new();
    cell.objects = vec![("cube".into(), "table_a".into()), ("cylinder".into(), "table_b".into())];
    let goal_pairs = [("cube", "table_b"), ("cylinder", "table_a")];
    let problem = cell.problem(&goal_pairs).expect("valid");
    let report = solve(&problem, &Deadline::none());
    let plan = report.outcome.into_solved().expect("a plan exists");
    let goal: Vec<String> = goal_pairs.iter().map(|(o, l)| format!("on({o},{l})")).collect();
    let shortest = bfs_length(&cell.initial_facts(), &cell.rules(), &goal).expect("reachable");
    assert_eq!(plan.len(), shortest);
    let end = simulate(&cell.initial_facts(), &plan_rules(&problem, &plan.operators));
    assert!(goal.iter().all(|g| end.contains(g)));
    let handovers = problem.actions(&plan).expect("own").iter().filter(|a| a.name == "handover").count();
    assert_eq!(handovers, 2);

    // The heuristic only prunes: uniform-cost search expands at least as much.
    let blind = solve(&problem.clone().with_heuristic(TaskHeuristic::Zero), &Deadline::none());
    assert!(blind.stats.expansions >= report.stats.expansions);
    assert_eq!(blind.outcome.solved().map(|p| p.len()), Some(shortest));
}

#[test]
fn actions_carry_data_for_motion_refinement() {
    let problem = TwoIrp6Cell::new().transfer_to_table_b("cube").expect("valid");
    let plan = solve(&problem, &Deadline::none()).outcome.into_solved().expect("plan");
    for action in problem.actions(&plan).expect("own") {
        match action.name.as_str() {
            "grasp" | "place" => {
                let arm = action.param("arm").expect("arm");
                let loc = action.param("location").expect("location");
                assert!(TwoIrp6Cell::reach(arm).contains(&loc), "{action}: {arm} cannot reach {loc}");
                assert!(action.param("object").is_some());
            }
            "move" => {
                let arm = action.param("arm").expect("arm");
                for end in ["from", "to"] {
                    assert!(TwoIrp6Cell::reach(arm).contains(&action.param(end).expect("end")));
                }
            }
            "handover" => {
                assert!(action.param("from").is_some() && action.param("to").is_some());
                assert_eq!(action.param("location"), Some(TwoIrp6Cell::HANDOVER));
            }
            other => panic!("unexpected action {other}"),
        }
    }
}

/// A fake motion planner that records what it was asked and can be told to fail.
#[derive(Default)]
struct RecordingRefiner {
    calls: Vec<GroundAction>,
    fail_on: Option<&'static str>,
}

impl Refiner for RecordingRefiner {
    type Refined = String;
    fn refine(&mut self, action: &GroundAction) -> Result<String, PlanError> {
        self.calls.push(action.clone());
        if self.fail_on == Some(action.name.as_str()) {
            return Err(PlanError::Refiner { reason: "no collision-free path".into() });
        }
        Ok(format!("trajectory for {}", action.param("arm").or(action.param("from")).unwrap_or("?")))
    }
}

#[test]
fn refiner_hook_is_called_in_order_and_failures_name_the_step() {
    let problem = TwoIrp6Cell::new().transfer_to_table_b("cube").expect("valid");
    let plan = solve(&problem, &Deadline::none()).outcome.into_solved().expect("plan");
    let expected: Vec<GroundAction> = problem.actions(&plan).expect("own").into_iter().cloned().collect();

    let mut refiner = RecordingRefiner::default();
    let refined = refine_plan(&problem, &plan, &mut refiner).expect("fake refiner succeeds");
    assert_eq!(refiner.calls, expected);
    assert_eq!(refined.len(), plan.len());

    let mut failing = RecordingRefiner { fail_on: Some("handover"), ..Default::default() };
    let err = refine_plan(&problem, &plan, &mut failing).expect_err("handover fails");
    let step = expected.iter().position(|a| a.name == "handover").expect("has handover");
    match err {
        PlanError::RefinementFailed { step: s, ref action, .. } => {
            assert_eq!(s, step);
            assert!(action.starts_with("handover("));
        }
        other => panic!("unexpected error {other}"),
    }
    assert_eq!(failing.calls.len(), step + 1, "refinement must stop at the failing step");
}

#[test]
fn unreachable_goal_is_infeasible_and_bad_input_rejected() {
    let cell = TwoIrp6Cell::new();
    // Objects never rest at the handover pose: no rule makes it true.
    let problem = cell.problem(&[("cube", "handover")]).expect("well-formed");
    assert_eq!(solve(&problem, &Deadline::none()).outcome, SearchOutcome::Infeasible);
    let blind = problem.with_heuristic(TaskHeuristic::Zero);
    assert_eq!(solve(&blind, &Deadline::none()).outcome, SearchOutcome::Infeasible);

    assert!(matches!(cell.problem(&[("sphere", "table_b")]), Err(PlanError::InvalidTask { .. })));
    let mut bad = cell.rules();
    bad[0].cost = f64::NAN;
    assert!(matches!(
        TaskProblem::new(cell.initial_facts(), bad, ["on(cube,table_b)"]),
        Err(PlanError::NanCost { .. })
    ));
    let mut misplaced = cell.clone();
    misplaced.arms[0].1 = "table_b".into();
    assert!(misplaced.transfer_to_table_b("cube").is_err());
}

#[test]
fn task_search_respects_expansion_budget() {
    let problem = TwoIrp6Cell::new().transfer_to_table_b("cube").expect("valid");
    let a = solve(&problem, &Deadline::expansions(3));
    let b = solve(&problem, &Deadline::expansions(3));
    assert!(a.outcome.is_out_of_time());
    assert_eq!(a.outcome, b.outcome);
    assert_eq!(a.stats.expansions, 3);
}
