//! Soundness of the certificate's per-segment arms: property tests against densely sampled
//! motions, on the spherized UR5 and on sphere versions of the built-in robots.
#![allow(clippy::unwrap_used, clippy::needless_range_loop)]

use std::path::PathBuf;
use std::sync::Arc;

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use proptest::prelude::*;

use super::super::super::{CollisionModel, Environment, Local, Obstacle, RobotGeom, disable_always_colliding};
use super::super::{SphereGeom, SphereScratch};
use crate::geometry::{PlacedShape, Shape};
use crate::joint::{JointKind, JointLimits};
use crate::rng::Rng;
use crate::robot::{Robot, RobotBuilder};
use crate::urdf::load_urdf;

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures").join(name)
}

fn ur5() -> Robot {
    let mut r = load_urdf(&fixture("ur5_spherized.urdf"), Some(&fixture("ur5.srdf"))).unwrap();
    disable_always_colliding(&mut r, 300, 3);
    r
}

/// A planar-ish arm whose third joint mimics the first (multiplier -1.5), with a prismatic
/// joint and a joint offset in between: several joints of one DOF on one chain.
fn mimic_arm() -> Robot {
    let mut b = RobotBuilder::new("mimic-arm");
    let ball = |x: f64, r: f64| vec![PlacedShape::new(Isometry3::translation(x, 0.0, 0.0), Shape::sphere(r))];
    let base = b.link("base", vec![]);
    let l1 = b.link("l1", ball(0.2, 0.05));
    let l2 = b.link("l2", ball(0.15, 0.04));
    let l3 = b.link("l3", [ball(0.1, 0.03), ball(0.3, 0.03)].concat());
    let l4 = b.link("l4", ball(0.05, 0.02));
    let lim = JointLimits::new(-2.0, 2.0, 1.0, 1.0);
    let id = Isometry3::identity();
    let rot = Isometry3::rotation(Vector3::new(0.3, -0.2, 0.5));
    b.joint("j1", JointKind::Revolute, base, l1, Isometry3::translation(0.0, 0.0, 0.1), Vector3::z(), 0.0, id, lim);
    b.joint("j2", JointKind::Prismatic, l1, l2, Isometry3::translation(0.3, 0.0, 0.0), Vector3::x(), 0.0, id, lim);
    let j3 = b.joint("j3", JointKind::Revolute, l2, l3, rot, Vector3::y(), 0.4, rot, lim);
    b.joint("j4", JointKind::Revolute, l3, l4, Isometry3::translation(0.4, 0.0, 0.0), Vector3::z(), 0.0, id, lim);
    b.mimic(j3, "j1".into(), -1.5, 0.2);
    b.build().unwrap()
}

/// A snake of 14 revolute links (axes alternating z and y), one sphere each: self-collision
/// pairs whose chains below their common body are longer than `DEEP` (pair margins fall back
/// to the sum of the two spheres' margins) and shorter (tightened).
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

fn robots() -> Vec<Robot> {
    let mut v = vec![ur5()];
    v.extend(["two-irp6", "polycrank", "irp6-on-track"].iter().map(|n| crate::builtin(n).unwrap()));
    v.push(load_urdf(&fixture("tiny_gripper.urdf"), Some(&fixture("tiny_gripper.srdf"))).unwrap());
    v.push(mimic_arm());
    v.push(snake());
    v
}

/// The robot's collision geometry with every shape replaced by its bounding sphere (the
/// spherized UR5 is unchanged): every robot takes the sphere path.
fn sphere_geom(robot: &Robot) -> RobotGeom {
    let mut g = RobotGeom::new(robot);
    for sh in &mut g.shapes {
        sh.local = Local::Sphere { c: sh.c, r: sh.r };
    }
    g
}

/// A collision model of `robot`'s spherized geometry among `env`.
fn sphere_model(robot: &Robot, env: Environment) -> CollisionModel {
    let g = sphere_geom(robot);
    let fast = SphereGeom::new(&g, false).map(Arc::new);
    assert!(fast.is_some());
    let mut m = CollisionModel::new(robot, Environment::new());
    m.geom = Arc::new(g);
    m.fast = fast;
    m.set_environment(env);
    m
}

/// Every sphere's centre relative to each body on its chain and the world: `out[k][e]` is
/// sphere `k`'s centre in the frame of the `e`-th body up from its own (the last is the world).
fn centres(fast: &SphereGeom, q: &[f64], s: &mut SphereScratch, out: &mut Vec<Vec<Vector3<f64>>>) {
    fast.pose(q, s);
    out.clear();
    for link in &fast.links {
        for k in link.first..link.end {
            let p = s.rot[link.body] * fast.centre[k] + s.pos[link.body];
            let mut v = Vec::new();
            let mut b = link.body;
            loop {
                v.push(s.rot[b].transpose() * (p - s.pos[b]));
                if b == 0 {
                    break;
                }
                b = fast.bodies[b].parent;
            }
            v.push(p);
            out.push(v);
        }
    }
}

