//! Effectors `e_j`: what executes `c^{i+1}_e`.
//!
//! * [`Effector`]: one small trait per capability (openrr's arci style).
//! * [`ServoModel`]: a simulated joint servo, tracking position or velocity targets within the
//!   robot's limits.
//! * [`SafetyLimiter`]: a decorator implementing the same trait that makes every command respect
//!   position, velocity and acceleration limits (and, for serial-parallel robots, the speed
//!   limits of the screws driving joints) before the wrapped effector sees it. It enforces
//!   limits by wrapping, from the measured state, not by remembering earlier commands.
//! * [`SafeHalt`]: the controlled stop (stop category 2) used when a specification error or a
//!   late plan leaves nothing sensible to command and no path is being followed.
//! * [`PathHalt`]: the controlled stop along the path being followed (a time-scaling of that
//!   path), and [`BrakeHalt`], the stops off the path used when the stop along it would collide.

use embodied_models::{JointLimits, ScrewTriangle};
use embodied_planner::trajectory::Trajectory;

use crate::error::ExecutorError;
use crate::image::{CommandMode, InputImages, JointCommand, OutputImages};
use crate::transition::TransitionFunction;

/// An effector: it executes joint commands and reports its state (the source of `c^i_e`).
pub trait Effector: Send {
    /// Limits of the joints, one per degree of freedom.
    fn limits(&self) -> &[JointLimits];
    /// Measured joint positions.
    fn q(&self) -> &[f64];
    /// Measured joint velocities.
    fn qd(&self) -> &[f64];
    /// Execute `command` for one control period `dt`.
    fn execute(&mut self, command: &JointCommand, dt: f64);
    /// Execute a command that a [`SafetyLimiter`] has already made feasible for the current
    /// measured state: the consistent one-step command `q + v dt` with feed-forward velocity `v`
    /// inside the [`velocity_window`]. The default is [`Effector::execute`]; an effector may
    /// skip recomputing what the limiter guarantees, but must still never exceed its limits.
    fn execute_limited(&mut self, command: &JointCommand, dt: f64) {
        self.execute(command, dt)
    }
}

impl Effector for Box<dyn Effector> {
    fn limits(&self) -> &[JointLimits] {
        (**self).limits()
    }
    fn q(&self) -> &[f64] {
        (**self).q()
    }
    fn qd(&self) -> &[f64] {
        (**self).qd()
    }
    fn execute(&mut self, command: &JointCommand, dt: f64) {
        (**self).execute(command, dt)
    }
    fn execute_limited(&mut self, command: &JointCommand, dt: f64) {
        (**self).execute_limited(command, dt)
    }
}

/// Check that limits can be enforced: positive finite velocity and acceleration bounds,
/// `lower <= upper`.
pub fn validate_limits(limits: &[JointLimits]) -> Result<(), ExecutorError> {
    for (joint, l) in limits.iter().enumerate() {
        let reason = if !(l.max_velocity > 0.0 && l.max_velocity.is_finite()) {
            "max_velocity must be positive and finite"
        } else if !(l.max_acceleration > 0.0 && l.max_acceleration.is_finite()) {
            "max_acceleration must be positive and finite"
        } else if l.lower.is_nan() || l.upper.is_nan() || l.lower > l.upper {
            "lower must not exceed upper"
        } else {
            continue;
        };
        return Err(ExecutorError::InvalidLimits { joint, reason: reason.to_string() });
    }
    Ok(())
}

