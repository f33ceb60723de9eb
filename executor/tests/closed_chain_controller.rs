#![allow(clippy::unwrap_used)]
//! The per-step closed-chain controller on `two-irp6`: the dense solver agrees with clarabel,
//! the bounds hold, infeasible steps are errors, and drift correction keeps the grasp closed.

use embodied_executor::ExecutorError;
use embodied_executor::closed_chain::*;
use embodied_models::nalgebra::{DVector, Vector3, Vector6};
use embodied_models::{JointLimits, Rng, Robot};
use proptest::prelude::*;

fn robot() -> Robot {
    embodied_models::builtin("two-irp6").expect("built-in")
}

/// A random problem: configuration, tightened limits, previous velocity, twist, closure error and
/// damper rows (some binding).
struct Random {
    q: Vec<f64>,
    limits: Vec<JointLimits>,
    qd_prev: Vec<f64>,
    kin: ChainKinematics,
    v_a: Vector6<f64>,
    e_r: Vector6<f64>,
    dampers: Vec<VelocityDamper>,
}

fn random_problem(robot: &Robot, rng: &mut Rng, dt: f64) -> Random {
    let mut q = robot.random_configuration(rng);
    let mut limits = robot.limits();
    for (i, l) in limits.iter_mut().enumerate() {
        l.max_velocity *= rng.range(0.05, 1.0);
        l.max_acceleration *= rng.range(0.2, 1.0);
        // Sometimes sit close to a position limit so the braking bound binds.
        if l.is_bounded() && rng.uniform() < 0.03 {
            q[i] = if rng.uniform() < 0.5 { l.lower + 1e-4 } else { l.upper - 1e-4 };
        }
    }
    let kin = ChainKinematics::new(robot, &q).unwrap();
    let n = q.len();
    // A reachable state: the previous velocity (nearly) keeps the grasp and leaves room to brake
    // before the position limits.
    let raw = DVector::from_fn(n, |i, _| limits[i].max_velocity * rng.range(-0.5, 0.5));
    let pinv = kin.j_r.clone().pseudo_inverse(1e-10).unwrap();
    let along = &raw - &pinv * (&kin.j_r * &raw);
    let qd_prev: Vec<f64> = (0..n)
        .map(|i| {
            let (l, qi) = (&limits[i], q[i]);
            let (a, b) =
                (-braking(qi - l.lower, l.max_acceleration, dt), braking(l.upper - qi, l.max_acceleration, dt));
            along[i].clamp(-l.max_velocity, l.max_velocity).clamp(a.min(0.0), b.max(0.0))
        })
        .collect();
    let scale = rng.range(0.01, 0.5);
    let v_a = Vector6::from_fn(|_, _| rng.normal() * scale);
    // Mostly the drift of one step; sometimes more than the acceleration bound can correct.
    let e_scale = if rng.uniform() < 0.2 { 1e-3 } else { 1e-5 };
    let e_r = Vector6::from_fn(|_, _| rng.normal() * e_scale);
    let count = rng.below(17);
    let dampers = (0..count)
        .map(|_| {
            let a = DVector::from_fn(n, |_, _| rng.normal());
            // Reach of aᵀqd within one step's acceleration; rows from slightly violated at the
            // previous velocity to loose.
            let reach: f64 = (0..n).map(|i| a[i].abs() * limits[i].max_acceleration * dt).sum();
            let b = a.dot(&DVector::from_column_slice(&qd_prev)) + reach * rng.range(-0.3, 1.5);
            VelocityDamper::new(a, b)
        })
        .collect();
    Random { q, limits, qd_prev, kin, v_a, e_r, dampers }
}

/// Fastest approach to a limit `d` ahead that can still stop in time (the controller's bound).
fn braking(d: f64, a: f64, dt: f64) -> f64 {
    if d.is_infinite() {
        return f64::INFINITY;
    }
    let adt = a * dt;
    -adt + (adt * adt + 2.0 * a * d.max(0.0)).sqrt()
}

fn input<'a>(r: &'a Random) -> StepInput<'a> {
    StepInput {
        q: &r.q,
        j_a: &r.kin.j_a,
        j_r: &r.kin.j_r,
        v_a: r.v_a,
        e_r: r.e_r,
        dampers: &r.dampers,
        reference: None,
    }
}

