//! End-to-end: `plan --urdf --srdf --scene --request --format joint-trajectory`, then `verify
//! --trajectory`; the same trajectory with its corner cut is refused; `--package-path`.

mod common;

use std::path::{Path, PathBuf};

use common::{TempDir, embodied};
use embodied_models::urdf::load_urdf;

fn corpus(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/corpus").join(rel)
}

const UR5: &str = "example-robot-data/robots/ur_description/urdf/ur5_robot.urdf";
const NAMES: [&str; 6] =
    ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"];
const START: [f64; 6] = [-1.4, -1.2, 1.2, -1.57, -1.57, 0.0];
const GOAL: [f64; 6] = [1.4, -1.2, 1.2, -1.57, -1.57, 0.0];

/// SRDF, scene (a box where the wrist passes at pan = 0) and request for the corpus UR5.
fn write_problem(dir: &Path) -> (PathBuf, PathBuf, PathBuf) {
    let srdf = dir.join("ur5.srdf");
    std::fs::write(
        &srdf,
        "<robot name=\"ur5\"><group name=\"manipulator\"><chain base_link=\"base_link\" tip_link=\"ee_link\"/></group></robot>",
    )
    .expect("srdf");
    let robot = load_urdf(&corpus(UR5), None).expect("UR5 loads");
    let mid = [0.0, START[1], START[2], START[3], START[4], START[5]];
    let p = (robot.base() * robot.forward_kinematics(&mid)[robot.link_index("wrist_1_link").expect("link")])
        .translation
        .vector;
    let scene = dir.join("scene.yaml");
    std::fs::write(
        &scene,
        format!(
            "world:\n  collision_objects:\n    - id: post\n      primitives:\n        - type: box\n          dimensions: [0.12, 0.12, 0.12]\n      primitive_poses:\n        - position: [{}, {}, {}]\n          orientation: [0, 0, 0, 1]\n",
            p.x, p.y, p.z
        ),
    )
    .expect("scene");
    let list = |v: &[f64]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>().join(", ");
    let mut req = format!(
        "group_name: manipulator\nallowed_planning_time: 10\nstart_state:\n  joint_state:\n    name: [{}]\n    position: [{}]\ngoal_constraints:\n  - joint_constraints:\n",
        NAMES.join(", "),
        list(&START)
    );
    for (n, v) in NAMES.iter().zip(GOAL) {
        req.push_str(&format!("      - joint_name: {n}\n        position: {v}\n"));
    }
    let request = dir.join("request.yaml");
    std::fs::write(&request, req).expect("request");
    (srdf, scene, request)
}

#[test]
fn planned_joint_trajectory_verifies_and_a_cut_corner_is_refused() {
    let dir = TempDir::new("moveit");
    let (srdf, scene, request) = write_problem(&dir);
    let urdf = corpus(UR5);
    let s = |p: &Path| p.to_str().expect("utf-8 path").to_string();
    for ext in ["yaml", "json"] {
        let out = dir.join(format!("traj.{ext}"));
        let (code, stdout, stderr) = embodied(&[
            "plan",
            "--urdf",
            &s(&urdf),
            "--srdf",
            &s(&srdf),
            "--scene",
            &s(&scene),
            "--request",
            &s(&request),
            "--format",
            "joint-trajectory",
            "-o",
            &s(&out),
        ]);
        assert_eq!(code, 0, "plan failed: {stdout}{stderr}");
        let text = std::fs::read_to_string(&out).expect("written");
        assert!(text.contains("joint_names") && text.contains("time_from_start"), "{text}");
        if ext == "json" {
            serde_json::from_str::<serde_json::Value>(&text).expect("a .json file holds JSON");
        }
        let verify = |traj: &Path| {
            embodied(&[
                "verify",
                "--urdf",
                &s(&urdf),
                "--srdf",
                &s(&srdf),
                "--scene",
                &s(&scene),
                "--trajectory",
                &s(traj),
            ])
        };
        let (code, stdout, stderr) = verify(&out);
        assert_eq!(code, 0, "not certified: {stdout}{stderr}");
        assert!(stdout.contains("certified: yes"), "{stdout}");
        // Cut the corner: keep the first and last point only.
        let jt = embodied_models::formats::trajectory::parse_joint_trajectory(&text, &out).expect("reads back");
        let mut cut = jt.clone();
        cut.points = vec![jt.points[0].clone(), jt.points[jt.points.len() - 1].clone()];
        let cut_file = dir.join(format!("cut.{ext}"));
        std::fs::write(&cut_file, cut.to_text_for(&cut_file)).expect("written");
        let (code, stdout, _) = verify(&cut_file);
        assert_eq!(code, 1, "{stdout}");
        assert!(stdout.contains("collide") && stdout.contains("post") && stdout.contains("t = "), "{stdout}");
    }
}

#[test]
fn package_path_finds_meshes_of_a_urdf_moved_away_from_its_package() {
    let dir = TempDir::new("pkg");
    let urdf = dir.join("ur5.urdf");
    std::fs::copy(corpus(UR5), &urdf).expect("copied");
    let s = |p: &Path| p.to_str().expect("utf-8 path").to_string();
    let (code, _, stderr) = embodied(&["model", &s(&urdf)]);
    assert_eq!(code, 2);
    assert!(stderr.contains("collision mesh file not found") && stderr.contains("tried:"), "{stderr}");
    let (code, stdout, stderr) = embodied(&["model", &s(&urdf), "--package-path", &s(&corpus(""))]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("shoulder_pan_joint"), "{stdout}");
    let (code, _, stderr) = embodied(&["model", &s(&urdf), "--allow-missing-meshes"]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stderr.contains("warning") && stderr.contains("shape dropped"), "{stderr}");
}
