//! `bench mbm` on a robot other than the UR5: MotionBenchMaker-style families written here for
//! the Franka Emika Panda of the corpus (OBJ collision meshes, two finger joints outside the
//! planning group), one with joint goals and one with hand-pose goals, planned and verified end
//! to end through the command line; and for the spherized Panda VAMP plans with
//! (`benches/peers/panda`: spheres only, seven joints, the fingers fixed).

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

const ARM: [&str; 7] =
    ["panda_joint1", "panda_joint2", "panda_joint3", "panda_joint4", "panda_joint5", "panda_joint6", "panda_joint7"];

/// The family's obstacles: a table top under the hand's reach and a post beside the robot,
/// as (name, full box size, centre).
const BOXES: [(&str, [f64; 3], [f64; 3]); 2] =
    [("table", [0.8, 1.2, 0.04], [0.65, 0.0, 0.2]), ("post", [0.1, 0.1, 0.6], [0.45, 0.0, 0.55])];

/// Write `count` problems (scene + request) of a family into `dir`: start and goal drawn at
/// random within the limits, collision-free among the boxes, the hand on either side of the
/// post (so most straight lines hit it).
fn write_family(urdf: &Path, dir: &Path, count: usize, pose_goals: bool) {
    std::fs::create_dir_all(dir).expect("family folder");
    let robot = load_urdf(urdf, None).expect("Panda loads");
    let mut env = Environment::new();
    for (name, size, at) in BOXES {
        env.add(Obstacle::new(
            name,
            Isometry3::translation(at[0], at[1], at[2]),
            Shape::cuboid(size[0] / 2.0, size[1] / 2.0, size[2] / 2.0),
        ));
    }
    let mut checked = robot.clone();
    embodied_models::collision::disable_always_colliding(&mut checked, 500, 0x5eed);
    let model = CollisionModel::new(&checked, env);
    let hand = robot.link_index("panda_hand").expect("panda_hand");
    let mut rng = Rng::new(42);
    let mut draw = |side: f64| loop {
        let q = robot.random_configuration(&mut rng);
        let p = robot.link_pose(&q, hand).translation.vector;
        if model.first_collision(&q).is_none() && p.y * side > 0.15 && p.x > 0.3 && p.z > 0.3 {
            return q;
        }
    };
    let mut scene = String::from("name: table_post\nworld:\n  collision_objects:\n");
    for (name, size, at) in BOXES {
        let _ = write!(
            scene,
            "    - id: {name}\n      header: {{frame_id: panda_link0}}\n      primitives:\n        - type: box\n          dimensions: {size:?}\n      primitive_poses:\n        - position: {at:?}\n          orientation: [0, 0, 0, 1]\n"
        );
    }
    let names = robot.joint_names();
    for k in 1..=count {
        let (start, goal) = (draw(1.0), draw(-1.0));
        std::fs::write(dir.join(format!("scene{k:04}.yaml")), &scene).expect("scene");
        let mut req = format!(
            "group_name: panda_arm\nallowed_planning_time: 5\nstart_state:\n  joint_state:\n    name: [{}]\n    position: {:?}\ngoal_constraints:\n  - joint_constraints:\n",
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
                "  - position_constraints:\n      - link_name: panda_hand\n        header: {{frame_id: panda_link0}}\n        constraint_region:\n          primitives: [{{type: sphere, dimensions: [0.005]}}]\n          primitive_poses: [{{position: [{}, {}, {}]}}]\n    orientation_constraints:\n      - link_name: panda_hand\n        orientation: [{}, {}, {}, {}]\n        absolute_x_axis_tolerance: 0.02\n        absolute_y_axis_tolerance: 0.02\n        absolute_z_axis_tolerance: 0.02\n",
                t.x, t.y, t.z, q.x, q.y, q.z, q.w
            );
        } else {
            for j in ARM {
                let d = names.iter().position(|n| n == j).expect("arm joint");
                let _ = writeln!(req, "      - {{joint_name: {j}, position: {}}}", goal[d]);
            }
        }
        std::fs::write(dir.join(format!("request{k:04}.yaml")), req).expect("request");
    }
}

/// Write a joint-goal family of `joint_goals` problems and a pose-goal family of `pose_goals`
/// for `urdf`, plan both with `bench mbm`, and check that every problem is solved and its path
/// re-checked, in the group's seven joints, and that each family counts all its problems.
fn plans_and_verifies(urdf: &Path, srdf: &Path, dir: &TempDir, joint_goals: usize, pose_goals: usize) {
    let problems = dir.join("problems");
    write_family(urdf, &problems.join("table_post_panda"), joint_goals, false);
    write_family(urdf, &problems.join("table_post_pose_panda"), pose_goals, true);
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
        assert_eq!(p["joint_names"].as_array().map(Vec::len), Some(7), "the group's seven joints: {p}");
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
    plans_and_verifies(&panda_urdf(), &srdf, &dir, 6, 3);
}

/// The spherized Panda of the VAMP comparison (spheres only, the fingers fixed) plans through
/// the same command, with its own SRDF.
#[test]
fn bench_mbm_plans_and_verifies_the_spherized_panda() {
    let dir = TempDir::new("mbm-panda-spheres");
    let (urdf, srdf) = spherized_panda();
    plans_and_verifies(&urdf, &srdf, &dir, 8, 3);
}
