//! Serial-parallel actuation: the screws' strokes cut the joints' ranges, the time scaling
//! slows a motion where a screw's speed binds, and the verifier refuses a trajectory whose
//! screw is too fast although every joint is within its limits.
#![allow(clippy::unwrap_used)]

use embodied_models::collision::{CollisionModel, Environment};
use embodied_models::{ModelError, builtin};
use embodied_planner::trajectory::{Trajectory, time_parameterize};
use embodied_planner::verify::{Finding, Verifier};

fn peak_ratio(robot: &embodied_models::Robot, traj: &Trajectory) -> f64 {
    traj.q.iter().zip(&traj.qd).map(|(q, qd)| robot.actuator_speed_ratio(q, qd)).fold(0.0, f64::max)
}

#[test]
fn the_irp6_screws_with_mrroc_strokes_cut_the_joint_ranges_and_the_built_in_arms_carry_their_speed() {
    use embodied_models::actuator::irp6_arm_screws;
    let robot = builtin("irp6-postument").unwrap();
    let home = robot.home().to_vec();
    let mrroc = irp6_arm_screws("", 1);
    let within = |q: &[f64]| mrroc.iter().all(|a| a.stroke_excess(q) <= 0.0);
    assert!(within(&home));
    // -129 degrees: inside the joint limit (-130), but MRROC++'s lower-arm screw is shorter than
    // its motor range allows (it ends at about -125.4 degrees).
    let mut q = home.clone();
    q[1] = -129f64.to_radians();
    assert!(mrroc[0].length(&q) < mrroc[0].min_length);
    // The upper-arm screw drives the upper arm's absolute angle q1 + q2 + pi/2: q2 = 39 degrees
    // is within its joint limit (40) but out of the stroke at q1 = -pi/2 ...
    let mut q = home.clone();
    q[2] = 39f64.to_radians();
    assert!(mrroc[1].stroke_excess(&q) > 0.0);
    // ... and within it with the lower arm raised by 10 degrees (the absolute angle counts).
    q[1] = home[1] - 10f64.to_radians();
    assert!(within(&q));
    // The built-in arms carry the same screws, strokes and speeds: a configuration within the
    // joint limits but out of a stroke is refused, naming the screw, and random configurations
    // are drawn within the strokes.
    assert_eq!(robot.actuators().len(), 2);
    for (a, m) in robot.actuators().iter().zip(&mrroc) {
        assert_eq!(
            (a.name.as_str(), a.max_speed, a.c, a.m, a.n, a.min_length, a.max_length),
            (m.name.as_str(), m.max_speed, m.c, m.m, m.n, m.min_length, m.max_length)
        );
    }
    let mut q = home.clone();
    q[1] = -129f64.to_radians();
    assert!(robot.limits().iter().zip(&q).all(|(l, v)| (l.lower..=l.upper).contains(v)));
    assert!(
        matches!(robot.check_configuration(&q), Err(ModelError::OutOfStroke { ref actuator, .. }) if actuator == "lower_arm_screw")
    );
    q = home.clone();
    q[2] = 39f64.to_radians();
    assert!(
        matches!(robot.check_configuration(&q), Err(ModelError::OutOfStroke { ref actuator, .. }) if actuator == "upper_arm_screw")
    );
    let mut rng = embodied_models::Rng::new(7);
    for _ in 0..200 {
        let q = robot.random_configuration(&mut rng);
        assert!(robot.within_limits(&q) && within(&q), "{:?}", robot.check_configuration(&q));
    }
    // The on-track and two-handed cells carry the screws on their arms' joints.
    let two = builtin("two-irp6").unwrap();
    let names: Vec<&str> = two.actuators().iter().map(|a| a.name.as_str()).collect();
    assert_eq!(names, ["ot_lower_arm_screw", "ot_upper_arm_screw", "p_lower_arm_screw", "p_upper_arm_screw"]);
    assert_eq!(two.actuators()[2].angle, vec![(8, 1.0)]);
    assert_eq!(two.actuators()[3].angle, vec![(8, 1.0), (9, 1.0)]);
    // Out of a stroke (the RNT's shoulder screw cuts q2 near -pi): refused by name.
    let rnt = builtin("rnt").unwrap();
    let mut q = rnt.home().to_vec();
    q[1] = -3.0;
    assert!(
        matches!(rnt.check_configuration(&q), Err(ModelError::OutOfStroke { ref actuator, .. }) if actuator == "shoulder_screw")
    );
}

