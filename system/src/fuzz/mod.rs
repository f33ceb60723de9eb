//! `embodied fuzz`: every loader fed structure-aware random inputs, none may panic or hang.
//!
//! For each loader (scenario TOML, URDF, SRDF, MoveIt scene and request YAML,
//! `joint_limits.yaml`, STL, OBJ and Collada meshes, plan files, JointTrajectory YAML/JSON, run
//! logs) a generator writes documents with the format's real keys and tags mixed with junk:
//! random nesting, random values (NaN, infinities, huge, negative, wrong types, wrong lengths),
//! sometimes cut short or edited byte by byte ([`gen`]); a share of the inputs are edits of a
//! well-formed file instead. Each input goes through the loader and the checks behind it (a
//! robot built, an environment made, a plan or a log verified, a mesh's convex pieces
//! computed) inside [`std::panic::catch_unwind`]; the report counts per loader the inputs
//! accepted, refused with an error and panicking, the slowest input and the peak memory.
//!
//! Input `i` of loader `L` with seed `S` is the same on every run ([`input`]), so a finding is
//! reproduced with `embodied fuzz --loader L --seed S --inputs i+1`, and long runs split into
//! chunks by seed.

pub mod generate;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use embodied_models::Robot;
use embodied_models::formats::srdf::Srdf;
use embodied_models::urdf::UrdfOptions;
use embodied_planner::verify::CheckSettings;
use serde::Serialize;

use crate::SystemError;
use crate::scenario::Scenario;
use generate::{Doc, Elem, G, finish, to_json, to_toml, to_xml, to_yaml};

/// The loaders the fuzzer feeds, by name.
pub const LOADERS: [&str; 13] = [
    "scenario",
    "urdf",
    "srdf",
    "moveit-scene",
    "moveit-request",
    "joint-limits",
    "stl",
    "obj",
    "collada",
    "plan",
    "trajectory",
    "log",
    "log-view",
];

/// One panic found.
#[derive(Debug, Clone, Serialize)]
pub struct PanicFound {
    /// Index of the input (with the report's seed).
    pub input: u64,
    /// The panic message.
    pub message: String,
    /// The input (lossy UTF-8, at most 4,000 characters).
    pub text: String,
}

/// What one loader did with its inputs.
#[derive(Debug, Clone, Serialize, Default)]
pub struct LoaderReport {
    /// The loader.
    pub loader: String,
    /// Inputs fed.
    pub inputs: u64,
    /// Inputs loaded (and checked) without error.
    pub accepted: u64,
    /// Inputs refused with an error.
    pub refused: u64,
    /// Inputs that panicked (must be 0).
    pub panics: u64,
    /// Refusals whose message names no file (must be 0).
    pub unnamed_errors: u64,
    /// The slowest input's time, s.
    pub slowest_s: f64,
    /// The slowest input's index.
    pub slowest_input: u64,
    /// Mean input size, bytes.
    pub mean_bytes: f64,
    /// Largest input, bytes.
    pub max_bytes: usize,
    /// Peak resident memory of the process while this loader ran, MB (`VmHWM`; 0 where
    /// `/proc` is missing).
    pub peak_rss_mb: f64,
    /// Wall time of this loader, s.
    pub time_s: f64,
    /// The first panics (at most 5).
    pub panic_samples: Vec<PanicFound>,
    /// The first refusal naming no file, if any.
    pub unnamed_sample: Option<String>,
    /// The commonest refusals (the message without file name and digits, cut to 80
    /// characters) and how often each came, most frequent first (at most 8).
    pub top_refusals: Vec<(String, u64)>,
}

/// A refusal's message without the file name and the numbers in it, cut short, to count alike
/// refusals together.
fn refusal_key(message: &str, file: &Path) -> String {
    let m = message.replace(&file.display().to_string(), "FILE");
    let m: String = m.chars().filter(|c| !c.is_ascii_digit()).collect();
    m.chars().take(80).collect()
}

/// The whole run.
#[derive(Debug, Clone, Serialize)]
pub struct FuzzReport {
    /// The program that ran it.
    pub generator: String,
    /// The seed.
    pub seed: u64,
    /// Inputs per loader.
    pub inputs_per_loader: u64,
    /// One report per loader.
    pub loaders: Vec<LoaderReport>,
}

impl FuzzReport {
    /// Whether a promise was broken: a panic, an input over `max_s` or an error naming no file.
    pub fn failed(&self, max_s: f64) -> bool {
        self.loaders.iter().any(|l| l.panics > 0 || l.slowest_s > max_s || l.unnamed_errors > 0)
    }
}

/// What the loaders need: a folder with the files inputs refer to, a robot and its SRDF, a
/// scenario to check plans and logs against, and well-formed files to edit.
pub struct Fixture {
    dir: PathBuf,
    robot: Robot,
    srdf: Srdf,
    scenario: Scenario,
    plan: String,
    log: String,
}

/// A three-joint arm with boxes, a cylinder and a mesh for collision, two end effectors' links.
const ARM_URDF: &str = r#"<?xml version="1.0"?>
<robot name="arm">
  <link name="base"><collision><geometry><cylinder radius="0.1" length="0.2"/></geometry></collision></link>
  <link name="upper"><collision><origin xyz="0 0 0.2"/><geometry><box size="0.08 0.08 0.4"/></geometry></collision></link>
  <link name="fore"><collision><origin xyz="0 0 0.15"/><geometry><box size="0.06 0.06 0.3"/></geometry></collision></link>
  <link name="tool"><collision><geometry><mesh filename="tetra.stl" scale="0.1 0.1 0.1"/></geometry></collision></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="upper"/><origin xyz="0 0 0.1"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" velocity="2" effort="10"/></joint>
  <joint name="j2" type="revolute"><parent link="upper"/><child link="fore"/><origin xyz="0 0 0.4"/><axis xyz="0 1 0"/><limit lower="-2" upper="2" velocity="2" effort="10"/></joint>
  <joint name="j3" type="prismatic"><parent link="fore"/><child link="tool"/><origin xyz="0 0 0.3"/><axis xyz="0 0 1"/><limit lower="0" upper="0.1" velocity="0.5" effort="10"/></joint>
</robot>
"#;

const ARM_SRDF: &str = r#"<?xml version="1.0"?>
<robot name="arm">
  <group name="arm"><chain base_link="base" tip_link="tool"/></group>
  <group_state name="home" group="arm"><joint name="j1" value="0"/><joint name="j2" value="0.5"/><joint name="j3" value="0.05"/></group_state>
  <end_effector name="tip" parent_link="tool" group="arm"/>
  <disable_collisions link1="base" link2="upper" reason="Adjacent"/>
</robot>
"#;

const TETRA_STL: &str = "solid t\nfacet normal 0 0 -1\nouter loop\nvertex 0 0 0\nvertex 0 1 0\nvertex 1 0 0\nendloop\nendfacet\nfacet normal 0 -1 0\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 0 1\nendloop\nendfacet\nfacet normal -1 0 0\nouter loop\nvertex 0 0 0\nvertex 0 0 1\nvertex 0 1 0\nendloop\nendfacet\nfacet normal 1 1 1\nouter loop\nvertex 1 0 0\nvertex 0 1 0\nvertex 0 0 1\nendloop\nendfacet\nendsolid t\n";

const CUBE_OBJ: &str = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\nf 1 3 2\nf 1 4 3\nf 5 6 7\nf 5 7 8\nf 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\nf 3 4 8\nf 3 8 7\nf 4 1 5\nf 4 5 8\n";

const JOINTS: [&str; 4] = ["j1", "j2", "j3", "base_joint"];
const LINKS: [&str; 5] = ["base", "upper", "fore", "tool", "world"];

