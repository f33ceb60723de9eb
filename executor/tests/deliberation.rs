//! Deliberation in the loop: faults end in a safe halt with the log intact, late plans halt
//! and resume, stale plans are discarded, obstacles trigger replanning, runs replay.

use std::sync::Arc;
use std::sync::atomic::{AtomicU32, Ordering};

use embodied_executor::deliberation::*;
use embodied_executor::*;
use embodied_models::{CollisionModel, Environment, Robot};
use embodied_planner::deadline::Deadline;
use embodied_planner::motion::{Goal, MotionSettings};
use embodied_planner::trajectory::time_parameterize;

// Collision-free under the current RNT geometry (the rnt-polish scenario's start and goal are
// not: see the report).
const START: [f64; 6] = [-0.5, -1.4, -1.0, 0.0, 0.3, 0.0];
const GOAL: [f64; 6] = [0.8, -1.2, -1.2, 0.0, 0.5, 0.0];

fn robot() -> Arc<Robot> {
    Arc::new(embodied_models::builtin("rnt").expect("built-in robot"))
}

fn simulated() -> DeliberationSettings {
    DeliberationSettings {
        clock: PlanClock::Simulated { steps_per_unit: 0.01, fixed_steps: 5 },
        budget: PlanBudget { steps: 200, wall: None, give_up_steps: None, work: None },
        retry_after_steps: 50,
        ..DeliberationSettings::default()
    }
}

fn goal() -> Goal {
    Goal::Configuration(GOAL.to_vec())
}

/// A test-double planner that ignores obstacles: a straight line, time-parameterised within limits.
fn straight_line(robot: &Robot) -> impl Fn(&PlanRequest, &Deadline) -> Result<Planned, PlanFailure> + use<> {
    let robot = robot.clone();
    move |r: &PlanRequest, _: &Deadline| {
        let Goal::Configuration(g) = &r.goal else { return Err(PlanFailure::Error("configuration goals only".into())) };
        let trajectory = time_parameterize(&[r.start.clone(), g.clone()], &robot, r.dt);
        Ok(Planned { trajectory, work: 100 })
    }
}

fn run(runtime: &mut Runtime, steps: u64) -> Vec<StepRecord> {
    let mut records = Vec::new();
    let result = runtime.run(steps, |r| records.push(r.clone()));
    assert!(result.is_ok(), "run failed: {result:?}");
    records
}

fn events(records: &[StepRecord]) -> Vec<(u64, String)> {
    records.iter().flat_map(|r| r.agents[0].events.iter().map(move |e| (r.step, e.to_string()))).collect()
}

fn first(records: &[StepRecord], prefix: &str) -> Option<u64> {
    events(records).into_iter().find(|(_, e)| e.starts_with(prefix)).map(|(s, _)| s)
}

/// The log is complete, every state within the limits, and the agent ends at rest.
fn assert_safe(records: &[StepRecord], steps: u64, robot: &Robot) {
    assert_eq!(records.len() as u64, steps, "one record per step");
    for (k, r) in records.iter().enumerate() {
        assert_eq!(r.step, k as u64);
    }
    let limits = robot.limits();
    let dt = 0.001;
    for w in records.windows(2) {
        let (a, b) = (&w[0].agents[0], &w[1].agents[0]);
        for (j, l) in limits.iter().enumerate() {
            assert!(b.q[j] >= l.lower - 1e-9 && b.q[j] <= l.upper + 1e-9, "position bound, joint {j}");
            assert!(b.qd[j].abs() <= l.max_velocity + 1e-9, "velocity bound, joint {j}");
            assert!(
                (b.qd[j] - a.qd[j]).abs() / dt <= l.max_acceleration * (1.0 + 1e-6) + 1e-6,
                "acceleration, joint {j}"
            );
        }
    }
    let last = &records[records.len() - 1].agents[0];
    // At rest up to floating-point rounding of the position loop.
    assert!(last.qd.iter().all(|v| v.abs() < 1e-9), "ends at rest: {:?}", last.qd);
}