/// Checks every bound of the sub-interval `[t0, t1]` of the segment `qa`-`qb` against the
/// paths of the spheres sampled at `n` points each side of the midpoint; returns, per sphere
/// and frame, (sampled path length, margin along the straight motion, margin at the midpoint
/// for any motion in the box of the steps, static margin).
fn check_span(
    robot: &Robot,
    fast: &SphereGeom,
    (qa, qb): (&[f64], &[f64]),
    (t0, t1): (f64, f64),
    n: usize,
) -> Result<Vec<(f64, f64, f64, f64)>, TestCaseError> {
    let space = robot.config_space();
    let dof = qa.len();
    let half = 0.5 * (t1 - t0);
    let tm = t0 + half;
    let dir: Vec<f64> = (0..dof).map(|i| space.delta(i, qa[i], qb[i]) * half * (1.0 + 1e-9)).collect();
    let step: Vec<f64> = dir.iter().map(|d| d.abs()).collect();
    // The query's pose at the midpoint, every link posed.
    let mut at = SphereScratch::new();
    fast.pose(&space.interpolate(qa, qb, tm), &mut at);
    for l in 0..fast.links.len() {
        fast.pose_link(l, &mut at);
    }
    let mut s = SphereScratch::new();
    let mut mid = Vec::new();
    centres(fast, &space.interpolate(qa, qb, tm), &mut s, &mut mid);
    // Path lengths from the midpoint towards each end (the longer), and the largest decrease
    // of each pair's centre distance.
    let mut length: Vec<Vec<f64>> = mid.iter().map(|v| vec![0.0; v.len()]).collect();
    let world = |v: &[Vec<Vector3<f64>>], k: usize| v[k][v[k].len() - 1];
    let mut shrink = std::collections::HashMap::new();
    let pair_spheres = |p: usize| {
        let (a, b) = fast.self_pairs[p];
        let (la, lb) = (&fast.links[a as usize], &fast.links[b as usize]);
        (la.first..la.end).flat_map(move |i| (lb.first..lb.end).map(move |j| (i, j)))
    };
    let mut q = vec![0.0; dof];
    let mut now = Vec::new();
    for dir in [-1.0, 1.0] {
        let mut last = mid.clone();
        let mut run: Vec<Vec<f64>> = mid.iter().map(|v| vec![0.0; v.len()]).collect();
        for i in 1..=n {
            space.interpolate_into(qa, qb, tm + dir * half * i as f64 / n as f64, &mut q);
            centres(fast, &q, &mut s, &mut now);
            for k in 0..now.len() {
                for e in 0..now[k].len() {
                    run[k][e] += (now[k][e] - last[k][e]).norm();
                }
            }
            for p in 0..fast.self_pairs.len() {
                for (i, j) in pair_spheres(p) {
                    let d0 = (world(&mid, i) - world(&mid, j)).norm();
                    let worst = shrink.entry((i, j)).or_insert(0.0f64);
                    *worst = worst.max(d0 - (world(&now, i) - world(&now, j)).norm());
                }
            }
            std::mem::swap(&mut last, &mut now);
        }
        for (k, r) in run.iter().enumerate() {
            for (e, v) in r.iter().enumerate() {
                length[k][e] = length[k][e].max(*v);
            }
        }
    }
    let mut out = Vec::new();
    for (l, lk) in fast.links.iter().enumerate() {
        fast.link_centre(l, &mut at);
        let link_bound = fast.link_margin(l, &step, &at);
        for k in lk.first..lk.end {
            // The link's midpoint margin bounds each of its spheres' against the world.
            let (world_moved, world_tight) =
                (length[k][length[k].len() - 1], fast.margin(k, 0, &step, Some(&at), None));
            prop_assert!(
                world_moved <= link_bound && world_tight <= link_bound * (1.0 + 1e-12) + 1e-12,
                "{}: sphere {k} moves {world_moved} over [{t0}, {t1}], margin {world_tight}, link {l}'s bound {link_bound}",
                robot.name()
            );
            // The frames: each body up the chain, then the world (stop 0 again, as the world).
            let mut b = lk.body;
            let mut frames = Vec::new();
            loop {
                frames.push(b);
                if b == 0 {
                    break;
                }
                b = fast.bodies[b].parent;
            }
            frames.push(0);
            for (e, &stop) in frames.iter().enumerate() {
                let straight = fast.margin(k, stop, &step, Some(&at), Some(&dir));
                let tight = fast.margin(k, stop, &step, Some(&at), None);
                let loose = fast.margin(k, stop, &step, None, None);
                let moved = length[k][e];
                prop_assert!(
                    moved <= straight && straight <= tight * (1.0 + 1e-12) && tight <= loose * (1.0 + 1e-12),
                    "{}: sphere {k} relative to body {stop} moves {moved} over [{t0}, {t1}]: margins {straight} (straight), {tight} (midpoint), {loose} (static)",
                    robot.name()
                );
                out.push((moved, straight, tight, loose));
            }
        }
    }
    for p in 0..fast.self_pairs.len() {
        let stop = fast.pair_common[p] as usize;
        for (i, j) in pair_spheres(p) {
            let straight = fast.pair_margin(i, j, stop, &step, Some(&dir), &at);
            let bound = fast.pair_margin(i, j, stop, &step, None, &at);
            let sum = fast.margin(i, stop, &step, Some(&at), None) + fast.margin(j, stop, &step, Some(&at), None);
            let worst = shrink[&(i, j)];
            prop_assert!(
                worst <= straight && straight <= bound * (1.0 + 1e-12) && bound <= sum * (1.0 + 1e-12),
                "{}: pair {p}, spheres {i} and {j}: distance shrinks by {worst} over [{t0}, {t1}], bound {straight} (straight), {bound} (any motion in the box; sum of margins {sum})",
                robot.name()
            );
        }
    }
    Ok(out)
}

