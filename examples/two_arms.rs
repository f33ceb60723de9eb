//! Two Polycrank arms and a coordinator, built in code (no TOML): both swing their bases 2 rad in
//! a world with a post between them; the coordinator grants their motions concurrently and hands
//! each arm the configurations the other will sweep. `cargo run --release --example two_arms`
use std::process::ExitCode;

use embodied_models::nalgebra::Isometry3;
use embodied_models::{Obstacle, Shape};
use embodied_system::{AgentSpec, Coordination, GoalSpec, RunOptions, Scenario, System, SystemError};

fn main() -> Result<ExitCode, SystemError> {
    let arm = embodied_models::builtin("polycrank")?;
    let (start, mut goal) = (arm.home().to_vec(), arm.home().to_vec());
    goal[0] += 2.0;
    let post = Obstacle::new(
        "post",
        Isometry3::translation(0.6, 0.0, 0.4),
        Shape::Cylinder { radius: 0.05, half_height: 0.4 },
    );
    let scenario = Scenario::builder("two-arms")
        .agent(
            AgentSpec::new("left", arm.clone())
                .at([0.0, -0.9, 0.0])
                .start(start.clone())
                .goal(GoalSpec::Configuration(goal.clone())),
        )
        .agent(AgentSpec::new("right", arm).at([0.0, 0.9, 0.0]).start(start).goal(GoalSpec::Configuration(goal)))
        .obstacle(post)
        .coordination(Coordination::Concurrent)
        .simulated_clock(2.0) // planning time counted from collision checks: the same run every time
        .duration(8.0)
        .build()?;
    let mut system = System::new(&scenario, &RunOptions::default())?;
    system.run_until(system.duration(), |record| {
        for agent in &record.agents {
            for event in &agent.events {
                println!("t={:6.3}s {:12} {event}", record.time, agent.agent);
            }
        }
    })?;
    // Read access to the system: every agent's input image c^i after the last step.
    let left = system.agent_id("left").and_then(|id| system.runtime().images(id));
    if let Some(images) = left {
        println!("left arm at q = {:.3?}", images.q());
    }
    let summary = system.summary();
    let done = summary.agents.iter().all(|a| a.goal_reached);
    println!("coordinator: {:?}; goals reached: {done}", system.coordinator());
    Ok(if done { ExitCode::SUCCESS } else { ExitCode::FAILURE })
}
