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

/// `embodied plan` of a MoveIt problem (the corpus UR5), with `extra` arguments.
fn plan_moveit(srdf: &Path, scene: &Path, request: &Path, extra: &[&str]) -> (i32, String, String) {
    let s = |p: &Path| p.to_str().expect("utf-8 path").to_string();
    let (urdf, srdf, scene, request) = (s(&corpus(UR5)), s(srdf), s(scene), s(request));
    let mut args = vec!["plan", "--urdf", &urdf, "--srdf", &srdf, "--scene", &scene, "--request", &request];
    args.extend_from_slice(extra);
    embodied(&args)
}

#[test]
fn planned_joint_trajectory_verifies_and_a_cut_corner_is_refused() {
    let dir = TempDir::new("moveit");
    let (srdf, scene, request) = write_problem(&dir);
    let urdf = corpus(UR5);
    let s = |p: &Path| p.to_str().expect("utf-8 path").to_string();
    for ext in ["yaml", "json"] {
        let out = dir.join(format!("traj.{ext}"));
        let (code, stdout, stderr) =
            plan_moveit(&srdf, &scene, &request, &["--format", "joint-trajectory", "-o", &s(&out)]);
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

/// A `MotionPlanRequest` whose goal is the pose of `ee_link` at [`GOAL`] (a 2 mm sphere and
/// 0.01 rad about each axis), the start as in [`write_problem`].
fn write_pose_request(dir: &Path) -> (PathBuf, embodied_models::nalgebra::Isometry3<f64>) {
    let robot = load_urdf(&corpus(UR5), None).expect("UR5 loads");
    let wanted = robot.link_pose(&GOAL, robot.link_index("ee_link").expect("ee_link"));
    let (t, q) = (wanted.translation.vector, wanted.rotation.coords);
    let list = |v: &[f64]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>().join(", ");
    let req = format!(
        "group_name: manipulator\nallowed_planning_time: 10\nstart_state:\n  joint_state:\n    name: [{}]\n    position: [{}]\ngoal_constraints:\n  - position_constraints:\n      - link_name: ee_link\n        header: {{frame_id: base_link}}\n        constraint_region:\n          primitives: [{{type: sphere, dimensions: [0.002]}}]\n          primitive_poses: [{{position: {{x: {}, y: {}, z: {}}}}}]\n    orientation_constraints:\n      - link_name: ee_link\n        orientation: {{x: {}, y: {}, z: {}, w: {}}}\n        absolute_x_axis_tolerance: 0.01\n        absolute_y_axis_tolerance: 0.01\n        absolute_z_axis_tolerance: 0.01\n",
        NAMES.join(", "),
        list(&START),
        t.x,
        t.y,
        t.z,
        q.x,
        q.y,
        q.z,
        q.w
    );
    let request = dir.join("pose_request.yaml");
    std::fs::write(&request, req).expect("request");
    (request, wanted)
}

#[test]
fn a_pose_goal_is_planned_around_the_post_and_verifies() {
    let dir = TempDir::new("moveit-pose");
    let (srdf, scene, _) = write_problem(&dir);
    let (request, wanted) = write_pose_request(&dir);
    let urdf = corpus(UR5);
    let s = |p: &Path| p.to_str().expect("utf-8 path").to_string();
    let out = dir.join("traj.yaml");
    let (code, stdout, stderr) =
        plan_moveit(&srdf, &scene, &request, &["--format", "joint-trajectory", "-o", &s(&out)]);
    assert_eq!(code, 0, "plan failed: {stdout}{stderr}");
    let text = std::fs::read_to_string(&out).expect("written");
    let jt = embodied_models::formats::trajectory::parse_joint_trajectory(&text, &out).expect("reads back");
    // The last point, by forward kinematics of the robot as loaded here, is at the wanted pose.
    let robot = load_urdf(&corpus(UR5), None).expect("UR5 loads");
    let last = &jt.points[jt.points.len() - 1].positions;
    let mut q = robot.home().to_vec();
    for (name, v) in jt.joint_names.iter().zip(last) {
        let d = robot.joint_names().iter().position(|n| n == name).expect("a joint of the robot");
        q[d] = *v;
    }
    let reached = robot.link_pose(&q, robot.link_index("ee_link").expect("ee_link"));
    assert!((reached.translation.vector - wanted.translation.vector).norm() <= 0.002 + 1e-5);
    assert!(reached.rotation.angle_to(&wanted.rotation) <= 0.02);
    let (code, stdout, stderr) = embodied(&[
        "verify",
        "--urdf",
        &s(&urdf),
        "--srdf",
        &s(&srdf),
        "--scene",
        &s(&scene),
        "--trajectory",
        &s(&out),
    ]);
    assert_eq!(code, 0, "not certified: {stdout}{stderr}");
    // A pose out of reach is a planning failure (exit 1) that says why, not bad input.
    let far = std::fs::read_to_string(&request).expect("request").replacen("x: ", "x: 9", 1);
    let far_request = dir.join("far.yaml");
    std::fs::write(&far_request, far).expect("written");
    let (code, stdout, stderr) = plan_moveit(&srdf, &scene, &far_request, &[]);
    assert_eq!(code, 1, "{stdout}{stderr}");
    assert!(stderr.contains("goal"), "{stderr}");
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
