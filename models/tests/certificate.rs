//! The sphere fast path and the conservative motion certificate.
#![allow(clippy::unwrap_used)]

use std::path::PathBuf;

use embodied_models::collision::{CollisionModel, Environment, Obstacle, disable_always_colliding};
use embodied_models::nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};
use embodied_models::urdf::load_urdf;
use embodied_models::{
    ConfigSpace, ConvexHull, JointKind, JointLimits, PlacedShape, Rng, Robot, RobotBuilder, Shape, builtin,
};
use proptest::prelude::*;

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures").join(name)
}

fn ur5() -> Robot {
    let mut r = load_urdf(&fixture("ur5_spherized.urdf"), Some(&fixture("ur5.srdf"))).unwrap();
    disable_always_colliding(&mut r, 300, 3);
    r
}

/// Boxes, cylinders, balls, capsules and a convex mesh scattered around the arm's base, at
/// random poses (the seed picks them), none over the base itself.
fn clutter(seed: u64, n: usize) -> Environment {
    let mut rng = Rng::new(seed);
    let mut env = Environment::new();
    let mut k = 0;
    while env.len() < n {
        let p = Vector3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-0.3, 1.2));
        if p.xy().norm() < 0.3 {
            continue;
        }
        let rot = UnitQuaternion::from_euler_angles(rng.range(-3.0, 3.0), rng.range(-3.0, 3.0), rng.range(-3.0, 3.0));
        let pose = Isometry3::from_parts(p.into(), rot);
        let shape = match k % 5 {
            0 => Shape::cuboid(rng.range(0.02, 0.2), rng.range(0.02, 0.2), rng.range(0.02, 0.2)),
            1 => Shape::cylinder(rng.range(0.02, 0.15), rng.range(0.05, 0.3)),
            2 => Shape::sphere(rng.range(0.02, 0.15)),
            3 => Shape::capsule([0.0, 0.0, -0.1], [0.0, 0.0, 0.1], rng.range(0.02, 0.1)),
            _ => Shape::ConvexMesh(std::sync::Arc::new(
                ConvexHull::from_points(&[
                    Point3::new(0.0, 0.0, 0.0),
                    Point3::new(0.15, 0.0, 0.0),
                    Point3::new(0.0, 0.15, 0.0),
                    Point3::new(0.0, 0.0, 0.15),
                ])
                .unwrap(),
            )),
        };
        env.add(Obstacle::new(format!("o{k}"), pose, shape));
        k += 1;
    }
    env
}

#[test]
fn spherized_ur5_takes_the_sphere_path_and_agrees_with_the_general_path() {
    let robot = ur5();
    for seed in 0..4 {
        let fast = CollisionModel::new(&robot, clutter(seed, 12));
        assert!(fast.uses_sphere_path());
        let general = fast.clone().general_path_only();
        assert!(!general.uses_sphere_path());
        let mut rng = Rng::new(seed + 100);
        let (mut hits, mut n) = (0, 0);
        for _ in 0..1500 {
            let q = robot.random_configuration(&mut rng);
            let c = fast.collides(&q);
            assert_eq!(c, general.collides(&q), "seed {seed}, q = {q:?}");
            assert_eq!(c, general.first_collision(&q).is_some());
            assert_eq!(c, fast.first_collision(&q).is_some(), "seed {seed}, q = {q:?}");
            hits += c as usize;
            n += 1;
        }
        // Both answers occur, so the comparison means something.
        assert!(hits > n / 20 && hits < n - n / 20, "{hits} of {n} collide");
    }
    // A robot with capsules does not take the sphere path.
    let irp6 = builtin("irp6-postument").unwrap();
    assert!(!CollisionModel::new(&irp6, Environment::new()).uses_sphere_path());
}

/// A sphere-only arm with every joint form the sphere path poses: skewed revolute axes, a
/// prismatic joint along a skewed axis, a DH-style `post` transform with an offset, a fixed
/// joint (two links on one body), a mimic joint, and a rotated base.
fn skewed_sphere_arm() -> Robot {
    let balls = |points: &[[f64; 3]], r: f64| -> Vec<PlacedShape> {
        points.iter().map(|p| PlacedShape::new(Isometry3::translation(p[0], p[1], p[2]), Shape::sphere(r))).collect()
    };
    let rpy = |x: f64, y: f64, z: f64, r: f64, p: f64, w: f64| {
        Isometry3::from_parts(Vector3::new(x, y, z).into(), UnitQuaternion::from_euler_angles(r, p, w))
    };
    let limits = JointLimits::new(-2.5, 2.5, 1.0, 2.0);
    let mut b = RobotBuilder::new("skewed-spheres").base(rpy(0.05, -0.1, 0.0, 0.1, -0.2, 0.7));
    let base = b.link("base", balls(&[[0.0, 0.0, 0.05], [0.05, 0.0, 0.1]], 0.08));
    let l1 = b.link("l1", balls(&[[0.0, 0.0, 0.1], [0.0, 0.05, 0.25], [0.02, 0.1, 0.4]], 0.06));
    let l2 = b.link("l2", balls(&[[0.0, 0.0, 0.0], [0.15, 0.0, 0.0], [0.3, 0.02, 0.0]], 0.05));
    let l3 = b.link("l3", balls(&[[0.0, 0.0, 0.0], [0.0, 0.2, 0.0], [0.0, 0.35, 0.05]], 0.05));
    let l3b = b.link("l3_cover", balls(&[[0.1, 0.3, 0.0], [0.12, 0.35, 0.1]], 0.04));
    let l4 = b.link("l4", balls(&[[0.0, 0.0, 0.0], [0.1, 0.0, 0.1], [0.2, 0.0, 0.15]], 0.04));
    b.joint(
        "j1",
        JointKind::Revolute,
        base,
        l1,
        rpy(0.0, 0.0, 0.15, 0.0, 0.0, 0.3),
        Vector3::new(0.3, -0.5, 0.8),
        0.0,
        Isometry3::identity(),
        limits,
    );
    b.joint(
        "j2",
        JointKind::Prismatic,
        l1,
        l2,
        rpy(0.02, 0.1, 0.45, 0.4, 0.2, -0.3),
        Vector3::new(1.0, 1.0, 0.0),
        0.05,
        Isometry3::identity(),
        JointLimits::new(-0.1, 0.35, 0.5, 1.0),
    );
    // DH: Tz(d) Tx(a) Rx(alpha) after the motion, with an offset on the joint value.
    let post = Isometry3::translation(0.0, 0.0, 0.08)
        * Isometry3::translation(0.12, 0.0, 0.0)
        * Isometry3::rotation(Vector3::x() * 0.7);
    b.joint(
        "j3",
        JointKind::Continuous,
        l2,
        l3,
        rpy(0.3, 0.0, 0.0, 0.0, 0.5, 0.0),
        Vector3::new(0.0, 1.0, 0.0),
        0.3,
        post,
        JointLimits::continuous(1.0, 2.0),
    );
    b.joint(
        "j3_cover",
        JointKind::Fixed,
        l3,
        l3b,
        rpy(0.0, 0.05, 0.0, 0.2, 0.0, 0.0),
        Vector3::z(),
        0.0,
        Isometry3::identity(),
        limits,
    );
    let j4 = b.joint(
        "j4",
        JointKind::Revolute,
        l3,
        l4,
        rpy(0.0, 0.4, 0.05, 0.0, 0.0, 0.0),
        Vector3::new(-0.2, 0.1, 1.0),
        0.0,
        Isometry3::identity(),
        limits,
    );
    b.mimic(j4, "j1".into(), -0.8, 0.2);
    b.build().unwrap()
}