/// The velocities `[lo, hi]` a joint at position `q` moving at `v` may take in the next step:
/// within `±max_velocity`, within `±max_acceleration * dt` of `v`, and slow enough to stop
/// before a position bound decelerating at `max_acceleration` (so that bounds are never
/// crossed). From a state that already violates the last condition the window is the hardest
/// allowed braking.
#[inline(always)]
pub fn velocity_window(q: f64, v: f64, lim: &JointLimits, dt: f64) -> (f64, f64) {
    let a = lim.max_acceleration;
    let mut lo = (-lim.max_velocity).max(v - a * dt);
    let mut hi = lim.max_velocity.min(v + a * dt);
    // Stopping distance after one step at v' with semi-implicit integration is at most
    // v' dt + v'^2 / (2a); keep it within the remaining room d.
    let bound = |d: f64| -a * dt + (a * a * dt * dt + 2.0 * a * d.max(0.0)).sqrt();
    // Far from a bound the square root is skipped: if `x + 2 a dt <= 0` or `(x + 2 a dt)^2 <
    // 2 a d`, then `bound(d) > x + a dt > x` (a margin of `a dt`, far above rounding), so
    // `min(x, bound(d)) = x` exactly.
    let far = |x: f64, d: f64| {
        let s = x + 2.0 * a * dt;
        s <= 0.0 || s * s < 2.0 * a * d
    };
    if lim.upper.is_finite() && !far(hi, lim.upper - q) {
        hi = hi.min(bound(lim.upper - q));
    }
    if lim.lower.is_finite() && !far(-lo, q - lim.lower) {
        lo = lo.max(-bound(q - lim.lower));
    }
    if lo > hi {
        let brake = 0.0_f64.clamp(v - a * dt, v + a * dt);
        return (brake, brake);
    }
    (lo, hi)
}

fn finite_or(x: f64, fallback: f64) -> f64 {
    if x.is_finite() { x } else { fallback }
}

/// A simulated servo: per joint, a velocity-level tracking law integrated at `dt`, saturated
/// by [`velocity_window`] so that the simulated joints never exceed their limits.
///
/// Position mode: `v = qd_ff + k (q_target - (q + qd_ff dt))` (the error is taken w.r.t. where
/// the feed-forward velocity alone would lead, so a consistent trajectory is tracked exactly),
/// with the correction capped at `sqrt(2 a |e|)` so the servo brakes into the target.
/// Velocity mode: `v = qd`. Non-finite targets are ignored (the joint brakes to rest).
#[derive(Debug, Clone)]
pub struct ServoModel {
    limits: Vec<JointLimits>,
    q: Vec<f64>,
    qd: Vec<f64>,
    gain: f64,
}

impl ServoModel {
    /// A servo at rest at `q0`, positions clamped into the limits.
    pub fn new(limits: Vec<JointLimits>, q0: &[f64]) -> Result<Self, ExecutorError> {
        validate_limits(&limits)?;
        if q0.len() != limits.len() {
            return Err(ExecutorError::DimensionMismatch {
                what: "initial configuration".into(),
                expected: limits.len(),
                got: q0.len(),
            });
        }
        let q = q0.iter().zip(&limits).map(|(q, l)| l.clamp(finite_or(*q, 0.0))).collect();
        let qd = vec![0.0; limits.len()];
        Ok(Self { limits, q, qd, gain: 50.0 })
    }
    /// Position-loop gain in 1/s (default 50); capped at `1/dt` when used.
    pub fn with_gain(mut self, gain: f64) -> Self {
        self.gain = finite_or(gain, 50.0).max(0.0);
        self
    }
}