impl Fixture {
    /// The fixture, with its files written into a new folder under `dir`.
    pub fn new(dir: &Path) -> Result<Self, SystemError> {
        std::fs::create_dir_all(dir).map_err(|e| SystemError::write(dir, e))?;
        let write = |name: &str, text: &str| -> Result<(), SystemError> {
            let p = dir.join(name);
            std::fs::write(&p, text).map_err(|e| SystemError::write(&p, e))
        };
        write("arm.urdf", ARM_URDF)?;
        write("arm.srdf", ARM_SRDF)?;
        write("tetra.stl", TETRA_STL)?;
        write("cube.obj", CUBE_OBJ)?;
        std::fs::create_dir_all(dir.join("fuzz")).map_err(|e| SystemError::write(dir, e))?;
        write("fuzz/tetra.stl", TETRA_STL)?;
        let srdf = embodied_models::srdf::parse_srdf(ARM_SRDF, &dir.join("arm.srdf"))?;
        let options = UrdfOptions { package_dirs: vec![dir.to_path_buf()], ..UrdfOptions::default() };
        let robot = embodied_models::formats::parse_urdf_with_srdf(ARM_URDF, &dir.join("arm.urdf"), &options, &srdf)?;
        let scenario = crate::scenario::load_scenario("polycrank-transfer")?;
        let plan = crate::plan::plan_scenario(&scenario, Some(10_000.0))?;
        let plan = serde_json::to_string_pretty(&plan).map_err(|e| SystemError::Failed(e.to_string()))?;
        let log_file = dir.join("run.jsonl");
        let args = crate::system::RunArgs {
            scenario: "polycrank-transfer".into(),
            options: crate::system::RunOptions { duration: Some(0.03), ..Default::default() },
            log: Some(log_file.clone()),
            ..Default::default()
        };
        crate::system::run_scenario(&args)?;
        let log = std::fs::read_to_string(&log_file).map_err(|e| SystemError::io(&log_file, e))?;
        Ok(Self { dir: dir.to_path_buf(), robot, srdf, scenario, plan, log })
    }
}

/// The random source of input `i` of loader `loader` with seed `seed`.
pub fn input_seed(seed: u64, loader: usize, i: u64) -> u64 {
    seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ ((loader as u64) << 56) ^ i.wrapping_mul(0xD1B5_4A32_D192_ED03)
}

/// Input `i` of `loader` (an index into [`LOADERS`]) with seed `seed`.
pub fn input(fx: &Fixture, loader: usize, seed: u64, i: u64) -> Vec<u8> {
    let g = G::new(input_seed(seed, loader, i));
    // One input in five edits a well-formed file instead of generating one.
    let edit = g.p(0.2);
    let seed_text = |g: &G| -> Option<String> {
        Some(match LOADERS[loader] {
            "scenario" => {
                crate::scenario::BUILTIN_SCENARIOS[g.below(crate::scenario::BUILTIN_SCENARIOS.len())].1.to_string()
            }
            "urdf" => ARM_URDF.to_string(),
            "srdf" => ARM_SRDF.to_string(),
            "stl" => TETRA_STL.to_string(),
            "obj" => CUBE_OBJ.to_string(),
            "plan" => fx.plan.clone(),
            "log" | "log-view" => fx.log.clone(),
            _ => return None,
        })
    };
    if edit && let Some(text) = seed_text(&g) {
        let mut bytes = text.into_bytes();
        let n = g.int(1, 6);
        generate::mutate(&mut bytes, &g, n);
        return bytes;
    }
    match LOADERS[loader] {
        "scenario" => finish(to_toml(&scenario_doc(&g), &g), &g),
        "urdf" => finish(to_xml(&urdf_elem(&g), &g), &g),
        "srdf" => finish(to_xml(&srdf_elem(&g), &g), &g),
        "moveit-scene" => finish(to_yaml(&scene_doc(&g), &g), &g),
        "moveit-request" => finish(to_yaml(&request_doc(&g), &g), &g),
        "joint-limits" => finish(to_yaml(&joint_limits_doc(&g), &g), &g),
        "stl" => stl_bytes(&g),
        "obj" => finish(obj_text(&g), &g),
        "collada" => finish(to_xml(&collada_elem(&g), &g), &g),
        "plan" => finish(to_json(&plan_doc(&g, fx), &g), &g),
        "trajectory" => {
            let doc = trajectory_doc(&g);
            let text = if g.p(0.5) { to_yaml(&doc, &g) } else { to_json(&doc, &g) };
            finish(text, &g)
        }
        _ => finish(log_text(&g, fx), &g),
    }
}

/// The file name an input of `loader` is read as.
pub fn file_name(loader: &str, i: u64) -> String {
    let ext = match loader {
        "scenario" => "toml",
        "urdf" => "urdf",
        "srdf" => "srdf",
        "stl" => "stl",
        "obj" => "obj",
        "collada" => "dae",
        "plan" => "json",
        "log" | "log-view" => "jsonl",
        _ => "yaml",
    };
    format!("fuzz-{loader}-{i}.{ext}")
}

/// The distance evaluations one `plan`, `trajectory` or `log` input's collision checks may spend
/// in all: the fixture's own plan and log need far fewer, and a few thousand evaluations of the
/// Polycrank's pairs take tens of milliseconds, so no input comes near 1 s. An input that
/// spends it is not certified (never free).
pub const FUZZ_MAX_EVALUATIONS: usize = 2_000;

fn fuzz_check_settings() -> CheckSettings {
    CheckSettings { max_evaluations: Some(FUZZ_MAX_EVALUATIONS), ..CheckSettings::default() }
}

/// Feed one input to `loader`: `Ok` if it was accepted, else the error's text.
pub fn load(fx: &Fixture, loader: &str, bytes: &[u8], file: &Path) -> Result<(), String> {
    let text = || std::str::from_utf8(bytes).map_err(|e| format!("{}: not UTF-8 text: {e}", file.display()));
    let err = |e: &dyn std::fmt::Display| e.to_string();
    match loader {
        "scenario" => crate::scenario::parse_scenario(text()?, file, &fx.dir).map(|_| ()).map_err(|e| match e {
            SystemError::Usage(m) => format!("{}: {m}", file.display()),
            e => e.to_string(),
        }),
        "urdf" => {
            let options = UrdfOptions { package_dirs: vec![fx.dir.clone()], ..UrdfOptions::default() };
            let robot = embodied_models::urdf::parse_urdf(text()?, file, &options).map_err(|e| err(&e))?;
            let model = embodied_models::CollisionModel::new(&robot, embodied_models::Environment::new());
            let _ = model.collides(robot.home());
            Ok(())
        }
        "srdf" => {
            let srdf = embodied_models::srdf::parse_srdf(text()?, file).map_err(|e| err(&e))?;
            let options = UrdfOptions { package_dirs: vec![fx.dir.clone()], ..UrdfOptions::default() };
            let robot =
                embodied_models::formats::parse_urdf_with_srdf(ARM_URDF, &fx.dir.join("arm.urdf"), &options, &srdf)
                    .map_err(|e| err(&e))?;
            for g in &srdf.groups {
                let _ = srdf.group_dofs(&robot, &g.name);
            }
            Ok(())
        }
        "moveit-scene" => {
            let scene = embodied_planner::moveit::parse_scene(text()?, file).map_err(|e| err(&e))?;
            let _ = scene.environment();
            let mut robot = fx.robot.clone();
            scene.apply_allowed_collisions(&mut robot);
            scene.check_frames(&robot).map_err(|e| err(&e))
        }
        "moveit-request" => {
            let request = embodied_planner::moveit::parse_request(text()?, file).map_err(|e| err(&e))?;
            request.resolve(&fx.robot, &fx.srdf, None).map(|_| ()).map_err(|e| err(&e))
        }
        "joint-limits" => {
            let limits =
                embodied_models::formats::joint_limits::parse_joint_limits(text()?, file).map_err(|e| err(&e))?;
            let mut robot = fx.robot.clone();
            limits.apply(&mut robot).map(|_| ()).map_err(|e| err(&e))
        }
        "stl" | "obj" | "collada" => {
            let ext = if loader == "collada" { "dae" } else { loader };
            let scale = nalgebra::Vector3::new(0.5, 2.0, 1.0);
            let mesh = embodied_models::formats::mesh::parse_mesh(bytes, ext, scale)
                .map_err(|e| format!("{}: {e}", file.display()))?;
            let rule = embodied_models::formats::mesh::Decomposition::default();
            embodied_models::formats::mesh::convex_pieces(&mesh, Some(&rule))
                .map(|_| ())
                .ok_or_else(|| format!("{}: degenerate mesh", file.display()))
        }
        "plan" => {
            let plan = crate::plan::parse_plan(text()?, file).map_err(|e| err(&e))?;
            crate::verify::verify_plan(&fx.scenario, &plan, file, &fuzz_check_settings())
                .map(|_| ())
                .map_err(|e| err(&e))
        }
        "trajectory" => {
            let jt = embodied_planner::moveit::parse_joint_trajectory(text()?, file).map_err(|e| err(&e))?;
            let problem = embodied_planner::moveit::trajectory_problem(
                &fx.robot,
                None,
                embodied_models::Environment::new(),
                &jt,
                file,
            )
            .map_err(|e| err(&e))?;
            let report = embodied_planner::verify::Verifier::default()
                .with_settings(fuzz_check_settings())
                .check_trajectory(&problem.model, &problem.trajectory, &[]);
            let _ = report.certified;
            Ok(())
        }
        "log" => {
            let text = text()?;
            for (n, line) in text.lines().enumerate() {
                let _ = crate::log::parse_log_line(line, file, n + 1);
            }
            crate::verify::verify_log_text(&fx.scenario, text, file, &fuzz_check_settings())
                .map(|_| ())
                .map_err(|e| err(&e))
        }
        _ => {
            let text = text()?;
            let agents: Vec<String> = fx.scenario.agents.iter().map(|a| a.name.clone()).collect();
            crate::view::read_run_log(text, file, &agents, 0.002).map(|_| ()).map_err(|e| err(&e))?;
            crate::view::log_origin(text, file).map(|_| ()).map_err(|e| err(&e))
        }
    }
}

