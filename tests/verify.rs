//! `embodied verify`: the certified plan checker and the run-log checker, end to end.
#![allow(clippy::unwrap_used)]

mod common;
use common::{TempDir, embodied};

use std::path::{Path, PathBuf};

use embodied::plan::{PlanFile, agent_problem, plan_scenario};
use embodied::scenario::{BUILTIN_SCENARIOS, load_scenario};
use embodied::verify::{verify_log, verify_plan};
use embodied_models::collision::{CollisionModel, Environment, Obstacle};
use embodied_models::nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use embodied_models::{Shape, builtin};
use embodied_planner::carry::{CarriedObject, ClosedChainSpan};
use embodied_planner::trajectory::Trajectory;
use embodied_planner::verify::certified::check_closure;
use embodied_planner::verify::{CheckSettings, CollisionReport, Finding, TrajectoryReport, Verifier};

/// The certified verifier's collision check (every pair apart, no clearance required).
fn check_collisions(
    model: &CollisionModel,
    traj: &Trajectory,
    spans: &[ClosedChainSpan],
    s: &CheckSettings,
) -> CollisionReport {
    Verifier::certified(0.0).with_settings(*s).check_collisions(model, traj, spans)
}

/// Everything the certified verifier checks.
fn check_trajectory(
    model: &CollisionModel,
    traj: &Trajectory,
    spans: &[ClosedChainSpan],
    s: &CheckSettings,
) -> TrajectoryReport {
    Verifier::certified(0.0).with_settings(*s).check_trajectory(model, traj, spans)
}

fn temp_dir(name: &str) -> TempDir {
    TempDir::new(name)
}

fn plan_of(name: &str) -> PlanFile {
    let scenario = load_scenario(name).unwrap();
    plan_scenario(&scenario, Some(30_000.0)).unwrap()
}

fn write_plan(dir: &Path, plan: &PlanFile) -> PathBuf {
    let path = dir.join("plan.json");
    std::fs::write(&path, serde_json::to_string(plan).unwrap()).unwrap();
    path
}

// (a) Every plan `embodied plan` writes for the built-in scenarios verifies.
#[test]
fn every_builtin_plan_is_certified() {
    let settings = CheckSettings::default();
    for (name, _) in BUILTIN_SCENARIOS {
        let scenario = load_scenario(name).unwrap();
        if scenario.agents.iter().all(|a| a.goal.is_none()) && scenario.carry.is_none() {
            continue;
        }
        let plan = plan_scenario(&scenario, Some(30_000.0)).unwrap();
        let v = verify_plan(&scenario, &plan, Path::new("plan.json"), &settings).unwrap();
        // The CLI's default budget of distance evaluations changes nothing.
        let budgeted = CheckSettings { max_evaluations: Some(embodied::verify::DEFAULT_MAX_EVALUATIONS), ..settings };
        let b = verify_plan(&scenario, &plan, Path::new("plan.json"), &budgeted).unwrap();
        assert!(!b.budget_exhausted && b.distance_evaluations == v.distance_evaluations, "{name}");
        for (a, x) in v.agents.iter().zip(&b.agents) {
            assert_eq!((a.certified, a.report.findings()), (x.certified, x.report.findings()), "{name}");
        }
        for a in &v.agents {
            let c = &a.report.collision;
            assert!(a.certified, "{name}/{}: {:?} {:?}", a.agent, a.report.findings(), a.timing);
            assert_eq!(c.certified_segments, c.segments, "{name}/{}", a.agent);
            assert!(c.min_clearance_m > 0.0 && c.certified_clearance_m > 0.0, "{name}/{}: {c:?}", a.agent);
        }
        assert!(v.certified && v.warnings.is_empty(), "{name}: {:?}", v.warnings);
    }
}

