//! Criterion benchmarks: collision checking.
//!
//! - `collides/ur5-table-pick/*`: the spherized UR5 of MotionBenchMaker (40 spheres) in the
//!   `table_pick_ur5` scene 0001 (`benches/fixtures/`, read by `planner::moveit`), over fixed sets of free and random
//!   configurations. Target: median <= 1 us per call.
//! - `batch8/ur5-table-pick/{free,random,along-motion}/{8-single,batch}`: eight configurations
//!   checked as one batch (`CollisionModel::any_collides_with`) against eight single checks.
//!   Target: a free batch <= 800 ns (100 ns per configuration). `.../f32-settle`: the same eight
//!   in one single-precision batch (`CollisionModel::settle_batch`, what the certificate's
//!   first pieces go through). `.../mbm-pairs/sse2`: the pairs `bench mbm` checks, on the
//!   x86-64 baseline's instructions where the CPU has AVX2 (`with_baseline_vectors`).
//! - `collides|distance/two-irp6-20-obstacles`: the two-arm IRp-6 cell among 20 boxes/cylinders.
//! - `collides/two-irp6-400-obstacles/free[/no-grid]`: the cell among 400 small obstacles, with
//!   the general path's obstacle grid and without it.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::hint::black_box;
use std::path::Path;

use criterion::{Criterion, criterion_group, criterion_main};
use embodied_models::collision::{
    CollisionModel, Environment, Obstacle, disable_always_colliding, disable_never_colliding,
};
use embodied_models::nalgebra::Isometry3;
use embodied_models::{Rng, Robot, Shape, builtin};

/// `problems/table_pick_ur5/scene0001.yaml` of /work/shared/mbm/ur5/problems-public.tar.bz2,
/// copied unchanged to `benches/fixtures/`, read through the project's MoveIt loader.
fn table_pick_scene0001() -> Environment {
    let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/fixtures/table_pick_ur5_scene0001.yaml");
    embodied_planner::moveit::load_scene(&file).expect("table_pick scene").environment()
}

/// The spherized UR5 with the SRDF's disabled pairs, plus the sphere pairs that touch in every
/// configuration (e.g. `wrist_2_link`/`fts_robotside`: the spheres overlap where the meshes do not).
fn ur5() -> Robot {
    let dir = Path::new("/work/shared/mbm/ur5");
    let mut robot = embodied_models::urdf::load_urdf(&dir.join("ur5_spherized.urdf"), Some(&dir.join("ur5.srdf")))
        .expect("UR5 URDF");
    let disabled = disable_always_colliding(&mut robot, 1000, 3);
    let name = |l: usize| robot.links()[l].name.clone();
    let names: Vec<(String, String)> = disabled.iter().map(|&(a, b)| (name(a), name(b))).collect();
    eprintln!("ur5: always-colliding pairs disabled: {names:?}");
    robot
}

/// `n` random configurations, and `n` of them that are collision-free.
fn samples(robot: &Robot, model: &CollisionModel, n: usize, seed: u64) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
    let mut rng = Rng::new(seed);
    let random: Vec<Vec<f64>> = (0..n).map(|_| robot.random_configuration(&mut rng)).collect();
    let mut free = Vec::new();
    for _ in 0..1000 * n {
        if free.len() == n {
            break;
        }
        let q = robot.random_configuration(&mut rng);
        if !model.collides(&q) {
            free.push(q);
        }
    }
    assert!(!free.is_empty(), "no collision-free configuration found");
    (random, free)
}

fn bench_cycle<R>(c: &mut Criterion, name: &str, qs: &[Vec<f64>], mut f: impl FnMut(&[f64]) -> R) {
    let mut i = 0;
    c.bench_function(name, |b| {
        b.iter(|| {
            i = (i + 1) % qs.len();
            black_box(f(black_box(&qs[i])))
        })
    });
}

