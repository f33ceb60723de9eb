//! The streaming limits checker: samples are fed one at a time (a trajectory's, or a run log's
//! read line by line) and checked against the robot's position, velocity and acceleration
//! limits.

use std::time::Instant;

use embodied_models::JointLimits;
use embodied_models::{ConfigSpace, Robot, ScrewTriangle};

use super::finding::Finding;
use super::report::{CheckSettings, LimitsReport};

/// Checks joint positions, velocities and accelerations against a robot's limits, one sample
/// at a time.
///
/// For every sample and joint, in this order: the position against `[lower, upper]` (up to
/// [`CheckSettings::position_tolerance`]); the stated velocity against the velocity limit; then,
/// from the second sample on, the finite difference of the positions against the velocity
/// limit (unless [`LimitsChecker::without_position_differences`]) and the finite difference of
/// the stated velocities against the acceleration limit. Velocity and acceleration limits hold up
/// to [`CheckSettings::limit_tolerance`] relative. Then, for a robot with actuators
/// ([`Robot::actuators`]), every screw's length against its stroke (up to the position
/// tolerance, in metres) and its speed `dl/dq qd` (from the stated velocities) against its speed
/// limit. Every limit exceeded counts as one violation; the first one is kept.
#[derive(Debug, Clone)]
pub struct LimitsChecker {
    limits: Vec<JointLimits>,
    /// Screws driving joints through triangles: stroke and speed checked too.
    actuators: Vec<ScrewTriangle>,
    names: Vec<String>,
    space: ConfigSpace,
    limit_tolerance: f64,
    position_tolerance: f64,
    velocity_source: String,
    position_differences: bool,
    /// Time of the previous sample (`None` before the first), and its positions and velocities.
    previous: Option<f64>,
    previous_q: Vec<f64>,
    previous_qd: Vec<f64>,
    first: Option<Finding>,
    violations: usize,
    samples: usize,
    max_velocity_ratio: f64,
    max_acceleration_ratio: f64,
    started: Instant,
}

impl LimitsChecker {
    /// A checker for `robot`'s limits with `settings`' tolerances. Stated velocities are named
    /// `qd` in findings.
    pub fn new(robot: &Robot, settings: &CheckSettings) -> Self {
        Self {
            limits: robot.limits(),
            actuators: robot.actuators().to_vec(),
            names: robot.joint_names(),
            space: robot.config_space(),
            limit_tolerance: settings.limit_tolerance,
            position_tolerance: settings.position_tolerance,
            velocity_source: "qd".into(),
            position_differences: true,
            previous: None,
            previous_q: Vec::new(),
            previous_qd: Vec::new(),
            first: None,
            violations: 0,
            samples: 0,
            max_velocity_ratio: 0.0,
            max_acceleration_ratio: 0.0,
            started: Instant::now(),
        }
    }

    /// Name the stated velocities `source` in [`Finding::Velocity`] (e.g. `logged qd`).
    pub fn with_velocity_source(mut self, source: impl Into<String>) -> Self {
        self.velocity_source = source.into();
        self
    }

    /// Do not check the finite difference of positions against the velocity limit (for samples
    /// whose velocities are measured, not planned, such as a run log's).
    pub fn without_position_differences(mut self) -> Self {
        self.position_differences = false;
        self
    }

    /// Check the sample at time `t` (s) with positions `q` and velocities `qd`; finite
    /// differences use the time since the previous sample. Returns the number of limits it
    /// exceeds.
    pub fn push(&mut self, t: f64, q: &[f64], qd: &[f64]) -> usize {
        let h = self.previous.map_or(f64::NAN, |tp| t - tp);
        self.push_with_interval(t, h, q, qd)
    }

