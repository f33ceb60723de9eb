//! Time parameterisation of a joint path into a [`Trajectory`] the executor can track.
//!
//! Each segment between waypoints is one synchronised trapezoidal (or triangular) velocity
//! profile: all joints move along the straight C-space segment with a common path parameter
//! `s(t)` in [0, 1], starting and ending at rest. The profile's peak `s'` and `s''` are the
//! largest every joint allows (`|dq_i| s' <= v_max,i`, `|dq_i| s'' <= a_max,i`), so the joint
//! whose limit binds moves at its limit. Stopping at waypoints costs time but keeps the path
//! exactly the one that was checked for collisions.

use embodied_models::Robot;

/// A time-parameterised joint trajectory: samples `(t, q, q-dot)`.
///
/// Between consecutive samples the acceleration is constant (the samples include every knot
/// where it changes), so [`Trajectory::sample`] is exact for trajectories built by
/// [`time_parameterize`], except where samples closer than 10 µs were merged (there the
/// interval's acceleration is the average over it, within the limits).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Trajectory {
    /// Names of the degrees of freedom, in the order of the values in `q` and `qd`.
    pub joint_names: Vec<String>,
    /// Sample times, seconds, strictly increasing from 0.
    pub t: Vec<f64>,
    /// Joint positions (rad or m), one vector per sample time.
    pub q: Vec<Vec<f64>>,
    /// Joint velocities (rad/s or m/s), one vector per sample time.
    pub qd: Vec<Vec<f64>>,
}

/// Where a time falls on a [`Trajectory`] (see `Trajectory::locate`).
enum At {
    /// At sample `k` (clamped into the span).
    Knot(usize),
    /// Inside sample interval `k` of length `h`, at fraction `s` of it.
    Inside(usize, f64, f64),
}

impl Trajectory {
    /// Total duration in seconds (0 for an empty trajectory).
    pub fn duration(&self) -> f64 {
        self.t.last().copied().unwrap_or(0.0)
    }

    /// Position, velocity and acceleration at time `t` (clamped into the trajectory's span):
    /// cubic Hermite interpolation of the samples, which reproduces the piecewise-quadratic
    /// motion of [`time_parameterize`] exactly. The acceleration is the interval's constant one,
    /// `(qd[k+1] - qd[k]) / h`: the Hermite second derivative, taken from positions, loses
    /// every digit on a short interval (positions rounded to 1e-15 over h = 2e-5 s give
    /// errors of 1e-5 rad/s², enough to read as over the limit).
    pub fn sample(&self, t: f64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let (k, h, s) = match self.locate(t) {
            None => return (Vec::new(), Vec::new(), Vec::new()),
            Some(At::Knot(k)) => return (self.q[k].clone(), self.qd[k].clone(), vec![0.0; self.q[k].len()]),
            Some(At::Inside(k, h, s)) => (k, h, s),
        };
        let dof = self.q[k].len();
        let (mut q, mut qd, mut qdd) = (vec![0.0; dof], vec![0.0; dof], vec![0.0; dof]);
        self.hermite_into(k, h, s, &mut q);
        for i in 0..dof {
            let (p0, p1) = (self.q[k][i], self.q[k + 1][i]);
            let (m0, m1) = (self.qd[k][i] * h, self.qd[k + 1][i] * h);
            let s2 = s * s;
            qd[i] = ((6.0 * s2 - 6.0 * s) * p0
                + (3.0 * s2 - 4.0 * s + 1.0) * m0
                + (-6.0 * s2 + 6.0 * s) * p1
                + (3.0 * s2 - 2.0 * s) * m1)
                / h;
            qdd[i] = (self.qd[k + 1][i] - self.qd[k][i]) / h;
        }
        (q, qd, qdd)
    }

    /// The position of [`Self::sample`] at time `t` into `out` (as many values as fit), with no
    /// allocation: for a control step that asks for many.
    pub fn sample_position_into(&self, t: f64, out: &mut [f64]) {
        match self.locate(t) {
            None => {}
            Some(At::Knot(k)) => out.iter_mut().zip(&self.q[k]).for_each(|(o, q)| *o = *q),
            Some(At::Inside(k, h, s)) => self.hermite_into(k, h, s, out),
        }
    }

