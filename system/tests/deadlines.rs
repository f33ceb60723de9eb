//! The deadline benchmark on a small problem set: structure, a zero deadline delivers nothing
//! and halts, and the MotionBenchMaker sample (fixtures only). Timing is not asserted (noisy
//! machines).

use std::path::PathBuf;

use embodied_system::deadlines::{DeadlineArgs, MbmSample, plot_svg, render_table, run_deadline_bench};

/// The IRp-6 pick scenario at a zero deadline and at 200 ms.
fn irp6_pick_args() -> DeadlineArgs {
    DeadlineArgs {
        deadlines_ms: vec![0.0, 200.0],
        scenarios: vec!["irp6-pick".into()],
        max_steps: 6000,
        ..DeadlineArgs::default()
    }
}

#[test]
fn small_deadline_bench_is_consistent() {
    let report = run_deadline_bench(&irp6_pick_args()).expect("bench runs");
    assert_eq!(report.rows.len(), 2);
    assert!(!report.problems.is_empty());
    for r in &report.rows {
        assert_eq!(r.set, "scenarios");
        assert!((0.0..=1.0).contains(&r.delivered_share));
        assert!(r.delivered_in_time <= r.requested);
        assert!(r.goals_reached <= r.problems);
        assert!(r.halt_distance_mean <= r.halt_distance_max + 1e-12);
        assert!(r.overshoot_p50_us <= r.overshoot_max_us);
        assert_eq!(r.halts.len(), r.halts_from_speed);
    }
    let zero = &report.rows[0];
    assert_eq!(zero.delivered_in_time, 0);
    assert_eq!(zero.goals_reached, 0);
    assert!(zero.requested > 0 && zero.safe_halts > 0);
    // Every search is stopped by a zero deadline.
    assert_eq!(zero.stopped, zero.requested);
    let table = render_table(&report);
    assert!(table.contains("deadline"));
    let json = serde_json::to_string(&report).expect("json");
    assert!(json.contains("delivered_share"));
    let dir = std::env::temp_dir().join(format!("embodied-deadlines-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temporary folder");
    let svg = dir.join("deadlines.svg");
    plot_svg(&report, &svg).expect("plot");
    assert!(std::fs::read_to_string(&svg).expect("svg").contains("<svg"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn mbm_sample_is_benchmarked_as_its_own_set() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let robot = root.join("models/tests/fixtures");
    let args = DeadlineArgs {
        deadlines_ms: vec![0.0, 500.0],
        mbm: Some(MbmSample {
            urdf: robot.join("ur5_spherized.urdf"),
            srdf: robot.join("ur5.srdf"),
            problems: root.join("tests/fixtures/mbm"),
            count: 2,
        }),
        max_steps: 60_000,
        ..DeadlineArgs::default()
    };
    let report = run_deadline_bench(&args).expect("bench runs");
    let mbm: Vec<_> = report.problems.iter().filter(|(set, _)| set == "mbm").collect();
    // Spread over both fixture families; problems with an invalid start or goal are left out.
    assert!(!mbm.is_empty() && mbm.len() <= 2, "{:?}", report.problems);
    assert!(report.problems.iter().all(|(set, _)| set == "mbm"), "only the sample was asked for");
    assert_eq!(report.rows.len(), 2);
    let (zero, wide) = (&report.rows[0], &report.rows[1]);
    assert_eq!(zero.delivered_in_time, 0);
    assert!(wide.delivered_in_time > 0, "{wide:?}");
    assert!(wide.goals_reached > 0, "{wide:?}");
    assert!(render_table(&report).contains(&format!("mbm ({})", mbm.len())));
}

#[test]
fn bad_deadlines_are_a_usage_error() {
    let args = DeadlineArgs { deadlines_ms: vec![-1.0], ..DeadlineArgs::default() };
    assert!(run_deadline_bench(&args).is_err());
}

/// Scenarios with a `[task]` are their own set: the task-level deliberation (search and
/// refinement) under each deadline, read back from the coordinator's events. A deadline of
/// 0.5 ms stops it (the arms hold, the overshoot is recorded); 20 s lets it finish.
#[test]
fn task_plans_are_benchmarked_as_their_own_set() {
    let args = DeadlineArgs {
        deadlines_ms: vec![0.5, 20_000.0],
        scenarios: vec!["two-irp6-stack".into()],
        max_steps: 40_000,
        ..DeadlineArgs::default()
    };
    let report = run_deadline_bench(&args).expect("bench runs");
    assert!(report.problems.contains(&("tasks".to_string(), "two-irp6-stack".to_string())), "{:?}", report.problems);
    let rows: Vec<_> = report.rows.iter().filter(|r| r.set == "tasks").collect();
    assert_eq!(rows.len(), 2, "{:?}", report.rows);
    let (short, long) = (rows[0], rows[1]);
    assert_eq!((short.requested, short.delivered_in_time, short.safe_halts, short.stopped), (1, 0, 1, 1), "{short:?}");
    assert_eq!((long.requested, long.delivered_in_time, long.goals_reached, long.safe_halts), (1, 1, 1, 0), "{long:?}");
    let table = render_table(&report);
    assert!(table.contains("tasks (1): two-irp6-stack"), "{table}");
    eprintln!("{table}");
}

/// With three planner seeds a scenario's planning problem counts three times, under its name
/// and `#1`, `#2`: a zero deadline delivers none of them, and 200 ms reaches the goal with each
/// seed.
#[test]
fn planner_seeds_multiply_the_problems() {
    let base = irp6_pick_args();
    let one = run_deadline_bench(&base).expect("bench runs");
    let three = run_deadline_bench(&DeadlineArgs { planner_seeds: 3, ..base }).expect("bench runs");
    let names: Vec<&str> = three.problems.iter().map(|(_, n)| n.as_str()).collect();
    assert_eq!(names, ["irp6-pick/irp6p", "irp6-pick/irp6p#1", "irp6-pick/irp6p#2"], "{names:?}");
    assert_eq!(one.problems.len(), 1);
    for (a, b) in one.rows.iter().zip(&three.rows) {
        assert_eq!((a.problems * 3, a.deadline_ms), (b.problems, b.deadline_ms));
        assert!(b.requested >= 3 * usize::from(a.requested > 0), "{} ms: {} requests", b.deadline_ms, b.requested);
    }
    assert_eq!(three.rows[0].goals_reached, 0);
    assert_eq!(three.rows[1].goals_reached, 3);
}