/// `VmHWM` (peak resident set) of this process, MB; 0 where `/proc` is missing.
pub fn peak_rss_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1).and_then(|kb| kb.parse::<f64>().ok()))
        })
        .map_or(0.0, |kb| kb / 1024.0)
}

/// Reset the peak resident set to the current one (Linux; elsewhere nothing happens), so each
/// loader's peak is its own.
fn reset_peak_rss() {
    let _ = std::fs::write("/proc/self/clear_refs", "5");
}

/// The fuzz run's settings.
#[derive(Debug, Clone)]
pub struct FuzzSettings {
    /// The loaders to feed (names from [`LOADERS`]).
    pub loaders: Vec<String>,
    /// Inputs per loader.
    pub inputs: u64,
    /// The seed.
    pub seed: u64,
    /// The folder for the fixture's files (removed afterwards).
    pub dir: PathBuf,
}

fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "a panic without a message".into())
}

/// Run the fuzzer; `progress` hears each loader's report as it finishes. Panics are caught
/// (and the panic hook silenced while the loaders run).
pub fn fuzz(settings: &FuzzSettings, mut progress: impl FnMut(&LoaderReport)) -> Result<FuzzReport, SystemError> {
    for l in &settings.loaders {
        if !LOADERS.contains(&l.as_str()) {
            return Err(SystemError::Usage(format!("unknown loader `{l}`; the loaders are: {}", LOADERS.join(", "))));
        }
    }
    let fx = Fixture::new(&settings.dir)?;
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let mut reports = Vec::new();
    for name in &settings.loaders {
        let k = LOADERS.iter().position(|l| l == name).unwrap_or(0);
        reset_peak_rss();
        let start = Instant::now();
        let mut r = LoaderReport { loader: name.clone(), ..LoaderReport::default() };
        let mut total_bytes = 0u64;
        let mut refusals: std::collections::HashMap<String, u64> = std::collections::HashMap::new();
        for i in 0..settings.inputs {
            let bytes = input(&fx, k, settings.seed, i);
            total_bytes += bytes.len() as u64;
            r.max_bytes = r.max_bytes.max(bytes.len());
            let file = fx.dir.join(file_name(name, i));
            let t0 = Instant::now();
            let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| load(&fx, name, &bytes, &file)));
            let dt = t0.elapsed();
            if dt.as_secs_f64() > r.slowest_s {
                r.slowest_s = dt.as_secs_f64();
                r.slowest_input = i;
            }
            r.inputs += 1;
            match outcome {
                Ok(Ok(())) => r.accepted += 1,
                Ok(Err(message)) => {
                    r.refused += 1;
                    if refusals.len() < 10_000 || refusals.contains_key(&refusal_key(&message, &file)) {
                        *refusals.entry(refusal_key(&message, &file)).or_default() += 1;
                    }
                    let named = message.contains(&file.display().to_string())
                        || message.contains(&file_name(name, i))
                        || ["arm.urdf", ".stl", ".obj", ".dae", ".urdf", ".srdf"].iter().any(|n| message.contains(n));
                    if !named {
                        r.unnamed_errors += 1;
                        r.unnamed_sample.get_or_insert(message);
                    }
                }
                Err(payload) => {
                    r.panics += 1;
                    if r.panic_samples.len() < 5 {
                        let text: String = String::from_utf8_lossy(&bytes).chars().take(4000).collect();
                        r.panic_samples.push(PanicFound { input: i, message: panic_message(&*payload), text });
                    }
                }
            }
        }
        r.time_s = start.elapsed().as_secs_f64();
        let mut top: Vec<(String, u64)> = refusals.into_iter().collect();
        top.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
        top.truncate(8);
        r.top_refusals = top;
        r.mean_bytes = if r.inputs > 0 { total_bytes as f64 / r.inputs as f64 } else { 0.0 };
        r.peak_rss_mb = peak_rss_mb();
        progress(&r);
        reports.push(r);
    }
    std::panic::set_hook(hook);
    let _ = std::fs::remove_dir_all(&settings.dir);
    Ok(FuzzReport {
        generator: crate::generator(),
        seed: settings.seed,
        inputs_per_loader: settings.inputs,
        loaders: reports,
    })
}

/// The report as a table.
pub fn render(report: &FuzzReport) -> String {
    let mut s = format!(
        "fuzz: {} inputs per loader, seed {} ({})\n{:<15} {:>9} {:>9} {:>9} {:>6} {:>8} {:>11} {:>9} {:>8}\n",
        report.inputs_per_loader,
        report.seed,
        report.generator,
        "loader",
        "inputs",
        "accepted",
        "refused",
        "panics",
        "unnamed",
        "slowest ms",
        "peak MB",
        "time s"
    );
    for l in &report.loaders {
        s.push_str(&format!(
            "{:<15} {:>9} {:>9} {:>9} {:>6} {:>8} {:>11.2} {:>9.1} {:>8.1}\n",
            l.loader,
            l.inputs,
            l.accepted,
            l.refused,
            l.panics,
            l.unnamed_errors,
            l.slowest_s * 1e3,
            l.peak_rss_mb,
            l.time_s
        ));
        for p in &l.panic_samples {
            s.push_str(&format!("  PANIC at input {}: {}\n", p.input, p.message));
        }
        if let Some(m) = &l.unnamed_sample {
            s.push_str(&format!("  error naming no file: {m}\n"));
        }
    }
    s
}

/// A duration in milliseconds, for messages.
pub fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

// ---- the generators of each format ----