#[test]
fn sphere_path_agrees_with_the_general_path_on_every_joint_form() {
    let robot = skewed_sphere_arm();
    assert_eq!(robot.dof(), 3);
    let space = robot.config_space();
    for seed in 0..4 {
        let mut env = Environment::new();
        let mut rng = Rng::new(seed + 40);
        for k in 0..10 {
            let p = Vector3::new(rng.range(-0.7, 0.7), rng.range(-0.7, 0.7), rng.range(0.0, 0.9));
            if p.xy().norm() < 0.2 {
                continue;
            }
            let rot =
                UnitQuaternion::from_euler_angles(rng.range(-3.0, 3.0), rng.range(-3.0, 3.0), rng.range(-3.0, 3.0));
            let shape = if k % 2 == 0 { Shape::cuboid(0.1, 0.05, 0.08) } else { Shape::sphere(0.07) };
            env.add(Obstacle::new(format!("o{k}"), Isometry3::from_parts(p.into(), rot), shape));
        }
        let fast = CollisionModel::new(&robot, env);
        assert!(fast.uses_sphere_path());
        let general = fast.clone().general_path_only();
        let (mut hits, mut n) = (0, 0);
        for i in 0..1500 {
            let mut q = robot.random_configuration(&mut rng);
            // Every tenth query turns the continuous joint by millions of radians: beyond the
            // range of the sphere path's own sine and cosine (2^20), where it falls back to libm's.
            if i % 10 == 0 {
                q[2] += 2.0e6;
            }
            let c = fast.collides(&q);
            assert_eq!(c, general.collides(&q), "seed {seed}, q = {q:?}");
            hits += c as usize;
            n += 1;
        }
        assert!(hits > n / 20 && hits < n - n / 20, "seed {seed}: {hits} of {n} collide");
        // Certified motions of the fast path are free when sampled finely.
        let mut certified = 0;
        for _ in 0..150 {
            let qa = robot.random_configuration(&mut rng);
            let far = robot.random_configuration(&mut rng);
            let qb = space.interpolate(&qa, &far, 0.3);
            if fast.motion_is_certified_free(&qa, &qb, 1e-4) {
                certified += 1;
                assert!(general.motion_is_free(&qa, &qb, 0.0005), "certified but collides: {qa:?} -> {qb:?}");
            }
        }
        assert!(certified > 10, "seed {seed}: only {certified} of 150 motions certified");
    }
}

/// Points that move rigidly with each link: shape centres and capsule end points, world frame.
fn link_points(robot: &Robot, q: &[f64]) -> Vec<(usize, Vector3<f64>)> {
    let poses = robot.forward_kinematics(q);
    let mut out = Vec::new();
    for (l, link) in robot.links().iter().enumerate() {
        for ps in &link.shapes {
            let pose = poses[l] * ps.pose;
            out.push((l, pose.translation.vector));
            if let Shape::Capsule { a, b, .. } = &ps.shape {
                out.push((l, (pose * a).coords));
                out.push((l, (pose * b).coords));
            }
        }
    }
    out
}

fn all_robots() -> Vec<Robot> {
    let mut v: Vec<Robot> = ["irp6-postument", "irp6-on-track", "two-irp6", "polycrank", "rnt"]
        .iter()
        .map(|n| builtin(n).unwrap())
        .collect();
    v.push(ur5());
    v
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// No point of a link travels further along a straight joint-space motion than the bound
    /// the certificate grows the link by (measured as the length of the sampled path).
    #[test]
    fn travel_bounds_hold_on_every_robot(which in 0usize..6, seed in any::<u64>(), scale in 0.01f64..1.0) {
        let robots = all_robots();
        let robot = &robots[which];
        let model = CollisionModel::new(robot, Environment::new());
        let mut rng = Rng::new(seed);
        let qa = robot.random_configuration(&mut rng);
        let target = robot.random_configuration(&mut rng);
        let space = robot.config_space();
        let qb = space.interpolate(&qa, &target, scale);
        let bounds = model.travel_bounds(&qa, &qb);
        prop_assert!(!bounds.is_empty());
        // Path length of every point, sampled finely; the largest per link.
        let n = 200;
        let mut last = link_points(robot, &qa);
        let mut length = vec![0.0; last.len()];
        for k in 1..=n {
            let q = space.interpolate(&qa, &qb, k as f64 / n as f64);
            let now = link_points(robot, &q);
            for (i, ((_, a), (_, b))) in last.iter().zip(&now).enumerate() {
                length[i] += (b - a).norm();
            }
            last = now;
        }
        let mut travelled = vec![0.0f64; robot.links().len()];
        for (i, (l, _)) in last.iter().enumerate() {
            travelled[*l] = travelled[*l].max(length[i]);
        }
        for (l, bound) in bounds {
            prop_assert!(travelled[l] <= bound * (1.0 + 1e-9) + 1e-12,
                "{}: link {} travels {} > bound {}", robot.name(), robot.links()[l].name, travelled[l], bound);
        }
    }
}

#[test]
fn certified_motions_are_free_at_a_fine_resolution() {
    let robot = ur5();
    let space = robot.config_space();
    for seed in 0..3 {
        let model = CollisionModel::new(&robot, clutter(seed, 10));
        let mut rng = Rng::new(seed + 7);
        let (mut certified, mut refused, mut tried) = (0, 0, 0);
        while tried < 150 {
            let qa = robot.random_configuration(&mut rng);
            let far = robot.random_configuration(&mut rng);
            let qb = space.interpolate(&qa, &far, 0.3);
            if model.collides(&qa) || model.collides(&qb) {
                continue;
            }
            tried += 1;
            let fine = model.motion_is_free(&qa, &qb, 0.0005);
            if model.motion_is_certified_free(&qa, &qb, 1e-4) {
                certified += 1;
                assert!(fine, "certified but collides: {qa:?} -> {qb:?}");
            } else {
                refused += 1;
            }
        }
        assert!(certified > 20 && refused > 5, "seed {seed}: {certified} certified, {refused} refused");
    }
}

#[test]
fn general_path_certificate_is_sound_on_irp6_among_obstacles() {
    let robot = builtin("irp6-postument").unwrap();
    let space = robot.config_space();
    let model = CollisionModel::new(&robot, clutter(11, 10));
    let mut rng = Rng::new(5);
    let (mut certified, mut tried) = (0, 0);
    while tried < 60 {
        let qa = robot.random_configuration(&mut rng);
        let far = robot.random_configuration(&mut rng);
        let qb = space.interpolate(&qa, &far, 0.3);
        if model.collides(&qa) || model.collides(&qb) {
            continue;
        }
        tried += 1;
        if model.motion_is_certified_free(&qa, &qb, 1e-4) {
            certified += 1;
            assert!(model.motion_is_free(&qa, &qb, 0.001), "{qa:?} -> {qb:?}");
        }
    }
    assert!(certified > 10, "{certified} of {tried} certified");
}

#[test]
fn few_checks_certify_a_long_motion_with_clearance() {
    let robot = ur5();
    let far = Obstacle::new("far", Isometry3::translation(5.0, 0.0, 0.0), Shape::cuboid(0.5, 0.5, 0.5));
    let model = CollisionModel::new(&robot, Environment::new().with(far));
    // Free configurations turning their base by 1 rad (the spherized UR5 keeps only 2.5 mm
    // between base_link and upper_arm_link, so the margins must shrink to that).
    let mut rng = Rng::new(9);
    let mut counts = Vec::new();
    while counts.len() < 20 {
        let qa = robot.random_configuration(&mut rng);
        let mut qb = qa.clone();
        qb[0] += 1.0;
        if !robot.within_limits(&qb) || !model.motion_is_free(&qa, &qb, 0.005) {
            continue;
        }
        let mut s = model.scratch();
        let (free, checks) = model.certify(&qa, &qb, 1e-4, false, &mut s);
        assert!(free);
        counts.push(checks);
    }
    counts.sort_unstable();
    eprintln!("checks to certify a 1 rad base turn: {counts:?}");
    // Far fewer than the 200 of a 0.005 rad scan.
    assert!(counts[10] <= 100, "median {} checks", counts[10]);
}

