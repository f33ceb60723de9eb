//! MoveIt planning scene / motion plan request YAML: shapes, poses, groups and error positions.

use std::path::{Path, PathBuf};

use embodied_models::Shape;
use embodied_models::nalgebra::{Point3, Vector3};
use embodied_models::srdf::load_srdf;
use embodied_models::urdf::load_urdf;
use embodied_planner::moveit::{MoveitError, load_request, load_scene, parse_request, parse_scene};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/moveit").join(name)
}

/// The UR5 (spherized) copied from MotionBenchMaker by the URDF tests of embodied-models.
fn ur5() -> (embodied_models::Robot, PathBuf) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/tests/fixtures");
    let srdf = dir.join("ur5.srdf");
    let robot = load_urdf(&dir.join("ur5_spherized.urdf"), Some(&srdf)).expect("UR5 fixture loads");
    (robot, srdf)
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-9
}

fn parse_error(e: MoveitError) -> (PathBuf, usize, usize, String) {
    match e {
        MoveitError::Parse { file, line, column, message } => (file, line, column, message),
        other => panic!("expected a parse error, got {other:?}"),
    }
}

#[test]
fn scene_gives_box_sphere_cylinder_with_poses_and_dimensions() {
    let scene = load_scene(&fixture("scene_shapes.yaml")).expect("scene parses");
    assert_eq!(scene.name, "shapes");
    let obstacles = scene.obstacles();
    let names: Vec<&str> = obstacles.iter().map(|o| o.name.as_str()).collect();
    // `ghost` is added and then removed (operation 1 = REMOVE).
    assert_eq!(names, ["table", "ball", "can"]);

    let table = &obstacles[0];
    match &table.shape {
        Shape::Cuboid { half_extents } => assert!((half_extents - Vector3::new(0.6, 0.4, 0.02)).norm() < 1e-12),
        other => panic!("table should be a box, got {other:?}"),
    }
    assert!((table.pose.translation.vector - Vector3::new(0.5, -0.25, 0.7)).norm() < 1e-12);
    assert!(table.pose.rotation.angle() < 1e-12);

    let ball = &obstacles[1];
    match &ball.shape {
        Shape::Sphere { radius } => assert!(close(*radius, 0.1)),
        other => panic!("ball should be a sphere, got {other:?}"),
    }
    assert!((ball.pose.translation.vector - Vector3::new(0.3, 0.2, 1.1)).norm() < 1e-12);

    // Cylinder [height, radius]; object pose (1, 0, 0.5) turned 90 deg about z, then the
    // primitive pose (0.2, 0, 0.1) in the object frame: world (1, 0.2, 0.6).
    let can = &obstacles[2];
    match &can.shape {
        Shape::Cylinder { radius, half_height } => {
            assert!(close(*radius, 0.05));
            assert!(close(*half_height, 0.15));
        }
        other => panic!("can should be a cylinder, got {other:?}"),
    }
    assert!((can.pose.translation.vector - Vector3::new(1.0, 0.2, 0.6)).norm() < 1e-9, "{:?}", can.pose);
    let x_axis = can.pose.rotation * Vector3::x();
    assert!((x_axis - Vector3::y()).norm() < 1e-9);
    // A point on the can's axis is where the composed pose says.
    let top = can.pose * Point3::new(0.0, 0.0, 0.15);
    assert!((top.coords - Vector3::new(1.0, 0.2, 0.75)).norm() < 1e-9);

    let state = scene.robot_state.as_ref().expect("robot_state");
    assert_eq!(state.names, ["shoulder_pan_joint", "elbow_joint"]);
    assert_eq!(state.positions, [0.25, -0.5]);
    assert_eq!(scene.environment().len(), 3);
    assert_eq!(scene.allowed_collisions, [("base_link".to_string(), "shoulder_link".to_string())]);
}

#[test]
fn scene_frames_are_checked_against_the_robot() {
    let (robot, _) = ur5();
    let scene = load_scene(&fixture("scene_shapes.yaml")).expect("scene parses");
    scene.check_frames(&robot).expect("world frame is accepted");
    let text = "world:\n  collision_objects:\n    - id: cup\n      header: {frame_id: wrist_3_link}\n      primitives: [{type: sphere, dimensions: [0.05]}]\n      primitive_poses: [{position: [0, 0, 0], orientation: [0, 0, 0, 1]}]\n";
    let scene = parse_scene(text, Path::new("attached.yaml")).expect("parses");
    let (_, line, column, message) = parse_error(scene.check_frames(&robot).expect_err("link frame is refused"));
    assert_eq!((line, column), (3, 7));
    assert!(message.contains("wrist_3_link"), "{message}");
}

