//! Motion planning: paths that the independent verifier accepts, wrap-around on Polycrank,
//! clear errors, deadlines, determinism, and time parameterisation within limits.

use std::time::{Duration, Instant};

use embodied_models::collision::{CollisionModel, CollisionScratch, Environment, Obstacle};
use embodied_models::nalgebra::{Isometry3, Vector3};
use embodied_models::{JointKind, JointLimits, PlacedShape, Robot, RobotBuilder, Shape, builtin};
use embodied_planner::PlanError;
use embodied_planner::deadline::{Deadline, Interrupt};
use embodied_planner::motion::{
    CERTIFY_TOLERANCE, Goal, LazyPrm, MotionSettings, Outcome, PlannerKind, RrtConnect, Sampler, StateValidity,
    plan_motion, plan_motion_with, plan_with_kind,
};
use embodied_planner::roadmap::Roadmap;
use embodied_planner::trajectory::time_parameterize;
use embodied_planner::verify::{Finding, Verifier};
use proptest::prelude::*;

fn boxed(robot: &str, obstacles: &[(&str, [f64; 3], [f64; 3])]) -> CollisionModel {
    let robot = builtin(robot).expect("built-in robot");
    let mut env = Environment::new();
    for (name, c, h) in obstacles {
        env.add(Obstacle::new(*name, Isometry3::translation(c[0], c[1], c[2]), Shape::cuboid(h[0], h[1], h[2])));
    }
    CollisionModel::new(&robot, env)
}

/// IRp-6 on its postument with a box where its tool is at `HIT`, between two arm poses either side.
const HIT: [f64; 6] = [0.0, -1.6, 0.1, 0.0, 1.5, 0.0];
fn irp6_around_box() -> (CollisionModel, Vec<f64>, Vec<f64>) {
    let robot = builtin("irp6-postument").expect("robot");
    let (flange, _) = robot.end_effector_poses(&HIT, 0);
    let c = flange.translation.vector;
    let model = boxed("irp6-postument", &[("box", [c.x, c.y, c.z / 2.0], [0.12, 0.12, c.z / 2.0])]);
    let start = vec![-0.8, -1.6, 0.1, 0.0, 1.5, 0.0];
    let goal = vec![0.8, -1.6, 0.1, 0.0, 1.5, 0.0];
    (model, start, goal)
}

fn assert_plan_ok(model: &CollisionModel, start: &[f64], goal: &[f64], path: &[Vec<f64>]) {
    let space = model.robot().config_space();
    assert!(space.distance(&path[0], start) < 1e-9, "path starts at {:?}, not {start:?}", path[0]);
    let end = path.last().expect("non-empty path");
    assert!(space.distance(end, goal) < 1e-9, "path ends at {end:?}, not {goal:?}");
    if let Err(v) = Verifier::sampled(0.005).verify_path(model, path) {
        panic!("planned path fails verification: {v}");
    }
}

fn settings(planner: PlannerKind) -> MotionSettings {
    MotionSettings { planner, deadline: Deadline::after(Duration::from_secs(20)), ..MotionSettings::default() }
}

#[test]
fn irp6_plans_around_a_box_with_both_planners() {
    let (model, start, goal) = irp6_around_box();
    assert!(!model.motion_is_free(&start, &goal, 0.02), "the direct segment must be blocked for this test");
    for planner in [PlannerKind::RrtConnect, PlannerKind::LazyPrm] {
        let plan = plan_motion(&model, &start, &Goal::Configuration(goal.clone()), &settings(planner))
            .unwrap_or_else(|e| panic!("{planner:?}: {e}"));
        assert_plan_ok(&model, &start, &goal, &plan.path);
        assert!(plan.path.len() > 2);
        assert_ne!(plan.stats.planner, "direct");
    }
}

#[test]
fn rrt_connect_variants_and_races_return_certified_paths() {
    let (model, start, goal) = irp6_around_box();
    let goal_q = Goal::Configuration(goal.clone());
    let variants = [
        (true, false, Sampler::Uniform, 1.0, 1),
        (false, true, Sampler::Uniform, 1.0, 1),
        (true, true, Sampler::Halton, 2.0, 1),
        (false, false, Sampler::Uniform, 1.0, 2),
        (true, true, Sampler::Halton, 2.0, 3),
    ];
    for (dd, balance, sampler, range, racers) in variants {
        for seed in 0..3 {
            let s = MotionSettings {
                seed,
                rrt_dynamic_domain: dd,
                rrt_balance: balance,
                sampler,
                rrt_range: range,
                racers,
                ..settings(PlannerKind::RrtConnect)
            };
            let what = format!("dd {dd}, balance {balance}, {sampler}, range {range}, racers {racers}, seed {seed}");
            let plan = plan_motion(&model, &start, &goal_q, &s).unwrap_or_else(|e| panic!("{what}: {e}"));
            assert_plan_ok(&model, &start, &goal, &plan.path);
            for w in plan.path.windows(2) {
                assert!(model.motion_is_certified_free(&w[0], &w[1], CERTIFY_TOLERANCE), "{what}: uncertified {w:?}");
            }
            if racers == 1 {
                let again = plan_motion(&model, &start, &goal_q, &s).expect("same settings");
                assert_eq!(plan.path, again.path, "{what}: not deterministic");
            }
        }
    }
    // A race honours the caller's deadline: an exhausted budget stops every racer.
    let s = MotionSettings { racers: 2, deadline: Deadline::expansions(3), ..MotionSettings::default() };
    let err = plan_motion(&model, &start, &goal_q, &s).expect_err("three expansions cannot solve it");
    assert!(matches!(err, PlanError::OutOfTime { .. }), "{err}");
}

