//! Many agents, one bounded planning queue: fairness and deadlines (`embodied bench load` runs
//! the same with 1,000 agents; its figures are in docs/benchmarks.md).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use embodied_executor::deliberation::QueuePolicy;
use embodied_system::load::{LoadSettings, run_load};

fn settings(policy: QueuePolicy, us_per_check: f64) -> LoadSettings {
    LoadSettings {
        agents: 50,
        deliberative_share: 0.6,
        workers: 2,
        policy,
        duration_s: 1.5,
        deadline_ms: 20.0,
        give_up_ms: 200.0,
        us_per_check,
        parallel: false,
        planner_threads: true,
        seed: 3,
    }
}

/// 30 deliberative agents ask at once, two workers: every request is answered by its deadline
/// or its agent gets `plan_late` and halts; no agent goes without a plan; with earliest deadline
/// first and equal deadlines, requests are served in the order they were made.
#[test]
fn a_burst_of_requests_is_served_fairly() {
    for policy in [QueuePolicy::EarliestDeadline, QueuePolicy::Fifo] {
        let r = run_load(&settings(policy, 2.0)).expect("load run");
        eprintln!("{r:?}");
        assert_eq!(r.deliberative, 30);
        assert!(r.requests >= 30, "{r:?}");
        assert_eq!(r.unanswered_without_halt, 0, "{r:?}");
        assert_eq!(r.starved_agents, 0, "{r:?}");
        // The burst at step 1 is served one after another: the last waits longer than the first.
        assert!(r.wait_max_ms > r.wait_p50_ms || r.max_waiting == 1, "{r:?}");
        assert!(r.max_waiting >= 28, "all but a few wait at once at the burst: {r:?}");
    }
}

/// Slow planning (400 µs per collision check): the queue cannot answer everyone by the 20 ms
/// deadline. Those agents get `plan_late` and halt (typed events), and their plans land later;
/// still no agent is starved and no request is left without an answer or a halt.
#[test]
fn an_overloaded_queue_halts_agents_instead_of_missing_deadlines_silently() {
    let r = run_load(&settings(QueuePolicy::EarliestDeadline, 400.0)).expect("load run");
    eprintln!("{r:?}");
    assert!(r.late > 0, "some deadlines must pass in the queue: {r:?}");
    assert!(r.landed_late > 0 || r.failed > 0, "{r:?}");
    assert_eq!(r.unanswered_without_halt, 0, "{r:?}");
    assert_eq!(r.starved_agents, 0, "{r:?}");
    assert!(r.halts >= r.late, "every late plan starts a halt: {r:?}");
}

/// Planning on the queue's own threads or inside the steps: the same events and queue figures
/// (the queue's timeline is simulated), on the rayon pool too.
#[test]
fn planner_threads_change_no_figure_but_wall_time() {
    for parallel in [false, true] {
        let run = |planner_threads: bool| {
            let s = LoadSettings { parallel, planner_threads, ..settings(QueuePolicy::EarliestDeadline, 2.0) };
            run_load(&s).expect("load run")
        };
        let (threads, inline) = (run(true), run(false));
        assert_eq!(threads.planner_threads, 2);
        assert_eq!(inline.planner_threads, 0);
        let figures = |r: &embodied_system::load::LoadReport| {
            (
                (r.requests, r.landed_in_time, r.landed_late, r.failed, r.late, r.halts, r.goals_reached),
                (r.min_plans_per_agent, r.max_plans_per_agent, r.queue_planned, r.queue_expired, r.queue_withdrawn),
                (r.wait_p50_ms, r.wait_p99_ms, r.wait_max_ms, r.max_waiting),
            )
        };
        assert_eq!(figures(&threads), figures(&inline), "parallel {parallel}");
    }
}
