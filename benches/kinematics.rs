//! Criterion benchmarks: forward kinematics (all links, and one end effector) and the geometric
//! Jacobian of the first end effector, per built-in robot, over random configurations; inverse
//! kinematics of the IRp-6 on its postument, closed form against the numerical solver, for tool
//! poses reached at random configurations (seeded at the home pose); and the numerical solver
//! tracking a moving target from a nearby seed, as path following does.

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
    // Tracking, as Cartesian path following does it (the two-arm carry's 1 ms samples): the
    // on-track arm of `two-irp6` (7 DOF with its track, so the numerical solver) seeded at a
    // configuration 0.01 rad or m per joint away from one that reaches the target, to 1e-10.
    let cell = builtin("two-irp6").unwrap();
    let near: Vec<(Vec<f64>, Isometry3<f64>)> = (0..64)
        .map(|_| {
            let q = cell.random_configuration(&mut rng);
            let mut reached = q.clone();
            for (v, l) in reached.iter_mut().zip(cell.limits()) {
                *v = l.clamp(*v + rng.range(-0.01, 0.01));
            }
            let target = cell.end_effector_poses(&reached, 0).1;
            (q, target)
        })
        .collect();
    let tracking = IkOptions {
        closed_form: false,
        position_tolerance: 1e-10,
        orientation_tolerance: 1e-10,
        restarts: 0,
        ..IkOptions::default()
    };
    c.bench_function("ik-numerical-tracking/two-irp6-on-track-arm", |b| {
        b.iter(|| {
            i = (i + 1) % near.len();
            let (seed, target) = &near[i];
            black_box(cell.inverse_kinematics(0, black_box(target), seed, &tracking).is_ok())
        })
    });
}

criterion_group!(benches, kinematics, inverse_kinematics);
criterion_main!(benches);
