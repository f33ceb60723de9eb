//! The IRp-6's closed-form inverse kinematics: every solution reaches the pose within the limits,
//! the configuration a pose came from is among the solutions, the numerical solver finds nothing
//! the closed form misses, and the singular and unreachable cases answer sensibly.
#![allow(clippy::unwrap_used)]

use std::f64::consts::{FRAC_PI_2, PI};

use embodied_models::ik::pose_error;
use embodied_models::nalgebra::{Isometry3, Translation3, UnitQuaternion};
use embodied_models::{ClosedForm, IkOptions, ModelError, Rng, Robot, builtin, wrap_angle};
use proptest::prelude::*;

/// The IRp-6 models and their end effectors with a closed form.
fn irp6_arms() -> Vec<(Robot, usize)> {
    let mut arms = Vec::new();
    for name in ["irp6-postument", "irp6-on-track", "two-irp6"] {
        let robot = builtin(name).unwrap();
        for ee in 0..robot.end_effectors().len() {
            assert_eq!(robot.closed_form(ee), Some(ClosedForm::Irp6), "{name} ee {ee}");
            arms.push((robot.clone(), ee));
        }
    }
    arms
}

/// The degrees of freedom that move end effector `ee` (with the track, if any).
fn arm_dofs(robot: &Robot, ee: usize) -> Vec<usize> {
    robot.chain_to(robot.end_effectors()[ee].link).iter().filter_map(|&j| robot.joints()[j].dof_index).collect()
}

/// Largest difference over the joints moving `ee`, angles compared modulo whole turns.
fn joint_gap(robot: &Robot, ee: usize, a: &[f64], b: &[f64]) -> f64 {
    arm_dofs(robot, ee)
        .into_iter()
        .map(|i| {
            let d = a[i] - b[i];
            if robot.dof_joint(i).kind == embodied_models::JointKind::Prismatic { d.abs() } else { wrap_angle(d).abs() }
        })
        .fold(0.0, f64::max)
}

/// Every solution lies within the limits, reaches `target` and keeps the joints off the arm.
fn check_solutions(robot: &Robot, ee: usize, target: &Isometry3<f64>, seed: &[f64], solutions: &[Vec<f64>]) {
    let arm_dofs = arm_dofs(robot, ee);
    for q in solutions {
        assert!(robot.within_limits(q), "{}: {q:?} breaks a limit", robot.name());
        let e = pose_error(&robot.end_effector_poses(q, ee).1, target);
        assert!(e.norm() < 1e-9, "{}: residual {}", robot.name(), e.norm());
        for d in 0..robot.dof() {
            let prismatic = robot.dof_joint(d).kind == embodied_models::JointKind::Prismatic;
            if !arm_dofs.contains(&d) || prismatic {
                assert_eq!(q[d], seed[d], "{}: joint {d} off the arm (or the track) moved", robot.name());
            }
        }
    }
    for (i, a) in solutions.iter().enumerate() {
        for b in &solutions[..i] {
            assert!(joint_gap(robot, ee, a, b) > 1e-9, "{}: a solution is listed twice", robot.name());
        }
    }
    let space = robot.config_space();
    let d: Vec<f64> = solutions.iter().map(|q| space.distance(seed, q)).collect();
    assert!(d.windows(2).all(|w| w[0] <= w[1]), "{}: not nearest first: {d:?}", robot.name());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// A pose reached at a random configuration: the closed form lists that configuration (from
    /// a seed elsewhere), and from the configuration itself it answers with it first.
    #[test]
    fn closed_form_finds_the_configuration_a_pose_came_from(seed in any::<u64>()) {
        let mut rng = Rng::new(seed);
        for (robot, ee) in irp6_arms() {
            let q_true = robot.random_configuration(&mut rng);
            let target = robot.end_effector_poses(&q_true, ee).1;
            // Elsewhere on the arm, but the same track position (the closed form keeps the track).
            let mut other = robot.random_configuration(&mut rng);
            for d in 0..robot.dof() {
                if robot.dof_joint(d).kind == embodied_models::JointKind::Prismatic {
                    other[d] = q_true[d];
                }
            }
            let all = robot.inverse_kinematics_all(ee, &target, &other).unwrap();
            check_solutions(&robot, ee, &target, &other, &all);
            let best = all.iter().map(|q| joint_gap(&robot, ee, q, &q_true)).fold(f64::INFINITY, f64::min);
            prop_assert!(best < 1e-7, "{} ee {ee}: {} solutions, nearest to the true one {best}", robot.name(), all.len());
            let from_true = robot.inverse_kinematics_all(ee, &target, &q_true).unwrap();
            prop_assert!(robot.config_space().distance(&from_true[0], &q_true) < 1e-7);
        }
    }
}