impl Effector for ServoModel {
    fn limits(&self) -> &[JointLimits] {
        &self.limits
    }
    fn q(&self) -> &[f64] {
        &self.q
    }
    fn qd(&self) -> &[f64] {
        &self.qd
    }
    fn execute(&mut self, command: &JointCommand, dt: f64) {
        for i in 0..self.limits.len() {
            let lim = &self.limits[i];
            let (q, v) = (self.q[i], self.qd[i]);
            let desired = tracking_velocity(command, i, q, lim, self.gain, dt);
            let (lo, hi) = velocity_window(q, v, lim, dt);
            let v_next = desired.clamp(lo, hi);
            self.qd[i] = v_next;
            self.q[i] = lim.clamp(q + v_next * dt);
        }
    }
    /// The limiter already tracked the target and clamped the velocity into the window of this
    /// very state, so the tracking law would reproduce its feed-forward velocity; the servo only
    /// re-checks (without square roots) the hard bounds: velocity, acceleration and position.
    fn execute_limited(&mut self, command: &JointCommand, dt: f64) {
        let n = self.limits.len().min(command.qd.len());
        let joints = self.limits.iter().zip(self.q.iter_mut()).zip(self.qd.iter_mut()).zip(&command.qd);
        for (((lim, q), v), &wanted) in joints {
            let dv = lim.max_acceleration * dt;
            // max/min rather than clamp: no panic whatever `dt` a caller passes.
            let v_next = finite_or(wanted, 0.0).max(*v - dv).min(*v + dv).max(-lim.max_velocity).min(lim.max_velocity);
            *v = v_next;
            *q = lim.clamp(*q + v_next * dt);
        }
        // A short command (never produced by the limiter) brakes the remaining joints.
        for i in n..self.limits.len() {
            let lim = &self.limits[i];
            let (q, v) = (self.q[i], self.qd[i]);
            let (lo, hi) = velocity_window(q, v, lim, dt);
            let v_next = 0.0_f64.max(lo).min(hi);
            self.qd[i] = v_next;
            self.q[i] = lim.clamp(q + v_next * dt);
        }
    }
}

/// The largest deviation (rad or m) of a joint's measured position from the position its last
/// limited command asked for that still counts as following it: a tenth of what one step at the
/// joint's acceleration limit changes (`0.1 a dt^2`). A healthy effector is exact to rounding
/// (1e-16 relative); an effector that does not follow its command deviates by up to `2 a dt^2`
/// per step, more if it slips.
pub fn tracking_bound(lim: &JointLimits, dt: f64) -> f64 {
    0.1 * lim.max_acceleration * dt * dt
}

/// The velocity joint `i` at `q` should take to follow `command` (see [`ServoModel`]); zero for
/// non-finite targets.
#[inline]
pub fn tracking_velocity(command: &JointCommand, i: usize, q: f64, lim: &JointLimits, gain: f64, dt: f64) -> f64 {
    track(command.mode, command.q.get(i).copied(), command.qd.get(i).copied(), q, lim, gain.min(1.0 / dt), dt)
}

/// [`tracking_velocity`] for one joint with the loop gain `k = min(gain, 1/dt)` given.
#[inline(always)]
fn track(mode: CommandMode, target: Option<f64>, ff: Option<f64>, q: f64, lim: &JointLimits, k: f64, dt: f64) -> f64 {
    let ff = finite_or(ff.unwrap_or(0.0), 0.0);
    match mode {
        CommandMode::Velocity => ff,
        CommandMode::Position => match target.filter(|t| t.is_finite()) {
            Some(target) => {
                let e = lim.clamp(target) - (q + ff * dt);
                let linear = k * e.abs();
                let braking_sq = 2.0 * lim.max_acceleration * e.abs();
                // min(linear, sqrt(braking_sq)), skipping the square root when `linear` is
                // clearly the smaller (the margin covers rounding, so the result is the same).
                let correction =
                    if linear * linear * (1.0 + 1e-9) < braking_sq { linear } else { linear.min(braking_sq.sqrt()) };
                ff + correction.copysign(e)
            }
            None => 0.0,
        },
    }
}

/// Safety decorator: turns every command into one the joints can follow within their limits
/// before the wrapped effector sees it. For each joint it takes the velocity the command asks
/// for ([`tracking_velocity`]; non-finite values mean "stop"), clamps it into the
/// [`velocity_window`] of the measured state (velocity, acceleration and position bounds), and
/// passes on the consistent one-step command `q + v dt` with feed-forward `v`.
#[derive(Debug, Clone)]
pub struct SafetyLimiter<E> {
    inner: E,
    limited: JointCommand,
    gain: f64,
    /// Screws driving joints through triangles: their speed limits hold too.
    actuators: Vec<ScrewTriangle>,
    commanded: bool,
}

