//! MoveIt link-pose goals (`position_constraints`, `orientation_constraints`): parsed with their
//! places, resolved into the world frame, solved by inverse kinematics and planned to.

use std::f64::consts::FRAC_PI_2;
use std::path::{Path, PathBuf};
use std::time::Duration;

use embodied_models::Robot;
use embodied_models::nalgebra::{Isometry3, UnitQuaternion, Vector3};
use embodied_models::srdf::{Srdf, load_srdf};
use embodied_models::urdf::load_urdf;
use embodied_planner::PlanError;
use embodied_planner::deadline::Deadline;
use embodied_planner::motion::MotionSettings;
use embodied_planner::moveit::{
    MoveitError, ResolvedGoal, load_scene, moveit_problem, orientation_error, parse_request, parse_scene, plan_request,
};
use embodied_planner::verify::Verifier;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn ur5() -> (Robot, Srdf) {
    let dir = root().join("models/tests/fixtures");
    let srdf = dir.join("ur5.srdf");
    let mut robot = load_urdf(&dir.join("ur5_spherized.urdf"), Some(&srdf)).expect("UR5 fixture loads");
    // As `bench mbm` does: the spherized model's neighbouring spheres overlap in every
    // configuration, which the SRDF (written for the mesh model) does not disable.
    embodied_models::collision::disable_always_colliding(&mut robot, 200, 0x5eed);
    (robot, load_srdf(&srdf).expect("srdf"))
}

/// MotionBenchMaker's box problem 1 (tests/fixtures/mbm): its start and its joint goal.
#[allow(clippy::approx_constant)] // the file's own rounded values, not pi
const START: [f64; 6] = [1.57, -1.5707, 0.0, -1.5707, -1.57, 3.14];
const GOAL: [f64; 6] = [
    -0.5967475061264721,
    -0.7665678720674942,
    1.373208815745217,
    -2.184912337240673,
    -1.563569777871108,
    0.1145459363691259,
];

fn start_state() -> String {
    let names =
        ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"];
    format!("start_state:\n  joint_state:\n    name: [{}]\n    position: {:?}\n", names.join(", "), START)
}

/// A request whose goal is `link` at `pose` (sphere of `radius`, orientation within `tol` as
/// a rotation vector), with `extra` appended to the goal entry.
fn pose_request(link: &str, pose: &Isometry3<f64>, radius: f64, tol: f64, extra: &str) -> String {
    let t = pose.translation.vector;
    let q = pose.rotation.coords; // x, y, z, w
    format!(
        "group_name: manipulator\n{}goal_constraints:\n  - position_constraints:\n      - link_name: {link}\n        header: {{frame_id: world}}\n        target_point_offset: {{x: 0, y: 0, z: 0}}\n        constraint_region:\n          primitives:\n            - {{type: 2, dimensions: [{radius}]}}\n          primitive_poses:\n            - position: [{}, {}, {}]\n              orientation: [0, 0, 0, 1]\n    orientation_constraints:\n      - link_name: {link}\n        orientation: {{x: {}, y: {}, z: {}, w: {}}}\n        absolute_x_axis_tolerance: {tol}\n        absolute_y_axis_tolerance: {tol}\n        absolute_z_axis_tolerance: {tol}\n        parameterization: 1\n{extra}allowed_planning_time: 5\n",
        start_state(),
        t.x,
        t.y,
        t.z,
        q.x,
        q.y,
        q.z,
        q.w
    )
}

fn settings() -> MotionSettings {
    MotionSettings { deadline: Deadline::after(Duration::from_secs(10)), seed: 7, ..MotionSettings::default() }
}

