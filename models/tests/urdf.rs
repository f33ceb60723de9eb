//! URDF + SRDF loading: the UR5 of MotionBenchMaker (fixtures copied from /work/shared/mbm/ur5),
//! a small hand-written gripper robot, STL meshes, package:// resolution and the error messages.

use std::path::{Path, PathBuf};

use embodied_models::nalgebra::{Point3, Vector3};
use embodied_models::srdf::{load_srdf, parse_srdf};
use embodied_models::urdf::{UrdfOptions, load_urdf, load_urdf_with, parse_urdf};
use embodied_models::{JointKind, ModelError, Robot, Shape};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures").join(name)
}

fn no_meshes() -> UrdfOptions {
    UrdfOptions { load_meshes: false, ..UrdfOptions::default() }
}

fn close(a: Vector3<f64>, b: [f64; 3], tol: f64) -> bool {
    (a - Vector3::from(b)).norm() < tol
}

/// Axis-aligned bounding box of a convex-mesh shape (in the shape's own frame).
fn mesh_aabb(shape: &Shape) -> ([f64; 3], [f64; 3]) {
    let Shape::ConvexMesh(hull) = shape else { panic!("expected a convex mesh, got a {}", shape.kind()) };
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in &hull.points {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}

fn assert_aabb(shape: &Shape, lo: [f64; 3], hi: [f64; 3]) {
    let (l, h) = mesh_aabb(shape);
    for k in 0..3 {
        assert!(
            (l[k] - lo[k]).abs() < 1e-6 && (h[k] - hi[k]).abs() < 1e-6,
            "aabb {l:?}..{h:?}, expected {lo:?}..{hi:?}"
        );
    }
}

fn link<'r>(robot: &'r Robot, name: &str) -> &'r embodied_models::Link {
    let i = robot.link_index(name).unwrap_or_else(|| panic!("no link `{name}`"));
    &robot.links()[i]
}

fn ur5_spherized() -> Robot {
    load_urdf(&fixture("ur5_spherized.urdf"), Some(&fixture("ur5.srdf"))).expect("the spherized UR5 loads")
}

const UR5_ARM: [&str; 6] =
    ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"];

#[test]
fn ur5_spherized_loads_six_arm_joints_and_the_manipulator_group() {
    let robot = ur5_spherized();
    assert_eq!(robot.name(), "ur5_robotiq85");
    // The Robotiq joints are all `fixed` in this URDF (no mimic), so the robot has 6 DOFs.
    assert_eq!(robot.dof(), 6);
    assert_eq!(robot.joint_names(), UR5_ARM);
    for (i, l) in robot.limits().iter().enumerate() {
        assert_eq!(robot.dof_joint(i).kind, JointKind::Revolute);
        // The URDF writes pi as "3.14159265".
        let urdf_pi: f64 = "3.14159265".parse().expect("a number");
        assert!(l.lower == -urdf_pi && l.upper == urdf_pi, "{l:?}");
        assert_eq!(l.max_velocity, 0.5);
        assert_eq!(l.max_acceleration, 10.0, "URDF has no acceleration limit: the default is used");
    }
    let srdf = load_srdf(&fixture("ur5.srdf")).expect("the UR5 SRDF parses");
    assert_eq!(srdf.group_joints(&robot, "manipulator").expect("group exists"), UR5_ARM);
    assert_eq!(srdf.group_dofs(&robot, "manipulator").expect("group exists"), vec![0, 1, 2, 3, 4, 5]);
    // The gripper group's joints are all fixed: no degrees of freedom.
    assert!(srdf.group_joints(&robot, "gripper").expect("group exists").is_empty());
    // SRDF home state and end effector.
    assert_eq!(robot.home(), &[0.0, -1.57, 0.0, -1.57, 0.0, 0.0]);
    assert_eq!(robot.end_effectors()[0].name, "ee_link");
    assert_eq!(robot.end_effectors()[0].link, robot.link_index("ee_link").expect("ee_link"));
}

#[test]
fn ur5_spherized_has_every_sphere_of_the_file() {
    let text = std::fs::read_to_string(fixture("ur5_spherized.urdf")).expect("fixture readable");
    let in_file = text.matches("<sphere").count();
    assert_eq!(in_file, 40);
    let robot = ur5_spherized();
    let shapes: Vec<&Shape> = robot.links().iter().flat_map(|l| l.shapes.iter().map(|s| &s.shape)).collect();
    let spheres = shapes.iter().filter(|s| matches!(s, Shape::Sphere { .. })).count();
    assert_eq!(spheres, in_file);
    assert_eq!(shapes.len(), in_file, "the visual .dae meshes are not collision geometry");
    // upper_arm_link: several spheres of radius 0.08 at z = 0.105, 0.21, 0.315, ... (file line 52 on).
    let upper = link(&robot, "upper_arm_link");
    assert!(upper.shapes.len() > 2);
    for (k, z) in [0.105, 0.21, 0.315].into_iter().enumerate() {
        assert!(matches!(upper.shapes[k].shape, Shape::Sphere { radius } if radius == 0.08));
        assert!(close(upper.shapes[k].pose.translation.vector, [0.0, 0.0, z], 1e-12));
    }
}