#[test]
fn lazy_rrt_connect_cuts_edges_whose_certificate_fails() {
    let (model, start, goal) = irp6_around_box();
    let goal_q = Goal::Configuration(goal.clone());
    // A probe step longer than any edge checks no inner configuration: edges through the box
    // join the trees, and only their certificates, once on a path, find them out. Every sample
    // over the whole joint box, so that long edges cross the box whatever the seed (with nine
    // tenths drawn near the trees, seed 1 found a path with no edge through it).
    for shortcut in [true, false] {
        for seed in 0..4 {
            let s = MotionSettings {
                seed,
                shortcut,
                lazy_probe: 100.0,
                rrt_local_bias: 0.0,
                rrt_late_local_bias: 0.0,
                ..settings(PlannerKind::RrtConnect)
            };
            let plan = plan_motion(&model, &start, &goal_q, &s).unwrap_or_else(|e| panic!("seed {seed}: {e}"));
            assert_plan_ok(&model, &start, &goal, &plan.path);
            for w in plan.path.windows(2) {
                assert!(model.motion_is_certified_free(&w[0], &w[1], CERTIFY_TOLERANCE), "uncertified {w:?}");
            }
            assert!(plan.stats.cut_edges > 0, "seed {seed}: no edge through the box was cut");
            assert_eq!(plan.stats.probe_checks, 0);
        }
    }
    // The default probes tree edges; 0 certifies every edge as it is added (nothing to cut).
    let lazy = plan_motion(&model, &start, &goal_q, &settings(PlannerKind::RrtConnect)).expect("lazy");
    assert!(lazy.stats.probe_checks > 0);
    let eager = MotionSettings { lazy_probe: 0.0, ..settings(PlannerKind::RrtConnect) };
    let eager = plan_motion(&model, &start, &goal_q, &eager).expect("eager");
    assert_plan_ok(&model, &start, &goal, &eager.path);
    assert_eq!((eager.stats.probe_checks, eager.stats.cut_edges), (0, 0));
    for bad in [-0.1, f64::NAN] {
        let s = MotionSettings { lazy_probe: bad, ..MotionSettings::default() };
        let err = plan_motion(&model, &start, &goal_q, &s).expect_err("bad lazy_probe");
        assert!(matches!(err, PlanError::InvalidInput { .. }), "{err}");
    }
}

#[test]
fn the_late_local_share_applies_from_its_sample_on() {
    let (model, start, goal) = irp6_around_box();
    let goal_q = Goal::Configuration(goal.clone());
    let run = |seed: u64, early: f64, late: f64, after: usize| {
        let s = MotionSettings {
            seed,
            rrt_local_bias: early,
            rrt_late_local_bias: late,
            rrt_late_after: after,
            ..settings(PlannerKind::RrtConnect)
        };
        let plan = plan_motion(&model, &start, &goal_q, &s).unwrap_or_else(|e| panic!("seed {seed}: {e}"));
        assert_plan_ok(&model, &start, &goal, &plan.path);
        (plan.path, plan.stats.samples, plan.stats.collision_checks)
    };
    for seed in 0..4 {
        // From the first sample on: the late share throughout.
        assert_eq!(run(seed, 0.0, 0.9, 0), run(seed, 0.9, 0.9, usize::MAX), "seed {seed}");
        // Never reached: the first share throughout.
        assert_eq!(run(seed, 0.0, 0.9, usize::MAX), run(seed, 0.0, 0.0, 0), "seed {seed}");
    }
}

#[test]
fn direct_segment_when_free() {
    let model = boxed("irp6-postument", &[]);
    let start = HIT.to_vec();
    let goal = vec![0.3, -1.5, 0.2, 0.1, 1.4, 0.2];
    let plan = plan_motion(&model, &start, &Goal::Configuration(goal.clone()), &MotionSettings::default())
        .expect("free space");
    assert_eq!(plan.stats.planner, "direct");
    assert_eq!(plan.path.len(), 2);
    assert_plan_ok(&model, &start, &goal, &plan.path);
}