fn env_agent(settings: DeliberationSettings, env: Environment) -> Agent<DeliberativeState> {
    let robot = robot();
    let collision = CollisionModel::new(&robot, env);
    deliberative_agent("arm", robot, collision, &START, goal(), settings).expect("agent")
}

fn runtime_with(agent: Agent<DeliberativeState>) -> Runtime {
    let mut rt = Runtime::new(RuntimeConfig { seed: 3, ..RuntimeConfig::default() });
    rt.add_agent(agent);
    rt
}

#[test]
fn plans_and_reaches_the_goal() {
    let mut rt = runtime_with(env_agent(simulated(), Environment::new()));
    let records = run(&mut rt, 6000);
    assert!(first(&records, "plan_requested id=1").is_some());
    assert!(first(&records, "plan_landed id=1 world=0 in_time").is_some(), "{:?}", events(&records));
    assert!(first(&records, "goal_reached").is_some(), "{:?}", events(&records));
    let last = &records[records.len() - 1].agents[0];
    for (q, g) in last.q.iter().zip(GOAL) {
        assert!((q - g).abs() < 1e-3, "{:?}", last.q);
    }
    assert_safe(&records, 6000, &robot());
}

#[test]
fn wall_clock_mode_never_blocks_and_reaches_the_goal() {
    let settings = DeliberationSettings {
        // The step budget is wide: simulated steps outrun a loaded machine's planner thread, and this
        // test is about never blocking, not about the budget.
        budget: PlanBudget {
            steps: 150_000,
            wall: Some(std::time::Duration::from_secs(5)),
            give_up_steps: None,
            work: None,
        },
        ..DeliberationSettings::default()
    };
    let mut rt = runtime_with(env_agent(settings, Environment::new()));
    let mut records = Vec::new();
    // Step until the plan lands (the runtime keeps producing records meanwhile).
    for _ in 0..200_000 {
        let rec = rt.step().expect("step").clone();
        let done = rec.agents[0].events.iter().any(|e| matches!(e, embodied_executor::Event::GoalReached { .. }));
        records.push(rec);
        if done {
            break;
        }
    }
    // Under load the first plan may come late and be superseded by a second request.
    assert!(first(&records, "plan_landed id=").is_some(), "{:?}", events(&records));
    assert!(first(&records, "goal_reached").is_some(), "{:?}", events(&records));
}

fn midway_fault_agent(sensor: impl VirtualSensor + 'static, config: SensorConfig) -> Agent<DeliberativeState> {
    let robot = robot();
    let collision = CollisionModel::new(&robot, Environment::new());
    let settings = DeliberationSettings { obstacle_sensing: Some(f64::INFINITY), ..simulated() };
    let state = DeliberativeState::new(robot.clone(), collision, goal(), settings);
    Agent::embodied("arm", robot, Some(&START), state, PlanFollower::new("deliberative"))
        .expect("agent")
        .with_sensor(sensor, config)
}

#[test]
fn nan_sensor_reading_halts_safely() {
    let calls = AtomicU32::new(0);
    let sensor = move |_: &SensorConfig, _: &ReceptorReadings| {
        if calls.fetch_add(1, Ordering::Relaxed) < 600 { Reading::new(&[]) } else { Reading::new(&[f64::NAN; 5]) }
    };
    let mut rt = runtime_with(midway_fault_agent(sensor, SensorConfig::default()));
    let records = run(&mut rt, 3000);
    let fault = first(&records, "sensor_non_finite").expect("fault event");
    assert_eq!(fault, 600);
    assert!(first(&records, "plan_landed").is_some_and(|s| s < fault), "moving when the fault comes");
    assert!(first(&records, "halt_started").is_some_and(|s| s == fault));
    assert!(first(&records, "halt_finished").is_some_and(|s| s > fault));
    assert!(first(&records, "goal_reached").is_none());
    assert_safe(&records, 3000, &robot());
}