/// What damped least squares finds from random seeds, the closed form lists too: it misses no
/// branch. 40 targets per arm, four numerical solutions each, on the arms without a track (the
/// numerical solver may move a track; the closed form keeps it).
#[test]
fn numerical_solutions_are_among_the_closed_form_ones() {
    let mut rng = Rng::new(7);
    let mut checked = 0;
    for (name, ee) in [("irp6-postument", 0), ("two-irp6", 1)] {
        let robot = builtin(name).unwrap();
        for _ in 0..40 {
            let q_true = robot.random_configuration(&mut rng);
            let target = robot.end_effector_poses(&q_true, ee).1;
            let all = robot.inverse_kinematics_all(ee, &target, &q_true).unwrap();
            for k in 0..4 {
                let seed = robot.random_configuration(&mut rng);
                let options = IkOptions { seed: k, restarts: 2, closed_form: false, ..IkOptions::default() };
                let Ok(q) = robot.inverse_kinematics(ee, &target, &seed, &options) else { continue };
                let gap = all.iter().map(|s| joint_gap(&robot, ee, s, &q)).fold(f64::INFINITY, f64::min);
                assert!(
                    gap < 1e-4,
                    "{name}: numerical {q:?} is not among the {} closed-form solutions ({gap})",
                    all.len()
                );
                checked += 1;
            }
        }
    }
    assert!(checked >= 160, "only {checked} numerical solutions to compare");
}

/// The wrist singularity (wrist V at 0 or pi: the pitch and N axes line up) and an elbow at full
/// stretch: solutions still reach the pose.
#[test]
fn singular_poses_are_solved() {
    let robot = builtin("irp6-postument").unwrap();
    for q in [
        [0.3, -1.2, 0.2, 0.4, 0.0, 0.5],
        [0.3, -1.2, 0.2, 0.4, PI, 0.5],
        [-1.0, -1.5, 0.1, -0.3, 2.0 * PI, -2.0],
        [0.0, -FRAC_PI_2, 0.0, 0.0, 1.0, 0.0],
    ] {
        let target = robot.end_effector_poses(&q, 0).1;
        for seed in [q.to_vec(), robot.home().to_vec()] {
            let all = robot.inverse_kinematics_all(0, &target, &seed).unwrap();
            assert!(!all.is_empty(), "{q:?}: no solution");
            check_solutions(&robot, 0, &target, &seed, &all);
        }
        let again = robot.inverse_kinematics_all(0, &target, &q).unwrap();
        assert!(robot.config_space().distance(&again[0], &q) < 1e-7, "{q:?}: got {:?}", again[0]);
    }
}

/// Out of reach: no closed-form solution, and `inverse_kinematics` reports failure.
#[test]
fn unreachable_pose_has_no_solution() {
    let robot = builtin("irp6-postument").unwrap();
    let far = Isometry3::from_parts(Translation3::new(2.5, 0.0, 1.0), UnitQuaternion::identity());
    assert!(robot.inverse_kinematics_all(0, &far, robot.home()).unwrap().is_empty());
    let options = IkOptions { restarts: 2, ..IkOptions::default() };
    assert!(matches!(robot.inverse_kinematics(0, &far, robot.home(), &options), Err(ModelError::IkFailed { .. })));
}

/// Robots without a closed form say so; a frozen track makes the on-track arm's closed form cover
/// every joint, so `inverse_kinematics` answers with the nearest closed-form solution.
#[test]
fn closed_form_availability() {
    let polycrank = builtin("polycrank").unwrap();
    assert_eq!(polycrank.closed_form(0), None);
    let target = polycrank.end_effector_poses(polycrank.home(), 0).1;
    let err = polycrank.inverse_kinematics_all(0, &target, polycrank.home()).unwrap_err();
    assert!(err.to_string().contains("no closed-form inverse kinematics"), "{err}");
    assert!(matches!(
        polycrank.inverse_kinematics_all(5, &target, polycrank.home()),
        Err(ModelError::NoSuchName { .. })
    ));

    let track = builtin("irp6-on-track").unwrap();
    let fixed = track.freeze_joints(&[("track", 0.4)]).unwrap();
    assert_eq!(fixed.dof(), 6);
    assert_eq!(fixed.closed_form(0), Some(ClosedForm::Irp6));
    let mut rng = Rng::new(3);
    for _ in 0..20 {
        let q = fixed.random_configuration(&mut rng);
        let target = fixed.end_effector_poses(&q, 0).1;
        let seed = fixed.home().to_vec();
        let all = fixed.inverse_kinematics_all(0, &target, &seed).unwrap();
        let one = fixed.inverse_kinematics(0, &target, &seed, &IkOptions::default()).unwrap();
        assert_eq!(one, all[0]);
        check_solutions(&fixed, 0, &target, &seed, &all);
    }
    // Freezing an arm joint removes the closed form.
    let no_wrist = builtin("irp6-postument").unwrap().freeze_joints(&[("wrist_n", 0.0)]).unwrap();
    assert_eq!(no_wrist.closed_form(0), None);
}