#[test]
fn request_gives_start_goal_and_the_groups_joints() {
    let (robot, srdf_path) = ur5();
    let srdf = load_srdf(&srdf_path).expect("srdf");
    let request = load_request(&fixture("request_ur5.yaml")).expect("request parses");
    assert_eq!(request.group_name, "manipulator");
    assert_eq!(request.planner_id.as_deref(), Some("RRTConnectkConfigDefault"));
    assert_eq!(request.goals.len(), 1);
    let joints = &request.goals[0].joints;
    assert_eq!(joints.len(), 6);
    assert!(close(joints[0].tolerance_above, 0.001));
    assert!(close(joints[0].tolerance_below, 0.002));
    assert_eq!(request.start.get("robotiq_85_left_knuckle_joint"), Some(0.2));

    let resolved = request.resolve(&robot, &srdf, None).expect("resolves");
    let arm =
        ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"];
    assert_eq!(resolved.joint_names, arm);
    // Start values are reordered from the request's order into the robot's joint order.
    assert_eq!(resolved.start, [1.5, -1.5, 0.1, -1.6, -1.5, 3.0]);
    assert_eq!(resolved.goal, [1.0, -1.0, 1.25, -0.5, 0.5, -3.0]);
    assert!(resolved.frozen.is_empty(), "the spherized UR5's gripper joints are fixed: {:?}", resolved.frozen);
    let planning = resolved.planning_robot(&robot).expect("planning robot");
    assert_eq!(planning.dof(), 6);
}

#[test]
fn joints_outside_the_group_are_frozen_at_their_start_values() {
    let (robot, _) = ur5();
    let srdf = load_srdf(&fixture("ur5_arm5.srdf")).expect("srdf");
    let request = load_request(&fixture("request_arm5.yaml")).expect("request parses");
    let resolved = request.resolve(&robot, &srdf, None).expect("resolves");
    assert_eq!(resolved.joint_names.len(), 5);
    assert_eq!(resolved.start, [0.1, -1.2, 0.3, -1.4, 0.5]);
    assert_eq!(resolved.goal, [1.1, -1.1, 1.3, -1.3, 1.5]);
    assert_eq!(resolved.frozen, [("wrist_3_joint".to_string(), 2.5)]);
    let arm = resolved.planning_robot(&robot).expect("freeze");
    assert_eq!(arm.joint_names(), resolved.joint_names);
    // The frozen joint really sits at 2.5 rad: the tool pose matches the full robot's.
    let full: Vec<f64> = [0.1, -1.2, 0.3, -1.4, 0.5, 2.5].to_vec();
    let tip_full = robot.link_pose(&full, robot.link_index("ee_link").expect("ee_link"));
    let tip_arm = arm.link_pose(&resolved.start, arm.link_index("ee_link").expect("ee_link"));
    assert!((tip_full.translation.vector - tip_arm.translation.vector).norm() < 1e-9);
    assert!(tip_full.rotation.angle_to(&tip_arm.rotation) < 1e-9);
}

#[test]
fn scene_robot_state_fills_joints_the_request_does_not_give() {
    let (robot, _) = ur5();
    let srdf = load_srdf(&fixture("ur5_arm5.srdf")).expect("srdf");
    let text = "group_name: arm5\nstart_state:\n  joint_state:\n    name: [shoulder_pan_joint, shoulder_lift_joint, elbow_joint, wrist_1_joint, wrist_2_joint]\n    position: [0, 0, 0, 0, 0]\ngoal_constraints:\n  - joint_constraints:\n      - {joint_name: shoulder_pan_joint, position: 1}\n      - {joint_name: shoulder_lift_joint, position: 1}\n      - {joint_name: elbow_joint, position: 1}\n      - {joint_name: wrist_1_joint, position: 1}\n      - {joint_name: wrist_2_joint, position: 1}\n";
    let request = parse_request(text, Path::new("r.yaml")).expect("parses");
    let scene = parse_scene(
        "robot_state:\n  joint_state:\n    name: [wrist_3_joint]\n    position: [-0.75]\n",
        Path::new("s.yaml"),
    )
    .expect("parses");
    let resolved = request.resolve(&robot, &srdf, scene.robot_state.as_ref()).expect("resolves");
    assert_eq!(resolved.frozen, [("wrist_3_joint".to_string(), -0.75)]);
}

