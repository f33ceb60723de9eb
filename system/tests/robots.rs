//! Robots in the world: every built-in scenario's log certified collision-free step to step
//! (robot-environment and robot-robot), the per-step clearance figure, plans that run together
//! checked against each other in time.
#![allow(clippy::unwrap_used)]

mod common;
use common::tmp;

use embodied_planner::trajectory::time_parameterize;
use embodied_planner::verify::{CheckSettings, Finding};
use embodied_system::plan::{AgentPlan, NamedHash, PLAN_FORMAT, PlanFile, robot_hash};
use embodied_system::scenario::BUILTIN_SCENARIOS;
use embodied_system::system::{RunArgs, RunOptions, run_scenario};
use embodied_system::verify::{verify_log, verify_plan};
use embodied_system::{AgentSpec, GoalSpec, Scenario, System};

#[test]
fn every_builtin_scenario_runs_and_its_log_passes_verify_with_collision_checking() {
    for (name, _) in BUILTIN_SCENARIOS {
        let path = tmp(&format!("{name}.jsonl"));
        let args = RunArgs { scenario: name.to_string(), log: Some(path.to_path_buf()), ..RunArgs::default() };
        let (summary, _) = run_scenario(&args).unwrap();
        assert!(summary.failure.is_none(), "{name}: {:?}", summary.failure);
        let scenario = embodied_system::scenario::load_scenario(name).unwrap();
        let v = verify_log(&scenario, &path, &CheckSettings::default()).unwrap();
        assert!(v.complete, "{name}");
        for a in &v.agents {
            let c = a.collision.as_ref().unwrap();
            assert!(c.ok, "{name}: {}: {:?}", a.agent, c.violation);
            assert_eq!(c.segments, v.steps - 1, "{name}: {}: every step-to-step motion", a.agent);
            assert!(c.min_clearance_m > 0.0, "{name}: {}", a.agent);
        }
        let robots = scenario.agents.len();
        assert_eq!(v.robot_robot.len(), robots * (robots - 1) / 2, "{name}: every two robots");
        for c in &v.robot_robot {
            assert!(c.ok && c.segments == v.steps - 1 && c.min_clearance_m > 0.0, "{name}: {c:?}");
        }
        assert!(v.certified, "{name}: {v:?}");
        // The per-step clearance figure: in every step line, positive, typed.
        let text = std::fs::read_to_string(&*path).unwrap();
        let mut smallest = (f64::INFINITY, f64::INFINITY);
        for line in text.lines().filter(|l| l.starts_with("{\"step\"")) {
            let s: embodied_system::log::LogStep = serde_json::from_str(line).unwrap();
            let c = s.clearance.unwrap_or_else(|| panic!("{name}: step {} without clearance", s.step));
            assert_eq!(c.robot_robot_m.is_some(), robots > 1, "{name}");
            if let Some(d) = c.robot_robot_m {
                smallest.0 = smallest.0.min(d);
            }
            if let Some(d) = c.robot_environment_m {
                smallest.1 = smallest.1.min(d);
            }
        }
        assert!(smallest.0 > 0.0 && smallest.1 > 0.0, "{name}: {smallest:?}");
        eprintln!(
            "{name}: {} steps certified in {:.0} ms; smallest robot-robot {:.4} m, robot-environment {:.4} m",
            v.steps,
            v.time_s * 1e3,
            smallest.0,
            smallest.1
        );
    }
}

/// Two Polycranks 0.8 m apart whose arms swing through the space between them: at the start
/// and at the end each points away from the other.
fn crossing() -> (Scenario, [Vec<Vec<f64>>; 2]) {
    let robot = embodied_models::builtin("polycrank").unwrap();
    let home = robot.home().to_vec();
    let with = |q1: f64| {
        let mut q = home.clone();
        q[0] = q1;
        q
    };
    let a = vec![with(-1.5), with(1.5)];
    let b = vec![with(std::f64::consts::PI - 1.5), with(std::f64::consts::PI + 1.5)];
    let scenario = Scenario::builder("crossing")
        .agent(AgentSpec::new("left", robot.clone()).start(a[0].clone()).goal(GoalSpec::Configuration(a[1].clone())))
        .agent(
            AgentSpec::new("right", robot)
                .at([0.8, 0.0, 0.0])
                .start(b[0].clone())
                .goal(GoalSpec::Configuration(b[1].clone())),
        )
        .build()
        .unwrap();
    (scenario, [a, b])
}