    /// [`LimitsChecker::push`] with the interval `h` (s) to the previous sample given (a log
    /// knows it as a whole number of control periods).
    pub fn push_with_interval(&mut self, t: f64, h: f64, q: &[f64], qd: &[f64]) -> usize {
        self.samples += 1;
        let dof = self.limits.len();
        if q.len() != dof || qd.len() != dof {
            let message =
                format!("sample at t = {t} s: {} positions and {} velocities for {dof} joints", q.len(), qd.len());
            self.note(Finding::Malformed { message });
            self.previous = None;
            return 1;
        }
        let before = self.violations;
        let rel = 1.0 + self.limit_tolerance;
        for (i, l) in self.limits.iter().enumerate() {
            let joint = || self.names[i].clone();
            let value = q[i];
            let excess = (l.lower - value).max(value - l.upper);
            let mut found: Vec<Finding> = Vec::new();
            if excess > self.position_tolerance {
                found.push(Finding::Position { t, joint: joint(), value, lower: l.lower, upper: l.upper, excess });
            }
            let velocity = |value: f64, source: &str, found: &mut Vec<Finding>, vr: &mut f64| {
                *vr = vr.max(value.abs() / l.max_velocity);
                if value.abs() > l.max_velocity * rel + 1e-12 {
                    found.push(Finding::Velocity {
                        t,
                        joint: joint(),
                        value,
                        limit: l.max_velocity,
                        excess: value.abs() - l.max_velocity,
                        source: source.into(),
                    });
                }
            };
            let mut vr = self.max_velocity_ratio;
            velocity(qd[i], &self.velocity_source, &mut found, &mut vr);
            if self.previous.is_some() {
                if self.position_differences {
                    let v = self.space.delta(i, self.previous_q[i], value) / h;
                    velocity(v, "finite difference of q", &mut found, &mut vr);
                }
                let a = (qd[i] - self.previous_qd[i]) / h;
                self.max_acceleration_ratio = self.max_acceleration_ratio.max(a.abs() / l.max_acceleration);
                if a.abs() > l.max_acceleration * rel + 1e-12 {
                    found.push(Finding::Acceleration {
                        t,
                        joint: joint(),
                        value: a,
                        limit: l.max_acceleration,
                        excess: a.abs() - l.max_acceleration,
                    });
                }
            }
            self.max_velocity_ratio = vr;
            for f in found {
                self.violations += 1;
                if self.first.is_none() {
                    self.first = Some(f);
                }
            }
        }
        let found = self.check_actuators(t, q, Some(qd));
        for f in found {
            self.note(f);
        }
        self.previous = Some(t);
        self.previous_q.clear();
        self.previous_q.extend_from_slice(q);
        self.previous_qd.clear();
        self.previous_qd.extend_from_slice(qd);
        self.violations - before
    }

    /// Check only the positions `q` of a sample at `t` (a waypoint of an untimed path: no
    /// velocities, no finite differences). Returns the number of joints out of limits.
    pub fn push_positions(&mut self, t: f64, q: &[f64]) -> usize {
        self.samples += 1;
        let dof = self.limits.len();
        if q.len() != dof {
            let message = format!("sample at t = {t}: {} positions for {dof} joints", q.len());
            self.note(Finding::Malformed { message });
            return 1;
        }
        let before = self.violations;
        for (i, l) in self.limits.iter().enumerate() {
            let value = q[i];
            let excess = (l.lower - value).max(value - l.upper);
            if excess > self.position_tolerance {
                let joint = self.names[i].clone();
                let f = Finding::Position { t, joint, value, lower: l.lower, upper: l.upper, excess };
                self.violations += 1;
                if self.first.is_none() {
                    self.first = Some(f);
                }
            }
        }
        for f in self.check_actuators(t, q, None) {
            self.note(f);
        }
        self.violations - before
    }

    /// Actuator strokes at `q` and, with velocities, speeds at `(q, qd)`.
    fn check_actuators(&mut self, t: f64, q: &[f64], qd: Option<&[f64]>) -> Vec<Finding> {
        let mut found = Vec::new();
        let rel = 1.0 + self.limit_tolerance;
        for a in &self.actuators {
            let length = a.length(q);
            let excess = a.stroke_excess(q);
            if excess > self.position_tolerance {
                let limit = if length < a.min_length { a.min_length } else { a.max_length };
                found.push(Finding::Actuator {
                    t,
                    actuator: a.name.clone(),
                    what: "length".into(),
                    value: length,
                    limit,
                    excess,
                });
            }
            if let Some(qd) = qd {
                let rate = a.rate(q, qd);
                self.max_velocity_ratio = self.max_velocity_ratio.max(rate.abs() / a.max_speed);
                if rate.abs() > a.max_speed * rel + 1e-12 {
                    found.push(Finding::Actuator {
                        t,
                        actuator: a.name.clone(),
                        what: "speed".into(),
                        value: rate,
                        limit: a.max_speed,
                        excess: rate.abs() - a.max_speed,
                    });
                }
            }
        }
        found
    }

