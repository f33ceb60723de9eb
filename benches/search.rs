//! Criterion benchmarks: A* search (grid and task level) and the deadline overshoot.
//!
//! Besides the criterion groups, `main` prints two numbers criterion does not measure:
//! A* expansions per second on a full 2000x2000 search, and the deadline overshoot
//! distribution (p50/p95/max) of `solve` against a wall-clock deadline.

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::Criterion;
use embodied_planner::deadline::Deadline;
use embodied_planner::search::grid::GridWorld;
use embodied_planner::search::{self, SearchProblem, solve, solve_astar};
use embodied_planner::task::TwoIrp6Cell;

fn percentile(sorted: &[Duration], p: f64) -> Duration {
    if sorted.is_empty() {
        return Duration::ZERO;
    }
    let i = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

fn expansions_per_second<P: SearchProblem>(name: &str, problem: &P) {
    let started = Instant::now();
    let report = solve(problem, &Deadline::none());
    let elapsed = started.elapsed();
    let rate = report.stats.expansions as f64 / elapsed.as_secs_f64();
    let verdict = match &report.outcome {
        search::SearchOutcome::Solved(plan) => format!("solved, cost {:.1}", plan.cost),
        search::SearchOutcome::Infeasible => "infeasible".to_owned(),
        search::SearchOutcome::OutOfTime { .. } => "out of time".to_owned(),
    };
    println!(
        "{name}: {} expansions, {} generated in {elapsed:.2?} -> {:.2} M expansions/s ({verdict})",
        report.stats.expansions,
        report.stats.generated,
        rate / 1e6
    );
}

fn print_measurements() {
    let solvable = GridWorld::random(2000, 2000, 0.2, 7);
    let walled = solvable.clone().with_goal_walled_off();
    expansions_per_second("A* 2000x2000 8-connected, 20% obstacles, solvable", &solvable);
    expansions_per_second("A* 2000x2000 8-connected, 20% obstacles, goal walled off (whole grid)", &walled);
    for budget_ms in [1u64, 10] {
        let mut samples = search::deadline_overshoot_samples(200, Duration::from_millis(budget_ms));
        samples.sort();
        println!(
            "deadline overshoot ({budget_ms} ms deadline, {} runs): p50 {:.1?}  p95 {:.1?}  max {:.1?}",
            samples.len(),
            percentile(&samples, 0.5),
            percentile(&samples, 0.95),
            samples.last().copied().unwrap_or_default()
        );
    }
}

fn bench_grid(c: &mut Criterion) {
    let mut group = c.benchmark_group("astar_grid");
    group.sample_size(10).measurement_time(Duration::from_secs(8));
    let world = GridWorld::random(2000, 2000, 0.2, 7);
    group.bench_function("solve_2000x2000", |b| b.iter(|| black_box(solve(&world, &Deadline::none()))));
    group.bench_function("pathfinding_astar_2000x2000", |b| b.iter(|| black_box(solve_astar(&world))));
    let small = GridWorld::random(200, 200, 0.2, 7);
    group.bench_function("solve_200x200", |b| b.iter(|| black_box(solve(&small, &Deadline::none()))));
    group.bench_function("pathfinding_astar_200x200", |b| b.iter(|| black_box(solve_astar(&small))));
    group.finish();
}

fn bench_deadline(c: &mut Criterion) {
    let mut group = c.benchmark_group("astar_deadline");
    group.sample_size(20);
    let walled = GridWorld::random(2000, 2000, 0.2, 7).with_goal_walled_off();
    group.bench_function("wall_clock_1ms", |b| {
        b.iter(|| black_box(solve(&walled, &Deadline::after(Duration::from_millis(1)))))
    });
    group.bench_function("budget_10k_expansions", |b| {
        b.iter(|| black_box(solve(&walled, &Deadline::expansions(10_000))))
    });
    group.finish();
}

fn bench_task(c: &mut Criterion) {
    let mut group = c.benchmark_group("task_plan");
    let cell = TwoIrp6Cell::new();
    let one = cell.transfer_to_table_b("cube").expect("valid task");
    group.bench_function("two_irp6_transfer_one_object", |b| b.iter(|| black_box(solve(&one, &Deadline::none()))));
    let mut swap = TwoIrp6Cell::new();
    swap.objects = vec![("cube".into(), "table_a".into()), ("cylinder".into(), "table_b".into())];
    let two = swap.problem(&[("cube", "table_b"), ("cylinder", "table_a")]).expect("valid task");
    group.bench_function("two_irp6_swap_two_objects", |b| b.iter(|| black_box(solve(&two, &Deadline::none()))));
    group.finish();
}

fn main() {
    // `cargo test --benches` runs this in test mode: keep it quick there.
    let test_mode = std::env::args().any(|a| a == "--test");
    if !test_mode {
        print_measurements();
    }
    let mut c = Criterion::default().configure_from_args();
    bench_grid(&mut c);
    bench_deadline(&mut c);
    bench_task(&mut c);
    c.final_summary();
}