impl<E: Effector> SafetyLimiter<E> {
    /// Wrap `inner` with the default position-loop gain (50 1/s).
    pub fn new(inner: E) -> Self {
        let n = inner.limits().len();
        Self {
            inner,
            limited: JointCommand { mode: CommandMode::Position, q: vec![0.0; n], qd: vec![0.0; n] },
            gain: 50.0,
            actuators: Vec::new(),
            commanded: false,
        }
    }
    /// Also keep every actuator (screw) within its speed limit: a command whose screw speeds
    /// at the measured configuration exceed a limit has all its joint velocities scaled down by
    /// one factor (the motion keeps its direction), as far as the acceleration limits allow.
    pub fn with_actuators(mut self, actuators: Vec<ScrewTriangle>) -> Self {
        self.actuators = actuators;
        self
    }
    /// The actuators whose speed limits the limiter enforces.
    pub fn actuators(&self) -> &[ScrewTriangle] {
        &self.actuators
    }
    /// Position-loop gain in 1/s used to turn position targets into velocities (default 50).
    pub fn with_gain(mut self, gain: f64) -> Self {
        self.gain = finite_or(gain, 50.0).max(0.0);
        self
    }
    /// The command that last reached the wrapped effector.
    pub fn last_limited(&self) -> &JointCommand {
        &self.limited
    }
    /// The positions the last command asked the wrapped effector to reach in its step (`None`
    /// before the first command). A healthy effector reaches them exactly (to rounding): the
    /// command is the consistent one-step command of a velocity inside the limits.
    pub fn commanded_position(&self) -> Option<&[f64]> {
        self.commanded.then_some(&self.limited.q[..])
    }
    /// The wrapped effector.
    pub fn inner(&self) -> &E {
        &self.inner
    }
    /// Limit `command` for the current state into `out` (as long as the joints).
    pub fn limit_into(&self, command: &JointCommand, dt: f64, out: &mut JointCommand) {
        self.limit_joints(command, dt, out);
        if !self.actuators.is_empty() {
            self.limit_actuators(dt, out);
        }
    }

    /// Scale the joint velocities of `out` so that every actuator is within its speed limit at
    /// the measured configuration, each joint staying within its velocity window.
    fn limit_actuators(&self, dt: f64, out: &mut JointCommand) {
        let (q, v, limits) = (self.inner.q(), self.inner.qd(), self.inner.limits());
        let ratio = self.actuators.iter().fold(0.0_f64, |m, a| m.max(a.rate(q, &out.qd).abs() / a.max_speed));
        if ratio <= 1.0 || !ratio.is_finite() {
            return;
        }
        for (i, lim) in limits.iter().enumerate() {
            let (lo, hi) = velocity_window(q[i], v[i], lim, dt);
            let v_next = (out.qd[i] / ratio).clamp(lo, hi);
            out.qd[i] = v_next;
            out.q[i] = lim.clamp(q[i] + v_next * dt);
        }
    }