#[test]
fn a_pose_goal_is_planned_to_a_configuration_that_meets_it() {
    let (robot, srdf) = ur5();
    let scene = load_scene(&root().join("tests/fixtures/mbm/problems/box_ur5/scene0001.yaml")).expect("scene");
    // The pose of ee_link at the problem's (collision-free) joint goal is the goal; IK may find
    // another configuration with the same pose.
    let ee = robot.link_index("ee_link").expect("ee_link");
    let wanted = robot.link_pose(&GOAL, ee);
    let text = pose_request("ee_link", &wanted, 0.002, 0.01, "");
    let request = parse_request(&text, Path::new("pose.yaml")).expect("pose request parses");
    let problem = moveit_problem(&robot, &srdf, &scene, &request).expect("problem");
    assert!(problem.resolved.goal.is_empty(), "no joint goal");
    assert!(matches!(problem.resolved.goals.as_slice(), [ResolvedGoal::Pose(_)]));
    let plan = plan_request(&problem, &settings()).expect("planned to the pose");
    let last = plan.path.last().expect("a path");
    // Checked here independently of the goal's own test: forward kinematics of the last
    // configuration against the wanted pose.
    let reached = problem.model.robot().link_pose(last, problem.model.robot().link_index("ee_link").expect("link"));
    let distance = (reached.translation.vector - wanted.translation.vector).norm();
    let angle = reached.rotation.angle_to(&wanted.rotation);
    assert!(distance <= 0.002 + 1e-5, "ends {distance} m from the wanted point");
    assert!(angle <= 0.01 * 3f64.sqrt() + 1e-5, "ends {angle} rad from the wanted orientation");
    let report = Verifier::default().check_trajectory(&problem.model, &plan.trajectory, &[]);
    assert!(report.certified, "{:?}", report.findings());
}

#[test]
fn joint_constraints_in_a_pose_goal_choose_among_the_solutions() {
    let (robot, srdf) = ur5();
    // No obstacles: the point is the choice among inverse-kinematics solutions.
    let scene = parse_scene("world: {collision_objects: []}\n", Path::new("empty.yaml")).expect("scene");
    let ee = robot.link_index("ee_link").expect("ee_link");
    let wanted = robot.link_pose(&GOAL, ee);
    // The UR5 reaches a pose with the elbow either way: the goal's elbow is bent one way
    // (+1.37 rad); a joint constraint allows only the other way.
    let extra = "    joint_constraints:\n      - {joint_name: elbow_joint, position: -1.5, tolerance_above: 1.4, tolerance_below: 1.5}\n".to_string();
    let text = pose_request("ee_link", &wanted, 0.002, 0.01, &extra);
    let request = parse_request(&text, Path::new("pose.yaml")).expect("parses");
    let problem = moveit_problem(&robot, &srdf, &scene, &request).expect("problem");
    let plan = plan_request(&problem, &settings()).expect("planned");
    let last = plan.path.last().expect("a path");
    assert!(last[2] <= -0.1 + 1e-5, "the elbow must end bent the other way (below -0.1 rad), got {}", last[2]);
    let reached = problem.model.robot().link_pose(last, problem.model.robot().link_index("ee_link").expect("link"));
    assert!((reached.translation.vector - wanted.translation.vector).norm() <= 0.002 + 1e-5);
}

#[test]
fn an_unreachable_pose_is_goal_unreachable() {
    let (robot, srdf) = ur5();
    let scene = load_scene(&root().join("tests/fixtures/mbm/problems/box_ur5/scene0001.yaml")).expect("scene");
    let far = Isometry3::translation(4.0, 0.0, 0.5);
    let text = pose_request("ee_link", &far, 0.01, 0.1, "");
    let request = parse_request(&text, Path::new("far.yaml")).expect("parses");
    let problem = moveit_problem(&robot, &srdf, &scene, &request).expect("problem");
    match plan_request(&problem, &settings()) {
        Err(PlanError::GoalUnreachable { reason }) => assert!(reason.contains("goal"), "{reason}"),
        other => panic!("expected GoalUnreachable, got {other:?}"),
    }
}

#[test]
fn orientation_errors_follow_moveits_two_parameterisations() {
    let wanted = UnitQuaternion::from_euler_angles(0.3, -0.2, 1.0);
    let (a, b, c) = (0.02, -0.03, 0.05);
    // R = Rx(a) Ry(b) Rz(c): intrinsic XYZ.
    let delta = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), a)
        * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), b)
        * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), c);
    let actual = wanted * delta;
    let e = orientation_error(&wanted, &actual, false);
    for (got, want) in e.iter().zip([a, b, c]) {
        assert!((got - want).abs() < 1e-12, "{e:?}");
    }
    let v = orientation_error(&wanted, &actual, true);
    let expected = delta.scaled_axis();
    assert!((Vector3::new(v[0], v[1], v[2]) - expected).norm() < 1e-12);
    // A quarter turn about y: b = pi/2 exactly (the Euler singularity is not a NaN).
    let quarter = wanted * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), FRAC_PI_2);
    let e = orientation_error(&wanted, &quarter, false);
    assert!(e.iter().all(|v| v.is_finite()) && (e[1] - FRAC_PI_2).abs() < 1e-6, "{e:?}");
}