#[test]
fn certificate_catches_a_thin_plate_and_bad_input() {
    let r = builtin("irp6-postument").unwrap();
    let (flange, _) = r.end_effector_poses(r.home(), 0);
    let p = flange.translation.vector;
    let plate = Obstacle::new("plate", Isometry3::translation(p.x, p.y, p.z), Shape::cuboid(0.1, 0.001, 0.1));
    let m = CollisionModel::new(&r, Environment::new().with(plate));
    let mut qa = r.home().to_vec();
    let mut qb = qa.clone();
    qa[0] = -0.5;
    qb[0] = 0.5;
    assert!(!m.collides(&qa) && !m.collides(&qb));
    assert!(!m.motion_is_certified_free(&qa, &qb, 1e-4));
    assert!(!m.motion_is_certified_free(&qb, &qa, 1e-4));
    let empty = CollisionModel::new(&r, Environment::new());
    assert!(empty.motion_is_certified_free(&qa, &qb, 1e-4));
    assert!(!empty.motion_is_certified_free(&qa[..3], &qb, 1e-4));
    assert!(!empty.motion_is_certified_free(&qa, &qb, 0.0));
    assert!(!empty.motion_is_certified_free(&qa, &qb, f64::NAN));
    let mut nan = qb.clone();
    nan[2] = f64::NAN;
    assert!(!empty.motion_is_certified_free(&qa, &nan, 1e-4));
}

/// An arm whose second body carries two links side by side (fixed joints from the same parent,
/// so not adjacent), `gap` apart between sphere surfaces: a self pair that never moves.
fn arm_with_a_rigid_pair(gap: f64) -> Robot {
    let ball =
        |x: f64, y: f64, z: f64, r: f64| vec![PlacedShape::new(Isometry3::translation(x, y, z), Shape::sphere(r))];
    let limits = JointLimits::new(-2.5, 2.5, 1.0, 2.0);
    let mut b = RobotBuilder::new("rigid-pair");
    let base = b.link("base", ball(0.0, 0.0, 0.05, 0.05));
    let arm = b.link("arm", ball(0.0, 0.0, 0.3, 0.04));
    let left = b.link("left", ball(0.0, 0.0, 0.0, 0.05));
    let right = b.link("right", ball(0.0, 0.0, 0.0, 0.05));
    let joint = |b: &mut RobotBuilder, name: &str, kind, parent, child, at: Isometry3<f64>| {
        b.joint(name, kind, parent, child, at, Vector3::y(), 0.0, Isometry3::identity(), limits);
    };
    joint(&mut b, "j1", JointKind::Revolute, base, arm, Isometry3::translation(0.0, 0.0, 0.1));
    joint(&mut b, "left", JointKind::Fixed, arm, left, Isometry3::translation(0.3, -(0.05 + gap / 2.0), 0.4));
    joint(&mut b, "right", JointKind::Fixed, arm, right, Isometry3::translation(0.3, 0.05 + gap / 2.0, 0.4));
    b.build().unwrap()
}

#[test]
fn a_self_pair_on_one_body_is_answered_like_the_general_path() {
    for (gap, always) in [(-0.01, true), (0.01, false)] {
        let robot = arm_with_a_rigid_pair(gap);
        let left = robot.links().iter().position(|l| l.name == "left").unwrap();
        let right = robot.links().iter().position(|l| l.name == "right").unwrap();
        let mut env = Environment::new();
        env.add(Obstacle::new("post", Isometry3::translation(0.45, 0.0, 0.2), Shape::cuboid(0.03, 0.03, 0.2)));
        let fast = CollisionModel::new(&robot, env);
        assert!(fast.uses_sphere_path());
        assert!(fast.self_collision_pairs().contains(&(left.min(right), left.max(right))));
        let general = fast.clone().general_path_only();
        let mut rng = Rng::new(7);
        let mut hits = 0;
        for _ in 0..400 {
            let q = robot.random_configuration(&mut rng);
            let c = fast.collides(&q);
            assert_eq!(c, general.collides(&q), "gap {gap}, q = {q:?}");
            hits += c as usize;
        }
        if always {
            assert_eq!(hits, 400, "overlapping rigid pair: every configuration collides");
            assert!(!fast.motion_is_certified_free(&[0.0], &[0.1], 1e-4));
        } else {
            assert!(hits > 0 && hits < 400, "gap {gap}: {hits} of 400 collide");
            assert!(fast.motion_is_certified_free(&[-2.0], &[-1.9], 1e-4));
        }
    }
}

/// [`clutter`] without its meshes: the obstacles the batched sphere path answers itself.
fn closed_clutter(seed: u64, n: usize) -> Environment {
    let mut env = Environment::new();
    for o in clutter(seed, n).obstacles() {
        if !matches!(o.shape, Shape::ConvexMesh(_)) {
            env.add(o.clone());
        }
    }
    env
}

/// A snake of 14 revolute links (axes alternating z and y), one sphere each: a long chain.
fn snake() -> Robot {
    let mut b = RobotBuilder::new("snake");
    let lim = JointLimits::new(-1.5, 1.5, 1.0, 1.0);
    let id = Isometry3::identity();
    let mut parent = b.link("base", vec![]);
    for k in 0..14 {
        let shapes = vec![PlacedShape::new(Isometry3::translation(0.06, 0.0, 0.0), Shape::sphere(0.03))];
        let link = b.link(format!("s{k}"), shapes);
        let axis = if k % 2 == 0 { Vector3::z() } else { Vector3::y() };
        let at = Isometry3::translation(if k == 0 { 0.0 } else { 0.12 }, 0.0, 0.0);
        b.joint(format!("j{k}"), JointKind::Revolute, parent, link, at, axis, 0.0, id, lim);
        parent = link;
    }
    b.build().unwrap()
}

/// The sphere robots of the batch tests: the spherized UR5, an arm with every joint form
/// (prismatic, DH `post`, fixed, mimic) and a long chain.
fn batch_robots() -> Vec<Robot> {
    vec![ur5(), skewed_sphere_arm(), snake()]
}

/// Configurations within about `gap` (rad) of contact: the boundary between a colliding and
/// a free configuration found by bisection, then nudged either side by up to `gap`.
fn near_contact(model: &CollisionModel, robot: &Robot, rng: &mut Rng, gap: f64) -> Option<Vec<f64>> {
    near_boundary(robot, rng, gap, |q| model.collides(q))
}

