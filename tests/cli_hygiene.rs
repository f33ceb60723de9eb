//! The binary behaves: a closed pipe, exit statuses, write errors, standard input, help.
#![allow(clippy::unwrap_used)]

mod common;
use std::io::{Read, Write};
use std::process::{Command, Stdio};

use common::{TempDir, embodied};

/// `embodied plan X | head -c 100`: the reader closes the pipe early; the program stops
/// quietly (status 0, nothing on standard error, no panic).
#[test]
fn a_closed_pipe_ends_the_output_quietly() {
    let mut child = Command::new(env!("CARGO_BIN_EXE_embodied"))
        .args(["plan", "two-irp6-cell"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdout = child.stdout.take().unwrap();
    let mut first = [0u8; 100];
    stdout.read_exact(&mut first).unwrap();
    assert!(first.starts_with(b"{\"format\""), "{}", String::from_utf8_lossy(&first));
    drop(stdout);
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(err.is_empty(), "stderr: {err}");
}

#[test]
fn exit_status_0_success_1_not_succeeded_2_bad_input() {
    let dir = TempDir::new("exit");
    // 0: planned.
    let (code, _, err) = embodied(&["plan", "polycrank-transfer", "-o", dir.join("p.json").to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    // 1: the input is fine but no plan in time (a 0 ms deadline).
    let (code, _, err) = embodied(&["plan", "irp6-pick", "--deadline-ms", "0"]);
    assert_eq!(code, 1, "{err}");
    assert!(err.starts_with("error: "), "{err}");
    // 1: the run ran, the force limit stopped the arm, its goal was not reached.
    let (code, out, err) = embodied(&["run", "rnt-polish", "--duration", "1.0"]);
    assert_eq!(code, 1, "{out}{err}");
    assert!(err.contains("goal not reached by: rnt"), "{err}");
    // 2: bad input.
    let (code, _, err) = embodied(&["plan", "no-such-scenario"]);
    assert_eq!(code, 2, "{err}");
    let (code, _, _) = embodied(&["run", "--duration", "-1"]);
    assert_eq!(code, 2);
    for (flag, says) in [
        ("--shortcut-min-gain=-0.1", "--shortcut-min-gain must be zero or a positive number"),
        ("--shortcut-min-gain=nan", "--shortcut-min-gain must be zero or a positive number"),
        ("--screen-above=-1", "--screen-above must be zero, a positive number or inf"),
        ("--screen-above=nan", "--screen-above must be zero, a positive number or inf"),
        ("--rrt-local-bias=1.5", "--rrt-local-bias must be a share in [0, 1]"),
        ("--rrt-local-bias=-0.1", "--rrt-local-bias must be a share in [0, 1]"),
        ("--rrt-local-bias=nan", "--rrt-local-bias must be a share in [0, 1]"),
        ("--rrt-late-local-bias=1.01", "--rrt-late-local-bias must be a share in [0, 1]"),
        ("--rrt-late-local-bias=nan", "--rrt-late-local-bias must be a share in [0, 1]"),
        ("--rrt-local-span=0", "--rrt-local-span must be a positive share"),
        ("--rrt-local-span=-1", "--rrt-local-span must be a positive share"),
        ("--rrt-local-span=inf", "--rrt-local-span must be a positive share"),
        ("--rrt-local-reach=0", "--rrt-local-reach must be above 0"),
        ("--rrt-local-reach=-2", "--rrt-local-reach must be above 0"),
        ("--rrt-local-reach=nan", "--rrt-local-reach must be above 0"),
        ("--max-samples=0", "--max-samples must be at least 1"),
        ("--lazy-probe=-0.1", "--lazy-probe must be 0 (every tree edge certified as added) or a positive number"),
        ("--lazy-probe=nan", "--lazy-probe must be 0 (every tree edge certified as added) or a positive number"),
        ("--lazy-probe=inf", "--lazy-probe must be 0 (every tree edge certified as added) or a positive number"),
        ("--racer-look-ms=-1", "--racer-look-ms must be a number of ms, at least 0"),
        ("--racer-look-ms=nan", "--racer-look-ms must be a number of ms, at least 0"),
        ("--racer-look-ms=inf", "--racer-look-ms must be a number of ms, at least 0"),
        ("--threads=0", "--threads must be `auto` or a count of at least 1, got `0`"),
        ("--threads=two", "--threads must be `auto` or a count of at least 1, got `two`"),
        ("--threads=-1", "--threads must be `auto` or a count of at least 1, got `-1`"),
    ] {
        let args = ["bench", "mbm", "--urdf", "u.urdf", "--srdf", "u.srdf", "--problems", "none", flag];
        let (code, _, err) = embodied(&args);
        assert_eq!(code, 2, "{flag}: {err}");
        assert!(err.contains(says), "{flag}: {err}");
    }
    let (code, _, err) = embodied(&["bench", "deadlines", "--scenarios", "irp6-pick", "--planner-seeds", "0"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--planner-seeds must be at least 1, got 0"), "{err}");
    // The statuses are documented in --help.
    let (code, out, _) = embodied(&["--help"]);
    assert_eq!(code, 0);
    assert!(out.contains("Exit status: 0 success; 1 the work was done but did not succeed"), "{out}");
}

#[test]
fn a_file_that_cannot_be_written_is_named_as_such() {
    let dir = TempDir::new("write");
    let target = dir.join("no-such-folder").join("plan.json");
    let (code, _, err) = embodied(&["plan", "polycrank-transfer", "-o", target.to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("cannot write") && err.contains("no-such-folder"), "{err}");
    let log = dir.join("no-such-folder").join("run.jsonl");
    let (code, _, err) = embodied(&["run", "--duration", "0.01", "--log", log.to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("cannot write"), "{err}");
    let (code, _, err) = embodied(&["verify", "polycrank-transfer", dir.join("missing.json").to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("cannot read") && err.contains("missing.json"), "{err}");
}

fn with_stdin(args: &[&str], input: &[u8]) -> (i32, String, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_embodied"))
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    child.stdin.take().unwrap().write_all(input).unwrap();
    let out = child.wait_with_output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn a_dash_reads_standard_input() {
    let dir = TempDir::new("stdin");
    let plan = dir.join("p.json");
    let (code, _, err) = embodied(&["plan", "polycrank-transfer", "-o", plan.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let text = std::fs::read(&plan).unwrap();
    // The plan file from standard input.
    let (code, out, err) = with_stdin(&["verify", "polycrank-transfer", "-"], &text);
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("CERTIFIED"), "{out}");
    // The scenario from standard input.
    let scenario = "name = \"piped\"\ndescription = \"from stdin\"\n[[agents]]\nname = \"p\"\nrobot = \"polycrank\"\n\
                    goal = [0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]\n";
    let (code, out, err) = with_stdin(&["plan", "-"], scenario.as_bytes());
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("\"name\":\"piped\""), "{out}");
    // Bad text on standard input is named as such.
    let (code, _, err) = with_stdin(&["plan", "-"], b"name = ");
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("<stdin>:1:"), "{err}");
}

#[test]
fn version_names_the_commit_and_files_name_the_version() {
    let (code, out, _) = embodied(&["--version"]);
    assert_eq!(code, 0);
    // `embodied 0.1.0 (commit 0123456789ab)`, or `(commit unknown)` when built outside git.
    let expected = format!("embodied {} (commit ", env!("CARGO_PKG_VERSION"));
    assert!(out.starts_with(&expected) && out.trim_end().ends_with(')'), "{out}");
    let commit = out.trim_end().trim_start_matches(&expected).trim_end_matches(')');
    assert!(commit == "unknown" || (commit.len() == 12 && commit.chars().all(|c| c.is_ascii_hexdigit())), "{out}");
    let dir = TempDir::new("version");
    let plan = dir.join("p.json");
    let log = dir.join("r.jsonl");
    assert_eq!(embodied(&["plan", "polycrank-transfer", "-o", plan.to_str().unwrap()]).0, 0);
    assert_eq!(embodied(&["run", "polycrank-transfer", "--duration", "0.05", "--log", log.to_str().unwrap()]).0, 1);
    let generator = format!("embodied {}", out.trim_end().trim_start_matches("embodied "));
    let plan_json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&plan).unwrap()).unwrap();
    assert_eq!(plan_json["generator"], generator.as_str());
    let header = std::fs::read_to_string(&log).unwrap();
    let header: serde_json::Value = serde_json::from_str(header.lines().next().unwrap()).unwrap();
    assert_eq!(header["header"]["generator"], generator.as_str());
    let (code, out, _) = embodied(&["verify", "polycrank-transfer", plan.to_str().unwrap(), "--json"]);
    assert_eq!(code, 0);
    let report: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(report["generator"], generator.as_str());
}

#[test]
fn completions_and_a_man_page_come_from_the_command_definitions() {
    for shell in ["bash", "zsh", "fish", "elvish", "powershell"] {
        let (code, out, err) = embodied(&["completions", shell]);
        assert_eq!(code, 0, "{shell}: {err}");
        for verb in ["run", "plan", "verify", "view", "bench"] {
            assert!(out.contains(verb), "{shell} completion lacks `{verb}`");
        }
    }
    let (code, out, _) = embodied(&["completions", "bash"]);
    assert_eq!(code, 0);
    assert!(out.contains("--html") && out.contains("--deadline-ms"), "bash completion lacks options");
    let (code, _, err) = embodied(&["completions", "tcsh"]);
    assert_eq!(code, 2, "{err}");
    let (code, out, _) = embodied(&["man"]);
    assert_eq!(code, 0);
    assert!(out.starts_with(".ie") || out.contains(".TH embodied"), "{}", &out[..out.len().min(200)]);
    assert!(out.contains("Exit status") && out.contains("completions"), "the page lacks the exit statuses or verbs");
}

/// `bench mbm` races as many planners as the process has cores, at most two, unless told:
/// the report says how many ran (`taskset -c 1` makes it one, as `compare-mbm` runs it).
#[test]
fn bench_mbm_races_one_planner_a_core_up_to_two() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let fixtures = root.join("models/tests/fixtures");
    let (urdf, srdf, problems) =
        (fixtures.join("ur5_spherized.urdf"), fixtures.join("ur5.srdf"), root.join("tests/fixtures/mbm/problems"));
    let base = [
        "bench",
        "mbm",
        "--urdf",
        urdf.to_str().unwrap(),
        "--srdf",
        srdf.to_str().unwrap(),
        "--problems",
        problems.to_str().unwrap(),
        "--limit",
        "1",
        "--json",
    ];
    let cores = std::thread::available_parallelism().map_or(1, usize::from);
    for (flag, racers) in [(None, cores.min(2)), (Some("--threads=auto"), cores.min(2)), (Some("--threads=3"), 3)] {
        let mut args = base.to_vec();
        args.extend(flag);
        let (code, out, err) = embodied(&args);
        assert_eq!(code, 0, "{flag:?}: {err}");
        let report: serde_json::Value = serde_json::from_str(&out).unwrap();
        assert_eq!(report["settings"]["threads"], racers, "{flag:?}");
        let overall = &report["overall"];
        assert!(overall["valid"].as_u64() >= Some(1) && overall["solved"] == overall["valid"], "{out}");
    }
}
