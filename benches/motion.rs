//! Criterion benchmarks: motion planning on fixed problems (IRp-6 around a box, Polycrank
//! across +-pi, the two-arm IRp-6 cell), each with both search back ends, plus the share of
//! planning time spent in collision checks (printed once before the timings); and the two-arm
//! carry planned whole, as `embodied plan two-irp6-carry` does.

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{Criterion, criterion_group, criterion_main};
use embodied_models::collision::{CollisionModel, Environment, Obstacle};
use embodied_models::nalgebra::Isometry3;
use embodied_models::{Rng, Shape, builtin};
use embodied_planner::motion::{Goal, MotionSettings, PlannerKind, plan_motion};

struct Problem {
    name: &'static str,
    model: CollisionModel,
    start: Vec<f64>,
    goal: Vec<f64>,
}

fn model(robot: &str, boxes: &[([f64; 3], [f64; 3])]) -> CollisionModel {
    let robot = builtin(robot).expect("built-in robot");
    let mut env = Environment::new();
    for (i, (c, h)) in boxes.iter().enumerate() {
        env.add(Obstacle::new(
            format!("box{i}"),
            Isometry3::translation(c[0], c[1], c[2]),
            Shape::cuboid(h[0], h[1], h[2]),
        ));
    }
    CollisionModel::new(&robot, env)
}

fn problems() -> Vec<Problem> {
    // The box stands where the IRp-6 tool is with the column at 0: the straight segment between
    // the two sides is blocked, so the search runs.
    let irp6 = builtin("irp6-postument").expect("built-in robot");
    let (flange, _) = irp6.end_effector_poses(&[0.0, -1.6, 0.1, 0.0, 1.5, 0.0], 0);
    let c = flange.translation.vector;
    let mut out = vec![
        Problem {
            name: "irp6-box",
            model: model("irp6-postument", &[([c.x, c.y, c.z / 2.0], [0.12, 0.12, c.z / 2.0])]),
            start: vec![-0.8, -1.6, 0.1, 0.0, 1.5, 0.0],
            goal: vec![0.8, -1.6, 0.1, 0.0, 1.5, 0.0],
        },
        Problem {
            name: "polycrank-wrap",
            model: model("polycrank", &[([0.45, 0.45, 1.3], [0.1, 0.1, 0.1])]),
            start: vec![3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            goal: vec![-3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        },
    ];
    // Two-arm cell: random valid start and goal (fixed seed) with a box between the arms.
    let two = model("two-irp6", &[([0.8, 1.05, 0.5], [0.15, 0.15, 0.5])]);
    let mut rng = Rng::new(11);
    let mut valid = || loop {
        let q = two.robot().random_configuration(&mut rng);
        if !two.collides(&q) {
            break q;
        }
    };
    let (start, goal) = (valid(), valid());
    out.push(Problem { name: "two-irp6", model: two, start, goal });
    out
}

fn settings(planner: PlannerKind, seed: u64) -> MotionSettings {
    MotionSettings { planner, seed, ..MotionSettings::default() }
}

/// Median and p95 over seeds, which planner produced the paths, and an estimate of the
/// collision-check share (as many bare `collides` calls on random configurations as the planner
/// made, over the planning time; random configurations are not the planner's, so it is rough).
fn report(problems: &[Problem]) {
    for p in problems {
        for planner in [PlannerKind::RrtConnect, PlannerKind::LazyPrm] {
            let mut times = Vec::new();
            let (mut checks, mut failures) = (0u64, 0);
            let mut used = std::collections::BTreeMap::new();
            for seed in 0..200 {
                let t = Instant::now();
                match plan_motion(&p.model, &p.start, &Goal::Configuration(p.goal.clone()), &settings(planner, seed)) {
                    Ok(plan) => {
                        checks += plan.stats.collision_checks;
                        *used.entry(plan.stats.planner).or_insert(0) += 1;
                    }
                    Err(_) => failures += 1,
                }
                times.push(t.elapsed());
            }
            times.sort();
            let total: Duration = times.iter().sum();
            let mut rng = Rng::new(1);
            let qs: Vec<Vec<f64>> = (0..1000).map(|_| p.model.robot().random_configuration(&mut rng)).collect();
            let t = Instant::now();
            for q in &qs {
                black_box(p.model.collides(q));
            }
            let per_check = t.elapsed().as_secs_f64() / qs.len() as f64;
            println!(
                "{:16} {:12} median {:8.1} us  p95 {:8.1} us  failures {failures}/200  checks/plan {:7.0}  ~{:4.1}% in collides ({:.2} us/check)  {used:?}",
                p.name,
                format!("{planner:?}"),
                times[times.len() / 2].as_secs_f64() * 1e6,
                times[times.len() * 95 / 100].as_secs_f64() * 1e6,
                checks as f64 / 200.0,
                100.0 * per_check * checks as f64 / total.as_secs_f64(),
                per_check * 1e6,
            );
        }
    }
}

fn bench(c: &mut Criterion) {
    let problems = problems();
    report(&problems);
    let mut group = c.benchmark_group("plan_motion");
    group.measurement_time(Duration::from_secs(3)).sample_size(30);
    for p in &problems {
        for planner in [PlannerKind::RrtConnect, PlannerKind::LazyPrm] {
            let mut seed = 0;
            group.bench_function(format!("{}/{planner:?}", p.name), |b| {
                b.iter(|| {
                    seed += 1;
                    let goal = Goal::Configuration(p.goal.clone());
                    black_box(plan_motion(&p.model, &p.start, &goal, &settings(planner, seed)).ok())
                })
            });
        }
    }
    group.finish();
}

/// The two-arm carry as `embodied plan two-irp6-carry` makes it: grasp, A* over object positions
/// with closed-chain inverse kinematics, timing with inverse kinematics at every 1 ms sample, and
/// the certified check of the result.
fn carry(c: &mut Criterion) {
    let scenario = embodied::scenario::load_scenario("two-irp6-carry").expect("built-in scenario");
    let mut group = c.benchmark_group("plan_scenario");
    group.measurement_time(Duration::from_secs(5)).sample_size(10);
    group.bench_function("two-irp6-carry", |b| {
        b.iter(|| black_box(embodied::plan::plan_scenario(&scenario, None).is_ok()))
    });
    group.finish();
}

criterion_group!(benches, bench, carry);
criterion_main!(benches);