const ROBOTS: [&str; 6] = ["polycrank", "irp6-postument", "irp6-on-track", "two-irp6", "rnt", "nobot"];
const SCENARIO_KEYS: [&str; 40] = [
    "name",
    "description",
    "seed",
    "agents",
    "obstacles",
    "planner",
    "run",
    "carry",
    "task",
    "faults",
    "robot",
    "urdf",
    "srdf",
    "xyz",
    "rpy",
    "start",
    "goal",
    "goals",
    "goal_pose",
    "behaviour",
    "box",
    "sphere",
    "cylinder",
    "capsule",
    "mesh",
    "scale",
    "appear_at",
    "velocity",
    "deadline_ms",
    "clock",
    "duration",
    "coordination",
    "agent",
    "object",
    "size",
    "start_xyz",
    "goal_xyz",
    "kind",
    "at_s",
    "probability",
];

fn scenario_doc(g: &G) -> Doc {
    if g.p(0.1) {
        return g.random_doc(&SCENARIO_KEYS, 4);
    }
    let n_agents = g.int(1, 4);
    let dof = [7usize, 6, 7, 13, 3, 4];
    let agents: Vec<Doc> = (0..n_agents)
        .map(|k| {
            let r = g.below(ROBOTS.len());
            let (lo, hi) = (-1.0, 1.0);
            let robot = if g.p(0.85) {
                ("robot", g.string(&ROBOTS[r..=r]))
            } else {
                ("urdf", g.string(&["arm.urdf", "missing.urdf", "tetra.stl"]))
            };
            let n = if robot.0 == "urdf" { 3 } else { dof[r] };
            let goal_pose = g.some(
                0.5,
                vec![("xyz", g.nums(3, -1.0, 1.0))],
                vec![("rpy", g.nums(3, -3.0, 3.0)), ("end_effector", g.string(&["tip", "tool", "left"]))],
            );
            let behaviour = g.some(0.5, vec![], vec![("force_limit", g.num(0.0, 100.0))]);
            let goals = g.seq(1, 3, |g| g.nums(n, lo, hi));
            g.some(
                0.5,
                vec![("name", g.string(&[["a", "b", "c"][k % 3], "arm", "a"])), robot],
                vec![
                    ("srdf", g.string(&["arm.srdf", "missing.srdf"])),
                    ("xyz", g.nums(3, -2.0, 2.0)),
                    ("rpy", g.nums(3, -3.0, 3.0)),
                    ("start", g.nums(n, lo, hi)),
                    ("goal", g.nums(n, lo, hi)),
                    ("goals", goals),
                    ("goal_pose", goal_pose),
                    ("behaviour", behaviour),
                ],
            )
        })
        .collect();
    let n_obstacles = g.int(0, 4);
    let obstacles: Vec<Doc> = (0..n_obstacles)
        .map(|k| {
            let shape = match g.below(5) {
                0 => ("box", g.nums(3, 0.0, 1.0)),
                1 => ("sphere", g.num(0.0, 1.0)),
                2 => ("cylinder", g.map(vec![("radius", g.num(0.0, 0.5)), ("length", g.num(0.0, 2.0))])),
                3 => ("capsule", g.map(vec![("radius", g.num(0.0, 0.5)), ("length", g.num(0.0, 2.0))])),
                _ => ("mesh", g.string(&["tetra.stl", "cube.obj", "missing.stl"])),
            };
            g.some(
                0.3,
                vec![("name", g.string(&[["o1", "o2"][k % 2], "pole"])), shape, ("xyz", g.nums(3, -2.0, 2.0))],
                vec![
                    ("rpy", g.nums(3, -3.0, 3.0)),
                    ("scale", g.num(0.0, 2.0)),
                    ("appear_at", g.num(0.0, 5.0)),
                    ("velocity", g.nums(3, -1.0, 1.0)),
                ],
            )
        })
        .collect();
    let planner = g.some(
        0.4,
        vec![],
        vec![
            ("deadline_ms", g.num(0.0, 500.0)),
            ("give_up_ms", g.num(0.0, 1000.0)),
            ("clock", g.string(&["wall", "simulated"])),
            ("simulated_us_per_check", g.num(0.0, 50.0)),
            ("edge_check", g.string(&["certified", "sampled"])),
            ("resolution", g.num(0.0, 0.1)),
            ("seed", g.integer(0, 100)),
            ("expansions", g.integer(0, 100_000)),
        ],
    );
    let run = g.some(
        0.5,
        vec![],
        vec![("duration", g.num(0.0, 20.0)), ("coordination", g.string(&["sequential", "concurrent"]))],
    );
    let carry = g.some(
        0.5,
        vec![
            ("agent", g.string(&["a", "pair"])),
            ("object", g.string(&["bar"])),
            ("size", g.nums(3, 0.0, 1.0)),
            ("start_xyz", g.nums(3, -1.0, 1.0)),
            ("goal_xyz", g.nums(3, -1.0, 1.0)),
        ],
        vec![
            ("rpy", g.nums(3, -3.0, 3.0)),
            ("end_effectors", g.seq(2, 3, |g| g.string(&["left", "right", "tip"]))),
            ("grasp_roll", g.nums(2, -3.0, 3.0)),
            ("lattice_step", g.num(0.0, 1.0)),
        ],
    );
    let faults = g.seq(0, 3, |g| {
        g.some(
            0.5,
            vec![("kind", g.string(&["planner_late", "planner_panic", "sensor_nan", "dropout", "link_loss"]))],
            vec![
                ("at_s", g.num(0.0, 3.0)),
                ("probability", g.num(0.0, 1.0)),
                ("agent", g.string(&["a", "b"])),
                ("seed", g.integer(0, 9)),
            ],
        )
    });
    let task = g.random_doc(&["stands", "parts", "goal", "arm", "level", "xyz", "name", "deadline_ms"], 3);
    g.some(
        0.25,
        vec![
            ("name", g.string(&["fuzz"])),
            ("description", g.string(&["a generated scenario"])),
            ("agents", Doc::Seq(agents)),
        ],
        vec![
            ("seed", g.integer(0, 1000)),
            ("obstacles", Doc::Seq(obstacles)),
            ("planner", planner),
            ("run", run),
            ("carry", carry),
            ("faults", faults),
            ("task", task),
        ],
    )
}

const URDF_TAGS: [&str; 24] = [
    "robot",
    "link",
    "joint",
    "parent",
    "child",
    "origin",
    "axis",
    "limit",
    "mimic",
    "dynamics",
    "safety_controller",
    "visual",
    "collision",
    "inertial",
    "geometry",
    "box",
    "cylinder",
    "sphere",
    "mesh",
    "material",
    "mass",
    "inertia",
    "calibration",
    "transmission",
];
const URDF_ATTRS: [&str; 16] = [
    "name",
    "type",
    "link",
    "xyz",
    "rpy",
    "lower",
    "upper",
    "velocity",
    "effort",
    "joint",
    "multiplier",
    "offset",
    "size",
    "radius",
    "length",
    "filename",
];

fn geometry(g: &G) -> Elem {
    let shape = match g.below(4) {
        0 => Elem::new("box", vec![("size", g.attr_nums(3, 0.0, 1.0))]),
        1 => Elem::new("cylinder", vec![("radius", g.attr_nums(1, 0.0, 0.3)), ("length", g.attr_nums(1, 0.0, 1.0))]),
        2 => Elem::new("sphere", vec![("radius", g.attr_nums(1, 0.0, 0.3))]),
        _ => {
            let file = g.name(&["tetra.stl", "cube.obj", "package://fuzz/tetra.stl", "missing.stl", "mesh.ply", ""]);
            let mut attrs = vec![("filename", file)];
            if g.p(0.5) {
                attrs.push(("scale", g.attr_nums(3, -1.0, 2.0)));
            }
            Elem::new("mesh", attrs)
        }
    };
    Elem::new("geometry", vec![]).with(vec![shape])
}

fn origin(g: &G) -> Elem {
    Elem::new("origin", vec![("xyz", g.attr_nums(3, -1.0, 1.0)), ("rpy", g.attr_nums(3, -3.2, 3.2))])
}