#[test]
fn ur5_ee_link_at_the_srdf_home_state() {
    let robot = ur5_spherized();
    let q = robot.home().to_vec();
    let ee = robot.link_index("ee_link").expect("ee_link");
    let pose = robot.forward_kinematics(&q)[ee];
    // By hand from the URDF joint origins, q = home = (0, -1.57, 0, -1.57, 0, 0):
    //   offset_joint       T(0, 0, 0.9144) Rz(1.57)
    //   shoulder_pan       T(0, 0, 0.089159)                Rz(0)
    //   shoulder_lift      T(0, 0.13585, 0) Ry(1.570796325)  Ry(-1.57)  -> Ry(d), d = 0.000796325
    //   elbow              T(0, -0.1197, 0.425)             Ry(0)
    //   wrist_1            T(0, 0, 0.39225) Ry(1.570796325)  Ry(-1.57)  -> Ry(d) again: Ry(2d) so far
    //   wrist_2            T(0, 0.093, 0)                   Rz(0)
    //   wrist_3            T(0, 0, 0.09465)                 Ry(0)
    //   ee_fixed_joint     T(0, 0.0823, 0) Rz(1.570796325)
    // With Ry(a)(x, y, z) = (x cos a + z sin a, y, -x sin a + z cos a), in the base_link frame:
    //   x = (0.425 + 0.39225) sin d + 0.09465 sin 2d             = 0.00080154080
    //   y = 0.13585 - 0.1197 + 0.093 + 0.0823                    = 0.19145
    //   z = 0.089159 + (0.425 + 0.39225) cos d + 0.09465 cos 2d  = 1.00105862084
    // then Rz(1.57) (c = cos 1.57, s = sin 1.57) and +0.9144 in z:
    //   X = x c - y s = -0.19144930101,  Y = x s + y c = 0.00095399729,  Z = 1.91545862084
    assert!(close(pose.translation.vector, [-0.19144930101, 0.00095399729, 1.91545862084], 1e-9), "{pose}");
    // The ee_link z axis: Rz(1.57) Ry(2d) Rz(1.570796325) z = (sin 2d cos 1.57, sin 2d sin 1.57, cos 2d).
    let z = pose.rotation * Vector3::z();
    assert!(close(z, [1.26826920e-6, 1.59264882e-3, 0.99999873173], 1e-9), "{z}");
    // The end effector pose is the ee_link pose (tool = identity).
    let (flange, tool) = robot.end_effector_poses(&q, 0);
    assert!(close(flange.translation.vector, pose.translation.vector.into(), 1e-15));
    assert!(close(tool.translation.vector, pose.translation.vector.into(), 1e-15));
}

#[test]
fn ur5_srdf_disabled_pairs_are_applied() {
    let robot = ur5_spherized();
    let srdf = load_srdf(&fixture("ur5.srdf")).expect("the UR5 SRDF parses");
    assert_eq!(srdf.disabled.len(), 88);
    let idx = |n: &str| robot.link_index(n).unwrap_or_else(|| panic!("no link {n}"));
    let pair = |a: &str, b: &str| (idx(a).min(idx(b)), idx(a).max(idx(b)));
    for (a, b) in &srdf.disabled {
        assert!(robot.disabled_pairs().contains(&pair(a, b)), "{a} - {b} not disabled");
    }
    assert_eq!(robot.disabled_pairs().len(), 88);
    assert!(robot.disabled_pairs().contains(&pair("base_link", "shoulder_link")));
    // Not in the SRDF: still checked.
    assert!(!robot.disabled_pairs().contains(&pair("base_link", "wrist_3_link")));
    // Without the SRDF nothing is disabled, home is zeros.
    let bare = load_urdf(&fixture("ur5_spherized.urdf"), None).expect("loads");
    assert!(bare.disabled_pairs().is_empty());
    assert_eq!(bare.home(), &[0.0; 6]);
}

