//! Mesh formats (STL, Collada, OBJ), convex decomposition, missing meshes, package lookup,
//! robots without a name, `.xacro`, `joint_limits.yaml` and JointTrajectory files.

use std::path::{Path, PathBuf};

use embodied_models::formats::joint_limits::parse_joint_limits;
use embodied_models::formats::mesh::{Decomposition, TriMesh, convex_pieces, enclosed_volume, hull_volume, read_mesh};
use embodied_models::formats::trajectory::parse_joint_trajectory;
use embodied_models::formats::{load_description, urdf::UrdfOptions};
use embodied_models::nalgebra::{Point3, Vector3};
use embodied_models::urdf::parse_urdf_with;
use embodied_models::{ModelError, Shape};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures").join(name)
}

fn bounds(mesh: &TriMesh) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in &mesh.vertices {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}

fn close(a: [f64; 3], b: [f64; 3]) -> bool {
    a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-6)
}

#[test]
fn obj_collada_and_stl_are_read_with_scale_units_and_node_transforms() {
    let cube = read_mesh(&fixture("meshes/cube.obj"), Vector3::new(2.0, 1.0, 0.5)).expect("obj");
    assert_eq!(cube.triangles.len(), 12);
    let (lo, hi) = bounds(&cube);
    assert!(close(lo, [0.0; 3]) && close(hi, [2.0, 1.0, 0.5]), "{lo:?} {hi:?}");
    assert!((enclosed_volume(&cube).expect("closed") - 1.0).abs() < 1e-9);
    // Collada: 100 units of 1 cm = 1 m, and the node's translation of 0.5 is applied (in metres:
    // mesh-loader scales vertices by `<unit>` but not node translations; see formats::mesh).
    let tetra = read_mesh(&fixture("meshes/tetra.dae"), Vector3::repeat(1.0)).expect("dae");
    let (lo, hi) = bounds(&tetra);
    assert!(close(lo, [0.5, 0.0, 0.0]) && close(hi, [1.5, 1.0, 1.0]), "{lo:?} {hi:?}");
    let stl = read_mesh(&fixture("meshes/tetra_binary.stl"), Vector3::repeat(1.0)).expect("stl");
    assert_eq!(stl.triangles.len(), 4);
    for bad in ["meshes/broken.obj", "meshes/broken.dae"] {
        let err = read_mesh(&fixture(bad), Vector3::repeat(1.0)).expect_err(bad);
        assert!(!err.is_empty());
    }
    let err = read_mesh(&fixture("meshes/x.ply"), Vector3::repeat(1.0)).expect_err("ply");
    assert!(err.contains("`.ply` meshes are not supported"), "{err}");
}

/// A closed U-shaped prism: the outline (0,0) (3,0) (3,3) (2.5,3) (2.5,0.5) (0.5,0.5) (0.5,3)
/// (0,3), extruded from z = 0 to 1. Volume 4; its hull's volume 9.
fn u_prism() -> TriMesh {
    let outline = [[0.0, 0.0], [3.0, 0.0], [3.0, 3.0], [2.5, 3.0], [2.5, 0.5], [0.5, 0.5], [0.5, 3.0], [0.0, 3.0]];
    let n = outline.len() as u32;
    let mut vertices = Vec::new();
    for z in [0.0, 1.0] {
        vertices.extend(outline.iter().map(|p| Point3::new(p[0], p[1], z)));
    }
    let mut triangles = Vec::new();
    for i in 0..n {
        let j = (i + 1) % n;
        triangles.push([i, j, n + j]);
        triangles.push([i, n + j, n + i]);
    }
    // Caps: the bottom bar and the two posts, two triangles each.
    let cap = [[0, 1, 4], [0, 4, 5], [1, 2, 3], [1, 3, 4], [0, 5, 6], [0, 6, 7]];
    for t in cap {
        triangles.push([t[0], t[2], t[1]]);
        triangles.push([n + t[0], n + t[1], n + t[2]]);
    }
    TriMesh { vertices, triangles }
}

