//! Timed joint trajectories, their time parameterisation and the verifier-side checks a plan
//! must pass before it may drive an effector.
//!
//! The verifier here shares no code with the planners that produce trajectories: it checks the
//! samples themselves (finite numbers, position bounds, velocity and acceleration recomputed from
//! the positions by finite differences) and collisions at a stated fine resolution.

use embodied_models::{CollisionModel, JointLimits};

/// A trajectory sampled at a fixed period: `q[k]`, `qd[k]` at time `t[k] = k * dt`.
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    pub joint_names: Vec<String>,
    pub t: Vec<f64>,
    pub q: Vec<Vec<f64>>,
    pub qd: Vec<Vec<f64>>,
}

impl Trajectory {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t.len()
    }
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }
    /// Duration in seconds (time of the last sample).
    pub fn duration(&self) -> f64 {
        self.t.last().copied().unwrap_or(0.0)
    }
    /// First configuration.
    pub fn start(&self) -> Option<&[f64]> {
        self.q.first().map(Vec::as_slice)
    }
    /// Last configuration.
    pub fn end(&self) -> Option<&[f64]> {
        self.q.last().map(Vec::as_slice)
    }
    /// Position and velocity at time `t`, linearly interpolated and held at the ends.
    pub fn sample(&self, t: f64, q: &mut [f64], qd: &mut [f64]) {
        let n = self.t.len();
        if n == 0 {
            return;
        }
        let k = self.t.partition_point(|s| *s <= t);
        if k == 0 || k >= n {
            let idx = if k == 0 { 0 } else { n - 1 };
            q.iter_mut().zip(&self.q[idx]).for_each(|(d, s)| *d = *s);
            let at_rest = k >= n;
            qd.iter_mut().zip(&self.qd[idx]).for_each(|(d, s)| *d = if at_rest { 0.0 } else { *s });
            return;
        }
        let (t0, t1) = (self.t[k - 1], self.t[k]);
        let u = if t1 > t0 { ((t - t0) / (t1 - t0)).clamp(0.0, 1.0) } else { 1.0 };
        for j in 0..q.len().min(self.q[k].len()) {
            q[j] = self.q[k - 1][j] + u * (self.q[k][j] - self.q[k - 1][j]);
            qd[j] = self.qd[k - 1][j] + u * (self.qd[k][j] - self.qd[k - 1][j]);
        }
    }
}

/// Turn a piecewise-linear joint path into a [`Trajectory`] sampled every `dt`: each segment is a
/// rest-to-rest trapezoidal profile (all joints synchronised, so the motion stays on the
/// segment), at `margin` (in (0, 1]) of the velocity and acceleration limits.
pub fn time_parameterize(
    path: &[Vec<f64>],
    limits: &[JointLimits],
    joint_names: &[String],
    dt: f64,
    margin: f64,
) -> Trajectory {
    let margin = if margin > 0.0 && margin <= 1.0 { margin } else { 0.95 };
    let dof = limits.len();
    let mut traj = Trajectory { joint_names: joint_names.to_vec(), t: Vec::new(), q: Vec::new(), qd: Vec::new() };
    let Some(first) = path.first() else { return traj };
    traj.t.push(0.0);
    traj.q.push(first.clone());
    traj.qd.push(vec![0.0; dof]);
    let mut t_offset = 0.0;
    for w in path.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        // Scalar profile s(t) in [0, 1]: the tightest joint sets the limits.
        let (mut vs, mut as_) = (f64::INFINITY, f64::INFINITY);
        for j in 0..dof {
            let d = (b[j] - a[j]).abs();
            if d > 0.0 {
                vs = vs.min(margin * limits[j].max_velocity / d);
                as_ = as_.min(margin * limits[j].max_acceleration / d);
            }
        }
        if !vs.is_finite() || !as_.is_finite() {
            continue;
        }
        // Triangle if the cruise speed is never reached.
        let (t_acc, t_total) = if vs * vs / as_ >= 1.0 {
            let ta = (1.0 / as_).sqrt();
            vs = as_ * ta;
            (ta, 2.0 * ta)
        } else {
            let ta = vs / as_;
            (ta, 1.0 / vs + ta)
        };
        let profile = |t: f64| -> (f64, f64) {
            if t <= t_acc {
                (0.5 * as_ * t * t, as_ * t)
            } else if t <= t_total - t_acc {
                (0.5 * as_ * t_acc * t_acc + vs * (t - t_acc), vs)
            } else {
                let r = (t_total - t).max(0.0);
                (1.0 - 0.5 * as_ * r * r, as_ * r)
            }
        };
        // Samples on the global grid k*dt; the segment ends at rest on a grid point.
        let steps = ((t_total / dt).ceil() as usize).max(1);
        let stretch = (steps as f64 * dt) / t_total;
        for k in 1..=steps {
            let (s, sd) = if k == steps { (1.0, 0.0) } else { profile(k as f64 * dt / stretch) };
            let sd = sd / stretch;
            traj.t.push(t_offset + k as f64 * dt);
            traj.q.push((0..dof).map(|j| a[j] + s * (b[j] - a[j])).collect());
            traj.qd.push((0..dof).map(|j| sd * (b[j] - a[j])).collect());
        }
        t_offset += steps as f64 * dt;
    }
    traj
}

