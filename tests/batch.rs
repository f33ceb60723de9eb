//! Batch work across processes: `--shard K/N` with `--jsonl`, `bench merge`, `plan --batch`,
//! and `bench mbm --ompl-log` (on the small MotionBenchMaker fixture and built-in scenarios).
#![allow(clippy::unwrap_used)]

mod common;
use std::path::{Path, PathBuf};

use common::{TempDir, embodied};
use embodied::AppError;
use embodied::batch::{JsonlWriter, Shard, read_shards};
use embodied::mbm::{MbmArgs, MbmReport, ProblemResult, ProblemStatus, merge_mbm, render_table, run_mbm_to};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn mbm_args() -> MbmArgs {
    let robot = root().join("models/tests/fixtures");
    let mut a =
        MbmArgs::new(robot.join("ur5_spherized.urdf"), robot.join("ur5.srdf"), root().join("tests/fixtures/mbm"));
    // Far from the planner's needs: no problem stops at the deadline, so results depend on the
    // seed alone.
    a.deadline_ms = 20_000.0;
    a
}

fn run_to(args: &MbmArgs, path: &Path) -> MbmReport {
    let file = std::fs::File::create(path).unwrap();
    let mut w = JsonlWriter::new(path, Box::new(file));
    run_mbm_to(args, &mut |_, _| {}, Some(&mut w)).expect("benchmark runs")
}

/// What a problem's result is apart from wall-clock time.
fn deterministic(r: &ProblemResult) -> serde_json::Value {
    let mut stats = r.stats.clone();
    if let Some(s) = stats.as_mut().and_then(serde_json::Value::as_object_mut) {
        s.remove("elapsed");
    }
    serde_json::json!({
        "family": r.family, "index": r.index, "run": r.run, "status": r.status, "solved": r.solved,
        "path": r.path, "path_length": r.path_length, "verified": r.verified, "stats": stats,
        "message": r.message, "joint_names": r.joint_names,
    })
}

fn lines(path: &Path) -> Vec<String> {
    std::fs::read_to_string(path).unwrap().lines().map(str::to_string).collect()
}

fn write_lines(path: &Path, lines: &[String]) {
    std::fs::write(path, lines.join("\n") + "\n").unwrap();
}

fn refusal(files: &[PathBuf]) -> String {
    match read_shards(files) {
        Err(e @ (AppError::Usage(_) | AppError::Parse { .. })) => e.to_string(),
        other => panic!("expected the merge to be refused, got {other:?}"),
    }
}

