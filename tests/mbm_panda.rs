//! `bench mbm` on a robot other than the UR5: MotionBenchMaker-style families written here for
//! the Franka Emika Panda of the corpus (OBJ collision meshes, two finger joints outside the
//! planning group), one with joint goals and one with hand-pose goals, planned and verified end
//! to end through the command line; for the spherized Panda VAMP plans with
//! (`benches/peers/panda`: spheres only, seven joints, the fingers fixed); and for the spherized
//! Fetch VAMP plans with (`benches/peers/fetch`: 111 spheres, the group `arm_with_torso` of eight
//! joints, the first the prismatic torso lift).

mod common;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use common::{TempDir, embodied};
use embodied_models::collision::{Environment, Obstacle};
use embodied_models::nalgebra::Isometry3;
use embodied_models::urdf::load_urdf;
use embodied_models::{CollisionModel, Rng, Shape};

fn panda_urdf() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/corpus/pybullet_data/franka_panda/panda.urdf")
}

fn spherized_panda() -> (PathBuf, PathBuf) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/peers/panda");
    (dir.join("panda_spherized.urdf"), dir.join("panda.srdf"))
}

fn spherized_fetch() -> (PathBuf, PathBuf) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/peers/fetch");
    (dir.join("fetch_spherized.urdf"), dir.join("fetch.srdf"))
}

