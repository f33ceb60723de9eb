//! Scenario parsing: errors carry file:line:column and what was expected.
#![allow(clippy::unwrap_used)]

use std::path::Path;

use embodied_system::scenario::{BUILTIN_SCENARIOS, parse_scenario};

fn err_of(text: &str) -> String {
    match parse_scenario(text, Path::new("bad.toml"), Path::new(".")) {
        Ok(_) => panic!("expected an error for:\n{text}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn builtin_scenarios_parse() {
    for (name, text) in BUILTIN_SCENARIOS {
        let sc = parse_scenario(text, Path::new(name), Path::new(".")).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(&sc.name, name);
        assert_eq!(sc.hash.len(), 64);
    }
}

#[test]
fn wrong_joint_count_names_line_and_column() {
    let e =
        err_of("name = \"x\"\ndescription = \"d\"\n[[agents]]\nname = \"a\"\nrobot = \"polycrank\"\nstart = [1, 2]\n");
    assert!(e.starts_with("bad.toml:6:9:"), "{e}");
    assert!(e.contains("7 joints, got 2"), "{e}");
}

#[test]
fn unknown_robot_names_line_and_builtins() {
    let e = err_of("name = \"x\"\ndescription = \"d\"\n[[agents]]\nname = \"a\"\nrobot = \"puma\"\n");
    assert!(e.starts_with("bad.toml:5:9:"), "{e}");
    assert!(e.contains("irp6-postument"), "{e}");
}

#[test]
fn unknown_key_and_syntax_errors() {
    let e = err_of("name = \"x\"\ndescription = \"d\"\n[[agents]]\nname = \"a\"\nrobt = \"puma\"\n");
    assert!(e.starts_with("bad.toml:5:1:") && e.contains("robt"), "{e}");
    let e = err_of("name = \"x\"\ndescription = \"d\"\n[[agents]\nname = \"a\"\n");
    assert!(e.starts_with("bad.toml:3:"), "{e}");
}

#[test]
fn obstacle_needs_exactly_one_shape() {
    let e = err_of(
        "name = \"x\"\ndescription = \"d\"\n[[agents]]\nname = \"a\"\nrobot = \"rnt\"\n[[obstacles]]\nname = \"o\"\nxyz = [0, 0, 0]\n",
    );
    assert!(e.starts_with("bad.toml:6:") && e.contains("exactly one shape"), "{e}");
    let e = err_of(
        "name = \"x\"\ndescription = \"d\"\n[[agents]]\nname = \"a\"\nrobot = \"rnt\"\n[[obstacles]]\nname = \"o\"\nbox = [1, -1, 1]\nxyz = [0, 0, 0]\n",
    );
    assert!(e.contains("positive"), "{e}");
}

#[test]
fn planner_clock_and_run_coordination_are_checked_with_their_place() {
    let base = "name = \"x\"\ndescription = \"d\"\n[[agents]]\nname = \"a\"\nrobot = \"rnt\"\n";
    let e = err_of(&format!("{base}[planner]\nclock = \"sundial\"\n"));
    assert!(e.starts_with("bad.toml:7:9:") && e.contains("\"wall\" or \"simulated\""), "{e}");
    let e = err_of(&format!("{base}[planner]\ndeadline_ms = 10\ngive_up_ms = 5\n"));
    assert!(e.starts_with("bad.toml:8:14:") && e.contains(">= deadline_ms"), "{e}");
    let e = err_of(&format!("{base}[run]\ncoordination = \"chaos\"\n"));
    assert!(e.starts_with("bad.toml:7:16:") && e.contains("\"sequential\" or \"concurrent\""), "{e}");
    let e = err_of(&format!("{base}[[obstacles]]\nname = \"o\"\nsphere = 0.1\nxyz = [0, 0, 0]\nappears_at = -1\n"));
    assert!(e.starts_with("bad.toml:10:14:") && e.contains("appear_at"), "{e}");
    // Both spellings of the appearance time are accepted.
    for key in ["appear_at", "appears_at"] {
        let text = format!("{base}[[obstacles]]\nname = \"o\"\nsphere = 0.1\nxyz = [0, 0, 0]\n{key} = 0.8\n");
        let sc = parse_scenario(&text, Path::new("ok.toml"), Path::new(".")).unwrap();
        assert_eq!(sc.obstacles[0].appear_at, Some(0.8));
        assert!(!sc.obstacles[0].on_map());
    }
}

#[test]
fn edge_check_is_certified_by_default_and_checked_with_its_place() {
    let base = "name = \"x\"\ndescription = \"d\"\n[[agents]]\nname = \"a\"\nrobot = \"polycrank\"\n";
    let sc = parse_scenario(base, Path::new("ok.toml"), Path::new(".")).unwrap();
    assert!(sc.planner.certify);
    let sampled = format!("{base}[planner]\nedge_check = \"sampled\"\n");
    assert!(!parse_scenario(&sampled, Path::new("ok.toml"), Path::new(".")).unwrap().planner.certify);
    let e = err_of(&format!("{base}[planner]\nedge_check = \"exact\"\n"));
    assert!(e.starts_with("bad.toml:7:14:"), "{e}");
    assert!(e.contains("\"certified\" or \"sampled\""), "{e}");
}

#[test]
fn non_finite_poses_are_refused_with_their_place() {
    let base = "name = \"x\"\ndescription = \"d\"\n[[agents]]\nname = \"a\"\nrobot = \"irp6-postument\"\n";
    let e = err_of(&format!("{base}goal_pose = {{ xyz = [0.5, 0.6, nan], rpy = [0.0, 1.5, 0.0] }}\n"));
    assert!(e.starts_with("bad.toml:6:") && e.contains("goal_pose: expected finite numbers"), "{e}");
    let e = err_of(&format!("{base}goal_pose = {{ xyz = [0.5, 0.6, 1.0], rpy = [0.0, inf, 0.0] }}\n"));
    assert!(e.starts_with("bad.toml:6:") && e.contains("rpy [0.0, inf, 0.0]"), "{e}");
    for bad in ["xyz = [0, nan, 0]", "xyz = [0, 0, 0]\nrpy = [0, 0, -inf]", "xyz = [0, 0, 0]\nvelocity = [nan, 0, 0]"] {
        let e = err_of(&format!("{base}[[obstacles]]\nname = \"o\"\nsphere = 0.1\n{bad}\n"));
        assert!(e.starts_with("bad.toml:6:") && e.contains("obstacle `o`: expected finite numbers"), "{bad}: {e}");
    }
}

/// The repository's test fixtures.
fn fixtures() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures")
}

#[test]
fn a_moveit_scene_gives_obstacles_on_the_map_where_the_table_places_it() {
    let dir = fixtures().join("mbm/problems/box_ur5");
    let text = "name = \"x\"\ndescription = \"d\"\n[[agents]]\nname = \"a\"\nrobot = \"irp6-postument\"\n[moveit_scene]\nfile = \"scene0001.yaml\"\nxyz = [1.0, 0.5, 0.0]\nrpy = [0, 0, 1.5707963267948966]\n";
    let sc = parse_scenario(text, &dir.join("s.toml"), &dir).unwrap();
    let scene = embodied_models::formats::moveit::load_scene(&dir.join("scene0001.yaml")).unwrap();
    let expected = scene.obstacles();
    assert!(!expected.is_empty());
    assert_eq!(sc.obstacles.len(), expected.len());
    for (got, want) in sc.obstacles.iter().zip(&expected) {
        assert_eq!(got.obstacle.name, want.name);
        assert!(got.appear_at.is_none() && got.velocity.is_none(), "a scene's objects are on the map");
        // Turned a quarter about z, then moved by (1, 0.5, 0): scene (x, y) -> world (1 - y, 0.5 + x).
        let (w, s) = (got.obstacle.pose.translation.vector, want.pose.translation.vector);
        assert!((w.x - (1.0 - s.y)).abs() < 1e-9 && (w.y - (0.5 + s.x)).abs() < 1e-9 && (w.z - s.z).abs() < 1e-9);
    }
    assert_eq!(sc.initial_environment().obstacles().len(), expected.len());
}

#[test]
fn a_bad_moveit_scene_is_an_error_naming_its_file_and_place() {
    let dir = std::env::temp_dir().join(format!("embodied-scene-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let toml = |file: &str| {
        format!(
            "name = \"x\"\ndescription = \"d\"\n[[agents]]\nname = \"a\"\nrobot = \"rnt\"\n[moveit_scene]\nfile = \"{file}\"\n"
        )
    };
    let parse = |text: &str| parse_scenario(text, &dir.join("s.toml"), &dir).map(|_| ()).unwrap_err().to_string();
    // Missing file.
    let e = parse(&toml("nowhere.yaml"));
    assert!(e.contains("nowhere.yaml"), "{e}");
    // A wrong value, with the scene file's own line and column.
    std::fs::write(dir.join("bad.yaml"), "world:\n  collision_objects:\n    - id: b\n      primitives:\n        - type: box\n          dimensions: [1, -2, 1]\n      primitive_poses:\n        - position: [0, 0, 0]\n").unwrap();
    let e = parse(&toml("bad.yaml"));
    assert!(e.contains("bad.yaml:6:") && e.contains("positive"), "{e}");
    // An object in a frame the scenario does not have.
    std::fs::write(dir.join("frame.yaml"), "world:\n  collision_objects:\n    - id: b\n      header: {frame_id: table_link}\n      primitives: [{type: sphere, dimensions: [0.1]}]\n      primitive_poses: [{position: [0, 0, 0]}]\n").unwrap();
    let e = parse(&toml("frame.yaml"));
    assert!(e.contains("frame.yaml:3:") && e.contains("table_link"), "{e}");
    // A name clash with a scenario obstacle.
    std::fs::write(dir.join("clash.yaml"), "world:\n  collision_objects:\n    - id: o\n      primitives: [{type: sphere, dimensions: [0.1]}]\n      primitive_poses: [{position: [0, 0, 0]}]\n").unwrap();
    let e = parse(&format!("{}[[obstacles]]\nname = \"o\"\nsphere = 0.1\nxyz = [2, 0, 0]\n", toml("clash.yaml")));
    assert!(e.contains("`o`") && e.contains("another obstacle"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn mesh_obstacles_read_stl_collada_and_obj() {
    let dir = fixtures().join("corpus/pybullet_data/franka_panda/meshes/collision");
    let text = "name = \"x\"\ndescription = \"d\"\n[[agents]]\nname = \"a\"\nrobot = \"rnt\"\n[[obstacles]]\nname = \"link\"\nmesh = \"link0.obj\"\nxyz = [2, 0, 0]\n";
    let sc = parse_scenario(text, &dir.join("s.toml"), &dir).unwrap();
    assert!(matches!(sc.obstacles[0].obstacle.shape, embodied_models::Shape::ConvexMesh(_)));
    let e = err_of(
        "name = \"x\"\ndescription = \"d\"\n[[agents]]\nname = \"a\"\nrobot = \"rnt\"\n[[obstacles]]\nname = \"m\"\nmesh = \"part.step\"\nxyz = [0, 0, 0]\n",
    );
    assert!(e.starts_with("bad.toml:6:") && e.contains(".step") && e.contains(".obj"), "{e}");
}