#[test]
fn three_shards_hold_the_unsharded_results_and_merge_into_its_report() {
    let dir = TempDir::new("batch-mbm");
    let whole = dir.join("all.jsonl");
    let unsharded = run_to(&mbm_args(), &whole);
    assert_eq!(unsharded.problems.len(), 3);
    assert_eq!(unsharded.overall.solved, 2);

    let mut shard_files = Vec::new();
    let mut sharded: Vec<ProblemResult> = Vec::new();
    for k in 1..=3 {
        let mut a = mbm_args();
        a.shard = Shard { k, n: 3 };
        let path = dir.join(format!("shard{k}.jsonl"));
        let report = run_to(&a, &path);
        assert_eq!(report.shard, Some(Shard { k, n: 3 }));
        assert_eq!(report.problems.len(), 1, "shard {k} holds problem {}", k - 1);
        // Problem i (families and indices sorted) is in shard (i mod 3) + 1.
        assert_eq!(deterministic(&report.problems[0]), deterministic(&unsharded.problems[k - 1]));
        sharded.extend(report.problems);
        shard_files.push(path);
    }
    assert_eq!(sharded.len(), unsharded.problems.len());

    // The unsharded file merges into exactly the unsharded report.
    let again = merge_mbm(read_shards(std::slice::from_ref(&whole)).unwrap()).unwrap();
    assert_eq!(serde_json::to_value(&again).unwrap(), serde_json::to_value(&unsharded).unwrap());
    assert_eq!(render_table(&again), render_table(&unsharded));

    // The shards, in any order, merge into the report of an unsharded file holding their lines.
    let mut reversed = shard_files.clone();
    reversed.reverse();
    let merged = merge_mbm(read_shards(&reversed).unwrap()).unwrap();
    assert_eq!(merged.shard, None);
    assert_eq!(
        merged.problems.iter().map(deterministic).collect::<Vec<_>>(),
        unsharded.problems.iter().map(deterministic).collect::<Vec<_>>()
    );
    assert_eq!(merged.settings, unsharded.settings);
    let mut spliced = vec![lines(&whole)[0].clone()];
    for f in &shard_files {
        spliced.extend(lines(f).into_iter().skip(1));
    }
    let one = dir.join("spliced.jsonl");
    write_lines(&one, &spliced);
    let from_one = merge_mbm(read_shards(&[one]).unwrap()).unwrap();
    assert_eq!(serde_json::to_value(&merged).unwrap(), serde_json::to_value(&from_one).unwrap());
    assert_eq!(render_table(&merged), render_table(&from_one));
    assert!(render_table(&merged).contains("box_ur5") && render_table(&merged).contains("2/2"));

    // Refusals name the file (and line) and what is wrong.
    let m = refusal(&[shard_files[0].clone(), shard_files[2].clone()]);
    assert!(m.contains("shard 2/3 missing"), "{m}");
    let m = refusal(&[shard_files[0].clone(), shard_files[1].clone(), shard_files[0].clone()]);
    assert!(m.contains("both shard 1/3"), "{m}");
    let m = refusal(&[shard_files[0].clone(), whole.clone()]);
    assert!(m.contains("all.jsonl") && m.contains("shard count"), "{m}");

    let edited = |name: &str, k: usize, f: &dyn Fn(&mut Vec<String>)| -> Vec<PathBuf> {
        let mut files = shard_files.clone();
        let mut l = lines(&files[k]);
        f(&mut l);
        let path = dir.join(name);
        write_lines(&path, &l);
        files[k] = path;
        files
    };
    // Other settings.
    let files = edited("slow.jsonl", 1, &|l| l[0] = l[0].replace("\"deadline_ms\":20000.0", "\"deadline_ms\":500.0"));
    let m = refusal(&files);
    assert!(m.contains("slow.jsonl") && m.contains("deadline_ms: 20000.0 vs 500.0"), "{m}");
    // Another program.
    let files =
        edited("other.jsonl", 1, &|l| l[0] = l[0].replace("\"generator\":\"embodied ", "\"generator\":\"embodied 9"));
    assert!(refusal(&files).contains("the program"), "{}", refusal(&files));
    // An unfinished shard.
    let files = edited("cut.jsonl", 2, &|l| l.truncate(1));
    let m = refusal(&files);
    assert!(m.contains("cut.jsonl") && m.contains("problem 2 run 0 of shard 3/3 is missing"), "{m}");
    // A line of another shard.
    let moved = lines(&shard_files[1])[1].clone();
    let files = edited("stray.jsonl", 2, &|l| l.push(moved.clone()));
    let m = refusal(&files);
    assert!(m.contains("stray.jsonl:3:1") && m.contains("belongs to shard 2/3"), "{m}");
    // Overlap: a problem twice.
    let two_lines = edited("overlap2.jsonl", 1, &|l| l.push(l[1].clone()));
    let m = refusal(&two_lines);
    assert!(m.contains("overlap2.jsonl:3") && m.contains("already at") && m.contains("overlap2.jsonl:2"), "{m}");
    // A line that is not JSON.
    let files = edited("garbage.jsonl", 0, &|l| l.push("{not json".into()));
    let m = refusal(&files);
    assert!(m.contains("garbage.jsonl:3:1") && m.contains("expected a JSON object"), "{m}");
}

/// Minimal reader of OMPL's benchmark log grammar (as `ompl_benchmark_statistics.py` reads
/// it): returns (experiment name, hostname, planner names, property names, rows per planner).
struct OmplLog {
    experiment: String,
    host: String,
    run_count: usize,
    properties: Vec<String>,
    planners: Vec<(String, Vec<Vec<Option<f64>>>)>,
}

