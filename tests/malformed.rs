//! Malformed input never panics: every loader (scenario TOML, URDF, SRDF, meshes (STL, OBJ,
//! Collada), MoveIt scene and request YAML, joint_limits.yaml, JointTrajectory YAML/JSON, plan
//! JSON, run log) is fed its own well-formed files with random edits
//! (deleted, repeated or replaced spans, inserted tokens such as `nan`, `1e309`, `]`, `<`, a cut
//! anywhere) and must answer `Ok` or an error that names the file. A panic fails the property,
//! and proptest shrinks it to the smallest edit list that panics.
//!
//! `PROPTEST_CASES=5000 FUZZ_SEED=7 cargo test --release --test malformed -- --nocapture` searches
//! harder than CI does, elsewhere; `FUZZ_RUN_S=4` runs each edited scenario for 4 simulated
//! seconds instead of 0.06.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::cell::Cell;
use std::path::{Path, PathBuf};

use common::TempDir;
use embodied::AppError;
use embodied::plan::{parse_plan, plan_scenario};
use embodied::scenario::{BUILTIN_SCENARIOS, load_scenario, parse_scenario};
use embodied::system::{RunArgs, RunOptions, run_scenario};
use embodied::verify::{verify_log, verify_plan};
use embodied_models::urdf::{UrdfOptions, parse_urdf, parse_urdf_with_srdf};
use embodied_planner::verify::CheckSettings;
use proptest::prelude::*;
use proptest::test_runner::{RngSeed, TestRunner};

/// Tokens that tend to break parsers and the checks behind them: numbers at the edges of `f64`,
/// the structure characters of TOML, XML, YAML and JSON, and a few keys of our own formats.
const TOKENS: &[&str] = &[
    "",
    "0",
    "-0",
    "-1",
    "1e309",
    "-1e309",
    "1e-320",
    "nan",
    "inf",
    "-inf",
    ".nan",
    ".inf",
    "18446744073709551616",
    "9999999999",
    "0.0",
    "3.5e38",
    "\"",
    "'",
    "[",
    "]",
    "{",
    "}",
    "[]",
    "{}",
    "<",
    ">",
    "/>",
    "</",
    "=",
    ",",
    ":",
    "- ",
    "\n",
    "  ",
    "#",
    "\u{0}",
    "é",
    "true",
    "null",
    "\"\"",
    "[[agents]]",
    "[[obstacles]]",
    "[carry]",
    "<joint name=\"x\" type=\"fixed\"><parent link=\"a\"/><child link=\"b\"/></joint>",
    "<link name=\"a\"/>",
    "package://",
    "../",
    "mimic",
    "continuous",
    "prismatic",
    "planar",
    "\"q\": []",
    "\"t\": [0]",
];

/// One edit of a text; positions are fractions of its length, so an edit applies to any text.
#[derive(Debug, Clone)]
enum Edit {
    Delete { at: f64, len: usize },
    Insert { at: f64, token: usize },
    Replace { at: f64, len: usize, token: usize },
    Repeat { at: f64, len: usize },
    Cut { at: f64 },
}

fn edit() -> impl Strategy<Value = Edit> {
    let at = 0.0..1.0f64;
    let token = 0..TOKENS.len();
    prop_oneof![
        (at.clone(), 1..40usize).prop_map(|(at, len)| Edit::Delete { at, len }),
        (at.clone(), token.clone()).prop_map(|(at, token)| Edit::Insert { at, token }),
        (at.clone(), 1..12usize, token).prop_map(|(at, len, token)| Edit::Replace { at, len, token }),
        (at.clone(), 1..80usize).prop_map(|(at, len)| Edit::Repeat { at, len }),
        at.prop_map(|at| Edit::Cut { at }),
    ]
}

