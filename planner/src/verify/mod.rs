//! The one checker of paths and trajectories: a [`Verifier`] in one of two [`Mode`]s, one
//! vocabulary of [`Finding`]s, and one streaming [`LimitsChecker`].
//!
//! It shares nothing with the planner's validity checks but the model's geometric queries.
//! What it checks of a timed trajectory: that it is well formed (lengths, DOF, finite values,
//! increasing times); positions, velocities and accelerations within the robot's limits (the
//! [`LimitsChecker`], fed sample by sample); the path through the samples free of collisions;
//! and every closed-chain span keeping its relative tool pose ([`certified::check_closure`]).
//! The collision check depends on the mode:
//!
//! * [`Mode::Certified`] proves the whole continuum of configurations between the samples free,
//!   every pair at least `tolerance` apart, with a distance certificate that poses the shapes
//!   itself (see [`certified`]). This is what `embodied verify` runs, and what the executor's
//!   online plan gate runs by default: the planner certifies its own edges, so the gate must not
//!   be weaker.
//! * [`Mode::Sampled`] checks configurations no more than `resolution` apart in every joint
//!   (the model's `first_collision` and `motion_is_free`). Cheaper; a thin obstacle between two
//!   checked configurations is missed.
//!
//! A path (a list of waypoints, no times) is checked as a trajectory whose waypoint `k` is at
//! `t = k` ([`Verifier::verify_path`]), without velocity or acceleration limits.

pub mod certified;
mod finding;
mod limits;
mod report;
mod sampled;

use embodied_models::Robot;
use embodied_models::collision::CollisionModel;
use serde::Serialize;

pub use finding::Finding;
pub use limits::LimitsChecker;
pub use report::{CheckSettings, ClosureReport, CollisionReport, LimitsReport, TrajectoryReport};

use crate::carry::ClosedChainSpan;
use crate::trajectory::Trajectory;

/// Relative tolerance on velocity and acceleration limits (rounding in the profiles): the
/// default [`CheckSettings::limit_tolerance`].
pub const LIMIT_TOLERANCE: f64 = 1e-6;

/// The distance evaluations one verification may still spend
/// ([`CheckSettings::max_evaluations`]), shared by all its collision checks: a check that finds
/// it spent reports [`Finding::BudgetExhausted`] and certifies nothing further.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct EvaluationBudget {
    /// The budget (`None`: no limit).
    pub limit: Option<usize>,
    /// Evaluations spent so far.
    pub used: usize,
}

impl EvaluationBudget {
    /// A budget of `limit` evaluations (`None`: no limit), none spent.
    pub fn new(limit: Option<usize>) -> Self {
        Self { limit, used: 0 }
    }

    /// Whether another evaluation may be spent.
    pub fn allows(&self) -> bool {
        self.limit.is_none_or(|l| self.used < l)
    }
}

/// How the [`Verifier`] checks that the path between samples is free.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "mode", rename_all = "snake_case")]
pub enum Mode {
    /// Configurations no more than `resolution` (rad or m) apart in every joint are checked.
    Sampled {
        /// Largest joint step between two checked configurations, rad or m.
        resolution: f64,
    },
    /// The whole continuum is certified free with every pair at least `tolerance` (m) apart
    /// (0: free, touching counts as collision).
    Certified {
        /// Clearance the certificate must prove, m.
        tolerance: f64,
    },
}

/// The checker of paths and trajectories against a collision model (see the
/// [module documentation](self)).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Verifier {
    /// How collisions between samples are checked.
    pub mode: Mode,
    /// Tolerances on limits and caps of the certificate.
    pub settings: CheckSettings,
}

impl Default for Verifier {
    /// Certified, touching counts as collision, default settings.
    fn default() -> Self {
        Self::certified(0.0)
    }
}

impl Verifier {
    /// A sampled verifier at `resolution` (rad or m), default settings.
    pub fn sampled(resolution: f64) -> Self {
        Self { mode: Mode::Sampled { resolution }, settings: CheckSettings::default() }
    }

    /// A certifying verifier that requires `tolerance` (m) of clearance, default settings.
    pub fn certified(tolerance: f64) -> Self {
        Self { mode: Mode::Certified { tolerance }, settings: CheckSettings::default() }
    }