fn urdf_elem(g: &G) -> Elem {
    if g.p(0.1) {
        let mut e = g.random_elem(&URDF_TAGS, &URDF_ATTRS, 4);
        e.tag = "robot".into();
        return e;
    }
    let n = g.int(1, 8);
    let links: Vec<String> = (0..n).map(|k| format!("l{k}")).collect();
    let mut children = Vec::new();
    for l in &links {
        let mut body = Vec::new();
        for part in ["collision", "visual"] {
            if g.p(0.6) {
                let mut c = vec![geometry(g)];
                if g.p(0.5) {
                    c.insert(0, origin(g));
                }
                body.push(Elem::new(part, vec![]).with(c));
            }
        }
        if g.p(0.3) {
            body.push(Elem::new("inertial", vec![]).with(vec![
                Elem::new("mass", vec![("value", g.attr_nums(1, 0.0, 10.0))]),
                Elem::new(
                    "inertia",
                    vec![
                        ("ixx", g.attr_nums(1, 0.0, 1.0)),
                        ("iyy", g.attr_nums(1, 0.0, 1.0)),
                        ("izz", g.attr_nums(1, 0.0, 1.0)),
                    ],
                ),
            ]));
        }
        let name = if g.junky() { g.junk_string() } else { l.clone() };
        children.push(Elem::new("link", vec![("name", name)]).with(body));
    }
    let names: Vec<&str> = links.iter().map(String::as_str).collect();
    for k in 1..n {
        let kind = g.name(&["revolute", "continuous", "prismatic", "fixed", "floating", "planar", "ball"]);
        let parent = if g.junky() { g.name(&names) } else { links[g.below(k)].clone() };
        let child = if g.junky() { g.name(&names) } else { links[k].clone() };
        let mut body = vec![Elem::new("parent", vec![("link", parent)]), Elem::new("child", vec![("link", child)])];
        if g.p(0.7) {
            body.push(origin(g));
        }
        if g.p(0.7) {
            body.push(Elem::new("axis", vec![("xyz", g.attr_nums(3, -1.0, 1.0))]));
        }
        if g.p(0.8) {
            let lo = g.f(-3.0, 0.0);
            body.push(Elem::new(
                "limit",
                vec![
                    ("lower", generate::fmt_num(lo)),
                    ("upper", g.attr_nums(1, -1.0, 3.0)),
                    ("velocity", g.attr_nums(1, -1.0, 5.0)),
                    ("effort", g.attr_nums(1, 0.0, 100.0)),
                ],
            ));
        }
        if g.p(0.1) {
            body.push(Elem::new(
                "mimic",
                vec![
                    ("joint", g.name(&["j1", "j2", "j0"])),
                    ("multiplier", g.attr_nums(1, -2.0, 2.0)),
                    ("offset", g.attr_nums(1, -1.0, 1.0)),
                ],
            ));
        }
        if g.p(0.1) {
            body.push(Elem::new(
                "safety_controller",
                vec![("soft_lower_limit", g.attr_nums(1, -3.0, 0.0)), ("soft_upper_limit", g.attr_nums(1, 0.0, 3.0))],
            ));
        }
        let name = if g.junky() { g.name(&["j1", "j2"]) } else { format!("j{k}") };
        children.push(Elem::new("joint", vec![("name", name), ("type", kind)]).with(body));
    }
    if g.junky() {
        children.push(g.random_elem(&URDF_TAGS, &URDF_ATTRS, 3));
    }
    if g.p(0.3) {
        for i in (1..children.len()).rev() {
            let j = g.below(i + 1);
            children.swap(i, j);
        }
    }
    let mut attrs = vec![];
    if g.p(0.9) {
        attrs.push(("name", g.name(&["fuzz"])));
    }
    Elem::new("robot", attrs).with(children)
}

const SRDF_TAGS: [&str; 14] = [
    "robot",
    "group",
    "chain",
    "joint",
    "link",
    "group_state",
    "end_effector",
    "virtual_joint",
    "disable_collisions",
    "enable_collisions",
    "disable_default_collisions",
    "passive_joint",
    "link_sphere_approximation",
    "sphere",
];
const SRDF_ATTRS: [&str; 14] = [
    "name",
    "base_link",
    "tip_link",
    "group",
    "value",
    "parent_link",
    "parent_group",
    "type",
    "parent_frame",
    "child_link",
    "link1",
    "link2",
    "reason",
    "link",
];

fn srdf_elem(g: &G) -> Elem {
    if g.p(0.1) {
        let mut e = g.random_elem(&SRDF_TAGS, &SRDF_ATTRS, 4);
        e.tag = "robot".into();
        return e;
    }
    let groups = ["arm", "hand", "both"];
    let mut children = Vec::new();
    for group in g.distinct(&groups, g.int(0, 4)) {
        let mut members = Vec::new();
        for _ in 0..g.int(0, 4) {
            members.push(match g.below(5) {
                0 => Elem::new("chain", vec![("base_link", g.name(&LINKS)), ("tip_link", g.name(&LINKS))]),
                1 => Elem::new("joint", vec![("name", g.name(&JOINTS))]),
                2 => Elem::new("link", vec![("name", g.name(&LINKS))]),
                3 => Elem::new("group", vec![("name", g.name(&groups))]),
                _ => Elem::new("passive_joint", vec![("name", g.name(&JOINTS))]),
            });
        }
        children.push(Elem::new("group", vec![("name", group)]).with(members));
    }
    for _ in 0..g.int(0, 3) {
        let joints = (0..g.int(0, 4))
            .map(|_| {
                let values = g.attr_nums(g.pick(&[1, 1, 1, 3, 7]), -3.0, 3.0);
                Elem::new("joint", vec![("name", g.name(&JOINTS)), ("value", values)])
            })
            .collect();
        children.push(
            Elem::new("group_state", vec![("name", g.name(&["home", "ready"])), ("group", g.name(&groups))])
                .with(joints),
        );
    }
    for _ in 0..g.int(0, 3) {
        children.push(match g.below(6) {
            0 => Elem::new(
                "end_effector",
                vec![("name", g.name(&["tip"])), ("parent_link", g.name(&LINKS)), ("group", g.name(&groups))],
            ),
            1 => Elem::new(
                "virtual_joint",
                vec![
                    ("name", g.name(&["world_joint"])),
                    ("type", g.name(&["fixed", "floating", "planar"])),
                    ("parent_frame", g.name(&["world"])),
                    ("child_link", g.name(&LINKS)),
                ],
            ),
            2 => Elem::new(
                "disable_collisions",
                vec![("link1", g.name(&LINKS)), ("link2", g.name(&LINKS)), ("reason", g.name(&["Adjacent", "Never"]))],
            ),
            3 => Elem::new("enable_collisions", vec![("link1", g.name(&LINKS)), ("link2", g.name(&LINKS))]),
            4 => Elem::new("disable_default_collisions", vec![("link", g.name(&LINKS))]),
            _ => Elem::new("passive_joint", vec![("name", g.name(&JOINTS))]),
        });
    }
    Elem::new("robot", vec![("name", g.name(&["arm"]))]).with(children)
}

const MOVEIT_KEYS: [&str; 24] = [
    "name",
    "robot_state",
    "joint_state",
    "position",
    "world",
    "collision_objects",
    "id",
    "header",
    "frame_id",
    "primitives",
    "type",
    "dimensions",
    "primitive_poses",
    "orientation",
    "operation",
    "pose",
    "allowed_collision_matrix",
    "entry_names",
    "entry_values",
    "group_name",
    "goal_constraints",
    "joint_constraints",
    "joint_name",
    "start_state",
];

fn pose_doc(g: &G) -> Doc {
    if g.p(0.5) {
        g.map(vec![("position", g.nums(3, -1.0, 1.0)), ("orientation", g.nums(4, -1.0, 1.0))])
    } else {
        let position = g.map(vec![("x", g.num(-1.0, 1.0)), ("y", g.num(-1.0, 1.0)), ("z", g.num(-1.0, 1.0))]);
        let orientation = g.map(vec![
            ("x", g.num(-1.0, 1.0)),
            ("y", g.num(-1.0, 1.0)),
            ("z", g.num(-1.0, 1.0)),
            ("w", g.num(-1.0, 1.0)),
        ]);
        g.map(vec![("position", position), ("orientation", orientation)])
    }
}