    fn limit_joints(&self, command: &JointCommand, dt: f64, out: &mut JointCommand) {
        let (q, v, limits) = (self.inner.q(), self.inner.qd(), self.inner.limits());
        out.mode = CommandMode::Position;
        let k = self.gain.min(1.0 / dt);
        let n = limits.len();
        // One joint: window, wanted velocity, clamp, consistent one-step command.
        #[inline(always)]
        fn joint(lim: &JointLimits, q: f64, v: f64, wanted: f64, dt: f64, out_q: &mut f64, out_qd: &mut f64) {
            let (lo, hi) = velocity_window(q, v, lim, dt);
            let v_next = wanted.clamp(lo, hi);
            *out_qd = v_next;
            *out_q = lim.clamp(q + v_next * dt);
        }
        let joints = limits.iter().zip(q).zip(v).zip(out.q.iter_mut().zip(out.qd.iter_mut()));
        if command.q.len() >= n && command.qd.len() >= n {
            // The usual full-length command: one loop per mode over zipped slices (no per-joint
            // `get`, mode test or `Option`); the same arithmetic as the general loop below.
            let targets = command.q.iter().zip(&command.qd);
            match command.mode {
                CommandMode::Position => {
                    for ((((lim, &q), &v), (out_q, out_qd)), (&t, &f)) in joints.zip(targets) {
                        let wanted = track(CommandMode::Position, Some(t), Some(f), q, lim, k, dt);
                        joint(lim, q, v, wanted, dt, out_q, out_qd);
                    }
                }
                CommandMode::Velocity => {
                    for ((((lim, &q), &v), (out_q, out_qd)), (&t, &f)) in joints.zip(targets) {
                        let wanted = track(CommandMode::Velocity, Some(t), Some(f), q, lim, k, dt);
                        joint(lim, q, v, wanted, dt, out_q, out_qd);
                    }
                }
            }
            return;
        }
        for (i, (((lim, &q), &v), (out_q, out_qd))) in joints.enumerate() {
            let wanted = track(command.mode, command.q.get(i).copied(), command.qd.get(i).copied(), q, lim, k, dt);
            joint(lim, q, v, wanted, dt, out_q, out_qd);
        }
    }
}

impl<E: Effector> Effector for SafetyLimiter<E> {
    fn limits(&self) -> &[JointLimits] {
        self.inner.limits()
    }
    fn q(&self) -> &[f64] {
        self.inner.q()
    }
    fn qd(&self) -> &[f64] {
        self.inner.qd()
    }
    fn execute(&mut self, command: &JointCommand, dt: f64) {
        let mut limited = std::mem::replace(
            &mut self.limited,
            JointCommand { mode: CommandMode::Position, q: Vec::new(), qd: Vec::new() },
        );
        self.limit_into(command, dt, &mut limited);
        self.inner.execute_limited(&limited, dt);
        self.limited = limited;
        self.commanded = true;
    }
}

/// The controlled stop (stop category 2): every joint decelerates to rest and holds, all joints
/// scaled by one factor so the arm stays on its current path, none decelerating faster than its
/// acceleration limit. Stateless: each step recomputes the stop from the measured state.
#[derive(Debug, Clone, Copy, Default)]
pub struct SafeHalt;

impl SafeHalt {
    /// The halting command for the state `(q, qd)` into `out`.
    pub fn command_into(q: &[f64], qd: &[f64], limits: &[JointLimits], dt: f64, out: &mut JointCommand) {
        // Time to stop of the slowest-stopping joint; all joints share it (path preserved).
        let t_stop = qd.iter().zip(limits).map(|(v, l)| v.abs() / l.max_acceleration).fold(0.0_f64, f64::max);
        let scale = if t_stop <= dt || !t_stop.is_finite() { 0.0 } else { 1.0 - dt / t_stop };
        out.mode = CommandMode::Position;
        for i in 0..q.len().min(out.q.len()) {
            let v = qd[i] * scale;
            out.qd[i] = v;
            out.q[i] = q[i] + v * dt;
        }
    }
}

impl<C> TransitionFunction<C> for SafeHalt {
    fn compute(&mut self, _cc: &mut C, inputs: &InputImages, outputs: &mut OutputImages) {
        if outputs.command.q.len() == inputs.q.len() {
            SafeHalt::command_into(&inputs.q, &inputs.qd, &inputs.limits, inputs.dt, &mut outputs.command);
            outputs.has_command = true;
        }
    }
}

/// A path being followed, parameterised by `s` on `[0, end]` (for a [`Trajectory`], its time).
pub trait FollowedPath {
    /// The parameter's end.
    fn end(&self) -> f64;
    /// Position at `s` (clamped into `[0, end]`) into `out` (as long as the joints).
    fn position_into(&self, s: f64, out: &mut [f64]);
}

