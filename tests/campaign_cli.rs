//! `embodied campaign` from the command line: chunks written with `--json` and merged with
//! `--merge` give the table of the whole campaign; reports that overlap, or are not reports,
//! are refused naming the file (exit status 2); `--keep-logs` keeps every run's log.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::{TempDir, embodied};

#[test]
fn chunks_run_apart_merge_into_the_whole_campaign() {
    let dir = TempDir::new("campaign-cli");
    let logs = dir.join("logs");
    let logs = logs.to_str().unwrap();
    let run = |runs: &str, seed: &str, extra: &[&str]| {
        let mut args = vec!["campaign", "--runs", runs, "--seed", seed, "--determinism-every", "0", "--dir", logs];
        args.extend(extra);
        let (code, out, err) = embodied(&args);
        assert_eq!(code, 0, "{err}");
        out
    };
    let whole = run("4", "70", &[]);
    let (a, b) = (dir.join("a.json"), dir.join("b.json"));
    std::fs::write(&a, run("1", "70", &["--json", "--keep-logs"])).unwrap();
    std::fs::write(&b, run("3", "71", &["--json"])).unwrap();
    // --keep-logs: the log of seed 70 is still there, the others are gone.
    let kept: Vec<String> =
        std::fs::read_dir(logs).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert!(kept.len() == 1 && kept[0].starts_with("campaign-70-"), "{kept:?}");

    let (code, merged, err) = embodied(&["campaign", "--merge", b.to_str().unwrap(), a.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(merged, whole);

    let (code, _, err) = embodied(&["campaign", "--merge", a.to_str().unwrap(), a.to_str().unwrap()]);
    assert_eq!(code, 2);
    assert!(err.contains("a.json") && err.contains("overlap"), "{err}");
    let bad = dir.join("bad.json");
    std::fs::write(&bad, "{\"runs\": 1, \"seed\": \"one\"}").unwrap();
    let (code, _, err) = embodied(&["campaign", "--merge", bad.to_str().unwrap()]);
    assert_eq!(code, 2);
    assert!(err.contains("bad.json:1:") && err.contains("embodied campaign --json"), "{err}");
}