#[test]
fn silent_sensor_halts_safely() {
    // Read once at step 0, then not for 100000 steps: the sensor stops delivering.
    let config = SensorConfig { period: 100_000, ..SensorConfig::default() };
    let mut rt = runtime_with(midway_fault_agent(NearestObstacle, config));
    let records = run(&mut rt, 3000);
    let fault = first(&records, "sensor_silent").expect("fault event");
    assert_eq!(fault, 51);
    assert!(first(&records, "plan_landed").is_some_and(|s| s < fault), "moving when the sensor falls silent");
    assert_eq!(first(&records, "halt_started"), Some(fault));
    assert!(first(&records, "goal_reached").is_none(), "no plan is followed without the sensor");
    assert_safe(&records, 3000, &robot());
}

fn injected(planner: impl MotionPlanner + 'static, env: Environment) -> Agent<DeliberativeState> {
    let settings = DeliberationSettings { planner: Some(Arc::new(planner)), max_attempts: 2, ..simulated() };
    env_agent(settings, env)
}

#[test]
fn planner_panic_halts_safely() {
    let planner = |_: &PlanRequest, _: &Deadline| -> Result<Planned, PlanFailure> { panic!("planner bug") };
    let mut rt = runtime_with(injected(planner, Environment::new()));
    let records = run(&mut rt, 1000);
    assert!(first(&records, "planner_panicked id=1: planner bug").is_some(), "{:?}", events(&records));
    assert!(first(&records, "planner_panicked id=2").is_some(), "retried");
    assert!(first(&records, "plan_abandoned").is_some());
    assert!(records.iter().all(|r| r.agents[0].q.iter().zip(START).all(|(a, b)| (a - b).abs() < 1e-12)));
    assert_safe(&records, 1000, &robot());
}

#[test]
fn limit_violating_plan_is_rejected() {
    // The straight line played twice as fast: twice the velocity limit, four times the
    // acceleration limit.
    let line = straight_line(&robot());
    let planner = move |r: &PlanRequest, d: &Deadline| {
        let mut p = line(r, d)?;
        p.trajectory.t.iter_mut().for_each(|t| *t /= 2.0);
        p.trajectory.qd.iter_mut().flatten().for_each(|v| *v *= 2.0);
        Ok(p)
    };
    let mut rt = runtime_with(injected(planner, Environment::new()));
    let records = run(&mut rt, 1000);
    let ev = events(&records);
    assert!(ev.iter().any(|(_, e)| e.starts_with("plan_rejected id=1") && e.contains("exceeds")), "{ev:?}");
    assert!(first(&records, "plan_landed").is_none());
    assert_safe(&records, 1000, &robot());
}

/// An obstacle on the straight line from START to GOAL (at the tool point halfway), clear of
/// both ends.
fn obstacle_midway(robot: &Robot, radius: f64) -> [f64; 3] {
    let mid: Vec<f64> = START.iter().zip(GOAL).map(|(a, b)| 0.5 * (a + b)).collect();
    let p = robot.end_effector_poses(&mid, 0).1.translation.vector;
    for end in [&START, &GOAL] {
        let e = robot.end_effector_poses(end, 0).1.translation.vector;
        assert!((e - p).norm() > radius + 0.05, "test setup: the obstacle must be clear of the ends");
    }
    [p.x, p.y, p.z]
}

#[test]
fn colliding_plan_is_rejected() {
    let robot = robot();
    let c = obstacle_midway(&robot, 0.08);
    let env = Environment::new().with(embodied_models::Obstacle::new(
        "ball",
        nalgebra::Isometry3::translation(c[0], c[1], c[2]),
        embodied_models::Shape::Sphere { radius: 0.08 },
    ));
    let mut rt = runtime_with(injected(straight_line(&robot), env));
    let records = run(&mut rt, 1000);
    let ev = events(&records);
    assert!(
        ev.iter().any(|(_, e)| e.starts_with("plan_rejected id=1") && e.contains("collide") && e.contains("ball")),
        "{ev:?}"
    );
    assert!(first(&records, "plan_landed").is_none());
    assert_safe(&records, 1000, &robot);
}

