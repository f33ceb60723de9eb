//! Every program in `examples/` runs (cargo builds them for `cargo test`) and does what it says.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// `target/<profile>/examples/NAME`, next to this test's `deps/` directory.
fn example(name: &str) -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    let profile_dir = exe.parent().and_then(Path::parent).unwrap();
    profile_dir.join("examples").join(format!("{name}{}", std::env::consts::EXE_SUFFIX))
}

/// The arguments each example is run with here, and a text its output must contain.
fn invocation(name: &str) -> Option<(Vec<String>, &'static str)> {
    let fixtures = root().join("models/tests/fixtures");
    let ur5 = [
        fixtures.join("ur5_spherized.urdf").display().to_string(),
        fixtures.join("ur5.srdf").display().to_string(),
        root().join("tests/fixtures/mbm/problems").display().to_string(),
    ];
    match name {
        "two_arms" => Some((Vec::new(), "goals reached: true")),
        "collision_work" => Some(([&ur5[..], &["2".to_string(), "1".to_string()]].concat(), "ns")),
        "mbm" => Some((ur5.to_vec(), "box_ur5")),
        _ => None,
    }
}

#[test]
fn every_example_runs_and_does_what_it_says() {
    let mut ran = Vec::new();
    for entry in std::fs::read_dir(root().join("examples")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().and_then(|e| e.to_str()) != Some("rs") {
            continue;
        }
        let name = path.file_stem().unwrap().to_string_lossy().into_owned();
        let (args, expected) =
            invocation(&name).unwrap_or_else(|| panic!("examples/{name}.rs: add how to run it to tests/examples.rs"));
        let bin = example(&name);
        if !bin.exists() {
            // `cargo test --test examples` alone does not build the examples; `cargo test` does.
            let status =
                Command::new(env!("CARGO")).args(["build", "--example", &name]).current_dir(root()).status().unwrap();
            assert!(status.success() && bin.exists(), "{} could not be built", bin.display());
        }
        let out = Command::new(&bin).args(&args).output().unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(out.status.success(), "{name}: {}\n{stdout}\n{}", out.status, String::from_utf8_lossy(&out.stderr));
        assert!(stdout.contains(expected), "{name}: `{expected}` not in\n{stdout}");
        ran.push(name);
    }
    ran.sort();
    assert!(ran.contains(&"two_arms".to_string()), "{ran:?}");
}

#[test]
fn the_code_built_system_example_is_short() {
    // The point of the example: a two-agent system with a coordinator fits in a page of code.
    let text = std::fs::read_to_string(root().join("examples/two_arms.rs")).unwrap();
    assert!(text.lines().count() < 60, "{} lines", text.lines().count());
}
