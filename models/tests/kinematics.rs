//! Golden kinematics: poses computed by hand from the DH tables in shared/robots/README.md.
#![allow(clippy::unwrap_used)]

use embodied_models::{BUILTIN_NAMES, builtin, nalgebra::Vector3};

fn close(a: Vector3<f64>, b: [f64; 3], tol: f64) -> bool {
    (a - Vector3::from(b)).norm() < tol
}

#[test]
fn irp6_postument_front_position_flange() {
    let r = builtin("irp6-postument").unwrap();
    let q = [0.0, -1.57, 0.0, 1.56, 1.57, -1.57];
    let (flange, tool) = r.end_effector_poses(&q, 0);
    // README 1.3.1: (0.6723, 0, 0.2645) from the shoulder, shoulder 0.95 m above the base.
    assert!(close(flange.translation.vector, [0.6723, 0.0, 1.2145], 5e-4), "{}", flange.translation.vector);
    // The tool is 0.25 m along the flange z axis.
    let z = flange.rotation * Vector3::z();
    assert!(close(tool.translation.vector, (flange.translation.vector + 0.25 * z).into(), 1e-12));
}

#[test]
fn irp6_on_track_is_the_postument_arm_shifted_along_y() {
    let p = builtin("irp6-postument").unwrap();
    let ot = builtin("irp6-on-track").unwrap();
    let q = [0.3, -1.2, 0.1, 0.4, 2.0, -1.0];
    let (fp, _) = p.end_effector_poses(&q, 0);
    let mut qo = vec![0.8];
    qo.extend(q);
    let (fo, _) = ot.end_effector_poses(&qo, 0);
    assert!(close(fo.translation.vector, (fp.translation.vector + Vector3::new(0.0, 0.8, 0.0)).into(), 1e-12));
    assert!(fo.rotation.angle_to(&fp.rotation) < 1e-12);
}

#[test]
fn two_irp6_has_both_arms_in_place() {
    let two = builtin("two-irp6").unwrap();
    assert_eq!(two.dof(), 13);
    assert_eq!(two.end_effectors().len(), 2);
    assert_eq!(two.end_effectors()[0].name, "irp6ot");
    let q = two.home().to_vec();
    let (f_ot, _) = two.end_effector_poses(&q, 0);
    let (f_p, _) = two.end_effector_poses(&q, 1);
    assert!(close(f_ot.translation.vector, [0.6723, 0.0, 1.2145], 5e-4));
    assert!(close(f_p.translation.vector, [0.6723, 2.11, 1.2145], 5e-4));
}

#[test]
fn polycrank_flange_at_zero() {
    let r = builtin("polycrank").unwrap();
    let q = [0.0; 7];
    let poses = r.forward_kinematics(&q);
    let link7 = r.link_index("link7").unwrap();
    // README 2.2: flange (frame 7) at (183, -296, 1589) mm when q = 0.
    assert!(
        close(poses[link7].translation.vector, [0.183, -0.296, 1.589], 1e-9),
        "{}",
        poses[link7].translation.vector
    );
    let link1 = r.link_index("link1").unwrap();
    assert!(close(poses[link1].translation.vector, [-0.299, 0.0, 1.145], 1e-9));
}

#[test]
fn every_builtin_builds_with_its_provenance() {
    for name in BUILTIN_NAMES {
        let r = builtin(name).unwrap();
        assert!(!r.provenance().is_empty());
        assert!(r.check_configuration(r.home()).is_ok(), "{name} home outside limits");
    }
    assert!(builtin("rnt").unwrap().provenance().contains("ASSUMPTION"));
    let err = builtin("puma").unwrap_err().to_string();
    assert!(err.contains("polycrank") && err.contains("two-irp6"), "{err}");
}

#[test]
fn wrap_around_metric_on_polycrank() {
    let r = builtin("polycrank").unwrap();
    let cs = r.config_space();
    let mut a = vec![0.0; 7];
    let mut b = vec![0.0; 7];
    a[0] = -3.1;
    b[0] = 3.1;
    let d = cs.distance(&a, &b);
    assert!((d - (std::f64::consts::TAU - 6.2)).abs() < 1e-12, "{d}");
    // Half way crosses +-pi.
    let mid = cs.interpolate(&a, &b, 0.5);
    assert!((embodied_models::wrap_angle(mid[0]).abs() - std::f64::consts::PI).abs() < 1e-9);
    // A limited joint does not wrap.
    let irp = builtin("irp6-postument").unwrap().config_space();
    let d2 = irp.distance(&[-3.1, 0.0, 0.0, 0.0, 0.0, 0.0], &[3.1, 0.0, 0.0, 0.0, 0.0, 0.0]);
    assert!((d2 - 6.2).abs() < 1e-12);
}

#[test]
fn freezing_joints_keeps_the_kinematics() {
    let ot = builtin("irp6-on-track").unwrap();
    let q = [0.7, 0.3, -1.2, 0.1, 0.4, 2.0, -1.0];
    let frozen = ot.freeze_joints(&[("track", 0.7), ("wrist_n", -1.0)]).unwrap();
    assert_eq!(frozen.dof(), 5);
    assert_eq!(frozen.joint_names(), vec!["column", "lower_arm", "upper_arm", "wrist_t", "wrist_v"]);
    let (a, _) = ot.end_effector_poses(&q, 0);
    let (b, _) = frozen.end_effector_poses(&[0.3, -1.2, 0.1, 0.4, 2.0], 0);
    assert!((a.translation.vector - b.translation.vector).norm() < 1e-12);
    assert!(a.rotation.angle_to(&b.rotation) < 1e-12);
    assert!(ot.freeze_joints(&[("nope", 0.0)]).is_err());
}
