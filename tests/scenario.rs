//! Scenario parsing: errors carry file:line:column and what was expected.
#![allow(clippy::unwrap_used)]

use std::path::Path;

use embodied::scenario::{BUILTIN_SCENARIOS, parse_scenario};

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