    fn note(&mut self, f: Finding) {
        self.violations += 1;
        if self.first.is_none() {
            self.first = Some(f);
        }
    }

    /// The first limit exceeded so far.
    pub fn first(&self) -> Option<&Finding> {
        self.first.as_ref()
    }

    /// Limits exceeded so far (once per sample, joint and kind).
    pub fn violations(&self) -> usize {
        self.violations
    }

    /// Samples checked so far.
    pub fn samples(&self) -> usize {
        self.samples
    }

    /// Largest |velocity| / limit so far.
    pub fn max_velocity_ratio(&self) -> f64 {
        self.max_velocity_ratio
    }

    /// Largest |acceleration| / limit so far.
    pub fn max_acceleration_ratio(&self) -> f64 {
        self.max_acceleration_ratio
    }

    /// The report so far (its time is the wall-clock time since the checker was made).
    pub fn report(&self) -> LimitsReport {
        LimitsReport {
            ok: self.first.is_none(),
            violation: self.first.clone(),
            violations: self.violations,
            samples: self.samples,
            max_velocity_ratio: self.max_velocity_ratio,
            max_acceleration_ratio: self.max_acceleration_ratio,
            time_s: self.started.elapsed().as_secs_f64(),
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use embodied_models::builtin;

    use super::*;

    /// Fed one sample at a time, the checker finds each kind of violation at its sample, keeps
    /// the first, counts all, and tracks the peak ratios.
    #[test]
    fn streaming_checker_finds_each_limit() {
        let robot = builtin("irp6-postument").unwrap();
        let l = robot.limits();
        let dof = robot.dof();
        let mut c = LimitsChecker::new(&robot, &CheckSettings::default());
        let middle: Vec<f64> = l.iter().map(|l| 0.5 * (l.lower + l.upper)).collect();
        let mut q = middle.clone();
        let zero = vec![0.0; dof];
        assert_eq!(c.push(0.0, &q, &zero), 0, "{:?}", c.first());
        // Half the velocity limit of joint 0, reached from rest within its acceleration limit.
        let v = 0.5 * l[0].max_velocity;
        let h = 1.1 * v / l[0].max_acceleration;
        q[0] += v * h;
        let mut qd = zero.clone();
        qd[0] = v;
        assert_eq!(c.push(h, &q, &qd), 0, "{:?}", c.first());
        assert!((c.max_velocity_ratio() - 0.5).abs() < 1e-9);
        // A jump in position: the finite difference of q exceeds the velocity limit.
        q[0] += 3.0 * l[0].max_velocity * h;
        assert_eq!(c.push(2.0 * h, &q, &qd), 1);
        match c.first() {
            Some(Finding::Velocity { joint, source, .. }) => {
                assert_eq!(joint, &robot.joint_names()[0]);
                assert_eq!(source, "finite difference of q");
            }
            other => panic!("{other:?}"),
        }
        // Joint 1 out of its position limits (so moving too fast, and both screws beyond their
        // strokes: the lower arm's drives joint 1, the upper arm's its absolute angle) and joint 0
        // stopping at once: five more violations, the first kept.
        q[1] = l[1].upper + 0.1;
        // Half a step later: stopping from v takes 2.2 / 1.1 times the acceleration limit.
        assert_eq!(c.push(2.5 * h, &q, &zero), 5, "position, velocity from q, acceleration, two strokes");
        assert_eq!(c.violations(), 6);
        assert_eq!(c.samples(), 4);
        assert!(matches!(c.first(), Some(Finding::Velocity { .. })));
        assert!(c.max_acceleration_ratio() > 1.0);
        // The same samples as a log would give them: measured velocities only.
        let mut log = LimitsChecker::new(&robot, &CheckSettings::default())
            .with_velocity_source("logged qd")
            .without_position_differences();
        assert_eq!(log.push_with_interval(0.0, f64::NAN, &middle, &zero), 0);
        qd[0] = 2.0 * l[0].max_velocity;
        assert_eq!(log.push_with_interval(0.001, 0.001, &middle, &qd), 2, "velocity and acceleration");
        assert!(matches!(log.first(), Some(Finding::Velocity { source, .. }) if source == "logged qd"));
        let report = log.report();
        assert!(!report.ok && report.violations == 2 && report.samples == 2);
        // A sample of the wrong length is malformed, not a panic.
        assert_eq!(log.push(0.002, &[0.0], &[0.0]), 1);
    }
}