/// A robot's planning group and the family's scene for it.
struct Arm {
    group: &'static str,
    /// The group's joints.
    joints: &'static [&'static str],
    base: &'static str,
    hand: &'static str,
    /// The family's obstacles: a table top under the hand's reach and a post in front of the
    /// robot, as (name, full box size, centre).
    boxes: [(&'static str, [f64; 3], [f64; 3]); 2],
    /// The least forward reach and height of the hand at a start or goal (m).
    hand_x: f64,
    hand_z: f64,
}

const PANDA: Arm = Arm {
    group: "panda_arm",
    joints: &[
        "panda_joint1",
        "panda_joint2",
        "panda_joint3",
        "panda_joint4",
        "panda_joint5",
        "panda_joint6",
        "panda_joint7",
    ],
    base: "panda_link0",
    hand: "panda_hand",
    boxes: [("table", [0.8, 1.2, 0.04], [0.65, 0.0, 0.2]), ("post", [0.1, 0.1, 0.6], [0.45, 0.0, 0.55])],
    hand_x: 0.3,
    hand_z: 0.3,
};

const FETCH: Arm = Arm {
    group: "arm_with_torso",
    joints: &[
        "torso_lift_joint",
        "shoulder_pan_joint",
        "shoulder_lift_joint",
        "upperarm_roll_joint",
        "elbow_flex_joint",
        "forearm_roll_joint",
        "wrist_flex_joint",
        "wrist_roll_joint",
    ],
    base: "base_link",
    hand: "gripper_link",
    boxes: [("table", [0.6, 1.2, 0.04], [0.85, 0.0, 0.7]), ("post", [0.1, 0.1, 0.6], [0.65, 0.0, 1.02])],
    hand_x: 0.5,
    hand_z: 0.8,
};

/// Write `count` problems (scene + request) of a family into `dir`: start and goal drawn at
/// random within the limits, collision-free among the boxes, the hand on either side of the
/// post (so most straight lines hit it).
fn write_family(arm: &Arm, urdf: &Path, dir: &Path, count: usize, pose_goals: bool) {
    std::fs::create_dir_all(dir).expect("family folder");
    let robot = load_urdf(urdf, None).expect("the robot loads");
    let mut env = Environment::new();
    for (name, size, at) in arm.boxes {
        env.add(Obstacle::new(
            name,
            Isometry3::translation(at[0], at[1], at[2]),
            Shape::cuboid(size[0] / 2.0, size[1] / 2.0, size[2] / 2.0),
        ));
    }
    let mut checked = robot.clone();
    embodied_models::collision::disable_always_colliding(&mut checked, 500, 0x5eed);
    let model = CollisionModel::new(&checked, env);
    let hand = robot.link_index(arm.hand).expect("the hand link");
    let mut rng = Rng::new(42);
    let mut draw = |side: f64| loop {
        let q = robot.random_configuration(&mut rng);
        let p = robot.link_pose(&q, hand).translation.vector;
        if model.first_collision(&q).is_none() && p.y * side > 0.15 && p.x > arm.hand_x && p.z > arm.hand_z {
            return q;
        }
    };
    let mut scene = String::from("name: table_post\nworld:\n  collision_objects:\n");
    for (name, size, at) in arm.boxes {
        let _ = write!(
            scene,
            "    - id: {name}\n      header: {{frame_id: {}}}\n      primitives:\n        - type: box\n          dimensions: {size:?}\n      primitive_poses:\n        - position: {at:?}\n          orientation: [0, 0, 0, 1]\n",
            arm.base
        );
    }
    let names = robot.joint_names();
    for k in 1..=count {
        let (start, goal) = (draw(1.0), draw(-1.0));
        std::fs::write(dir.join(format!("scene{k:04}.yaml")), &scene).expect("scene");
        let mut req = format!(
            "group_name: {}\nallowed_planning_time: 5\nstart_state:\n  joint_state:\n    name: [{}]\n    position: {:?}\ngoal_constraints:\n  - joint_constraints:\n",
            arm.group,
            names.join(", "),
            start
        );
        if pose_goals {
            // The hand's pose at the drawn goal: a 5 mm sphere and 0.02 rad about each axis.
            let pose = robot.link_pose(&goal, hand);
            let (t, q) = (pose.translation.vector, pose.rotation.coords);
            req = req.replace("  - joint_constraints:\n", "");
            let _ = write!(
                req,
                "  - position_constraints:\n      - link_name: {hand}\n        header: {{frame_id: {base}}}\n        constraint_region:\n          primitives: [{{type: sphere, dimensions: [0.005]}}]\n          primitive_poses: [{{position: [{}, {}, {}]}}]\n    orientation_constraints:\n      - link_name: {hand}\n        orientation: [{}, {}, {}, {}]\n        absolute_x_axis_tolerance: 0.02\n        absolute_y_axis_tolerance: 0.02\n        absolute_z_axis_tolerance: 0.02\n",
                t.x,
                t.y,
                t.z,
                q.x,
                q.y,
                q.z,
                q.w,
                hand = arm.hand,
                base = arm.base
            );
        } else {
            for j in arm.joints {
                let d = names.iter().position(|n| n == j).expect("arm joint");
                let _ = writeln!(req, "      - {{joint_name: {j}, position: {}}}", goal[d]);
            }
        }
        std::fs::write(dir.join(format!("request{k:04}.yaml")), req).expect("request");
    }
}

/// Write a joint-goal family of `joint_goals` problems and a pose-goal family of `pose_goals`
/// for `urdf`, plan both with `bench mbm`, and check that every problem is solved and its path
/// re-checked, in the group's joints, and that each family counts all its problems.
fn plans_and_verifies(arm: &Arm, urdf: &Path, srdf: &Path, dir: &TempDir, joint_goals: usize, pose_goals: usize) {
    let problems = dir.join("problems");
    write_family(arm, urdf, &problems.join("table_post"), joint_goals, false);
    write_family(arm, urdf, &problems.join("table_post_pose"), pose_goals, true);
    let s = |p: &Path| p.to_str().expect("utf-8 path").to_string();
    let (code, stdout, stderr) = embodied(&[
        "bench",
        "mbm",
        "--urdf",
        &s(urdf),
        "--srdf",
        &s(srdf),
        "--problems",
        &s(&problems),
        "--deadline-ms",
        "5000",
        "--json",
    ]);
    assert_eq!(code, 0, "{stdout}{stderr}");
    let report: serde_json::Value = serde_json::from_str(&stdout).expect("JSON report");
    let problems = report["problems"].as_array().expect("problems");
    assert_eq!(problems.len(), joint_goals + pose_goals, "{report}");
    for p in problems {
        let names: Vec<&str> =
            p["joint_names"].as_array().expect("joint names").iter().filter_map(|n| n.as_str()).collect();
        assert_eq!(names, arm.joints, "the group's joints: {p}");
        assert_eq!(p["solved"], true, "{p}");
        assert_eq!(p["verified"], true, "{p}");
    }
    for (family, n) in [(&report["families"][0], joint_goals), (&report["families"][1], pose_goals)] {
        assert_eq!(
            (family["solved"].as_u64(), family["verification_failures"].as_u64()),
            (Some(n as u64), Some(0)),
            "{family}"
        );
    }
}

#[test]
fn bench_mbm_plans_and_verifies_a_panda_family() {
    let dir = TempDir::new("mbm-panda");
    let srdf = dir.join("panda.srdf");
    std::fs::write(
        &srdf,
        "<robot name=\"panda\"><group name=\"panda_arm\"><chain base_link=\"panda_link0\" tip_link=\"panda_link8\"/></group></robot>",
    )
    .expect("srdf");
    plans_and_verifies(&PANDA, &panda_urdf(), &srdf, &dir, 6, 3);
}

/// The spherized Panda of the VAMP comparison (spheres only, the fingers fixed) plans through
/// the same command, with its own SRDF.
#[test]
fn bench_mbm_plans_and_verifies_the_spherized_panda() {
    let dir = TempDir::new("mbm-panda-spheres");
    let (urdf, srdf) = spherized_panda();
    plans_and_verifies(&PANDA, &urdf, &srdf, &dir, 8, 3);
}

/// The spherized Fetch of the VAMP comparison: VAMP's URDF and SRDF as they are (meshes named
/// by the visuals only, disabled pairs naming links the URDF lacks), on the sphere fast path,
/// planning in `arm_with_torso` with its prismatic torso lift.
#[test]
fn bench_mbm_plans_and_verifies_the_spherized_fetch() {
    let dir = TempDir::new("mbm-fetch-spheres");
    let (urdf, srdf) = spherized_fetch();
    let robot = load_urdf(&urdf, Some(&srdf)).expect("the Fetch loads with its SRDF");
    assert!(CollisionModel::new(&robot, Environment::new()).uses_sphere_path(), "every Fetch shape a sphere");
    plans_and_verifies(&FETCH, &urdf, &srdf, &dir, 8, 3);
}