#[test]
fn other_builtins_plan_around_boxes() {
    type Boxes = Vec<(&'static str, [f64; 3], [f64; 3])>;
    let cases: Vec<(&str, Boxes)> = vec![
        ("polycrank", vec![("box", [0.45, 0.45, 1.3], [0.1, 0.1, 0.1])]),
        ("two-irp6", vec![("box", [0.8, 1.05, 0.5], [0.15, 0.15, 0.5])]),
    ];
    for (name, obstacles) in cases {
        let model = boxed(name, &obstacles);
        let robot = model.robot();
        // Random valid start and goal, fixed seed, so the test covers each robot's whole range.
        let mut rng = embodied_models::Rng::new(7);
        let mut valid = || {
            (0..10_000)
                .map(|_| robot.random_configuration(&mut rng))
                .find(|q| !model.collides(q))
                .unwrap_or_else(|| panic!("{name}: no collision-free sample in 10000"))
        };
        for _ in 0..3 {
            let (start, goal) = (valid(), valid());
            let plan =
                plan_motion(&model, &start, &Goal::Configuration(goal.clone()), &settings(PlannerKind::RrtConnect))
                    .unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_plan_ok(&model, &start, &goal, &plan.path);
        }
    }
}

#[test]
fn rnt_plans_from_home() {
    let model = boxed("rnt", &[("box", [1.2, 1.2, 2.8], [0.2, 0.2, 0.2])]);
    let start = model.robot().home().to_vec();
    let mut goal = start.clone();
    goal[0] += 1.2;
    goal[3] -= 1.0;
    for q in [&start, &goal] {
        if let Some(c) = model.first_collision(q) {
            panic!("rnt fixture in collision at {q:?}: {c}");
        }
    }
    let plan = plan_motion(&model, &start, &Goal::Configuration(goal.clone()), &settings(PlannerKind::RrtConnect))
        .expect("rnt plan");
    assert_plan_ok(&model, &start, &goal, &plan.path);
}

#[test]
fn polycrank_wraps_around_pi() {
    let model = boxed("polycrank", &[]);
    let mut start = vec![0.0; 7];
    start[0] = 3.0;
    let mut goal = vec![0.0; 7];
    goal[0] = -3.0;
    for planner in [PlannerKind::RrtConnect, PlannerKind::LazyPrm] {
        let plan = plan_motion(&model, &start, &Goal::Configuration(goal.clone()), &settings(planner)).expect("plan");
        assert_plan_ok(&model, &start, &goal, &plan.path);
        let travel: f64 = plan.path.windows(2).map(|w| (w[1][0] - w[0][0]).abs()).sum();
        let expected = std::f64::consts::TAU - 6.0;
        assert!((travel - expected).abs() < 1e-6, "q1 travelled {travel} rad, expected {expected}");
        let last = plan.path.last().expect("path");
        assert!((last[0] - (3.0 + expected)).abs() < 1e-9, "unwrapped end {}", last[0]);
    }
}

#[test]
fn start_in_collision_names_the_pair() {
    let (model, _, goal) = irp6_around_box();
    // Find a start that hits the box (the arm pointing at it).
    let start = HIT.to_vec();
    let contact = model.first_collision(&start).expect("this start touches the box");
    let err = plan_motion(&model, &start, &Goal::Configuration(goal), &MotionSettings::default()).expect_err("start");
    match &err {
        PlanError::StartInCollision { contact: c } => {
            assert_eq!(c, &contact.to_string());
            assert!(err.to_string().contains("box"), "{err}");
        }
        other => panic!("expected StartInCollision, got {other:?}"),
    }
}

#[test]
fn goal_errors_are_specific() {
    let (model, start, _) = irp6_around_box();
    let robot = model.robot();
    // Outside limits.
    let mut outside = start.clone();
    outside[1] = robot.limits()[1].upper + 0.5;
    let err =
        plan_motion(&model, &start, &Goal::Configuration(outside), &MotionSettings::default()).expect_err("limits");
    assert!(matches!(err, PlanError::GoalUnreachable { .. }), "{err:?}");
    // In collision.
    let hit = HIT.to_vec();
    let err = plan_motion(&model, &start, &Goal::Configuration(hit), &MotionSettings::default()).expect_err("hit");
    assert!(matches!(err, PlanError::GoalInCollision { index: 0, .. }), "{err:?}");
    // Unreachable tool pose: 10 m away.
    let far = Goal::ToolPose { end_effector: 0, pose: Isometry3::translation(10.0, 0.0, 1.0) };
    let t = Instant::now();
    let err = plan_motion(&model, &start, &far, &MotionSettings::default()).expect_err("far");
    assert!(matches!(err, PlanError::GoalUnreachable { .. }), "{err:?}");
    assert!(t.elapsed() < Duration::from_secs(10));
    // Wrong input.
    let err = plan_motion(&model, &[0.0; 3], &Goal::Configuration(start.clone()), &MotionSettings::default());
    assert!(matches!(err, Err(PlanError::InvalidInput { .. })), "{err:?}");
    let mut nan = start.clone();
    nan[2] = f64::NAN;
    let err = plan_motion(&model, &nan, &Goal::Configuration(start.clone()), &MotionSettings::default());
    assert!(matches!(err, Err(PlanError::InvalidInput { .. })), "{err:?}");
    let err = plan_motion(&model, &start, &Goal::AnyOf(vec![]), &MotionSettings::default());
    assert!(matches!(err, Err(PlanError::InvalidInput { .. })), "{err:?}");
    for gain in [-0.1, f64::NAN, f64::INFINITY] {
        let settings = MotionSettings { shortcut_min_gain: gain, ..MotionSettings::default() };
        let err = plan_motion(&model, &start, &Goal::Configuration(start.clone()), &settings);
        assert!(
            matches!(&err, Err(PlanError::InvalidInput { message }) if message.contains("shortcut_min_gain")),
            "{err:?}"
        );
    }
}

#[test]
fn tool_pose_goal_is_reached() {
    let (model, start, goal_q) = irp6_around_box();
    let robot = model.robot();
    let (_, pose) = robot.end_effector_poses(&goal_q, 0);
    let plan =
        plan_motion(&model, &start, &Goal::ToolPose { end_effector: 0, pose }, &settings(PlannerKind::RrtConnect))
            .expect("plan to a tool pose");
    let end = plan.path.last().expect("path");
    let (_, reached) = robot.end_effector_poses(end, 0);
    let dp = (reached.translation.vector - pose.translation.vector).norm();
    let dr = reached.rotation.angle_to(&pose.rotation);
    assert!(dp < 1e-4 && dr < 1e-4, "tool pose missed by {dp} m, {dr} rad");
    Verifier::sampled(0.005).verify_path(&model, &plan.path).expect("verified");
    Verifier::default().verify_path(&model, &plan.path).expect("certified");
}

#[test]
fn goal_set_reaches_a_member() {
    let (model, start, goal) = irp6_around_box();
    let blocked = HIT.to_vec();
    let plan = plan_motion(&model, &start, &Goal::AnyOf(vec![blocked, goal.clone()]), &settings(PlannerKind::LazyPrm))
        .expect("plan to a set");
    assert_plan_ok(&model, &start, &goal, &plan.path);
}

#[test]
fn deadlines_are_honoured() {
    let (model, start, goal) = irp6_around_box();
    let goal = Goal::Configuration(goal);
    for planner in [PlannerKind::RrtConnect, PlannerKind::LazyPrm] {
        for deadline in [Deadline::after(Duration::ZERO), Deadline::expansions(0), Deadline::expansions(3)] {
            let t = Instant::now();
            let s = MotionSettings { planner, deadline, ..MotionSettings::default() };
            let err = plan_motion(&model, &start, &goal, &s).expect_err("no time to plan");
            assert!(matches!(err, PlanError::OutOfTime { .. }), "{planner:?}: {err:?}");
            assert!(t.elapsed() < Duration::from_millis(200), "took {:?}", t.elapsed());
        }
    }
    // A cancellation flag raised by another thread stops planning too.
    let flag = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(true));
    let s = MotionSettings { deadline: Deadline::none().with_cancel_flag(flag), ..MotionSettings::default() };
    let err = plan_motion(&model, &start, &goal, &s).expect_err("cancelled");
    assert!(matches!(err, PlanError::OutOfTime { .. }), "{err:?}");
}

#[test]
fn sample_budget_ends_with_no_path() {
    let (model, start, goal) = irp6_around_box();
    for planner in [PlannerKind::RrtConnect, PlannerKind::LazyPrm] {
        let s = MotionSettings { planner, max_samples: 0, ..MotionSettings::default() };
        let err = plan_motion(&model, &start, &Goal::Configuration(goal.clone()), &s).expect_err("no samples");
        assert!(matches!(err, PlanError::NoPath { samples: 0 }), "{planner:?}: {err:?}");
    }
}

/// RRT-Connect starts again with new trees when an attempt draws `max_samples` samples without a
/// path: with one sample fewer than a run needs, the same seed fails alone (the same draws) and
/// succeeds with restarts, having drawn more samples than one attempt may; a problem run out of
/// attempts reports every attempt's samples.
#[test]
fn a_stuck_rrt_connect_starts_again() {
    let (model, start, goal) = irp6_around_box();
    let goal = Goal::Configuration(goal);
    let base = MotionSettings { seed: 3, rrt_restarts: 0, ..settings(PlannerKind::RrtConnect) };
    let need = plan_motion(&model, &start, &goal, &base).expect("solvable").stats.samples;
    assert!(need >= 2, "{need} samples");
    let tight = MotionSettings { max_samples: need - 1, ..base.clone() };
    let err = plan_motion(&model, &start, &goal, &tight).expect_err("one sample short");
    assert!(matches!(err, PlanError::NoPath { samples } if samples == need - 1), "{err:?}");
    let again = MotionSettings { rrt_restarts: 50, ..tight.clone() };
    let plan = plan_motion(&model, &start, &goal, &again).expect("solved by a later attempt");
    assert!(plan.stats.restarts > 0 && plan.stats.samples > need - 1, "{:?}", plan.stats);
    let none = MotionSettings { max_samples: 1, rrt_restarts: 3, ..base };
    let err = plan_motion(&model, &start, &goal, &none).expect_err("one sample an attempt");
    assert!(matches!(err, PlanError::NoPath { samples: 4 }), "{err:?}");
}