/// Why a trajectory may not drive an effector.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum TrajectoryViolation {
    #[error("empty trajectory")]
    Empty,
    #[error("sample {sample}: expected {expected} joint values, got {got}")]
    Dimension { sample: usize, expected: usize, got: usize },
    #[error("sample {sample}: non-finite value")]
    NonFinite { sample: usize },
    #[error("sample {sample}: times must increase")]
    Time { sample: usize },
    #[error("sample {sample}: joint {joint} position {value:.4} outside [{lower:.4}, {upper:.4}]")]
    Position { sample: usize, joint: usize, value: f64, lower: f64, upper: f64 },
    #[error("sample {sample}: joint {joint} velocity {value:.4} exceeds {limit:.4}")]
    Velocity { sample: usize, joint: usize, value: f64, limit: f64 },
    #[error("sample {sample}: joint {joint} acceleration {value:.4} exceeds {limit:.4}")]
    Acceleration { sample: usize, joint: usize, value: f64, limit: f64 },
    #[error("sample {sample}: collision ({contact})")]
    Collision { sample: usize, contact: String },
    #[error("does not start at rest (joint {joint} velocity {value:.4})")]
    NotAtRestAtStart { joint: usize, value: f64 },
    #[error("does not end at rest (joint {joint} velocity {value:.4})")]
    NotAtRestAtEnd { joint: usize, value: f64 },
}

/// Relative tolerance on velocity and acceleration limits (rounding of sampled profiles).
const LIMIT_TOLERANCE: f64 = 1e-3;

/// Check `traj` against `limits` and, when given, `collision` at `resolution` (rad/m between
/// checked configurations). Velocities and accelerations are recomputed from the positions by
/// finite differences, so a trajectory whose `qd` lies cannot pass.
pub fn verify_trajectory(
    traj: &Trajectory,
    limits: &[JointLimits],
    collision: Option<&CollisionModel>,
    resolution: f64,
) -> Result<(), TrajectoryViolation> {
    let dof = limits.len();
    if traj.is_empty() {
        return Err(TrajectoryViolation::Empty);
    }
    if traj.q.len() != traj.t.len() || traj.qd.len() != traj.t.len() {
        return Err(TrajectoryViolation::Dimension { sample: 0, expected: traj.t.len(), got: traj.q.len() });
    }
    for k in 0..traj.len() {
        for v in [&traj.q[k], &traj.qd[k]] {
            if v.len() != dof {
                return Err(TrajectoryViolation::Dimension { sample: k, expected: dof, got: v.len() });
            }
            if v.iter().any(|x| !x.is_finite()) {
                return Err(TrajectoryViolation::NonFinite { sample: k });
            }
        }
        if !traj.t[k].is_finite() || (k > 0 && traj.t[k] <= traj.t[k - 1]) {
            return Err(TrajectoryViolation::Time { sample: k });
        }
        for (j, l) in limits.iter().enumerate() {
            let value = traj.q[k][j];
            if value < l.lower - 1e-9 || value > l.upper + 1e-9 {
                return Err(TrajectoryViolation::Position {
                    sample: k,
                    joint: j,
                    value,
                    lower: l.lower,
                    upper: l.upper,
                });
            }
            let v = traj.qd[k][j];
            if v.abs() > l.max_velocity * (1.0 + LIMIT_TOLERANCE) {
                return Err(TrajectoryViolation::Velocity { sample: k, joint: j, value: v, limit: l.max_velocity });
            }
        }
    }
    for (j, v) in traj.qd[0].iter().enumerate() {
        if v.abs() > 1e-9 {
            return Err(TrajectoryViolation::NotAtRestAtStart { joint: j, value: *v });
        }
    }
    for (j, v) in traj.qd[traj.len() - 1].iter().enumerate() {
        if v.abs() > 1e-9 {
            return Err(TrajectoryViolation::NotAtRestAtEnd { joint: j, value: *v });
        }
    }
    // Finite differences: the velocity the positions imply, and its rate of change.
    let mut prev_v = vec![0.0; dof];
    for k in 1..traj.len() {
        let h = traj.t[k] - traj.t[k - 1];
        for (j, l) in limits.iter().enumerate() {
            let v = (traj.q[k][j] - traj.q[k - 1][j]) / h;
            if v.abs() > l.max_velocity * (1.0 + LIMIT_TOLERANCE) + 1e-9 {
                return Err(TrajectoryViolation::Velocity { sample: k, joint: j, value: v, limit: l.max_velocity });
            }
            let a = (v - prev_v[j]) / h;
            if a.abs() > l.max_acceleration * (1.0 + LIMIT_TOLERANCE) + 1e-6 {
                return Err(TrajectoryViolation::Acceleration {
                    sample: k,
                    joint: j,
                    value: a,
                    limit: l.max_acceleration,
                });
            }
            prev_v[j] = v;
        }
    }
    if let Some(model) = collision {
        let resolution = if resolution > 0.0 && resolution.is_finite() { resolution } else { 0.01 };
        let mut scratch = model.scratch();
        if model.collides_with(&traj.q[0], &mut scratch) {
            return Err(collision_at(model, traj, 0));
        }
        // Consecutive samples are joined by straight segments; they are checked in strides of
        // at most four resolutions, each at `resolution` (a chord error far below it).
        let stride = 4.0 * resolution;
        let mut knot = 0;
        for k in 1..traj.len() {
            let last = k + 1 == traj.len();
            let next_far = !last && traj.q[k + 1].iter().zip(&traj.q[knot]).any(|(a, b)| (a - b).abs() > stride);
            if last || next_far {
                if !model.motion_is_free_with(&traj.q[knot], &traj.q[k], resolution, &mut scratch) {
                    return Err(collision_at(model, traj, k));
                }
                knot = k;
            }
        }
    }
    Ok(())
}

fn collision_at(model: &CollisionModel, traj: &Trajectory, k: usize) -> TrajectoryViolation {
    let contact = model.first_collision(&traj.q[k]).map_or_else(|| "between samples".to_string(), |c| c.to_string());
    TrajectoryViolation::Collision { sample: k, contact }
}
