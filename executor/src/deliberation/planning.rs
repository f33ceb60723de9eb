//! The motion planner deliberative agents use: the planner crate's
//! [`embodied_planner::motion::plan_with_kind`] (straight segment, RRT-Connect or lazy PRM,
//! shortcuts) under the request's [`Deadline`], time-parameterised by
//! [`embodied_planner::trajectory::time_parameterize`] (knots only).
//!
//! Work is counted in collision checks: deterministic for a seed, and what planning time is made
//! of, so that [`super::PlanClock::Simulated`] turns it into simulated planning time.

use embodied_models::CollisionModel;
use embodied_planner::deadline::Deadline;
use embodied_planner::motion::{MotionSettings, Outcome, plan_with_kind};
use embodied_planner::trajectory::time_parameterize;

use embodied_planner::request::{MotionPlanner, PlanFailure, PlanRequest, Planned};

/// [`plan_with_kind`] as a [`MotionPlanner`]: `model` gives the robot (and the environment when the
/// request has none); `settings` everything but the deadline, which comes with each request.
/// Each request plans with seed `settings.seed + request id`, so a replan is a fresh draw and a
/// run is still reproducible.
#[derive(Clone)]
pub struct PlanMotion {
    /// The robot and the environment it plans in (used when the request brings none).
    pub model: CollisionModel,
    /// Motion planning settings; the deadline and the seed come from each request.
    pub settings: MotionSettings,
}

impl PlanMotion {
    /// A planner over `model` with `settings` (see the type's documentation).
    pub fn new(model: CollisionModel, settings: MotionSettings) -> Self {
        Self { model, settings }
    }
}

impl MotionPlanner for PlanMotion {
    fn plan(&self, request: &PlanRequest, deadline: &Deadline) -> Result<Planned, PlanFailure> {
        let mut model = self.model.clone();
        if let Some(env) = &request.environment {
            model.set_environment(env.clone());
        }
        let settings = MotionSettings {
            seed: self.settings.seed.wrapping_add(request.id),
            deadline: deadline.clone(),
            ..self.settings.clone()
        };
        match plan_with_kind(settings.planner, &model, &request.start, &request.goal, &settings) {
            Ok(Outcome::Solved(plan)) => {
                // Knots only (every point where the acceleration changes): the follower's
                // Hermite sampling reproduces the motion exactly at any control period, and the
                // verifier checks a few knots and the straight segments between them instead of
                // one sample per control step.
                let trajectory = time_parameterize(&plan.path, model.robot(), 0.0);
                Ok(Planned { trajectory, work: plan.stats.collision_checks })
            }
            Ok(Outcome::OutOfTime { best, .. }) => {
                let stats = best.unwrap_or_default();
                Err(PlanFailure::OutOfTime {
                    work: stats.collision_checks,
                    reason: format!("{} samples, {} collision checks", stats.samples, stats.collision_checks),
                })
            }
            Ok(Outcome::Infeasible) => Err(PlanFailure::Infeasible { work: settings.max_samples as u64 }),
            Err(e) => Err(PlanFailure::Error(e.to_string())),
        }
    }
}
