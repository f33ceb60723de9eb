//! `embodied bench mbm` on a tiny MotionBenchMaker problem folder (fixtures only).

use std::path::{Path, PathBuf};

use embodied::AppError;
use embodied::mbm::{MbmArgs, ProblemStatus, render_table, run_mbm};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn args(families: Option<Vec<String>>) -> MbmArgs {
    let robot = root().join("models/tests/fixtures");
    let mut a =
        MbmArgs::new(robot.join("ur5_spherized.urdf"), robot.join("ur5.srdf"), root().join("tests/fixtures/mbm"));
    a.deadline_ms = 20_000.0;
    a.families = families;
    a
}

#[test]
fn solves_the_fixture_family_and_reports_verified_paths_as_json() {
    let mut calls = Vec::new();
    let report = run_mbm(&args(Some(vec!["box_ur5".into()])), &mut |done, total| calls.push((done, total)))
        .expect("benchmark runs");
    assert_eq!(calls, [(0, 2), (1, 2), (2, 2)]);
    assert_eq!(report.families.len(), 1);
    let fam = &report.families[0];
    assert_eq!((fam.name.as_str(), fam.total, fam.solved, fam.invalid), ("box_ur5", 2, 2, 0));
    assert_eq!(fam.verification_failures, 0);
    assert!(fam.p50_us.is_some() && fam.p95_us >= fam.p50_us && fam.max_us >= fam.p95_us);
    assert_eq!(report.overall.solved, 2);
    // The spherized UR5's wrist_2/fts_robotside spheres overlap everywhere: that pair is disabled.
    assert!(report.settings.always_colliding_disabled.contains(&("wrist_2_link".into(), "fts_robotside".into())));

    let json: serde_json::Value = serde_json::to_value(&report).expect("serializes");
    let problems = json["problems"].as_array().expect("problems array");
    assert_eq!(problems.len(), 2);
    for (k, p) in problems.iter().enumerate() {
        assert_eq!(p["family"], "box_ur5");
        assert_eq!(p["index"], k as u64 + 1);
        assert_eq!(p["solved"], true);
        assert_eq!(p["status"], "solved");
        assert_eq!(p["verified"], true);
        assert!(p["planning_us"].as_f64().expect("planning_us") > 0.0);
        let names = p["joint_names"].as_array().expect("joint_names");
        assert_eq!(names.len(), 6);
        assert_eq!(names[0], "shoulder_pan_joint");
        let path = p["path"].as_array().expect("path");
        assert!(path.len() >= 2);
        // The path runs from the request's start (1.57, -1.5707, 0, -1.5707, -1.57, 3.14).
        let first: Vec<f64> = path[0].as_array().expect("waypoint").iter().filter_map(|v| v.as_f64()).collect();
        #[allow(clippy::approx_constant)] // the literal start of the MotionBenchMaker request
        let start = [1.57, -1.5707, 0.0, -1.5707, -1.57, 3.14];
        assert!(first.iter().zip(start).all(|(a, b)| (a - b).abs() < 1e-9), "{first:?}");
    }
    for key in ["families", "overall"] {
        assert!(json.get(key).is_some(), "missing {key}");
    }
    assert_eq!(json["overall"]["solved"], 2);
    let out = serde_json::to_value(report.paths_file()).expect("paths file");
    assert_eq!(out["problems"].as_array().map(Vec::len), Some(2));

    let table = render_table(&report);
    assert!(table.contains("box_ur5") && table.contains("overall") && table.contains("2/2"), "{table}");
}

#[test]
fn a_goal_in_collision_is_reported_invalid_not_failed() {
    let mut a = args(Some(vec!["bookshelf_small_ur5".into()]));
    // The tarball layout `problems/<family>` is found one level deeper as well.
    a.problems = root().join("tests/fixtures/mbm/problems");
    let report = run_mbm(&a, &mut |_, _| {}).expect("benchmark runs");
    let p = &report.problems[0];
    assert_eq!((p.family.as_str(), p.index), ("bookshelf_small_ur5", 9));
    assert_eq!(p.status, ProblemStatus::InvalidGoal);
    assert!(!p.solved && p.path.is_empty() && p.planning_us.is_none());
    assert!(p.message.as_deref().is_some_and(|m| m.contains("forearm_link")), "{:?}", p.message);
    assert_eq!((report.overall.invalid, report.overall.failed, report.overall.valid), (1, 0, 0));
}

#[test]
fn bad_inputs_are_errors_with_their_place() {
    let mut a = args(Some(vec!["no_such_family".into()]));
    match run_mbm(&a, &mut |_, _| {}) {
        Err(AppError::Usage(m)) => assert!(m.contains("no_such_family") && m.contains("box_ur5"), "{m}"),
        other => panic!("expected a usage error, got {other:?}"),
    }
    a.families = None;
    a.problems = root().join("tests/fixtures/nowhere");
    assert!(matches!(run_mbm(&a, &mut |_, _| {}), Err(AppError::Usage(_))));

    // A malformed scene is a parse error naming file:line:column.
    let dir = std::env::temp_dir().join(format!("embodied-mbm-test-{}", std::process::id()));
    let fam = dir.join("broken");
    std::fs::create_dir_all(&fam).expect("temp dir");
    let fixtures = root().join("tests/fixtures/mbm/problems/box_ur5");
    std::fs::copy(fixtures.join("request0001.yaml"), fam.join("request0001.yaml")).expect("copy");
    std::fs::write(
        fam.join("scene0001.yaml"),
        "world:\n  collision_objects:\n    - id: crate\n      primitives:\n        - type: box\n          dimensions: [0.5, 0.5]\n      primitive_poses:\n        - position: [0, 0, 0]\n          orientation: [0, 0, 0, 1]\n",
    )
    .expect("write");
    a.problems = dir.clone();
    let result = run_mbm(&a, &mut |_, _| {});
    let _ = std::fs::remove_dir_all(&dir);
    match result {
        Err(AppError::Parse { file, line, column, message }) => {
            assert!(Path::new(&file).ends_with("broken/scene0001.yaml"));
            assert_eq!((line, column), (6, 23));
            assert_eq!(message, "expected a list of 3 numbers for box dimensions, got 2");
        }
        other => panic!("expected a parse error, got {other:?}"),
    }
}
