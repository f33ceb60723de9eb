//! The simulated effector, behind its safety limiter, never exceeds position, velocity or
//! acceleration limits, whatever it is commanded.

use embodied_executor::*;
use proptest::prelude::*;

fn value() -> impl Strategy<Value = f64> {
    prop_oneof![
        8 => -20.0..20.0f64,
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(-1e9),
    ]
}

fn command(dof: usize) -> impl Strategy<Value = JointCommand> {
    (any::<bool>(), prop::collection::vec(value(), dof), prop::collection::vec(value(), dof)).prop_map(
        |(velocity, q, qd)| JointCommand {
            mode: if velocity { CommandMode::Velocity } else { CommandMode::Position },
            q,
            qd,
        },
    )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    #[test]
    fn limits_are_never_exceeded(
        robot_name in prop::sample::select(vec!["rnt", "polycrank", "irp6-postument", "irp6-on-track"]),
        seed in any::<u64>(),
        plan in prop::collection::vec((command(8), 1usize..200), 1..8),
    ) {
        let robot = embodied_models::builtin(robot_name).expect("built-in");
        let limits = robot.limits();
        let dof = robot.dof();
        let mut rng = embodied_models::Rng::new(seed);
        let q0 = robot.random_configuration(&mut rng);
        let mut effector = SafetyLimiter::new(ServoModel::new(limits.clone(), &q0).expect("servo"));
        let dt = 0.001;
        let mut prev = effector.qd().to_vec();
        for (mut cmd, repeat) in plan {
            cmd.q.truncate(dof);
            cmd.qd.truncate(dof);
            for _ in 0..repeat {
                effector.execute(&cmd, dt);
                for i in 0..dof {
                    let (q, v, l) = (effector.q()[i], effector.qd()[i], &limits[i]);
                    prop_assert!(q >= l.lower && q <= l.upper, "{robot_name} joint {i}: q = {q} outside [{}, {}]", l.lower, l.upper);
                    prop_assert!(v.abs() <= l.max_velocity * (1.0 + 1e-12), "joint {i}: |qd| = {} > {}", v.abs(), l.max_velocity);
                    prop_assert!((v - prev[i]).abs() <= l.max_acceleration * dt * (1.0 + 1e-9) + 1e-12,
                        "joint {i}: acceleration {} > {}", (v - prev[i]).abs() / dt, l.max_acceleration);
                    prop_assert!(q.is_finite() && v.is_finite());
                }
                prev.copy_from_slice(effector.qd());
            }
        }
    }

    #[test]
    fn the_limiter_alone_produces_feasible_commands(
        seed in any::<u64>(),
        cmd in command(6),
    ) {
        let robot = embodied_models::builtin("rnt").expect("built-in");
        let limits = robot.limits();
        let mut rng = embodied_models::Rng::new(seed);
        let q0 = robot.random_configuration(&mut rng);
        let limiter = SafetyLimiter::new(ServoModel::new(limits.clone(), &q0).expect("servo"));
        let mut out = JointCommand::hold(&q0);
        limiter.limit_into(&cmd, 0.001, &mut out);
        for i in 0..6 {
            let (lo, hi) = velocity_window(q0[i], 0.0, &limits[i], 0.001);
            prop_assert!(out.qd[i] >= lo && out.qd[i] <= hi);
            prop_assert!(out.q[i] >= limits[i].lower && out.q[i] <= limits[i].upper);
        }
    }

    /// The limiter-fed shortcut of the servo (`execute_limited`) moves the joints exactly as the
    /// full tracking law would for the same limited command.
    #[test]
    fn the_servo_shortcut_matches_the_full_tracking_law(
        robot_name in prop::sample::select(vec!["rnt", "polycrank", "irp6-postument"]),
        seed in any::<u64>(),
        warm_up in command(8),
        cmd in command(8),
    ) {
        let robot = embodied_models::builtin(robot_name).expect("built-in");
        let (limits, dof) = (robot.limits(), robot.dof());
        let mut rng = embodied_models::Rng::new(seed);
        let q0 = robot.random_configuration(&mut rng);
        let mut warm_up = warm_up;
        warm_up.q.truncate(dof);
        warm_up.qd.truncate(dof);
        let mut cmd = cmd;
        cmd.q.truncate(dof);
        cmd.qd.truncate(dof);
        let dt = 0.001;
        // Bring the servo to a moving state first.
        let mut limiter = SafetyLimiter::new(ServoModel::new(limits.clone(), &q0).expect("servo"));
        for _ in 0..20 {
            limiter.execute(&warm_up, dt);
        }
        let mut limited = JointCommand::hold(limiter.q());
        limiter.limit_into(&cmd, dt, &mut limited);
        let (mut full, mut short) = (limiter.inner().clone(), limiter.inner().clone());
        full.execute(&limited, dt);
        short.execute_limited(&limited, dt);
        for i in 0..dof {
            prop_assert!((full.q()[i] - short.q()[i]).abs() <= 1e-12, "joint {i}: q {} vs {}", full.q()[i], short.q()[i]);
            prop_assert!((full.qd()[i] - short.qd()[i]).abs() <= 1e-9, "joint {i}: qd {} vs {}", full.qd()[i], short.qd()[i]);
        }
    }
}