/// The `table_pick_ur5` scene 0001 of MotionBenchMaker (as in `benches/collision.rs`): MoveIt
/// objects (pose xyz + quaternion xyzw, times the primitive's offset), boxes as full sizes and
/// cylinders as (height, radius).
fn table_pick() -> Environment {
    let table = [
        -0.08882545052091238,
        -0.0838528117056479,
        0.08705641176758652,
        0.0,
        0.0,
        0.9972514405491772,
        0.07409159414259424,
    ];
    let bx = |x: f64, y: f64, z: f64| Shape::cuboid(x / 2.0, y / 2.0, z / 2.0);
    let cyl = |h: f64, r: f64| Shape::cylinder(r, h / 2.0);
    let objects = [
        (
            "Can1",
            [-0.06371788662107358, -0.1102475820769556, 0.087056, 0.0, 0.0, 0.9972514405491772, 0.07409159414259425],
            [0.85, 0.0, 0.8],
            cyl(0.12, 0.03),
        ),
        (
            "Cube",
            [-0.08791923452392993, -0.08940951248661265, 0.087056, 0.0, 0.0, 0.9974531188710987, 0.07132514040868118],
            [0.75, 0.4, 0.85],
            bx(0.25, 0.25, 0.25),
        ),
        (
            "Object1",
            [-0.7615492092843769, -1.105577808942591, 0.087056, 0.0, 0.0, 0.8736437177567432, 0.4865661870950101],
            [1.35, 0.0, 0.85],
            cyl(0.35, 0.05),
        ),
        (
            "Object2",
            [-0.4754801784139817, 0.979941530894374, 0.087056, 0.0, 0.0, -0.8748279033106394, 0.4844338340672655],
            [1.05, -0.2, 0.9],
            bx(0.2, 0.02, 0.4),
        ),
        (
            "Object3",
            [-0.432097732466474, -0.7753937328216794, 0.087056, 0.0, 0.0, 0.8158325401727546, 0.5782882208685141],
            [0.65, 0.2, 0.9],
            bx(0.02, 0.2, 0.4),
        ),
        (
            "Object4",
            [-0.7016326445863116, -0.3798568368884329, 0.087056, 0.0, 0.0, 0.8220975726243217, 0.5693466264809149],
            [0.65, -0.2, 0.9],
            bx(0.2, 0.05, 0.35),
        ),
        (
            "Object5",
            [-0.02201615875713062, 0.149141008133426, 0.087056, 0.0, 0.0, -0.9999817664221317, 0.006038776637155595],
            [1.05, 0.2, 0.9],
            bx(0.2, 0.05, 0.35),
        ),
        ("leg1", table, [1.5, 0.85, 0.35], bx(0.05, 0.05, 0.7)),
        ("leg2", table, [0.6, 0.85, 0.35], bx(0.05, 0.05, 0.7)),
        ("leg3", table, [1.5, -0.85, 0.35], bx(0.05, 0.05, 0.7)),
        ("leg4", table, [0.6, -0.85, 0.35], bx(0.05, 0.05, 0.7)),
        ("table_top", table, [1.05, 0.0, 0.7], bx(1.2, 2.0, 0.04)),
    ];
    let mut env = Environment::new();
    for (name, p, at, shape) in objects {
        let rot = UnitQuaternion::from_quaternion(Quaternion::new(p[6], p[3], p[4], p[5]));
        let pose = Isometry3::from_parts(Translation3::new(p[0], p[1], p[2]), rot)
            * Isometry3::translation(at[0], at[1], at[2]);
        env.add(Obstacle::new(name, pose, shape));
    }
    env
}