/// Configurations within about `gap` (rad) of where `side` changes between two random
/// configurations (bisection), nudged either side by up to `gap`; `None` when both are on one side.
fn near_boundary(robot: &Robot, rng: &mut Rng, gap: f64, side: impl Fn(&[f64]) -> bool) -> Option<Vec<f64>> {
    let space = robot.config_space();
    let a = robot.random_configuration(rng);
    let b = robot.random_configuration(rng);
    let ca = side(&a);
    if ca == side(&b) {
        return None;
    }
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if side(&space.interpolate(&a, &b, mid)) == ca {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let t = lo + rng.range(-1.0, 1.0) * gap / space.max_joint_step(&a, &b).max(1e-9);
    Some(space.interpolate(&a, &b, t.clamp(0.0, 1.0)))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Each bit of a batched check is exactly the single check of its configuration, on
    /// random configurations and on configurations within a hair of contact.
    #[test]
    fn batched_and_single_checks_agree(which in 0usize..3, seed in any::<u64>(), lanes in 1usize..=8, gap_exp in 2i32..15) {
        let robot = &batch_robots()[which];
        let model = CollisionModel::new(robot, closed_clutter(seed % 50, 14));
        prop_assert!(model.uses_sphere_path());
        let mut rng = Rng::new(seed);
        let mut s = model.scratch();
        let mut baseline = model.scratch().with_baseline_vectors();
        let dof = robot.dof();
        let gap = 10f64.powi(-gap_exp);
        let (mut near, mut hits) = (0, 0);
        // At least 20 rounds, and on until both a near-contact configuration and a collision
        // were checked (one lane may need more rounds to meet a collision).
        for round in 0..400 {
            if round >= 20 && near > 0 && hits > 0 {
                break;
            }
            let mut qs = Vec::new();
            for lane in 0..lanes {
                let q = match lane % 2 {
                    0 => near_contact(&model, robot, &mut rng, gap).unwrap_or_else(|| robot.random_configuration(&mut rng)),
                    _ => robot.random_configuration(&mut rng),
                };
                qs.extend(q);
            }
            let mask = model.batch_collisions_with(&qs, &mut s);
            prop_assert_eq!(mask >> lanes, 0);
            // The baseline vectors (SSE2) give the same exact answer as the best the CPU has.
            prop_assert_eq!(model.batch_collisions_with(&qs, &mut baseline), mask);
            for (i, q) in qs.chunks(dof).enumerate() {
                let single = model.collides_with(q, &mut s);
                prop_assert_eq!(mask & (1 << i) != 0, single, "lane {} of {}: {:?}", i, lanes, q);
                hits += single as usize;
                near += (i % 2 == 0) as usize;
            }
            prop_assert_eq!(model.any_collides_with(&qs, &mut s), mask != 0);
        }
        prop_assert!(near > 0 && hits > 0);
    }
}

#[test]
fn batched_checks_reject_bad_input_and_fall_back_on_meshes() {
    let robot = ur5();
    let with_mesh = CollisionModel::new(&robot, clutter(3, 15));
    let closed = CollisionModel::new(&robot, closed_clutter(3, 15));
    let mut s = closed.scratch();
    let mut rng = Rng::new(1);
    let qs: Vec<f64> = (0..13).flat_map(|_| robot.random_configuration(&mut rng)).collect();
    let dof = robot.dof();
    // Too many, none, or a broken configuration.
    assert_eq!(closed.batch_collisions_with(&qs[..9 * dof], &mut s), u32::MAX);
    assert_eq!(closed.batch_collisions_with(&[], &mut s), u32::MAX);
    assert_eq!(closed.batch_collisions_with(&qs[..dof + 1], &mut s), u32::MAX);
    assert!(closed.any_collides_with(&qs[..dof + 1], &mut s));
    assert!(!closed.any_collides_with(&[], &mut s));
    assert!(closed.any_collides_settled(&qs[..dof + 1], &mut s));
    assert!(!closed.any_collides_settled(&[], &mut s));
    // Meshes (answered one by one) and any number of configurations.
    for model in [&with_mesh, &closed] {
        let singles: Vec<bool> = qs.chunks(dof).map(|q| model.collides_with(q, &mut s)).collect();
        assert!(singles.iter().any(|&c| c) && singles.iter().any(|&c| !c));
        let mask = model.batch_collisions_with(&qs[..8 * dof], &mut s);
        for (i, &c) in singles[..8].iter().enumerate() {
            assert_eq!(mask & (1 << i) != 0, c);
        }
        assert_eq!(model.any_collides_with(&qs, &mut s), singles.iter().any(|&c| c));
        assert_eq!(model.any_collides_settled(&qs, &mut s), singles.iter().any(|&c| c));
        let free: Vec<f64> = qs.chunks(dof).zip(&singles).filter(|(_, c)| !**c).flat_map(|(q, _)| q.to_vec()).collect();
        assert!(!model.any_collides_with(&free, &mut s));
        assert!(!model.any_collides_settled(&free, &mut s));
    }
    // A NaN lane is answered by the single check.
    let mut nan = qs[..2 * dof].to_vec();
    nan[dof + 1] = f64::NAN;
    let m = closed.batch_collisions_with(&nan, &mut s);
    assert_eq!(m & 2 != 0, closed.collides_with(&nan[dof..], &mut s));
}

/// The certificate of the sphere path stays sound under dense sampling: on the spherized UR5,
/// on an arm with a mimic joint (and every other joint form) and on a long chain, among boxes,
/// cylinders, balls and capsules.
#[test]
fn certificate_is_sound_under_dense_sampling_on_sphere_robots() {
    certificates_are_sound_under_dense_sampling(|seed| closed_clutter(seed + 20, 12), 70, false);
}

/// Certificates of random motions (short and long, so that the first level has 16 pieces)
/// among the obstacles `env(seed)`, seeds 0-2, on every batch robot: each one certified is free
/// when sampled every 0.0005 rad by the general path, and some are certified, some refused.
/// `batches`: whether the models must use single-precision batches (or must not).
fn certificates_are_sound_under_dense_sampling(env: impl Fn(u64) -> Environment, rng_seed: u64, batches: bool) {
    for (which, robot) in batch_robots().iter().enumerate() {
        let space = robot.config_space();
        let (mut certified, mut refused) = (0, 0);
        for seed in 0..3 {
            let model = CollisionModel::new(robot, env(seed));
            assert_eq!(model.certifies_in_batches(), batches);
            let general = model.clone().general_path_only();
            assert!(!general.certifies_in_batches());
            let mut rng = Rng::new(seed + rng_seed);
            let (mut s, mut baseline) = (model.scratch(), model.scratch().with_baseline_vectors());
            let mut tried = 0;
            while tried < 60 {
                let qa = robot.random_configuration(&mut rng);
                let far = robot.random_configuration(&mut rng);
                let qb = space.interpolate(&qa, &far, [0.2, 0.5, 1.0][tried % 3]);
                if model.collides(&qa) || model.collides(&qb) {
                    continue;
                }
                tried += 1;
                // The CPU's widest vector instructions and the baseline's: what either
                // certifies is free (their batches may settle other pieces near a threshold:
                // AVX2 fuses products into sums, so the work may differ).
                let answer = model.certify(&qa, &qb, 1e-4, true, &mut s);
                if model.certify(&qa, &qb, 1e-4, true, &mut baseline).0 {
                    assert!(
                        general.motion_is_free(&qa, &qb, 0.0005),
                        "{which}: certified on the baseline but collides: {qa:?} -> {qb:?}"
                    );
                }
                if answer.0 {
                    certified += 1;
                    assert!(
                        general.motion_is_free(&qa, &qb, 0.0005),
                        "{which}: certified but collides: {qa:?} -> {qb:?}"
                    );
                } else {
                    refused += 1;
                }
            }
        }
        assert!(certified > 20 && refused > 5, "robot {which}: {certified} certified, {refused} refused");
    }
}

/// A box sliding 2 m along a wall 1e-6 m away grazes it the whole way: the certificate gives up
/// after [`CERTIFY_MAX_CHECKS`] checks and says "not free" (never "free"), instead of bisecting
/// the whole slide down to the tolerance.
#[test]
fn a_long_grazing_slide_is_refused_within_the_check_cap() {
    use embodied_models::collision::CERTIFY_MAX_CHECKS;
    let limits = JointLimits::new(-0.1, 2.5, 1.0, 2.0);
    let mut b = RobotBuilder::new("slider");
    let base = b.link("base", vec![]);
    let cart = b.link("cart", vec![PlacedShape::new(Isometry3::identity(), Shape::cuboid(0.05, 0.05, 0.05))]);
    b.joint(
        "x",
        JointKind::Prismatic,
        base,
        cart,
        Isometry3::identity(),
        Vector3::x(),
        0.0,
        Isometry3::identity(),
        limits,
    );
    let robot = b.build().unwrap();
    let wall = Obstacle::new("wall", Isometry3::translation(1.0, 0.05 + 1e-6 + 0.5, 0.0), Shape::cuboid(2.0, 0.5, 0.5));
    let model = CollisionModel::new(&robot, Environment::new().with(wall));
    assert!(!model.collides(&[0.0]) && !model.collides(&[2.0]) && !model.collides(&[1.0]));
    let mut s = model.scratch();
    let (free, checks) = model.certify(&[0.0], &[2.0], 1e-4, false, &mut s);
    assert!(!free);
    assert_eq!(checks, CERTIFY_MAX_CHECKS, "the slide is refused by the cap, not before");
    // With room to spare the same slide is certified in a few checks.
    let far = Obstacle::new("wall", Isometry3::translation(1.0, 0.05 + 0.2 + 0.5, 0.0), Shape::cuboid(2.0, 0.5, 0.5));
    let model = CollisionModel::new(&robot, Environment::new().with(far));
    let (free, checks) = model.certify(&[0.0], &[2.0], 1e-4, false, &mut model.scratch());
    assert!(free && checks < 100, "{free} {checks}");
}

/// [`clutter`] with balls, boxes and cylinders only: the obstacles the single-precision
/// batches answer.
/// Balls, boxes and cylinders; every other one turned about z only (as MotionBenchMaker's
/// scenes place them), which the single-precision batch answers in a shorter form.
fn solid_clutter(seed: u64, n: usize) -> Environment {
    let mut env = Environment::new();
    for (k, o) in clutter(seed, 2 * n).obstacles().iter().enumerate() {
        if matches!(o.shape, Shape::Sphere { .. } | Shape::Cuboid { .. } | Shape::Cylinder { .. }) && env.len() < n {
            let mut o = o.clone();
            if k % 2 == 0 {
                let yaw = o.pose.rotation.euler_angles().2;
                o.pose = Isometry3::from_parts(o.pose.translation, UnitQuaternion::from_euler_angles(0.0, 0.0, yaw));
            }
            env.add(o);
        }
    }
    env
}

/// Configurations within about `gap` (rad) of where the clearance crosses `margin`.
/// A world-fixed base sphere (radius 0.1 m, at the origin) and one arm sphere turning on a
/// circle 0.5 m above it, with a ball beside the base at a clearance just below, at and above
/// each margin a batch grows the spheres by, and overlapping it. Only the base can meet the
/// ball, so a batch's answer is the base's: in contact every lane collides, within the margin
/// none is free, beyond the margin and the batch's allowance every lane is free (the batches
/// skip the base's obstacle tests there), and what is settled is the truth.
#[test]
fn batches_beside_the_world_fixed_spheres_settle_only_the_truth() {
    let mut b = RobotBuilder::new("base-and-arm");
    let base = b.link("base", vec![PlacedShape::new(Isometry3::identity(), Shape::sphere(0.1))]);
    let arm = b.link("arm", vec![PlacedShape::new(Isometry3::translation(0.5, 0.0, 0.0), Shape::sphere(0.05))]);
    b.joint(
        "turn",
        JointKind::Revolute,
        base,
        arm,
        Isometry3::translation(0.0, 0.0, 0.5),
        Vector3::z(),
        0.0,
        Isometry3::identity(),
        JointLimits::new(-3.0, 3.0, 1.0, 2.0),
    );
    let robot = b.build().unwrap();
    let mut rng = Rng::new(17);
    for margin in [0.0, 1e-3, 0.03] {
        for gap in [-0.01, margin - 1e-4, margin + 1e-7, margin + 1e-3, margin + 0.05] {
            if gap <= 0.0 && gap != -0.01 {
                continue;
            }
            let mut env = Environment::new();
            env.add(Obstacle::new("ball", Isometry3::translation(-(0.1 + 0.05 + gap), 0.0, 0.0), Shape::sphere(0.05)));
            let model = CollisionModel::new(&robot, env);
            assert!(model.certifies_in_batches());
            let mut s = model.scratch();
            for _ in 0..10 {
                let qs: Vec<f64> = (0..8).flat_map(|_| robot.random_configuration(&mut rng)).collect();
                let settled = model.settle_batch(&qs, margin, &mut s).unwrap();
                for (i, q) in qs.chunks(1).enumerate() {
                    let d = model.distance(q).distance;
                    assert!((d - gap).abs() < 1e-9, "the base's gap is the clearance: {d} against {gap}");
                    if settled.free & (1 << i) != 0 {
                        assert!(d > margin - 1e-9, "gap {gap}, margin {margin}: free with clearance {d}: {q:?}");
                    }
                    if settled.colliding & (1 << i) != 0 {
                        assert!(model.collides_with(q, &mut s), "gap {gap}: called colliding: {q:?}");
                    }
                }
                if gap < 0.0 {
                    assert_eq!(settled.colliding, 0xff, "the base is in contact in every lane");
                } else if gap < margin {
                    assert_eq!(settled.free, 0, "gap {gap} within the margin {margin}");
                } else if gap >= margin + 1e-3 {
                    assert_eq!(settled.free, 0xff, "gap {gap} beyond the margin {margin}");
                }
            }
        }
    }
}

fn near_clearance(model: &CollisionModel, robot: &Robot, rng: &mut Rng, margin: f64, gap: f64) -> Option<Vec<f64>> {
    near_boundary(robot, rng, gap, |q| model.distance(q).distance > margin)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// What a single-precision batch settles is true in double precision: a configuration it
    /// calls free has more than the margin of clearance (the general path's distance), one it
    /// calls colliding collides; on random configurations and on configurations within a hair
    /// of the margin or of contact, on the UR5, an arm with every joint form and a long chain;
    /// on the CPU's widest vector instructions and on the baseline's.
    #[test]
    fn single_precision_batches_settle_only_the_truth(
        which in 0usize..3, seed in any::<u64>(), lanes in 1usize..=8, gap_exp in 3i32..13, m in 0usize..3,
    ) {
        let robot = &batch_robots()[which];
        let model = CollisionModel::new(robot, solid_clutter(seed % 50, 10));
        prop_assert!(model.certifies_in_batches());
        let margin = [0.0, 1e-3, 0.03][m];
        let mut rng = Rng::new(seed);
        let mut s = model.scratch();
        let mut baseline = model.scratch().with_baseline_vectors();
        let dof = robot.dof();
        let gap = 10f64.powi(-gap_exp);
        for _ in 0..12 {
            let mut qs = Vec::new();
            for lane in 0..lanes {
                let q = match lane % 3 {
                    0 => near_clearance(&model, robot, &mut rng, margin, gap),
                    1 => near_contact(&model, robot, &mut rng, gap),
                    _ => None,
                };
                qs.extend(q.unwrap_or_else(|| robot.random_configuration(&mut rng)));
            }
            let settled = model.settle_batch(&qs, margin, &mut s).unwrap();
            // The baseline's instructions (which round a product before adding it, where
            // AVX2 fuses the two) may settle other lanes near a threshold, never the opposite.
            let base = model.settle_batch(&qs, margin, &mut baseline).unwrap();
            prop_assert_eq!(base.free & settled.colliding, 0);
            prop_assert_eq!(base.colliding & settled.free, 0);
            // The planner's probe query (batches, then one by one what they leave) answers as
            // single checks do, over one batch and over more than one.
            let singles = qs.chunks(dof).any(|q| model.collides_with(q, &mut s));
            prop_assert_eq!(model.any_collides_settled(&qs, &mut s), singles);
            let twice = [&qs[..], &qs[..]].concat();
            prop_assert_eq!(model.any_collides_settled(&twice, &mut baseline), singles);
            prop_assert_eq!((settled.free | settled.colliding) >> lanes, 0);
            prop_assert_eq!(settled.free & settled.colliding, 0);
            let free = settled.free | base.free;
            let colliding = settled.colliding | base.colliding;
            prop_assert_eq!((base.free | base.colliding) >> lanes, 0);
            prop_assert_eq!(base.free & base.colliding, 0);
            for (i, q) in qs.chunks(dof).enumerate() {
                if free & (1 << i) != 0 {
                    let d = model.distance(q).distance;
                    prop_assert!(d > margin - 1e-9, "lane {} called free with clearance {} < {}: {:?}", i, d, margin, q);
                    prop_assert!(!model.collides_with(q, &mut s));
                }
                if colliding & (1 << i) != 0 {
                    prop_assert!(model.collides_with(q, &mut s), "lane {} called colliding: {:?}", i, q);
                }
            }
        }
    }
}

/// The points an edge probe checks, in its order: `end` first when given, then the inner points
/// `a + (i / n) delta` in bisection order (one row of the robot's values each).
fn probe_points(a: &[f64], end: Option<&[f64]>, delta: &[f64], n: usize) -> Vec<f64> {
    let mut points: Vec<f64> = end.map(<[f64]>::to_vec).unwrap_or_default();
    let mut q = vec![0.0; a.len()];
    embodied_models::cspace::bisection_order(n, |i| {
        ConfigSpace::step_into(a, delta, i as f64 / n as f64, &mut q);
        points.extend_from_slice(&q);
        true
    });
    points
}

/// An edge probe (its end, then its inner points in bisection order, written into the lanes
/// straight from the segment) answers as the same points built one by one and passed to
/// `any_collides_settled` do, and as single checks: with and without its end, from 1 to 40
/// steps (one batch, several, and the few checked one by one), on segments from free
/// configurations to configurations near contact, anywhere and a short step away, on the UR5,
/// an arm with every joint form and a long chain, on both instruction sets; and where the
/// model has no batches (capsules among the obstacles). Both answers occur.
#[test]
fn edge_probes_answer_as_their_points_do() {
    let (mut blocked, mut clear) = (0, 0);
    for (which, robot) in batch_robots().iter().enumerate() {
        let space = robot.config_space();
        let dof = robot.dof();
        for seed in 0..8u64 {
            let closed = seed % 4 == 3;
            let env = if closed { closed_clutter(seed, 12) } else { solid_clutter(seed, 10) };
            let model = CollisionModel::new(robot, env);
            assert_eq!(model.certifies_in_batches(), !closed);
            let mut rng = Rng::new(seed * 31 + which as u64);
            let mut s = model.scratch();
            let mut baseline = model.scratch().with_baseline_vectors();
            for k in 0..24usize {
                let a = (0..200)
                    .map(|_| robot.random_configuration(&mut rng))
                    .find(|q| !model.collides_with(q, &mut s))
                    .unwrap_or_else(|| robot.random_configuration(&mut rng));
                let b = match k % 3 {
                    0 => near_contact(&model, robot, &mut rng, 1e-6)
                        .unwrap_or_else(|| robot.random_configuration(&mut rng)),
                    1 => robot.random_configuration(&mut rng),
                    _ => a.iter().map(|v| v + rng.range(-0.05, 0.05)).collect(),
                };
                let mut delta = Vec::new();
                space.deltas_into(&a, &b, &mut delta);
                let n = 1 + (k * 7 + seed as usize) % 40;
                for end in [None, Some(&b[..])] {
                    let points = probe_points(&a, end, &delta, n);
                    let expected = model.any_collides_settled(&points, &mut s);
                    assert_eq!(expected, points.chunks(dof).any(|q| model.collides_with(q, &mut s)));
                    let at = format!("robot {which}, seed {seed}, segment {k}, {n} steps, end {}", end.is_some());
                    assert_eq!(model.probe_collides(&a, end, &delta, n, &mut s), expected, "{at}");
                    assert_eq!(model.probe_collides(&a, end, &delta, n, &mut baseline), expected, "{at}");
                    if expected { blocked += 1 } else { clear += 1 }
                }
            }
            // Ends and steps of another length than the robot's count as colliding.
            let a = robot.random_configuration(&mut rng);
            assert!(model.probe_collides(&a[..dof - 1], None, &a[..dof - 1], 4, &mut s));
            assert!(model.probe_collides(&a, Some(&a[..dof - 1]), &a, 4, &mut s));
        }
    }
    assert!(blocked > 100 && clear > 100, "{blocked} blocked, {clear} clear");
}

/// Two arms of three sphere links on a torso of two balls, reaching across each other: a robot
/// whose arms move apart (one group of joints each).
fn two_sphere_arms() -> Robot {
    let mut b = RobotBuilder::new("two-sphere-arms");
    let lim = JointLimits::new(-2.0, 2.0, 1.0, 1.0);
    let ball = |x: f64, r: f64| PlacedShape::new(Isometry3::translation(x, 0.0, 0.0), Shape::sphere(r));
    let torso = b.link(
        "torso",
        vec![
            PlacedShape::new(Isometry3::translation(0.0, 0.0, 0.1), Shape::sphere(0.1)),
            PlacedShape::new(Isometry3::translation(0.0, 0.0, 0.3), Shape::sphere(0.08)),
        ],
    );
    for (side, y) in [("left", 0.2), ("right", -0.2)] {
        let mut parent = torso;
        for k in 0..3 {
            let link = b.link(format!("{side}{k}"), vec![ball(0.05, 0.04), ball(0.15, 0.04), ball(0.25, 0.035)]);
            let at = if k == 0 { Isometry3::translation(0.0, y, 0.3) } else { Isometry3::translation(0.3, 0.0, 0.0) };
            let axis = if k == 1 { Vector3::y() } else { Vector3::z() };
            b.joint(
                format!("{side}_j{k}"),
                JointKind::Revolute,
                parent,
                link,
                at,
                axis,
                0.0,
                Isometry3::identity(),
                lim,
            );
            parent = link;
        }
    }
    b.build().unwrap()
}

/// A probe from a free configuration that holds some joints still answers as the same probe
/// with every body tested (and as its points one by one): the batches skip the bodies no
/// joint moves, whose poses are those of the free start. On two arms moved one at a time, an
/// arm with a mimic joint and a prismatic joint, a long chain and the UR5, with starts near
/// contact (where a still body's tests could not settle a lane) and anywhere, ends near
/// contact, anywhere and a short step away, on both instruction sets; and on the general path
/// (shape by shape), whose probes from a free start skip the links no joint moves against
/// obstacles and the pairs of two such links.
#[test]
fn probes_from_free_starts_skip_still_bodies_with_the_same_answer() {
    let (mut blocked, mut clear) = (0, 0);
    let robots = [two_sphere_arms(), skewed_sphere_arm(), snake(), ur5()];
    for ((which, robot), general) in robots.iter().enumerate().flat_map(|r| [(r, false), (r, true)]) {
        let space = robot.config_space();
        let dof = robot.dof();
        for seed in 0..6u64 {
            let model = CollisionModel::new(robot, solid_clutter(seed + 20, 10));
            let model = if general { model.general_path_only() } else { model };
            assert_eq!(model.certifies_in_batches(), !general);
            let mut rng = Rng::new(seed * 17 + which as u64);
            let mut s = model.scratch();
            let mut baseline = model.scratch().with_baseline_vectors();
            for k in 0..30usize {
                let near = if k % 2 == 0 { near_contact(&model, robot, &mut rng, 1e-6) } else { None };
                let Some(a) = near.filter(|q| !model.collides_with(q, &mut s)).or_else(|| {
                    (0..200).map(|_| robot.random_configuration(&mut rng)).find(|q| !model.collides_with(q, &mut s))
                }) else {
                    continue;
                };
                let mut b = match k % 3 {
                    0 => near_contact(&model, robot, &mut rng, 1e-6)
                        .unwrap_or_else(|| robot.random_configuration(&mut rng)),
                    1 => robot.random_configuration(&mut rng),
                    _ => a.iter().map(|v| v + rng.range(-0.05, 0.05)).collect(),
                };
                // The first half of the joints still, the second half, or a random few.
                for d in 0..dof {
                    let hold = match k % 4 {
                        0 => d < dof / 2,
                        1 => d >= dof / 2,
                        2 => rng.range(0.0, 1.0) < 0.4,
                        _ => d + 1 < dof,
                    };
                    if hold {
                        b[d] = a[d];
                    }
                }
                let mut delta = Vec::new();
                space.deltas_into(&a, &b, &mut delta);
                let n = 1 + (k * 5 + seed as usize) % 30;
                for end in [None, Some(&b[..])] {
                    let points = probe_points(&a, end, &delta, n);
                    let expected = points.chunks(dof).any(|q| model.collides_with(q, &mut s));
                    let at = format!(
                        "robot {which} (general path: {general}), seed {seed}, segment {k}, {n} steps, end {}",
                        end.is_some()
                    );
                    assert_eq!(model.probe_collides(&a, end, &delta, n, &mut s), expected, "{at}");
                    assert_eq!(model.probe_from_free_collides(&a, end, &delta, n, &mut s), expected, "{at}");
                    assert_eq!(model.probe_from_free_collides(&a, end, &delta, n, &mut baseline), expected, "{at}");
                    if expected { blocked += 1 } else { clear += 1 }
                }
            }
        }
    }
    assert!(blocked > 200 && clear > 200, "{blocked} blocked, {clear} clear");
}

/// The frames a probe keeps for its still bodies serve a later probe only while those bodies'
/// joints keep their values: probes whose held joints go back and forth between two sets of
/// values (the other arm, or the first joints of a long chain, moving at random) answer as
/// their points checked one by one, on both instruction sets.
#[test]
fn kept_frames_of_still_bodies_follow_the_held_values() {
    let (mut blocked, mut clear) = (0, 0);
    for (which, robot) in [two_sphere_arms(), snake()].iter().enumerate() {
        let space = robot.config_space();
        let dof = robot.dof();
        // Held: the second arm, or the first half of the chain.
        let held = |d: usize| if which == 0 { d >= dof / 2 } else { d < dof / 2 };
        for seed in 0..6u64 {
            let model = CollisionModel::new(robot, solid_clutter(seed + 40, 10));
            let mut rng = Rng::new(seed * 31 + which as u64);
            let mut s = model.scratch();
            let mut baseline = model.scratch().with_baseline_vectors();
            let sets: Vec<Vec<f64>> = (0..2).map(|_| robot.random_configuration(&mut rng)).collect();
            for k in 0..60usize {
                let hold = &sets[k % 2];
                let free_start = (0..200).find_map(|_| {
                    let mut q = robot.random_configuration(&mut rng);
                    for d in (0..dof).filter(|&d| held(d)) {
                        q[d] = hold[d];
                    }
                    (!model.collides_with(&q, &mut s)).then_some(q)
                });
                let Some(a) = free_start else { continue };
                let mut b = robot.random_configuration(&mut rng);
                for d in (0..dof).filter(|&d| held(d)) {
                    b[d] = a[d];
                }
                let mut delta = Vec::new();
                space.deltas_into(&a, &b, &mut delta);
                let n = 1 + k % 24;
                for end in [None, Some(&b[..])] {
                    let points = probe_points(&a, end, &delta, n);
                    let expected = points.chunks(dof).any(|q| model.collides_with(q, &mut s));
                    let at = format!("robot {which}, seed {seed}, probe {k}, {n} steps, end {}", end.is_some());
                    assert_eq!(model.probe_from_free_collides(&a, end, &delta, n, &mut s), expected, "{at}");
                    assert_eq!(model.probe_from_free_collides(&a, end, &delta, n, &mut baseline), expected, "{at}");
                    if expected { blocked += 1 } else { clear += 1 }
                }
            }
        }
    }
    assert!(blocked > 100 && clear > 100, "{blocked} blocked, {clear} clear");
}

/// The batches settle nearly everything that is not within a hair of the question, so the
/// certificate gains from them: on the UR5 among obstacles, batches of eight random free
/// configurations are settled free, and a batch holding one colliding configuration among
/// free ones finds a contact.
#[test]
fn single_precision_batches_settle_random_configurations() {
    let robot = ur5();
    let dof = robot.dof();
    let (mut free, mut settled_free, mut with_contact, mut found) = (0, 0, 0, 0);
    for seed in 0..6 {
        let model = CollisionModel::new(&robot, solid_clutter(seed, 10));
        let mut s = model.scratch();
        let mut rng = Rng::new(seed + 40);
        let (mut frees, mut colliding) = (Vec::new(), Vec::new());
        while frees.len() < 8 * 40 || colliding.len() < 40 {
            let q = robot.random_configuration(&mut rng);
            if model.collides_with(&q, &mut s) {
                colliding.push(q);
            } else {
                frees.push(q);
            }
        }
        for (k, batch) in frees.chunks(8).take(40).enumerate() {
            let qs: Vec<f64> = batch.concat();
            let settled = model.settle_batch(&qs, 0.0, &mut s).unwrap();
            free += 8;
            settled_free += settled.free.count_ones();
            assert_eq!(settled.colliding, 0);
            // The same with one lane swapped for a colliding configuration.
            let mut qs = qs;
            let lane = k % 8;
            qs[lane * dof..(lane + 1) * dof].copy_from_slice(&colliding[k]);
            let settled = model.settle_batch(&qs, 0.0, &mut s).unwrap();
            with_contact += 1;
            found += (settled.colliding == 1 << lane) as usize;
            assert_eq!(settled.free & (1 << lane), 0);
        }
    }
    assert!(settled_free as f64 >= 0.99 * free as f64, "{settled_free} of {free} free configurations settled");
    assert!(found as f64 >= 0.95 * with_contact as f64, "{found} of {with_contact} contacts found");
}

/// The certificate with single-precision batches stays sound under dense sampling: among
/// balls, boxes and cylinders, where the batches are used.
#[test]
fn certificate_with_batches_is_sound_under_dense_sampling() {
    certificates_are_sound_under_dense_sampling(|seed| solid_clutter(seed + 20, 12), 90, true);
}

/// Probes one after another that hold the same joints at the same values (one arm of two
/// still while the other searches, as in a planner's leg) answer as their points do, with
/// other queries between them on the same scratch (a certificate, a batch of rows, a probe
/// moving every joint) and the held values changed now and then: what a batch keeps from the
/// last one never answers for another pose.
#[test]
fn consecutive_probes_holding_joints_answer_as_their_points_do() {
    let (mut blocked, mut clear) = (0, 0);
    for (which, robot) in [two_sphere_arms(), ur5(), snake()].iter().enumerate() {
        let space = robot.config_space();
        let dof = robot.dof();
        for seed in 0..4u64 {
            let model = CollisionModel::new(robot, solid_clutter(seed + 60, 10));
            let mut rng = Rng::new(seed * 13 + 5 + which as u64);
            let mut s = model.scratch();
            let mut base = robot.random_configuration(&mut rng);
            let held = |d: usize| d < dof / 2;
            for k in 0..80usize {
                if k % 16 == 0 {
                    base = robot.random_configuration(&mut rng);
                }
                // A free start with the held joints at the base's values.
                let Some(a) = (0..200)
                    .map(|_| {
                        let q = robot.random_configuration(&mut rng);
                        (0..dof).map(|d| if held(d) { base[d] } else { q[d] }).collect::<Vec<f64>>()
                    })
                    .find(|q| !model.collides_with(q, &mut s))
                else {
                    continue;
                };
                let far = robot.random_configuration(&mut rng);
                let t = [0.1, 0.4, 1.0][k % 3];
                let b: Vec<f64> = (0..dof).map(|d| if held(d) { a[d] } else { a[d] + t * (far[d] - a[d]) }).collect();
                let mut delta = Vec::new();
                space.deltas_into(&a, &b, &mut delta);
                let n = 2 + (k * 3) % 20;
                let points = probe_points(&a, Some(&b), &delta, n);
                let expected = points.chunks(dof).any(|q| model.collides_with(q, &mut s));
                let at = format!("robot {which}, seed {seed}, probe {k}");
                assert_eq!(model.probe_from_free_collides(&a, Some(&b), &delta, n, &mut s), expected, "{at}");
                if expected {
                    blocked += 1
                } else {
                    clear += 1
                }
                // Something else on the same scratch now and then.
                match k % 7 {
                    3 => {
                        model.certify(&a, &b, 1e-4, false, &mut s);
                    }
                    5 => {
                        let rows: Vec<f64> = (0..8).flat_map(|_| robot.random_configuration(&mut rng)).collect();
                        model.settle_batch(&rows, 0.0, &mut s);
                    }
                    6 => {
                        let c = robot.random_configuration(&mut rng);
                        let mut d = Vec::new();
                        space.deltas_into(&a, &c, &mut d);
                        model.probe_from_free_collides(&a, Some(&c), &d, 8, &mut s);
                    }
                    _ => {}
                }
            }
        }
    }
    assert!(blocked > 50 && clear > 50, "{blocked} blocked, {clear} clear");
    // Ends and steps of another length than the robot's count as colliding here too.
    let robot = ur5();
    let model = CollisionModel::new(&robot, solid_clutter(1, 4));
    let (a, dof) = (robot.home().to_vec(), robot.dof());
    let mut s = model.scratch();
    assert!(model.probe_from_free_collides(&a[..dof - 1], None, &a[..dof - 1], 4, &mut s));
    assert!(model.probe_from_free_collides(&a, Some(&a[..dof - 1]), &vec![0.0; dof], 4, &mut s));
    assert!(model.probe_from_free_collides(&a, None, &a[..dof - 1], 4, &mut s));
}

/// Certificates of motions that hold some joints still (one arm of two, half a chain, a few at
/// random) from free ends, often within a hair of contact, stay sound: the batches skip the
/// bodies no joint moves, and whatever is certified is free when sampled every 0.0005 rad by
/// the general path. Some motions are certified, some refused.
#[test]
fn certificates_holding_joints_still_stay_sound() {
    let robots = [two_sphere_arms(), skewed_sphere_arm(), snake(), ur5()];
    for (which, robot) in robots.iter().enumerate() {
        let space = robot.config_space();
        let dof = robot.dof();
        let (mut certified, mut refused) = (0, 0);
        for seed in 0..3 {
            let model = CollisionModel::new(robot, solid_clutter(seed + 40, 12));
            assert!(model.certifies_in_batches());
            let general = model.clone().general_path_only();
            let mut rng = Rng::new(seed * 7 + 3 + which as u64);
            let mut s = model.scratch();
            let mut tried = 0;
            while tried < 40 {
                let near = if tried % 2 == 0 { near_contact(&model, robot, &mut rng, 1e-6) } else { None };
                let qa = near.unwrap_or_else(|| robot.random_configuration(&mut rng));
                let far = robot.random_configuration(&mut rng);
                let mut qb = space.interpolate(&qa, &far, [0.2, 0.5, 1.0][tried % 3]);
                for d in 0..dof {
                    let hold = match tried % 3 {
                        0 => d < dof / 2,
                        1 => d >= dof / 2,
                        _ => rng.range(0.0, 1.0) < 0.5,
                    };
                    if hold {
                        qb[d] = qa[d];
                    }
                }
                if model.collides(&qa) || model.collides(&qb) {
                    continue;
                }
                tried += 1;
                if model.certify(&qa, &qb, 1e-4, false, &mut s).0 {
                    certified += 1;
                    assert!(
                        general.motion_is_free(&qa, &qb, 0.0005),
                        "{which}: certified but collides: {qa:?} -> {qb:?}"
                    );
                } else {
                    refused += 1;
                }
            }
        }
        assert!(certified > 20 && refused > 3, "robot {which}: {certified} certified, {refused} refused");
    }
}

#[test]
fn settle_batch_refuses_bad_input_and_models_without_batches() {
    let robot = ur5();
    let dof = robot.dof();
    let model = CollisionModel::new(&robot, solid_clutter(2, 8));
    let with_capsules = CollisionModel::new(&robot, closed_clutter(2, 15));
    assert!(!with_capsules.certifies_in_batches());
    let mut s = model.scratch();
    let mut rng = Rng::new(5);
    let qs: Vec<f64> = (0..9).flat_map(|_| robot.random_configuration(&mut rng)).collect();
    assert!(model.settle_batch(&qs, 0.0, &mut s).is_none());
    assert!(model.settle_batch(&qs[..dof + 1], 0.0, &mut s).is_none());
    assert!(model.settle_batch(&[], 0.0, &mut s).is_none());
    assert!(model.settle_batch(&qs[..dof], -1.0, &mut s).is_none());
    assert!(model.settle_batch(&qs[..dof], f64::NAN, &mut s).is_none());
    assert!(with_capsules.settle_batch(&qs[..dof], 0.0, &mut s).is_none());
    // A configuration that is not finite settles nothing.
    let mut nan = qs[..2 * dof].to_vec();
    nan[dof + 2] = f64::NAN;
    assert_eq!(
        model.settle_batch(&nan, 0.0, &mut s),
        Some(embodied_models::collision::BatchSettled { free: 0, colliding: 0 })
    );
}

/// A scratch space handed on from another robot's queries (a dropped one comes back from the
/// thread's spares) answers exactly as a new one: batches, single checks and certificates.
#[test]
fn a_scratch_handed_on_between_robots_answers_as_a_new_one() {
    let robots = batch_robots();
    let mut rng = Rng::new(17);
    for round in 0..6 {
        let (a, b) = (&robots[round % 3], &robots[(round + 1 + round / 3) % 3]);
        let (ma, mb) =
            (CollisionModel::new(a, closed_clutter(round as u64, 14)), CollisionModel::new(b, closed_clutter(7, 14)));
        let mut used = ma.scratch();
        for _ in 0..20 {
            let qs: Vec<f64> = (0..8).flat_map(|_| a.random_configuration(&mut rng)).collect();
            ma.batch_collisions_with(&qs, &mut used);
            ma.certify(&qs[..a.dof()], &qs[a.dof()..2 * a.dof()], 1e-3, true, &mut used);
        }
        drop(used);
        let mut handed = mb.scratch();
        let mut fresh = embodied_models::collision::CollisionScratch::new();
        let dof = b.dof();
        for _ in 0..40 {
            let qs: Vec<f64> = (0..8).flat_map(|_| b.random_configuration(&mut rng)).collect();
            assert_eq!(mb.batch_collisions_with(&qs, &mut handed), mb.batch_collisions_with(&qs, &mut fresh));
            assert_eq!(mb.collides_with(&qs[..dof], &mut handed), mb.collides_with(&qs[..dof], &mut fresh));
            let (qa, qb) = (&qs[..dof], &qs[dof..2 * dof]);
            assert_eq!(mb.certify(qa, qb, 1e-3, true, &mut handed), mb.certify(qa, qb, 1e-3, true, &mut fresh));
        }
    }
}