#[test]
fn lost_transmission_times_out_and_replans() {
    // Built by hand to reach the deliberator before the run.
    let robot = robot();
    let collision = CollisionModel::new(&robot, Environment::new());
    let settings = DeliberationSettings { plan_timeout_steps: 300, ..simulated() };
    let mut state = DeliberativeState::new(robot.clone(), collision, goal(), settings);
    state.deliberator.lose_next_deliveries(1);
    let agent = Agent::embodied("arm", robot.clone(), Some(&START), state, PlanFollower::new("d")).expect("agent");
    let mut rt = runtime_with(agent);
    let records = run(&mut rt, 6000);
    assert!(first(&records, "plan_late id=1").is_some(), "{:?}", events(&records));
    assert!(first(&records, "plan_lost id=1").is_some());
    assert!(first(&records, "plan_landed id=2").is_some());
    assert!(first(&records, "goal_reached").is_some());
    assert_safe(&records, 6000, &robot);
}

#[test]
fn zero_deadline_delivers_nothing_and_halts() {
    for clock in [PlanClock::WallClock, PlanClock::Simulated { steps_per_unit: 0.01, fixed_steps: 0 }] {
        let settings = DeliberationSettings {
            clock,
            budget: PlanBudget::hard(0, 0.001),
            retry_after_steps: 20,
            ..DeliberationSettings::default()
        };
        let mut rt = runtime_with(env_agent(settings, Environment::new()));
        let mut records = Vec::new();
        for _ in 0..500 {
            records.push(rt.step().expect("step").clone());
            std::thread::sleep(std::time::Duration::from_micros(50));
        }
        assert!(first(&records, "plan_late id=1").is_some_and(|s| s == 0));
        assert!(first(&records, "halt_started").is_some());
        assert!(first(&records, "plan_landed").is_none(), "{clock:?}: {:?}", events(&records));
        assert!(first(&records, "plan_failed id=1").is_some(), "{clock:?}: {:?}", events(&records));
        assert_safe(&records, 500, &robot());
    }
}

/// The motion planner, but reporting `extra` more work units (a slow planner in simulated time).
fn slow_planner(extra: u64) -> impl MotionPlanner {
    let robot = robot();
    let planner = PlanMotion::new(CollisionModel::new(&robot, Environment::new()), MotionSettings::default());
    move |r: &PlanRequest, d: &Deadline| {
        let mut p = planner.plan(r, d)?;
        p.work += extra;
        Ok(p)
    }
}

#[test]
fn late_plan_halts_then_resumes_when_it_lands() {
    let settings = DeliberationSettings {
        planner: Some(Arc::new(slow_planner(20_000))),
        budget: PlanBudget { steps: 50, wall: None, give_up_steps: None, work: None },
        ..simulated()
    };
    let mut rt = runtime_with(env_agent(settings, Environment::new()));
    let records = run(&mut rt, 6000);
    let late = first(&records, "plan_late id=1").expect("late");
    assert_eq!(late, 50);
    assert!(first(&records, "halt_started").is_some_and(|s| s == late));
    let ready = first(&records, "plan_landed id=1 world=0 late").expect("lands late");
    assert!(ready > 200 && ready < 300, "{ready}");
    // At rest until it lands, then moving.
    assert!(records[..ready as usize].iter().all(|r| r.agents[0].qd.iter().all(|v| *v == 0.0)));
    assert!(first(&records, "goal_reached").is_some());
    assert_safe(&records, 6000, &robot());
}

#[test]
fn plan_for_an_old_world_is_discarded() {
    let settings = DeliberationSettings {
        planner: Some(Arc::new(slow_planner(10_000))),
        budget: PlanBudget { steps: 500, wall: None, give_up_steps: None, work: None },
        obstacle_sensing: Some(f64::INFINITY),
        ..simulated()
    };
    let mut rt = runtime_with(env_agent(settings, Environment::new()));
    // Far away: it changes the world model but blocks nothing.
    rt.world_mut().add_obstacle(Obstacle { appears_at: 20, ..Obstacle::fixed("far", [10.0, 10.0, 10.0], 0.1) });
    let records = run(&mut rt, 6000);
    assert_eq!(first(&records, "world_changed version=1"), Some(20));
    let stale = first(&records, "plan_discarded id=1").expect("stale plan discarded");
    assert!(first(&records, "plan_requested id=2 world=1").is_some_and(|s| s >= stale));
    assert!(first(&records, "plan_landed id=1").is_none(), "the stale plan is never followed");
    assert!(first(&records, "plan_landed id=2 world=1").is_some());
    assert!(first(&records, "goal_reached").is_some());
    assert_safe(&records, 6000, &robot());
}