/// Balls and boxes scattered around the base (not over it), at random poses.
fn clutter(seed: u64) -> Environment {
    let mut rng = Rng::new(seed);
    let mut env = Environment::new();
    while env.len() < 10 {
        let p = Vector3::new(rng.range(-1.2, 1.2), rng.range(-1.2, 1.2), rng.range(-0.3, 1.5));
        if p.xy().norm() < 0.35 {
            continue;
        }
        let shape = if env.len().is_multiple_of(2) {
            Shape::cuboid(rng.range(0.02, 0.2), rng.range(0.02, 0.2), rng.range(0.02, 0.2))
        } else {
            Shape::sphere(rng.range(0.03, 0.15))
        };
        let rot = UnitQuaternion::from_euler_angles(rng.range(-3.0, 3.0), rng.range(-3.0, 3.0), rng.range(-3.0, 3.0));
        env.add(Obstacle::new(format!("o{}", env.len()), Isometry3::from_parts(p.into(), rot), shape));
    }
    env
}

/// A random segment: `qb` a random fraction `scale` of the way to a random configuration.
fn segment(robot: &Robot, seed: u64, scale: f64) -> (Vec<f64>, Vec<f64>) {
    let mut rng = Rng::new(seed);
    let qa = robot.random_configuration(&mut rng);
    let far = robot.random_configuration(&mut rng);
    let qb = robot.config_space().interpolate(&qa, &far, scale);
    (qa, qb)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// For random segments and the sub-intervals the certificate bisects them into (and a few
    /// arbitrary ones), no sphere moves further from its position at the sub-interval's
    /// midpoint (measured as the sampled path length, relative to the world and to each body
    /// up its chain) than its margin at the midpoint, which is no larger than the static one;
    /// no pair of spheres of a self-collision pair gets closer than their pair margin allows.
    #[test]
    fn segment_arms_bound_the_sampled_motion(which in 0usize..7, seed in any::<u64>(), scale in 0.005f64..1.0) {
        let robots = robots();
        let robot = &robots[which];
        let g = sphere_geom(robot);
        let fast = SphereGeom::new(&g, false).unwrap();
        let (qa, qb) = segment(robot, seed, scale);
        let mut spans = vec![(0.0, 1.0)];
        for level in 1..4 {
            let w = 0.5f64.powi(level);
            let k = (seed >> (8 * level)) as usize % (1 << level);
            spans.push((k as f64 * w, (k + 1) as f64 * w));
        }
        let mut rng = Rng::new(seed ^ 0x5eed);
        let (a, b) = (rng.uniform(), rng.uniform());
        spans.push((a.min(b), a.max(b)));
        for span in spans {
            check_span(robot, &fast, (&qa, &qb), span, 48)?;
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Every margin grows at least in proportion to the joint steps (what lets a listing query
    /// certify free the share of its sub-interval around the midpoint that its nearest item's
    /// gap allows: see `reach_of` in the certificate): at a random pose, with the steps of a
    /// random segment's sub-interval, each sphere's margin against the world and against
    /// each body up its chain, and each self pair's margin, for `a` times the steps is at
    /// most `a` times the margin for the steps (the absolute slack aside).
    #[test]
    fn margins_grow_at_least_in_proportion_to_the_steps(
        which in 0usize..7, seed in any::<u64>(), scale in 0.005f64..1.0, a in 0.0f64..=1.0,
    ) {
        let robots = robots();
        let robot = &robots[which];
        let g = sphere_geom(robot);
        let fast = SphereGeom::new(&g, false).unwrap();
        let (qa, qb) = segment(robot, seed, scale);
        let space = robot.config_space();
        let half = 0.5f64.powi((seed % 5) as i32 + 1);
        let dir: Vec<f64> = (0..qa.len()).map(|i| space.delta(i, qa[i], qb[i]) * half).collect();
        let step: Vec<f64> = dir.iter().map(|d| d.abs()).collect();
        let part: Vec<f64> = step.iter().map(|d| d * a).collect();
        let part_dir: Vec<f64> = dir.iter().map(|d| d * a).collect();
        let mut at = SphereScratch::new();
        fast.pose(&space.interpolate(&qa, &qb, Rng::new(seed).uniform()), &mut at);
        for l in 0..fast.links.len() {
            fast.pose_link(l, &mut at);
        }
        let within = |small: f64, whole: f64, slack: f64| (small - slack) <= a * (whole - slack) * (1.0 + 1e-12) + 1e-15;
        for lk in &fast.links {
            for k in lk.first..lk.end {
                let mut b = lk.body;
                loop {
                    for d in [None, Some((&part_dir, &dir))] {
                        let small = fast.margin(k, b, &part, Some(&at), d.map(|d| &d.0[..]));
                        let whole = fast.margin(k, b, &step, Some(&at), d.map(|d| &d.1[..]));
                        prop_assert!(within(small, whole, 1e-12), "{}: sphere {k} against body {b}: {small} for {a} of {whole}", robot.name());
                    }
                    if b == 0 {
                        break;
                    }
                    b = fast.bodies[b].parent;
                }
            }
        }
        for p in 0..fast.self_pairs.len() {
            let (la, lb) = fast.self_pairs[p];
            let stop = fast.pair_common[p] as usize;
            let (la, lb) = (&fast.links[la as usize], &fast.links[lb as usize]);
            for i in la.first..la.end {
                for j in lb.first..lb.end {
                    for d in [None, Some((&part_dir, &dir))] {
                        let small = fast.pair_margin(i, j, stop, &part, d.map(|d| &d.0[..]), &at);
                        let whole = fast.pair_margin(i, j, stop, &step, d.map(|d| &d.1[..]), &at);
                        prop_assert!(within(small, whole, 2e-12), "{}: pair {p} ({i}, {j}): {small} for {a} of {whole}", robot.name());
                    }
                }
            }
        }
    }
}

/// A segment with both ends free: from a random configuration a random share in `lo..hi` of
/// the way to another.
fn free_ends(robot: &Robot, model: &CollisionModel, rng: &mut Rng, lo: f64, hi: f64) -> (Vec<f64>, Vec<f64>) {
    let space = robot.config_space();
    loop {
        let qa = robot.random_configuration(rng);
        let far = robot.random_configuration(rng);
        let qb = space.interpolate(&qa, &far, rng.range(lo, hi));
        if !model.collides(&qa) && !model.collides(&qb) {
            return (qa, qb);
        }
    }
}

/// `robot`'s sphere model among `clutter(seed)`, with the table-pick scene too for robot 0 (the
/// UR5 of the tests below).
fn cluttered(which: usize, robot: &Robot, seed: u64) -> CollisionModel {
    let mut env = clutter(seed);
    if which == 0 {
        for o in table_pick().obstacles() {
            env.add(o.clone());
        }
    }
    sphere_model(robot, env)
}

/// Robot 0 (the UR5) as loaded, with its self-collision cell tables, in the table-pick scene
/// plus `clutter(seed)`; any other robot as [`cluttered`] (with the seed plus `which`).
fn loaded_in_clutter(which: usize, robot: &Robot, seed: u64) -> CollisionModel {
    if which == 0 {
        let mut env = clutter(seed);
        for o in table_pick().obstacles() {
            env.add(o.clone());
        }
        CollisionModel::new(robot, env)
    } else {
        cluttered(which, robot, seed + which as u64)
    }
}

/// No configuration of the segment `qa`-`qb` sampled every 1e-3 rad (or m) collides.
fn assert_free_when_sampled_finely(robot: &Robot, model: &CollisionModel, qa: &[f64], qb: &[f64]) {
    let space = robot.config_space();
    let n = (space.max_joint_step(qa, qb) / 1e-3).ceil() as usize;
    let mut q = qa.to_vec();
    for k in 1..n {
        space.interpolate_into(qa, qb, k as f64 / n as f64, &mut q);
        assert!(!model.collides(&q), "{}: certified but collides at {q:?}", robot.name());
    }
}

/// Segments the certificate passes are free when sampled every 1e-3 rad (or m), on the
/// spherized UR5 in the table-pick scene plus clutter, and on a small arm with prismatic and
/// mimic joints among clutter. (Sphere versions of the built-in robots make the certificate
/// refine to the tolerance almost everywhere, too slow for a test: their bounds are checked by
/// the property test above.)
#[test]
fn certified_segments_are_free_when_sampled_finely() {
    for (which, robot) in [ur5(), mimic_arm()].iter().enumerate() {
        let model = cluttered(which, robot, which as u64);
        let mut rng = Rng::new(17 + which as u64);
        let (mut certified, mut refused) = (0, 0);
        for _ in 0..30 {
            let (qa, qb) = free_ends(robot, &model, &mut rng, 0.02, 0.25);
            if model.motion_is_certified_free(&qa, &qb, 1e-4) {
                certified += 1;
                assert_free_when_sampled_finely(robot, &model, &qa, &qb);
            } else {
                refused += 1;
            }
        }
        assert!(
            certified > 10 && (which > 0 || refused > 0),
            "{}: {certified} certified, {refused} refused",
            robot.name()
        );
    }
}

/// How much tighter the straight-motion margins are than the midpoint ones, and those than the
/// static ones, and how far all are from the sampled motion (`cargo test -p embodied-models
/// tightness -- --nocapture` prints the medians): all bound the motion, and each is the tighter
/// by median.
#[test]
fn tightness() {
    let robot = ur5();
    let g = sphere_geom(&robot);
    let fast = SphereGeom::new(&g, false).unwrap();
    for scale in [0.02, 0.1, 0.3] {
        for level in [0, 2, 4, 6] {
            let (mut straight, mut tight, mut loose) = (Vec::new(), Vec::new(), Vec::new());
            for seed in 0..30 {
                let (qa, qb) = segment(&robot, seed, scale);
                let w = 0.5f64.powi(level);
                let k = (seed as usize * 7) % (1 << level);
                let out = check_span(&robot, &fast, (&qa, &qb), (k as f64 * w, (k + 1) as f64 * w), 16).unwrap();
                for (moved, st, t, l) in out {
                    if moved > 1e-6 {
                        straight.push(st / moved);
                        tight.push(t / moved);
                        loose.push(l / moved);
                    }
                }
            }
            let med = |v: &mut Vec<f64>| {
                v.sort_by(f64::total_cmp);
                v[v.len() / 2]
            };
            let lowest = straight.iter().chain(&tight).chain(&loose).fold(f64::INFINITY, |m, &r| m.min(r));
            let (line, mid, stat) = (med(&mut straight), med(&mut tight), med(&mut loose));
            eprintln!(
                "scale {scale} level {level}: margin / sampled motion, median: straight {line:.2}, midpoint {mid:.2}, static {stat:.2}"
            );
            assert!(line < mid, "scale {scale} level {level}: straight {line} not tighter than midpoint {mid}");
            assert!(lowest >= 1.0 - 1e-9, "scale {scale} level {level}: a margin below the motion ({lowest})");
            assert!(mid < stat, "scale {scale} level {level}: midpoint {mid} not tighter than static {stat}");
        }
    }
}

/// The snake of the property test has self-collision pairs on both sides of `DEEP` (moving
/// joints from a sphere up to the pair's common body), so both the tightened pair margin and
/// its fallback are exercised.
#[test]
fn the_snake_has_pairs_deeper_than_deep_and_shallower() {
    let robot = snake();
    let fast = SphereGeom::new(&sphere_geom(&robot), false).unwrap();
    let step = vec![0.1; robot.dof()];
    let depths: Vec<usize> = (0..fast.self_pairs.len())
        .flat_map(|p| {
            let (a, b) = fast.self_pairs[p];
            let stop = fast.pair_common[p] as usize;
            [a, b].map(|l| {
                let mut n = 0;
                fast.walk(fast.links[l as usize].first, stop, &step, None, None, |_, _, _| n += 1);
                n
            })
        })
        .collect();
    assert!(depths.iter().any(|&n| n > super::DEEP), "{depths:?}");
    assert!(depths.iter().any(|&n| (2..=super::DEEP).contains(&n)), "{depths:?}");
}

/// The certificate that checks a half against only what was near over the whole (the default)
/// passes every segment the full one passes, and what it passes is free when sampled finely:
/// on the UR5 in the table-pick scene plus clutter, on the mimic arm and on the snake (whose
/// self pairs are near all the time).
#[test]
fn listed_certificate_passes_what_the_full_one_does_and_stays_sound() {
    for (which, robot) in [ur5(), mimic_arm(), snake()].iter().enumerate() {
        let model = cluttered(which, robot, 40 + which as u64);
        let mut s = model.scratch();
        let mut rng = Rng::new(91 + which as u64);
        let (mut both, mut only_listed, mut refused) = (0, 0, 0);
        for _ in 0..100 {
            let (qa, qb) = free_ends(robot, &model, &mut rng, 0.05, 0.8);
            let (full, _) = model.certify_in(&qa, &qb, 1e-4, false, false, &mut s);
            let (listed, _) = model.certify_in(&qa, &qb, 1e-4, false, true, &mut s);
            assert!(listed || !full, "{}: the full certificate passes {qa:?} -> {qb:?}, the listed not", robot.name());
            match (full, listed) {
                (true, _) => both += 1,
                (false, true) => only_listed += 1,
                (false, false) => refused += 1,
            }
            if listed {
                assert_free_when_sampled_finely(robot, &model, &qa, &qb);
            }
        }
        eprintln!("{}: {both} both, {only_listed} listed only, {refused} neither", robot.name());
        assert!(
            both > 5 && refused > 0,
            "{}: {both} passed by both, {only_listed} by the listed alone, {refused} by neither",
            robot.name()
        );
    }
}

/// What a listing query certifies free around its sub-interval's midpoint (the share its
/// nearest item's gap allows, see `reach_of` in the certificate) is free when sampled every
/// 1e-4 rad (or m): on sub-intervals of random segments among obstacles, for the UR5 in the
/// table-pick scene plus clutter, the mimic arm and the snake (whose self pairs are near all
/// the time). Many queries are near and certify some share, which the certificate then skips.
#[test]
fn what_a_listing_query_certifies_around_the_midpoint_is_free() {
    for (which, robot) in [ur5(), mimic_arm(), snake()].iter().enumerate() {
        let model = cluttered(which, robot, 60 + which as u64);
        let space = robot.config_space();
        let mut s = model.scratch();
        let mut rng = Rng::new(7 + which as u64);
        let (mut reached, mut most) = (0, 0);
        let mut q = vec![0.0; robot.dof()];
        for _ in 0..150 {
            let (qa, qb) = free_ends(robot, &model, &mut rng, 0.05, 0.8);
            let (a, b) = (rng.uniform(), rng.uniform());
            let (t0, t1) = (a.min(b), a.max(b));
            let (answer, rho) = model.span_query(&qa, &qb, (t0, t1), &mut s).unwrap();
            if answer != super::super::Check::Near || rho == 0.0 {
                continue;
            }
            reached += 1;
            let half = 0.5 * (t1 - t0);
            most += usize::from(rho > 0.5 * half);
            let tm = t0 + half;
            let (lo, hi) = (space.interpolate(&qa, &qb, tm - rho), space.interpolate(&qa, &qb, tm + rho));
            let n = (space.max_joint_step(&lo, &hi) / 1e-4).ceil().max(1.0) as usize;
            for k in 0..=n {
                space.interpolate_into(&qa, &qb, tm - rho + 2.0 * rho * k as f64 / n as f64, &mut q);
                assert!(
                    !model.collides(&q),
                    "{}: certified around {tm} ({rho} either side) but collides at {q:?}",
                    robot.name()
                );
            }
        }
        eprintln!("{}: {reached} queries near with a share certified, {most} of them more than half", robot.name());
        assert!(reached > 10 && most > 0, "{}: {reached} near with a share, {most} more than half", robot.name());
    }
}

/// The pieces a certificate's single-precision batches (all their levels, or four) leave to double precision with their
/// self pairs found free (whose checks then skip the self pairs) have no self pair near in the
/// double-precision query of the piece and no self contact anywhere, sampled every 1e-3 rad
/// (or m); and both kinds of piece occur: on the UR5 (as
/// loaded, with its self-collision cell tables) in the table-pick scene plus clutter, the
/// mimic arm and the snake (whose self pairs are near all the time).
#[test]
fn pieces_left_with_their_self_pairs_free_have_no_self_contact() {
    for (which, robot) in [ur5(), mimic_arm(), snake()].iter().enumerate() {
        let model = loaded_in_clutter(which, robot, 80);
        let space = robot.config_space();
        let mut s = model.scratch();
        let mut rng = Rng::new(23 + which as u64);
        let (mut freed, mut kept) = (0, 0);
        let mut q = vec![0.0; robot.dof()];
        let zero = vec![0.0; robot.dof()];
        // Until enough pieces of each kind were seen (the batches' levels leave few), with the
        // certificate's levels and with four (which leave more pieces without their pairs free).
        for k in 0..4000 {
            if freed >= 40 && (which < 2 || kept >= 40) {
                break;
            }
            let (qa, qb) = free_ends(robot, &model, &mut rng, 0.05, 1.0);
            let levels = if k % 2 == 0 { super::super::super::LANES_LEVELS } else { 4 };
            let Some(left) = model.batches_left(&qa, &qb, levels, &mut s) else { continue };
            for (t0, t1, pairs_free) in left {
                if !pairs_free {
                    kept += 1;
                    continue;
                }
                freed += 1;
                // The double-precision query of the piece (its pairs' margins at most the
                // batch's) finds no self pair near either.
                model.span_query(&qa, &qb, (t0, t1), &mut s).unwrap();
                assert!(
                    !s.spheres.items.iter().any(|item| matches!(item, super::super::Item::Pair { .. })),
                    "{}: a self pair near on a piece [{t0}, {t1}] left with its pairs free",
                    robot.name()
                );
                let (lo, hi) = (space.interpolate(&qa, &qb, t0), space.interpolate(&qa, &qb, t1));
                let n = (space.max_joint_step(&lo, &hi) / 1e-3).ceil().max(1.0) as usize;
                for k in 0..=n {
                    space.interpolate_into(&qa, &qb, t0 + (t1 - t0) * k as f64 / n as f64, &mut q);
                    for p in 0..model.geom.self_pairs.len() {
                        assert!(
                            model.pair_check(&q, p, &zero, &mut s) != super::super::Check::Hit,
                            "{}: self pair {p} in contact at {q:?}, on a piece [{t0}, {t1}] left with its pairs free",
                            robot.name()
                        );
                    }
                }
            }
        }
        eprintln!("{}: {freed} pieces left with their self pairs free, {kept} without", robot.name());
        assert!(freed > 10 && (which < 2 || kept > 10), "{}: {freed} with pairs free, {kept} without", robot.name());
    }
}

/// Every level of batches only narrows what the one before left: on the UR5 in clutter, each
/// piece [`LANES_LEVELS`](super::super::super::LANES_LEVELS) levels leave lies inside a piece
/// the first level alone leaves, with the same self-pair verdict or a freer one, and the
/// further levels prove most of the first level's pieces free.
#[test]
fn further_levels_of_batches_only_narrow_what_is_left() {
    let robot = ur5();
    let mut env = clutter(80);
    for o in table_pick().obstacles() {
        env.add(o.clone());
    }
    let model = CollisionModel::new(&robot, env);
    let mut s = model.scratch();
    let mut rng = Rng::new(41);
    let levels = super::super::super::LANES_LEVELS;
    assert!(levels > 1);
    let (mut first_len, mut all_len, mut segments) = (0.0, 0.0, 0);
    for _ in 0..600 {
        let (qa, qb) = free_ends(&robot, &model, &mut rng, 0.05, 1.0);
        let (Some(one), Some(all)) =
            (model.batches_left(&qa, &qb, 1, &mut s), model.batches_left(&qa, &qb, levels, &mut s))
        else {
            continue;
        };
        segments += 1;
        for &(t0, t1, pairs) in &all {
            assert!(t0 < t1, "an empty piece [{t0}, {t1}]");
            let parent = one.iter().find(|&&(a, b, _)| a <= t0 && t1 <= b);
            let Some(&(_, _, parent_pairs)) = parent else {
                panic!("piece [{t0}, {t1}] left by {levels} levels lies in no piece the first leaves: {one:?}");
            };
            assert!(pairs || !parent_pairs, "piece [{t0}, {t1}] lost its parent's free self pairs");
        }
        first_len += one.iter().map(|p| p.1 - p.0).sum::<f64>();
        all_len += all.iter().map(|p| p.1 - p.0).sum::<f64>();
    }
    eprintln!("{segments} segments: the first level leaves {first_len:.3} of them, {levels} levels {all_len:.3}");
    assert!(segments > 100 && first_len > 0.0, "{segments} segments, {first_len} left by the first level");
    assert!(all_len < 0.5 * first_len, "{levels} levels leave {all_len}, one level {first_len}");
}

/// A level of batches that tests only what the level before left near (the groups it found
/// near an obstacle, and the self pairs unless it found them free) leaves no piece that the
/// same levels testing everything would not leave, and whatever it proves free beyond them is
/// free: sampled every 1e-3 rad (or m) by the exact double-precision check. On the UR5 (as
/// loaded, with its cell tables) in the table-pick scene plus clutter, the mimic arm and the
/// snake. The scoped levels also run: pieces left by the first level are proven free by them.
#[test]
fn scoped_levels_leave_a_subset_of_what_full_levels_leave_and_stay_sound() {
    let levels = super::super::super::LANES_LEVELS;
    for (which, robot) in [ur5(), mimic_arm(), snake()].iter().enumerate() {
        let model = loaded_in_clutter(which, robot, 90);
        let space = robot.config_space();
        let (mut scoped_s, mut full_s) = (model.scratch(), model.scratch().with_unscoped_levels());
        let mut rng = Rng::new(71 + which as u64);
        let mut q = vec![0.0; robot.dof()];
        let (mut segments, mut refined, mut gained, mut same_len) = (0, 0, 0.0, 0);
        for _ in 0..500 {
            let (qa, qb) = free_ends(robot, &model, &mut rng, 0.05, 1.0);
            let one = model.batches_left(&qa, &qb, 1, &mut full_s);
            let scoped = model.batches_left(&qa, &qb, levels, &mut scoped_s);
            let full = model.batches_left(&qa, &qb, levels, &mut full_s);
            let (Some(one), Some(scoped), Some(full)) = (one, scoped, full) else {
                // A contact found by one is found by the other (the first level is the same).
                continue;
            };
            segments += 1;
            if !one.is_empty() {
                refined += 1;
            }
            // Every piece the scoped levels leave, the full ones leave too, with the same
            // self-pair verdict or a freer one.
            for &(t0, t1, pairs) in &scoped {
                let Some(&(_, _, full_pairs)) = full.iter().find(|&&(a, b, _)| a == t0 && b == t1) else {
                    panic!("{}: scoped levels leave [{t0}, {t1}], the full ones do not: {full:?}", robot.name());
                };
                assert!(pairs || !full_pairs, "{}: piece [{t0}, {t1}] lost its free self pairs", robot.name());
            }
            if scoped.len() == full.len() {
                same_len += 1;
            }
            // What the full levels leave and the scoped ones prove free is free.
            for &(t0, t1, _) in full.iter().filter(|p| !scoped.iter().any(|s| s.0 == p.0 && s.1 == p.1)) {
                gained += t1 - t0;
                let (lo, hi) = (space.interpolate(&qa, &qb, t0), space.interpolate(&qa, &qb, t1));
                let n = (space.max_joint_step(&lo, &hi) / 1e-3).ceil().max(1.0) as usize;
                for k in 0..=n {
                    space.interpolate_into(&qa, &qb, t0 + (t1 - t0) * k as f64 / n as f64, &mut q);
                    assert!(
                        !model.collides_with(&q, &mut full_s),
                        "{}: contact at {q:?} on [{t0}, {t1}], proven free by the scoped levels",
                        robot.name()
                    );
                }
            }
        }
        eprintln!(
            "{}: {segments} segments, {refined} refined past the first level, {same_len} with the same pieces left, \
             {gained:.4} more proven free, {} scoped batches",
            robot.name(),
            scoped_s.scoped_batches
        );
        let scoped_batches = scoped_s.scoped_batches;
        assert_eq!(full_s.scoped_batches, 0);
        assert!(
            segments > 100 && refined > 10 && scoped_batches > 10,
            "{}: {segments} segments, {refined} refined, {scoped_batches} scoped batches",
            robot.name()
        );
    }
}