    /// Where time `t` falls (`None` for an empty trajectory): clamped to the first or last
    /// sample (NaN to the first), else the sample interval holding it, its length and `t`'s
    /// fraction of it.
    fn locate(&self, t: f64) -> Option<At> {
        let n = self.t.len();
        if n == 0 {
            return None;
        }
        if n == 1 || t <= self.t[0] || t.is_nan() {
            return Some(At::Knot(0));
        }
        if t >= self.t[n - 1] {
            return Some(At::Knot(n - 1));
        }
        let k = self.t.partition_point(|&x| x <= t).saturating_sub(1).min(n - 2);
        let h = self.t[k + 1] - self.t[k];
        Some(At::Inside(k, h, (t - self.t[k]) / h))
    }

    /// The cubic Hermite position at fraction `s` of interval `k` (length `h`) into `q`.
    fn hermite_into(&self, k: usize, h: f64, s: f64, q: &mut [f64]) {
        let (s2, s3) = (s * s, s * s * s);
        let rows = self.q[k].iter().zip(&self.q[k + 1]).zip(self.qd[k].iter().zip(&self.qd[k + 1]));
        for (o, ((&p0, &p1), (&v0, &v1))) in q.iter_mut().zip(rows) {
            let (m0, m1) = (v0 * h, v1 * h);
            *o = (2.0 * s3 - 3.0 * s2 + 1.0) * p0
                + (s3 - 2.0 * s2 + s) * m0
                + (-2.0 * s3 + 3.0 * s2) * p1
                + (s3 - s2) * m1;
        }
    }
}

/// The synchronised rest-to-rest profile of one segment: times of the end of acceleration, the
/// start of deceleration and the end, with the peak rate and acceleration of `s`.
#[derive(Debug, Clone, Copy)]
struct Profile {
    t_acc: f64,
    t_dec: f64,
    t_end: f64,
    v: f64,
    a: f64,
}

impl Profile {
    /// `s`, `s'` at time `t` in [0, t_end].
    fn at(&self, t: f64) -> (f64, f64) {
        let t = t.clamp(0.0, self.t_end);
        if t <= self.t_acc {
            (0.5 * self.a * t * t, self.a * t)
        } else if t <= self.t_dec {
            (0.5 * self.a * self.t_acc * self.t_acc + self.v * (t - self.t_acc), self.v)
        } else {
            let r = self.t_end - t;
            (1.0 - 0.5 * self.a * r * r, self.a * r)
        }
    }
}

/// Relative margin kept below an actuator's speed limit: the screw's speed per unit path rate
/// is sampled along the segment (every [`ACTUATOR_STEP`] rad of the largest joint motion), and
/// it varies smoothly between the samples.
const ACTUATOR_MARGIN: f64 = 0.01;
/// Largest joint motion between two samples of an actuator's speed along a segment, rad or m.
const ACTUATOR_STEP: f64 = 0.01;

/// The largest `|dl/ds|` of every actuator of `robot` along the straight motion
/// `start + s delta`, `s` in [0, 1], sampled; one entry per actuator.
fn actuator_rates(start: &[f64], delta: &[f64], robot: &Robot) -> Vec<f64> {
    let span = delta.iter().fold(0.0_f64, |m, d| m.max(d.abs()));
    let n = ((span / ACTUATOR_STEP).ceil() as usize).clamp(4, 10_000);
    let mut q = start.to_vec();
    let mut worst = vec![0.0_f64; robot.actuators().len()];
    for k in 0..=n {
        let s = k as f64 / n as f64;
        for ((qi, &x), &d) in q.iter_mut().zip(start).zip(delta) {
            *qi = x + s * d;
        }
        for (w, a) in worst.iter_mut().zip(robot.actuators()) {
            *w = w.max(a.rate_along(&q, delta).abs());
        }
    }
    worst
}

