//! Properties of deliberative runs over many random runs (simulated plan clock): limits are
//! never exceeded, halts stop within the kinematic stopping distance, stale plans are never
//! followed, and the same seed gives the same log.

use std::sync::Arc;

use embodied_executor::deliberation::*;
use embodied_executor::*;
use embodied_models::{CollisionModel, Environment, Robot};
use embodied_planner::deadline::Deadline;
use embodied_planner::motion::{Goal, MotionSettings};
use proptest::prelude::*;

const START: [f64; 6] = [-0.5, -1.4, -1.0, 0.0, 0.3, 0.0];
const GOAL: [f64; 6] = [0.8, -1.2, -1.2, 0.0, 0.5, 0.0];
const DT: f64 = 0.001;

fn robot() -> Arc<Robot> {
    Arc::new(embodied_models::builtin("rnt").expect("built-in robot"))
}

/// One run: the motion planner made slower by `extra` work units, a far obstacle appearing at
/// `appear` (the agent halts from speed and replans), `steps` steps.
fn run(extra: u64, deadline_steps: u64, appear: u64, seed: u64, steps: u64) -> Vec<StepRecord> {
    let robot = robot();
    let inner = PlanMotion::new(CollisionModel::new(&robot, Environment::new()), MotionSettings::default());
    let planner = move |r: &PlanRequest, d: &Deadline| {
        let mut p = inner.plan(r, d)?;
        p.work += extra;
        Ok(p)
    };
    let settings = DeliberationSettings {
        clock: PlanClock::Simulated { steps_per_unit: 0.01, fixed_steps: 2 },
        budget: PlanBudget { steps: deadline_steps, wall: None, give_up_steps: None, work: None },
        planner: Some(Arc::new(planner)),
        obstacle_sensing: Some(f64::INFINITY),
        halt_on_any_change: true,
        retry_after_steps: 30,
        ..DeliberationSettings::default()
    };
    let collision = CollisionModel::new(&robot, Environment::new());
    let agent = deliberative_agent("arm", robot, collision, &START, Goal::Configuration(GOAL.to_vec()), settings)
        .expect("agent");
    let mut rt = Runtime::new(RuntimeConfig { seed, dt: DT, ..RuntimeConfig::default() });
    rt.add_agent(agent);
    rt.world_mut().add_obstacle(Obstacle { appears_at: appear, ..Obstacle::fixed("far", [20.0, 0.0, 0.0], 0.1) });
    let mut records = Vec::new();
    rt.run(steps, |r| records.push(r.clone())).expect("run");
    records
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 12, ..ProptestConfig::default() })]

    #[test]
    fn deliberative_runs_are_safe(extra in 0u64..30_000, deadline in 0u64..400, appear in 1u64..2500, seed in 0u64..1000) {
        let records = run(extra, deadline, appear, seed, 3000);
        let limits = robot().limits();
        prop_assert_eq!(records.len(), 3000);
        // Limits: position, velocity, acceleration (from consecutive velocities).
        for w in records.windows(2) {
            let (a, b) = (&w[0].agents[0], &w[1].agents[0]);
            for (j, l) in limits.iter().enumerate() {
                prop_assert!(b.q[j] >= l.lower - 1e-9 && b.q[j] <= l.upper + 1e-9);
                prop_assert!(b.qd[j].abs() <= l.max_velocity + 1e-9);
                prop_assert!((b.qd[j] - a.qd[j]).abs() <= l.max_acceleration * DT * (1.0 + 1e-6) + 1e-9);
            }
        }
        let mut world = 0u64;
        let mut halt_from: Option<usize> = None;
        for (i, r) in records.iter().enumerate() {
            for e in &r.agents[0].events {
                if let Event::WorldChanged { version } = e {
                    world = *version;
                }
                // A stale plan is never followed: every plan taken is for the current world.
                if let Event::PlanLanded { world: planned_for, .. } = e {
                    prop_assert_eq!(*planned_for, world, "{}", e);
                }
                if matches!(e, Event::HaltStarted { reason: HaltReason::NoValidPlan, .. }) && i > 0 {
                    halt_from = Some(i - 1);
                }
                if matches!(e, Event::HaltFinished { .. })
                    && let Some(s) = halt_from.take()
                {
                    // Stopping distance for the speed at the start of the halt: the path-preserving
                    // stop takes T = max_j |v_j| / a_j; joint j travels |v_j| T / 2 (= v^2 / 2a for
                    // the joint that sets T), plus one step.
                    let (q0, v0) = (&records[s].agents[0].q, &records[s].agents[0].qd);
                    let t_stop = v0.iter().zip(&limits).map(|(v, l)| v.abs() / l.max_acceleration).fold(0.0, f64::max);
                    for j in 0..limits.len() {
                        let travelled = (r.agents[0].q[j] - q0[j]).abs();
                        let bound = v0[j].abs() * t_stop / 2.0 + v0[j].abs() * DT + 1e-9;
                        prop_assert!(travelled <= bound, "joint {} travelled {} > {}", j, travelled, bound);
                    }
                    prop_assert!(r.agents[0].qd.iter().all(|v| *v == 0.0));
                }
            }
        }
    }

    #[test]
    fn same_seed_same_log(extra in 0u64..20_000, appear in 1u64..1500, seed in 0u64..1000) {
        let a = run(extra, 300, appear, seed, 1500);
        let b = run(extra, 300, appear, seed, 1500);
        prop_assert_eq!(a, b);
    }
}