fn joint_state_doc(g: &G) -> Doc {
    let n = g.int(0, 5);
    let names = Doc::Seq(g.distinct(&JOINTS, n).into_iter().map(Doc::Str).collect());
    let len = g.len(n.min(JOINTS.len()));
    g.map(vec![("name", names), ("position", g.nums(len, -1.0, 1.0))])
}

fn scene_doc(g: &G) -> Doc {
    if g.p(0.1) {
        return g.random_doc(&MOVEIT_KEYS, 5);
    }
    let objects = g.seq(0, 4, |g| {
        let n = g.int(0, 3);
        let prims = Doc::Seq(
            (0..n)
                .map(|_| {
                    let (kind, dims) = g.pick(&[("box", 3), ("sphere", 1), ("cylinder", 2), ("cone", 2)]);
                    let kind = if g.p(0.1) { Doc::Int(g.below(6) as i64) } else { g.string(&[kind]) };
                    g.map(vec![("type", kind), ("dimensions", g.nums(dims, 0.0, 1.0))])
                })
                .collect(),
        );
        let m = g.len(n);
        let poses = Doc::Seq((0..m).map(|_| pose_doc(g)).collect());
        let header = g.map(vec![("frame_id", g.string(&["world", "base", "tool", ""]))]);
        g.some(
            0.4,
            vec![("id", g.string(&["table", "ball", "box"])), ("primitives", prims), ("primitive_poses", poses)],
            vec![
                ("header", header),
                ("pose", pose_doc(g)),
                ("operation", g.string(&["add", "remove", "append", "move", "0", "1"])),
                ("meshes", Doc::Seq(vec![])),
            ],
        )
    });
    let n = g.int(0, 4);
    let entry_names = Doc::Seq((0..n).map(|_| g.string(&LINKS)).collect());
    let rows = g.len(n);
    let entry_values = Doc::Seq(
        (0..rows)
            .map(|_| {
                let cols = g.len(n);
                Doc::Seq((0..cols).map(|_| g.boolean()).collect())
            })
            .collect(),
    );
    let acm = g.map(vec![("entry_names", entry_names), ("entry_values", entry_values)]);
    let js = joint_state_doc(g);
    let robot_state = g.map(vec![("joint_state", js)]);
    let world = g.map(vec![("collision_objects", objects)]);
    g.some(
        0.6,
        vec![("name", g.string(&["scene"]))],
        vec![("robot_state", robot_state), ("allowed_collision_matrix", acm), ("world", world)],
    )
}

fn request_doc(g: &G) -> Doc {
    if g.p(0.1) {
        return g.random_doc(&MOVEIT_KEYS, 5);
    }
    let goals = g.seq(1, 2, |g| {
        let n = g.pick(&[3, 3, 3, 2, 4]);
        let names = g.distinct(&JOINTS[..3 + usize::from(g.p(0.1))], n);
        let jc = Doc::Seq(
            names
                .into_iter()
                .map(|name| {
                    g.some(
                        0.5,
                        vec![("joint_name", Doc::Str(name)), ("position", g.num(-0.1, 0.1))],
                        vec![
                            ("tolerance_above", g.num(0.0, 0.1)),
                            ("tolerance_below", g.num(0.0, 0.1)),
                            ("weight", g.num(0.0, 1.0)),
                        ],
                    )
                })
                .collect(),
        );
        let mut entries = vec![("joint_constraints", jc)];
        if g.p(0.1) {
            entries.push(("position_constraints", g.random_doc(&MOVEIT_KEYS, 2)));
        }
        g.map(entries)
    });
    let js = joint_state_doc(g);
    let start = g.map(vec![("joint_state", js)]);
    g.some(
        0.5,
        vec![("group_name", g.string(&["arm", "arm", "arm", "hand"])), ("goal_constraints", goals)],
        vec![
            ("start_state", start),
            ("planner_id", g.string(&["RRTConnect"])),
            ("allowed_planning_time", g.num(0.0, 60.0)),
            ("num_planning_attempts", g.integer(0, 5)),
            ("max_velocity_scaling_factor", g.num(0.0, 1.0)),
            ("max_acceleration_scaling_factor", g.num(0.0, 1.0)),
        ],
    )
}

fn joint_limits_doc(g: &G) -> Doc {
    if g.p(0.1) {
        return g.random_doc(&["joint_limits", "has_velocity_limits", "max_velocity", "j1", "j2"], 4);
    }
    let n = g.int(0, 4);
    let joints: Vec<(String, Doc)> = g
        .distinct(&JOINTS, n)
        .into_iter()
        .map(|name| {
            let v = g.some(
                0.6,
                vec![],
                vec![
                    ("has_velocity_limits", g.boolean()),
                    ("max_velocity", g.num(-1.0, 5.0)),
                    ("has_acceleration_limits", g.boolean()),
                    ("max_acceleration", g.num(-1.0, 10.0)),
                    ("has_position_limits", g.boolean()),
                    ("min_position", g.num(-3.0, 0.0)),
                    ("max_position", g.num(-1.0, 3.0)),
                ],
            );
            (name, v)
        })
        .collect();
    let limits = Doc::Map(joints);
    let body = g.some(
        0.5,
        vec![("joint_limits", limits)],
        vec![
            ("default_velocity_scaling_factor", g.num(0.0, 1.0)),
            ("default_acceleration_scaling_factor", g.num(0.0, 1.0)),
        ],
    );
    if g.p(0.2) { g.map(vec![("robot_description_planning", body)]) } else { body }
}

fn stl_bytes(g: &G) -> Vec<u8> {
    if g.p(0.4) {
        // Binary: header, a count (right, wrong or huge), triangles of random floats.
        let n = g.int(0, 40);
        let mut out = vec![b' '; 80];
        if g.p(0.1) {
            out[..5].copy_from_slice(b"solid");
        }
        let count: u32 = if g.junky() { g.pick(&[0, u32::MAX, n as u32 + 1, 1 << 30]) } else { n as u32 };
        out.extend_from_slice(&count.to_le_bytes());
        for _ in 0..n {
            for _ in 0..12 {
                let v = g.f(-1.0, 1.0) as f32;
                out.extend_from_slice(&v.to_le_bytes());
            }
            out.extend_from_slice(&[0, 0]);
        }
        if g.junky() {
            let cut = g.below(out.len() + 1);
            out.truncate(cut);
        }
        return out;
    }
    let mut s = String::from("solid fuzz\n");
    for _ in 0..g.int(0, 30) {
        s.push_str(&format!("facet normal {}\n  outer loop\n", g.attr_nums(3, -1.0, 1.0)));
        for _ in 0..g.len(3) {
            s.push_str(&format!("    vertex {}\n", g.attr_nums(3, -1.0, 1.0)));
        }
        s.push_str("  endloop\nendfacet\n");
    }
    if g.p(0.9) {
        s.push_str("endsolid fuzz\n");
    }
    finish(s, g)
}

fn obj_text(g: &G) -> String {
    let nv = g.int(0, 30);
    let mut s = String::new();
    if g.p(0.2) {
        s.push_str("mtllib fuzz.mtl\n");
    }
    for _ in 0..nv {
        let n = if g.p(0.01) { g.pick(&[2, 5]) } else { g.pick(&[3, 3, 3, 4]) };
        s.push_str(&format!("v {}\n", g.attr_nums(n, -1.0, 1.0)));
    }
    if g.p(0.3) {
        for _ in 0..g.int(0, 5) {
            s.push_str(&format!("vn {}\nvt {}\n", g.attr_nums(3, -1.0, 1.0), g.attr_nums(2, 0.0, 1.0)));
        }
    }
    if g.p(0.3) {
        s.push_str(&format!("o {}\ng {}\nusemtl {}\n", g.junk_string(), g.junk_string(), g.junk_string()));
    }
    for _ in 0..g.int(0, 40) {
        let corners = g.pick(&[3, 3, 3, 4, 5, 2, 1]);
        let idx: Vec<String> = (0..corners)
            .map(|_| {
                let i: i64 = if g.junky() {
                    g.pick(&[0, -1, -(nv as i64) - 1, nv as i64 + 1, i64::from(u32::MAX), i64::MAX])
                } else {
                    1 + g.below(nv.max(1)) as i64
                };
                match g.below(4) {
                    0 => format!("{i}/{i}/{i}"),
                    1 => format!("{i}//{i}"),
                    2 => format!("{i}/{i}"),
                    _ => i.to_string(),
                }
            })
            .collect();
        s.push_str(&format!("f {}\n", idx.join(" ")));
    }
    s
}