impl FollowedPath for Trajectory {
    fn end(&self) -> f64 {
        self.duration()
    }
    fn position_into(&self, s: f64, out: &mut [f64]) {
        self.sample_position_into(s, out);
    }
}

/// Velocity tolerance (rad/s or m/s) within which a step along the path counts as inside the
/// [`velocity_window`]: the limiter's clamp then moves the joint off the path by at most this
/// times `dt` (1e-10 at 1 ms), below the 1e-9 the halt promises, and the next step aims at the
/// path again (no accumulation). It absorbs a sampled trajectory's own rounding at a limit.
const WINDOW_TOLERANCE: f64 = 1e-7;

/// How far (rad or m) a [`PathHalt`] step may leave the path and still count as on it: the
/// limiter's clamp of a step outside the windows by `e` moves the joint by at most `e dt`.
const ON_PATH: f64 = 1e-9;

/// The controlled stop along the path being followed: the path's parameter `s` slows from its
/// rate (1 while the trajectory is followed at its own pace) to rest, as fast as every joint's
/// velocity, acceleration and position limits allow. Each step commands the next point of the
/// path, `q' = path(s + r' dt)`, with the consistent feed-forward velocity `(q' - q) / dt`, and
/// picks the smallest rate `r'` (at most the starting rate where possible) whose step lies inside every joint's
/// [`velocity_window`] (bisection on `r'`): the executed motion stays on the path, exactly
/// (to rounding), and inside the limits. It is not the tangent that is scaled (as in
/// [`SafeHalt`]), so a curved path is followed to second order and beyond.
#[derive(Debug, Clone, PartialEq)]
pub struct PathHalt {
    s: f64,
    rate: f64,
    max_rate: f64,
    next: Vec<f64>,
}

impl PathHalt {
    /// A stop beginning at parameter `s`, moving along the path at `rate` (ds/dt; 1 when the
    /// trajectory was being followed at its own pace).
    pub fn new(s: f64, rate: f64) -> Self {
        let s = if s.is_finite() { s } else { 0.0 };
        let rate = if rate.is_finite() { rate.max(0.0) } else { 0.0 };
        Self { s, rate, max_rate: rate, next: Vec::new() }
    }

    /// The path parameter reached.
    pub fn s(&self) -> f64 {
        self.s
    }

    /// The current rate ds/dt.
    pub fn rate(&self) -> f64 {
        self.rate
    }

    /// Whether the path parameter has stopped.
    pub fn is_stopped(&self) -> bool {
        self.rate == 0.0
    }