/// The char boundary at or before `at` of the way through `text`.
fn boundary(text: &str, at: f64) -> usize {
    let mut i = ((text.len() as f64) * at) as usize;
    i = i.min(text.len());
    while !text.is_char_boundary(i) {
        i -= 1;
    }
    i
}

/// The boundary at most `len` bytes after `from`.
fn span_end(text: &str, from: usize, len: usize) -> usize {
    let mut j = (from + len).min(text.len());
    while !text.is_char_boundary(j) {
        j -= 1;
    }
    j
}

fn apply(text: &str, edits: &[Edit]) -> String {
    let mut t = text.to_string();
    for e in edits {
        match *e {
            Edit::Delete { at, len } => {
                let i = boundary(&t, at);
                let j = span_end(&t, i, len);
                t.replace_range(i..j, "");
            }
            Edit::Insert { at, token } => {
                let i = boundary(&t, at);
                t.insert_str(i, TOKENS[token]);
            }
            Edit::Replace { at, len, token } => {
                let i = boundary(&t, at);
                let j = span_end(&t, i, len);
                t.replace_range(i..j, TOKENS[token]);
            }
            Edit::Repeat { at, len } => {
                let i = boundary(&t, at);
                let j = span_end(&t, i, len);
                let copy = t[i..j].to_string();
                t.insert_str(j, &copy);
            }
            Edit::Cut { at } => {
                let i = boundary(&t, at);
                t.truncate(i);
            }
        }
    }
    t
}

fn edits(most: usize) -> impl Strategy<Value = Vec<Edit>> {
    prop::collection::vec(edit(), 1..=most)
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The spherized UR5 and its SRDF, loaded once.
fn ur5() -> &'static (embodied_models::Robot, embodied_models::srdf::Srdf) {
    static UR5: std::sync::OnceLock<(embodied_models::Robot, embodied_models::srdf::Srdf)> = std::sync::OnceLock::new();
    UR5.get_or_init(|| {
        let dir = root().join("models/tests/fixtures");
        let srdf = embodied_models::srdf::load_srdf(&dir.join("ur5.srdf")).expect("UR5 SRDF");
        let robot = embodied_models::urdf::load_urdf(&dir.join("ur5_spherized.urdf"), Some(&dir.join("ur5.srdf")))
            .expect("UR5");
        (robot, srdf)
    })
}

/// Feed `cases` random edits of the `seeds` (file path, text) to `load`, which answers `Ok(())`
/// or an error message; a panic fails, and so does an error that names none of `names`. Some
/// edits must load and some must be refused, so that the edits reach past the syntax into the
/// checks behind it.
fn fuzz(
    what: &str,
    (default_cases, most_edits): (u32, usize),
    seeds: &[(PathBuf, String)],
    names: &[&str],
    load: impl Fn(&Path, &str) -> Result<(), String>,
) {
    let cases = std::env::var("PROPTEST_CASES").ok().and_then(|s| s.parse().ok()).unwrap_or(default_cases);
    // A fixed seed in CI, so that a run is repeatable; `FUZZ_SEED=N` searches elsewhere.
    let seed = std::env::var("FUZZ_SEED").ok().and_then(|s| s.parse().ok()).unwrap_or(1);
    let config = ProptestConfig {
        cases,
        failure_persistence: None,
        rng_seed: RngSeed::Fixed(seed),
        ..ProptestConfig::default()
    };
    let mut runner = TestRunner::new(config);
    let (loaded, refused) = (Cell::new(0usize), Cell::new(0usize));
    let result = runner.run(&(0..seeds.len(), edits(most_edits)), |(which, edits)| {
        let (path, text) = &seeds[which];
        let text = apply(text, &edits);
        match load(path, &text) {
            Ok(()) => loaded.set(loaded.get() + 1),
            Err(msg) => {
                let own = path.file_name().and_then(|n| n.to_str()).unwrap_or_default();
                prop_assert!(
                    msg.contains(own) || names.iter().any(|n| msg.contains(n)),
                    "{what}: `{msg}` names no file"
                );
                refused.set(refused.get() + 1);
            }
        }
        Ok(())
    });
    if let Err(e) = result {
        panic!("{what}: {e}");
    }
    let (l, r) = (loaded.get(), refused.get());
    eprintln!("{what}: {l} edited files loaded, {r} refused with an error naming the file");
    assert!(l > 0 && r > 0, "{what}: {l} loaded, {r} refused: the edits test too little");
}