const COLLADA_TAGS: [&str; 22] = [
    "COLLADA",
    "asset",
    "unit",
    "up_axis",
    "library_geometries",
    "geometry",
    "mesh",
    "source",
    "float_array",
    "technique_common",
    "accessor",
    "param",
    "vertices",
    "input",
    "triangles",
    "polylist",
    "vcount",
    "p",
    "library_visual_scenes",
    "visual_scene",
    "node",
    "instance_geometry",
];

fn collada_elem(g: &G) -> Elem {
    if g.p(0.1) {
        let mut e = g.random_elem(&COLLADA_TAGS, &["id", "url", "source", "semantic", "offset", "count", "stride"], 5);
        e.tag = "COLLADA".into();
        return e;
    }
    let nv = g.int(0, 12);
    let floats: Vec<String> = (0..g.len(nv * 3)).map(|_| generate::fmt_num(g.f(-1.0, 1.0))).collect();
    let count_attr =
        |g: &G, n: usize| if g.junky() { g.pick(&["-1", "999999999", "x", "0"]).to_string() } else { n.to_string() };
    let mut float_array =
        Elem::new("float_array", vec![("id", "pos-array".into()), ("count", count_attr(g, floats.len()))]);
    float_array.text = Some(floats.join(" "));
    let accessor = Elem::new(
        "accessor",
        vec![
            ("source", g.name(&["#pos-array", "#nothing"])),
            ("count", count_attr(g, nv)),
            ("stride", if g.p(0.05) { g.pick(&["0", "4", "-3"]).to_string() } else { g.name(&["3"]) }),
        ],
    )
    .with(vec![
        Elem::new("param", vec![("name", "X".into()), ("type", "float".into())]),
        Elem::new("param", vec![("name", "Y".into()), ("type", "float".into())]),
        Elem::new("param", vec![("name", "Z".into()), ("type", "float".into())]),
    ]);
    let source = Elem::new("source", vec![("id", "pos".into())])
        .with(vec![float_array, Elem::new("technique_common", vec![]).with(vec![accessor])]);
    let vertices = Elem::new("vertices", vec![("id", "verts".into())]).with(vec![Elem::new(
        "input",
        vec![("semantic", g.name(&["POSITION"])), ("source", g.name(&["#pos", "#pos", "#pos", "#missing"]))],
    )]);
    let nt = g.int(0, 12);
    let idx: Vec<String> = (0..g.len(nt * 3))
        .map(|_| if g.junky() { g.pick(&["-1", "99999", "x"]).to_string() } else { g.below(nv.max(1)).to_string() })
        .collect();
    let mut p = Elem::new("p", vec![]);
    p.text = Some(idx.join(" "));
    let prim = g.name(&["triangles", "triangles", "polylist", "lines"]);
    let mut prim_children = vec![Elem::new(
        "input",
        vec![
            ("semantic", g.name(&["VERTEX"])),
            ("source", g.name(&["#verts", "#verts", "#pos", "#none"])),
            ("offset", g.name(&["0", "0", "0", "1", "-1"])),
        ],
    )];
    if prim == "polylist" {
        let mut vcount = Elem::new("vcount", vec![]);
        vcount.text = Some((0..nt).map(|_| g.name(&["3", "4", "0"])).collect::<Vec<_>>().join(" "));
        prim_children.push(vcount);
    }
    prim_children.push(p);
    let mut prim = Elem::new(&prim, vec![("count", count_attr(g, nt))]);
    prim.children = prim_children;
    let mesh = Elem::new("mesh", vec![]).with(vec![source, vertices, prim]);
    let geometry = Elem::new("geometry", vec![("id", "geom".into())]).with(vec![mesh]);
    let mut matrix = Elem::new("matrix", vec![]);
    matrix.text = Some(g.attr_nums(16, -2.0, 2.0));
    let node = Elem::new("node", vec![("id", "n".into())])
        .with(vec![matrix, Elem::new("instance_geometry", vec![("url", g.name(&["#geom", "#other"]))])]);
    let scenes = Elem::new("library_visual_scenes", vec![])
        .with(vec![Elem::new("visual_scene", vec![("id", "scene".into())]).with(vec![node])]);
    let unit = Elem::new("unit", vec![("meter", g.attr_nums(1, 0.0, 2.0))]);
    Elem::new("COLLADA", vec![("version", g.name(&["1.4.1", "1.5.0"]))]).with(vec![
        Elem::new("asset", vec![]).with(vec![unit]),
        Elem::new("library_geometries", vec![]).with(vec![geometry]),
        scenes,
        Elem::new("scene", vec![])
            .with(vec![Elem::new("instance_visual_scene", vec![("url", g.name(&["#scene", "#x"]))])]),
    ])
}

fn plan_doc(g: &G, fx: &Fixture) -> Doc {
    let keys = ["format", "scenario", "plans", "agent", "robot", "path", "trajectory", "t", "q", "qd"];
    if g.p(0.1) {
        return g.random_doc(&keys, 5);
    }
    let agent = &fx.scenario.agents[0];
    let names: Vec<String> = agent.robot.joint_names();
    let name_pool: Vec<&str> = names.iter().map(String::as_str).collect();
    let robot_hash = crate::plan::robot_hash(&agent.robot);
    let start = agent.start.clone();
    let plans = g.seq(1, 3, |g| {
        let n = g.len(names.len());
        let steps = g.int(0, 40);
        let t: Vec<Doc> = (0..g.len(steps)).map(|k| g.num(k as f64 * 0.001, k as f64 * 0.001 + 1e-9)).collect();
        // Small steps from the start: within the limits unless junk says otherwise.
        let walk = |g: &G, scale: f64| -> Doc {
            Doc::Seq(
                (0..g.len(steps))
                    .map(|k| {
                        if g.junky() {
                            return g.junk_value(1);
                        }
                        Doc::Seq(
                            (0..n)
                                .map(|j| {
                                    Doc::Num(start.get(j).copied().unwrap_or(0.0) * scale + g.f(0.0, 1e-4) * k as f64)
                                })
                                .collect(),
                        )
                    })
                    .collect(),
            )
        };
        let q = walk(g, 1.0);
        let qd = walk(g, 0.0);
        let joint_names = || Doc::Seq(g.distinct(&name_pool, n).into_iter().map(Doc::Str).collect());
        let jn = if g.p(0.8) { Doc::Seq(names.iter().map(|s| Doc::Str(s.clone())).collect()) } else { joint_names() };
        let trajectory = g.map(vec![("joint_names", jn.clone()), ("t", Doc::Seq(t)), ("q", q), ("qd", qd)]);
        let robot = g.map(vec![("name", g.string(&["polycrank"])), ("hash", g.string(&[robot_hash.as_str(), "0"]))]);
        let path = g.seq(0, 5, |g| g.nums(n, -3.0, 3.0));
        let span = g.map(vec![
            ("from_s", g.num(0.0, 1.0)),
            ("to_s", g.num(0.0, 1.0)),
            ("end_effectors", g.seq(2, 3, |g| g.string(&["left", "right"]))),
            ("tolerance_m", g.num(0.0, 0.01)),
            ("tolerance_rad", g.num(0.0, 0.01)),
        ]);
        let stats = g.random_doc(&["planner", "planning_ms", "elapsed"], 2);
        g.some(
            0.1,
            vec![
                ("agent", g.string(&["polycrank", "polycrank", "other"])),
                ("robot", robot),
                ("joint_names", jn),
                ("path", path),
                ("trajectory", trajectory),
                ("stats", stats),
            ],
            vec![("closed_chain", Doc::Seq(vec![span]))],
        )
    });
    let scenario = g.map(vec![
        ("name", g.string(&["polycrank-transfer", "polycrank-transfer", "x"])),
        ("hash", g.string(&[fx.scenario.hash.as_str(), "0"])),
    ]);
    let together = g.seq(0, 2, |g| g.seq(0, 3, |g| g.string(&["polycrank", "x"])));
    g.some(
        0.3,
        vec![
            ("format", g.string(&["embodied-plan/1", "embodied-plan/1", "embodied-plan/0"])),
            ("scenario", scenario),
            ("plans", plans),
        ],
        vec![("generator", g.string(&["embodied"])), ("together", together)],
    )
}

