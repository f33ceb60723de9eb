//! Task-level deliberation end to end: the production-rule A* in the coordinator's `c_c`, its
//! operators refined into certified motion, the plan run by both arms as `Wait` / `Move`.
#![allow(clippy::unwrap_used)]

mod common;

use embodied_executor::Event;
use embodied_planner::task::GroundAction;
use embodied_system::scenario::{ClockSpec, load_scenario};
use embodied_system::system::{RunArgs, RunOptions, run_scenario};
use embodied_system::task::{TaskBudget, TaskDomain, deliberate};

fn stand(domain: &TaskDomain, name: &str) -> usize {
    domain.stand_index(name).unwrap()
}

/// The planning is necessary: neither arm reaches both the start and the goal stand (so a
/// handover on the shared stand is needed), and the greedy order (each part straight to its
/// goal level, top part first) is not applicable.
#[test]
fn two_irp6_stack_needs_handover_and_order() {
    let scenario = load_scenario("two-irp6-stack").unwrap();
    let domain = TaskDomain::new(&scenario).unwrap();
    let (ot, p) = (0, 1);
    let (a, x, b, c) = (stand(&domain, "a"), stand(&domain, "x"), stand(&domain, "b"), stand(&domain, "c"));
    // Reach comes from inverse kinematics and a collision check, not from the file.
    assert!(domain.reaches(ot, a) && domain.reaches(ot, x), "the on-track arm reaches a and x");
    assert!(!domain.reaches(ot, b) && !domain.reaches(ot, c), "the on-track arm reaches neither b nor c");
    assert!(domain.reaches(p, x) && domain.reaches(p, b) && domain.reaches(p, c), "the postument arm reaches x, b, c");
    assert!(!domain.reaches(p, a), "the postument arm does not reach a");
    // Greedy: the top part (p4) straight to its goal level on b: no arm can pick it and place it there.
    for arm in ["irp6ot", "irp6p"] {
        let pick = GroundAction::new("pick", &[("arm", arm), ("part", "p4"), ("stand", "a"), ("level", "3")]);
        let place = GroundAction::new("place", &[("arm", arm), ("part", "p4"), ("stand", "b"), ("level", "0")]);
        assert!(
            domain.rule_of(&pick).is_none() || domain.rule_of(&place).is_none(),
            "{arm} can carry p4 from a to b directly"
        );
    }
    // Order matters: p1 cannot be taken first (it is buried under p2..p4), and the greedy way of
    // clearing the start stand (every part onto the shared stand, then on to b) ends with p1 on
    // top of x, where the goal wants p4 at the bottom of b: that sequence reaches no goal.
    let mut state = embodied_planner::search::SearchProblem::initial(&domain.problem);
    let act = |name: &str, arm: &str, part: &str, stand: &str, level: &str| {
        let a = GroundAction::new(name, &[("arm", arm), ("part", part), ("stand", stand), ("level", level)]);
        domain.rule_of(&a).unwrap_or_else(|| panic!("no rule {a}"))
    };
    let pick_p1 = act("pick", "irp6ot", "p1", "a", "0");
    assert!(domain.problem.apply(&state, pick_p1).unwrap().is_none(), "p1 could be picked from under the stack");
    for (k, part) in ["p4", "p3", "p2", "p1"].into_iter().enumerate() {
        let pick = act("pick", "irp6ot", part, "a", &(3 - k).to_string());
        state = domain.problem.apply(&state, pick).unwrap().expect("greedy pick applies");
        let place = act("place", "irp6ot", part, "x", &k.to_string());
        state = domain.problem.apply(&state, place).unwrap().expect("greedy place applies");
    }
    let p4_to_b = act("pick", "irp6p", "p4", "x", "0");
    assert!(domain.problem.apply(&state, p4_to_b).unwrap().is_none(), "p4 is free after the greedy stacking");
}

