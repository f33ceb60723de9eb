//! End-to-end tests of the `embodied` binary.

use std::process::Command;

fn embodied(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_embodied")).args(args).output().expect("binary runs");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

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
