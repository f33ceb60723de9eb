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

/// A sparse file of `len` bytes (no disk space used), holding `head` at its start.
fn sparse(path: &Path, head: &[u8], len: u64) {
    use std::io::Write;
    let mut f = std::fs::File::create(path).expect("created");
    f.write_all(head).expect("written");
    f.set_len(len).expect("sized");
}

/// A 1 GB mesh is refused from its size before a byte of it is read, with an error naming the
/// URDF, the mesh and the limit.
#[test]
fn a_one_gigabyte_mesh_is_refused_before_reading() {
    let dir = TempDir::new("limits-mesh");
    sparse(&dir.join("huge.obj"), b"v 0 0 0\n", 1_000_000_000);
    let urdf = "<robot name=\"m\"><link name=\"a\"><collision><geometry><mesh filename=\"huge.obj\"/></geometry></collision></link></robot>";
    let start = std::time::Instant::now();
    let e = parse_urdf(urdf, &dir.join("m.urdf"), &UrdfOptions::default()).unwrap_err().to_string();
    assert!(e.contains("m.urdf") && e.contains("huge.obj"), "{e}");
    assert!(e.contains("1.00 GB is larger than the limit of 268.4 MB for a mesh"), "{e}");
    // Refused from the metadata: nothing near a gigabyte was read (a loose bound, not a timing target).
    assert!(start.elapsed().as_secs_f64() < 5.0);
}

/// A binary STL whose size says it holds more triangles than the limit is refused before its
/// triangles are read (the limit counts from the size: 50 bytes a triangle).
#[test]
fn a_binary_stl_with_too_many_triangles_is_refused() {
    let dir = TempDir::new("limits-stl");
    let n: u64 = 5_000_001;
    let mut head = vec![0u8; 80];
    head.extend_from_slice(&(n as u32).to_le_bytes());
    sparse(&dir.join("dense.stl"), &head, 84 + 50 * n);
    let urdf = "<robot name=\"m\"><link name=\"a\"><collision><geometry><mesh filename=\"dense.stl\"/></geometry></collision></link></robot>";
    let e = parse_urdf(urdf, &dir.join("m.urdf"), &UrdfOptions::default()).unwrap_err().to_string();
    assert!(e.contains("dense.stl") && e.contains("5000001 triangles, more than the limit of 5000000"), "{e}");
}

/// A plan file with ten million waypoints is refused from a count of its values before it is
/// parsed; so is a JointTrajectory with ten million positions.
#[test]
fn ten_million_element_arrays_are_refused_before_parsing() {
    let mut plan = String::from("{\"format\": \"embodied-plan/1\", \"plans\": [{\"path\": [");
    plan.push_str(&"[0],".repeat(10_000_000));
    plan.push_str("[0]]}]}");
    let e = parse_plan(&plan, Path::new("big-plan.json")).unwrap_err().to_string();
    assert!(e.starts_with("big-plan.json:1:1:") && e.contains("more than the limit of 10000000"), "{e}");
    let mut traj = String::from("joint_names: [a]\npoints:\n  - positions: [");
    traj.push_str(&"0,".repeat(10_000_001));
    traj.push_str("0]\n    time_from_start: 1\n");
    let e = embodied_planner::moveit::parse_joint_trajectory(&traj, Path::new("big.yaml")).unwrap_err().to_string();
    assert!(e.starts_with("big.yaml:1:1:") && e.contains("more than the limit of 10000000"), "{e}");
}

/// A URDF with a million links is refused with the link limit, before a robot is built.
#[test]
fn a_urdf_with_a_million_links_is_refused() {
    let mut urdf = String::from("<robot name=\"r\">");
    for k in 0..1_000_000 {
        urdf.push_str(&format!("<link name=\"l{k}\"/>"));
    }
    urdf.push_str("</robot>");
    let options = UrdfOptions { load_meshes: false, ..UrdfOptions::default() };
    let e = parse_urdf(&urdf, Path::new("many.urdf"), &options).unwrap_err().to_string();
    assert!(e.starts_with("many.urdf:1:") && e.contains("1000000 links, more than the limit of 10000"), "{e}");
}

/// A run log or a plan file larger than its limit is refused from its size, by `verify`.
#[test]
fn oversized_logs_and_plans_are_refused_by_the_command_line() {
    let dir = TempDir::new("limits-cli");
    let plan = dir.join("plan.json");
    sparse(&plan, b"{", 300_000_000);
    let (code, _, err) = common::embodied(&["verify", "polycrank-transfer", plan.to_str().expect("path")]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("plan.json") && err.contains("300.0 MB is larger than the limit of 268.4 MB"), "{err}");
    // The limit can be raised (then the file is read, and refused as the JSON it is not).
    let (code, _, err) =
        common::embodied(&["--max-input-mb", "400", "verify", "polycrank-transfer", plan.to_str().expect("path")]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("not a plan file"), "{err}");
    let log = dir.join("run.jsonl");
    sparse(&log, b"{", 5_000_000_000);
    let (code, _, err) = common::embodied(&["verify", "polycrank-transfer", "--log", log.to_str().expect("path")]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("run.jsonl") && err.contains("5.00 GB is larger than the limit of 4.29 GB for a run log"),
        "{err}"
    );
}

/// Found by `embodied fuzz --loader log --seed 2000` (input 45850, cut to its first 4,000
/// characters): a log header with `step_s = 1e308` made the times of standing obstacles
/// `0 * inf = NaN`, and the clearance check grew a cylinder by NaN, which parry refuses with a
/// panic. The header's control period is now checked, and a standing obstacle never moves.
#[test]
fn a_log_with_an_absurd_control_period_is_refused() {
    let scenario = load_scenario("polycrank-transfer").expect("built-in scenario");
    let file = root().join("tests/fixtures/fuzz/log-step-1e308.jsonl");
    let e = verify_log(&scenario, &file, &CheckSettings::default()).unwrap_err().to_string();
    assert!(e.contains("log-step-1e308.jsonl:1:1: header.step_s") && e.contains("(0, 1] s"), "{e}");
    let grown = embodied_system::clearance::grown(&embodied_models::Shape::cylinder(0.1, 0.5), f64::NAN);
    assert_eq!(format!("{grown:?}"), format!("{:?}", embodied_models::Shape::cylinder(0.1, 0.5)));
}
