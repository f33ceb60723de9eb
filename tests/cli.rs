//! End-to-end tests of the `embodied` binary.
#![allow(clippy::unwrap_used)]

mod common;
use common::{embodied, tmp};

#[test]
fn model_json_has_the_documented_fields() {
    let (code, out, err) = embodied(&["model", "irp6-postument", "--q", "0,-1.57,0,1.56,1.57,-1.57", "--json"]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).expect("one JSON object");
    assert_eq!(v["robot"], "irp6-postument");
    assert_eq!(v["dof"], 6);
    assert_eq!(v["joints"].as_array().map(Vec::len), Some(6));
    assert_eq!(v["joints"][0]["kind"], "revolute");
    let flange = &v["end_effectors"][0]["flange"]["translation"];
    let got: Vec<f64> = flange.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
    for (g, e) in got.iter().zip([0.6723, 0.0, 1.2145]) {
        assert!((g - e).abs() < 5e-4, "flange {got:?}");
    }
    assert_eq!(v["self_collision"], false);
    assert!(v["min_distance"].as_f64().unwrap() > 0.0);
    assert!(v["links"][0]["quaternion_xyzw"].as_array().is_some());
}

#[test]
fn model_json_continuous_joints_have_null_limits() {
    let (code, out, _) = embodied(&["model", "polycrank", "--json"]);
    assert_eq!(code, 0);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["joints"][0]["kind"], "continuous");
    assert!(v["joints"][0]["lower"].is_null() && v["joints"][0]["upper"].is_null());
}

#[test]
fn model_two_irp6_lists_on_track_first() {
    let (code, out, _) = embodied(&["model", "two-irp6", "--json"]);
    assert_eq!(code, 0);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["dof"], 13);
    assert_eq!(v["end_effectors"][0]["name"], "irp6ot");
    assert_eq!(v["end_effectors"][1]["name"], "irp6p");
}

#[test]
fn model_bad_input_is_a_clear_error() {
    let cases: [(&[&str], &str); 5] = [
        (&["model", "puma"], "built-in models are: irp6-postument"),
        (&["model", "irp6-postument", "--q", "1,2"], "has 6 joints, got 2"),
        (&["model", "irp6-postument", "--q", "0,0,0,0,0,0"], "outside its limits"),
        (&["model", "irp6-postument", "--q", "0,x,0,0,0,0"], "not a number"),
        (&["model", "/no/such/robot.urdf"], "/no/such/robot.urdf"),
    ];
    for (args, expected) in cases {
        let (code, _, err) = embodied(args);
        assert_eq!(code, 2, "{args:?}: {err}");
        assert!(err.contains(expected), "{args:?}: `{err}` lacks `{expected}`");
        assert!(!err.contains("panicked"), "{err}");
    }
}