#[test]
fn scenario_files() {
    let dir = root().join("scenarios");
    let seeds: Vec<(PathBuf, String)> =
        BUILTIN_SCENARIOS.iter().map(|(name, text)| (dir.join(format!("{name}.toml")), text.to_string())).collect();
    fuzz("scenarios", (96, 4), &seeds, &[".urdf", ".srdf", ".stl"], |file, text| {
        parse_scenario(text, file, &dir).map(|_| ()).map_err(|e| match e {
            // Usage errors (an unknown built-in robot, say) are about the scenario the caller named.
            AppError::Usage(m) => format!("{}: {m}", file.display()),
            e => e.to_string(),
        })
    });
}

#[test]
fn urdf_files() {
    let dir = root().join("models/tests/fixtures");
    let seeds: Vec<(PathBuf, String)> = ["tiny_gripper.urdf", "ur5_spherized.urdf", "package_mesh.urdf", "ur5.urdf"]
        .iter()
        .map(|n| (dir.join(n), read(&dir.join(n))))
        .collect();
    fuzz("urdf", (96, 4), &seeds, &[".stl", ".STL", ".dae", ".obj"], |file, text| {
        // The UR5's own meshes are not distributed (shared/mbm/README.md): they are skipped there,
        // so the parser behind them is what gets fed.
        let load_meshes = !file.ends_with("ur5.urdf");
        let options = UrdfOptions { package_dirs: vec![dir.join("pkgroot")], load_meshes, ..UrdfOptions::default() };
        parse_urdf(text, file, &options).map(|_| ()).map_err(|e| e.to_string())
    });
}

#[test]
fn srdf_files() {
    let dir = root().join("models/tests/fixtures");
    let seeds: Vec<(PathBuf, String)> =
        ["tiny_gripper.srdf", "ur5.srdf"].iter().map(|n| (dir.join(n), read(&dir.join(n)))).collect();
    fuzz("srdf", (96, 4), &seeds, &[], |file, text| {
        let srdf = embodied_models::srdf::parse_srdf(text, file).map_err(|e| e.to_string())?;
        let urdf = dir.join(if file.ends_with("ur5.srdf") { "ur5_spherized.urdf" } else { "tiny_gripper.urdf" });
        parse_urdf_with_srdf(&read(&urdf), &urdf, &UrdfOptions::default(), &srdf).map(|_| ()).map_err(|e| e.to_string())
    });
}

/// A MoveIt-generated SRDF (PR2: virtual and passive joints, group states, groups of groups)
/// with its URDF, meshes skipped.
#[test]
fn moveit_generated_srdf_files() {
    let pr2 = root().join("tests/fixtures/corpus/example-robot-data/robots/pr2_description");
    let urdf = pr2.join("urdf/pr2.urdf");
    let urdf_text = read(&urdf);
    let seeds = [(pr2.join("srdf/pr2.srdf"), read(&pr2.join("srdf/pr2.srdf")))];
    let options = UrdfOptions { load_meshes: false, ..UrdfOptions::default() };
    fuzz("moveit-srdf", (64, 4), &seeds, &[], |file, text| {
        let srdf = embodied_models::srdf::parse_srdf(text, file).map_err(|e| e.to_string())?;
        let robot = parse_urdf_with_srdf(&urdf_text, &urdf, &options, &srdf).map_err(|e| e.to_string())?;
        for g in &srdf.groups {
            let _ = srdf.group_joints(&robot, &g.name);
        }
        Ok(())
    });
}