fn ur5_table_pick(c: &mut Criterion) {
    let robot = ur5();
    let model = CollisionModel::new(&robot, table_pick_scene0001());
    let (random, free) = samples(&robot, &model, 256, 1);
    let colliding = random.iter().filter(|q| model.collides(q)).count();
    let spheres: usize = robot.links().iter().map(|l| l.shapes.len()).sum();
    eprintln!(
        "ur5: {} dof, {spheres} spheres, {} self pairs checked; {colliding}/256 random configurations collide",
        robot.dof(),
        model.self_collision_pairs().len()
    );
    let mut scratch = model.scratch();
    bench_cycle(c, "collides/ur5-table-pick/free", &free, |q| model.collides(q));
    bench_cycle(c, "collides/ur5-table-pick/random", &random, |q| model.collides(q));
    let mut i = 0;
    c.bench_function("collides_with/ur5-table-pick/free", |b| {
        b.iter(|| {
            i = (i + 1) % free.len();
            black_box(model.collides_with(black_box(&free[i]), &mut scratch))
        })
    });
    // Eight configurations at once (`batch_collisions_with`, one per vector lane) against
    // eight single checks of the same configurations: free ones, random ones (the batch stops
    // at its first contact, as the singles do), and eight points along a short motion (as a
    // planner's edge probe).
    let dof = robot.dof();
    let flat = |qs: &[Vec<f64>]| -> Vec<Vec<f64>> { qs.chunks_exact(8).map(|c| c.concat()).collect() };
    let (free8, random8) = (flat(&free), flat(&random));
    let space = robot.config_space();
    let along8: Vec<Vec<f64>> = free
        .windows(2)
        .map(|w| (1..=8).flat_map(|k| space.interpolate(&w[0], &w[1], 0.1 * k as f64 / 8.0)).collect())
        .collect();
    for (name, set) in [("free", &free8), ("random", &random8), ("along-motion", &along8)] {
        let mut i = 0;
        c.bench_function(&format!("batch8/ur5-table-pick/{name}/8-single"), |b| {
            b.iter(|| {
                i = (i + 1) % set.len();
                black_box(black_box(&set[i]).chunks_exact(dof).any(|q| model.collides_with(q, &mut scratch)))
            })
        });
        let mut i = 0;
        c.bench_function(&format!("batch8/ur5-table-pick/{name}/batch"), |b| {
            b.iter(|| {
                i = (i + 1) % set.len();
                black_box(model.any_collides_with(black_box(&set[i]), &mut scratch))
            })
        });
        let mut i = 0;
        c.bench_function(&format!("batch8/ur5-table-pick/{name}/f32-settle"), |b| {
            b.iter(|| {
                i = (i + 1) % set.len();
                black_box(model.settle_batch(black_box(&set[i]), 0.0, &mut scratch))
            })
        });
        // The planner's probe query: the batch, then what it leaves unsettled one by one (the
        // same answer as `8-single`).
        let mut i = 0;
        c.bench_function(&format!("batch8/ur5-table-pick/{name}/any-settled"), |b| {
            b.iter(|| {
                i = (i + 1) % set.len();
                black_box(model.any_collides_settled(black_box(&set[i]), &mut scratch))
            })
        });
    }
    // The pairs `embodied bench mbm` checks: also without the pairs proven never to touch.
    let mut pruned = robot.clone();
    disable_never_colliding(&mut pruned, 2, 200_000);
    let planner_model = CollisionModel::new(&pruned, table_pick_scene0001());
    eprintln!("ur5: {} self pairs checked as in bench mbm", planner_model.self_collision_pairs().len());
    bench_cycle(c, "collides/ur5-table-pick/free/mbm-pairs", &free, |q| planner_model.collides(q));
    // Also on the x86-64 baseline's instructions (SSE2) where the CPU has AVX2 (`/sse2`): what
    // the run-time dispatch of the batch gains on this machine.
    let (mut planner_scratch, mut baseline) =
        (planner_model.scratch(), planner_model.scratch().with_baseline_vectors());
    for (isa, s) in [("", &mut planner_scratch), ("/sse2", &mut baseline)] {
        bench_cycle(c, &format!("batch8/ur5-table-pick/free/8-single/mbm-pairs{isa}"), &free8, |qs| {
            qs.chunks_exact(dof).any(|q| planner_model.collides_with(q, s))
        });
        bench_cycle(c, &format!("batch8/ur5-table-pick/free/f32-settle/mbm-pairs{isa}"), &free8, |qs| {
            planner_model.settle_batch(qs, 0.0, s)
        });
    }
    let general = model.clone().general_path_only();
    bench_cycle(c, "collides/ur5-table-pick/free/general-path", &free, |q| general.collides(q));
    bench_cycle(c, "distance/ur5-table-pick/free", &free, |q| model.distance(q).distance > 0.0);
    let mut k = 0;
    c.bench_function("motion_is_free/ur5-table-pick/free-pairs-0.05rad", |b| {
        b.iter(|| {
            k = (k + 1) % (free.len() - 1);
            black_box(model.motion_is_free(&free[k], &free[k + 1], 0.05))
        })
    });
    // Short motions (0.1 of the way between two free configurations), as a planner's edges.
    let short: Vec<(Vec<f64>, Vec<f64>)> = free
        .windows(2)
        .map(|w| (w[0].clone(), space.interpolate(&w[0], &w[1], 0.1)))
        .filter(|(_, b)| !model.collides(b))
        .collect();
    let certified = short.iter().filter(|(a, b)| model.motion_is_certified_free(a, b, 1e-4)).count();
    eprintln!("ur5: {certified}/{} short motions certified free", short.len());
    let mut k = 0;
    c.bench_function("motion_is_certified_free/ur5-table-pick/short-motions", |b| {
        b.iter(|| {
            k = (k + 1) % short.len();
            black_box(model.motion_is_certified_free(&short[k].0, &short[k].1, 1e-4))
        })
    });
    let mut k = 0;
    c.bench_function("motion_is_free/ur5-table-pick/short-motions-0.005rad", |b| {
        b.iter(|| {
            k = (k + 1) % short.len();
            black_box(model.motion_is_free(&short[k].0, &short[k].1, 0.005))
        })
    });
}