fn parse_ompl_log(text: &str) -> OmplLog {
    let mut lines = text.lines();
    let mut next = || lines.next().expect("log ends early");
    let first = next();
    assert_eq!(first.split_whitespace().nth(1), Some("version"), "{first}");
    let experiment = next().strip_prefix("Experiment ").expect("Experiment NAME").to_string();
    let count = |line: &str, suffix: &str| -> usize {
        let n = line.strip_suffix(suffix).unwrap_or_else(|| panic!("`{line}` should end with `{suffix}`"));
        n.trim().parse().unwrap_or_else(|_| panic!("`{line}`: a count"))
    };
    let props = count(next(), " experiment properties");
    for _ in 0..props {
        let l = next();
        let (name, value) = l.split_once(" = ").expect("name TYPE = value");
        let ty = name.split_whitespace().last().unwrap();
        assert!(["REAL", "INTEGER", "BOOLEAN", "STRING"].contains(&ty), "{l}");
        assert!(!value.is_empty());
    }
    let host = next().strip_prefix("Running on ").expect("Running on HOST").to_string();
    assert!(next().starts_with("Starting at "));
    for _ in 0..2 {
        assert_eq!(next(), "<<<|");
        while next() != "|>>>" {}
    }
    let word0 = |l: &str, rest: &str| -> f64 {
        let (v, r) = l.split_once(' ').unwrap();
        assert_eq!(r, rest, "{l}");
        v.parse().unwrap_or_else(|_| panic!("{l}"))
    };
    word0(next(), "is the random seed");
    assert!(word0(next(), "seconds per run") > 0.0);
    word0(next(), "MB per run");
    let run_count = word0(next(), "runs per planner") as usize;
    assert!(word0(next(), "seconds spent to collect the data") >= 0.0);
    let enums = count(next(), " enum type");
    for _ in 0..enums {
        assert!(next().split('|').count() > 2);
    }
    let n_planners = count(next(), " planners");
    let mut planners = Vec::new();
    let mut properties = Vec::new();
    for _ in 0..n_planners {
        let name = next().to_string();
        let common = count(next(), " common properties");
        for _ in 0..common {
            assert!(next().contains(" = "));
        }
        let n_props = count(next(), " properties for each run");
        properties = (0..n_props).map(|_| next().to_string()).collect();
        for p in &properties {
            let ty = p.split_whitespace().last().unwrap();
            assert!(["REAL", "INTEGER", "BOOLEAN", "ENUM", "STRING"].contains(&ty), "{p}");
        }
        let n_runs = count(next(), " runs");
        let mut rows = Vec::new();
        for _ in 0..n_runs {
            let l = next();
            let values: Vec<&str> = l.split("; ").collect();
            // Every value is followed by "; ": the last piece is empty.
            assert_eq!(values.len(), n_props + 1, "{l}");
            assert_eq!(values[n_props], "");
            rows.push(values[..n_props].iter().map(|v| (!v.is_empty()).then(|| v.parse().unwrap())).collect());
        }
        assert_eq!(next(), ".");
        planners.push((name, rows));
    }
    assert!(lines.next().is_none(), "text after the last planner");
    OmplLog { experiment, host, run_count, properties, planners }
}

#[test]
fn ompl_logs_follow_the_benchmark_log_grammar() {
    let dir = TempDir::new("ompl-log");
    let mut a = mbm_args();
    a.runs = 3;
    a.limit = Some(1);
    a.families = Some(vec!["box_ur5".into()]);
    let report = run_mbm_to(&a, &mut |_, _| {}, None).unwrap();
    assert_eq!(report.problems.len(), 3);
    assert_eq!(report.problems.iter().map(|p| p.run).collect::<Vec<_>>(), [0, 1, 2]);
    // Runs plan with different seeds.
    assert_ne!(report.problems[0].path, report.problems[1].path);
    let files = embodied::ompl_log::write_ompl_logs(&report, &dir.join("logs")).unwrap();
    assert_eq!(files.len(), 1);
    assert!(files[0].ends_with("box_ur5_0001.log"));
    let text = std::fs::read_to_string(&files[0]).unwrap();
    let log = parse_ompl_log(&text);
    assert_eq!(log.experiment, "box_ur5_0001");
    assert!(!log.host.is_empty());
    assert_eq!(log.run_count, 3);
    assert_eq!(log.planners.len(), 1);
    let (name, rows) = &log.planners[0];
    assert_eq!(name, "embodied_rrt_connect");
    assert_eq!(rows.len(), 3);
    let col = |p: &str| log.properties.iter().position(|x| x == p).unwrap_or_else(|| panic!("no {p}"));
    let mut sorted = log.properties.clone();
    sorted.sort();
    assert_eq!(sorted, log.properties, "OMPL writes the properties sorted");
    for (row, r) in rows.iter().zip(&report.problems) {
        assert_eq!(row[col("solved BOOLEAN")], Some(1.0));
        assert_eq!(row[col("status ENUM")], Some(6.0), "Exact solution");
        let t = row[col("time REAL")].unwrap();
        assert!((t - r.planning_us.unwrap() / 1e6).abs() < 1e-12);
        let len = row[col("solution length REAL")].unwrap();
        assert!((len - r.path_length.unwrap()).abs() < 1e-12);
        assert_eq!(row[col("solution segments INTEGER")], Some((r.path.len() - 1) as f64));
        assert_eq!(row[col("correct solution BOOLEAN")], Some(1.0));
    }
    assert!(text.contains("git_commit STRING = "), "{text}");

    // An invalid problem: status Invalid goal, not solved, no path properties.
    let mut b = mbm_args();
    b.families = Some(vec!["bookshelf_small_ur5".into()]);
    let report = run_mbm_to(&b, &mut |_, _| {}, None).unwrap();
    let files = embodied::ompl_log::write_ompl_logs(&report, &dir.join("logs")).unwrap();
    let log = parse_ompl_log(&std::fs::read_to_string(&files[0]).unwrap());
    let col = |p: &str| log.properties.iter().position(|x| x == p).unwrap();
    let row = &log.planners[0].1[0];
    assert_eq!((row[col("solved BOOLEAN")], row[col("status ENUM")]), (Some(0.0), Some(2.0)));
    assert_eq!(row[col("solution length REAL")], None);
}