/// Text meshes (OBJ, Collada, ASCII STL), edited, loaded as a URDF's collision mesh (hull and
/// decomposition included).
#[test]
fn mesh_files() {
    let dir = TempDir::new("malformed-meshes");
    let fixtures = root().join("models/tests/fixtures/meshes");
    let seeds: Vec<(PathBuf, String)> = ["cube.obj", "tetra.dae", "box_ascii.stl"]
        .iter()
        .map(|n| (fixtures.join(n), read(&fixtures.join(n))))
        .collect();
    fuzz("meshes", (96, 4), &seeds, &["edited.obj", "edited.dae", "edited.stl"], |file, text| {
        let ext = file.extension().and_then(|e| e.to_str()).unwrap_or("obj");
        let mesh = dir.join(format!("edited.{ext}"));
        std::fs::write(&mesh, text).expect("written");
        let urdf = format!(
            "<robot name=\"m\"><link name=\"a\"><collision><geometry><mesh filename=\"{}\" scale=\"0.5 2 1\"/></geometry></collision></link></robot>",
            mesh.display()
        );
        parse_urdf(&urdf, &dir.join("m.urdf"), &UrdfOptions::default()).map(|_| ()).map_err(|e| e.to_string())
    });
}

/// MoveIt's joint_limits.yaml, edited, applied to the UR5.
#[test]
fn joint_limits_files() {
    let mut text = String::from("default_velocity_scaling_factor: 0.1\njoint_limits:\n");
    for j in
        ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"]
    {
        text.push_str(&format!(
            "  {j}:\n    has_velocity_limits: true\n    max_velocity: 3.15\n    has_acceleration_limits: true\n    max_acceleration: 5.0\n    has_position_limits: false\n    min_position: -1\n    max_position: 1\n"
        ));
    }
    let seeds = [(PathBuf::from("joint_limits.yaml"), text)];
    fuzz("joint-limits", (96, 4), &seeds, &[], |file, text| {
        let limits =
            embodied_models::formats::joint_limits::parse_joint_limits(text, file).map_err(|e| e.to_string())?;
        let mut robot = ur5().0.clone();
        limits.apply(&mut robot).map(|_| ()).map_err(|e| e.to_string())
    });
}

/// JointTrajectory files (YAML as `ros2 topic echo` writes, and JSON), edited, read and certified
/// against the UR5.
#[test]
fn joint_trajectory_files() {
    use embodied_planner::moveit::{JointTrajectory, TrajectoryPoint, parse_joint_trajectory, trajectory_problem};
    let (robot, _) = ur5();
    let names = robot.joint_names();
    let points = (0..4)
        .map(|k| TrajectoryPoint {
            positions: robot.home().iter().map(|h| h + 0.05 * k as f64).collect(),
            velocities: vec![0.0; names.len()],
            accelerations: vec![0.0; names.len()],
            time_from_start: 0.5 * k as f64,
        })
        .collect();
    let jt = JointTrajectory { joint_names: names, points };
    let seeds = [(PathBuf::from("traj.yaml"), jt.to_yaml()), (PathBuf::from("traj.json"), jt.to_json())];
    let settings = CheckSettings::default();
    fuzz("joint-trajectories", (96, 4), &seeds, &[], |file, text| {
        let jt = parse_joint_trajectory(text, file).map_err(|e| e.to_string())?;
        let problem = trajectory_problem(robot, None, embodied_models::Environment::new(), &jt, file)
            .map_err(|e| e.to_string())?;
        let report = embodied_planner::verify::Verifier::default().with_settings(settings).check_trajectory(
            &problem.model,
            &problem.trajectory,
            &[],
        );
        let _ = report.certified;
        Ok(())
    });
}

