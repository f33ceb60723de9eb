//! The built-in motion planner for deliberative agents: A* (the planner crate's
//! [`embodied_planner::search::solve`], under a [`Deadline`]) on a joint-space lattice around the
//! start, edges checked with the collision model, then greedy shortcutting and time
//! parameterisation. Deterministic: the same request and budget give the same expansions and
//! the same trajectory on every machine.

use embodied_models::CollisionModel;
use embodied_planner::deadline::Deadline;
use embodied_planner::search::{Cost, SearchOutcome, SearchProblem, Successor, solve};

use super::trajectory::time_parameterize;
use super::worker::{PlanFailure, PlanRequest, Planned};

/// Lattice A* settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LatticeSettings {
    /// Lattice spacing, rad or m.
    pub step: f64,
    /// Edge collision-check resolution, rad or m.
    pub resolution: f64,
    /// Fraction of the velocity/acceleration limits used by the time parameterisation.
    pub margin: f64,
}

impl Default for LatticeSettings {
    fn default() -> Self {
        Self { step: 0.1, resolution: 0.02, margin: 0.9 }
    }
}

/// A* on the lattice `start + step * z`, `z` integer; one operator per joint and direction.
struct Lattice<'a> {
    model: &'a CollisionModel,
    start: &'a [f64],
    goal: &'a [f64],
    step: f64,
    resolution: f64,
}

impl Lattice<'_> {
    fn config(&self, z: &[i32]) -> Vec<f64> {
        self.start.iter().zip(z).map(|(s, k)| s + self.step * f64::from(*k)).collect()
    }
    fn within_bounds(&self, q: &[f64]) -> bool {
        self.model.robot().limits().iter().zip(q).all(|(l, v)| *v >= l.lower && *v <= l.upper)
    }
}

impl SearchProblem for Lattice<'_> {
    type State = Vec<i32>;
    type Operator = ();

    fn initial(&self) -> Vec<i32> {
        vec![0; self.start.len()]
    }

    fn successors(&self, z: &Vec<i32>, out: &mut Vec<Successor<Vec<i32>, ()>>) {
        let here = self.config(z);
        let Ok(cost) = Cost::new(self.step) else { return };
        for j in 0..z.len() {
            for d in [1, -1] {
                let mut next = z.clone();
                next[j] += d;
                let q = self.config(&next);
                if self.within_bounds(&q) && self.model.motion_is_free(&here, &q, self.resolution) {
                    out.push(Successor { operator: (), state: next, cost });
                }
            }
        }
    }

    fn is_goal(&self, z: &Vec<i32>) -> bool {
        let q = self.config(z);
        q.iter().zip(self.goal).all(|(a, b)| (a - b).abs() <= 0.5 * self.step + 1e-12)
            && self.model.motion_is_free(&q, self.goal, self.resolution)
    }

    fn heuristic(&self, z: &Vec<i32>) -> f64 {
        // Each operator moves one joint by `step`: the L1 distance to the goal box is admissible.
        let q = self.config(z);
        q.iter().zip(self.goal).map(|(a, b)| ((a - b).abs() - 0.5 * self.step).max(0.0)).sum()
    }
}

/// Plan `request` on the lattice under `deadline`.
pub fn lattice_plan(
    model: &CollisionModel,
    settings: &LatticeSettings,
    request: &PlanRequest,
    deadline: &Deadline,
) -> Result<Planned, PlanFailure> {
    let robot = model.robot();
    let dof = robot.dof();
    if request.start.len() != dof || request.goal.len() != dof {
        return Err(PlanFailure::Error(format!(
            "start/goal need {dof} values, got {}/{}",
            request.start.len(),
            request.goal.len()
        )));
    }
    let mut model = model.clone();
    if let Some(env) = &request.environment {
        model.set_environment(env.clone());
    }
    if model.collides(&request.goal) {
        return Err(PlanFailure::Error("goal configuration collides".into()));
    }
    let problem = Lattice {
        model: &model,
        start: &request.start,
        goal: &request.goal,
        step: settings.step.max(1e-3),
        resolution: settings.resolution,
    };
    // A straight line, when free, needs no search (one expansion's worth of work).
    if model.motion_is_free(&request.start, &request.goal, settings.resolution) && !deadline.is_past(0) {
        let path = [request.start.clone(), request.goal.clone()];
        let trajectory = time_parameterize(&path, &robot.limits(), &robot.joint_names(), request.dt, settings.margin);
        return Ok(Planned { trajectory, expansions: 1 });
    }
    let report = solve(&problem, deadline);
    let expansions = report.stats.expansions;
    let plan = match report.outcome {
        SearchOutcome::Solved(plan) => plan,
        SearchOutcome::OutOfTime { cause, .. } => {
            return Err(PlanFailure::OutOfTime { expansions, reason: format!("{cause:?}") });
        }
        SearchOutcome::Infeasible => return Err(PlanFailure::Infeasible { expansions }),
    };
    let mut path: Vec<Vec<f64>> = plan.states.iter().map(|z| problem.config(z)).collect();
    path.push(request.goal.clone());
    let path = shortcut(&model, &path, settings.resolution);
    let trajectory = time_parameterize(&path, &robot.limits(), &robot.joint_names(), request.dt, settings.margin);
    Ok(Planned { trajectory, expansions })
}

/// Greedy shortcutting: from each kept waypoint jump to the farthest one reachable in a straight
/// collision-free line.
fn shortcut(model: &CollisionModel, path: &[Vec<f64>], resolution: f64) -> Vec<Vec<f64>> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < path.len() {
        out.push(path[i].clone());
        if i + 1 == path.len() {
            break;
        }
        let mut j = path.len() - 1;
        while j > i + 1 && !model.motion_is_free(&path[i], &path[j], resolution) {
            j -= 1;
        }
        i = j;
    }
    out
}
