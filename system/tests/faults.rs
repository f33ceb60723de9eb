//! Fault injection: `[[faults]]` read and checked with clear errors, and every fault kind
//! answered by its reaction in the built-in `rnt-faults` scenario, checked from its log.
#![allow(clippy::unwrap_used)]

use std::path::Path;

use embodied_executor::{Event, HaltReason};
use embodied_system::campaign::{Answer, run_checked};
use embodied_system::scenario::{load_scenario, parse_scenario};
use embodied_system::system::{RunOptions, System};
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

fn run_builtin(name: &str) -> embodied_system::campaign::RunReport {
    let scenario = load_scenario(name).unwrap();
    static RUN: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let k = RUN.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("embodied-faults-test-{}-{k}", std::process::id()));
    let r = run_checked(&scenario, 0, &dir, true).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    assert!(r.problems.is_empty(), "{name}: {:?}", r.problems);
    assert_eq!(r.deterministic, Some(true), "{name}");
    assert_eq!(r.limit_violations, 0, "{name}");
    assert_eq!(r.map_collisions, 0, "{name}");
    assert!(r.log_complete, "{name}");
    r
}

fn answered(r: &embodied_system::campaign::RunReport, kind: FaultKind) -> usize {
    r.faults.iter().filter(|(i, a)| i.kind == kind && *a == Answer::Answered).count()
}

#[test]
fn every_fault_kind_is_answered_in_the_builtin_scenario() {
    let r = run_builtin("rnt-faults");
    for kind in [
        FaultKind::PlannerPanic,
        FaultKind::PlanOverLimits,
        FaultKind::PlannerLate,
        FaultKind::SensorNan,
        FaultKind::SensorWild,
        FaultKind::SensorDropout,
    ] {
        assert_eq!(answered(&r, kind), 1, "{kind:?}: {:?}", r.faults);
    }
    assert!(r.halts >= 4, "{r:?}");
}

/// Every fault kind is injected and answered in one of the built-in fault scenarios.
#[test]
fn the_builtin_fault_scenarios_answer_every_kind() {
    let runs: Vec<_> =
        ["rnt-faults", "rnt-motion-faults", "two-irp6-link-faults", "two-irp6-carry-qp-fault"].map(run_builtin).into();
    for kind in FaultKind::ALL {
        let n: usize = runs.iter().map(|r| answered(r, kind)).sum();
        assert!(n >= 1, "{kind:?} never answered: {:?}", runs.iter().map(|r| &r.faults).collect::<Vec<_>>());
    }
}

fn events_of(name: &str) -> Vec<(f64, String, Event)> {
    let scenario = load_scenario(name).unwrap();
    let mut system = System::new(&scenario, &RunOptions::default()).unwrap();
    system.run_until(system.duration(), |_| {}).unwrap();
    system.summary().events
}

#[test]
fn a_plan_through_a_collision_is_refused_and_a_stuck_joint_halts_the_arm() {
    let events = events_of("rnt-motion-faults");
    let first = |f: &dyn Fn(&Event) -> bool| events.iter().find(|(_, _, e)| f(e)).map(|(t, _, _)| *t);
    // The first plan passes through a collision: the gate refuses it before it can move the arm.
    let rejected = events.iter().find_map(|(t, _, e)| match e {
        Event::PlanRejected { id: 1, reason } => Some((*t, reason.clone())),
        _ => None,
    });
    let (t_rejected, reason) = rejected.expect("plan 1 rejected");
    assert!(reason.contains("collision") || reason.contains("collid"), "{reason}");
    assert!(first(&|e| matches!(e, Event::PlanLanded { .. })).unwrap() > t_rejected);
    // The stuck joint: a tracking error within one step of the fault (at 0.6 s), the halt at once,
    // every joint braking; the effector recovers and the arm goes on to its goal.
    let t_error = first(&|e| matches!(e, Event::TrackingError { .. })).expect("tracking error");
    assert!((0.6..0.6025).contains(&t_error), "{t_error}");
    let halts: Vec<_> = events
        .iter()
        .filter(|(t, _, e)| *t == t_error && matches!(e, Event::HaltStarted { reason: HaltReason::Fault, .. }))
        .collect();
    assert_eq!(halts.len(), 1, "{events:?}");
    let recovered = first(&|e| matches!(e, Event::EffectorRecovered)).expect("recovered");
    assert!(recovered > 0.9, "{recovered}");
    // The ball on the path: seen the step it appears.
    assert!(events.iter().any(|(t, _, e)| (2.2..2.2015).contains(t) && matches!(e, Event::WorldChanged { .. })));
    assert!(events.iter().any(|(_, _, e)| matches!(e, Event::GoalReached { .. })), "{events:?}");
}