#[test]
fn ur5_with_meshes_fails_clearly_and_loads_without_them() {
    let err = load_urdf(&fixture("ur5.urdf"), Some(&fixture("ur5.srdf"))).expect_err("the UR5 meshes are not included");
    assert!(matches!(err, ModelError::Mesh { line: 25, .. }), "{err:?}");
    let msg = err.to_string();
    assert!(msg.contains("ur5.urdf:25"), "{msg}");
    assert!(msg.contains("package://meshes/ur5/collision/base.stl"), "{msg}");
    assert!(msg.contains("meshes/ur5/collision/base.stl"), "{msg}");
    assert!(msg.contains("not found"), "{msg}");

    let robot = load_urdf_with(&fixture("ur5.urdf"), Some(&fixture("ur5.srdf")), &no_meshes()).expect("loads");
    assert_eq!(robot.joint_names(), UR5_ARM);
    assert_eq!(robot.links().len(), 22);
    // Mesh collision elements are skipped; ee_link keeps its box (size 0.01 -> half 0.005).
    assert!(link(&robot, "base_link").shapes.is_empty());
    let ee = link(&robot, "ee_link");
    assert_eq!(ee.shapes.len(), 1);
    assert!(matches!(ee.shapes[0].shape, Shape::Cuboid { half_extents } if close(half_extents, [0.005; 3], 1e-15)));
    assert!(close(ee.shapes[0].pose.translation.vector, [-0.01, 0.0, 0.0], 1e-15));
    // Same kinematics as the spherized file.
    let sph = ur5_spherized();
    let q = [0.3, -1.0, 0.7, -0.4, 1.1, 2.0];
    let a = robot.link_pose(&q, robot.link_index("ee_link").expect("ee_link"));
    let b = sph.link_pose(&q, sph.link_index("ee_link").expect("ee_link"));
    assert!(close(a.translation.vector, b.translation.vector.into(), 1e-12));
    // Without an SRDF: the arm's tip carries several fixed leaves (tool0, gripper links), so
    // the one end effector is the link of the last moving joint.
    let bare = load_urdf_with(&fixture("ur5.urdf"), None, &no_meshes()).expect("loads");
    assert_eq!(bare.end_effectors().len(), 1);
    assert_eq!(bare.end_effectors()[0].name, "wrist_3_link");
    assert!(bare.provenance().contains("acceleration limit 10"), "{}", bare.provenance());
}

#[test]
fn tiny_gripper_joints_shapes_and_meshes() {
    let robot = load_urdf(&fixture("tiny_gripper.urdf"), None).expect("loads");
    // finger_right_joint mimics finger_left_joint: 3 DOFs.
    assert_eq!(robot.joint_names(), ["shoulder", "wrist_joint", "finger_left_joint"]);
    assert!(robot.is_continuous(1) && !robot.is_continuous(0));
    let limits = robot.limits();
    assert_eq!((limits[0].lower, limits[0].upper, limits[0].max_velocity), (-2.0, 2.0, 1.5));
    assert!(limits[1].lower.is_infinite() && limits[1].upper.is_infinite());
    assert_eq!(limits[1].max_velocity, 1.0, "no <limit>: default velocity");
    assert_eq!((limits[2].lower, limits[2].upper), (0.0, 0.04));
    let wrist = &robot.joints()[robot.joint_index("wrist_joint").expect("wrist_joint")];
    assert!(close(wrist.axis.into_inner(), [0.0, 1.0, 0.0], 1e-15), "axis normalised");
    assert_eq!(robot.home(), &[0.0, 0.0, 0.0]);

    let base = link(&robot, "base");
    assert!(
        matches!(base.shapes[0].shape, Shape::Cylinder { radius, half_height } if radius == 0.1 && half_height == 0.05)
    );
    assert!(close(base.shapes[0].pose.translation.vector, [0.0, 0.0, 0.05], 1e-15));
    let arm = link(&robot, "arm");
    assert_eq!(arm.shapes.len(), 2);
    assert!(
        matches!(arm.shapes[0].shape, Shape::Cuboid { half_extents } if close(half_extents, [0.05, 0.05, 0.25], 1e-15))
    );
    // ASCII STL -> convex hull with the box's bounding box.
    assert_aabb(&arm.shapes[1].shape, [0.0, -0.1, 0.05], [0.2, 0.3, 0.65]);
    // Binary STL, scaled (0.1, 0.2, 0.3); the <visual> .dae is ignored.
    let w = link(&robot, "wrist");
    assert_eq!(w.shapes.len(), 1);
    assert_aabb(&w.shapes[0].shape, [0.0; 3], [0.1, 0.2, 0.3]);
    let Shape::ConvexMesh(hull) = &w.shapes[0].shape else { unreachable!() };
    assert_eq!(hull.points.len(), 4);
    assert!(hull.points.contains(&Point3::new(0.0, 0.2, 0.0)));

    // Without meshes, the mesh collision elements are skipped and the box stays.
    let lean = load_urdf_with(&fixture("tiny_gripper.urdf"), None, &no_meshes()).expect("loads");
    assert_eq!(link(&lean, "arm").shapes.len(), 1);
    assert!(link(&lean, "wrist").shapes.is_empty());
}