#[test]
fn obstacle_entering_the_path_halts_and_replans() {
    let robot = robot();
    let c = obstacle_midway(&robot, 0.05);
    let settings = DeliberationSettings { obstacle_sensing: Some(f64::INFINITY), ..simulated() };
    let mut rt = runtime_with(env_agent(settings, Environment::new()));
    rt.world_mut().add_obstacle(Obstacle { appears_at: 400, ..Obstacle::fixed("intruder", c, 0.05) });
    let records = run(&mut rt, 12_000);
    let ev = events(&records);
    assert!(first(&records, "plan_landed id=1").is_some_and(|s| s < 400), "{ev:?}");
    assert_eq!(first(&records, "world_changed version=1"), Some(400));
    assert_eq!(first(&records, "plan_invalidated id=1: obstacle_in_path"), Some(400), "{ev:?}");
    let halt = first(&records, "halt_started reason=no_valid_plan speed=").expect("halt while moving");
    assert_eq!(halt, 400);
    let done = first(&records, "halt_finished").expect("halt ends");
    assert!(first(&records, "plan_requested id=2 world=1").is_some_and(|s| s >= done));
    // Whatever the replan gives, nothing from the old world is followed after the change.
    assert!(!ev.iter().any(|(s, e)| *s > 400 && e.starts_with("plan_landed") && e.contains("world=0")));
    assert_safe(&records, 12_000, &robot);
}

#[test]
fn avoidance_reaction_suppresses_the_plan_follower() {
    let robot = robot();
    let collision = CollisionModel::new(&robot, Environment::new());
    let settings = DeliberationSettings { obstacle_sensing: Some(f64::INFINITY), ..simulated() };
    let state = DeliberativeState::new(robot.clone(), collision, goal(), settings);
    let near = Predicate::new("obstacle-near", |_: &DeliberativeState, i: &InputImages| {
        let r = i.sensor(0);
        r.len >= 5 && r.values[0] < 0.3
    });
    let avoid = Primitive::new("avoid", 1, SafeHalt);
    let program = Reactive::priority("main").rule(near, avoid).main_reaction(PlanFollower::new("deliberative"));
    let agent = Agent::embodied("arm", robot.clone(), Some(&START), state, program)
        .expect("agent")
        .with_sensor(NearestObstacle, SensorConfig::default())
        .with_receptors(ReceptorSpec { detector_range: Some(f64::INFINITY), ..ReceptorSpec::default() });
    let mut rt = runtime_with(agent);
    let tool = robot.end_effector_poses(&START, 0).1.translation.vector;
    rt.world_mut().add_obstacle(Obstacle {
        appears_at: 300,
        vanishes_at: Some(1500),
        ..Obstacle::fixed("visitor", [tool.x + 0.25, tool.y, tool.z], 0.02)
    });
    let records = run(&mut rt, 8000);
    assert_eq!(records[300].agents[0].behaviour, "main/avoid");
    assert!(records[1600].agents[0].behaviour.starts_with("main/deliberative"));
    assert!(first(&records, "plan_suspended").is_some_and(|s| s >= 1500), "{:?}", events(&records));
    assert!(first(&records, "goal_reached").is_some(), "{:?}", events(&records));
    assert_safe(&records, 8000, &robot);
}

#[test]
fn simulated_clock_replays_bit_for_bit() {
    let log = || {
        let settings = DeliberationSettings { obstacle_sensing: Some(f64::INFINITY), ..simulated() };
        let mut rt = runtime_with(env_agent(settings, Environment::new()));
        rt.world_mut().add_obstacle(Obstacle { appears_at: 500, ..Obstacle::fixed("far", [5.0, 0.0, 0.0], 0.1) });
        let records = run(&mut rt, 4000);
        records.iter().map(|r| serde_json::to_string(r).expect("json")).collect::<Vec<_>>().join("\n")
    };
    let (a, b) = (log(), log());
    assert!(a.contains("plan_landed"));
    assert_eq!(a, b);
}

