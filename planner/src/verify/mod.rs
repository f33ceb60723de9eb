//! An independent checker of paths and trajectories against a collision model.
//!
//! It shares nothing with the planner's validity checks but the model's geometric queries:
//! waypoints are checked with `first_collision` (to name the pair), segments with the model's
//! own `motion_is_free` at the caller's resolution, then walked in order to say where.
//!
//! [`certified`] is the certified checker behind `embodied verify`: continuous collision
//! freedom with a distance certificate, limits, the closed-chain constraint and timing.

pub mod certified;

use embodied_models::ConfigSpace;
use embodied_models::collision::CollisionModel;

use crate::trajectory::Trajectory;

/// Relative tolerance on velocity and acceleration limits (rounding in the profiles).
pub const LIMIT_TOLERANCE: f64 = 1e-6;

/// What is wrong with a path or trajectory, and where.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Violation {
    #[error("the path is empty")]
    Empty,
    #[error("waypoint {index} has {got} joint values, the robot has {expected}")]
    WrongDof { index: usize, expected: usize, got: usize },
    #[error("waypoint {index}: joint `{joint}` is {value}, not a finite number")]
    NotFinite { index: usize, joint: String, value: f64 },
    #[error("waypoint {index}: joint `{joint}` = {value:.6} is outside [{lower:.6}, {upper:.6}] by {by:.3e}")]
    OutOfLimits { index: usize, joint: String, value: f64, lower: f64, upper: f64, by: f64 },
    #[error("waypoint {index} is in collision: {contact}")]
    WaypointCollision { index: usize, contact: String },
    #[error("segment {index} -> {} collides at fraction {fraction:.4}: {contact}", index + 1)]
    SegmentCollision { index: usize, fraction: f64, contact: String },
    #[error("trajectory: sample {index} at t = {t} s does not come after t = {previous} s")]
    TimeNotIncreasing { index: usize, t: f64, previous: f64 },
    #[error("trajectory: {what} has {got} entries for {expected} samples")]
    LengthMismatch { what: &'static str, expected: usize, got: usize },
    #[error("trajectory at t = {t:.4} s: joint `{joint}` velocity {value:.6} exceeds {limit:.6} by {by:.3e}")]
    Velocity { t: f64, joint: String, value: f64, limit: f64, by: f64 },
    #[error("trajectory at t = {t:.4} s: joint `{joint}` acceleration {value:.6} exceeds {limit:.6} by {by:.3e}")]
    Acceleration { t: f64, joint: String, value: f64, limit: f64, by: f64 },
}

/// Check a path: every waypoint has the robot's DOF, is finite, within the position limits
/// and collision-free, and every straight segment (short way on continuous joints) is
/// collision-free at `resolution` (largest joint step between checked points).
pub fn verify_path(model: &CollisionModel, path: &[Vec<f64>], resolution: f64) -> Result<(), Violation> {
    if path.is_empty() {
        return Err(Violation::Empty);
    }
    for (index, q) in path.iter().enumerate() {
        check_waypoint(model, index, q)?;
    }
    let space = model.robot().config_space();
    for (index, w) in path.windows(2).enumerate() {
        check_segment(model, &space, index, &w[0], &w[1], resolution)?;
    }
    Ok(())
}

/// Check a trajectory: its path (every sample and the segments between them) as
/// [`verify_path`], increasing times, and joint velocities and accelerations within the
/// limits (sampled velocities, and finite differences of positions and velocities) up to
/// [`LIMIT_TOLERANCE`] relative.
pub fn verify_trajectory(model: &CollisionModel, traj: &Trajectory, resolution: f64) -> Result<(), Violation> {
    let n = traj.t.len();
    for (what, got) in [("q", traj.q.len()), ("qd", traj.qd.len())] {
        if got != n {
            return Err(Violation::LengthMismatch { what, expected: n, got });
        }
    }
    verify_path(model, &traj.q, resolution)?;
    let robot = model.robot();
    let limits = robot.limits();
    let names = robot.joint_names();
    let space = robot.config_space();
    for (index, qd) in traj.qd.iter().enumerate() {
        if qd.len() != limits.len() {
            return Err(Violation::WrongDof { index, expected: limits.len(), got: qd.len() });
        }
        for (i, &v) in qd.iter().enumerate() {
            over(v, limits[i].max_velocity, traj.t[index], &names[i], true)?;
        }
    }
    for k in 1..n {
        let h = traj.t[k] - traj.t[k - 1];
        if h.is_nan() || h <= 0.0 {
            return Err(Violation::TimeNotIncreasing { index: k, t: traj.t[k], previous: traj.t[k - 1] });
        }
        for i in 0..limits.len() {
            let v = space.delta(i, traj.q[k - 1][i], traj.q[k][i]) / h;
            over(v, limits[i].max_velocity, traj.t[k], &names[i], true)?;
            let a = (traj.qd[k][i] - traj.qd[k - 1][i]) / h;
            over(a, limits[i].max_acceleration, traj.t[k], &names[i], false)?;
        }
    }
    Ok(())
}

fn over(value: f64, limit: f64, t: f64, joint: &str, velocity: bool) -> Result<(), Violation> {
    let allowed = limit * (1.0 + LIMIT_TOLERANCE) + 1e-9;
    if value.abs() <= allowed {
        return Ok(());
    }
    let (joint, by) = (joint.to_string(), value.abs() - limit);
    Err(if velocity {
        Violation::Velocity { t, joint, value, limit, by }
    } else {
        Violation::Acceleration { t, joint, value, limit, by }
    })
}

fn check_waypoint(model: &CollisionModel, index: usize, q: &[f64]) -> Result<(), Violation> {
    let robot = model.robot();
    if q.len() != robot.dof() {
        return Err(Violation::WrongDof { index, expected: robot.dof(), got: q.len() });
    }
    for (i, (&value, l)) in q.iter().zip(robot.limits()).enumerate() {
        let joint = || robot.dof_joint(i).name.clone();
        if !value.is_finite() {
            return Err(Violation::NotFinite { index, joint: joint(), value });
        }
        let by = (l.lower - value).max(value - l.upper);
        if by > 1e-9 {
            return Err(Violation::OutOfLimits { index, joint: joint(), value, lower: l.lower, upper: l.upper, by });
        }
    }
    if let Some(contact) = model.first_collision(q) {
        return Err(Violation::WaypointCollision { index, contact: contact.to_string() });
    }
    Ok(())
}

fn check_segment(
    model: &CollisionModel,
    space: &ConfigSpace,
    index: usize,
    a: &[f64],
    b: &[f64],
    resolution: f64,
) -> Result<(), Violation> {
    if model.motion_is_free(a, b, resolution) {
        return Ok(());
    }
    // Find the first colliding point in order, to say where.
    let steps = (space.max_joint_step(a, b) / resolution).ceil().clamp(1.0, 1e7) as usize;
    for k in 0..=steps {
        let fraction = k as f64 / steps as f64;
        if let Some(contact) = model.first_collision(&space.interpolate(a, b, fraction)) {
            return Err(Violation::SegmentCollision { index, fraction, contact: contact.to_string() });
        }
    }
    Err(Violation::SegmentCollision { index, fraction: f64::NAN, contact: "reported by motion_is_free".into() })
}