#[test]
fn errors_carry_file_line_column_and_what_was_expected() {
    let (file, line, column, message) =
        parse_error(load_scene(&fixture("bad_box_dims.yaml")).expect_err("two box dimensions"));
    assert!(file.ends_with("bad_box_dims.yaml"));
    assert_eq!((line, column), (6, 23), "{message}");
    assert_eq!(message, "expected a list of 3 numbers for box dimensions, got 2");
    let shown = load_scene(&fixture("bad_box_dims.yaml")).expect_err("again").to_string();
    assert!(
        shown.ends_with("bad_box_dims.yaml:6:23: expected a list of 3 numbers for box dimensions, got 2"),
        "{shown}"
    );

    let (_, line, column, message) = parse_error(load_scene(&fixture("cone.yaml")).expect_err("cone"));
    assert_eq!((line, column), (5, 17));
    assert!(
        message.contains("cone") && message.contains("party_hat") && message.contains("not supported"),
        "{message}"
    );

    let (_, line, _, message) = parse_error(load_scene(&fixture("bad_yaml.yaml")).expect_err("truncated"));
    assert!(line >= 4, "{line}: {message}");
    assert!(message.starts_with("invalid YAML"), "{message}");

    let (_, line, column, message) =
        parse_error(load_request(&fixture("request_bad_position.yaml")).expect_err("a word for a position"));
    assert_eq!((line, column), (5, 19));
    assert!(message.contains("expected a number") && message.contains("fast"), "{message}");

    let (robot, srdf_path) = ur5();
    let srdf = load_srdf(&srdf_path).expect("srdf");
    let request = load_request(&fixture("request_foreign_joint.yaml")).expect("parses");
    let (_, line, column, message) =
        parse_error(request.resolve(&robot, &srdf, None).expect_err("gripper joint in an arm goal"));
    assert_eq!((line, column), (9, 21));
    assert!(message.contains("robotiq_85_left_knuckle_joint") && message.contains("manipulator"), "{message}");

    let missing = "group_name: manipulator\ngoal_constraints:\n  - joint_constraints:\n      - {joint_name: shoulder_pan_joint, position: 1}\n";
    let request = parse_request(missing, Path::new("partial.yaml")).expect("parses");
    let (_, line, column, message) = parse_error(request.resolve(&robot, &srdf, None).expect_err("goal misses joints"));
    assert_eq!((line, column), (3, 5));
    assert!(message.contains("shoulder_lift_joint"), "{message}");

    let unknown_group = "group_name: legs\ngoal_constraints:\n  - joint_constraints: []\n";
    let request = parse_request(unknown_group, Path::new("legs.yaml")).expect("parses");
    let (_, line, column, message) = parse_error(request.resolve(&robot, &srdf, None).expect_err("no such group"));
    assert_eq!((line, column), (1, 13));
    assert!(message.contains("legs"), "{message}");

    let no_goal = "group_name: manipulator\n";
    let (_, line, _, message) = parse_error(parse_request(no_goal, Path::new("g.yaml")).expect_err("no goal"));
    assert_eq!(line, 1);
    assert!(message.contains("goal_constraints"), "{message}");

    let pose_goal =
        "group_name: manipulator\ngoal_constraints:\n  - position_constraints:\n      - link_name: ee_link\n";
    let (_, line, column, message) =
        parse_error(parse_request(pose_goal, Path::new("p.yaml")).expect_err("pose goal without a region"));
    assert_eq!((line, column), (4, 9));
    assert!(message.contains("constraint_region"), "{message}");
}