#[test]
fn moveit_scenes_and_requests() {
    let mbm = root().join("tests/fixtures/mbm/problems/box_ur5");
    let moveit = root().join("planner/tests/fixtures/moveit");
    let seeds: Vec<(PathBuf, String)> = [
        mbm.join("scene0001.yaml"),
        mbm.join("request0001.yaml"),
        moveit.join("scene_shapes.yaml"),
        moveit.join("request_ur5.yaml"),
        moveit.join("request_pose.yaml"),
    ]
    .into_iter()
    .map(|p| {
        let text = read(&p);
        (p, text)
    })
    .collect();
    fuzz("moveit", (96, 4), &seeds, &[], |file, text| {
        let scene = file.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.starts_with("scene"));
        let result = if scene {
            embodied_planner::moveit::parse_scene(text, file).map(|s| {
                let _ = s.environment();
            })
        } else {
            embodied_planner::moveit::parse_request(text, file).and_then(|r| {
                let (robot, srdf) = ur5();
                r.resolve(robot, srdf, None).map(|_| ())
            })
        };
        result.map_err(|e| e.to_string())
    });
}

/// A plan file `embodied plan irp6-pick` writes, edited, read back and verified.
#[test]
fn plan_files() {
    let scenario = load_scenario("irp6-pick").expect("built-in scenario");
    let plan = plan_scenario(&scenario, Some(30_000.0)).expect("plan");
    let file = PathBuf::from("irp6-pick-plan.json");
    let seeds = [(file, serde_json::to_string_pretty(&plan).expect("JSON"))];
    let settings = CheckSettings::default();
    fuzz("plans", (32, 1), &seeds, &[], |file, text| {
        let plan = parse_plan(text, file).map_err(|e| e.to_string())?;
        verify_plan(&scenario, &plan, file, &settings).map(|_| ()).map_err(|e| e.to_string())
    });
}

/// A run log of `embodied run irp6-pick`, edited and checked by `embodied verify --log`.
#[test]
fn run_logs() {
    let dir = TempDir::new("malformed-logs");
    let log = dir.join("run.jsonl");
    let args = RunArgs {
        scenario: "irp6-pick".into(),
        options: RunOptions { duration: Some(0.04), ..RunOptions::default() },
        log: Some(log.clone()),
        ..RunArgs::default()
    };
    run_scenario(&args).expect("run");
    let scenario = load_scenario("irp6-pick").expect("built-in scenario");
    let seeds = [(log.clone(), read(&log))];
    let settings = CheckSettings::default();
    let edited = dir.join("edited.jsonl");
    fuzz("logs", (48, 2), &seeds, &["edited.jsonl"], |_, text| {
        std::fs::write(&edited, text).map_err(|e| e.to_string())?;
        verify_log(&scenario, &edited, &settings).map(|_| ()).map_err(|e| e.to_string())
    });
}

/// Edited scenarios that still load must also run: 60 simulated steps of each, planning included.
#[test]
fn edited_scenarios_run() {
    let dir = TempDir::new("malformed-runs");
    let scenarios = root().join("scenarios");
    let seeds: Vec<(PathBuf, String)> =
        BUILTIN_SCENARIOS.iter().map(|(name, text)| (dir.join(format!("{name}.toml")), text.to_string())).collect();
    fuzz("scenario runs", (16, 2), &seeds, &[".urdf", ".srdf", ".stl"], |file, text| {
        if let Err(e) = parse_scenario(text, file, &scenarios) {
            return Err(format!("{}: {e}", file.display()));
        }
        std::fs::write(file, text).map_err(|e| e.to_string())?;
        let args = RunArgs {
            scenario: file.display().to_string(),
            options: RunOptions {
                duration: Some(std::env::var("FUZZ_RUN_S").ok().and_then(|s| s.parse().ok()).unwrap_or(0.06)),
                ..RunOptions::default()
            },
            ..RunArgs::default()
        };
        run_scenario(&args).map(|_| ()).map_err(|e| format!("{}: {e}", file.display()))
    });
}