#[test]
fn mimic_joint_follows_its_leader() {
    let robot = load_urdf(&fixture("tiny_gripper.urdf"), None).expect("loads");
    let right = robot.joint_index("finger_right_joint").expect("joint");
    assert_eq!(robot.joints()[right].dof_index, None);
    assert_eq!(robot.joints()[right].mimic, Some((2, 1.0, 0.001)));
    let q = [0.0, 0.0, 0.03];
    assert!((robot.joint_value(right, &q) - 0.031).abs() < 1e-15);
    let poses = robot.forward_kinematics(&q);
    // wrist at z = 0.1 + 0.5; fingers 0.05 above it, at y = +-0.02, moving apart along +-y.
    let left = poses[robot.link_index("finger_left").expect("link")].translation.vector;
    let right = poses[robot.link_index("finger_right").expect("link")].translation.vector;
    assert!(close(left, [0.0, 0.05, 0.65], 1e-12), "{left}");
    assert!(close(right, [0.0, -0.051, 0.65], 1e-12), "{right}");
    // The Jacobian column of the finger DOF moves the mimic finger too.
    let jac = robot.jacobian(&q, robot.link_index("finger_right").expect("link"), &Default::default());
    assert!((jac[(1, 2)] + 1.0).abs() < 1e-12, "{jac}");
    // End effectors without an SRDF: each moving chain tip (the two fingers).
    let names: Vec<&str> = robot.end_effectors().iter().map(|e| e.name.as_str()).collect();
    assert_eq!(names, ["finger_left", "finger_right"]);
}

#[test]
fn tiny_gripper_srdf_groups_home_end_effector_and_pairs() {
    let robot = load_urdf(&fixture("tiny_gripper.urdf"), Some(&fixture("tiny_gripper.srdf"))).expect("loads");
    let srdf = load_srdf(&fixture("tiny_gripper.srdf")).expect("parses");
    assert_eq!(srdf.group_joints(&robot, "arm").expect("arm"), ["shoulder", "wrist_joint"]);
    // <joint> finger_left_joint; <link> finger_right -> its parent joint, a mimic: not active.
    assert_eq!(srdf.group_joints(&robot, "hand").expect("hand"), ["finger_left_joint"]);
    // Subgroups, listed hand first, come out in q order.
    assert_eq!(srdf.group_joints(&robot, "everything").expect("all"), ["shoulder", "wrist_joint", "finger_left_joint"]);
    assert_eq!(robot.home(), &[0.5, -0.25, 0.0]);
    let names: Vec<&str> = robot.end_effectors().iter().map(|e| e.name.as_str()).collect();
    assert_eq!(names, ["wrist", "finger_left", "finger_right"]);
    // Two pairs; the one naming an unknown link is skipped.
    assert_eq!(robot.disabled_pairs().len(), 2);
    let (b, a) = (robot.link_index("base").expect("base"), robot.link_index("arm").expect("arm"));
    assert!(robot.disabled_pairs().contains(&(b.min(a), b.max(a))));
    // apply_srdf on a robot loaded without it gives the same pairs.
    let mut bare = load_urdf(&fixture("tiny_gripper.urdf"), None).expect("loads");
    embodied_models::srdf::apply_srdf(&mut bare, &srdf);
    assert_eq!(bare.disabled_pairs(), robot.disabled_pairs());
}

#[test]
fn package_uris_resolve_through_package_dirs_and_ancestors() {
    let urdf = fixture("package_mesh.urdf");
    for dir in [fixture("pkgroot"), fixture("pkgroot/my_pkg")] {
        let options = UrdfOptions { package_dirs: vec![dir.clone()], ..UrdfOptions::default() };
        let robot = load_urdf_with(&urdf, None, &options).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
        assert_aabb(&robot.links()[0].shapes[0].shape, [0.0; 3], [2.0; 3]);
    }
    // Not found without package_dirs (fixtures/ neither is nor contains my_pkg).
    let err = load_urdf(&urdf, None).expect_err("no package dir");
    let msg = err.to_string();
    assert!(msg.contains("package_mesh.urdf:5") && msg.contains("package://my_pkg/meshes/tetra.stl"), "{msg}");
    // A URDF inside a package folder finds the package among its ancestors.
    let text = std::fs::read_to_string(&urdf).expect("readable");
    let inside = fixture("pkgroot/my_pkg/urdf/robot.urdf");
    let robot = parse_urdf(&text, &inside, &UrdfOptions::default()).expect("found through an ancestor");
    assert_eq!(robot.links()[0].shapes.len(), 1);
    // file:// is an absolute path.
    let abs = fixture("meshes/tetra_binary.stl");
    let text = format!(
        r#"<robot name="f"><link name="l"><collision><geometry><mesh filename="file://{}"/></geometry></collision></link></robot>"#,
        abs.display()
    );
    let robot = parse_urdf(&text, Path::new("/nowhere/f.urdf"), &UrdfOptions::default()).expect("file:// loads");
    assert_aabb(&robot.links()[0].shapes[0].shape, [0.0; 3], [1.0; 3]);
}