/// The commanded velocity respects the model's limits: speed, acceleration from `qd_prev` and the
/// next position (when the current one is inside its limits).
fn assert_within_limits(qd: &DVector<f64>, q: &[f64], qd_prev: &[f64], limits: &[JointLimits], dt: f64) {
    for i in 0..qd.len() {
        let l = &limits[i];
        assert!(qd[i].abs() <= l.max_velocity + 1e-12, "joint {i}: speed {} > {}", qd[i], l.max_velocity);
        let acc = (qd[i] - qd_prev[i]).abs() / dt;
        assert!(acc <= l.max_acceleration * (1.0 + 1e-9), "joint {i}: acceleration {acc} > {}", l.max_acceleration);
        if q[i] >= l.lower && q[i] <= l.upper {
            let next = q[i] + qd[i] * dt;
            assert!(next >= l.lower - 1e-12 && next <= l.upper + 1e-12, "joint {i}: position {next} leaves limits");
        }
    }
}

#[test]
fn dense_solver_agrees_with_clarabel_on_random_problems() {
    let robot = robot();
    let mut rng = Rng::new(11);
    let dt = 1e-3;
    let (mut compared, mut slacked, mut with_active_bounds, mut with_active_rows, mut infeasible) = (0, 0, 0, 0, 0);
    let mut worst = (0.0f64, 0.0f64);
    for _ in 0..300 {
        let r = random_problem(&robot, &mut rng, dt);
        let config = ClosedChainConfig { dt, ..ClosedChainConfig::default() };
        let mut ctl = ClosedChainController::new(r.limits.clone(), config).unwrap();
        ctl.set_previous_velocity(&r.qd_prev).unwrap();
        match ctl.compare(&input(&r)) {
            Ok(cmp) => {
                let (f, c) = (&cmp.fast, &cmp.reference);
                assert!(!f.fell_back, "dense solver fell back");
                assert_eq!(f.closure, c.closure, "closure modes differ");
                assert!(cmp.qd_difference <= 1e-5, "qd differs by {} (rel.)", cmp.qd_difference);
                assert!(cmp.objective_difference <= 1e-6, "objective differs by {} (rel.)", cmp.objective_difference);
                worst = (worst.0.max(cmp.qd_difference), worst.1.max(cmp.objective_difference));
                let (lo, hi) = ctl.bounds();
                for sol in [f, c] {
                    for i in 0..sol.qd.len() {
                        assert!(sol.qd[i] >= lo[i] && sol.qd[i] <= hi[i], "joint {i} outside the step box");
                    }
                    assert_within_limits(&sol.qd, &r.q, &r.qd_prev, &r.limits, dt);
                    for d in &r.dampers {
                        assert!(d.a.dot(&sol.qd) <= d.b + 1e-7);
                    }
                }
                match f.closure {
                    ClosureMode::Hard => assert!(f.closure_residual < 1e-8, "closure residual {}", f.closure_residual),
                    ClosureMode::Slacked => slacked += 1,
                }
                let tol = 1e-9;
                if (0..f.qd.len()).any(|i| f.qd[i] - lo[i] < tol || hi[i] - f.qd[i] < tol) {
                    with_active_bounds += 1;
                }
                if r.dampers.iter().any(|d| d.b - d.a.dot(&f.qd) < 1e-9) {
                    with_active_rows += 1;
                }
                compared += 1;
            }
            Err(e) => {
                // Both solvers must call it infeasible; neither returns a velocity.
                assert!(matches!(e, ExecutorError::QpInfeasible(_)), "{e}");
                let mut ctl = ClosedChainController::new(r.limits.clone(), config_clarabel(dt)).unwrap();
                ctl.set_previous_velocity(&r.qd_prev).unwrap();
                assert!(matches!(ctl.step(&input(&r)), Err(ExecutorError::QpInfeasible(_))));
                infeasible += 1;
            }
        }
    }
    println!(
        "compared {compared}, slacked {slacked}, active bounds {with_active_bounds}, active rows {with_active_rows}, \
         infeasible {infeasible}, worst qd {:.2e} objective {:.2e}",
        worst.0, worst.1
    );
    assert!(compared >= 200, "only {compared} comparable problems");
    assert!(compared - slacked >= 50 && slacked >= 20, "too few of one closure mode");
    assert!(with_active_bounds >= 50 && with_active_rows >= 50, "too few active constraints exercised");
}

