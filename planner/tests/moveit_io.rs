//! MoveIt in and out: a request planned in a scene comes out as a JointTrajectory that the
//! certified checker certifies after a round trip through YAML and JSON; the same trajectory
//! with its corner cut (two waypoints straight through the obstacle) is refused with the time
//! and the colliding pair.

use std::path::{Path, PathBuf};
use std::time::Duration;

use embodied_models::Robot;
use embodied_models::srdf::{Srdf, load_srdf};
use embodied_models::urdf::load_urdf;
use embodied_planner::deadline::Deadline;
use embodied_planner::motion::MotionSettings;
use embodied_planner::moveit::{
    JointTrajectory, moveit_problem, parse_joint_trajectory, parse_request, parse_scene, plan_request,
    to_joint_trajectory, trajectory_problem,
};
use embodied_planner::verify::{Finding, Verifier};

fn ur5() -> (Robot, Srdf) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/tests/fixtures");
    let srdf: PathBuf = dir.join("ur5.srdf");
    let mut robot = load_urdf(&dir.join("ur5_spherized.urdf"), Some(&srdf)).expect("UR5 loads");
    // The spherized model's wrist_2_link and fts_robotside overlap everywhere (the SRDF was
    // written for the mesh model): disabled as `bench mbm` does.
    embodied_models::collision::disable_always_colliding(&mut robot, 2000, 0x5eed);
    (robot, load_srdf(&srdf).expect("SRDF"))
}

const START: [f64; 6] = [-1.4, -1.2, 1.2, -1.57, -1.57, 0.0];
const GOAL: [f64; 6] = [1.4, -1.2, 1.2, -1.57, -1.57, 0.0];

/// A 12 cm box where the wrist is when the base has turned half way (pan = 0): the straight
/// motion from START to GOAL sweeps through it, START and GOAL are far from it.
fn scene_text(robot: &Robot) -> String {
    let mid = [0.0, START[1], START[2], START[3], START[4], START[5]];
    let link = robot.link_index("wrist_1_link").expect("wrist_1_link");
    let p = (robot.base() * robot.forward_kinematics(&mid)[link]).translation.vector;
    format!(
        "name: graze\nworld:\n  collision_objects:\n    - id: post\n      header: {{frame_id: world}}\n      primitives:\n        - type: box\n          dimensions: [0.12, 0.12, 0.12]\n      primitive_poses:\n        - position: [{}, {}, {}]\n          orientation: [0, 0, 0, 1]\n",
        p.x, p.y, p.z
    )
}

fn request_text() -> String {
    let names =
        ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"];
    let mut s = format!(
        "group_name: manipulator\nallowed_planning_time: 5\nstart_state:\n  joint_state:\n    name: [{}]\n    position: [{}]\ngoal_constraints:\n  - joint_constraints:\n",
        names.join(", "),
        START.iter().map(|v| v.to_string()).collect::<Vec<_>>().join(", ")
    );
    for (n, v) in names.iter().zip(GOAL) {
        s.push_str(&format!("      - joint_name: {n}\n        position: {v}\n"));
    }
    s
}

fn certify(robot: &Robot, scene_yaml: &str, jt: &JointTrajectory) -> embodied_planner::verify::TrajectoryReport {
    let scene = parse_scene(scene_yaml, Path::new("scene.yaml")).expect("scene");
    let problem =
        trajectory_problem(robot, scene.robot_state.as_ref(), scene.environment(), jt, Path::new("traj.yaml"))
            .expect("trajectory fits the robot");
    Verifier::default().check_trajectory(&problem.model, &problem.trajectory, &[])
}

#[test]
fn planned_request_round_trips_as_joint_trajectory_and_a_cut_corner_is_refused() {
    let (robot, srdf) = ur5();
    let scene_yaml = scene_text(&robot);
    let scene = parse_scene(&scene_yaml, Path::new("scene.yaml")).expect("scene");
    let request = parse_request(&request_text(), Path::new("request.yaml")).expect("request");
    let problem = moveit_problem(&robot, &srdf, &scene, &request).expect("problem");
    assert!(problem.model.first_collision(&START).is_none(), "{:?}", problem.model.first_collision(&START));
    assert!(problem.model.first_collision(&GOAL).is_none());
    let settings = MotionSettings { deadline: Deadline::after(Duration::from_secs(20)), ..MotionSettings::default() };
    let plan = plan_request(&problem, &settings).expect("planned");
    let jt = to_joint_trajectory(&plan.trajectory);
    assert_eq!(jt.joint_names, problem.resolved.joint_names);

    // Through YAML and JSON, as `plan --format joint-trajectory` writes it.
    let yaml = parse_joint_trajectory(&jt.to_yaml(), Path::new("t.yaml")).expect("yaml reads back");
    let json = parse_joint_trajectory(&jt.to_json(), Path::new("t.json")).expect("json reads back");
    assert_eq!(json, yaml);
    let report = certify(&robot, &scene_yaml, &yaml);
    assert!(report.certified, "planned trajectory not certified: {:?}", report.findings());

    // Cut the corner: first and last point only, straight through the post.
    let mut cut = yaml.clone();
    let last = cut.points.len() - 1;
    cut.points = vec![cut.points[0].clone(), cut.points[last].clone()];
    let report = certify(&robot, &scene_yaml, &cut);
    assert!(!report.certified);
    let Some(Finding::Collision { t, a, b, .. }) = &report.collision.violation else {
        panic!("expected a collision, got {:?}", report.findings())
    };
    assert!(*t > 0.0 && *t < cut.points[1].time_from_start, "collision at t = {t}");
    assert!(a.contains("post") || b.contains("post"), "pair {a} / {b}");
}

#[test]
fn a_moveit_style_trajectory_grazing_the_obstacle_between_waypoints_is_caught() {
    // Waypoints every 0.7 rad of base rotation, none of them touching the post: the post lies
    // between two of them (pan = 0 is not a waypoint).
    let (robot, _) = ur5();
    let scene_yaml = scene_text(&robot);
    let scene = parse_scene(&scene_yaml, Path::new("scene.yaml")).expect("scene");
    let pans = [-1.4, -0.7, 0.35, 1.05, 1.4];
    let mut text = String::from(
        "joint_names: [shoulder_pan_joint, shoulder_lift_joint, elbow_joint, wrist_1_joint, wrist_2_joint, wrist_3_joint]\npoints:\n",
    );
    for (k, pan) in pans.iter().enumerate() {
        text.push_str(&format!(
            "  - positions: [{pan}, {}, {}, {}, {}, {}]\n    time_from_start: {{sec: {}, nanosec: 0}}\n",
            START[1],
            START[2],
            START[3],
            START[4],
            START[5],
            2 * k
        ));
    }
    let jt = parse_joint_trajectory(&text, Path::new("moveit.yaml")).expect("parses");
    let problem = trajectory_problem(&robot, None, scene.environment(), &jt, Path::new("moveit.yaml")).expect("fits");
    for q in &problem.trajectory.q {
        assert!(problem.model.first_collision(q).is_none(), "waypoint {q:?} itself collides");
    }
    let report = Verifier::default().check_trajectory(&problem.model, &problem.trajectory, &[]);
    let Some(Finding::Collision { t, .. }) = &report.collision.violation else {
        panic!("the graze between waypoints was not caught: {:?}", report.findings())
    };
    assert!(*t > 2.0 && *t < 4.0, "the collision lies between the 2nd and 3rd waypoints, got t = {t}");
}
