//! The two-handed carry plan: closure, limits, collisions, the obstacle, bad input.
#![allow(clippy::unwrap_used)]

mod common;
use common::tmp;

use std::path::Path;

use embodied_executor::{Event, HaltReason};
use embodied_models::collision::CollisionModel;
use embodied_models::{Obstacle, Shape};
use embodied_planner::carry::{plan_carry, pose_difference, relative_tool_pose};
use embodied_system::scenario::{load_scenario, parse_scenario};

#[test]
fn carry_plan_keeps_the_grasp_stays_in_limits_and_goes_over_the_wall() {
    let scenario = load_scenario("two-irp6-carry").unwrap();
    let task = scenario.carry_task().unwrap();
    let plan = plan_carry(&task, &scenario.carry_settings()).unwrap();
    let traj = &plan.trajectory;
    let robot = &task.robot;
    let span = &plan.span;
    assert!(span.from_s > 0.5 && span.to_s > span.from_s + 0.3, "{span:?}");

    // Closure: the relative tool pose stays what it is at the grasp.
    let inside: Vec<usize> =
        (0..traj.t.len()).filter(|&k| traj.t[k] >= span.from_s && traj.t[k] <= span.to_s).collect();
    assert!(inside.len() > 300);
    let reference = relative_tool_pose(robot, &traj.q[inside[0]], task.end_effectors);
    let mut worst = (0.0f64, 0.0f64);
    for &k in &inside {
        let (m, r) = pose_difference(&reference, &relative_tool_pose(robot, &traj.q[k], task.end_effectors));
        worst = (worst.0.max(m), worst.1.max(r));
    }
    assert!(worst.0 < 1e-6 && worst.1 < 1e-6, "closure drift {worst:?}");
    // Outside the span the tools do move relative to each other (approach, retreat).
    let (m0, _) = pose_difference(&reference, &relative_tool_pose(robot, &traj.q[0], task.end_effectors));
    assert!(m0 > 0.05, "{m0}");

    // Velocity and acceleration limits, as finite differences of the samples.
    let limits = robot.limits();
    for k in 1..traj.t.len() {
        let dt = traj.t[k] - traj.t[k - 1];
        assert!(dt > 0.0);
        for (j, l) in limits.iter().enumerate() {
            assert!(traj.qd[k][j].abs() <= l.max_velocity * (1.0 + 1e-6), "qd at {k} joint {j}");
            assert!(traj.q[k][j] >= l.lower - 1e-9 && traj.q[k][j] <= l.upper + 1e-9);
            if dt > 1e-4 {
                let a = (traj.qd[k][j] - traj.qd[k - 1][j]) / dt;
                assert!(a.abs() <= l.max_acceleration * (1.0 + 1e-6), "accel {a} at t={} joint {j}", traj.t[k]);
                let v = (traj.q[k][j] - traj.q[k - 1][j]) / dt;
                assert!(v.abs() <= l.max_velocity * (1.0 + 1e-3), "position step {v} at {k} joint {j}");
            }
        }
    }

    // The object goes over the wall (its top at 1.0 m) and ends at its goal.
    let object = span.object.clone().unwrap();
    let in_tool = object.pose_in_tool().unwrap();
    let tool = |k: usize| robot.end_effector_poses(&traj.q[k], task.end_effectors[0]).1;
    let top = inside.iter().map(|&k| (tool(k) * in_tool).translation.z).fold(f64::MIN, f64::max);
    assert!(top > 1.0 + object.size[2] / 2.0, "highest object centre {top}");
    let end = tool(*inside.last().unwrap()) * in_tool;
    assert!((end.translation.vector - task.object_goal.translation.vector).norm() < 1e-6);

    // Collision-free: the arms with the object while it is held, among the obstacles and the
    // object where it stands otherwise.
    let other = robot.end_effectors()[task.end_effectors[1]].link;
    let held =
        CollisionModel::new(&object.attach(robot, task.end_effectors[0], &[other]).unwrap(), task.environment.clone());
    let box_at = |pose| {
        let s = task.object_size;
        Obstacle::new("bar", pose, Shape::cuboid(s[0] / 2.0, s[1] / 2.0, s[2] / 2.0))
    };
    let mut env_start = task.environment.clone();
    env_start.add(box_at(task.object_start));
    let mut env_goal = task.environment.clone();
    env_goal.add(box_at(task.object_goal));
    let (before, after) = (CollisionModel::new(robot, env_start), CollisionModel::new(robot, env_goal));
    for k in (0..traj.t.len()).step_by(7) {
        let t = traj.t[k];
        let model = if t < span.from_s {
            &before
        } else if t <= span.to_s {
            &held
        } else {
            &after
        };
        assert!(
            model.first_collision(&traj.q[k]).is_none(),
            "collision at t = {t}: {:?}",
            model.first_collision(&traj.q[k])
        );
    }
    assert!(plan.stats.object_segments >= 2, "{:?}", plan.stats);
}