/// The tool pose of `model --json` at `q` as `X,Y,Z,ROLL,PITCH,YAW` (roll-pitch-yaw from the quaternion).
fn tool_pose_arg(robot: &str, q: &str, ee: usize) -> String {
    let (code, out, err) = embodied(&["model", robot, "--q", q, "--json"]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let tool = &v["end_effectors"][ee]["tool"];
    let t: Vec<f64> = tool["translation"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
    let r: Vec<f64> = tool["quaternion_xyzw"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
    let (x, y, z, w) = (r[0], r[1], r[2], r[3]);
    let roll = (2.0 * (w * x + y * z)).atan2(1.0 - 2.0 * (x * x + y * y));
    let pitch = (2.0 * (w * y - z * x)).clamp(-1.0, 1.0).asin();
    let yaw = (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z));
    format!("{},{},{},{roll},{pitch},{yaw}", t[0], t[1], t[2])
}

#[test]
fn model_ik_lists_the_configuration_a_pose_came_from() {
    let q = [0.4, -1.3, 0.2, 0.5, 2.0, -0.7];
    let q_text: Vec<String> = q.iter().map(f64::to_string).collect();
    let pose = tool_pose_arg("irp6-postument", &q_text.join(","), 0);
    let (code, out, err) = embodied(&["model", "irp6-postument", "--ik", &pose, "--json"]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["ik"]["method"], "closed-form");
    assert_eq!(v["ik"]["end_effector"], "irp6p");
    let solutions = v["ik"]["solutions"].as_array().unwrap();
    let found = solutions.iter().any(|s| {
        let got: Vec<f64> = s["q"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
        got.iter().zip(&q).all(|(a, b)| (a - b).abs() < 1e-6)
    });
    assert!(found, "{q:?} not among {solutions:?}");
    // Text output, and the second arm of the cell by name.
    let pose = tool_pose_arg("two-irp6", "0.3,0,-1.4,0.1,0.3,1.0,0.2,0.5,-1.2,0.1,-0.2,-1.0,0.4", 1);
    let (code, out, err) = embodied(&["model", "two-irp6", "--ik", &pose, "--ee", "irp6p"]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("inverse kinematics of irp6p") && out.contains("closed-form"), "{out}");
    assert!(out.contains("+0.5000, -1.2000, +0.1000, -0.2000, -1.0000, +0.4000]"), "{out}");
}

#[test]
fn model_ik_out_of_reach_exits_1_and_bad_poses_exit_2() {
    let (code, out, _) = embodied(&["model", "irp6-postument", "--ik", "3,0,1,0,0,0", "--json"]);
    assert_eq!(code, 1);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["ik"]["solutions"].as_array().map(Vec::len), Some(0));
    assert!(v["ik"]["failure"].as_str().unwrap().contains("out of reach"));
    // No closed form: the numerical solver, from the seed.
    let pose = tool_pose_arg("polycrank", "0.3,0.2,-0.4,0.5,0.1,0.2,0.3", 0);
    let (code, out, err) =
        embodied(&["model", "polycrank", "--q", "0.25,0.25,-0.35,0.45,0.1,0.25,0.3", "--ik", &pose, "--json"]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["ik"]["method"], "numerical");
    assert_eq!(v["ik"]["solutions"].as_array().map(Vec::len), Some(1));
    let cases: [(&[&str], &str); 4] = [
        (&["model", "irp6-postument", "--ik", "1,2,3"], "got 3 values; expected 6"),
        (&["model", "irp6-postument", "--ik", "1,0,1,x,0,0"], "value 4 (`x`) is not a finite number"),
        (&["model", "irp6-postument", "--ik", "1,0,1,0,0,inf"], "value 6 (`inf`) is not a finite number"),
        (&["model", "irp6-postument", "--ik", "1,0,1,0,0,0", "--ee", "left"], "no end effector `left`; it has: irp6p"),
    ];
    for (args, expected) in cases {
        let (code, _, err) = embodied(args);
        assert_eq!(code, 2, "{args:?}: {err}");
        assert!(err.contains(expected), "{args:?}: `{err}` lacks `{expected}`");
    }
}

#[test]
fn model_help_names_every_source() {
    let (code, out, _) = embodied(&["model", "--help"]);
    assert_eq!(code, 0);
    for name in embodied_models::BUILTIN_NAMES {
        assert!(out.contains(name), "{name} missing from --help");
    }
    assert!(out.contains("ASSUMPTION MODEL"));
}

#[test]
fn scenarios_lists_the_builtins() {
    let (code, out, _) = embodied(&["scenarios", "--json"]);
    assert_eq!(code, 0);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let names: Vec<&str> = v.as_array().unwrap().iter().map(|s| s["name"].as_str().unwrap()).collect();
    for (name, _) in embodied::scenario::BUILTIN_SCENARIOS {
        assert!(names.contains(name));
    }
}

#[test]
fn plan_output_round_trips_and_passes_the_verifier() {
    let path = tmp("polycrank.plan.json");
    let (code, _, err) = embodied(&["plan", "polycrank-transfer", "-o", path.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let plan = embodied::plan::read_plan(&path).unwrap();
    assert_eq!(plan.scenario.name, "polycrank-transfer");
    let p = &plan.plans[0];
    assert_eq!(p.joint_names.len(), 7);
    // Continuous joint 1 goes from 2.6 to -2.6 the short way (across +-pi): about 1.08 rad.
    let q1: Vec<f64> = p.trajectory.q.iter().map(|q| q[0]).collect();
    let travel = q1.windows(2).map(|w| (w[1] - w[0]).abs()).sum::<f64>();
    assert!((travel - (std::f64::consts::TAU - 5.2)).abs() < 1e-6, "travel {travel}");
    // Round trip: serialise again and compare.
    let again: embodied::plan::PlanFile = serde_json::from_str(&serde_json::to_string(&plan).unwrap()).unwrap();
    assert_eq!(again.plans[0].trajectory.q, p.trajectory.q);
    // The verifier accepts the trajectory against the scenario's world.
    let sc = embodied::scenario::load_scenario("polycrank-transfer").unwrap();
    let model = embodied_models::collision::CollisionModel::new(&sc.agents[0].robot, sc.initial_environment());
    embodied_planner::verify::Verifier::sampled(0.005).verify_trajectory(&model, &p.trajectory).unwrap();
    embodied_planner::verify::Verifier::default().verify_trajectory(&model, &p.trajectory).unwrap();
    // A file that is not a plan is a clear error.
    std::fs::write(&path, "{\"format\": 3}").unwrap();
    let e = embodied::plan::read_plan(&path).unwrap_err().to_string();
    assert!(e.contains("polycrank.plan.json:1:"), "{e}");
}

#[test]
fn plan_with_zero_deadline_is_out_of_time_not_a_hang() {
    let (code, _, err) = embodied(&["plan", "irp6-pick", "--deadline-ms", "0"]);
    // Ran, did not succeed: status 1 (2 is bad input).
    assert_eq!(code, 1);
    assert!(err.contains("out of time"), "{err}");
}

#[test]
fn run_writes_a_complete_deterministic_log() {
    let a = tmp("a.jsonl");
    let b = tmp("b.jsonl");
    let svg = tmp("run.svg");
    for log in [&a, &b] {
        let (code, out, err) = embodied(&[
            "run",
            "two-irp6-cell",
            "--duration",
            "2.5",
            "--seed",
            "3",
            "--log",
            log.to_str().unwrap(),
            "--plot",
            svg.to_str().unwrap(),
        ]);
        assert_eq!(code, 0, "{err}");
        assert!(out.contains("real-time factor"), "{out}");
    }
    let text = std::fs::read_to_string(&a).unwrap();
    let lines: Vec<serde_json::Value> = text.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    // header, 2500 steps, summary
    assert_eq!(lines.len(), 2502);
    let header = &lines[0]["header"];
    assert_eq!(header["seed"], 3);
    assert_eq!(header["step_s"], 0.001);
    assert_eq!(header["agents"]["irp6ot"]["joint_names"].as_array().unwrap().len(), 7);
    let step = &lines[1];
    assert_eq!(step["step"], 0);
    assert!(step["agents"]["irp6p"]["q"].as_array().unwrap().len() == 6);
    assert!(lines[2501]["summary"].is_object());
    // Byte-identical for the same scenario and seed, summary line included.
    let text_b = std::fs::read_to_string(&b).unwrap();
    assert!(text == text_b, "two runs with the same seed wrote different logs");
    // Both arms reached their goals, coordinated one after the other, within their limits.
    let events: Vec<serde_json::Value> = lines
        .iter()
        .skip(1)
        .take(2500)
        .flat_map(|l| l["agents"]["coordinator"]["events"].as_array().cloned().unwrap_or_default())
        .collect();
    assert!(events.iter().any(|e| e["kind"] == "all_done"), "{events:?}");
    let svg_text = std::fs::read_to_string(&svg).unwrap();
    assert!(svg_text.starts_with("<svg"));
}

#[test]
fn run_force_limited_reaction_stops_rnt() {
    let (code, out, err) = embodied(&["run", "rnt-polish", "--duration", "1.0", "--json"]);
    // The arm was stopped, so its goal was not reached: status 1, the summary still printed.
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("goal not reached by: rnt"), "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let events = v["events"].as_array().unwrap();
    assert!(events.iter().any(|e| e[2]["kind"] == "force_limit"), "{events:?}");
    assert!(v["agents"][0]["max_speed_ratio"].as_f64().unwrap() <= 1.0 + 1e-9);
}

#[test]
fn run_rejects_a_bad_duration() {
    let (code, _, err) = embodied(&["run", "--duration=-1"]);
    assert_eq!(code, 2);
    assert!(err.contains("--duration"), "{err}");
}
