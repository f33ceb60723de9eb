//! The deadline benchmark on a small problem set: structure, and a zero deadline delivers
//! nothing and halts. Timing is not asserted (noisy machines).

use embodied::deadlines::{DeadlineArgs, plot_svg, render_table, run_deadline_bench};

#[test]
fn small_deadline_bench_is_consistent() {
    let args =
        DeadlineArgs { deadlines_ms: vec![0.0, 200.0], scenarios: vec!["irp6-pick".into()], max_steps: 6000, seed: 1 };
    let report = run_deadline_bench(&args).expect("bench runs");
    assert_eq!(report.rows.len(), 2);
    assert!(!report.problems.is_empty());
    for r in &report.rows {
        assert!((0.0..=1.0).contains(&r.delivered_share));
        assert!(r.delivered_in_time <= r.requested);
        assert!(r.goals_reached <= r.problems);
        assert!(r.halt_distance_mean <= r.halt_distance_max + 1e-12);
    }
    let zero = &report.rows[0];
    assert_eq!(zero.delivered_in_time, 0);
    assert_eq!(zero.goals_reached, 0);
    assert!(zero.requested > 0 && zero.safe_halts > 0);
    let table = render_table(&report);
    assert!(table.contains("deadline"));
    let json = serde_json::to_string(&report).expect("json");
    assert!(json.contains("delivered_share"));
    let svg = std::env::temp_dir().join(format!("deadlines-{}.svg", std::process::id()));
    plot_svg(&report, &svg).expect("plot");
    assert!(std::fs::read_to_string(&svg).expect("svg").contains("<svg"));
    let _ = std::fs::remove_file(&svg);
}

#[test]
fn bad_deadlines_are_a_usage_error() {
    let args = DeadlineArgs { deadlines_ms: vec![-1.0], ..DeadlineArgs::default() };
    assert!(run_deadline_bench(&args).is_err());
}