/// A race whose racer 0 finds no path waits for the others: with a sample budget that one seed
/// cannot meet and the next can, the race of two answers with the second racer's path (that
/// seed's own plan). A validity wrapping a model races within the call, with the same answers;
/// a plain model hands its racers a clone they own.
#[test]
fn a_race_answers_with_another_racer_when_the_first_finds_no_path() {
    let (model, start, goal_q) = irp6_around_box();
    let goal = Goal::Configuration(goal_q.clone());
    let wrapped = OneByOne(model.clone());
    assert!(model.collision_model().is_some() && wrapped.collision_model().is_none());
    let base = MotionSettings { rrt_restarts: 0, max_samples: 12, ..settings(PlannerKind::RrtConnect) };
    let alone = |seed: u64| plan_motion(&model, &start, &goal, &MotionSettings { seed, ..base.clone() });
    let seed = (0..200u64)
        .find(|&s| alone(s).is_err() && alone(s + 1).is_ok())
        .expect("a seed that fails its budget followed by one that meets it");
    let second = alone(seed + 1).expect("meets the budget");
    let race = MotionSettings { seed, racers: 2, ..base.clone() };
    let plan = plan_motion(&model, &start, &goal, &race).expect("the second racer's path");
    assert_eq!(plan.path, second.path, "seed {seed}");
    assert_plan_ok(&model, &start, &goal_q, &plan.path);
    let scoped = plan_motion_with(&wrapped, &start, &goal, &race).expect("the second racer's path");
    assert_eq!(scoped.path, second.path, "seed {seed}, within the call");
    // Every racer out of samples: racer 0's error.
    let none = MotionSettings { max_samples: 1, racers: 3, ..base };
    for err in [plan_motion(&model, &start, &goal, &none), plan_motion_with(&wrapped, &start, &goal, &none)] {
        assert!(matches!(err, Err(PlanError::NoPath { samples: 1 })), "{err:?}");
    }
}

#[test]
fn same_seed_same_path() {
    let (model, start, goal) = irp6_around_box();
    for planner in [PlannerKind::RrtConnect, PlannerKind::LazyPrm] {
        let run = |seed| {
            let s = MotionSettings { seed, planner, parallel: true, ..MotionSettings::default() };
            plan_motion(&model, &start, &Goal::Configuration(goal.clone()), &s).expect("plan").path
        };
        assert_eq!(run(3), run(3));
    }
}

#[test]
fn roadmap_build_is_deterministic_and_queries_lazily() {
    let (model, start, goal) = irp6_around_box();
    let a = Roadmap::build(&model, 500, 10, 1);
    let b = Roadmap::build(&model, 500, 10, 1);
    assert!(a.vertex_count() > 100);
    assert_eq!(a.vertex_count(), b.vertex_count());
    for i in 0..a.vertex_count() {
        assert_eq!(a.configuration(i), b.configuration(i));
    }
    let mut roadmap = a;
    let path = roadmap.query(&model, &start, &goal, &Deadline::none()).expect("query");
    assert_plan_ok(&model, &start, &goal, &path);
    let (unchecked, valid, _) = roadmap.edge_states();
    assert!(unchecked > valid, "lazy: most edges stay unchecked ({unchecked} vs {valid})");
    let mut empty = Roadmap::new(model.robot(), 10, 0);
    let err = empty.query(&model, &start, &goal, &Deadline::none()).expect_err("empty");
    assert!(matches!(err, PlanError::EmptyRoadmap));
}

#[test]
fn verify_path_rejects_bad_paths() {
    let (model, start, goal) = irp6_around_box();
    for verifier in [Verifier::sampled(0.005), Verifier::certified(0.0)] {
        // The segment 0 -> 1 collides with the box: placed strictly inside it on the path parameter.
        match verifier.verify_path(&model, &[start.clone(), goal.clone()]) {
            Err(Finding::Collision { t, a, b, penetration_m, .. }) => {
                assert!(a.contains("box") || b.contains("box"), "{a} and {b}");
                assert!(t > 0.0 && t < 1.0, "{t}");
                assert!(penetration_m >= 0.0);
            }
            other => panic!("{verifier:?}: expected a segment collision, got {other:?}"),
        }
        let mut outside = start.clone();
        outside[1] = model.robot().limits()[1].lower - 0.1;
        match verifier.verify_path(&model, &[start.clone(), outside]) {
            Err(v @ Finding::Position { t: 1.0, .. }) => assert!(v.to_string().contains("by 1.000e-1"), "{v}"),
            other => panic!("expected out of limits, got {other:?}"),
        }
        match verifier.verify_path(&model, &[]) {
            Err(Finding::Malformed { message }) => assert!(message.contains("empty"), "{message}"),
            other => panic!("expected an empty path, got {other:?}"),
        }
    }
}

