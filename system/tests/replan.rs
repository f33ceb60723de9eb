//! Replanning in motion: a ball drops into the Polycrank's path while it moves. The agent asks
//! for a new plan without stopping, from where its path, braked from the deadline on, comes to
//! rest. In time: the plan is joined at speed (superposed on the braking) and there is no halt. Late: the agent halts from speed at
//! the deadline, within its limits, and resumes from where it stopped. Both runs' logs pass
//! `verify --log` with collision checking.
#![allow(clippy::unwrap_used)]

mod common;
use common::tmp;

use embodied_executor::{Event, HaltReason};
use embodied_planner::verify::CheckSettings;
use embodied_system::log::{LogStep, RunLog};
use embodied_system::scenario::{ClockSpec, load_scenario};
use embodied_system::verify::verify_log;
use embodied_system::{RunOptions, Scenario, System};

/// `polycrank-intruder` with the ball dropping at `appear_s` and `us_per_check` µs of
/// simulated planning time per collision check.
fn intruder(appear_s: f64, us_per_check: f64) -> Scenario {
    let mut sc = load_scenario("polycrank-intruder").unwrap();
    let ball = sc.obstacles.iter_mut().find(|o| o.appear_at.is_some()).unwrap();
    ball.appear_at = Some(appear_s);
    sc.planner.clock = ClockSpec::Simulated { us_per_check };
    sc
}

struct Run {
    steps: Vec<LogStep>,
    scenario: Scenario,
}

impl Run {
    fn events(&self) -> Vec<(usize, Event)> {
        let mut out = Vec::new();
        for (k, s) in self.steps.iter().enumerate() {
            for e in &s.agents["polycrank"].events {
                out.push((k, e.clone()));
            }
        }
        out
    }
    fn first(&self, f: impl Fn(&Event) -> bool) -> Option<(usize, Event)> {
        self.events().into_iter().find(|(_, e)| f(e))
    }
    fn q(&self, k: usize) -> &[f64] {
        &self.steps[k].agents["polycrank"].q
    }
    fn qd(&self, k: usize) -> &[f64] {
        &self.steps[k].agents["polycrank"].qd
    }
}

/// Run `scenario` for 4 s, logging it as `embodied run` does, and check the log with
/// `verify --log` (limits and collisions).
fn run(scenario: Scenario, name: &str) -> Run {
    let path = tmp(name);
    let mut system = System::new(&scenario, &RunOptions { duration: Some(4.0), ..RunOptions::default() }).unwrap();
    let mut log = RunLog::create(Some(&path)).unwrap();
    log.line(&serde_json::json!({ "header": system.header() })).unwrap();
    let mut steps = Vec::new();
    system
        .run_until(4.0, |r| {
            let s = LogStep::of(r);
            log.line(&s).unwrap();
            steps.push(s);
        })
        .unwrap();
    log.line(&serde_json::json!({ "summary": system.summary().replayable() })).unwrap();
    let v = verify_log(&scenario, &path, &CheckSettings::default()).unwrap();
    assert!(v.certified, "{v:?}");
    let c = v.agents[0].collision.as_ref().unwrap();
    assert!(c.ok && c.segments == steps.len() - 1, "{c:?}");
    Run { steps, scenario }
}