    /// The same verifier with other tolerances and caps.
    pub fn with_settings(mut self, settings: CheckSettings) -> Self {
        self.settings = settings;
        self
    }

    /// A streaming limits checker for `robot` with this verifier's tolerances.
    pub fn limits_checker(&self, robot: &Robot) -> LimitsChecker {
        LimitsChecker::new(robot, &self.settings)
    }

    /// Check one agent's timed trajectory against `model` (robot and environment): the
    /// trajectory is well formed; positions, velocities and accelerations within limits; the
    /// path through the samples collision-free (by the mode); every closed-chain span keeps its
    /// relative tool pose. Inside a span with an object, collisions are checked with the object
    /// attached.
    pub fn check_trajectory(
        &self,
        model: &CollisionModel,
        traj: &Trajectory,
        spans: &[ClosedChainSpan],
    ) -> TrajectoryReport {
        let mut budget = EvaluationBudget::new(self.settings.max_evaluations);
        self.check_trajectory_within(model, traj, spans, &mut budget)
    }

    /// [`Verifier::check_trajectory`] spending distance evaluations from `budget` (shared with
    /// other checks of the same verification) instead of a budget of its own.
    pub fn check_trajectory_within(
        &self,
        model: &CollisionModel,
        traj: &Trajectory,
        spans: &[ClosedChainSpan],
        budget: &mut EvaluationBudget,
    ) -> TrajectoryReport {
        let robot = model.robot();
        let samples = traj.t.len();
        if let Err(message) = well_formed(robot, traj) {
            return malformed(Finding::Malformed { message }, traj, spans);
        }
        let mut limits = self.limits_checker(robot);
        for k in 0..samples {
            limits.push(traj.t[k], &traj.q[k], &traj.qd[k]);
        }
        let limits = limits.report();
        let collision = self.check_collisions_within(model, traj, spans, budget);
        let closure = certified::check_closure(robot, traj, spans);
        TrajectoryReport {
            certified: limits.ok && collision.ok && closure.ok,
            duration_s: traj.duration(),
            samples,
            limits,
            collision,
            closure,
        }
    }

    /// Only the collision check of [`Verifier::check_trajectory`] (the trajectory is assumed
    /// well formed: lengths and DOF are not checked here).
    pub fn check_collisions(
        &self,
        model: &CollisionModel,
        traj: &Trajectory,
        spans: &[ClosedChainSpan],
    ) -> CollisionReport {
        let mut budget = EvaluationBudget::new(self.settings.max_evaluations);
        self.check_collisions_within(model, traj, spans, &mut budget)
    }

    /// [`Verifier::check_collisions`] spending distance evaluations from `budget` (the
    /// certified mode; the sampled mode measures no distances and spends none).
    pub fn check_collisions_within(
        &self,
        model: &CollisionModel,
        traj: &Trajectory,
        spans: &[ClosedChainSpan],
        budget: &mut EvaluationBudget,
    ) -> CollisionReport {
        match self.mode {
            Mode::Sampled { resolution } => sampled::sample_collisions(model, traj, spans, resolution),
            Mode::Certified { tolerance } => {
                certified::certify_collisions(model, traj, spans, &self.settings, tolerance.max(0.0), budget)
            }
        }
    }

    /// [`Verifier::check_trajectory`] without closed-chain spans, as a yes or the first finding
    /// (limits before collisions).
    // A finding is returned once, when the check refuses: boxing it would only burden callers'
    // pattern matching.
    #[allow(clippy::result_large_err)]
    pub fn verify_trajectory(&self, model: &CollisionModel, traj: &Trajectory) -> Result<(), Finding> {
        let robot = model.robot();
        if let Err(message) = well_formed(robot, traj) {
            return Err(Finding::Malformed { message });
        }
        let mut limits = self.limits_checker(robot);
        for k in 0..traj.t.len() {
            limits.push(traj.t[k], &traj.q[k], &traj.qd[k]);
        }
        if let Some(f) = limits.first() {
            return Err(f.clone());
        }
        let collision = self.check_collisions(model, traj, &[]);
        collision.violation.map_or(Ok(()), Err)
    }

