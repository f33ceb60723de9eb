//! The closed-chain QP keeps the grasp closed (||J_R qd|| ~ 0) and respects the bounds.

use embodied_executor::closed_chain::*;
use embodied_models::nalgebra::DVector;

#[test]
fn closure_residual_is_zero_and_bounds_hold_for_two_irp6() {
    let robot = embodied_models::builtin("two-irp6").expect("built-in");
    assert!(robot.end_effectors().len() >= 2);
    let limits = robot.limits();
    let mut q = robot.home().to_vec();
    let dt = 0.01;
    let (e1, e2) = (&robot.end_effectors()[0], &robot.end_effectors()[1]);
    let start = {
        let (_, t1) = robot.end_effector_poses(&q, 0);
        let (_, t2) = robot.end_effector_poses(&q, 1);
        t1.inverse() * t2
    };
    for _ in 0..50 {
        let j1 = robot.jacobian(&q, e1.link, &e1.tool);
        let j2 = robot.jacobian(&q, e2.link, &e2.tool);
        let (_, t1) = robot.end_effector_poses(&q, 0);
        let (_, t2) = robot.end_effector_poses(&q, 1);
        let (lower, upper) = velocity_bounds(&q, &limits, dt);
        let qp = ClosedChainQp {
            j_a: absolute_jacobian(&j1, &j2),
            v_a: DVector::from_vec(vec![0.0, 0.0, 0.05, 0.0, 0.0, 0.0]),
            j_r: relative_jacobian(&j1, &j2, &t1, &t2),
            lambda: 1e-4,
            lower: lower.clone(),
            upper: upper.clone(),
        };
        let qd = qp.solve().expect("solved");
        let residual = (&qp.j_r * &qd).norm();
        assert!(residual < 1e-6, "closure residual {residual}");
        for i in 0..qd.len() {
            assert!(
                qd[i] >= lower[i] - 1e-7 && qd[i] <= upper[i] + 1e-7,
                "joint {i}: {} not in [{}, {}]",
                qd[i],
                lower[i],
                upper[i]
            );
        }
        // The absolute task is pursued.
        assert!((&qp.j_a * &qd).dot(&qp.v_a) > 0.0);
        for i in 0..q.len() {
            q[i] += qd[i] * dt;
        }
    }
    // Integrated over 0.5 s, the grasp stayed (nearly) closed: only second-order drift.
    let (_, t1) = robot.end_effector_poses(&q, 0);
    let (_, t2) = robot.end_effector_poses(&q, 1);
    let drift = (t1.inverse() * t2).translation.vector - start.translation.vector;
    assert!(drift.norm() < 2e-3, "relative pose drift {}", drift.norm());
}

#[test]
fn bad_dimensions_are_an_error_not_a_panic() {
    let qp = ClosedChainQp {
        j_a: embodied_models::nalgebra::DMatrix::zeros(6, 3),
        v_a: DVector::zeros(6),
        j_r: embodied_models::nalgebra::DMatrix::zeros(6, 2),
        lambda: 1e-3,
        lower: DVector::zeros(3),
        upper: DVector::zeros(3),
    };
    assert!(qp.solve().is_err());
}