#[test]
fn trajectory_of_a_plan_verifies() {
    let (model, start, goal) = irp6_around_box();
    let plan = plan_motion(&model, &start, &Goal::Configuration(goal), &MotionSettings::default()).expect("plan");
    let traj = time_parameterize(&plan.path, model.robot(), 0.001);
    Verifier::sampled(0.005).verify_trajectory(&model, &traj).expect("trajectory verifies");
    Verifier::default().verify_trajectory(&model, &traj).expect("trajectory certified");
    let json = serde_json::to_string(&traj).expect("serialise");
    let back: embodied_planner::trajectory::Trajectory = serde_json::from_str(&json).expect("deserialise");
    assert_eq!(back.t.len(), traj.t.len());
    for (a, b) in back.q.iter().flatten().zip(traj.q.iter().flatten()) {
        assert!((a - b).abs() < 1e-12);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    #[test]
    #[allow(clippy::needless_range_loop)]
    fn time_parameterisation_respects_limits(
        robot_name in prop::sample::select(vec!["irp6-postument", "polycrank", "rnt"]),
        seed in any::<u64>(),
        n in 2usize..6,
        dt in prop::sample::select(vec![0.0, 0.001, 0.013]),
    ) {
        let robot = builtin(robot_name).expect("robot");
        let mut rng = embodied_models::Rng::new(seed);
        let path: Vec<Vec<f64>> = (0..n).map(|_| robot.random_configuration(&mut rng)).collect();
        let traj = time_parameterize(&path, &robot, dt);
        let limits = robot.limits();
        let space = robot.config_space();
        // Passes through every waypoint, in order.
        let mut k = 0;
        for w in &path {
            while k < traj.q.len() && space.distance(&traj.q[k], w) > 1e-9 { k += 1; }
            prop_assert!(k < traj.q.len(), "waypoint {:?} not on the trajectory", w);
        }
        for i in 1..traj.t.len() {
            let h = traj.t[i] - traj.t[i - 1];
            prop_assert!(h > 0.0);
            for j in 0..robot.dof() {
                let v = (traj.q[i][j] - traj.q[i - 1][j]) / h;
                let a = (traj.qd[i][j] - traj.qd[i - 1][j]) / h;
                prop_assert!(v.abs() <= limits[j].max_velocity * (1.0 + 1e-9) + 1e-9, "v {} > {}", v, limits[j].max_velocity);
                prop_assert!(a.abs() <= limits[j].max_acceleration * (1.0 + 1e-9) + 1e-9, "a {} > {}", a, limits[j].max_acceleration);
                prop_assert!(traj.qd[i][j].abs() <= limits[j].max_velocity * (1.0 + 1e-9));
            }
        }
        // sample() agrees with the samples and stays within the acceleration limits.
        let d = traj.duration();
        for s in 0..50 {
            let t = d * s as f64 / 49.0;
            let (_, qd, qdd) = traj.sample(t);
            for j in 0..robot.dof() {
                prop_assert!(qd[j].abs() <= limits[j].max_velocity * (1.0 + 1e-6) + 1e-9);
                prop_assert!(qdd[j].abs() <= limits[j].max_acceleration * (1.0 + 1e-6) + 1e-6);
            }
        }
        let (q_end, _, _) = traj.sample(d + 1.0);
        prop_assert!(space.distance(&q_end, &path[n - 1]) < 1e-9);
    }
}

/// Found by `time_parameterisation_respects_limits`: the last interval of this trajectory lasts
/// 17 µs (the leftover after the last 1 ms sample), and an acceleration taken from the
/// positions there read 7.0000158 rad/s² against a limit of 7.
#[test]
fn sampled_acceleration_stays_within_limits_on_a_short_last_interval() {
    let robot = builtin("irp6-postument").unwrap();
    let mut rng = embodied_models::Rng::new(5997461242674014337);
    // Drawn uniformly within the joint limits, as the property test drew them then (before the
    // screws' strokes were applied to the draws).
    let limits = robot.limits();
    let path: Vec<Vec<f64>> = (0..2).map(|_| limits.iter().map(|l| rng.range(l.lower, l.upper)).collect()).collect();
    let traj = time_parameterize(&path, &robot, 0.001);
    let n = traj.t.len();
    let last = traj.t[n - 1] - traj.t[n - 2];
    assert!(last < 1e-4, "the case needs a short last interval, got {last} s");
    for k in 0..=20 {
        let t = traj.t[n - 2] + last * k as f64 / 20.0;
        let (_, qd, qdd) = traj.sample(t);
        for j in 0..robot.dof() {
            assert!(qd[j].abs() <= limits[j].max_velocity * (1.0 + 1e-9), "t {t}: qd[{j}] = {}", qd[j]);
            assert!(qdd[j].abs() <= limits[j].max_acceleration * (1.0 + 1e-9), "t {t}: qdd[{j}] = {}", qdd[j]);
        }
    }
}

/// A user's own validity on top of the collision model: a forbidden rectangle of joint space
/// `(q0, q1)`, with an exact segment test (Liang-Barsky clipping).
struct Fenced {
    model: CollisionModel,
    q0: [f64; 2],
    q1: [f64; 2],
}

impl Fenced {
    fn inside(&self, q: &[f64]) -> bool {
        (self.q0[0]..=self.q0[1]).contains(&q[0]) && (self.q1[0]..=self.q1[1]).contains(&q[1])
    }

    /// Whether the straight segment `a`-`b` meets the closed rectangle.
    fn segment_meets(&self, a: &[f64], b: &[f64]) -> bool {
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        for (i, [lo, hi]) in [(0, self.q0), (1, self.q1)] {
            let d = b[i] - a[i];
            for (p, q) in [(-d, a[i] - lo), (d, hi - a[i])] {
                if p == 0.0 {
                    if q < 0.0 {
                        return false;
                    }
                } else if p < 0.0 {
                    t0 = t0.max(q / p);
                } else {
                    t1 = t1.min(q / p);
                }
            }
        }
        t0 <= t1
    }
}

impl StateValidity for Fenced {
    type Scratch = CollisionScratch;

    fn robot(&self) -> &Robot {
        self.model.robot()
    }

    fn scratch(&self) -> CollisionScratch {
        self.model.scratch()
    }

    fn collides(&self, q: &[f64], scratch: &mut CollisionScratch) -> bool {
        q.len() < 2 || self.inside(q) || self.model.collides_with(q, scratch)
    }

    fn first_collision(&self, q: &[f64]) -> Option<String> {
        if self.inside(q) { Some("the fence".into()) } else { self.model.first_collision(q).map(|c| c.to_string()) }
    }

    fn certify_motion(
        &self,
        qa: &[f64],
        qb: &[f64],
        tolerance: f64,
        check_ends: bool,
        scratch: &mut CollisionScratch,
    ) -> (bool, u32) {
        if self.segment_meets(qa, qb) {
            return (false, 1);
        }
        self.model.certify(qa, qb, tolerance, check_ends, scratch)
    }
}

/// Both public planners take any `StateValidity`: around a fence the collision model knows
/// nothing of, every segment of the path (shortcuts included) stays clear of it.
#[test]
fn planners_take_a_user_validity() {
    let fenced = Fenced { model: boxed("irp6-postument", &[]), q0: [-0.1, 0.1], q1: [-1.7, -1.5] };
    let (start, goal) = (vec![-0.8, -1.6, 0.1, 0.0, 1.5, 0.0], vec![0.8, -1.6, 0.1, 0.0, 1.5, 0.0]);
    assert!(fenced.segment_meets(&start, &goal), "test setup: the straight segment crosses the fence");
    let settings = settings(PlannerKind::RrtConnect);
    let goal_q = Goal::Configuration(goal.clone());
    for (name, outcome) in [
        ("rrt-connect", RrtConnect::new(settings.clone()).plan(&fenced, &start, &goal_q)),
        ("lazy-prm", LazyPrm::new(settings.clone()).plan(&fenced, &start, &goal_q)),
    ] {
        let plan = match outcome {
            Ok(Outcome::Solved(plan)) => plan,
            other => panic!("{name}: {other:?}"),
        };
        assert!(plan.stats.planner.starts_with(name), "{name}: {}", plan.stats.planner);
        assert!(plan.path.len() > 2, "{name}: a detour");
        for w in plan.path.windows(2) {
            assert!(!fenced.segment_meets(&w[0], &w[1]), "{name}: {:?} -> {:?} crosses the fence", w[0], w[1]);
        }
        assert_plan_ok(&fenced.model, &start, &goal, &plan.path);
    }
}

/// The one outcome type: solved, out of time with the work so far and what stopped it, and
/// infeasible when the sample budget is spent.
#[test]
fn motion_planners_report_outcomes() {
    let (model, start, goal) = irp6_around_box();
    let goal = Goal::Configuration(goal);
    let base = settings(PlannerKind::RrtConnect);
    for kind in PlannerKind::ALL {
        let out_of_time = MotionSettings { deadline: Deadline::expansions(2), ..base.clone() };
        match plan_with_kind(kind, &model, &start, &goal, &out_of_time) {
            Ok(Outcome::OutOfTime { best: Some(stats), cause: Interrupt::ExpansionBudget }) => {
                assert!(stats.collision_checks > 0, "{kind}: {stats:?}")
            }
            other => panic!("{kind}: expected out of time, got {other:?}"),
        }
        let no_samples = MotionSettings { max_samples: 0, ..base.clone() };
        assert!(matches!(plan_with_kind(kind, &model, &start, &goal, &no_samples), Ok(Outcome::Infeasible)), "{kind}");
        assert!(matches!(plan_with_kind(kind, &model, &start, &goal, &base), Ok(Outcome::Solved(_))), "{kind}");
        // A start in collision is an error, not an outcome.
        let inside = HIT.to_vec();
        assert!(matches!(plan_with_kind(kind, &model, &inside, &goal, &base), Err(PlanError::StartInCollision { .. })));
    }
}

/// A collision-check budget stops both planners, with that cause, within one certificate of
/// the budget; a budget above what a run needs changes nothing.
#[test]
fn a_check_budget_stops_planning_and_takes_nothing_below_it() {
    let (model, start, goal) = irp6_around_box();
    let goal = Goal::Configuration(goal);
    let base = MotionSettings { deadline: Deadline::none(), ..MotionSettings::default() };
    for kind in PlannerKind::ALL {
        let Ok(Outcome::Solved(plan)) = plan_with_kind(kind, &model, &start, &goal, &base) else {
            panic!("{kind}: no plan")
        };
        let needed = plan.stats.collision_checks;
        let roomy = MotionSettings { deadline: Deadline::none().and_checks(needed + 1), ..base.clone() };
        match plan_with_kind(kind, &model, &start, &goal, &roomy) {
            Ok(Outcome::Solved(p)) => assert_eq!(p.path, plan.path, "{kind}"),
            other => panic!("{kind}: a budget over the need changed the outcome: {other:?}"),
        }
        for budget in [1, needed / 4] {
            let tight = MotionSettings { deadline: Deadline::none().and_checks(budget), ..base.clone() };
            match plan_with_kind(kind, &model, &start, &goal, &tight) {
                Ok(Outcome::OutOfTime { best: Some(stats), cause: Interrupt::CheckBudget }) => {
                    let limit = budget + u64::from(embodied_models::collision::CERTIFY_MAX_CHECKS) + 64;
                    assert!(stats.collision_checks <= limit, "{kind}: {} checks for {budget}", stats.collision_checks);
                }
                // The shortcut pass is anytime: stopped there, the path so far is returned.
                Ok(Outcome::Solved(p)) => {
                    assert!(p.stats.collision_checks >= budget, "{kind}");
                    assert!(p.stats.collision_checks < needed, "{kind}: the budget did not stop it");
                }
                other => panic!("{kind}: expected out of time, got {other:?}"),
            }
        }
    }
}

#[test]
fn planner_names_round_trip() {
    for kind in PlannerKind::ALL {
        assert_eq!(kind.name().parse::<PlannerKind>(), Ok(kind));
        assert_eq!(kind.to_string(), kind.name());
    }
    let err = "rrt".parse::<PlannerKind>().expect_err("unknown");
    assert!(err.to_string().contains("rrt-connect, lazy-prm"), "{err}");
}

/// A collision model that answers every query one configuration at a time (the default
/// [`StateValidity::any_collides`]).
struct OneByOne(CollisionModel);

impl StateValidity for OneByOne {
    type Scratch = CollisionScratch;

    fn robot(&self) -> &Robot {
        self.0.robot()
    }

    fn scratch(&self) -> CollisionScratch {
        self.0.scratch()
    }

    fn collides(&self, q: &[f64], scratch: &mut CollisionScratch) -> bool {
        self.0.collides_with(q, scratch)
    }

    fn first_collision(&self, q: &[f64]) -> Option<String> {
        self.0.first_collision(q).map(|c| c.to_string())
    }

    fn certify_motion(
        &self,
        qa: &[f64],
        qb: &[f64],
        tolerance: f64,
        check_ends: bool,
        scratch: &mut CollisionScratch,
    ) -> (bool, u32) {
        self.0.certify(qa, qb, tolerance, check_ends, scratch)
    }
}

/// RRT-Connect's edge probes go to the model together, and the spherized UR5 checks them in
/// single-precision vector lanes: the paths are exactly those of one-by-one checks, among
/// boxes turned about z (MotionBenchMaker's form) and tilted ones.
#[test]
fn probes_in_vector_lanes_give_the_paths_of_single_checks() {
    use embodied_models::nalgebra::{Translation3, UnitQuaternion};
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/tests/fixtures");
    let mut robot = embodied_models::urdf::load_urdf(&dir.join("ur5_spherized.urdf"), Some(&dir.join("ur5.srdf")))
        .expect("UR5 fixture loads");
    // Two of its links overlap everywhere (the SRDF was written for the mesh model): disabled
    // as `bench mbm` does.
    embodied_models::collision::disable_always_colliding(&mut robot, 2000, 0x5eed);
    let mut env = Environment::new();
    let walls = [([0.45, 0.0, 0.35], [0.02, 0.35, 0.35], 0.3, 0.0), ([0.0, 0.5, 0.3], [0.3, 0.02, 0.3], -0.4, 0.2)];
    for (k, (c, h, yaw, tilt)) in walls.into_iter().enumerate() {
        let pose = Isometry3::from_parts(
            Translation3::new(c[0], c[1], c[2]),
            UnitQuaternion::from_euler_angles(tilt, 0.0, yaw),
        );
        env.add(Obstacle::new(format!("wall{k}"), pose, Shape::cuboid(h[0], h[1], h[2])));
    }
    let model = CollisionModel::new(&robot, env);
    assert!(model.certifies_in_batches(), "test setup: the sphere path answers in batches");
    let single = OneByOne(model.clone());
    let mut rng = embodied_models::Rng::new(3);
    let (mut solved, mut detours) = (0, 0);
    for seed in 0..8 {
        let (start, goal) = loop {
            let (a, b) = (robot.random_configuration(&mut rng), robot.random_configuration(&mut rng));
            if !model.collides(&a) && !model.collides(&b) {
                break (a, b);
            }
        };
        // No deadline (the two runs would share one, and a busy machine would decide the
        // answer): three attempts of 20,000 samples bound a walled-off goal's cost instead.
        let settings = MotionSettings {
            seed,
            rrt_restarts: 2,
            max_samples: 20_000,
            deadline: Deadline::none(),
            ..settings(PlannerKind::RrtConnect)
        };
        let goal_q = Goal::Configuration(goal.clone());
        let lanes = RrtConnect::new(settings.clone()).plan(&model, &start, &goal_q);
        let ones = RrtConnect::new(settings.clone()).plan(&single, &start, &goal_q);
        match (lanes, ones) {
            (Ok(Outcome::Solved(lanes)), Ok(Outcome::Solved(ones))) => {
                assert_eq!(lanes.path, ones.path, "seed {seed}");
                assert_eq!(lanes.stats.samples, ones.stats.samples, "seed {seed}");
                solved += 1;
                detours += (lanes.path.len() > 2) as usize;
                assert_plan_ok(&model, &start, &goal, &lanes.path);
            }
            // A goal walled off from the start: both spend the sample budget.
            (Ok(Outcome::Infeasible), Ok(Outcome::Infeasible)) => {}
            other => panic!("seed {seed}: {other:?}"),
        }
    }
    assert!(solved >= 4, "test setup: {solved} of 8 solved");
    assert!(detours > 0, "test setup: some plans leave the straight segment");
}

/// The two-IRp-6 cell among two posts, and a start and goal (both free, the straight segment
/// between them blocked) whose waypoints (one arm at its goal, the other at its start) are
/// free or in collision as `want` asks (first: the track's arm moved first; second: the
/// postument's), from the seeded draws.
fn two_arm_problem(seed: u64, want: [bool; 2]) -> (CollisionModel, Vec<f64>, Vec<f64>) {
    let model = boxed(
        "two-irp6",
        &[("post", [0.8, 1.05, 0.5], [0.15, 0.15, 0.5]), ("post2", [-0.7, 1.0, 0.4], [0.1, 0.1, 0.4])],
    );
    let robot = model.robot();
    let mut rng = embodied_models::Rng::new(seed);
    let mut free = || {
        (0..10_000)
            .map(|_| robot.random_configuration(&mut rng))
            .find(|q| !model.collides(q))
            .expect("a free configuration in 10,000 draws")
    };
    for _ in 0..20_000 {
        let (start, goal) = (free(), free());
        let first: Vec<f64> = goal[..7].iter().chain(&start[7..]).copied().collect();
        let second: Vec<f64> = start[..7].iter().chain(&goal[7..]).copied().collect();
        if [!model.collides(&first), !model.collides(&second)] == want
            && !model.motion_is_certified_free(&start, &goal, CERTIFY_TOLERANCE)
        {
            return (model, start, goal);
        }
    }
    panic!("test setup: no problem with waypoints {want:?} in 20,000 draws");
}

/// On a robot of two independent arms, a path moving one arm at a time is searched first; it
/// is certified like any (and the shortcuts may move both arms at once); switched off, the
/// search over every joint runs.
#[test]
fn independent_arms_are_planned_one_at_a_time_first() {
    assert_eq!(builtin("two-irp6").unwrap().independent_dof_groups().len(), 2);
    for (seed, want) in [(3, [true, true]), (4, [false, true]), (5, [true, false])] {
        let (model, start, goal) = two_arm_problem(seed, want);
        let plan = plan_motion(&model, &start, &Goal::Configuration(goal.clone()), &settings(PlannerKind::RrtConnect))
            .unwrap_or_else(|e| panic!("{want:?}: {e}"));
        assert_plan_ok(&model, &start, &goal, &plan.path);
        assert_eq!(plan.stats.planner, "rrt-connect-groups+shortcut", "{want:?}");
        let whole = MotionSettings { rrt_by_groups: false, ..settings(PlannerKind::RrtConnect) };
        let plan = plan_motion(&model, &start, &Goal::Configuration(goal.clone()), &whole).unwrap();
        assert_plan_ok(&model, &start, &goal, &plan.path);
        assert_eq!(plan.stats.planner, "rrt-connect+shortcut", "{want:?}");
    }
}

/// Two arms of three sphere links on a lift (one prismatic joint, first), among two posts.
fn lifted_arms_among_posts() -> CollisionModel {
    let mut b = RobotBuilder::new("lifted-arms");
    let id = Isometry3::identity();
    let ball = |x: f64, r: f64| PlacedShape::new(Isometry3::translation(x, 0.0, 0.0), Shape::sphere(r));
    let base = b.link("base", vec![PlacedShape::new(Isometry3::translation(0.0, 0.0, 0.1), Shape::sphere(0.1))]);
    let lift = b.link("lift", vec![PlacedShape::new(Isometry3::translation(0.0, 0.0, 0.35), Shape::sphere(0.08))]);
    let travel = JointLimits::new(0.0, 0.3, 0.5, 1.0);
    b.joint("lift", JointKind::Prismatic, base, lift, id, Vector3::z(), 0.0, id, travel);
    let turn = JointLimits::new(-2.5, 2.5, 1.0, 1.0);
    for (side, y) in [("left", 0.25), ("right", -0.25)] {
        let mut parent = lift;
        for k in 0..3 {
            let link = b.link(format!("{side}{k}"), vec![ball(0.08, 0.05), ball(0.2, 0.05)]);
            let at = if k == 0 { Isometry3::translation(0.0, y, 0.4) } else { Isometry3::translation(0.28, 0.0, 0.0) };
            let axis = if k == 1 { Vector3::y() } else { Vector3::z() };
            b.joint(format!("{side}_j{k}"), JointKind::Revolute, parent, link, at, axis, 0.0, id, turn);
            parent = link;
        }
    }
    let robot = b.build().expect("a robot");
    let mut env = Environment::new();
    for (name, c) in [("post", [0.55, 0.45, 0.4]), ("post2", [0.55, -0.45, 0.4])] {
        env.add(Obstacle::new(name, Isometry3::translation(c[0], c[1], c[2]), Shape::cuboid(0.06, 0.06, 0.4)));
    }
    CollisionModel::new(&robot, env)
}

/// Two arms on a lift that stays where it is: the lift is held and the arms are planned one at
/// a time first, as on a fixed torso; the lift never moves along the path. A lift that moves is
/// a group of its own: its leg moves it alone, then each arm's (or the reverse); every plan is
/// verified, and these problems are solved that way.
#[test]
fn arms_on_a_lift_are_planned_one_at_a_time() {
    let model = lifted_arms_among_posts();
    let robot = model.robot();
    assert_eq!(robot.dof(), 7);
    assert_eq!(robot.independent_dof_groups().len(), 1);
    assert_eq!(robot.branch_dofs(), [0]);
    let mut rng = embodied_models::Rng::new(11);
    let mut free = |lift: Option<f64>| {
        (0..10_000)
            .map(|_| {
                let mut q = robot.random_configuration(&mut rng);
                if let Some(h) = lift {
                    q[0] = h;
                }
                q
            })
            .find(|q| !model.collides(q))
            .expect("a free configuration in 10,000 draws")
    };
    let (mut held, mut moved, mut moved_by_groups) = (0, 0, 0);
    for _ in 0..400 {
        let start = free(None);
        let same = held < 3;
        let goal = free(same.then_some(start[0]));
        let first: Vec<f64> = start[..1].iter().chain(&goal[1..4]).chain(&start[4..]).copied().collect();
        let second: Vec<f64> = start[..4].iter().chain(&goal[4..]).copied().collect();
        if (same && (model.collides(&first) || model.collides(&second)))
            || model.motion_is_certified_free(&start, &goal, CERTIFY_TOLERANCE)
        {
            continue;
        }
        let plan = plan_motion(&model, &start, &Goal::Configuration(goal.clone()), &settings(PlannerKind::RrtConnect))
            .unwrap_or_else(|e| panic!("{start:?} -> {goal:?}: {e}"));
        assert_plan_ok(&model, &start, &goal, &plan.path);
        if same {
            assert_eq!(plan.stats.planner, "rrt-connect-groups+shortcut");
            assert!(plan.path.iter().all(|q| q[0] == start[0]), "the lift moved: {:?}", plan.path);
            held += 1;
        } else {
            moved += 1;
            moved_by_groups += usize::from(plan.stats.planner == "rrt-connect-groups+shortcut");
            if moved == 4 {
                break;
            }
        }
    }
    assert_eq!((held, moved), (3, 4), "test setup: problems found");
    assert!(moved_by_groups >= 2, "{moved_by_groups} of 4 with a moving lift planned group by group");
}

/// When neither order of the arms has a free waypoint, the search over every joint finds the
/// path; when only one arm must move, the other stays where it is along the whole path.
#[test]
fn arms_that_block_each_other_fall_back_and_a_still_arm_stays() {
    let (model, start, goal) = two_arm_problem(6, [false, false]);
    let plan = plan_motion(&model, &start, &Goal::Configuration(goal.clone()), &settings(PlannerKind::RrtConnect))
        .unwrap_or_else(|e| panic!("{e}"));
    assert_plan_ok(&model, &start, &goal, &plan.path);
    assert_eq!(plan.stats.planner, "rrt-connect+shortcut");

    // Only the postument's arm moves, and not straight to its goal.
    let (model, start, goal) = (7..40)
        .map(|seed| {
            let (model, start, goal) = two_arm_problem(seed, [true, true]);
            let goal: Vec<f64> = start[..7].iter().chain(&goal[7..]).copied().collect();
            (model, start, goal)
        })
        .find(|(model, start, goal)| !model.motion_is_certified_free(start, goal, CERTIFY_TOLERANCE))
        .expect("test setup: a blocked one-arm motion");
    let plan = plan_motion(&model, &start, &Goal::Configuration(goal.clone()), &settings(PlannerKind::RrtConnect))
        .unwrap_or_else(|e| panic!("{e}"));
    assert_plan_ok(&model, &start, &goal, &plan.path);
    assert_eq!(plan.stats.planner, "rrt-connect-groups+shortcut");
    for q in &plan.path {
        assert_eq!(q[..7], start[..7], "the still arm moved: {q:?}");
    }
}

/// A plan by groups with a racer thread free searches its legs two at a time, one of them on
/// the racer thread, and returns the path of one thread unless the caller's race of a leg gave
/// it (each leg draws from a stream of its own); every plan is verified. With a check budget
/// (whose count would depend on the threads) the legs stay on the caller's thread, and seeds
/// race.
#[test]
fn legs_two_at_a_time_give_the_path_of_one_thread() {
    for (seed, want) in [(3, [true, true]), (4, [false, true]), (5, [true, false]), (6, [true, true])] {
        let (model, start, goal) = two_arm_problem(seed, want);
        let goal = Goal::Configuration(goal);
        for plan_seed in 0..4 {
            let one = MotionSettings { seed: plan_seed, ..settings(PlannerKind::RrtConnect) };
            let two = MotionSettings { racers: 2, ..one.clone() };
            let alone = plan_motion(&model, &start, &goal, &one).unwrap_or_else(|e| panic!("{want:?}: {e}"));
            assert_eq!((alone.stats.legs_on_racer, alone.stats.legs_raced), (0, 0));
            let both = plan_motion(&model, &start, &goal, &two).unwrap_or_else(|e| panic!("{want:?}: {e}"));
            assert_eq!(both.stats.planner, "rrt-connect-groups+shortcut", "{want:?}");
            assert_plan_ok(&model, &start, goal_q(&goal), &both.path);
            if both.stats.legs_raced == 0 {
                assert_eq!(both.path, alone.path, "{want:?}, seed {plan_seed}");
            }
            let budgeted = MotionSettings { deadline: Deadline::none().and_checks(1_000_000), ..two.clone() };
            let counted = plan_motion(&model, &start, &goal, &budgeted).expect("a plan within the budget");
            assert_eq!(
                counted.stats.legs_on_racer + counted.stats.legs_raced,
                0,
                "{want:?}: legs beside a check budget"
            );
            assert_plan_ok(&model, &start, goal_q(&goal), &counted.path);
        }
    }
}

/// The configuration of a configuration goal.
fn goal_q(goal: &Goal) -> &[f64] {
    match goal {
        Goal::Configuration(q) => q,
        other => panic!("not a configuration goal: {other:?}"),
    }
}