#[test]
fn a_concave_closed_mesh_is_decomposed_and_a_convex_one_is_not() {
    let u = u_prism();
    let inside = enclosed_volume(&u).expect("the U prism is closed");
    assert!((inside - 4.0).abs() < 1e-9, "volume {inside}");
    let rule = Decomposition::default();
    let pieces = convex_pieces(&u, Some(&rule)).expect("pieces");
    assert!(pieces.len() > 1, "hull 9 > 2 x 4 should decompose, got {} piece", pieces.len());
    let total: f64 = pieces.iter().map(|p| hull_volume(p)).sum();
    assert!(total < 9.0 * 0.9, "pieces cover {total}, the single hull 9");
    // Without the rule, or for a convex mesh, one hull.
    assert_eq!(convex_pieces(&u, None).expect("hull").len(), 1);
    let cube = read_mesh(&fixture("meshes/cube.obj"), Vector3::repeat(1.0)).expect("obj");
    assert_eq!(convex_pieces(&cube, Some(&rule)).expect("hull").len(), 1);
}

fn write_temp(name: &str, text: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("embodied-formats-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let p = dir.join(name);
    std::fs::write(&p, text).expect("written");
    p
}

fn mesh_robot(collision: &str, visual: &str) -> String {
    format!(
        r#"<robot name="m"><link name="a">
  <visual><geometry><mesh filename="{visual}"/></geometry></visual>
  <collision><geometry><mesh filename="{collision}"/></geometry></collision>
</link></robot>"#
    )
}

#[test]
fn missing_visual_meshes_never_stop_a_load_and_missing_collision_meshes_are_errors_or_dropped() {
    let urdf = fixture("inline.urdf");
    let options = UrdfOptions { use_environment: false, ..UrdfOptions::default() };
    let load = parse_urdf_with(&mesh_robot("meshes/cube.obj", "meshes/nowhere.dae"), &urdf, &options, None)
        .expect("a missing visual mesh is fine");
    assert!(matches!(load.robot.links()[0].shapes[0].shape, Shape::ConvexMesh(_)));
    let text = mesh_robot("package://nopkg/meshes/gone.stl", "meshes/cube.obj");
    let err = parse_urdf_with(&text, &urdf, &options, None).expect_err("missing collision mesh");
    let msg = err.to_string();
    assert!(matches!(err, ModelError::Mesh { .. }));
    for part in ["inline.urdf:3", "gone.stl", "tried:", "fixtures/nopkg/meshes/gone.stl", "--allow-missing-meshes"] {
        assert!(msg.contains(part), "`{msg}` lacks `{part}`");
    }
    let allow = UrdfOptions { allow_missing_meshes: true, ..options.clone() };
    let load = parse_urdf_with(&text, &urdf, &allow, None).expect("dropped");
    assert!(load.robot.links()[0].shapes.is_empty());
    assert_eq!(load.warnings.len(), 1);
    assert!(load.warnings[0].to_string().contains("inline.urdf:3:"), "{}", load.warnings[0]);
}

#[test]
fn package_uris_with_three_slashes_package_dirs_and_ament_prefixes() {
    let urdf = Path::new("/nowhere/r.urdf");
    let text = mesh_robot("package:///meshes/cube.obj", "x.stl");
    // `package:///meshes/...`: the package `meshes` is the fixtures' meshes folder.
    let options =
        UrdfOptions { package_dirs: vec![fixture("meshes")], use_environment: false, ..UrdfOptions::default() };
    let load = parse_urdf_with(&text, urdf, &options, None).expect("package:/// and --package-path");
    assert_eq!(load.robot.links()[0].shapes.len(), 1);
    // A folder containing the package works too.
    let options = UrdfOptions { package_dirs: vec![fixture("")], ..options };
    assert!(parse_urdf_with(&text, urdf, &options, None).is_ok());
}

#[test]
fn a_robot_without_a_name_takes_the_file_stem_with_a_warning() {
    let text = r#"<robot><link name="a"/></robot>"#;
    let load = parse_urdf_with(text, Path::new("dir/my_arm.urdf"), &UrdfOptions::default(), None).expect("loads");
    assert_eq!(load.robot.name(), "my_arm");
    assert!(load.warnings[0].to_string().contains("dir/my_arm.urdf:1:1"), "{}", load.warnings[0]);
}

#[test]
fn a_xacro_file_needs_the_xacro_program() {
    let p = write_temp("r.urdf.xacro", "<robot name=\"r\"><link name=\"a\"/></robot>");
    // Whether xacro is installed or not, the outcome is stated: a robot, or an error naming xacro.
    match load_description(&p, None, &UrdfOptions::default()) {
        Ok(d) => assert_eq!(d.robot.name(), "r"),
        Err(e) => assert!(e.to_string().contains("xacro"), "{e}"),
    }
    let no_path = std::process::Command::new("xacro").arg("--version").output().is_err();
    if no_path {
        let e = load_description(&p, None, &UrdfOptions::default()).expect_err("no xacro");
        assert!(e.to_string().contains("needs the `xacro` program"), "{e}");
    }
    // Passed: the temporary folder goes (a failure keeps it for a look).
    if let Some(dir) = p.parent() {
        let _ = std::fs::remove_dir_all(dir);
    }
}

#[test]
fn joint_limits_yaml_sets_accelerations() {
    let urdf = r#"<robot name="r"><link name="a"/><link name="b"/>
<joint name="j" type="revolute"><parent link="a"/><child link="b"/><limit lower="-1" upper="1" velocity="2"/></joint></robot>"#;
    let mut robot = parse_urdf_with(urdf, Path::new("r.urdf"), &UrdfOptions::default(), None).expect("loads").robot;
    assert_eq!(robot.limits()[0].max_acceleration, 10.0);
    let text = "joint_limits:\n  j:\n    has_velocity_limits: true\n    max_velocity: 1.5\n    has_acceleration_limits: true\n    max_acceleration: 3.25\n";
    let limits = parse_joint_limits(text, Path::new("joint_limits.yaml")).expect("parses");
    assert_eq!(limits.apply(&mut robot).expect("applies"), 1);
    assert_eq!((robot.limits()[0].max_velocity, robot.limits()[0].max_acceleration), (1.5, 3.25));
    assert!(robot.provenance().contains("joint_limits.yaml"));
    // Flags false: nothing applied; a joint of another robot: an error naming the line.
    let text = "joint_limits:\n  j:\n    has_acceleration_limits: false\n    max_acceleration: 0\n  k:\n    has_velocity_limits: false\n";
    let limits = parse_joint_limits(text, Path::new("jl.yaml")).expect("parses");
    let err = limits.apply(&mut robot).expect_err("unknown joint k").to_string();
    assert!(err.contains("jl.yaml:5:") && err.contains("`k`"), "{err}");
    let err = parse_joint_limits("joint_limits:\n  j:\n    has_acceleration_limits: true\n", Path::new("jl.yaml"))
        .expect_err("missing max_acceleration")
        .to_string();
    assert!(err.contains("jl.yaml:3:") && err.contains("max_acceleration"), "{err}");
}

#[test]
fn joint_trajectories_read_ros1_and_ros2_times_and_refuse_bad_points() {
    let ros1 = "joint_names: [a, b]\npoints:\n  - positions: [0, 1]\n    time_from_start: {secs: 0, nsecs: 0}\n  - positions: [1, 2]\n    velocities: []\n    time_from_start: {secs: 1, nsecs: 500000000}\n";
    let t = parse_joint_trajectory(ros1, Path::new("t.yaml")).expect("ros1");
    assert_eq!(t.points[1].time_from_start, 1.5);
    let wrapped = format!("joint_trajectory:\n{}", ros1.lines().map(|l| format!("  {l}\n")).collect::<String>());
    assert_eq!(parse_joint_trajectory(&wrapped, Path::new("t.yaml")).expect("RobotTrajectory"), t);
    let back = parse_joint_trajectory(&t.to_json(), Path::new("t.json")).expect("json");
    assert_eq!(back, t);
    let bad = "joint_names: [a, b]\npoints:\n  - positions: [0, 1]\n    time_from_start: {sec: 1}\n  - positions: [1]\n    time_from_start: {sec: 2}\n";
    let err = parse_joint_trajectory(bad, Path::new("t.yaml")).expect_err("short").to_string();
    assert!(err.contains("t.yaml:5:") && err.contains("2 numbers"), "{err}");
    let bad = "joint_names: [a]\npoints:\n  - positions: [0]\n    time_from_start: {sec: 1}\n  - positions: [1]\n    time_from_start: {sec: 1}\n";
    let err = parse_joint_trajectory(bad, Path::new("t.yaml")).expect_err("not increasing").to_string();
    assert!(err.contains("t.yaml:6:") && err.contains("increasing"), "{err}");
}