#[test]
fn a_lost_grant_is_sent_again_and_no_arm_moves_without_it() {
    let events = events_of("two-irp6-link-faults");
    let resent: Vec<_> = events.iter().filter(|(_, _, e)| matches!(e, Event::GrantResent { .. })).collect();
    assert!(!resent.is_empty(), "{events:?}");
    let granted = events
        .iter()
        .find(|(_, _, e)| matches!(e, Event::Granted { agent } if agent == "irp6p"))
        .map(|(t, _, _)| *t)
        .unwrap();
    let received =
        events.iter().find(|(_, a, e)| a == "irp6p" && matches!(e, Event::GrantReceived)).map(|(t, _, _)| *t).unwrap();
    // The first grant was lost; the second, 100 steps later, arrived.
    assert!(received >= granted + 0.1, "granted {granted}, received {received}");
    let goals = events.iter().filter(|(_, _, e)| matches!(e, Event::GoalReached { .. })).count();
    assert_eq!(goals, 2, "{events:?}");
    // (`run_builtin` checks from the log that no arm moved before its grant arrived.)
    let r = run_builtin("two-irp6-link-faults");
    assert!(r.faults.iter().all(|(i, _)| i.messages > 0), "{:?}", r.faults);
}

#[test]
fn an_infeasible_closed_chain_qp_halts_the_pair_the_same_step() {
    let events = events_of("two-irp6-carry-qp-fault");
    let halt = events
        .iter()
        .find(|(_, _, e)| matches!(e, Event::HaltStarted { reason: HaltReason::ClosedChain, .. }))
        .map(|(t, _, _)| *t)
        .expect("halt");
    assert!((2.5..2.5015).contains(&halt), "{halt}");
    assert!(events.iter().any(|(_, _, e)| matches!(e, Event::Grasp)));
    assert!(!events.iter().any(|(_, _, e)| matches!(e, Event::Release | Event::GoalReached { .. })), "{events:?}");
}

#[test]
fn link_faults_are_read_and_checked() {
    let two = "name = \"x\"\ndescription = \"d\"\n[[agents]]\nname = \"a\"\nrobot = \"rnt\"\ngoal = [0.1, -1.0, 0, 0, 0, 0]\n\
               [[agents]]\nname = \"b\"\nrobot = \"rnt\"\nxyz = [0, 2, 0]\ngoal = [0.1, -1.0, 0, 0, 0, 0]\n";
    let ok = format!(
        "{two}[[faults]]\nkind = \"link_loss\"\nlink = \"coordinator->b\"\nat = 0.5\nloss = 0.5\nduration = 0.2\n"
    );
    let s = parse_scenario(&ok, Path::new("ok.toml"), Path::new(".")).unwrap();
    assert_eq!(s.faults[0].link.as_deref(), Some("coordinator->b"));
    assert_eq!(s.faults[0].loss, 0.5);
    let bad = |f: &str| match parse_scenario(&format!("{two}{f}"), Path::new("bad.toml"), Path::new(".")) {
        Ok(_) => panic!("expected an error for {f}"),
        Err(e) => e.to_string(),
    };
    let e = bad("[[faults]]\nkind = \"link_loss\"\nlink = \"coordinator->c\"\nat = 0.5\n");
    assert!(e.contains("link end `c`") && e.contains("coordinator"), "{e}");
    let e = bad("[[faults]]\nkind = \"link_loss\"\nlink = \"coordinator\"\nat = 0.5\n");
    assert!(e.contains("expected \"FROM->TO\""), "{e}");
    let e = bad("[[faults]]\nkind = \"link_loss\"\nat = 0.5\nloss = 2\n");
    assert!(e.contains("loss: expected a probability in [0, 1], got 2"), "{e}");
    let e = bad("[[faults]]\nkind = \"link_delay\"\nat = 0.5\ndelay = -1\n");
    assert!(e.contains("delay: expected a time"), "{e}");
    let e = bad("[[faults]]\nkind = \"sensor_nan\"\nat = 0.5\nlink = \"a->b\"\n");
    assert!(e.contains("only link faults"), "{e}");
}