fn parse_failure(e: MoveitError) -> (usize, usize, String) {
    match e {
        MoveitError::Parse { line, column, message, .. } => (line, column, message),
        other => panic!("expected a parse error, got {other:?}"),
    }
}

#[test]
fn bad_pose_goals_are_errors_with_their_place() {
    let (robot, srdf) = ur5();
    let scene = load_scene(&root().join("tests/fixtures/mbm/problems/box_ur5/scene0001.yaml")).expect("scene");
    let pose = Isometry3::translation(0.4, 0.1, 0.5);
    let good = pose_request("ee_link", &pose, 0.01, 0.1, "");
    let resolve = |text: &str| {
        let request = parse_request(text, Path::new("bad.yaml")).expect("parses");
        parse_failure(moveit_problem(&robot, &srdf, &scene, &request).expect_err("refused"))
    };
    // A link the robot does not have: named, at the constraint.
    let (line, _, message) =
        resolve(&good.replace("link_name: ee_link\n        header", "link_name: hand\n        header"));
    assert_eq!(line, 8);
    assert!(message.contains("no link `hand`"), "{message}");
    // Two links in one goal.
    let (_, _, message) = resolve(&good.replacen(
        "link_name: ee_link\n        orientation",
        "link_name: wrist_3_link\n        orientation",
        1,
    ));
    assert!(message.contains("one link"), "{message}");
    // A frame that is neither the world nor a link.
    let (line, _, message) = resolve(&good.replace("frame_id: world", "frame_id: table"));
    assert_eq!(line, 8);
    assert!(message.contains("frame `table`"), "{message}");
    // Parse errors: an unknown parameterisation, a negative tolerance, a region without
    // primitives, a non-unit quaternion.
    let parse = |text: &str| parse_failure(parse_request(text, Path::new("bad.yaml")).expect_err("refused"));
    let (_, _, message) = parse(&good.replace("parameterization: 1", "parameterization: 3"));
    assert!(message.contains("parameterization"), "{message}");
    let (_, _, message) = parse(&good.replace("absolute_y_axis_tolerance: 0.1", "absolute_y_axis_tolerance: -0.1"));
    assert!(message.contains("absolute_y_axis_tolerance"), "{message}");
    let (_, _, message) = parse(
        &good
            .replace("            - {type: 2, dimensions: [0.01]}\n", "            []\n")
            .replace("primitives:\n            []", "primitives: []"),
    );
    assert!(message.contains("primitive"), "{message}");
    let (_, _, message) =
        parse(&good.replace("orientation: {x: 0, y: 0, z: 0, w: 1}", "orientation: {x: 0, y: 0, z: 0, w: 3}"));
    assert!(message.contains("unit quaternion"), "{message}");
}

#[test]
fn a_request_in_ros2_echo_style_gives_a_pose_goal_and_a_joint_alternative() {
    let (robot, srdf) = ur5();
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/moveit");
    let request = embodied_planner::moveit::load_request(&dir.join("request_pose.yaml")).expect("parses");
    assert_eq!(request.goals.len(), 2);
    let pose = &request.goals[0];
    assert_eq!((pose.positions.len(), pose.orientations.len(), pose.joints.len()), (1, 1, 1));
    assert_eq!(pose.positions[0].offset, [0.0, 0.0, 0.02]);
    assert!(!pose.orientations[0].rotation_vector);
    let resolved = request.resolve(&robot, &srdf, None).expect("resolves");
    match &resolved.goals[0] {
        ResolvedGoal::Pose(p) => {
            assert_eq!(p.link, "ee_link");
            assert_eq!(p.joints, [(0, -0.5, 1.5)]);
            let (centre, orientation) = p.aim();
            // The region is in base_link's frame, which the model places above its root link.
            let base = robot.link_pose(robot.home(), robot.link_index("base_link").expect("base_link"));
            let expected = base * embodied_models::nalgebra::Point3::new(0.4, 0.2, 0.5);
            assert!((centre.expect("a position goal") - expected.coords).norm() < 1e-12);
            assert!(orientation.is_some());
        }
        other => panic!("expected a pose goal, got {other:?}"),
    }
    assert!(matches!(&resolved.goals[1], ResolvedGoal::Configuration(q) if q.len() == 6));
    // The first alternative is a pose: there is no single joint goal.
    assert!(resolved.goal.is_empty());
}