fn plan_file(scenario: &Scenario, paths: &[Vec<Vec<f64>>; 2], together: bool) -> PlanFile {
    let plans = scenario
        .agents
        .iter()
        .zip(paths)
        .map(|(agent, path)| AgentPlan {
            agent: agent.name.clone(),
            robot: NamedHash { name: agent.robot.name().to_string(), hash: robot_hash(&agent.robot) },
            joint_names: agent.robot.joint_names(),
            path: path.clone(),
            trajectory: time_parameterize(path, &agent.robot, 0.001),
            stats: serde_json::Value::Null,
            closed_chain: Vec::new(),
        })
        .collect();
    PlanFile {
        format: PLAN_FORMAT.into(),
        generator: None,
        scenario: NamedHash { name: scenario.name.clone(), hash: scenario.hash.clone() },
        plans,
        together: if together { vec![vec!["left".into(), "right".into()]] } else { Vec::new() },
    }
}

#[test]
fn verify_rejects_plans_that_are_each_free_but_collide_with_each_other_in_time() {
    let (scenario, paths) = crossing();
    let file = std::path::Path::new("crossing.json");
    let settings = CheckSettings::default();
    // One after another (the other stands at its start or where its plan ended): certified.
    let alone = verify_plan(&scenario, &plan_file(&scenario, &paths, false), file, &settings).unwrap();
    assert!(alone.certified, "{alone:?}");
    assert!(alone.together.is_empty());
    // At the same time: both arms reach into the middle at once.
    let v = verify_plan(&scenario, &plan_file(&scenario, &paths, true), file, &settings).unwrap();
    assert!(v.agents.iter().all(|a| a.certified), "each plan alone is free: {v:?}");
    assert_eq!(v.together.len(), 1);
    let c = &v.together[0];
    assert!(!c.ok && !v.certified, "{c:?}");
    let f = c.violation.as_ref().unwrap();
    let t = f.time().unwrap();
    let d = v.agents[0].report.duration_s;
    assert!(t > 0.1 * d && t < 0.9 * d, "they meet midway, at t = {t} of {d} s: {f}");
    match f {
        Finding::Collision { a, b, .. } | Finding::NotCertified { a, b, .. } | Finding::TooClose { a, b, .. } => {
            assert!(a.starts_with("left/") && b.contains("right/"), "{f}");
        }
        other => panic!("{other}"),
    }
    // The plan file says which run together; a name that has no plan is an input error.
    let mut bad = plan_file(&scenario, &paths, true);
    bad.together[0][1] = "nobody".into();
    let e = verify_plan(&scenario, &bad, file, &settings).unwrap_err().to_string();
    assert!(e.contains("together[0][1]") && e.contains("nobody"), "{e}");
}

#[test]
fn agents_bodies_are_in_the_world_and_seen_by_the_others_receptors() {
    let (scenario, _) = crossing();
    let mut system = System::new(&scenario, &RunOptions::default()).unwrap();
    system.step().unwrap();
    let bodies = system.world().bodies();
    assert_eq!(bodies.len(), 2);
    assert_eq!((bodies[0].name.as_str(), bodies[1].name.as_str()), ("left", "right"));
    // The right arm's base stands 0.8 m along x.
    assert!(bodies[1].spheres.iter().any(|(c, _)| (c[0] - 0.8).abs() < 0.2 && c[1].abs() < 0.2));
    let c = system.runtime().last_record().clearance.unwrap();
    assert!(c.robot_robot_m.unwrap() > 0.0 && c.robot_environment_m.is_none(), "{c:?}");
}