fn config_clarabel(dt: f64) -> ClosedChainConfig {
    ClosedChainConfig { dt, backend: QpBackend::Clarabel, ..ClosedChainConfig::default() }
}

#[test]
fn contradicting_dampers_are_an_error_not_a_velocity() {
    let robot = robot();
    let q = robot.home().to_vec();
    let kin = ChainKinematics::new(&robot, &q).unwrap();
    let n = q.len();
    let mut e0 = DVector::zeros(n);
    e0[0] = 1.0;
    // qd_0 <= -0.01 and -qd_0 <= -0.01: no velocity satisfies both.
    let dampers = [VelocityDamper::new(e0.clone(), -0.01), VelocityDamper::new(-e0, -0.01)];
    for backend in [QpBackend::Dense, QpBackend::Clarabel, QpBackend::ClarabelFresh] {
        let mut ctl = ClosedChainController::new(robot.limits(), ClosedChainConfig::default()).unwrap();
        ctl.set_previous_velocity(&vec![0.001; n]).unwrap();
        let input = StepInput {
            q: &q,
            j_a: &kin.j_a,
            j_r: &kin.j_r,
            v_a: Vector6::zeros(),
            e_r: Vector6::zeros(),
            dampers: &dampers,
            reference: None,
        };
        let err = ctl.step_with(&input, backend).unwrap_err();
        assert!(matches!(err, ExecutorError::QpInfeasible(_)), "{backend:?}: {err}");
        assert_eq!(ctl.previous_velocity().as_slice(), &vec![0.001; n][..], "a failed step changed the state");
    }
}

#[test]
fn bad_inputs_are_errors() {
    let robot = robot();
    let q = robot.home().to_vec();
    let kin = ChainKinematics::new(&robot, &q).unwrap();
    let mut ctl = ClosedChainController::new(robot.limits(), ClosedChainConfig::default()).unwrap();
    let ok = StepInput {
        q: &q,
        j_a: &kin.j_a,
        j_r: &kin.j_r,
        v_a: Vector6::zeros(),
        e_r: Vector6::zeros(),
        dampers: &[],
        reference: None,
    };
    assert!(ctl.step(&ok).is_ok());
    let mut v = Vector6::zeros();
    v[2] = f64::NAN;
    assert!(matches!(ctl.step(&StepInput { v_a: v, ..ok }), Err(ExecutorError::NotFinite { .. })));
    assert!(matches!(ctl.step(&StepInput { q: &q[..5], ..ok }), Err(ExecutorError::DimensionMismatch { .. })));
    let many = vec![VelocityDamper::new(DVector::zeros(q.len()), 1.0); 17];
    assert!(matches!(ctl.step(&StepInput { dampers: &many, ..ok }), Err(ExecutorError::DimensionMismatch { .. })));
    let short = [VelocityDamper::new(DVector::zeros(3), 1.0)];
    assert!(matches!(ctl.step(&StepInput { dampers: &short, ..ok }), Err(ExecutorError::DimensionMismatch { .. })));
    let mut limits = robot.limits();
    limits[3].max_acceleration = f64::NAN;
    assert!(matches!(
        ClosedChainController::new(limits, ClosedChainConfig::default()),
        Err(ExecutorError::InvalidLimits { joint: 3, .. })
    ));
    let cfg = ClosedChainConfig { dt: 0.0, ..ClosedChainConfig::default() };
    assert!(ClosedChainController::new(robot.limits(), cfg).is_err());
}