fn trajectory_doc(g: &G) -> Doc {
    if g.p(0.1) {
        return g.random_doc(&["joint_names", "points", "positions", "velocities", "time_from_start", "sec"], 5);
    }
    let n = g.int(1, 4);
    let names = Doc::Seq(g.distinct(&JOINTS[..3 + usize::from(g.p(0.1))], n).into_iter().map(Doc::Str).collect());
    let count = g.int(0, 30);
    let points = Doc::Seq(
        (0..count)
            .map(|k| {
                let t = 0.3 * k as f64;
                let time = match g.below(3) {
                    0 => g.num(t, t + 0.2),
                    // The same times as seconds and nanoseconds (ROS 2 and ROS 1 spellings).
                    1 => g.map(vec![
                        ("sec", g.integer((3 * k / 10) as i64, (3 * k / 10) as i64 + 1)),
                        (
                            "nanosec",
                            g.integer(
                                ((3 * k) % 10) as i64 * 100_000_000,
                                ((3 * k) % 10) as i64 * 100_000_000 + 50_000_000,
                            ),
                        ),
                    ]),
                    _ => g.map(vec![
                        ("secs", g.integer((3 * k / 10) as i64, (3 * k / 10) as i64 + 1)),
                        (
                            "nsecs",
                            g.integer(
                                ((3 * k) % 10) as i64 * 100_000_000,
                                ((3 * k) % 10) as i64 * 100_000_000 + 50_000_000,
                            ),
                        ),
                    ]),
                };
                g.some(
                    0.5,
                    vec![("positions", g.nums(n, -3.0, 3.0)), ("time_from_start", time)],
                    vec![
                        ("velocities", g.nums(n, -2.0, 2.0)),
                        ("accelerations", g.nums(n, -2.0, 2.0)),
                        ("effort", g.nums(n, -1.0, 1.0)),
                    ],
                )
            })
            .collect(),
    );
    let header = g.map(vec![("frame_id", g.string(&["world"]))]);
    let body = g.some(0.3, vec![("joint_names", names), ("points", points)], vec![("header", header)]);
    if g.p(0.2) { g.map(vec![("trajectory", body)]) } else { body }
}

const EVENT_KINDS: [&str; 14] = [
    "plan_requested",
    "plan_landed",
    "plan_late",
    "plan_rejected",
    "halt_started",
    "halt_finished",
    "goal_reached",
    "grasp",
    "release",
    "world_changed",
    "sensor_non_finite",
    "note",
    "replan",
    "nonsense",
];

fn log_text(g: &G, fx: &Fixture) -> String {
    let spec = &fx.scenario.agents[0];
    let agent = spec.name.as_str();
    let names: Vec<String> = spec.robot.joint_names();
    let n = g.len(names.len());
    let logged = crate::log::LoggedAgent::of(&spec.robot);
    let limits = Doc::Seq(
        logged
            .limits
            .iter()
            .map(|l| {
                let side = |v: Option<f64>| v.map_or(Doc::Null, Doc::Num);
                g.map(vec![
                    ("lower", if g.junky() { g.num(-3.0, 0.0) } else { side(l.lower) }),
                    ("upper", if g.junky() { g.num(0.0, 3.0) } else { side(l.upper) }),
                    ("max_velocity", if g.junky() { g.num(0.0, 3.0) } else { Doc::Num(l.max_velocity) }),
                    ("max_acceleration", if g.junky() { g.num(0.0, 3.0) } else { Doc::Num(l.max_acceleration) }),
                ])
            })
            .collect(),
    );
    let name_pool: Vec<&str> = names.iter().map(String::as_str).collect();
    let names = if g.p(0.9) {
        Doc::Seq(names.iter().map(|s| Doc::Str(s.clone())).collect())
    } else {
        Doc::Seq(g.distinct(&name_pool, n).into_iter().map(Doc::Str).collect())
    };
    let logged = g.map(vec![("joint_names", names), ("limits", limits)]);
    let agents = g.map(vec![(agent, logged)]);
    let closed_chain = if g.p(0.1) {
        g.map(vec![
            ("agent", g.string(&[agent])),
            ("end_effectors", g.seq(2, 3, |g| g.string(&["left", "right"]))),
            ("tolerance_m", g.num(0.0, 0.01)),
            ("tolerance_rad", g.num(0.0, 0.01)),
        ])
    } else {
        Doc::Null
    };
    let header = g.some(
        0.8,
        vec![
            ("scenario", g.string(&[if g.p(0.05) { "other" } else { "polycrank-transfer" }])),
            ("step_s", g.num(0.001, 0.001)),
            ("agents", agents),
        ],
        vec![
            ("format", g.string(&["embodied-log/2", "embodied-log/1"])),
            ("generator", g.string(&["embodied"])),
            ("scenario_hash", g.string(&["0"])),
            ("seed", g.integer(0, 10)),
            ("duration_s", g.num(0.0, 1.0)),
            ("planning_clock", g.string(&["simulated", "wall"])),
            ("closed_chain", closed_chain),
        ],
    );
    let mut lines = vec![to_json(&g.map(vec![("header", header)]), g)];
    let mut q: Vec<f64> = spec.start.clone();
    for step in 1..=g.int(0, 30) {
        for v in &mut q {
            *v += g.f(-0.0005, 0.0005);
        }
        let events = g.seq(0, 2, |g| {
            g.some(
                0.5,
                vec![("kind", g.string(&EVENT_KINDS))],
                vec![
                    ("id", g.integer(0, 5)),
                    ("world", g.integer(0, 3)),
                    ("in_time", g.boolean()),
                    ("reason", g.string(&["late", "blocked"])),
                    ("speed", g.num(0.0, 2.0)),
                    ("text", g.string(&["x"])),
                ],
            )
        });
        let qs = Doc::Seq(q.iter().take(n).map(|v| if g.junky() { g.junk_value(1) } else { Doc::Num(*v) }).collect());
        let a = g.some(
            0.9,
            vec![
                ("q", qs),
                ("qd", g.nums(n, -0.1, 0.1)),
                ("behaviour", g.string(&["follow_plan"])),
                ("events", events),
            ],
            vec![],
        );
        let clearance = g.map(vec![("robot_environment_m", g.num(-0.1, 1.0))]);
        let step_line = g.some(
            0.5,
            vec![
                ("step", g.integer(step as i64, step as i64 + 1)),
                ("t", g.num(step as f64 * 0.001, step as f64 * 0.001 + 1e-9)),
                ("agents", g.map(vec![(agent, a)])),
            ],
            vec![("clearance", clearance)],
        );
        lines.push(to_json(&step_line, g));
    }
    if g.p(0.6) {
        let summary = g.random_doc(&["agents", "failure", "steps"], 2);
        lines.push(to_json(&g.map(vec![("summary", summary)]), g));
    }
    lines.join("\n") + "\n"
}
