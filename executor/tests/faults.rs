//! The executor's side of injected faults: link faults keep a channel in order, the obstacle
//! sensor reports news first, a healthy effector follows its limited command exactly and one
//! that does not is seen.

use embodied_executor::deliberation::UnmappedObstacle;
use embodied_executor::*;
use embodied_models::JointLimits;

/// Delays messages sent in steps 0..=2 by 5 steps, loses those sent in step 3.
struct Faulty;

impl LinkFaults for Faulty {
    fn transit(&mut self, _: AgentId, _: AgentId, step: u64) -> Transit {
        match step {
            0..=2 => Transit::Deliver { extra: 5 },
            3 => Transit::Lose,
            _ => Transit::Deliver { extra: 0 },
        }
    }
}

#[test]
fn a_delayed_message_is_never_overtaken_and_a_lost_one_never_arrives() {
    let (a, b) = (AgentId(0), AgentId(1));
    let mut t = Transmitter::new();
    t.connect(a, b, Link::IDEAL, 1);
    t.set_faults(Box::new(Faulty));
    for step in 0..6 {
        let message = Message::new(step as u32, &[]);
        assert!(t.send(Envelope { from: a, to: b, message }, step));
    }
    let mut got = Vec::new();
    for step in 0..20 {
        t.deliver(step, |_, env| got.push((step, env.message.tag().unwrap_or(99))));
    }
    // Sent at 0, 1, 2: due at 6, 7, 8; 3 lost; 4 and 5 (due at 5 and 6) wait behind them.
    assert_eq!(got, vec![(6, 0), (7, 1), (8, 2), (8, 4), (8, 5)]);
    let stats = t.stats(a, b).unwrap();
    assert_eq!((stats.sent, stats.lost, stats.delivered), (6, 1, 5));
}

fn echo(id: usize, position: [f64; 3], distance: f64) -> ObstacleEcho {
    ObstacleEcho { id, agent: None, position, distance }
}

#[test]
fn the_obstacle_sensor_reports_a_new_obstacle_before_the_nearest() {
    let mut sensor = UnmappedObstacle::new(vec![], false);
    let config = SensorConfig::default();
    let mut r = ReceptorReadings { obstacles: vec![echo(0, [0.5, 0.0, 0.0], 0.1)], ..Default::default() };
    assert_eq!(sensor.aggregate(&config, &r).as_slice()[4], 0.0);
    assert_eq!(sensor.aggregate(&config, &r).as_slice()[4], 0.0);
    // A farther obstacle appears: news, reported at once; then the nearest again.
    r.obstacles.push(echo(1, [1.5, 0.0, 0.0], 1.0));
    assert_eq!(sensor.aggregate(&config, &r).as_slice()[4], 1.0);
    assert_eq!(sensor.aggregate(&config, &r).as_slice()[4], 0.0);
    // The far one moves by more than the tolerance: news again.
    r.obstacles[1].position[1] += 2.0 * embodied_executor::deliberation::sensing::NEWS_TOLERANCE;
    assert_eq!(sensor.aggregate(&config, &r).as_slice()[4], 1.0);
    assert_eq!(sensor.aggregate(&config, &r).as_slice()[4], 0.0);
}

#[test]
fn a_healthy_effector_is_exactly_where_its_limited_command_asked() {
    let limits = vec![JointLimits::new(-1.0, 1.0, 1.0, 10.0); 2];
    let mut e = SafetyLimiter::new(ServoModel::new(limits.clone(), &[0.0, 0.0]).unwrap());
    assert!(e.commanded_position().is_none());
    let dt = 0.001;
    for k in 0..2000 {
        // Targets far off and moving: the limiter clamps into the limits every step.
        let t = k as f64 * dt;
        let c = JointCommand { mode: CommandMode::Position, q: vec![(5.0 * t).sin(), -2.0], qd: vec![0.0, 0.0] };
        e.execute(&c, dt);
        let asked = e.commanded_position().unwrap().to_vec();
        for j in 0..2 {
            assert!((e.q()[j] - asked[j]).abs() <= 1e-12, "step {k} joint {j}");
            assert!(tracking_bound(&limits[j], dt) >= 1e-6);
        }
    }
}