// ---------------------------------------------------------------------------------------
// Errors: each names the file, the line and what was expected.

fn urdf_error(text: &str) -> String {
    let err = parse_urdf(text, Path::new("dir/bad.urdf"), &UrdfOptions::default()).expect_err("must fail");
    err.to_string()
}

fn assert_mentions(msg: &str, parts: &[&str]) {
    for p in parts {
        assert!(msg.contains(p), "`{msg}` does not mention `{p}`");
    }
}

const ONE_JOINT_HEAD: &str = r#"<robot name="r">
<link name="a"/>
<link name="b"/>
"#;

#[test]
fn error_malformed_xml() {
    let msg = urdf_error("<robot name=\"r\">\n  <link name=\"a\">\n</robot>\n");
    assert_mentions(&msg, &["dir/bad.urdf:3:", "malformed XML", "expected"]);
    let msg = urdf_error("<robot name=\"r\">\n  <link name=\"a\"/>\n");
    assert_mentions(&msg, &["dir/bad.urdf:", "malformed XML"]);
}

#[test]
fn error_joint_with_unknown_link() {
    let text = format!(
        "{ONE_JOINT_HEAD}<joint name=\"j\" type=\"fixed\">\n  <parent link=\"a\"/>\n  <child link=\"nope\"/>\n</joint>\n</robot>"
    );
    let msg = urdf_error(&text);
    assert_mentions(&msg, &["dir/bad.urdf:6:", "unknown link `nope`", "expected the name of a <link>"]);
}

#[test]
fn error_missing_required_attribute() {
    let text = "<robot name=\"r\">\n<link name=\"a\">\n <collision>\n  <geometry>\n   <box/>\n  </geometry>\n </collision>\n</link>\n</robot>";
    let msg = urdf_error(text);
    assert_mentions(&msg, &["dir/bad.urdf:5:", "<box>", "`size`", "expected three non-negative lengths"]);
    let msg = urdf_error("<robot name=\"r\">\n<link/>\n</robot>");
    assert_mentions(&msg, &["dir/bad.urdf:2:", "`name`"]);
}

#[test]
fn error_bad_number() {
    let text = format!(
        "{ONE_JOINT_HEAD}<joint name=\"j\" type=\"fixed\">\n  <parent link=\"a\"/>\n  <child link=\"b\"/>\n  <origin xyz=\"0 1.0.0 0\"/>\n</joint>\n</robot>"
    );
    let msg = urdf_error(&text);
    assert_mentions(&msg, &["dir/bad.urdf:7:", "`1.0.0` is not a finite number", "expected three numbers"]);
    let msg = urdf_error("<robot name=\"r\"><link name=\"a\"><collision><geometry>\n<sphere radius=\"0.1 0.2\"/>");
    assert_mentions(&msg, &["malformed XML"]);
    let msg = urdf_error(
        "<robot name=\"r\"><link name=\"a\"><collision><geometry>\n<sphere radius=\"0.1 0.2\"/></geometry></collision></link></robot>",
    );
    assert_mentions(&msg, &["dir/bad.urdf:2:", "has 2 numbers", "expected a non-negative radius"]);
}