/// A joint the start state names and the robot does not have (MotionBenchMaker's Fetch requests
/// name the wheels, which VAMP's spherized Fetch drops) is ignored with a warning at the name,
/// while the group's joints keep the values given; with a group joint left without a value, the
/// unknown name is taken for that joint misspelt: an error at the name.
#[test]
fn start_joints_the_robot_lacks_are_ignored_with_a_warning_unless_a_group_joint_has_no_value() {
    let (robot, srdf_path) = ur5();
    let srdf = load_srdf(&srdf_path).expect("srdf");
    let arm =
        ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"];
    let goal: String =
        arm.iter().map(|j| format!("      - {{joint_name: {j}, position: 0.5}}\n")).collect::<Vec<_>>().concat();
    let request_with = |names: &[&str]| {
        let values = vec!["0.25"; names.len()].join(", ");
        format!(
            "group_name: manipulator\ngoal_constraints:\n  - joint_constraints:\n{goal}start_state:\n  joint_state:\n    name: [{}]\n    position: [{values}]\n",
            names.join(", ")
        )
    };
    let mut names = vec!["l_wheel_joint"];
    names.extend(arm);
    names.push("r_wheel_joint");
    let request = parse_request(&request_with(&names), Path::new("wheels.yaml")).expect("parses");
    let resolved = request.resolve(&robot, &srdf, None).expect("unknown start joints are ignored");
    assert_eq!(resolved.start, vec![0.25; 6]);
    assert_eq!(resolved.joint_names, arm);
    let warned: Vec<String> = resolved.warnings.iter().map(|w| w.to_string()).collect();
    assert_eq!(warned.len(), 2, "{warned:?}");
    assert!(warned[0].starts_with("wheels.yaml:12:12: warning: start state names joint `l_wheel_joint`"), "{warned:?}");
    assert!(warned[0].ends_with("does not have; ignored"), "{warned:?}");
    assert!(warned[1].contains("`r_wheel_joint`"), "{warned:?}");

    // Every name known: no warning.
    let request = parse_request(&request_with(&arm), Path::new("arm.yaml")).expect("parses");
    assert!(request.resolve(&robot, &srdf, None).expect("resolves").warnings.is_empty());

    // `elbow_joint` misspelt: the group's joint has no value, so the name is an error.
    let typo: Vec<&str> = arm.iter().map(|&j| if j == "elbow_joint" { "elbow_jiont" } else { j }).collect();
    let request = parse_request(&request_with(&typo), Path::new("typo.yaml")).expect("parses");
    let (file, line, column, message) = parse_error(request.resolve(&robot, &srdf, None).expect_err("a typo"));
    assert_eq!((file.as_path(), line, column), (Path::new("typo.yaml"), 12, 53), "{message}");
    assert!(message.contains("`elbow_jiont`") && message.contains("no value for `elbow_joint`"), "{message}");
    // With a wheel named too, the error lists every name the robot lacks, at the first.
    let mut both = vec!["l_wheel_joint"];
    both.extend(&typo);
    let request = parse_request(&request_with(&both), Path::new("both.yaml")).expect("parses");
    let (_, line, column, message) = parse_error(request.resolve(&robot, &srdf, None).expect_err("a typo"));
    assert_eq!((line, column), (12, 12), "{message}");
    assert!(message.contains("names `l_wheel_joint`, `elbow_jiont`, which robot"), "{message}");
}

/// A start or goal value past a joint's limit by no more than the limit's rounding
/// (`LIMIT_ROUNDING`), or than the goal's tolerance that side, is taken at the limit with a
/// warning at the value's name; one farther is kept, so the problem stays invalid.
#[test]
fn values_past_a_limit_by_its_rounding_or_the_tolerance_are_taken_at_the_limit() {
    let (robot, srdf_path) = ur5();
    let srdf = load_srdf(&srdf_path).expect("srdf");
    let upper = robot.limits()[0].upper;
    let request = |pan_goal: f64, below: f64, pan_start: f64| {
        format!(
            "group_name: manipulator\ngoal_constraints:\n  - joint_constraints:\n      - {{joint_name: shoulder_pan_joint, position: {pan_goal}, tolerance_below: {below}}}\n{}start_state:\n  joint_state:\n    name: [shoulder_pan_joint]\n    position: [{pan_start}]\n",
            ["shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"]
                .iter()
                .map(|j| format!("      - {{joint_name: {j}, position: 0.5}}\n"))
                .collect::<String>()
        )
    };
    let resolve = |text: String| {
        parse_request(&text, Path::new("limits.yaml")).expect("parses").resolve(&robot, &srdf, None).expect("resolves")
    };
    // Past by half the rounding: at the limit, both ends, one warning each.
    let past = upper + 0.5 * embodied_planner::moveit::LIMIT_ROUNDING;
    let r = resolve(request(past, 0.0, -past));
    assert_eq!((r.goal[0], r.start[0]), (upper, -upper));
    let warned: Vec<String> = r.warnings.iter().map(|w| w.to_string()).collect();
    assert_eq!(warned.len(), 2, "{warned:?}");
    assert!(warned[0].starts_with("limits.yaml:12:12: warning: start joint `shoulder_pan_joint`"), "{warned:?}");
    assert!(warned[1].starts_with("limits.yaml:4:22: warning: goal joint `shoulder_pan_joint`"), "{warned:?}");
    assert!(robot.check_configuration(&[r.goal[0], 0.5, 0.5, 0.5, 0.5, 0.5]).is_ok());
    // Past by more: kept, no warning, and out of the limits.
    let r = resolve(request(upper + 1e-3, 0.0, 0.0));
    assert_eq!(r.goal[0], upper + 1e-3);
    assert!(r.warnings.is_empty());
    assert!(robot.check_configuration(&r.goal).is_err());
    // The goal's tolerance below reaches back within the limit: at the limit.
    let r = resolve(request(upper + 1e-3, 2e-3, 0.0));
    assert_eq!((r.goal[0], r.warnings.len()), (upper, 1));
    // Within the limits: untouched.
    let r = resolve(request(upper - 1e-3, 0.0, 0.0));
    assert_eq!((r.goal[0], r.warnings.len()), (upper - 1e-3, 0));
}