#[test]
fn without_the_wall_the_object_path_is_straight_and_low() {
    let mut scenario = load_scenario("two-irp6-carry").unwrap();
    scenario.obstacles.retain(|o| o.obstacle.name != "wall");
    let task = scenario.carry_task().unwrap();
    let plan = plan_carry(&task, &scenario.carry_settings()).unwrap();
    assert_eq!(plan.stats.object_segments, 1, "{:?}", plan.stats);
    let straight = (task.object_goal.translation.vector - task.object_start.translation.vector).norm();
    assert!((plan.stats.object_path_m - straight).abs() < 1e-9);
}

#[test]
fn an_unreachable_goal_is_an_error_not_a_panic() {
    let mut scenario = load_scenario("two-irp6-carry").unwrap();
    let c = scenario.carry.as_mut().unwrap();
    c.object_goal.translation.vector.x = 2.5;
    let e = plan_carry(&scenario.carry_task().unwrap(), &scenario.carry_settings()).unwrap_err().to_string();
    assert!(e.contains("no path for the object"), "{e}");
}

fn carry_scenario(carry: &str) -> String {
    format!("name = \"c\"\ndescription = \"d\"\n[[agents]]\nname = \"pair\"\nrobot = \"two-irp6\"\n[carry]\n{carry}\n")
}

