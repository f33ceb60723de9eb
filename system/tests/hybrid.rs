//! Hybrid deliberative-behavioural runs of the built-in scenarios, end to end through
//! `embodied_system::system::run_scenario`, every behaviour asserted from the JSON Lines log.
#![allow(clippy::unwrap_used)]

mod common;
use common::tmp;

use embodied_executor::Event;
use embodied_models::collision::{CollisionModel, Environment};
use embodied_system::scenario::{ClockSpec, load_scenario};
use embodied_system::system::{RunArgs, RunOptions, run_scenario};

struct Log {
    steps: Vec<serde_json::Value>,
    text: String,
}

impl Log {
    fn q(&self, step: usize, agent: &str) -> Vec<f64> {
        self.steps[step]["agents"][agent]["q"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect()
    }
    fn qd(&self, step: usize, agent: &str) -> Vec<f64> {
        self.steps[step]["agents"][agent]["qd"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect()
    }
    /// (step, event) of `agent`, in order.
    fn events(&self, agent: &str) -> Vec<(usize, Event)> {
        let mut out = Vec::new();
        for (k, s) in self.steps.iter().enumerate() {
            for e in s["agents"][agent]["events"].as_array().into_iter().flatten() {
                out.push((k, serde_json::from_value(e.clone()).unwrap()));
            }
        }
        out
    }
    /// First step with an event of `agent` whose terminal form starts with `prefix`.
    fn first(&self, agent: &str, prefix: &str) -> Option<usize> {
        self.events(agent).into_iter().find(|(_, e)| e.to_string().starts_with(prefix)).map(|(k, _)| k)
    }
    /// The whole log file.
    fn file_text(&self) -> String {
        self.text.clone()
    }
}

fn run(scenario: &str, duration: f64, name: &str) -> Log {
    let path = tmp(name);
    let options = RunOptions { duration: Some(duration), ..RunOptions::default() };
    let args = RunArgs { scenario: scenario.into(), options, log: Some(path.clone()), ..RunArgs::default() };
    let (summary, _) = run_scenario(&args).unwrap();
    assert!(summary.failure.is_none(), "{:?}", summary.failure);
    let text = std::fs::read_to_string(&path).unwrap();
    let lines: Vec<serde_json::Value> = text.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    let steps: Vec<serde_json::Value> = lines.into_iter().filter(|l| l.get("step").is_some()).collect();
    assert_eq!(steps.len() as f64, (duration / 0.001).round(), "one line per step");
    Log { steps, text }
}

/// Every step: position, velocity and acceleration within the robot's limits.
fn assert_within_limits(log: &Log, scenario: &str, agent: &str) {
    let sc = load_scenario(scenario).unwrap();
    let robot = &sc.agents.iter().find(|a| a.name == agent).unwrap().robot;
    let limits = robot.limits();
    for k in 1..log.steps.len() {
        let (q, qd, qd0) = (log.q(k, agent), log.qd(k, agent), log.qd(k - 1, agent));
        for (j, l) in limits.iter().enumerate() {
            assert!(q[j] >= l.lower - 1e-9 && q[j] <= l.upper + 1e-9, "step {k} joint {j} position");
            assert!(qd[j].abs() <= l.max_velocity * (1.0 + 1e-9) + 1e-9, "step {k} joint {j} velocity");
            let a = (qd[j] - qd0[j]).abs() / 0.001;
            assert!(a <= l.max_acceleration * (1.0 + 1e-6) + 1e-6, "step {k} joint {j} acceleration {a}");
        }
    }
}

#[test]
fn polycrank_intruder_halts_replans_and_reaches_its_goal_without_colliding() {
    let log = run("polycrank-intruder", 6.0, "intruder.jsonl");
    let a = "polycrank";
    let ev = log.events(a);
    let appear = log.first(a, "world_changed").expect("the ball is sensed");
    let landed = log.first(a, "plan_landed id=1").expect("first plan");
    assert!(landed < appear, "moving when the ball appears: {ev:?}");
    assert_eq!(log.first(a, "plan_invalidated id=1: obstacle_in_path"), Some(appear), "{ev:?}");
    assert_eq!(log.first(a, "replan reason=obstacle_in_path"), Some(appear));
    // The halt from speed: it starts when the plan is dropped, and the arm was moving.
    let halt = log.first(a, "halt_started reason=no_valid_plan").expect("halt");
    assert_eq!(halt, appear);
    assert!(log.qd(appear - 1, a).iter().any(|v| v.abs() > 0.1), "moving fast when it halts");
    let finished = log.first(a, "halt_finished").expect("halt ends");
    let (_, e) = ev.iter().find(|(k, _)| *k == finished).unwrap();
    let Event::HaltFinished { distance, time_s, .. } = e else { panic!("{e}") };
    assert!(*distance > 0.0 && *time_s > 0.0, "{e}");
    // A new plan for the new world, from rest, then resumed and reached.
    let requested = log.first(a, "plan_requested id=2 world=2").expect("replan request");
    assert!(requested >= finished);
    let landed2 = log.first(a, "plan_landed id=2 world=2").expect("replan lands");
    assert!(log.first(a, "resumed id=2").is_some_and(|k| k == landed2));
    assert!(log.first(a, "goal_reached id=2").is_some(), "{ev:?}");
    // Never in collision: the scenario's obstacles, the ball once it is there.
    let sc = load_scenario("polycrank-intruder").unwrap();
    let robot = &sc.agents[0].robot;
    let before = CollisionModel::new(robot, sc.initial_environment());
    let mut env = Environment::new();
    for o in &sc.obstacles {
        env.add(o.obstacle.clone());
    }
    let after = CollisionModel::new(robot, env);
    let ball = sc.obstacles.iter().find(|o| o.appear_at.is_some()).unwrap();
    let appears_step = (ball.appear_at.unwrap() / 0.001).round() as usize;
    let mut min_clearance = f64::INFINITY;
    for k in 0..log.steps.len() {
        let q = log.q(k, a);
        let model = if k + 1 >= appears_step { &after } else { &before };
        assert!(!model.collides(&q), "collision at step {k}: {:?}", model.first_collision(&q));
        if k + 1 >= appears_step && k % 10 == 0 {
            min_clearance = min_clearance.min(model.distance(&q).distance);
        }
    }
    assert!(min_clearance > 0.0);
    // Goal reached: the last configuration is the goal (modulo turns on continuous joints).
    let goal = match &sc.agents[0].goal {
        Some(embodied_system::scenario::GoalSpec::Configuration(g)) => g.clone(),
        _ => unreachable!(),
    };
    assert!(robot.config_space().distance(&goal, &log.q(log.steps.len() - 1, a)) < 1e-3);
    assert_within_limits(&log, "polycrank-intruder", a);
}

#[test]
fn irp6_with_a_too_short_deadline_halts_then_resumes_when_the_plan_lands() {
    let log = run("irp6-late-plan", 6.0, "late.jsonl");
    let a = "irp6p";
    let ev = log.events(a);
    let sc = load_scenario("irp6-late-plan").unwrap();
    let deadline_steps = (sc.planner.deadline_ms / 1.0).ceil() as usize;
    assert_eq!(log.first(a, "plan_requested id=1"), Some(0), "{ev:?}");
    assert_eq!(log.first(a, "plan_late id=1"), Some(deadline_steps), "{ev:?}");
    assert_eq!(log.first(a, "halt_started reason=plan_late"), Some(deadline_steps));
    let landed = log.first(a, "plan_landed id=1 world=1 late").expect("the plan lands late");
    let (_, e) = ev.iter().find(|(k, _)| *k == landed).unwrap();
    let Event::PlanLanded { planning_ms, .. } = *e else { panic!("{e}") };
    assert!(planning_ms > sc.planner.deadline_ms, "{e}");
    assert!((planning_ms - landed as f64).abs() < 1e-9, "planning time is the simulated time: {e}");
    assert_eq!(log.first(a, "resumed id=1"), Some(landed));
    // Held still until the plan landed, moving after it.
    for k in 0..landed {
        assert!(log.qd(k, a).iter().all(|v| *v == 0.0), "step {k} moved before the plan landed");
    }
    assert!(log.qd(landed + 50, a).iter().any(|v| v.abs() > 0.0));
    assert!(log.first(a, "goal_reached id=1").is_some(), "{ev:?}");
    assert_within_limits(&log, "irp6-late-plan", a);
    // The deterministic budget: the same seed gives the same log file, byte for byte.
    let again = run("irp6-late-plan", 6.0, "late2.jsonl");
    assert_eq!(log.file_text(), again.file_text());
}

#[test]
fn two_irp6_arms_move_at_the_same_time_and_never_collide() {
    let log = run("two-irp6-together", 5.0, "together.jsonl");
    let (ot, p) = ("irp6ot", "irp6p");
    let coord = log.events("coordinator");
    let granted = |name: &str| Event::Granted { agent: name.into() };
    assert!(coord.iter().any(|(_, e)| *e == granted("irp6ot")), "{coord:?}");
    assert!(coord.iter().any(|(_, e)| *e == granted("irp6p")), "{coord:?}");
    assert!(coord.iter().any(|(_, e)| *e == Event::AllDone), "{coord:?}");
    // The second arm was told the first arm's planned sweep before it planned.
    let told = log.first(p, "told: `irp6ot` occupies").expect("sweep handed on");
    assert!(log.first(p, "plan_requested").is_some_and(|k| k > told));
    assert!(log.first(ot, "goal_reached").is_some() && log.first(p, "goal_reached").is_some());
    // At the same time: steps in which both arms move.
    let moving = |k: usize, a: &str| log.qd(k, a).iter().any(|v| v.abs() > 1e-3);
    let together = (0..log.steps.len()).filter(|&k| moving(k, ot) && moving(k, p)).count();
    assert!(together > 300, "both arms moving in {together} steps only");
    // Never in collision with each other: recomputed from the logged q of both arms.
    let sc = load_scenario("two-irp6-together").unwrap();
    let robot_ot = &sc.agents.iter().find(|a| a.name == ot).unwrap().robot;
    let robot_p = &sc.agents.iter().find(|a| a.name == p).unwrap().robot;
    let body_p = CollisionModel::new(robot_p, Environment::new());
    let mut min_distance = f64::INFINITY;
    for k in 0..log.steps.len() {
        let mut env = Environment::new();
        for o in body_p.link_shapes_world(&log.q(k, p)) {
            env.add(o);
        }
        let model = CollisionModel::new(robot_ot, env);
        let q = log.q(k, ot);
        assert!(!model.collides(&q), "the arms collide at step {k}: {:?}", model.first_collision(&q));
        if k % 5 == 0 {
            min_distance = min_distance.min(model.distance(&q).distance);
        }
    }
    assert!(min_distance > 0.0, "minimum distance {min_distance}");
    assert_within_limits(&log, "two-irp6-together", ot);
    assert_within_limits(&log, "two-irp6-together", p);
}

#[test]
fn in_two_irp6_together_the_handed_sweep_changes_the_second_arms_plan() {
    use embodied_planner::verify::Verifier;
    use embodied_system::plan::{agent_problem, plan_scenario};
    use embodied_system::scenario::GoalSpec;
    let sc = load_scenario("two-irp6-together").unwrap();
    let plan = plan_scenario(&sc, None).unwrap();
    let (ot, p) = (&plan.plans[0], &plan.plans[1]);
    assert_eq!((ot.agent.as_str(), p.agent.as_str()), ("irp6ot", "irp6p"));
    // The postument arm's straight swing passes through the on-track arm where it ends...
    let parked = vec![ot.path.last().unwrap().clone()];
    let model = agent_problem(&sc, 1, &[parked, Vec::new()]);
    let GoalSpec::Configuration(goal) = sc.agents[1].goal.clone().unwrap() else { panic!("a configuration goal") };
    let straight = [sc.agents[1].start.clone(), goal];
    assert!(Verifier::sampled(0.01).verify_path(&model, &straight).is_err(), "the straight swing is free");
    // ... and is free without it: the other arm is what the plan goes around.
    let alone = agent_problem(&sc, 1, &[Vec::new(), Vec::new()]);
    assert!(Verifier::sampled(0.01).verify_path(&alone, &straight).is_ok());
    // So the plan leaves the straight line.
    assert!(p.path.len() > 2, "{} waypoints", p.path.len());
}

#[test]
fn the_default_scenario_runs_through_the_deliberator_one_arm_after_the_other() {
    let log = run("two-irp6-cell", 4.0, "cell.jsonl");
    for a in ["irp6ot", "irp6p"] {
        assert!(log.first(a, "plan_requested id=1").is_some(), "{a}");
        assert!(log.first(a, "plan_landed id=1").is_some(), "{a}");
        assert!(log.first(a, "goal_reached").is_some(), "{a}: {:?}", log.events(a));
    }
    // One after the other: the postument arm asks for its plan after the track arm is done.
    let done = log.first("irp6ot", "task_done").unwrap();
    assert!(log.first("irp6p", "plan_requested").unwrap() > done);
}

#[test]
fn wall_clock_runs_report_real_planning_time() {
    let path = tmp("wall.jsonl");
    let options = RunOptions { duration: Some(3.0), clock: Some(ClockSpec::Wall), ..RunOptions::default() };
    let args = RunArgs { scenario: "irp6-pick".into(), options, log: Some(path.clone()), ..RunArgs::default() };
    let (summary, _) = run_scenario(&args).unwrap();
    assert!(summary.failure.is_none());
    assert_eq!(summary.clock, "wall");
    let text = std::fs::read_to_string(&path).unwrap();
    // Landed with its wall-clock planning time, or (on a loaded machine) failed past the
    // deadline and retried: either way the time is the wall clock's.
    assert!(text.contains("\"elapsed_us\":"), "no wall-clock planning time in the log");
    assert!(summary.agents[0].plans_requested >= 1);
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig { cases: 3, ..Default::default() })]

    /// With the deterministic budget (simulated planning time), the same seed gives the same log
    /// file byte for byte, whatever the seed and the simulated cost of a collision check.
    #[test]
    fn simulated_planning_time_replays_bit_for_bit(seed in 0u64..1000, us in 1.0f64..60.0) {
        let logs: Vec<String> = (0..2)
            .map(|k| {
                let path = tmp(&format!("replay-{seed}-{k}.jsonl"));
                let options = RunOptions {
                    duration: Some(0.8),
                    seed: Some(seed),
                    clock: Some(ClockSpec::Simulated { us_per_check: us }),
                    ..RunOptions::default()
                };
                let args =
                    RunArgs { scenario: "polycrank-intruder".into(), options, log: Some(path.clone()), ..RunArgs::default() };
                run_scenario(&args).unwrap();
                // The whole file, summary line included: it holds no wall-clock figure.
                std::fs::read_to_string(&path).unwrap()
            })
            .collect();
        proptest::prop_assert!(logs[0].contains("plan_landed"));
        proptest::prop_assert_eq!(&logs[0], &logs[1]);
    }
}
