//! Criterion benchmarks: forward kinematics (all links, and one end effector) and the geometric
//! Jacobian of the first end effector, per built-in robot, over random configurations; inverse
//! kinematics of the IRp-6 on its postument, closed form against the numerical solver, for tool
//! poses reached at random configurations (seeded at the home pose).

#![allow(clippy::unwrap_used)]

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use embodied_models::nalgebra::Isometry3;
use embodied_models::{BUILTIN_NAMES, IkOptions, Rng, builtin};

fn kinematics(c: &mut Criterion) {
    for name in BUILTIN_NAMES {
        let robot = builtin(name).unwrap();
        let mut rng = Rng::new(5);
        let qs: Vec<Vec<f64>> = (0..256).map(|_| robot.random_configuration(&mut rng)).collect();
        let mut poses = vec![Isometry3::identity(); robot.links().len()];
        let ee = &robot.end_effectors()[0];
        let (link, tool) = (ee.link, ee.tool);
        let mut i = 0;
        c.bench_function(&format!("fk-all-links/{name}"), |b| {
            b.iter(|| {
                i = (i + 1) % qs.len();
                robot.forward_kinematics_into(black_box(&qs[i]), &mut poses);
                black_box(&poses);
            })
        });
        c.bench_function(&format!("fk-end-effector/{name}"), |b| {
            b.iter(|| {
                i = (i + 1) % qs.len();
                black_box(robot.end_effector_poses(black_box(&qs[i]), 0))
            })
        });
        c.bench_function(&format!("jacobian/{name}"), |b| {
            b.iter(|| {
                i = (i + 1) % qs.len();
                black_box(robot.jacobian(black_box(&qs[i]), link, &tool))
            })
        });
    }
}

fn inverse_kinematics(c: &mut Criterion) {
    let robot = builtin("irp6-postument").unwrap();
    let mut rng = Rng::new(9);
    let targets: Vec<Isometry3<f64>> =
        (0..64).map(|_| robot.end_effector_poses(&robot.random_configuration(&mut rng), 0).1).collect();
    let home = robot.home().to_vec();
    let mut i = 0;
    c.bench_function("ik-closed-form-all/irp6-postument", |b| {
        b.iter(|| {
            i = (i + 1) % targets.len();
            black_box(robot.inverse_kinematics_all(0, black_box(&targets[i]), &home).unwrap().len())
        })
    });
    let numerical = IkOptions { closed_form: false, ..IkOptions::default() };
    c.bench_function("ik-numerical/irp6-postument", |b| {
        b.iter(|| {
            i = (i + 1) % targets.len();
            black_box(robot.inverse_kinematics(0, black_box(&targets[i]), &home, &numerical).is_ok())
        })
    });
}

criterion_group!(benches, kinematics, inverse_kinematics);
criterion_main!(benches);