fn err_of(text: &str) -> String {
    match parse_scenario(text, Path::new("bad.toml"), Path::new(".")) {
        Ok(_) => panic!("expected an error for:\n{text}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn bad_carry_tables_name_the_place() {
    let ok =
        "object = \"bar\"\nsize = [0.8, 0.04, 0.04]\nstart_xyz = [0.55, 1.05, 0.95]\ngoal_xyz = [0.78, 1.05, 0.95]";
    assert!(
        parse_scenario(&carry_scenario(&format!("agent = \"pair\"\n{ok}")), Path::new("a"), Path::new(".")).is_ok()
    );
    let e = err_of(&carry_scenario(&format!("agent = \"nobody\"\n{ok}")));
    assert!(e.starts_with("bad.toml:7:") && e.contains("no agent `nobody`"), "{e}");
    let e = err_of(&carry_scenario(&format!("agent = \"pair\"\n{}", ok.replace("0.8, 0.04", "-0.8, 0.04"))));
    assert!(e.contains("size: expected three positive lengths"), "{e}");
    let e = err_of(&carry_scenario(&format!("agent = \"pair\"\nend_effectors = [\"irp6p\", \"irp6p\"]\n{ok}")));
    assert!(e.contains("two different end effectors"), "{e}");
    let e = err_of(&carry_scenario(&format!("agent = \"pair\"\nend_effectors = [\"irp6p\", \"hand\"]\n{ok}")));
    assert!(e.contains("no end effector `hand`"), "{e}");
    let e = err_of(&carry_scenario(&format!("agent = \"pair\"\nlattice_step = 0\n{ok}")));
    assert!(e.contains("lattice_step"), "{e}");
    let e = err_of(&carry_scenario(&format!("agent = \"pair\"\ncolour = 3\n{ok}")));
    assert!(e.contains("colour"), "{e}");
    let one_arm =
        "name = \"c\"\ndescription = \"d\"\n[[agents]]\nname = \"arm\"\nrobot = \"irp6-postument\"\n[carry]\n";
    let e = err_of(&format!("{one_arm}agent = \"arm\"\n{ok}"));
    assert!(e.contains("a carry needs two"), "{e}");
}

fn log_lines(path: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(path).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect()
}

/// The events of agent `agent` with their step times.
fn events(lines: &[serde_json::Value], agent: &str) -> Vec<(f64, Event)> {
    let mut out = Vec::new();
    for l in lines.iter().filter(|l| l.get("step").is_some()) {
        for e in l["agents"][agent]["events"].as_array().cloned().unwrap_or_default() {
            out.push((l["t"].as_f64().unwrap(), serde_json::from_value(e).unwrap()));
        }
    }
    out
}

#[test]
fn the_default_run_carries_the_bar_with_the_chain_closed_and_its_log_verifies() {
    use embodied_system::system::{RunArgs, run_scenario};
    let log = tmp("carry.jsonl");
    let args = RunArgs { scenario: "two-irp6-carry".into(), log: Some(log.clone()), ..RunArgs::default() };
    let (summary, _) = run_scenario(&args).unwrap();
    assert!(summary.failure.is_none(), "{:?}", summary.failure);
    let c = summary.closed_chain.as_ref().unwrap();
    assert!(c.completed && c.halts == 0, "{c:?}");
    assert!(c.qp_steps > 1000, "{c:?}");
    assert!(c.max_closure_error_m < 1e-4 && c.max_closure_error_rad < 1e-3, "{c:?}");
    assert!(c.max_tracking_error_m < 2e-3, "{c:?}");
    assert!(c.object_goal_error_m.unwrap() < 1e-3, "{c:?}");
    assert!(c.qp_p50_us > 0.0 && c.qp_p99_us >= c.qp_p50_us, "{c:?}");
    let lines = log_lines(&log);
    assert!(lines[0]["header"]["closed_chain"]["agent"] == "pair");
    let ev = events(&lines, "pair");
    let grasp = ev.iter().find(|(_, e)| *e == Event::Grasp).unwrap().0;
    let release = ev.iter().find(|(_, e)| *e == Event::Release).unwrap().0;
    assert!(grasp > 1.0 && release > grasp + 0.5, "{grasp} {release}");
    assert!(ev.iter().any(|(_, e)| matches!(e, Event::GoalReached { .. })));
    // Between grasp and release the closed-chain transition function drives the arms.
    for l in lines.iter().filter(|l| l.get("step").is_some()) {
        let t = l["t"].as_f64().unwrap();
        let b = l["agents"]["pair"]["behaviour"].as_str().unwrap();
        if t > grasp + 0.002 && t < release - 0.002 {
            assert!(b.ends_with("closed_chain"), "t = {t}: {b}");
        }
    }
    // The independent checker agrees: limits and closure within tolerance.
    let scenario = load_scenario("two-irp6-carry").unwrap();
    let settings = embodied_planner::verify::CheckSettings::default();
    let v = embodied_system::verify::verify_log(&scenario, &log, &settings).unwrap();
    assert!(v.certified, "{}", embodied_system::verify::render_log(&v));
}

#[test]
fn a_failing_closed_chain_qp_ends_in_a_safe_halt_within_the_limits() {
    use embodied_executor::closed_chain::ClosedChainConfig;
    use embodied_system::system::{RunArgs, RunOptions, run_scenario};
    // No room for damper rows: the first step near an obstacle is a failed QP.
    let log = tmp("halt.jsonl");
    let options = RunOptions {
        duration: Some(5.0),
        closed_chain: Some(ClosedChainConfig { max_dampers: 0, ..ClosedChainConfig::default() }),
        ..RunOptions::default()
    };
    let args = RunArgs { scenario: "two-irp6-carry".into(), log: Some(log.clone()), options, ..RunArgs::default() };
    let (summary, _) = run_scenario(&args).unwrap();
    let c = summary.closed_chain.as_ref().unwrap();
    assert_eq!(c.halts, 1, "{c:?}");
    assert!(!c.completed);
    assert!(c.halt_reason.as_deref().unwrap().contains("damper"), "{c:?}");
    let lines = log_lines(&log);
    let ev = events(&lines, "pair");
    let halt =
        ev.iter().find(|(_, e)| matches!(e, Event::HaltStarted { reason: HaltReason::ClosedChain, .. })).unwrap().0;
    assert!(!ev.iter().any(|(_, e)| *e == Event::Release));
    // From the halt on: velocities only shrink, within the acceleration limits, to rest.
    let robot = &load_scenario("two-irp6-carry").unwrap().agents[0].robot;
    let limits = robot.limits();
    let steps: Vec<&serde_json::Value> =
        lines.iter().filter(|l| l.get("step").is_some() && l["t"].as_f64().unwrap() >= halt).collect();
    let qd = |l: &serde_json::Value| -> Vec<f64> {
        l["agents"]["pair"]["qd"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect()
    };
    for w in steps.windows(2) {
        let (a, b) = (qd(w[0]), qd(w[1]));
        for j in 0..a.len() {
            assert!(b[j].abs() <= a[j].abs() + 1e-12, "joint {j} speeds up during the halt");
            assert!((b[j] - a[j]).abs() <= limits[j].max_acceleration * 0.001 * (1.0 + 1e-9));
        }
    }
    assert!(qd(steps.last().unwrap()).iter().all(|v| *v == 0.0), "not at rest");
}

#[test]
fn bench_qp_solves_every_held_step_with_both_solvers_and_they_agree() {
    let r = embodied_system::bench_qp::bench_qp("two-irp6-carry").unwrap();
    assert!(r.steps > 1000, "{r:?}");
    assert_eq!(r.halts, 0);
    assert!(r.max_qd_difference < 1e-3 && r.max_objective_difference < 1e-6, "{r:?}");
    assert!(r.dense_p50_us > 0.0 && r.clarabel_p50_us > 0.0 && r.dense_p99_us >= r.dense_p50_us);
    let e = embodied_system::bench_qp::bench_qp("irp6-pick").unwrap_err().to_string();
    assert!(e.contains("no [carry] table"), "{e}");
}

#[test]
fn carry_runs_replay_bit_for_bit() {
    use embodied_system::system::{RunArgs, RunOptions, run_scenario};
    let logs: Vec<String> = (0..2)
        .map(|k| {
            let log = tmp(&format!("replay{k}.jsonl"));
            let options = RunOptions { duration: Some(4.5), ..RunOptions::default() };
            let args =
                RunArgs { scenario: "two-irp6-carry".into(), log: Some(log.clone()), options, ..RunArgs::default() };
            run_scenario(&args).unwrap();
            // The whole file, summary line included: the log holds no wall-clock figure.
            std::fs::read_to_string(&log).unwrap()
        })
        .collect();
    assert!(logs[0].lines().count() == 4502, "{}", logs[0].lines().count());
    assert!(logs[0] == logs[1], "two runs with the same seed differ");
}