#[test]
fn error_cycle_and_two_roots() {
    // a is the root; b and c are each other's child: not connected to a.
    let text = "<robot name=\"r\">\n<link name=\"a\"/><link name=\"b\"/><link name=\"c\"/>\n\
        <joint name=\"bc\" type=\"fixed\"><parent link=\"b\"/><child link=\"c\"/></joint>\n\
        <joint name=\"cb\" type=\"fixed\"><parent link=\"c\"/><child link=\"b\"/></joint>\n</robot>";
    let msg = urdf_error(text);
    assert_mentions(&msg, &["dir/bad.urdf:", "cycle", "expected a tree"]);
    assert!(msg.contains("bad.urdf:3:") || msg.contains("bad.urdf:4:"), "{msg}");
    // Every link a child: no root at all.
    let text = "<robot name=\"r\">\n<link name=\"b\"/><link name=\"c\"/>\n\
        <joint name=\"bc\" type=\"fixed\"><parent link=\"b\"/><child link=\"c\"/></joint>\n\
        <joint name=\"cb\" type=\"fixed\"><parent link=\"c\"/><child link=\"b\"/></joint>\n</robot>";
    assert_mentions(&urdf_error(text), &["dir/bad.urdf:1:", "cycle", "expected one root link"]);
    // Two roots.
    let msg = urdf_error("<robot name=\"r\">\n<link name=\"a\"/>\n<link name=\"b\"/>\n</robot>");
    assert_mentions(&msg, &["dir/bad.urdf:3:", "two roots", "`a` (line 2)", "expected exactly one root link"]);
    // A link with two parents.
    let text = "<robot name=\"r\">\n<link name=\"a\"/><link name=\"b\"/><link name=\"c\"/>\n\
        <joint name=\"ab\" type=\"fixed\"><parent link=\"a\"/><child link=\"b\"/></joint>\n\
        <joint name=\"cb\" type=\"fixed\"><parent link=\"c\"/><child link=\"b\"/></joint>\n</robot>";
    assert_mentions(
        &urdf_error(text),
        &["dir/bad.urdf:4:", "child of joint `ab` (line 3)", "expected one parent joint"],
    );
}

#[test]
fn error_unsupported_and_invalid_joints() {
    let joint = |body: &str| {
        format!(
            "{ONE_JOINT_HEAD}<joint name=\"j\" {body}\n  <parent link=\"a\"/>\n  <child link=\"b\"/>\n</joint>\n</robot>"
        )
    };
    assert_mentions(
        &urdf_error(&joint("type=\"floating\">")),
        &["dir/bad.urdf:4:", "`floating` joints are not supported"],
    );
    assert_mentions(&urdf_error(&joint("type=\"planar\">")), &["dir/bad.urdf:4:", "not supported"]);
    assert_mentions(
        &urdf_error(&joint("type=\"hinge\">")),
        &["dir/bad.urdf:4:", "unknown type `hinge`", "expected revolute"],
    );
    assert_mentions(&urdf_error(&joint("type=\"revolute\">")), &["dir/bad.urdf:4:", "no <limit>", "expected <limit"]);
    assert_mentions(
        &urdf_error(&joint("type=\"revolute\"><limit lower=\"1\" upper=\"-1\"/>")),
        &["dir/bad.urdf:4:", "lower limit 1 > upper limit -1"],
    );
    assert_mentions(
        &urdf_error(&joint("type=\"continuous\"><mimic joint=\"ghost\"/>")),
        &["dir/bad.urdf:4:", "mimics `ghost`", "expected the name of a non-fixed joint"],
    );
    assert_mentions(
        &urdf_error(&joint("type=\"continuous\"><axis xyz=\"0 0 0\"/>")),
        &["zero axis", "expected a non-zero"],
    );
}

#[test]
fn error_missing_and_unsupported_meshes() {
    let mesh = |file: &str| {
        format!(
            "<robot name=\"r\">\n<link name=\"a\">\n<collision><geometry>\n<mesh filename=\"{file}\"/>\n</geometry></collision></link></robot>"
        )
    };
    let urdf = fixture("inline.urdf");
    let parse = |text: &str, options: &UrdfOptions| parse_urdf(text, &urdf, options);
    let err = parse(&mesh("meshes/missing.stl"), &UrdfOptions::default()).expect_err("missing");
    let msg = err.to_string();
    assert_mentions(&msg, &["inline.urdf:4", "`meshes/missing.stl`", "fixtures/meshes/missing.stl", "not found"]);
    let ModelError::Mesh { resolved, line, .. } = &err else { panic!("{err:?}") };
    assert_eq!((resolved, *line), (&fixture("meshes/missing.stl"), 4));
    // PLY: not supported unless meshes are skipped; a missing Collada/OBJ file names every path tried.
    let err = parse(&mesh("meshes/arm.ply"), &UrdfOptions::default()).expect_err("ply");
    assert_mentions(&err.to_string(), &["inline.urdf:4", "`.ply` meshes are not supported", "expected STL, Collada"]);
    assert_mentions(
        &parse(&mesh("x.obj"), &UrdfOptions::default()).expect_err("obj").to_string(),
        &["`x.obj`", "not found", "--allow-missing-meshes"],
    );
    for f in ["meshes/missing.stl", "meshes/arm.ply", "x.obj"] {
        let robot = parse(&mesh(f), &no_meshes()).expect("skipped");
        assert!(robot.links()[0].shapes.is_empty());
    }
    // A file that is not an STL.
    let err = parse(&mesh("README.md.stl"), &UrdfOptions::default()).expect_err("missing");
    assert_mentions(&err.to_string(), &["not found"]);
    let err = parse(&mesh("package://onlyname"), &UrdfOptions::default()).expect_err("malformed");
    assert_mentions(&err.to_string(), &["inline.urdf:4", "expected package://NAME/path"]);
}