    /// Check a path: every waypoint has the robot's DOF, is finite and within the position
    /// limits, and the polyline through the waypoints (straight segments, the short way round
    /// on continuous joints) is collision-free by the mode. Findings are placed on the path
    /// parameter: waypoint `k` is at `t = k`.
    // A finding is returned once, when the check refuses: boxing it would only burden callers'
    // pattern matching.
    #[allow(clippy::result_large_err)]
    pub fn verify_path(&self, model: &CollisionModel, path: &[Vec<f64>]) -> Result<(), Finding> {
        let robot = model.robot();
        if path.is_empty() {
            return Err(Finding::Malformed { message: "the path is empty".into() });
        }
        let dof = robot.dof();
        let mut limits = self.limits_checker(robot);
        for (index, q) in path.iter().enumerate() {
            if q.len() != dof {
                let message = format!("waypoint {index} has {} joint values, the robot has {dof}", q.len());
                return Err(Finding::Malformed { message });
            }
            if let Some(i) = q.iter().position(|x| !x.is_finite()) {
                let joint = &robot.dof_joint(i).name;
                let message = format!("waypoint {index}: joint `{joint}` is {}, not a finite number", q[i]);
                return Err(Finding::Malformed { message });
            }
            limits.push_positions(index as f64, q);
            if let Some(f) = limits.first() {
                return Err(f.clone());
            }
        }
        let traj = Trajectory {
            joint_names: robot.joint_names(),
            t: (0..path.len()).map(|k| k as f64).collect(),
            q: path.to_vec(),
            qd: Vec::new(),
        };
        self.check_collisions(model, &traj, &[]).violation.map_or(Ok(()), Err)
    }
}

/// Lengths, DOF, finite values and strictly increasing times.
fn well_formed(robot: &Robot, traj: &Trajectory) -> Result<(), String> {
    let n = traj.t.len();
    if n == 0 {
        return Err("the trajectory has no samples".into());
    }
    if traj.q.len() != n || traj.qd.len() != n {
        return Err(format!("{} times, {} positions and {} velocities", n, traj.q.len(), traj.qd.len()));
    }
    let dof = robot.dof();
    for k in 0..n {
        for (what, v) in [("q", &traj.q[k]), ("qd", &traj.qd[k])] {
            if v.len() != dof {
                return Err(format!("sample {k}: {what} has {} values, the robot has {dof} joints", v.len()));
            }
            if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                return Err(format!("sample {k}: {what}[{i}] = {} is not a finite number", v[i]));
            }
        }
        if !traj.t[k].is_finite() {
            return Err(format!("sample {k}: t = {} is not a finite number", traj.t[k]));
        }
        if k > 0 && traj.t[k] <= traj.t[k - 1] {
            return Err(format!("sample {k}: t = {} s does not come after t = {} s", traj.t[k], traj.t[k - 1]));
        }
    }
    Ok(())
}

/// The report of a malformed trajectory: every check fails with the same finding.
fn malformed(m: Finding, traj: &Trajectory, spans: &[ClosedChainSpan]) -> TrajectoryReport {
    let samples = traj.t.len();
    TrajectoryReport {
        certified: false,
        duration_s: traj.duration(),
        samples,
        limits: LimitsReport {
            ok: false,
            violation: Some(m.clone()),
            violations: 1,
            samples,
            max_velocity_ratio: f64::NAN,
            max_acceleration_ratio: f64::NAN,
            time_s: 0.0,
        },
        collision: CollisionReport {
            ok: false,
            violation: Some(m.clone()),
            segments: samples.saturating_sub(1),
            certified_segments: 0,
            distance_evaluations: 0,
            subdivisions: 0,
            max_depth: 0,
            pairs: 0,
            min_clearance_m: f64::NAN,
            certified_clearance_m: f64::NAN,
            closest_pair: None,
            time_s: 0.0,
        },
        closure: ClosureReport {
            ok: false,
            violation: Some(m),
            spans: spans.len(),
            samples: 0,
            max_position_error_m: f64::NAN,
            max_angle_error_rad: f64::NAN,
            time_s: 0.0,
        },
    }
}