fn profile(start: &[f64], delta: &[f64], robot: &Robot) -> Option<Profile> {
    let limits = robot.limits();
    let mut v = f64::INFINITY;
    let mut a = f64::INFINITY;
    for (d, l) in delta.iter().zip(&limits) {
        let d = d.abs();
        if d > 0.0 {
            v = v.min(l.max_velocity / d);
            a = a.min(l.max_acceleration / d);
        }
    }
    // Serial-parallel actuation: every screw within its speed limit along the whole segment.
    if !robot.actuators().is_empty() {
        for (rate, act) in actuator_rates(start, delta, robot).into_iter().zip(robot.actuators()) {
            if rate > 0.0 {
                v = v.min(act.max_speed / (rate * (1.0 + ACTUATOR_MARGIN)));
            }
        }
    }
    if !(v.is_finite() && a.is_finite() && v > 0.0 && a > 0.0) {
        return None;
    }
    if v * v / a >= 1.0 {
        // Triangular: never reaches the peak rate.
        let t_acc = (1.0 / a).sqrt();
        Some(Profile { t_acc, t_dec: t_acc, t_end: 2.0 * t_acc, v: a * t_acc, a })
    } else {
        let t_acc = v / a;
        let t_end = 1.0 / v + t_acc;
        Some(Profile { t_acc, t_dec: t_end - t_acc, t_end, v, a })
    }
}

/// Samples of one segment closer together than this (s) are merged.
const MIN_GAP: f64 = 1e-5;

/// The positive times of sorted `times` (the last one the segment's end), thinned so that
/// consecutive ones, and the first and the segment's start, are at least `gap` apart; the end
/// is always kept (it replaces the time before it when the two are too close). A velocity
/// difference over a sliver of time turns the velocities' rounding into an acceleration over
/// the limit (a grid sample 1e-8 s from a profile knot read 1.6e-9 over, relative); over any
/// interval the velocity difference is the average acceleration, so merging keeps every
/// sampled acceleration within the limits.
fn spread(times: &[f64], gap: f64) -> Vec<f64> {
    let mut kept: Vec<f64> = Vec::with_capacity(times.len());
    let positive: Vec<f64> = times.iter().copied().filter(|&t| t > 0.0).collect();
    for (k, &t) in positive.iter().enumerate() {
        if t - kept.last().copied().unwrap_or(0.0) < gap {
            if k + 1 < positive.len() {
                continue;
            }
            kept.pop();
        }
        kept.push(t);
    }
    kept
}

/// Time-parameterise `path` for `robot`: rest-to-rest synchronised trapezoids per segment,
/// within every joint's velocity and acceleration limit and every actuator's speed limit
/// ([`Robot::actuators`]: the segment's peak rate is the largest every screw allows anywhere
/// along it, so a screw near its fastest point slows the whole segment), passing exactly through every
/// waypoint. Sampled every `sample_dt` seconds plus every knot (waypoints and profile switch
/// points, merged where closer than 10 µs or a quarter of `sample_dt`); `sample_dt <= 0` or
/// NaN gives the knots only. Continuous joints move the short way
/// and stay unwrapped. Repeated waypoints are skipped.
pub fn time_parameterize(path: &[Vec<f64>], robot: &Robot, sample_dt: f64) -> Trajectory {
    let joint_names = robot.joint_names();
    let mut traj = Trajectory { joint_names, t: Vec::new(), q: Vec::new(), qd: Vec::new() };
    let Some(first) = path.first() else { return traj };
    let dof = first.len();
    let space = robot.config_space();
    let dt = if sample_dt.is_finite() && sample_dt > 0.0 { sample_dt } else { f64::INFINITY };
    let gap = MIN_GAP.min(0.25 * dt);
    let mut current = first.clone();
    traj.t.push(0.0);
    traj.q.push(current.clone());
    traj.qd.push(vec![0.0; dof]);
    let mut t0 = 0.0;
    for next in &path[1..] {
        if next.len() != dof {
            break;
        }
        let delta: Vec<f64> = (0..dof).map(|i| space.delta(i, current[i], next[i])).collect();
        let Some(p) = profile(&current, &delta, robot) else { continue };
        let mut times: Vec<f64> = Vec::new();
        if dt.is_finite() {
            let n = (p.t_end / dt).floor() as usize;
            times.extend((1..=n).map(|k| k as f64 * dt).filter(|&t| t < p.t_end - 1e-12));
        }
        times.extend([p.t_acc, p.t_dec, p.t_end]);
        times.sort_by(f64::total_cmp);
        times.dedup_by(|a, b| (*a - *b).abs() < 1e-12);
        let times = spread(&times, gap);
        let end: Vec<f64> = (0..dof).map(|i| current[i] + delta[i]).collect();
        for &t in &times {
            let (s, sd) = p.at(t);
            if (t - p.t_end).abs() < 1e-12 {
                traj.t.push(t0 + p.t_end);
                traj.q.push(end.clone());
                traj.qd.push(vec![0.0; dof]);
            } else {
                traj.t.push(t0 + t);
                traj.q.push((0..dof).map(|i| current[i] + s * delta[i]).collect());
                traj.qd.push((0..dof).map(|i| sd * delta[i]).collect());
            }
        }
        t0 += p.t_end;
        current = end;
    }
    traj
}