#[test]
fn a_motion_where_a_screw_binds_is_slowed_to_the_screws_speed() {
    let robot = builtin("rnt").unwrap();
    let screw = &robot.actuators()[0];
    assert_eq!(screw.name, "shoulder_screw");
    let home = robot.home().to_vec();
    let segment = |from: f64, to: f64| {
        let (mut a, mut b) = (home.clone(), home.clone());
        a[1] = from;
        b[1] = to;
        time_parameterize(&[a, b], &robot, 0.001)
    };
    let peak_q2 = |t: &Trajectory| t.qd.iter().map(|qd| qd[1].abs()).fold(0.0, f64::max);
    // Mid-stroke (triangle angle near pi/2) the screw moves 0.35 m per rad: at 0.5 rad/s it
    // would run 0.17 m/s, over its 0.15 m/s. The segment is slowed until the screw is at its limit.
    let mid = segment(-1.75, -1.35);
    let ratio = peak_ratio(&robot, &mid);
    assert!(ratio <= 1.0 && ratio > 0.97, "screw speed ratio {ratio}");
    assert!(peak_q2(&mid) < 0.45, "{}", peak_q2(&mid));
    // Near the end of the stroke the screw moves little per rad: the joint's limit binds.
    let end = segment(-0.6, -0.2);
    assert!((peak_q2(&end) - 0.5).abs() < 1e-9, "{}", peak_q2(&end));
    assert!(peak_ratio(&robot, &end) < 0.7);
    assert!(mid.duration() > end.duration() + 0.05, "{} vs {}", mid.duration(), end.duration());
    // Both pass the certified verifier.
    let model = CollisionModel::new(&robot, Environment::new());
    for t in [&mid, &end] {
        let r = Verifier::certified(0.0).check_trajectory(&model, t, &[]);
        assert!(r.limits.ok, "{:?}", r.limits.violation);
    }
}

#[test]
fn the_verifier_refuses_a_screw_faster_than_its_limit_while_every_joint_is_within_its_limits() {
    let robot = builtin("rnt").unwrap();
    let mut q = robot.home().to_vec();
    q[1] = -1.6;
    // J2 at a constant 0.48 rad/s (limit 0.5) for 0.2 s: the shoulder screw runs ~0.167 m/s.
    let v = 0.48;
    let mut traj = Trajectory { joint_names: robot.joint_names(), t: vec![], q: vec![], qd: vec![] };
    for k in 0..=200 {
        let t = k as f64 * 0.001;
        let mut qk = q.clone();
        qk[1] += v * t;
        let mut qd = vec![0.0; q.len()];
        qd[1] = v;
        traj.t.push(t);
        traj.q.push(qk);
        traj.qd.push(qd);
    }
    let model = CollisionModel::new(&robot, Environment::new());
    let report = Verifier::certified(0.0).check_trajectory(&model, &traj, &[]);
    assert!(!report.certified);
    match &report.limits.violation {
        Some(Finding::Actuator { actuator, what, value, limit, .. }) => {
            assert_eq!((actuator.as_str(), what.as_str()), ("shoulder_screw", "speed"));
            assert!(value.abs() > *limit && *limit == 0.15, "{value} {limit}");
        }
        other => panic!("{other:?}"),
    }
    // Every finding is about the screw: no joint exceeds anything.
    assert!(report.limits.violations > 0);
    let text = report.limits.violation.as_ref().unwrap().to_string();
    assert!(text.contains("actuator `shoulder_screw` speed"), "{text}");
    // The same motion at 0.35 rad/s is certified.
    for qd in traj.qd.iter_mut() {
        qd[1] = 0.35;
    }
    for (k, qk) in traj.q.iter_mut().enumerate() {
        qk[1] = q[1] + 0.35 * k as f64 * 0.001;
    }
    let report = Verifier::certified(0.0).check_trajectory(&model, &traj, &[]);
    assert!(report.limits.ok, "{:?}", report.limits.violation);
}