/// Follow a constant object twist for 500 steps of 1 ms, integrating `q += qd dt`: the grasp
/// stays closed (an initial 2 mm / 2 mrad error is corrected) and the bar moves as commanded.
#[test]
fn drift_correction_keeps_the_grasp_and_the_bar_follows_the_twist() {
    let robot = robot();
    let dt = 1e-3;
    let mut q = robot.home().to_vec();
    let kin0 = ChainKinematics::new(&robot, &q).unwrap();
    // Grasp reference: the relative pose now, shifted so the run starts with an error.
    let offset =
        embodied_models::nalgebra::Isometry3::new(Vector3::new(0.002, 0.0, 0.0), Vector3::new(0.0, 0.0, 0.002));
    let reference = kin0.relative_pose() * offset;
    let start = kin0.absolute_pose();
    let twist = Vector6::new(0.03, 0.0, 0.05, 0.0, 0.0, 0.1);
    let k_a = 10.0;
    let limits = robot.limits();
    let mut ctl =
        ClosedChainController::new(limits.clone(), ClosedChainConfig { dt, ..ClosedChainConfig::default() }).unwrap();
    let e0 = relative_pose_error(&kin0.tool1, &kin0.tool2, &reference);
    let mut worst_late = (0.0f64, 0.0f64);
    let mut prev = vec![0.0; q.len()];
    let mut slacked = 0;
    for step in 0..500 {
        let kin = ChainKinematics::new(&robot, &q).unwrap();
        let t = step as f64 * dt;
        let desired = integrate_pose(&start, &twist, t);
        let v_a = twist + pose_error(&desired, &kin.absolute_pose()) * k_a;
        let e_r = relative_pose_error(&kin.tool1, &kin.tool2, &reference);
        if step >= 250 {
            worst_late =
                (worst_late.0.max(e_r.fixed_rows::<3>(0).norm()), worst_late.1.max(e_r.fixed_rows::<3>(3).norm()));
        }
        let input = StepInput { q: &q, j_a: &kin.j_a, j_r: &kin.j_r, v_a, e_r, dampers: &[], reference: None };
        let sol = ctl.step(&input).unwrap();
        // Starting from rest, the acceleration bound may not allow the full correction at once.
        if sol.closure == ClosureMode::Slacked {
            slacked += 1;
            assert!(step < 100, "still slacked at step {step}");
        }
        assert_within_limits(&sol.qd, &q, &prev, &limits, dt);
        for (qi, v) in q.iter_mut().zip(sol.qd.iter()) {
            *qi += v * dt;
        }
        prev = sol.qd.as_slice().to_vec();
    }
    let kin = ChainKinematics::new(&robot, &q).unwrap();
    let e_end = relative_pose_error(&kin.tool1, &kin.tool2, &reference);
    println!(
        "e_r start {:.2e}, worst in the second half {:?}, end {:.2e}, slacked steps {slacked}",
        e0.norm(),
        worst_late,
        e_end.norm()
    );
    assert!(e0.norm() > 2.5e-3);
    assert!(worst_late.0 < 1e-3 && worst_late.1 < 1e-3, "relative pose error {worst_late:?}");
    assert!(e_end.fixed_rows::<3>(0).norm() < 1e-4 && e_end.fixed_rows::<3>(3).norm() < 1e-4, "{e_end}");
    // The bar followed the commanded twist (acceleration limits make it lag a little at first).
    let desired = integrate_pose(&start, &twist, 500.0 * dt);
    let err = pose_error(&desired, &kin.absolute_pose());
    let moved = (kin.absolute_pose().translation.vector - start.translation.vector).norm();
    println!(
        "absolute error {:.2e} m / {:.2e} rad, moved {moved:.4} m",
        err.fixed_rows::<3>(0).norm(),
        err.fixed_rows::<3>(3).norm()
    );
    assert!(err.fixed_rows::<3>(0).norm() < 2e-3 && err.fixed_rows::<3>(3).norm() < 5e-3, "absolute error {err}");
    assert!((moved - 0.5 * (0.03f64.hypot(0.05))).abs() < 3e-3, "moved {moved}");
}

/// Without an initial error the grasp stays within 1 mm / 1 mrad for the whole run.
#[test]
fn closed_grasp_stays_closed_while_carrying() {
    let robot = robot();
    let dt = 1e-3;
    let mut q = robot.home().to_vec();
    let kin0 = ChainKinematics::new(&robot, &q).unwrap();
    let reference = kin0.relative_pose();
    let twist = Vector6::new(0.0, 0.05, -0.03, 0.05, 0.0, 0.0);
    let mut ctl =
        ClosedChainController::new(robot.limits(), ClosedChainConfig { dt, ..ClosedChainConfig::default() }).unwrap();
    let mut worst = 0.0f64;
    for _ in 0..500 {
        let kin = ChainKinematics::new(&robot, &q).unwrap();
        let e_r = relative_pose_error(&kin.tool1, &kin.tool2, &reference);
        worst = worst.max(e_r.amax());
        let input = StepInput { q: &q, j_a: &kin.j_a, j_r: &kin.j_r, v_a: twist, e_r, dampers: &[], reference: None };
        let sol = ctl.step(&input).unwrap();
        for (qi, v) in q.iter_mut().zip(sol.qd.iter()) {
            *qi += v * dt;
        }
    }
    assert!(worst < 1e-4, "relative pose error reached {worst}");
}