/// 20 boxes and cylinders on a ring around the two-IRp-6 cell, partly within reach.
fn irp6_obstacles() -> Environment {
    (0..20)
        .map(|i| {
            let a = i as f64 * 0.61;
            let r = 1.9 + 0.3 * (i % 3) as f64;
            let pose = Isometry3::translation(r * a.cos(), 1.05 + r * a.sin(), 0.2 + 0.09 * i as f64);
            let shape = if i % 2 == 0 { Shape::cuboid(0.08, 0.1, 0.12) } else { Shape::cylinder(0.07, 0.1) };
            Obstacle::new(format!("o{i}"), pose, shape)
        })
        .collect()
}

fn two_irp6(c: &mut Criterion) {
    let robot = builtin("two-irp6").unwrap();
    let model = CollisionModel::new(&robot, irp6_obstacles());
    let (random, free) = samples(&robot, &model, 256, 2);
    let colliding = random.iter().filter(|q| model.collides(q)).count();
    eprintln!(
        "two-irp6: {} self pairs checked; {colliding}/256 random configurations collide",
        model.self_collision_pairs().len()
    );
    bench_cycle(c, "collides/two-irp6-20-obstacles/free", &free, |q| model.collides(q));
    bench_cycle(c, "collides/two-irp6-20-obstacles/random", &random, |q| model.collides(q));
    bench_cycle(c, "distance/two-irp6-20-obstacles/free", &free, |q| model.distance(q).distance > 0.0);
}

/// 400 small boxes and balls strewn through the two-IRp-6 cell (none touching it at home): the
/// general path's obstacle grid against the plain obstacle pass.
fn two_irp6_clutter(c: &mut Criterion) {
    let robot = builtin("two-irp6").unwrap();
    let mut rng = Rng::new(3);
    let mut clutter = Vec::new();
    while clutter.len() < 400 {
        let pose = Isometry3::translation(rng.range(-2.5, 2.5), rng.range(-1.5, 3.5), rng.range(0.0, 2.5));
        let shape = if clutter.len() % 2 == 0 { Shape::cuboid(0.03, 0.05, 0.04) } else { Shape::sphere(0.04) };
        let o = Obstacle::new(format!("o{}", clutter.len()), pose, shape);
        if !CollisionModel::new(&robot, std::iter::once(o.clone()).collect()).collides(robot.home()) {
            clutter.push(o);
        }
    }
    let model = CollisionModel::new(&robot, clutter.into_iter().collect());
    let (_, free) = samples(&robot, &model, 256, 4);
    let plain = model.clone().without_obstacle_grid();
    bench_cycle(c, "collides/two-irp6-400-obstacles/free", &free, |q| model.collides(q));
    bench_cycle(c, "collides/two-irp6-400-obstacles/free/no-grid", &free, |q| plain.collides(q));
}

criterion_group!(benches, ur5_table_pick, two_irp6, two_irp6_clutter);
criterion_main!(benches);