/// A keyframe plan from `qa` to `qb`: two samples, at rest at both, slow enough for every
/// velocity limit (the straight segment between them is the plan's path).
fn keyframe(robot: &Robot, qa: &[f64], qb: &[f64]) -> embodied_planner::trajectory::Trajectory {
    let space = robot.config_space();
    let t = robot
        .limits()
        .iter()
        .enumerate()
        .map(|(i, l)| 2.0 * space.delta(i, qa[i], qb[i]).abs() / l.max_velocity)
        .fold(0.1, f64::max);
    embodied_planner::trajectory::Trajectory {
        joint_names: robot.joint_names(),
        t: vec![0.0, t],
        q: vec![qa.to_vec(), qb.to_vec()],
        qd: vec![vec![0.0; qa.len()]; 2],
    }
}

/// A small sphere that the robot's outermost surface grazes halfway between two configurations
/// that the sampled check at 0.01 rad looks at, while `START` turns 0.4 rad about the base: the
/// segment collides (by 0.2 mm) but no checked sample does. Found by placing the sphere against
/// each link's surface, on the side away from the base axis, and keeping the first placement
/// that the sampled check misses.
fn grazing_case(robot: &Robot) -> Option<(Environment, Vec<f64>, Vec<f64>)> {
    use embodied_models::collision::{Obstacle, shape_separation};
    use embodied_models::nalgebra::{Isometry3, Point3, Vector3};
    use embodied_planner::verify::Verifier;
    let (qa, mut qb) = (START.to_vec(), START.to_vec());
    qb[0] += 0.4;
    let space = robot.config_space();
    let plain = CollisionModel::new(robot, Environment::new());
    let plan = keyframe(robot, &qa, &qb);
    let probe = embodied_models::Shape::sphere(0.005);
    for k in [20, 10, 30, 5, 35, 15, 25] {
        let qm = space.interpolate(&qa, &qb, (k as f64 + 0.5) / 40.0);
        let fk = robot.forward_kinematics(&qm);
        let shapes = plain.link_shapes_world(&qm);
        for frame in &fk {
            let p = frame.translation.vector;
            let radial = Vector3::new(p.x, p.y, 0.0);
            if radial.norm() < 0.05 {
                continue;
            }
            let c0 = Point3::from(p + radial.normalize() * 0.5);
            let at = Isometry3::translation(c0.x, c0.y, c0.z);
            let Some(sep) = shapes
                .iter()
                .map(|o| shape_separation(&probe, &at, &o.shape, &o.pose))
                .min_by(|a, b| a.distance.total_cmp(&b.distance))
            else {
                continue;
            };
            let dir = (sep.point_b - sep.point_a).normalize();
            let c = c0 + dir * (sep.distance + 2e-4);
            let env =
                Environment::new().with(Obstacle::new("sliver", Isometry3::translation(c.x, c.y, c.z), probe.clone()));
            let model = CollisionModel::new(robot, env.clone());
            if model.collides(&qm)
                && !model.collides(&qa)
                && !model.collides(&qb)
                && Verifier::sampled(0.01).verify_trajectory(&model, &plan).is_ok()
            {
                return Some((env, qa, qb));
            }
        }
    }
    None
}