/// The deliberation finds a plan that uses both arms and the shared stand, and every operator
/// comes with a certified trajectory from where its arm was.
#[test]
fn two_irp6_stack_deliberation_plans_handovers_and_buffering() {
    let scenario = load_scenario("two-irp6-stack").unwrap();
    let domain = TaskDomain::new(&scenario).unwrap();
    let clock = ClockSpec::Simulated { us_per_check: 2.0 };
    let report = deliberate(&domain, &scenario, &TaskBudget::new(clock, 10_000.0));
    let ops = report.operators.as_ref().unwrap_or_else(|| {
        panic!("no plan: {:?}; failures: {:?}", report.failure, &report.failures[..report.failures.len().min(8)])
    });
    for (k, o) in ops.iter().enumerate() {
        eprintln!("{k:2} {} after {:?} {:.2} s", o.name, o.after, o.trajectory.duration());
    }
    // Every part is picked and placed at least twice (once by each arm).
    assert!(ops.len() >= 16, "{} operators", ops.len());
    let on = |stand: &str| ops.iter().filter(|o| o.name.contains(&format!("stand={stand},"))).count();
    assert!(on("x") >= 8, "every part passes the shared stand: {}", on("x"));
    // Handed over one at a time, in the order the goal stack needs: no detour through the buffer c.
    assert!(on("c") == 0, "the plan buffers parts on c: {}", on("c"));
    let places_on_x: Vec<&str> = ops
        .iter()
        .filter(|o| o.name.starts_with("place(") && o.name.contains("stand=x,"))
        .map(|o| &o.name[..])
        .collect();
    assert!(places_on_x.iter().all(|n| n.contains("level=0")), "parts were stacked on x: {places_on_x:?}");
    assert!(ops.iter().any(|o| o.arm == 0) && ops.iter().any(|o| o.arm == 1));
    // Some operator may run alongside one of the other arm (not every pair is ordered).
    let independent = ops
        .iter()
        .enumerate()
        .any(|(j, o)| (0..j).any(|i| ops[i].arm != o.arm && o.after.iter().all(|(k, t)| *k != i || t.is_finite())));
    assert!(independent, "the plan leaves no room for the arms to act at once");
    let (planning_ms, motion_ms) = report.planning_ms(clock, 20.0);
    assert!(report.expansions > 0 && report.refinements as usize >= ops.len() && motion_ms > 0.0);
    eprintln!(
        "two-irp6-stack: {} operators, cost {:.2}, {} expansions, {} searches, refinements {} tried / {} failed, {} checks, planning {planning_ms:.1} ms (motion {motion_ms:.1} ms) simulated; wall: search {:?}, motion {:?}; straight segment collides in {} operators",
        ops.len(),
        report.cost,
        report.expansions,
        report.searches,
        report.refinements,
        report.refinements_failed,
        report.collision_checks,
        report.search_wall,
        report.motion_wall,
        ops.iter().filter(|o| o.straight_collides).count()
    );
}

/// The run: the plan lands, every operator starts and finishes in its arm, both arms move at
/// once at some time, and the coordinator hears that all is done. Two runs write the same log.
#[test]
fn two_irp6_stack_runs_concurrently_and_replays_bit_for_bit() {
    let spans = run_twice("two-irp6-stack");
    let overlap = spans.iter().any(|(a, s0, e0)| spans.iter().any(|(b, s1, e1)| a != b && s0 < e1 && s1 < e0));
    assert!(overlap, "the two arms never moved at the same time");
}

#[test]
fn polycrank_sort_runs_and_replays_bit_for_bit() {
    let spans = run_twice("polycrank-sort");
    assert!(spans.len() >= 6, "{spans:?}");
}

/// Run scenario `name` twice with its seed; both logs must be the same bytes. Returns the
/// operators' (agent, start, end) of the first run, after checking them.
fn run_twice(name: &str) -> Vec<(String, f64, f64)> {
    let dir = common::TempDir::new(name);
    let mut spans = Vec::new();
    let logs: Vec<String> = (0..2)
        .map(|k| {
            let log = dir.join(format!("run{k}.jsonl"));
            let args = RunArgs {
                scenario: name.into(),
                log: Some(log.clone()),
                options: RunOptions::default(),
                ..RunArgs::default()
            };
            let (summary, _) = run_scenario(&args).unwrap();
            assert!(summary.failure.is_none(), "{:?}", summary.failure);
            if k == 0 {
                spans = check_run(name, &summary.events);
            }
            std::fs::read_to_string(&log).unwrap()
        })
        .collect();
    assert!(logs[0] == logs[1], "{name}: two runs with the same seed differ");
    spans
}

fn check_run(name: &str, events: &[(f64, String, Event)]) -> Vec<(String, f64, f64)> {
    let found = events.iter().find_map(|(t, _, e)| match e {
        Event::TaskPlanFound { operators, .. } => Some((*t, *operators)),
        _ => None,
    });
    let (t_plan, n) = found.expect("a task plan landed");
    let mut spans: Vec<(String, f64, f64)> = Vec::new();
    for index in 0..n {
        let start = events.iter().find_map(|(t, a, e)| match e {
            Event::OperatorStarted { index: i, .. } if *i == index => Some((*t, a.clone())),
            _ => None,
        });
        let end = events.iter().find_map(|(t, _, e)| match e {
            Event::OperatorFinished { index: i, error, .. } if *i == index => Some((*t, *error)),
            _ => None,
        });
        let (t0, agent) = start.unwrap_or_else(|| panic!("operator {index} never started"));
        let (t1, error) = end.unwrap_or_else(|| panic!("operator {index} never finished"));
        assert!(t0 >= t_plan && t1 > t0, "operator {index}: {t0} .. {t1}");
        assert!(error < 0.01, "operator {index} ended {error} from its last configuration");
        spans.push((agent, t0, t1));
    }
    assert!(events.iter().any(|(_, a, e)| a == "coordinator" && matches!(e, Event::AllDone)), "no all_done");
    let end = spans.iter().map(|s| s.2).fold(0.0, f64::max);
    eprintln!("{name} run: plan landed at {t_plan:.3} s, {n} operators executed by {end:.3} s");
    spans
}

