//! The safety limiter keeps the screws that drive joints within their speed limits: a command
//! that would drive a screw too fast is scaled down as a whole.
#![allow(clippy::unwrap_used)]

use embodied_executor::*;

#[test]
fn the_limiter_scales_a_command_that_would_drive_a_screw_too_fast() {
    let robot = embodied_models::builtin("rnt").unwrap();
    let mut q0 = robot.home().to_vec();
    q0[1] = -1.8;
    let servo = ServoModel::new(robot.limits(), &q0).unwrap();
    let mut e = SafetyLimiter::new(servo).with_actuators(robot.actuators().to_vec());
    let dt = 0.001;
    // J2 and J3 at their joint limits' speed (0.5 rad/s), for 0.6 s.
    let mut wanted = vec![0.0; q0.len()];
    wanted[1] = 0.5;
    wanted[2] = 0.5;
    let mut peak = (0.0_f64, 0.0_f64);
    for _ in 0..600 {
        let command = JointCommand { mode: CommandMode::Velocity, q: e.q().to_vec(), qd: wanted.clone() };
        let q_before = e.q().to_vec();
        e.execute(&command, dt);
        // The screws' speeds at the configuration the limiter saw, with the velocity it let through.
        let ratio = robot.actuator_speed_ratio(&q_before, e.qd());
        assert!(ratio <= 1.0 + 1e-9, "ratio {ratio}");
        peak.0 = peak.0.max(ratio);
        peak.1 = peak.1.max(e.qd()[1]);
        for (v, l) in e.qd().iter().zip(robot.limits()) {
            assert!(v.abs() <= l.max_velocity + 1e-12);
        }
    }
    assert!(peak.0 > 0.99, "a screw reached its limit: {peak:?}");
    assert!(peak.1 < 0.49, "the joints were slowed: {peak:?}");
    // Without the screws, the same commands run the joints at their own limit.
    let servo = ServoModel::new(robot.limits(), &q0).unwrap();
    let mut plain = SafetyLimiter::new(servo);
    for _ in 0..600 {
        let command = JointCommand { mode: CommandMode::Velocity, q: plain.q().to_vec(), qd: wanted.clone() };
        plain.execute(&command, dt);
    }
    assert!((plain.qd()[1] - 0.5).abs() < 1e-9, "{}", plain.qd()[1]);
}
