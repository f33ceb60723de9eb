//! Fault injection: `[[faults]]` read and checked with clear errors, and every fault kind
//! answered by its reaction in the built-in `rnt-faults` scenario, checked from its log.
#![allow(clippy::unwrap_used)]

use std::path::Path;

use embodied_system::campaign::{Answer, run_checked};
use embodied_system::scenario::{load_scenario, parse_scenario};
use embodied_system::{FaultKind, FaultTrigger};

const HEAD: &str =
    "name = \"x\"\ndescription = \"d\"\n[[agents]]\nname = \"a\"\nrobot = \"rnt\"\ngoal = [0.1, -1.0, 0, 0, 0, 0]\n";

fn err_of(faults: &str) -> String {
    match parse_scenario(&format!("{HEAD}{faults}"), Path::new("bad.toml"), Path::new(".")) {
        Ok(_) => panic!("expected an error for:\n{faults}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn faults_are_read() {
    let text = format!(
        "{HEAD}[[faults]]\nkind = \"sensor_dropout\"\nagent = \"a\"\nat = 1.5\nduration = 0.2\n\
         [[faults]]\nkind = \"planner_panic\"\nprobability = 0.25\nseed = 9\n"
    );
    let s = parse_scenario(&text, Path::new("ok.toml"), Path::new(".")).unwrap();
    assert_eq!(s.faults.len(), 2);
    assert_eq!(s.faults[0].kind, FaultKind::SensorDropout);
    assert_eq!(s.faults[0].agent.as_deref(), Some("a"));
    assert_eq!(s.faults[0].trigger, FaultTrigger::At(1.5));
    assert_eq!(s.faults[1].trigger, FaultTrigger::Probability(0.25));
    assert_eq!(s.faults[1].seed, Some(9));
}

#[test]
fn bad_faults_are_refused_with_the_place_and_what_was_expected() {
    let e = err_of("[[faults]]\nkind = \"gremlins\"\nat = 1\n");
    assert!(e.starts_with("bad.toml:8:8:"), "{e}");
    assert!(e.contains("sensor_dropout"), "{e}");
    let e = err_of("[[faults]]\nkind = \"sensor_nan\"\nat = 1\nprobability = 0.1\n");
    assert!(e.contains("exactly one of `at"), "{e}");
    let e = err_of("[[faults]]\nkind = \"sensor_nan\"\n");
    assert!(e.contains("exactly one of `at"), "{e}");
    let e = err_of("[[faults]]\nkind = \"sensor_nan\"\nprobability = 1.5\n");
    assert!(e.contains("probability: expected a number in [0, 1], got 1.5"), "{e}");
    let e = err_of("[[faults]]\nkind = \"sensor_nan\"\nat = -1\n");
    assert!(e.contains("at: expected a time >= 0 s"), "{e}");
    let e = err_of("[[faults]]\nkind = \"sensor_nan\"\nat = 1\nagent = \"b\"\n");
    assert!(e.contains("no agent `b`"), "{e}");
    let e = err_of("[[faults]]\nkind = \"sensor_nan\"\nat = 1\nwhen = 2\n");
    assert!(e.contains("unknown field `when`"), "{e}");
}

#[test]
fn every_fault_kind_is_answered_in_the_builtin_scenario() {
    let scenario = load_scenario("rnt-faults").unwrap();
    let dir = std::env::temp_dir().join(format!("embodied-faults-test-{}", std::process::id()));
    let r = run_checked(&scenario, 0, &dir, true).unwrap();
    assert!(r.problems.is_empty(), "{:?}", r.problems);
    assert_eq!(r.deterministic, Some(true));
    for kind in FaultKind::ALL {
        let answered = r.faults.iter().filter(|(i, a)| i.kind == kind && *a == Answer::Answered).count();
        assert_eq!(answered, 1, "{kind:?}: {:?}", r.faults);
    }
    assert!(r.halts >= 4, "{r:?}");
    assert_eq!(r.limit_violations, 0);
    assert!(r.log_complete);
}
