//! Corpus: real, public robot descriptions (tests/fixtures/corpus, sources in its README) load
//! with their collision meshes, and their forward kinematics agrees with an independent
//! implementation (Pinocchio; `reference_fk.json`, made by `make_reference_fk.py`) to 1e-6 on
//! every link, at the zero configuration and three random ones.
//!
//! `cargo test -p embodied-models --test corpus -- --nocapture` prints the table: DOF, load
//! time, largest position and rotation disagreement.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use embodied_models::formats::{Description, load_description};
use embodied_models::nalgebra::{Quaternion, UnitQuaternion, Vector3};
use embodied_models::urdf::UrdfOptions;

fn corpus(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/corpus").join(rel)
}

/// `(key in reference_fk.json, SRDF)` of each description.
const ROBOTS: [(&str, Option<&str>); 5] = [
    ("ur5", None),
    ("pr2", Some("example-robot-data/robots/pr2_description/srdf/pr2.srdf")),
    ("baxter", Some("example-robot-data/robots/baxter_description/srdf/baxter_manipulation.srdf")),
    ("simple_humanoid", Some("example-robot-data/robots/simple_humanoid_description/srdf/simple_humanoid.srdf")),
    ("panda", None),
];

fn reference() -> serde_json::Value {
    let text = std::fs::read_to_string(corpus("reference_fk.json")).expect("reference_fk.json readable");
    serde_json::from_str(&text).expect("reference_fk.json is JSON")
}

fn load(key: &str, srdf: Option<&str>, reference: &serde_json::Value) -> (Description, f64) {
    let urdf = corpus(reference[key]["urdf"].as_str().expect("urdf path"));
    let srdf = srdf.map(corpus);
    let options = UrdfOptions { use_environment: false, ..UrdfOptions::default() };
    let start = Instant::now();
    let d = load_description(&urdf, srdf.as_deref(), &options).unwrap_or_else(|e| panic!("{key} does not load: {e}"));
    (d, start.elapsed().as_secs_f64() * 1e3)
}

#[test]
fn every_description_loads_and_agrees_with_pinocchio() {
    let reference = reference();
    let mut rows = Vec::new();
    for (key, srdf) in ROBOTS {
        let (d, ms) = load(key, srdf, &reference);
        let robot = &d.robot;
        let shapes: usize = robot.links().iter().map(|l| l.shapes.len()).sum();
        assert!(shapes > 0, "{key}: no collision shapes loaded");
        let (mut worst_pos, mut worst_rot, mut compared) = (0.0f64, 0.0f64, 0usize);
        for sample in reference[key]["samples"].as_array().expect("samples") {
            let values: HashMap<&str, f64> = sample["joints"]
                .as_object()
                .expect("joints")
                .iter()
                .map(|(k, v)| (k.as_str(), v.as_f64().expect("number")))
                .collect();
            let q: Vec<f64> = robot
                .joint_names()
                .iter()
                .map(|n| *values.get(n.as_str()).unwrap_or_else(|| panic!("{key}: reference lacks joint {n}")))
                .collect();
            let poses = robot.forward_kinematics(&q);
            for (link, pose) in sample["links"].as_object().expect("links") {
                let v: Vec<f64> = pose.as_array().expect("pose").iter().map(|x| x.as_f64().expect("number")).collect();
                let li = robot.link_index(link).unwrap_or_else(|| panic!("{key}: no link {link}"));
                let ours = robot.base() * poses[li];
                let p = Vector3::new(v[0], v[1], v[2]);
                let r = UnitQuaternion::from_quaternion(Quaternion::new(v[6], v[3], v[4], v[5]));
                worst_pos = worst_pos.max((ours.translation.vector - p).norm());
                worst_rot = worst_rot.max(ours.rotation.angle_to(&r));
                compared += 1;
            }
        }
        assert!(compared > 0, "{key}: nothing compared");
        assert!(
            worst_pos < 1e-6 && worst_rot < 1e-6,
            "{key}: FK disagrees with Pinocchio by {worst_pos:.2e} m / {worst_rot:.2e} rad"
        );
        rows.push(format!(
            "{key:16} loads  dof {:3}  links {:3}  shapes {:4}  load {ms:8.1} ms  FK max |dp| {worst_pos:.1e} m  |dR| {worst_rot:.1e} rad over {compared} link poses  warnings {}",
            robot.dof(),
            robot.links().len(),
            shapes,
            d.warnings.len()
        ));
    }
    for r in rows {
        eprintln!("{r}");
    }
}

#[test]
fn moveit_srdfs_read_passive_joints_group_states_and_virtual_joints() {
    let reference = reference();
    let (pr2, _) = load("pr2", ROBOTS[1].1, &reference);
    let srdf = pr2.srdf.as_ref().expect("pr2 srdf");
    assert!(!srdf.passive_joints.is_empty(), "PR2's SRDF has passive joints");
    assert!(!srdf.virtual_joints.is_empty(), "PR2's SRDF has a virtual joint");
    assert!(!srdf.group_states.is_empty(), "PR2's SRDF has group states");
    // Every group resolves to joints of the URDF, and no passive joint is planned.
    for g in &srdf.groups {
        let joints = srdf.group_joints(&pr2.robot, &g.name).unwrap_or_else(|e| panic!("group {}: {e}", g.name));
        assert!(joints.iter().all(|j| !srdf.passive_joints.contains(j)), "group {} plans a passive joint", g.name);
    }
    // Baxter's and the humanoid's groups resolve too.
    for i in [2, 3] {
        let (d, _) = load(ROBOTS[i].0, ROBOTS[i].1, &reference);
        let srdf = d.srdf.as_ref().expect("srdf");
        for g in &srdf.groups {
            srdf.group_joints(&d.robot, &g.name).unwrap_or_else(|e| panic!("{} group {}: {e}", ROBOTS[i].0, g.name));
        }
    }
}

#[test]
fn decomposition_rule_on_the_corpus() {
    // How many meshes the rule splits and what it costs: one load with the rule, one without.
    let reference = reference();
    for (key, srdf) in ROBOTS {
        let urdf = corpus(reference[key]["urdf"].as_str().expect("urdf path"));
        let srdf = srdf.map(corpus);
        let mut row = format!("{key:16}");
        let mut counts = Vec::new();
        for decomposition in [None, Some(embodied_models::formats::mesh::Decomposition::default())] {
            let options = UrdfOptions { use_environment: false, decomposition, ..UrdfOptions::default() };
            let start = Instant::now();
            let d = load_description(&urdf, srdf.as_deref(), &options).expect("loads");
            let ms = start.elapsed().as_secs_f64() * 1e3;
            let shapes: usize = d.robot.links().iter().map(|l| l.shapes.len()).sum();
            counts.push(shapes);
            row.push_str(&format!(
                "  {} shapes {shapes:4} in {ms:7.1} ms",
                if decomposition.is_some() { "rule:" } else { "hulls:" }
            ));
        }
        assert!(counts[1] >= counts[0], "{key}: decomposition never removes shapes");
        eprintln!("{row}");
    }
}