#[cfg(test)]
mod tests {
    use super::{spread, time_parameterize};

    /// The allocation-free position is `sample`'s to the bit: inside intervals, at knots,
    /// before the start, after the end and at NaN.
    #[test]
    fn position_into_is_the_sampled_position() {
        let robot = embodied_models::builtin("rnt").expect("built-in robot");
        let limits = robot.limits();
        let mut rng = embodied_models::Rng::new(4);
        for _ in 0..20 {
            let path: Vec<Vec<f64>> = (0..4)
                .map(|_| limits.iter().map(|l| rng.range(0.1, 0.9) * (l.upper - l.lower) + l.lower).collect())
                .collect();
            for dt in [0.0, 0.01] {
                let traj = time_parameterize(&path, &robot, dt);
                let end = traj.duration();
                let mut times: Vec<f64> = (0..500).map(|_| rng.range(-0.1, end + 0.1)).collect();
                times.extend(traj.t.iter().copied());
                times.extend([f64::NAN, -1.0, end, end + 1.0, 0.0]);
                let mut out = vec![7.0; robot.dof()];
                for t in times {
                    traj.sample_position_into(t, &mut out);
                    let (q, _, _) = traj.sample(t);
                    let same = q.iter().zip(&out).all(|(a, b)| a.to_bits() == b.to_bits());
                    assert!(same, "t = {t}: {out:?} against {q:?}");
                }
            }
        }
    }

    #[test]
    fn samples_closer_than_the_gap_are_merged_and_the_end_is_kept() {
        let gap = 1e-5;
        // A grid time 1e-8 s before a knot: the knot is dropped, not the grid time.
        assert_eq!(spread(&[0.0, 0.001, 0.002 - 1e-8, 0.002, 0.003], gap), vec![0.001, 0.002 - 1e-8, 0.003]);
        // The end replaces the time just before it.
        assert_eq!(spread(&[0.001, 0.002, 0.002 + 1e-9], gap), vec![0.001, 0.002 + 1e-9]);
        // A first time too close to the start goes; a segment shorter than the gap keeps its end.
        assert_eq!(spread(&[1e-7, 0.001], gap), vec![0.001]);
        assert_eq!(spread(&[1e-7, 2e-7], gap), vec![2e-7]);
        let out = spread(&[0.0, 1e-6, 5e-6, 1.2e-5, 2e-5, 3.5e-5, 3.6e-5], gap);
        assert_eq!(out.last(), Some(&3.6e-5));
        assert!(out.windows(2).all(|w| w[1] - w[0] >= gap), "{out:?}");
    }
}