    /// The halting command for the measured state `(q, qd)` into `out`. Where no step along
    /// the path fits the limits (at a rest point of the path that falls between two control
    /// steps and is reached a hair too fast, or with the state off the path, e.g. the effector
    /// lagged), the command is the path's point that leaves the velocity windows least, and a
    /// [`SafetyLimiter`] makes it feasible, leaving the path by that excess times `dt`; the
    /// next step aims at the path again. Returns `false` when that takes the joints more than
    /// 1e-9 off the path.
    pub fn command_into<P: FollowedPath + ?Sized>(
        &mut self,
        path: &P,
        q: &[f64],
        qd: &[f64],
        limits: &[JointLimits],
        dt: f64,
        out: &mut JointCommand,
    ) -> bool {
        let n = q.len().min(qd.len()).min(limits.len()).min(out.q.len()).min(out.qd.len());
        let mut next = std::mem::take(&mut self.next);
        next.resize(q.len().max(n), 0.0);
        let end = path.end();
        let s = self.s;
        // How far (rad/s or m/s) the step at rate `r` lies outside the joints' windows, at most.
        let excess = |r: f64, next: &mut Vec<f64>| -> f64 {
            path.position_into((s + r * dt).min(end), next);
            (0..n).fold(0.0_f64, |e, j| {
                let v = (next[j] - q[j]) / dt;
                let (lo, hi) = velocity_window(q[j], qd[j], &limits[j], dt);
                e.max(lo - v).max(v - hi)
            })
        };
        let feasible = |r: f64, next: &mut Vec<f64>| -> bool { excess(r, next) <= WINDOW_TOLERANCE };
        // A feasible rate to bisect from: the current one, or (when the path's own timing is
        // a hair over a limit, e.g. a sampled trajectory at full speed) slightly below it.
        // Where the path itself brakes at a joint's limit, an earlier step that braked a hair
        // (within the tolerance) harder leaves only rates a hair above the current one: back
        // up towards the path's own pace; where a sampled trajectory's own next step brakes a
        // hair harder than a limit allows, a hair past it (the window still bounds every joint);
        // where the arm is a hair ahead of a path braking into a rest point, up to five times
        // the largest rate (a step that reaches the rest point sooner). Last, the rate that
        // reaches the path's end in this step: a path braking at a limit to its end, followed a
        // hair faster than its own pace, needs rates growing without bound as its speed
        // vanishes there, and only a step that ends at its end still fits.
        let (rate0, max_rate) = (self.rate, self.max_rate);
        let mut candidates = [1.0, 1.0 - 1e-9, 1.0 - 1e-7, 1.0 - 1e-5, 1.0 - 1e-3, 0.99, 0.9, 0.75, 0.5, 0.25]
            .into_iter()
            .map(|f| f * rate0)
            .chain([1e-6, 1e-4, 1e-2, 0.1, 0.5, 1.0].into_iter().map(|f| rate0 + f * (max_rate - rate0)))
            .chain([1e-6, 1e-5, 1e-4, 1e-3, 1e-2].into_iter().map(|f| max_rate * (1.0 + f)))
            .chain([1.02, 1.05, 1.1, 1.2, 1.35, 1.5, 1.75, 2.0, 2.5, 3.0, 4.0, 5.0].into_iter().map(|f| max_rate * f))
            .chain(std::iter::once((end - s) / dt));
        // Tried only when the arm cannot simply stay (at rest the candidates are not needed).
        let (rate, on_path) = if feasible(0.0, &mut next) {
            (0.0, true)
        } else if let Some(start) = candidates.find(|&r| r > 0.0 && r.is_finite() && feasible(r, &mut next)) {
            // The smallest feasible rate: [lo, hi] with lo infeasible and hi feasible.
            let (mut lo, mut hi) = (0.0, start);
            for _ in 0..40 {
                let mid = 0.5 * (lo + hi);
                if mid <= lo || mid >= hi {
                    break;
                }
                if feasible(mid, &mut next) {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            (hi, true)
        } else {
            // No step fits (a rest point of the path between two control steps that the arm
            // reaches a hair too fast, or an arm off the path): the step that leaves the
            // windows least, which the limiter clamps, leaving the path by its excess times
            // `dt`; the next step aims at the path again. Rates from 0 to past the largest so
            // far on a grid, then golden-section search around the best.
            let top = (2.0 * max_rate.max(rate0)).max(1e-3).min((end - s).max(0.0) / dt);
            const GRID: usize = 64;
            let (mut best, mut best_e) = (0.0, f64::INFINITY);
            for k in 0..=GRID {
                let r = top * k as f64 / GRID as f64;
                let e = excess(r, &mut next);
                if e < best_e {
                    (best, best_e) = (r, e);
                }
            }
            let (mut a, mut b) = ((best - top / GRID as f64).max(0.0), (best + top / GRID as f64).min(top));
            let g = 0.5 * (5f64.sqrt() - 1.0);
            for _ in 0..40 {
                let (c, d) = (b - g * (b - a), a + g * (b - a));
                if excess(c, &mut next) <= excess(d, &mut next) {
                    b = d;
                } else {
                    a = c;
                }
            }
            let r = 0.5 * (a + b);
            let e = excess(r, &mut next);
            if e < best_e {
                (best, best_e) = (r, e);
            }
            (best, best_e * dt <= ON_PATH)
        };
        self.s = (s + rate * dt).min(end);
        self.rate = if self.s >= end { 0.0 } else { rate };
        path.position_into(self.s, &mut next);
        out.mode = CommandMode::Position;
        for j in 0..n {
            out.q[j] = next[j];
            out.qd[j] = (next[j] - q[j]) / dt;
        }
        self.next = next;
        on_path
    }
}

/// The stops off the path, used when the stop along the path would collide.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
#[non_exhaustive]
pub enum StopMotion {
    /// Along the path being followed ([`PathHalt`]).
    Path,
    /// Along the straight line of the current joint velocity ([`SafeHalt`]).
    Straight,
    /// Every joint braking at its own acceleration limit ([`BrakeHalt`]): the quickest stop the
    /// limits allow for each joint, leaving both the path and the line.
    JointBrake,
}

impl StopMotion {
    /// The name as in the log.
    pub fn as_str(&self) -> &'static str {
        match self {
            StopMotion::Path => "path",
            StopMotion::Straight => "straight",
            StopMotion::JointBrake => "joint_brake",
        }
    }
}

/// Every joint brakes at its acceleration limit (inside its [`velocity_window`]) to rest.
#[derive(Debug, Clone, Copy, Default)]
pub struct BrakeHalt;

impl BrakeHalt {
    /// The braking command for the state `(q, qd)` into `out`.
    pub fn command_into(q: &[f64], qd: &[f64], limits: &[JointLimits], dt: f64, out: &mut JointCommand) {
        out.mode = CommandMode::Position;
        let n = q.len().min(qd.len()).min(limits.len()).min(out.q.len()).min(out.qd.len());
        for j in 0..n {
            let (lo, hi) = velocity_window(q[j], qd[j], &limits[j], dt);
            let v = 0.0_f64.clamp(lo, hi);
            out.qd[j] = v;
            out.q[j] = q[j] + v * dt;
        }
    }
}

/// The positions an ideal effector (one that executes each consistent one-step command
/// exactly) passes through while stopping from `(q, qd)` with `motion` (`path` and `halt` for
/// [`StopMotion::Path`]), the start included; at most `max_steps` steps.
pub fn predict_stop<P: FollowedPath + ?Sized>(
    motion: StopMotion,
    path: Option<(&P, &PathHalt)>,
    q: &[f64],
    qd: &[f64],
    limits: &[JointLimits],
    dt: f64,
    max_steps: usize,
) -> Vec<Vec<f64>> {
    let (mut q, mut qd) = (q.to_vec(), qd.to_vec());
    let mut cmd = JointCommand::hold(&q);
    let mut halt = path.map(|(_, h)| h.clone());
    let mut out = vec![q.clone()];
    for _ in 0..max_steps {
        match (motion, path, halt.as_mut()) {
            (StopMotion::Path, Some((p, _)), Some(h)) => {
                h.command_into(p, &q, &qd, limits, dt, &mut cmd);
            }
            (StopMotion::JointBrake, ..) => BrakeHalt::command_into(&q, &qd, limits, dt, &mut cmd),
            _ => SafeHalt::command_into(&q, &qd, limits, dt, &mut cmd),
        }
        // The limiter's clamp, as the effector would see it.
        for j in 0..q.len().min(limits.len()) {
            let (lo, hi) = velocity_window(q[j], qd[j], &limits[j], dt);
            let v = finite_or(cmd.qd[j], 0.0).clamp(lo, hi);
            qd[j] = v;
            q[j] = limits[j].clamp(q[j] + v * dt);
        }
        out.push(q.clone());
        if qd.iter().all(|v| v.abs() < 1e-9) {
            break;
        }
    }
    out
}