/// `irp6-pick` is true to its description: the straight joint-space line from the front
/// position to the pick pose runs into the pillar, and the plan lifts the wrist over it.
#[test]
fn irp6_pick_plan_lifts_the_wrist_over_the_pillar() {
    let scenario = load_scenario("irp6-pick").unwrap();
    let agent = &scenario.agents[0];
    let model = embodied_system::plan::agent_problem(&scenario, 0, &[]);
    let Some(embodied_system::GoalSpec::Configuration(goal)) = &agent.goal else { panic!("a configuration goal") };
    assert!(!model.motion_is_free(&agent.start, goal, 0.01), "the straight line misses the pillar");
    let plan = embodied_system::plan::plan_scenario(&scenario, None).unwrap();
    let path = &plan.plans[0].path;
    assert!(path.len() > 2, "the plan is a straight line: {path:?}");
    let pillar = scenario.obstacles.iter().find(|o| o.obstacle.name == "pillar").unwrap();
    let top = pillar.obstacle.pose.translation.vector.z * 2.0; // the pillar stands on the floor
    let highest = plan.plans[0]
        .trajectory
        .q
        .iter()
        .map(|q| agent.robot.end_effector_poses(q, 0).1.translation.vector.z)
        .fold(f64::NEG_INFINITY, f64::max);
    let tool = |q: &[f64]| agent.robot.end_effector_poses(q, 0).1.translation.vector.z;
    eprintln!(
        "irp6-pick: {} waypoints, tool z start {:.3} goal {:.3} highest {highest:.3}, pillar top {top:.3}",
        path.len(),
        tool(&agent.start),
        tool(goal)
    );
    assert!(highest > top, "the tool never rises over the pillar's top ({highest:.3} <= {top:.3})");
}

/// `polycrank-sort`: the order is the search's (the parts must pass the buffer), and the
/// continuous joint 1 crosses +-pi on the short way between the stations.
#[test]
fn polycrank_sort_orders_the_parts_and_crosses_pi() {
    let scenario = load_scenario("polycrank-sort").unwrap();
    let domain = TaskDomain::new(&scenario).unwrap();
    for name in ["a", "b", "c"] {
        eprintln!("{name}: {:?}", domain.reach_levels(0, stand(&domain, name)));
        assert!(domain.reaches(0, stand(&domain, name)), "Polycrank does not reach {name}");
    }
    let clock = ClockSpec::Simulated { us_per_check: 2.0 };
    let report = deliberate(&domain, &scenario, &TaskBudget::new(clock, 10_000.0));
    let ops =
        report.operators.as_ref().unwrap_or_else(|| panic!("no plan: {:?} {:?}", report.failure, report.failures));
    for (k, o) in ops.iter().enumerate() {
        let q1: Vec<f64> = o.path.iter().map(|q| q[0]).collect();
        eprintln!("{k:2} {} {:.2} s q1 {:?}", o.name, o.trajectory.duration(), q1);
    }
    let via_c = ops.iter().filter(|o| o.name.contains("stand=c,")).count();
    assert!(via_c >= 2, "the parts do not pass the buffer: {via_c}");
    // Crossing +-pi: an unwrapped joint-1 value beyond pi in magnitude along some path.
    let crosses = ops.iter().any(|o| {
        o.path.windows(2).any(|w| (w[0][0].abs() <= std::f64::consts::PI) != (w[1][0].abs() <= std::f64::consts::PI))
    });
    assert!(crosses, "no motion crosses +-pi");
    let (planning_ms, motion_ms) = report.planning_ms(clock, 20.0);
    eprintln!(
        "polycrank-sort: {} operators, cost {:.2}, {} expansions, {} searches, refinements {} tried / {} failed, {} checks, planning {planning_ms:.1} ms (motion {motion_ms:.1} ms) simulated; wall: search {:?}, motion {:?}",
        ops.len(),
        report.cost,
        report.expansions,
        report.searches,
        report.refinements,
        report.refinements_failed,
        report.collision_checks,
        report.search_wall,
        report.motion_wall
    );
}