#[test]
fn unknown_srdf_group_is_a_warning_and_drops_the_reference() {
    // As in MoveIt's parser: the referring element is dropped, with a warning at its position.
    let text = "<robot name=\"r\">\n<group name=\"arm\"><chain base_link=\"a\" tip_link=\"b\"/></group>\n\
        <group_state name=\"home\" group=\"amr\">\n<joint name=\"j\" value=\"0\"/></group_state>\n</robot>";
    let srdf = parse_srdf(text, Path::new("dir/bad.srdf")).expect("loads");
    assert!(srdf.group_states.is_empty());
    let msg = srdf.warnings[0].to_string();
    assert_mentions(&msg, &["dir/bad.srdf:3:", "unknown group `amr`", "expected one of the groups", "arm"]);
    let text = "<robot name=\"r\">\n<group name=\"all\">\n<group name=\"arm\"/></group>\n</robot>";
    let srdf = parse_srdf(text, Path::new("dir/bad.srdf")).expect("loads");
    assert!(srdf.groups[0].subgroups.is_empty());
    assert_mentions(&srdf.warnings[0].to_string(), &["dir/bad.srdf:3:", "unknown group `arm`"]);
    let msg = parse_srdf(
        "<robot name=\"r\">\n<group_state name=\"x\" group=\"g\">\n<joint name=\"j\" value=\"1.0.0\"/>",
        Path::new("s.srdf"),
    )
    .expect_err("malformed")
    .to_string();
    assert_mentions(&msg, &["s.srdf:", "malformed XML"]);
    // A value that is not a number stays an error.
    let msg = parse_srdf(
        "<robot name=\"r\">\n<group name=\"g\"/>\n<group_state name=\"x\" group=\"g\">\n<joint name=\"j\" value=\"1.0.0\"/></group_state></robot>",
        Path::new("s.srdf"),
    )
    .expect_err("bad number")
    .to_string();
    assert_mentions(&msg, &["s.srdf:4:", "`1.0.0` is not a finite number"]);
    // Asking a robot for a group the SRDF does not define.
    let robot = ur5_spherized();
    let srdf = load_srdf(&fixture("ur5.srdf")).expect("parses");
    let msg = srdf.group_joints(&robot, "arm").expect_err("no such group").to_string();
    assert_mentions(&msg, &["ur5.srdf", "no group `arm`", "expected one of: manipulator, gripper"]);
}