#[test]
fn online_gate_certifies_and_refuses_a_plan_the_sampled_check_passes() {
    use embodied_planner::verify::{Finding, Mode, Verifier};
    let robot = robot();
    assert!(
        matches!(DeliberationSettings::default().plan_check.mode, Mode::Certified { .. }),
        "the gate certifies by default"
    );
    let (env, qa, qb) = grazing_case(&robot).expect("a placement the sampled check misses");
    let model = CollisionModel::new(&robot, env.clone());
    let plan = keyframe(&robot, &qa, &qb);
    // The segment really collides: a dense walk finds it.
    let space = robot.config_space();
    assert!((0..=20_000).any(|s| model.collides(&space.interpolate(&qa, &qb, s as f64 / 20_000.0))));
    // The sampled check at the old gate's resolution passes it; the certificate does not.
    assert!(Verifier::sampled(0.01).verify_trajectory(&model, &plan).is_ok());
    match Verifier::default().verify_trajectory(&model, &plan) {
        Err(Finding::Collision { a, b, .. }) => assert!(a.contains("sliver") || b.contains("sliver"), "{a} and {b}"),
        Err(f @ Finding::NotCertified { .. }) => assert!(f.to_string().contains("sliver"), "{f}"),
        other => panic!("the certificate should refuse the plan, got {other:?}"),
    }
    // Through the agent: the default gate refuses the plan, a sampled gate would have let it drive.
    let outcome = |plan_check: Option<Verifier>| {
        let keyframes = plan.clone();
        let planner = move |_: &PlanRequest, _: &Deadline| Ok(Planned { trajectory: keyframes.clone(), work: 10 });
        let mut settings = DeliberationSettings { planner: Some(Arc::new(planner)), max_attempts: 1, ..simulated() };
        if let Some(v) = plan_check {
            settings.plan_check = v;
        }
        let collision = CollisionModel::new(&robot, env.clone());
        let agent = deliberative_agent("arm", robot.clone(), collision, &qa, Goal::Configuration(qb.clone()), settings)
            .expect("agent");
        let records = run(&mut runtime_with(agent), 300);
        events(&records)
    };
    let certified = outcome(None);
    assert!(
        certified.iter().any(|(_, e)| e.starts_with("plan_rejected id=1") && e.contains("sliver")),
        "{certified:?}"
    );
    assert!(!certified.iter().any(|(_, e)| e.starts_with("plan_landed")), "{certified:?}");
    let sampled = outcome(Some(Verifier::sampled(0.01)));
    assert!(sampled.iter().any(|(_, e)| e.starts_with("plan_landed id=1")), "{sampled:?}");
}

/// In simulated time the search is stopped by the collision checks that would put it past its
/// give-up step: the deliberator hands the planner exactly that many as a check budget (and
/// none where simulated time does not apply or work costs no time).
#[test]
fn simulated_give_up_becomes_a_check_budget() {
    let seen = Arc::new(std::sync::Mutex::new(Vec::new()));
    let record = seen.clone();
    let planner = move |_: &PlanRequest, d: &Deadline| {
        record.lock().unwrap_or_else(std::sync::PoisonError::into_inner).push(d.check_budget());
        Err(PlanFailure::Infeasible { work: 0 })
    };
    let planner: Arc<dyn MotionPlanner> = Arc::new(planner);
    let robot = robot();
    let verifier = PlanVerifier {
        collision: CollisionModel::new(&robot, Environment::new()),
        verifier: Default::default(),
        goal_tolerance: 1e-3,
    };
    let cases = [
        // 5 + ceil(w / 100) > 100 from w = 9,501 on.
        (PlanClock::Simulated { steps_per_unit: 0.01, fixed_steps: 5 }, Some(100), Some(9_501)),
        // ceil(w / 3) > 7 from w = 22 on.
        (PlanClock::Simulated { steps_per_unit: 1.0 / 3.0, fixed_steps: 0 }, Some(7), Some(22)),
        (PlanClock::Simulated { steps_per_unit: 0.01, fixed_steps: 5 }, None, None),
        (PlanClock::Simulated { steps_per_unit: 0.0, fixed_steps: 5 }, Some(100), None),
        (PlanClock::WallClock, Some(100), None),
    ];
    for (clock, give_up_steps, _) in cases {
        let mut deliberator = Deliberator::new(planner.clone(), verifier.clone(), clock);
        let request = PlanRequest {
            id: 0,
            world_version: 0,
            step: 0,
            start: START.to_vec(),
            goal: goal(),
            dt: 0.001,
            environment: None,
            budget: PlanBudget { steps: 10, wall: None, give_up_steps, work: None },
        };
        deliberator.request(request);
        let mut step = 0;
        while deliberator.poll(step).is_none() {
            step += 1;
            std::thread::sleep(std::time::Duration::from_micros(100));
            assert!(step < 100_000, "{clock:?}: no delivery");
        }
    }
    let seen = seen.lock().unwrap_or_else(std::sync::PoisonError::into_inner).clone();
    assert_eq!(seen, cases.iter().map(|c| c.2).collect::<Vec<_>>());
}