#[test]
fn plan_batch_shards_hold_the_unsharded_plans_and_merge() {
    let dir = TempDir::new("plan-batch");
    let list = dir.join("list.txt");
    std::fs::write(&list, "# three scenarios\npolycrank-transfer\n\ntwo-irp6-cell   # built-in\nirp6-pick\n").unwrap();
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let whole = dir.join("all.jsonl");
    let (code, stdout, stderr) = embodied(&["plan", "--batch", &s(&list), "--jsonl", &s(&whole)]);
    assert_eq!(code, 0, "{stdout}{stderr}");
    assert!(stdout.contains("3/3 problems planned and certified"), "{stdout}");
    let plans = |files: &[PathBuf]| -> Vec<(u64, serde_json::Value)> {
        let mut out = Vec::new();
        for f in files {
            for l in lines(f).iter().skip(1) {
                let v: serde_json::Value = serde_json::from_str(l).unwrap();
                let paths: Vec<serde_json::Value> =
                    v["plan"]["plans"].as_array().unwrap().iter().map(|p| p["path"].clone()).collect();
                out.push((v["i"].as_u64().unwrap(), serde_json::json!([v["name"], v["certified"], paths])));
            }
        }
        out.sort_by_key(|(i, _)| *i);
        out
    };
    let mut shard_files = Vec::new();
    for k in 1..=2 {
        let path = dir.join(format!("s{k}.jsonl"));
        let (code, stdout, stderr) =
            embodied(&["plan", "--batch", &s(&list), "--shard", &format!("{k}/2"), "--jsonl", &s(&path)]);
        assert_eq!(code, 0, "{stdout}{stderr}");
        assert!(stdout.contains(&format!("shard {k}/2")), "{stdout}");
        shard_files.push(path);
    }
    let unsharded = plans(std::slice::from_ref(&whole));
    assert_eq!(unsharded.len(), 3);
    assert_eq!(plans(&shard_files), unsharded);
    let (code, stdout, stderr) = embodied(&["bench", "merge", &s(&shard_files[1]), &s(&shard_files[0]), "--json"]);
    assert_eq!(code, 0, "{stdout}{stderr}");
    let merged: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!((merged["total"].as_u64(), merged["certified"].as_u64()), (Some(3), Some(3)));
    let names: Vec<&str> = merged["problems"].as_array().unwrap().iter().map(|p| p["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["polycrank-transfer", "two-irp6-cell", "irp6-pick"]);

    // A missing shard is bad input, named.
    let (code, _, stderr) = embodied(&["bench", "merge", &s(&shard_files[0])]);
    assert_eq!(code, 2);
    assert!(stderr.contains("shard 2/2 missing"), "{stderr}");
    // Bad shard specs are refused by the parser.
    let (code, _, stderr) = embodied(&["plan", "--batch", &s(&list), "--shard", "3/2"]);
    assert_eq!(code, 2);
    assert!(stderr.contains("K/N"), "{stderr}");
}

/// The `embodied` invocations of a shell script or manifest: (subcommand path, flags).
fn invocations(text: &str, yaml: bool) -> Vec<(Vec<String>, Vec<String>)> {
    // One logical line per command: shell continuations joined, and a YAML block scalar's
    // lines joined to the line that opens it.
    let mut logical: Vec<String> = Vec::new();
    let mut block_indent: Option<usize> = None;
    let mut continued = false;
    for line in text.lines() {
        let indent = line.len() - line.trim_start().len();
        if let Some(b) = block_indent {
            if indent >= b && !line.trim().is_empty() {
                logical.last_mut().unwrap().push_str(&format!(" {}", line.trim()));
                continue;
            }
            block_indent = None;
        }
        if continued {
            logical.last_mut().unwrap().push_str(&format!(" {}", line.trim()));
        } else {
            logical.push(line.trim().to_string());
        }
        continued = line.trim_end().ends_with('\\');
        if yaml && (line.trim_end().ends_with(">-") || line.trim_end().ends_with('|')) {
            block_indent = Some(indent + 1);
        }
    }
    let mut out = Vec::new();
    for line in logical {
        let cleaned: String = line.chars().map(|c| if "\"'\\[],".contains(c) { ' ' } else { c }).collect();
        let tokens: Vec<&str> = cleaned.split_whitespace().collect();
        for (at, t) in tokens.iter().enumerate() {
            if *t != "embodied" && !t.ends_with("/embodied") {
                continue;
            }
            let mut path = Vec::new();
            let mut flags = Vec::new();
            for t in &tokens[at + 1..] {
                if [";", "|", "&&", "||", ">", "2>", ":::", "embodied"].contains(t) || t.starts_with('>') {
                    break;
                }
                if let Some(flag) = t.strip_prefix("--") {
                    flags.push(format!("--{}", flag.split('=').next().unwrap()));
                } else if flags.is_empty() && ["bench", "mbm", "merge", "plan", "verify", "run"].contains(t) {
                    path.push(t.to_string());
                }
            }
            if !path.is_empty() {
                out.push((path, flags));
            }
        }
    }
    out
}

#[test]
fn the_batch_examples_use_real_flags_and_end_with_a_merge() {
    let dir = root().join("examples/batch");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().path()).collect();
    files.sort();
    let names: Vec<String> = files.iter().map(|f| f.file_name().unwrap().to_string_lossy().into_owned()).collect();
    for wanted in ["parallel.sh", "slurm.sh", "k8s-indexed-job.yaml", "k8s-merge-job.yaml"] {
        assert!(names.iter().any(|n| n == wanted), "examples/batch/{wanted} missing: {names:?}");
    }
    let mut help_cache: std::collections::BTreeMap<Vec<String>, String> = Default::default();
    let mut checked = 0;
    for file in files.iter().filter(|f| f.extension().is_some_and(|e| e == "sh" || e == "yaml")) {
        let text = std::fs::read_to_string(file).unwrap();
        let calls = invocations(&text, file.extension().is_some_and(|e| e == "yaml"));
        assert!(!calls.is_empty(), "{}: no embodied invocation found", file.display());
        let name = file.file_name().unwrap().to_string_lossy();
        if name != "k8s-indexed-job.yaml" {
            let last = calls.last().unwrap();
            assert_eq!(last.0, ["bench", "merge"], "{}: should end with `embodied bench merge`", file.display());
        } else {
            assert!(text.contains("JOB_COMPLETION_INDEX") && text.contains("completionMode: Indexed"));
        }
        for (path, flags) in &calls {
            let help = help_cache.entry(path.clone()).or_insert_with(|| {
                let mut args: Vec<&str> = path.iter().map(String::as_str).collect();
                args.push("--help");
                let (code, stdout, stderr) = embodied(&args);
                assert_eq!(code, 0, "{}: `embodied {}` is not a command: {stderr}", file.display(), path.join(" "));
                stdout
            });
            for flag in flags {
                let known = help.match_indices(flag.as_str()).any(|(at, _)| {
                    let after = help[at + flag.len()..].chars().next();
                    !after.is_some_and(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
                });
                assert!(
                    known,
                    "{}: `embodied {} {flag}` is not a flag of that command",
                    file.display(),
                    path.join(" ")
                );
                checked += 1;
            }
        }
    }
    // The examples pass --urdf --srdf --problems --shard --jsonl to bench mbm at least.
    assert!(checked >= 15, "only {checked} flags found: the extraction misses commands");
}

#[test]
fn bench_mbm_writes_json_lines_to_stdout_and_ompl_logs() {
    let dir = TempDir::new("mbm-cli");
    let robot = root().join("models/tests/fixtures");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let logs = dir.join("ompl");
    let (urdf, srdf, problems) =
        (s(&robot.join("ur5_spherized.urdf")), s(&robot.join("ur5.srdf")), s(&root().join("tests/fixtures/mbm")));
    let base = ["bench", "mbm", "--urdf", &urdf, "--srdf", &srdf, "--problems", &problems, "--deadline-ms", "20000"];
    let mut args = base.to_vec();
    args.extend(["--limit", "1", "--runs", "2", "--jsonl", "-", "--ompl-log", logs.to_str().unwrap()]);
    let (code, stdout, stderr) = embodied(&args);
    assert_eq!(code, 0, "{stderr}");
    // Standard output carries the JSON Lines, the table goes to standard error.
    let lines: Vec<serde_json::Value> = stdout.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(lines.len(), 1 + 2 * 2, "{stdout}");
    assert_eq!(lines[0]["format"], "embodied-batch/1");
    assert_eq!(lines[0]["runs"], 2);
    assert!(lines[0]["machine"]["hostname"].as_str().is_some_and(|h| !h.is_empty()));
    let keys: Vec<(u64, u64)> =
        lines[1..].iter().map(|l| (l["i"].as_u64().unwrap(), l["run"].as_u64().unwrap())).collect();
    assert_eq!(keys, [(0, 0), (0, 1), (1, 0), (1, 1)]);
    assert!(stderr.contains("2 runs per problem") && stderr.contains("overall"), "{stderr}");
    let mut written: Vec<String> =
        std::fs::read_dir(&logs).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    written.sort();
    assert_eq!(written, ["bookshelf_small_ur5_0009.log", "box_ur5_0001.log"]);

    let mut args = base.to_vec();
    args.extend(["--runs", "0"]);
    let (code, _, stderr) = embodied(&args);
    assert_eq!(code, 2);
    assert!(stderr.contains("--runs must be at least 1"), "{stderr}");
}

#[test]
fn bench_mbm_plans_only_the_families_asked_for() {
    let robot = root().join("models/tests/fixtures");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let (urdf, srdf, problems) =
        (s(&robot.join("ur5_spherized.urdf")), s(&robot.join("ur5.srdf")), s(&root().join("tests/fixtures/mbm")));
    let base = ["bench", "mbm", "--urdf", &urdf, "--srdf", &srdf, "--problems", &problems, "--deadline-ms", "20000"];
    // One family, named twice: planned once, the other family left out.
    let mut args = base.to_vec();
    args.extend(["--families", "box_ur5, box_ur5", "--jsonl", "-"]);
    let (code, stdout, stderr) = embodied(&args);
    assert_eq!(code, 0, "{stderr}");
    let lines: Vec<serde_json::Value> = stdout.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(lines[0]["settings"]["families"], serde_json::json!(["box_ur5"]), "{}", lines[0]);
    assert!(lines.len() > 1, "{stdout}");
    assert!(lines[1..].iter().all(|l| l["family"] == "box_ur5"), "{stdout}");
    // Both, comma separated: every problem of the fixture.
    let mut args = base.to_vec();
    args.extend(["--families", "box_ur5,bookshelf_small_ur5", "--jsonl", "-"]);
    let (code, both, stderr) = embodied(&args);
    assert_eq!(code, 0, "{stderr}");
    let families: std::collections::BTreeSet<String> = both
        .lines()
        .skip(1)
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap()["family"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(families.into_iter().collect::<Vec<_>>(), ["bookshelf_small_ur5", "box_ur5"]);
    // A family that is not there, and an empty name: usage errors naming what is.
    let mut args = base.to_vec();
    args.extend(["--families", "cage_ur5"]);
    let (code, _, stderr) = embodied(&args);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("no family `cage_ur5`") && stderr.contains("bookshelf_small_ur5, box_ur5"), "{stderr}");
    let mut args = base.to_vec();
    args.extend(["--families", "box_ur5,"]);
    let (code, _, stderr) = embodied(&args);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("--families") && stderr.contains("empty name"), "{stderr}");
}

/// A report written before the late share existed reads as the first share throughout: its
/// settings lack `rrt_late_local_bias` and `rrt_late_after`, and the table says nothing of a
/// late share (nor overflows counting its first sample).
#[test]
fn a_report_without_the_late_share_reads_as_one_share_throughout() {
    let dir = TempDir::new("batch-old-report");
    let mut report = run_to(&mbm_args(), &dir.join("now.jsonl"));
    assert!(render_table(&report).contains("0.9 from sample 129 of an attempt"), "{}", render_table(&report));
    let mut old = serde_json::to_value(&report.settings).unwrap();
    let fields = old.as_object_mut().unwrap();
    assert!(fields.remove("rrt_late_local_bias").is_some() && fields.remove("rrt_late_after").is_some());
    report.settings = serde_json::from_value(old).expect("an old report's settings");
    assert_eq!((report.settings.rrt_late_local_bias, report.settings.rrt_late_after), (0.0, usize::MAX));
    let table = render_table(&report);
    assert!(table.contains("near the growing tree") && !table.contains("from sample"), "{table}");
}

/// The screen's length goes into the report's settings: a number, `null` for an infinite one
/// (JSON has no infinity), read back as infinite, as is a report written before the screen
/// existed (none screened).
#[test]
fn the_screen_length_reads_back_infinite_or_finite() {
    let dir = TempDir::new("batch-screen");
    let mut report = run_to(&mbm_args(), &dir.join("now.jsonl"));
    assert_eq!(report.settings.screen_above, 2.0);
    let mut value = serde_json::to_value(&report.settings).unwrap();
    assert_eq!(value["screen_above"], serde_json::json!(2.0));
    report.settings.screen_above = f64::INFINITY;
    let never = serde_json::to_value(&report.settings).unwrap();
    assert!(never["screen_above"].is_null(), "{never}");
    let back: embodied::mbm::MbmSettings = serde_json::from_value(never).expect("settings");
    assert_eq!(back.screen_above, f64::INFINITY);
    assert!(value.as_object_mut().unwrap().remove("screen_above").is_some());
    let old: embodied::mbm::MbmSettings = serde_json::from_value(value).expect("an old report's settings");
    assert_eq!(old.screen_above, f64::INFINITY);
}

/// `max_samples`, `rrt_restarts` and `lazy_probe` reach the planner and the report: with
/// attempts of 5 samples and one restart, no solved run drew more than 10 samples and the runs
/// that need more end without a path; with the defaults every problem is solved. A report
/// written before they were recorded reads them as unknown.
#[test]
fn attempt_length_restarts_and_probe_step_reach_the_planner_and_the_report() {
    let dir = TempDir::new("batch-attempts");
    let mut args = mbm_args();
    args.max_samples = 5;
    args.rrt_restarts = 1;
    args.lazy_probe = 0.05;
    let short = run_to(&args, &dir.join("short.jsonl"));
    let s = &short.settings;
    assert_eq!((s.max_samples, s.rrt_restarts, s.lazy_probe), (Some(5), Some(1), Some(0.05)));
    let samples = |r: &ProblemResult| r.stats.as_ref().and_then(|v| v["samples"].as_u64());
    let mut out_of_samples = 0;
    for r in short.problems.iter().filter(|r| !r.status.is_invalid()) {
        if r.solved {
            assert!(samples(r).is_some_and(|n| n <= 10), "{}/{}: {:?}", r.family, r.index, r.stats);
        } else {
            assert_eq!(r.status, ProblemStatus::Failed, "{}/{}: {:?}", r.family, r.index, r.message);
            assert!(r.message.as_deref().is_some_and(|m| m.contains("with 10 samples")), "{:?}", r.message);
            out_of_samples += 1;
        }
    }
    assert!(out_of_samples > 0, "every fixture problem was solved within 10 samples");
    let table = render_table(&short);
    assert!(table.contains(", attempts of 5 samples, 1 restart, tree edges probed every 0.05 rad ("), "{table}");
    let full = run_to(&mbm_args(), &dir.join("full.jsonl"));
    let s = &full.settings;
    assert_eq!((s.max_samples, s.rrt_restarts, s.lazy_probe), (Some(50_000), Some(64), Some(0.1)));
    assert!(full.problems.iter().filter(|r| !r.status.is_invalid()).all(|r| r.solved));
    let table = render_table(&full);
    assert!(!table.contains("attempts of") && !table.contains("tree edges"), "{table}");
    let mut old = serde_json::to_value(&full.settings).unwrap();
    let fields = old.as_object_mut().unwrap();
    for f in ["max_samples", "rrt_restarts", "lazy_probe"] {
        assert!(fields.remove(f).is_some(), "{f}");
    }
    let old: embodied::mbm::MbmSettings = serde_json::from_value(old).expect("an old report's settings");
    assert_eq!((old.max_samples, old.rrt_restarts, old.lazy_probe), (None, None, None));
}

/// Goal retreats are off by default and go into the report's settings and table when asked
/// for; every problem is still solved with a verified path. A report written before they
/// existed reads as without them.
#[test]
fn goal_retreats_are_recorded_in_the_report() {
    let dir = TempDir::new("batch-goal-retreat");
    let plain = run_to(&mbm_args(), &dir.join("plain.jsonl"));
    assert!(!plain.settings.goal_retreat && !render_table(&plain).contains("goal retreats"));
    let mut args = mbm_args();
    args.goal_retreat = true;
    let report = run_to(&args, &dir.join("retreat.jsonl"));
    assert!(report.settings.goal_retreat);
    let table = render_table(&report);
    assert!(table.contains("with goal retreats"), "{table}");
    let valid: Vec<_> = report.problems.iter().filter(|p| !p.status.is_invalid()).collect();
    assert!(!valid.is_empty());
    for p in valid {
        assert!(p.solved && p.verified == Some(true), "{} {}: {:?}", p.family, p.index, p.status);
    }
    let mut old = serde_json::to_value(&report.settings).unwrap();
    assert!(old.as_object_mut().unwrap().remove("goal_retreat").is_some());
    let read: embodied::mbm::MbmSettings = serde_json::from_value(old).expect("an old report's settings");
    assert!(!read.goal_retreat);
}

/// `--versus FLAGS` plans every problem with the settings given (A) and with the flags added
/// (B), and compares them: B keeps A's other flags, the same settings give identical paths,
/// and flags that would change the problems, a second `--versus`, the process-wide racer look
/// or a per-problem output are refused with the flag named.
#[test]
fn bench_mbm_versus_compares_two_settings_on_the_same_problems() {
    let robot = root().join("models/tests/fixtures");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let (urdf, srdf, problems) =
        (s(&robot.join("ur5_spherized.urdf")), s(&robot.join("ur5.srdf")), s(&root().join("tests/fixtures/mbm")));
    let base = [
        "bench",
        "mbm",
        "--urdf",
        &urdf,
        "--srdf",
        &srdf,
        "--problems",
        &problems,
        "--deadline-ms",
        "20000",
        "--limit",
        "1",
        "--rrt-range",
        "0.7",
        "--threads",
        "1",
    ];
    let mut args = base.to_vec();
    args.extend(["--json", "--versus", "--seed 3 --shortcut-attempts 0"]);
    let (code, stdout, stderr) = embodied(&args);
    assert_eq!(code, 0, "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(v["flags"], "--seed 3 --shortcut-attempts 0");
    // B: A's range kept, its seed and shortcuts replaced.
    assert_eq!(
        (v["a"]["settings"]["rrt_range"].as_f64(), v["b"]["settings"]["rrt_range"].as_f64()),
        (Some(0.7), Some(0.7))
    );
    assert_eq!((v["a"]["settings"]["seed"].as_u64(), v["b"]["settings"]["seed"].as_u64()), (Some(1), Some(3)));
    assert_eq!(v["b"]["settings"]["shortcut_attempts"], 0);
    assert_ne!(v["a"]["settings"]["shortcut_attempts"], 0);
    let names = |side: &str| -> Vec<String> {
        v[side]["problems"].as_array().unwrap().iter().map(|p| format!("{}/{}", p["family"], p["index"])).collect()
    };
    assert_eq!(names("a"), names("b"));
    assert_eq!(names("a").len(), 2);
    assert_eq!(v["overall"]["pairs"], 2);
    assert_eq!(v["families"].as_array().unwrap().len(), 2);
    assert!(v["overall"]["time_ratio"].as_f64().is_some_and(|r| r > 0.0), "{}", v["overall"]);

    // The same settings: the same paths, checks and lengths (only the times differ); the flag
    // with its value after `=`.
    let mut args = base.to_vec();
    args.push("--versus=--seed 1");
    let (code, stdout, stderr) = embodied(&args);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("B against A") && stdout.contains("time B/A"), "{stdout}");
    let overall = stdout.lines().rev().find(|l| l.starts_with("overall")).unwrap();
    let cells: Vec<&str> = overall.split_whitespace().collect();
    // overall, pairs, both, time, CI, median, sum, checks, path, <=1 ms A, <=1 ms B, changed
    assert_eq!(cells.len(), 12, "{overall}");
    // One of the two is invalid (its goal collides): one pair solved by both.
    assert_eq!((cells[1], cells[2], cells[7], cells[8], cells[11]), ("2", "1", "1.000", "1.000", "0"), "{overall}");

    for (flags, says) in [
        ("--limit 2", "changes the problems"),
        ("--bogus 1", "unexpected argument '--bogus'"),
        ("--versus --seed", "B cannot have a --versus of its own"),
        ("--racer-look-ms 5", "--racer-look-ms is a setting of the whole process"),
        ("--rrt-range=0", "--rrt-range must be a positive number"),
    ] {
        let mut args = base.to_vec();
        args.extend(["--versus", flags]);
        let (code, _, stderr) = embodied(&args);
        assert_eq!(code, 2, "{flags}: {stderr}");
        assert!(stderr.contains(says), "{flags}: {stderr}");
    }
    let mut args = base.to_vec();
    args.extend(["--jsonl", "-", "--versus", "--seed 2"]);
    let (code, _, stderr) = embodied(&args);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("--versus reports both settings in one report"), "{stderr}");
}
