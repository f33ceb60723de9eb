//! Criterion benchmark: the two-arm closed-chain velocity QP (13 joints of `two-irp6`), one solve.

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use embodied_executor::closed_chain::*;
use embodied_models::nalgebra::DVector;

fn bench(c: &mut Criterion) {
    let robot = embodied_models::builtin("two-irp6").expect("built-in robot");
    let q = robot.home().to_vec();
    let (e1, e2) = (&robot.end_effectors()[0], &robot.end_effectors()[1]);
    let j1 = robot.jacobian(&q, e1.link, &e1.tool);
    let j2 = robot.jacobian(&q, e2.link, &e2.tool);
    let (_, t1) = robot.end_effector_poses(&q, 0);
    let (_, t2) = robot.end_effector_poses(&q, 1);
    let (lower, upper) = velocity_bounds(&q, &robot.limits(), 0.01);
    let qp = ClosedChainQp {
        j_a: absolute_jacobian(&j1, &j2),
        v_a: DVector::from_vec(vec![0.0, 0.0, 0.05, 0.0, 0.0, 0.0]),
        j_r: relative_jacobian(&j1, &j2, &t1, &t2),
        lambda: 1e-4,
        lower,
        upper,
    };
    let mut g = c.benchmark_group("qp");
    g.sample_size(30).measurement_time(Duration::from_secs(3)).warm_up_time(Duration::from_secs(1));
    g.bench_function("closed-chain-two-irp6-solve", |b| b.iter(|| black_box(qp.solve().is_ok())));
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