/// A previous speed far above the velocity limit with a small acceleration step (3.82 rad/s
/// against 0.01 rad/s, 1e-5 rad/s per step): `3.82 - 1e-5` rounds 4e-16 away, and the step must
/// still not exceed the acceleration limit as computed.
#[test]
fn hardest_deceleration_never_exceeds_the_acceleration_limit_by_rounding() {
    let (prev, amax, dt) = (3.820_704_946_486_966, 0.1, 1e-4);
    let limits = [JointLimits::new(0.0, 0.01, 0.01, amax)];
    let (mut lo, mut hi) = ([0.0], [0.0]);
    for p in [prev, -prev, 1.0 + 1e-9, 123.456] {
        step_bounds(&[0.0], &[p], &limits, dt, &mut lo, &mut hi);
        assert!(lo[0] <= hi[0]);
        for v in [lo[0], hi[0]] {
            assert!((v - p).abs() <= amax * dt, "{p}: {v} changes by {}", (v - p).abs());
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(500))]

    /// The step box is never empty and never lets speed or acceleration exceed the limits, and
    /// from inside the position limits it keeps the next position inside.
    #[test]
    fn step_bounds_are_never_empty_and_respect_limits(
        lower in -3.0f64..0.0, width in 0.01f64..6.0, frac in -0.1f64..1.1,
        vmax in 0.01f64..3.0, amax in 0.1f64..20.0, prev in -4.0f64..4.0, dt in 1e-4f64..0.02,
    ) {
        let limits = [JointLimits::new(lower, lower + width, vmax, amax)];
        let q = [lower + frac * width];
        let (mut lo, mut hi) = ([0.0], [0.0]);
        step_bounds(&q, &[prev], &limits, dt, &mut lo, &mut hi);
        prop_assert!(lo[0] <= hi[0]);
        for v in [lo[0], hi[0], 0.5 * (lo[0] + hi[0])] {
            // Acceleration always holds; speed holds whenever the previous speed did.
            prop_assert!((v - prev).abs() <= amax * dt * (1.0 + 1e-12));
            if prev.abs() <= vmax {
                prop_assert!(v.abs() <= vmax * (1.0 + 1e-12));
                let inside = q[0] >= limits[0].lower && q[0] <= limits[0].upper;
                // From a state that respected the braking bound, the next position stays inside.
                let brake = |d: f64| {
                    let adt = amax * dt;
                    -adt + (adt * adt + 2.0 * amax * d.max(0.0)).sqrt()
                };
                let braking_ok = prev <= brake(limits[0].upper - q[0]) && prev >= -brake(q[0] - limits[0].lower);
                if inside && braking_ok {
                    let next = q[0] + v * dt;
                    prop_assert!(next >= limits[0].lower - 1e-12 && next <= limits[0].upper + 1e-12);
                }
            }
        }
    }

    /// Moving along the braking bound and then braking as hard as allowed never crosses the limit.
    #[test]
    fn braking_bound_is_invariant(d in 0.0f64..1.0, vmax in 0.05f64..3.0, amax in 0.1f64..20.0, dt in 1e-4f64..0.02) {
        let limits = [JointLimits::new(-10.0, 0.0, vmax, amax)];
        let mut q = -d;
        let mut qd = 0.0;
        // Accelerate toward the upper limit as fast as the box allows, for as long as it allows.
        for _ in 0..20_000 {
            let (mut lo, mut hi) = ([0.0], [0.0]);
            step_bounds(&[q], &[qd], &limits, dt, &mut lo, &mut hi);
            prop_assert!(lo[0] <= hi[0]);
            prop_assert!((hi[0] - qd).abs() <= amax * dt * (1.0 + 1e-9));
            qd = hi[0];
            q += qd * dt;
            prop_assert!(q <= 1e-12, "crossed the limit: q = {}", q);
        }
    }
}