#[test]
fn cli_verifies_a_plan_it_wrote() {
    let dir = temp_dir("cli-ok");
    let plan = dir.join("p.json");
    let (code, _, err) = embodied(&["plan", "two-irp6-cell", "-o", plan.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let (code, out, err) = embodied(&["verify", "two-irp6-cell", plan.to_str().unwrap()]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("irp6ot: CERTIFIED") && out.contains("irp6p: CERTIFIED"), "{out}");
    assert!(out.contains("others: irp6ot: where its plan ends"), "{out}");
    let (code, out, _) = embodied(&["verify", "two-irp6-cell", plan.to_str().unwrap(), "--json"]);
    assert_eq!(code, 0);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["certified"], true);
    assert_eq!(v["agents"][0]["trajectory"]["collision"]["ok"], true);
    assert!(v["agents"][0]["trajectory"]["collision"]["certified_segments"].as_u64().unwrap() > 0);
    // Each object says `certified` once: the report, each agent, each agent's trajectory.
    let agents = v["agents"].as_array().unwrap().len();
    assert_eq!(out.matches("\"certified\":").count(), 1 + 2 * agents, "{out}");
}

// (b) A 1 mm plate between two free waypoints is caught.
#[test]
fn thin_plate_between_free_waypoints_is_caught() {
    let name = "irp6-pick";
    let scenario = load_scenario(name).unwrap();
    let plan = plan_of(name);
    let p = &plan.plans[0];
    let robot = &scenario.agents[0].robot;
    // The shape centre of the gripper link, which sweeps the longest way.
    let ee = &robot.end_effectors()[0];
    let centre = |q: &[f64]| {
        let pose = robot.forward_kinematics(q)[ee.link] * robot.links()[ee.link].shapes[0].pose;
        pose.translation.vector
    };
    // The plate goes across the middle of a segment, normal to the gripper's chord there; of
    // the plan's segments, the one whose gripper travels farthest with both ends clear of it.
    let base = agent_problem(&scenario, 0, &[vec![scenario.agents[0].start.clone()]]);
    let with_plate = |qa: &[f64], qb: &[f64]| {
        let qm = robot.config_space().interpolate(qa, qb, 0.5);
        let dir = (centre(qb) - centre(qa)).normalize();
        let rot = UnitQuaternion::rotation_between(&Vector3::z(), &dir).unwrap();
        let at = centre(&qm);
        let plate = Obstacle::new(
            "plate",
            Isometry3::from_parts(Translation3::from(at), rot),
            Shape::cuboid(0.04, 0.04, 0.0005),
        );
        let mut model = base.clone();
        let mut env: Environment = model.environment().clone();
        env.add(plate);
        model.set_environment(env);
        (model, qm, at, rot)
    };
    let mut segments: Vec<(Vec<f64>, Vec<f64>)> = p.path.windows(2).map(|w| (w[0].clone(), w[1].clone())).collect();
    segments.sort_by(|a, b| (centre(&b.0) - centre(&b.1)).norm().total_cmp(&(centre(&a.0) - centre(&a.1)).norm()));
    let (qa, qb, model, qm, at, rot) = segments
        .into_iter()
        .find_map(|(qa, qb)| {
            let (model, qm, at, rot) = with_plate(&qa, &qb);
            let ends_free = model.first_collision(&qa).is_none() && model.first_collision(&qb).is_none();
            ends_free.then_some((qa, qb, model, qm, at, rot))
        })
        .expect("a segment whose ends are clear of its plate");
    assert!(model.first_collision(&qm).is_some(), "the plate must be in the way");

    // The two waypoints alone, as a two-sample path: the certificate finds the plate.
    let two = Trajectory { joint_names: p.joint_names.clone(), t: vec![0.0, 1.0], q: vec![qa, qb], qd: vec![] };
    let report = check_collisions(&model, &two, &[], &CheckSettings::default());
    assert!(!report.ok);
    match report.violation.unwrap() {
        Finding::Collision { a, b, penetration_m, t, .. } => {
            assert!(a.contains("link") && b.contains("plate"), "{a} / {b}");
            assert!(penetration_m >= 0.0 && t > 0.0 && t < 1.0);
        }
        f => panic!("expected a collision, got {f}"),
    }
    assert!(report.subdivisions >= 1);

    // The whole plan against the model with the plate.
    let full = check_trajectory(&model, &p.trajectory, &[], &CheckSettings::default());
    assert!(!full.certified && full.limits.ok);
    assert!(matches!(full.collision.violation, Some(Finding::Collision { .. })), "{:?}", full.collision.violation);

    // And through the CLI: the plate in a scenario file (same name, so the hash differs: a warning).
    let dir = temp_dir("plate");
    let (r, pch, y) = rot.euler_angles();
    let plate_toml = format!(
        "[[obstacles]]\nname = \"plate\"\nbox = [0.08, 0.08, 0.001]\nxyz = [{}, {}, {}]\nrpy = [{r}, {pch}, {y}]\n\n[planner]",
        at.x, at.y, at.z
    );
    let builtin_text = BUILTIN_SCENARIOS.iter().find(|(n, _)| *n == name).unwrap().1;
    let toml = builtin_text.replace("[planner]", &plate_toml);
    let scenario_path = dir.join("irp6-pick-plate.toml");
    std::fs::write(&scenario_path, toml).unwrap();
    let plan_path = write_plan(&dir, &plan);
    let (code, out, err) = embodied(&["verify", scenario_path.to_str().unwrap(), plan_path.to_str().unwrap()]);
    assert_eq!(code, 1, "{out}{err}");
    assert!(out.contains("NOT CERTIFIED") && out.contains("obstacle `plate`") && out.contains("collide"), "{out}");
    assert!(out.contains("warning: scenario `irp6-pick` changed"), "{out}");
}

// (c) A velocity or acceleration limit broken for one step: the right time and joint.
#[test]
fn one_step_over_a_limit_is_caught() {
    let scenario = load_scenario("irp6-pick").unwrap();
    let plan = plan_of("irp6-pick");
    let p = &plan.plans[0];
    let model = agent_problem(&scenario, 0, &[vec![scenario.agents[0].start.clone()]]);
    let limits = model.robot().limits();
    let names = model.robot().joint_names();
    let settings = CheckSettings::default();
    let base = check_trajectory(&model, &p.trajectory, &[], &settings);
    assert!(base.certified);

    // Velocity: joint 2 at 1.05 x its limit at sample k.
    let k = p.trajectory.t.len() / 2;
    let mut traj = p.trajectory.clone();
    traj.qd[k][2] = 1.05 * limits[2].max_velocity;
    let r = check_trajectory(&model, &traj, &[], &settings);
    assert!(!r.certified);
    match r.limits.violation.clone().unwrap() {
        Finding::Velocity { t, joint, value, limit, excess, source } => {
            assert_eq!(t, traj.t[k]);
            assert_eq!(joint, names[2]);
            assert_eq!(source, "qd");
            assert!((value - 1.05 * limit).abs() < 1e-12 && (excess - 0.05 * limit).abs() < 1e-9);
        }
        f => panic!("expected a velocity violation, got {f}"),
    }
    assert!(r.collision.ok, "collisions are not affected");

    // Acceleration: joint 1 kicked early (velocity still far below its limit) at sample 3.
    let mut traj = p.trajectory.clone();
    let h = traj.t[3] - traj.t[2];
    traj.qd[3][1] += 1.5 * limits[1].max_acceleration * h;
    let r = check_trajectory(&model, &traj, &[], &settings);
    match r.limits.violation.clone().unwrap() {
        Finding::Acceleration { t, joint, value, limit, .. } => {
            assert_eq!(t, traj.t[3]);
            assert_eq!(joint, names[1]);
            assert!(value.abs() > limit);
        }
        f => panic!("expected an acceleration violation, got {f}"),
    }
    // The velocity kick is undone at the next sample: a second violation there, counted.
    assert!(r.limits.violations >= 2);

    // Position: one sample outside the limits.
    let mut traj = p.trajectory.clone();
    traj.q[k][0] = limits[0].upper + 0.01;
    let r = check_trajectory(&model, &traj, &[], &settings);
    assert!(
        matches!(&r.limits.violation, Some(Finding::Position { t, joint, .. }) if *t == traj.t[k] && *joint == names[0]),
        "{:?}",
        r.limits.violation
    );
}

/// A 13-DOF two-irp6 trajectory at rest at home, with joint `moving` ramping by `amount` rad
/// between 0.3 s and 0.5 s (10 ms samples).
fn two_arm_trajectory(moving: usize, amount: f64) -> Trajectory {
    let robot = builtin("two-irp6").unwrap();
    let home = robot.home().to_vec();
    let mut traj = Trajectory { joint_names: robot.joint_names(), t: vec![], q: vec![], qd: vec![] };
    for k in 0..=100 {
        let t = k as f64 * 0.01;
        let s = ((t - 0.3) / 0.2).clamp(0.0, 1.0);
        let mut q = home.clone();
        q[moving] += amount * s;
        traj.t.push(t);
        traj.q.push(q);
        traj.qd.push(vec![0.0; robot.dof()]);
    }
    traj
}

fn span(from_s: f64, to_s: f64, object: Option<CarriedObject>) -> ClosedChainSpan {
    ClosedChainSpan {
        from_s,
        to_s,
        end_effectors: ["irp6ot".into(), "irp6p".into()],
        tolerance_m: 1e-4,
        tolerance_rad: 1e-4,
        object,
    }
}

// (d) Closure drift in a closed-chain span.
#[test]
fn closure_drift_is_caught_and_a_still_span_is_certified() {
    let robot = builtin("two-irp6").unwrap();
    assert_eq!(robot.dof(), 13);
    // Joint 5 (the on-track wrist) turns by 0.2 rad between 0.3 and 0.5 s.
    let traj = two_arm_trajectory(5, 0.2);
    let r = check_closure(&robot, &traj, &[span(0.2, 0.8, None)]);
    assert!(!r.ok);
    match r.violation.unwrap() {
        Finding::ClosureDrift { t, span, position_error_m, angle_error_rad, .. } => {
            assert_eq!(span, 0);
            // The first sample after 0.3 s already turned 0.01 rad.
            assert!((t - 0.31).abs() < 1e-9, "t = {t}");
            assert!(position_error_m > 1e-4 || angle_error_rad > 1e-4);
        }
        f => panic!("expected a closure drift, got {f}"),
    }
    assert!(r.max_angle_error_rad > 0.19);

    // Nothing moves in [0, 0.25] and in [0.5, 1]: certified.
    let r = check_closure(&robot, &traj, &[span(0.0, 0.25, None), span(0.5, 1.0, None)]);
    assert!(r.ok, "{:?}", r.violation);
    assert_eq!(r.spans, 2);
    assert!(r.max_position_error_m < 1e-12 && r.max_angle_error_rad < 1e-6);

    // The same through check_trajectory, and an unknown end effector is malformed.
    let model = CollisionModel::new(&robot, Environment::new());
    let r = check_trajectory(&model, &traj, &[span(0.2, 0.8, None)], &CheckSettings::default());
    assert!(!r.certified && r.limits.ok && r.collision.ok && !r.closure.ok);
    let mut bad = span(0.0, 0.2, None);
    bad.end_effectors[1] = "nope".into();
    let r = check_closure(&robot, &traj, &[bad]);
    assert!(matches!(r.violation, Some(Finding::Malformed { ref message }) if message.contains("nope")));
}

#[test]
fn a_carried_object_counts_in_collisions_inside_its_span_only() {
    let robot = builtin("two-irp6").unwrap();
    let model = CollisionModel::new(
        &robot,
        Environment::new().with(Obstacle::new(
            "floor",
            Isometry3::translation(0.0, 0.0, -0.011),
            Shape::cuboid(3.0, 3.0, 0.01),
        )),
    );
    let traj = two_arm_trajectory(5, 0.0);
    let settings = CheckSettings::default();
    assert!(check_collisions(&model, &traj, &[], &settings).ok);
    // A 3 m box held by the on-track arm reaches the floor.
    let object =
        CarriedObject { name: "beam".into(), size: [3.0, 3.0, 3.0], in_tool: [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0] };
    let r = check_collisions(&model, &traj, &[span(0.6, 0.9, Some(object.clone()))], &settings);
    match r.violation.unwrap() {
        Finding::Collision { t, a, b, .. } => {
            assert!((0.59..=0.9).contains(&t), "t = {t}");
            assert!(a.contains("ot_link6") || b.contains("ot_link6"), "{a} / {b}");
        }
        f => panic!("expected a collision, got {f}"),
    }
    // A small box between the grippers' reach is fine.
    let small = CarriedObject { size: [0.05, 0.05, 0.05], ..object };
    let r = check_collisions(&model, &traj, &[span(0.6, 0.9, Some(small))], &settings);
    assert!(r.ok, "{:?}", r.violation);
}

// (e) Run logs.
fn log_header(scenario: &str, agent: &str, robot: &embodied_models::Robot, chain: Option<serde_json::Value>) -> String {
    let limits: Vec<serde_json::Value> = robot
        .limits()
        .iter()
        .map(|l| {
            serde_json::json!({"lower": l.lower.is_finite().then_some(l.lower), "upper": l.upper.is_finite().then_some(l.upper),
                "max_velocity": l.max_velocity, "max_acceleration": l.max_acceleration})
        })
        .collect();
    let mut header = serde_json::json!({"header": {"scenario": scenario, "step_s": 0.001, "seed": 1,
        "agents": {agent: {"joint_names": robot.joint_names(), "limits": limits}}}});
    if let Some(c) = chain {
        header["header"]["closed_chain"] = c;
    }
    header.to_string()
}

fn log_step(step: usize, agent: &str, q: &[f64], qd: &[f64], events: &[embodied_executor::Event]) -> String {
    serde_json::json!({"step": step, "t": (step + 1) as f64 * 0.001,
        "agents": {agent: {"q": q, "qd": qd, "behaviour": "main", "events": events}}})
    .to_string()
}

#[test]
fn run_logs_limits_and_truncation() {
    let scenario = load_scenario("irp6-pick").unwrap();
    let agent = &scenario.agents[0];
    let robot = &agent.robot;
    let vmax = robot.limits()[3].max_velocity;
    // A half sine over 200 steps: peak velocity `amp`, peak acceleration amp * pi / 0.2 s.
    let amp = (0.5 * vmax).min(0.5 * robot.limits()[3].max_acceleration * 0.2 / std::f64::consts::PI);
    let dir = temp_dir("logs");
    let write = |name: &str, bad_step: Option<usize>, summary: bool| {
        let mut lines = vec![log_header("irp6-pick", "irp6p", robot, None)];
        for s in 0..200 {
            let mut qd = vec![0.0; 6];
            // A smooth ramp up and down, well inside the limits.
            qd[3] = amp * (s as f64 / 200.0 * std::f64::consts::PI).sin();
            if Some(s) == bad_step {
                qd[3] = 1.2 * vmax;
            }
            lines.push(log_step(s, "irp6p", &agent.start, &qd, &[]));
        }
        if summary {
            lines.push(r#"{"summary": {"steps": 200}}"#.into());
        }
        let path = dir.join(name);
        std::fs::write(&path, lines.join("\n") + "\n").unwrap();
        path
    };
    let settings = CheckSettings::default();
    let clean = write("clean.jsonl", None, true);
    let v = verify_log(&scenario, &clean, &settings).unwrap();
    assert!(v.certified && v.complete && v.note.is_none(), "{v:?}");
    assert_eq!(v.agents[0].steps, 200);
    assert!((v.agents[0].max_velocity_ratio - amp / vmax).abs() < 1e-3);
    assert!(v.agents[0].max_acceleration_ratio < 0.51);

    let bad = write("bad.jsonl", Some(120), true);
    let v = verify_log(&scenario, &bad, &settings).unwrap();
    assert!(!v.certified);
    match v.agents[0].violation.clone().unwrap() {
        Finding::Velocity { t, joint, .. } => {
            assert!((t - 0.121).abs() < 1e-12, "t = {t}");
            assert_eq!(joint, robot.joint_names()[3]);
        }
        f => panic!("expected a velocity violation, got {f}"),
    }
    assert!(v.agents[0].violations >= 2, "the jump also breaks the acceleration limit");

    // CLI: clean exits 0, bad exits 1 and names the time and joint.
    let (code, out, err) = embodied(&["verify", "irp6-pick", "--log", clean.to_str().unwrap()]);
    assert_eq!(code, 0, "{out}{err}");
    let (code, out, _) = embodied(&["verify", "irp6-pick", "--log", bad.to_str().unwrap()]);
    assert_eq!(code, 1, "{out}");
    assert!(out.contains("t = 0.1210 s") && out.contains(&robot.joint_names()[3]), "{out}");

    // A run that stopped mid-line: checked up to the last complete line, and says so.
    let text = std::fs::read_to_string(&clean).unwrap();
    let cut = text.len() - text.lines().last().unwrap().len() - 30;
    let truncated = dir.join("truncated.jsonl");
    std::fs::write(&truncated, &text[..cut]).unwrap();
    let v = verify_log(&scenario, &truncated, &settings).unwrap();
    assert!(v.certified && !v.complete);
    assert!(v.note.as_deref().unwrap().contains("incomplete"), "{:?}", v.note);
    assert_eq!(v.steps, 199);
    let (code, out, _) = embodied(&["verify", "irp6-pick", "--log", truncated.to_str().unwrap()]);
    assert_eq!(code, 0);
    assert!(out.contains("(truncated)"), "{out}");
}

#[test]
fn run_log_grasp_release_drift() {
    let dir = temp_dir("closure-log");
    let toml = "name = \"two-arm-hold\"\ndescription = \"two-irp6 holding a box\"\n\n[[agents]]\nname = \"arms\"\nrobot = \"two-irp6\"\n";
    let scenario_path = dir.join("hold.toml");
    std::fs::write(&scenario_path, toml).unwrap();
    let scenario = load_scenario(scenario_path.to_str().unwrap()).unwrap();
    let robot = &scenario.agents[0].robot;
    let chain = serde_json::json!({"agent": "arms", "end_effectors": ["irp6ot", "irp6p"], "tolerance_m": 1e-3, "tolerance_rad": 1e-3});
    let write = |name: &str, move_from: usize| {
        let mut lines = vec![log_header("two-arm-hold", "arms", robot, Some(chain.clone()))];
        let home = robot.home().to_vec();
        let mut q = home.clone();
        for s in 0..300 {
            // The logged velocity stays 0 (the log check does not compare q with qd): only
            // the closure is under test here.
            let qd = vec![0.0; 13];
            if s >= move_from && s < move_from + 50 {
                q[3] += 0.2 * 0.001; // the on-track arm's third joint, 0.2 rad/s
            }
            let events: &[embodied_executor::Event] = match s {
                20 => &[embodied_executor::Event::Grasp],
                150 => &[embodied_executor::Event::Release],
                _ => &[],
            };
            lines.push(log_step(s, "arms", &q, &qd, events));
        }
        lines.push(r#"{"summary": {}}"#.into());
        let path = dir.join(name);
        std::fs::write(&path, lines.join("\n") + "\n").unwrap();
        path
    };
    let settings = CheckSettings::default();
    // The arm moves while holding: drift.
    let v = verify_log(&scenario, &write("drift.jsonl", 60), &settings).unwrap();
    let c = v.agents[0].closure.clone().unwrap();
    assert!(!v.certified && !c.ok, "{v:?}");
    assert_eq!(c.grasps, 1);
    match c.violation.unwrap() {
        Finding::ClosureDrift { t, position_error_m, angle_error_rad, .. } => {
            assert!(t > 0.061 && t < 0.111, "t = {t}");
            assert!(position_error_m > 1e-3 || angle_error_rad > 1e-3);
        }
        f => panic!("expected a closure drift, got {f}"),
    }
    // The arm moves only after the release: certified.
    let v = verify_log(&scenario, &write("after.jsonl", 200), &settings).unwrap();
    assert!(v.certified, "{v:?}");
    let c = v.agents[0].closure.clone().unwrap();
    assert_eq!(c.samples, 129);
    assert!(c.max_position_error_m < 1e-12);
}

// (f) Bad input: a clear error naming the file and place, never a panic.
#[test]
fn bad_inputs_name_the_file() {
    let dir = temp_dir("bad");
    let plan = plan_of("irp6-pick");
    let good = write_plan(&dir, &plan);
    let missing = dir.join("missing.json");
    let not_json = dir.join("not.json");
    std::fs::write(&not_json, "{\"format\": \"embodied-plan/1\",\n \"scenario\": oops}").unwrap();
    let wrong_tag = dir.join("tag.json");
    std::fs::write(
        &wrong_tag,
        serde_json::to_string(&PlanFile { format: "embodied-plan/0".into(), ..plan.clone() }).unwrap(),
    )
    .unwrap();
    let mut short = plan.clone();
    short.plans[0].trajectory.q[7].pop();
    let wrong_dof = dir.join("dof.json");
    std::fs::write(&wrong_dof, serde_json::to_string(&short).unwrap()).unwrap();
    let mut renamed = plan.clone();
    renamed.plans[0].joint_names[0] = "elbow".into();
    let wrong_names = dir.join("names.json");
    std::fs::write(&wrong_names, serde_json::to_string(&renamed).unwrap()).unwrap();
    let bad_log = dir.join("bad.jsonl");
    std::fs::write(&bad_log, "not a header\n").unwrap();
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let cases: Vec<(Vec<String>, String)> = vec![
        (vec![s(&missing)], format!("cannot read {}", s(&missing))),
        (vec![s(&not_json)], format!("{}:2:", s(&not_json))),
        (vec![s(&wrong_tag)], format!("{}:1:1: format `embodied-plan/0`", s(&wrong_tag))),
        (vec![s(&wrong_dof)], format!("{}: plans[0] (agent `irp6p`).trajectory.q[7]: 5 values", s(&wrong_dof))),
        (vec![s(&wrong_names)], format!("{}: plans[0] (agent `irp6p`).joint_names", s(&wrong_names))),
        (vec!["--log".into(), s(&bad_log)], format!("{}:1:", s(&bad_log))),
        (vec!["--log".into(), s(&missing)], format!("cannot read {}", s(&missing))),
    ];
    for (extra, expected) in cases {
        let mut args = vec!["verify".to_string(), "irp6-pick".into()];
        args.extend(extra);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let (code, _, err) = embodied(&args);
        assert_eq!(code, 2, "{args:?}: {err}");
        assert!(err.contains(&expected), "{args:?}: `{err}` lacks `{expected}`");
        assert!(!err.contains("panicked"), "{err}");
    }
    // A plan for another scenario.
    let (code, _, err) = embodied(&["verify", "polycrank-transfer", good.to_str().unwrap()]);
    assert_eq!(code, 2);
    assert!(err.contains("the plan is for scenario `irp6-pick`, not `polycrank-transfer`"), "{err}");
    // Neither a plan nor a log.
    let (code, _, err) = embodied(&["verify", "irp6-pick"]);
    assert_eq!(code, 2);
    assert!(err.contains("PLAN") || err.contains("required"), "{err}");
}

// (f) The budget of distance evaluations.

/// A plan of polycrank-transfer whose middle sample jumps `jump` rad on joint `joint` and back.
fn jumping_plan(joint: usize, jump: f64) -> PlanFile {
    let mut plan = plan_of("polycrank-transfer");
    let traj = &mut plan.plans[0].trajectory;
    let k = traj.q.len() / 2;
    traj.q[k][joint] += jump;
    plan
}

#[test]
fn a_grazing_jumping_plan_spends_the_budget_and_is_not_certified() {
    let scenario = load_scenario("polycrank-transfer").unwrap();
    let agent = scenario.agents[0].name.clone();
    // Joint 5 jumps 40 rad and back: certifying the two segments free takes about a thousand
    // distance evaluations.
    let plan = jumping_plan(4, 40.0);
    let verify = |max_evaluations: Option<usize>| {
        let settings = CheckSettings { max_evaluations, ..CheckSettings::default() };
        verify_plan(&scenario, &plan, Path::new("plan.json"), &settings).unwrap()
    };
    let free = verify(None);
    let needed = free.distance_evaluations;
    assert!(needed > 800, "{needed}");
    assert!(free.agents[0].report.collision.ok && !free.budget_exhausted, "{:?}", free.agents[0].report.collision);
    // A smaller budget: not certified, never free, and the finding says where it ran out.
    let spent = verify(Some(500));
    assert!(!spent.certified && spent.budget_exhausted);
    assert_eq!(spent.distance_evaluations, 500);
    let c = &spent.agents[0].report.collision;
    assert!(!c.ok && !spent.agents[0].certified);
    let k = plan.plans[0].trajectory.q.len() / 2;
    match c.violation.as_ref().unwrap() {
        f @ Finding::BudgetExhausted { budget, segment, agent: a, .. } => {
            assert_eq!((*budget, a.as_str()), (500, agent.as_str()));
            assert!(*segment == k - 1 || *segment == k, "segment {segment}, jump at sample {k}");
            let text = f.to_string();
            assert!(text.contains("not certified: budget of 500 distance evaluations exhausted at segment"), "{text}");
            assert!(text.contains(&format!("of agent {agent}")), "{text}");
        }
        f => panic!("expected the budget spent, got {f}"),
    }
    // Enough budget: the same report as without one.
    let enough = verify(Some(needed));
    assert_eq!(enough.agents[0].report.findings(), free.agents[0].report.findings());
    assert_eq!((enough.certified, enough.distance_evaluations), (free.certified, needed));
    // The CLI: the flag sets it, the report says so and how to raise it.
    let dir = temp_dir("budget");
    let file = write_plan(&dir, &plan);
    let (code, out, err) =
        embodied(&["verify", "polycrank-transfer", file.to_str().unwrap(), "--max-evaluations", "500"]);
    assert_eq!(code, 1, "{out}{err}");
    assert!(out.contains("budget of 500 distance evaluations exhausted") && out.contains("--max-evaluations"), "{out}");
    let (_, out, _) = embodied(&["verify", "polycrank-transfer", file.to_str().unwrap()]);
    assert!(!out.contains("exhausted") && out.contains("of 2000000 allowed"), "{out}");
}

#[test]
fn a_grazing_jumping_log_spends_the_budget_and_normal_logs_are_unaffected() {
    let scenario = load_scenario("polycrank-transfer").unwrap();
    let agent = &scenario.agents[0];
    let dir = temp_dir("budget-log");
    let write = |name: &str, jump: f64| {
        let mut lines = vec![log_header("polycrank-transfer", &agent.name, &agent.robot, None)];
        for s in 0..40 {
            let mut q = agent.start.clone();
            if s == 20 {
                q[4] += jump;
            }
            lines.push(log_step(s, &agent.name, &q, &vec![0.0; q.len()], &[]));
        }
        lines.push(r#"{"summary": {"steps": 40}}"#.into());
        let path = dir.join(name);
        std::fs::write(&path, lines.join("\n") + "\n").unwrap();
        path
    };
    let verify = |file: &Path, max_evaluations: Option<usize>| {
        let settings = CheckSettings { max_evaluations, ..CheckSettings::default() };
        verify_log(&scenario, file, &settings).unwrap()
    };
    let findings = |v: &embodied::verify::LogVerification| {
        let mut f: Vec<Option<Finding>> =
            v.agents.iter().map(|a| a.collision.as_ref().unwrap().violation.clone()).collect();
        f.extend(v.agents.iter().map(|a| a.violation.clone()));
        (v.certified, f)
    };
    // A quiet log: the same findings with the CLI's default budget as with none.
    let quiet = write("quiet.jsonl", 0.0);
    let (a, b) = (verify(&quiet, None), verify(&quiet, Some(embodied::verify::DEFAULT_MAX_EVALUATIONS)));
    assert!(a.certified && !b.budget_exhausted);
    assert_eq!(findings(&a), findings(&b));
    assert_eq!(a.distance_evaluations, b.distance_evaluations);
    // Joint 5 jumps 40 rad for one step: a small budget runs out there, and the log is not
    // certified although its collision check would otherwise pass.
    let jumping = write("jumping.jsonl", 40.0);
    let free = verify(&jumping, None);
    assert!(free.agents[0].collision.as_ref().unwrap().ok, "{:?}", free.agents[0].collision);
    assert!(free.distance_evaluations > 1000, "{}", free.distance_evaluations);
    let spent = verify(&jumping, Some(500));
    assert!(!spent.certified && spent.budget_exhausted && spent.distance_evaluations == 500);
    let c = spent.agents[0].collision.as_ref().unwrap();
    match c.violation.as_ref().unwrap() {
        Finding::BudgetExhausted { budget: 500, segment, agent: a, t_from, .. } => {
            assert_eq!(a, &agent.name);
            assert!(*segment == 19 || *segment == 20, "segment {segment}");
            assert!((0.019..=0.022).contains(t_from), "t = {t_from}");
        }
        f => panic!("expected the budget spent, got {f}"),
    }
}