#[test]
fn srdf_home_with_unknown_joint_is_a_warning_naming_the_srdf_line() {
    let urdf = fixture("tiny_gripper.urdf");
    let dir = std::env::temp_dir().join(format!("embodied-srdf-home-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let srdf = dir.join("tiny.srdf");
    std::fs::write(
        &srdf,
        "<robot name=\"tiny_gripper\">\n<group name=\"arm\"><joint name=\"shoulder\"/></group>\n\
        <group_state name=\"home\" group=\"arm\">\n<joint name=\"elbow\" value=\"0\"/></group_state>\n</robot>",
    )
    .expect("written");
    let d = embodied_models::formats::load_description(&urdf, Some(&srdf), &no_meshes()).expect("loads");
    let all: Vec<String> = d.warnings.iter().map(|w| w.to_string()).collect();
    assert!(
        all.iter().any(|w| w.contains("tiny.srdf:3:") && w.contains("`elbow`") && w.contains("ignored")),
        "{all:?}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// A `<disable_collisions>` naming a link the URDF lacks (VAMP's Fetch SRDF has
/// `torso_link_link_collision_2`) disables nothing and is a warning naming the line and the link;
/// the pairs around it still apply.
#[test]
fn srdf_disabled_pair_with_unknown_link_is_a_warning_naming_the_srdf_line() {
    let urdf = fixture("tiny_gripper.urdf");
    let dir = std::env::temp_dir().join(format!("embodied-srdf-pair-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let srdf = dir.join("pairs.srdf");
    std::fs::write(
        &srdf,
        "<robot name=\"tiny_gripper\">\n<disable_collisions link1=\"base\" link2=\"arm\"/>\n\
        <disable_collisions link1=\"arm\" link2=\"wirst\"/>\n<disable_collisions link1=\"wrist\" link2=\"finger_left\"/>\n\
        <disable_collisions link1=\"wirst\" link2=\"base\"/>\n</robot>",
    )
    .expect("written");
    let d = embodied_models::formats::load_description(&urdf, Some(&srdf), &no_meshes()).expect("loads");
    let all: Vec<String> = d.warnings.iter().map(|w| w.to_string()).collect();
    let named: Vec<&String> = all.iter().filter(|w| w.contains("`wirst`")).collect();
    assert_eq!(named.len(), 1, "{all:?}");
    assert!(
        named[0].contains("pairs.srdf:3:") && named[0].contains("its 2 disable_collisions pairs are ignored"),
        "{all:?}"
    );
    let index = |n: &str| d.robot.link_index(n).expect(n);
    let pair = |a: &str, b: &str| (index(a).min(index(b)), index(a).max(index(b)));
    let disabled = d.robot.disabled_pairs();
    assert!(disabled.contains(&pair("base", "arm")) && disabled.contains(&pair("wrist", "finger_left")));
    assert!(!disabled.contains(&pair("arm", "wrist")));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn error_missing_file_is_io() {
    let err = load_urdf(&fixture("nope.urdf"), None).expect_err("missing");
    assert!(matches!(err, ModelError::Io { .. }));
    assert_mentions(&err.to_string(), &["nope.urdf"]);
}

/// Two arms on a torso: independent groups when the torso is fixed (a mimic finger stays with
/// its arm), one group when a torso joint moves both arms.
#[test]
fn independent_dof_groups_follow_the_tree() {
    let arm = |side: &str, parent: &str| {
        format!(
            r#"<link name="{side}_upper"/><link name="{side}_lower"/><link name="{side}_finger"/>
            <joint name="{side}_shoulder" type="revolute"><parent link="{parent}"/><child link="{side}_upper"/>
              <axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
            <joint name="{side}_elbow" type="revolute"><parent link="{side}_upper"/><child link="{side}_lower"/>
              <origin xyz="0.3 0 0"/><axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
            <joint name="{side}_finger" type="prismatic"><parent link="{side}_lower"/><child link="{side}_finger"/>
              <origin xyz="0.3 0 0"/><axis xyz="1 0 0"/><limit lower="0" upper="0.04" effort="1" velocity="1"/>
              <mimic joint="{side}_elbow" multiplier="0.01"/></joint>"#
        )
    };
    let robot = |torso_joint: &str| {
        format!(
            r#"<robot name="two"><link name="base"/><link name="torso"/>
            <joint name="torso" type="{torso_joint}"><parent link="base"/><child link="torso"/>
              <axis xyz="0 0 1"/><limit lower="0" upper="0.3" effort="1" velocity="1"/></joint>
            {}{}</robot>"#,
            arm("left", "torso"),
            arm("right", "torso")
        )
    };
    let fixed = parse_urdf(&robot("fixed"), Path::new("two.urdf"), &no_meshes()).unwrap();
    assert_eq!(fixed.dof(), 4);
    assert_eq!(fixed.independent_dof_groups(), vec![vec![0, 1], vec![2, 3]]);
    let lift = parse_urdf(&robot("prismatic"), Path::new("two.urdf"), &no_meshes()).unwrap();
    assert_eq!(lift.dof(), 5);
    assert_eq!(lift.independent_dof_groups(), vec![vec![0, 1, 2, 3, 4]]);
    // The lift frozen: the arms part again (renumbered).
    let frozen = lift.freeze_joints(&[("torso", 0.1)]).unwrap();
    assert_eq!(frozen.independent_dof_groups(), vec![vec![0, 1], vec![2, 3]]);
    // The lift held (in no group): the arms part, numbered as before; an elbow held leaves its
    // shoulder in a group of its own; nothing held, or too short a mask: the plain groups.
    assert_eq!(lift.dof_groups_holding(&[true, false, false, false, false]), vec![vec![1, 2], vec![3, 4]]);
    assert_eq!(lift.dof_groups_holding(&[true, false, true, false, false]), vec![vec![1], vec![3, 4]]);
    assert_eq!(lift.dof_groups_holding(&[false; 5]), lift.independent_dof_groups());
    assert_eq!(lift.dof_groups_holding(&[]), lift.independent_dof_groups());
    // Where groups meet: the lift; none on a fixed torso, a chain or the built-in cell.
    assert_eq!(lift.branch_dofs(), [0]);
    assert!(fixed.branch_dofs().is_empty() && frozen.branch_dofs().is_empty());
    // The built-in cell: the track and its arm, then the postument arm (screws stay in each).
    let two = embodied_models::builtin("two-irp6").unwrap();
    assert_eq!(two.independent_dof_groups(), vec![(0..7).collect::<Vec<_>>(), (7..13).collect()]);
    let one = embodied_models::builtin("irp6-postument").unwrap();
    assert_eq!(one.independent_dof_groups(), vec![(0..6).collect::<Vec<_>>()]);
    assert!(two.branch_dofs().is_empty() && one.branch_dofs().is_empty());
}