#[test]
fn a_replan_that_lands_in_time_is_joined_in_motion_without_a_halt() {
    let r = run(intruder(0.05, 2.0), "in-time.jsonl");
    let ev = r.events();
    let (seen, _) = r.first(|e| matches!(e, Event::WorldChanged { .. })).unwrap();
    let (asked, e) = r.first(|e| matches!(e, Event::ReplanInMotion { .. })).expect("asks in motion");
    assert_eq!(asked, seen, "{ev:?}");
    let Event::ReplanInMotion { plan: 1, id: 2, speed, .. } = e else { panic!("{e}") };
    assert!(speed > 0.5, "moving fast at the deadline: {speed}");
    assert!(r.qd(asked).iter().any(|v| v.abs() > 0.3), "moving when it asks");
    let (joined, _) = r.first(|e| matches!(e, Event::PlanJoined { id: 2, plan: 1, .. })).expect("joined");
    let deadline = r.scenario.planner.deadline_ms as usize;
    assert!(joined <= asked + deadline, "in time");
    assert!(r.first(|e| matches!(e, Event::PlanLanded { id: 2, in_time: true, .. })).is_some());
    // No halt, no stale plan; the goal is reached by the joined plan.
    assert!(r.first(|e| matches!(e, Event::HaltStarted { .. })).is_none(), "{ev:?}");
    assert!(r.first(|e| matches!(e, Event::PlanDiscarded { .. })).is_none(), "{ev:?}");
    assert!(r.first(|e| matches!(e, Event::GoalReached { id: Some(2) })).is_some(), "{ev:?}");
    // The arm kept moving from the request until the plan landed ...
    for k in asked..=joined {
        assert!(r.qd(k).iter().any(|v| v.abs() > 0.1), "still moving at step {k}");
    }
    // ... and through the join: the new plan is superposed on the braking, so the arm turns onto
    // it at speed instead of coming to rest where it starts; position, velocity and
    // acceleration stay within the limits (and the log verified above).
    let (_, e) = r.first(|e| matches!(e, Event::PlanJoined { id: 2, .. })).unwrap();
    let Event::PlanJoined { join_in_s, moving, .. } = e else { unreachable!() };
    assert!(moving, "{e}");
    let join_step = joined + (join_in_s / 0.001).round() as usize;
    let speed = |k: usize| r.qd(k).iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let slowest = (asked..=join_step + 50).map(speed).fold(f64::INFINITY, f64::min);
    assert!(slowest > 0.2, "the arm slowed to {slowest} rad/s around the join at step {join_step}");
    let limits = r.scenario.agents[0].robot.limits();
    for k in asked..=join_step + 50 {
        for (j, l) in limits.iter().enumerate() {
            let a = (r.qd(k)[j] - r.qd(k - 1)[j]) / 0.001;
            assert!(a.abs() <= l.max_acceleration * (1.0 + 1e-6), "joint {j} at step {k}: {a}");
            assert!(r.qd(k)[j].abs() <= l.max_velocity * (1.0 + 1e-9));
        }
    }
}

#[test]
fn a_replan_that_lands_late_halts_from_speed_within_limits_and_resumes_where_it_stopped() {
    // 80 µs per check: the replan (between 834 and 1,249 checks) takes longer than its 50 ms.
    let r = run(intruder(0.02, 80.0), "late.jsonl");
    let ev = r.events();
    let (asked, _) = r.first(|e| matches!(e, Event::ReplanInMotion { id: 2, .. })).expect("asks in motion");
    let budget = r.scenario.planner.deadline_ms as usize;
    let (late, _) = r.first(|e| matches!(e, Event::PlanLate { id: 2 })).expect("late");
    assert_eq!(late, asked + budget + 1, "late right after the deadline: {ev:?}");
    let (halt, e) = r.first(|e| matches!(e, Event::HaltStarted { .. })).unwrap();
    assert_eq!(halt, late);
    let Event::HaltStarted { reason: HaltReason::PlanLate, speed, .. } = e else { panic!("{e}") };
    assert!(speed > 0.5, "a halt from speed: {speed}");
    let (stopped, e) = r.first(|e| matches!(e, Event::HaltFinished { .. })).unwrap();
    let Event::HaltFinished { distance, time_s, .. } = e else { panic!("{e}") };
    assert!(distance > 0.0 && time_s > 0.0, "{e}");
    // The halt: speeds only shrink, within the acceleration limits, to rest.
    let limits = r.scenario.agents[0].robot.limits();
    for k in halt..=stopped {
        for (j, l) in limits.iter().enumerate() {
            let (a, b) = (r.qd(k - 1)[j], r.qd(k)[j]);
            assert!(b.abs() <= a.abs() + 1e-12, "joint {j} speeds up at step {k}");
            assert!((b - a).abs() / 0.001 <= l.max_acceleration * (1.0 + 1e-6), "joint {j} at step {k}");
        }
    }
    assert!(r.qd(stopped).iter().all(|v| *v == 0.0));
    // The late plan starts where the braked path would have stopped, not where the arm is.
    let (discarded, _) = r.first(|e| matches!(e, Event::PlanDiscarded { id: 2, .. })).expect("late plan discarded");
    assert!(discarded > late);
    // Resume from where it stopped: a request at rest, landed, followed to the goal.
    let (again, e) = r.first(|e| matches!(e, Event::PlanRequested { id, .. } if *id > 2)).unwrap();
    assert!(again >= stopped && again >= discarded, "{ev:?}");
    let Event::PlanRequested { id, .. } = e else { unreachable!() };
    let (resumed, _) = r.first(|e| matches!(e, Event::Resumed { id: i, .. } if *i == id)).expect("resumes");
    let rest = r.q(again).to_vec();
    for k in stopped..resumed {
        assert_eq!(r.q(k), &rest[..], "at rest where it stopped until it resumes (step {k})");
    }
    assert!(r.first(|e| matches!(e, Event::GoalReached { id: Some(i) } if *i == id)).is_some(), "{ev:?}");
}
