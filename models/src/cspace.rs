//! Configuration-space metric and interpolation.
//!
//! Continuous joints are angles: their difference is taken on the circle, so the distance from
//! -3.1 to 3.1 rad is 0.083 rad and interpolation between them crosses +-pi.

use std::f64::consts::{PI, TAU};

use crate::robot::Robot;

/// Wrap an angle into [-pi, pi).
#[inline]
pub fn wrap_angle(a: f64) -> f64 {
    let r = (a + PI).rem_euclid(TAU) - PI;
    if r >= PI { r - TAU } else { r }
}

/// Which degrees of freedom wrap, extracted once from a robot for hot loops.
#[derive(Debug, Clone, PartialEq)]
pub struct ConfigSpace {
    wraps: Vec<bool>,
}

impl ConfigSpace {
    /// The space of `robot`'s configurations (its continuous joints wrap).
    pub fn new(robot: &Robot) -> Self {
        Self { wraps: (0..robot.dof()).map(|i| robot.is_continuous(i)).collect() }
    }
    /// A space where the flagged dimensions wrap.
    pub fn from_wraps(wraps: Vec<bool>) -> Self {
        Self { wraps }
    }
    /// Number of degrees of freedom.
    pub fn dof(&self) -> usize {
        self.wraps.len()
    }
    /// Whether degree of freedom `i` is an angle that wraps (a continuous joint).
    pub fn wraps(&self, i: usize) -> bool {
        self.wraps[i]
    }
    /// Shortest signed step from `a[i]` to `b[i]`.
    #[inline]
    pub fn delta(&self, i: usize, a: f64, b: f64) -> f64 {
        if self.wraps[i] { wrap_angle(b - a) } else { b - a }
    }
    /// Euclidean distance with wrapped differences on continuous joints.
    #[inline]
    pub fn distance(&self, a: &[f64], b: &[f64]) -> f64 {
        self.distance_squared(a, b).sqrt()
    }
    #[inline]
    /// Squared [`Self::distance`] (no square root).
    pub fn distance_squared(&self, a: &[f64], b: &[f64]) -> f64 {
        let mut s = 0.0;
        for i in 0..a.len() {
            let d = self.delta(i, a[i], b[i]);
            s += d * d;
        }
        s
    }
    /// Largest per-joint step |delta| between two configurations (the L-infinity distance).
    pub fn max_joint_step(&self, a: &[f64], b: &[f64]) -> f64 {
        (0..a.len()).map(|i| self.delta(i, a[i], b[i]).abs()).fold(0.0, f64::max)
    }
    /// The signed joint steps from `a` to `b` ([`Self::delta`] of each joint: the short way
    /// on continuous joints), written over `out`: for [`Self::step_into`].
    pub fn deltas_into(&self, a: &[f64], b: &[f64], out: &mut Vec<f64>) {
        out.clear();
        out.extend((0..a.len()).map(|i| self.delta(i, a[i], b[i])));
    }
    /// `a + t d` per joint, written into `out`: [`Self::interpolate_into`] with the joint steps
    /// `d` (from [`Self::deltas_into`]) worked out once for the many points of one segment; the
    /// very same numbers.
    #[inline]
    pub fn step_into(a: &[f64], d: &[f64], t: f64, out: &mut [f64]) {
        // Over slices cut to one length (a zip of three slices was not vectorised: 38
        // instructions a six-joint point in RRT-Connect's edge probes).
        let n = out.len().min(a.len()).min(d.len());
        let (out, a, d) = (&mut out[..n], &a[..n], &d[..n]);
        for i in 0..n {
            out[i] = a[i] + t * d[i];
        }
    }
    /// The point at fraction `t` along the shortest way from `a` to `b`, written into `out`.
    /// Continuous joints are left unwrapped (continuing from `a`), so a path stays continuous.
    #[inline]
    pub fn interpolate_into(&self, a: &[f64], b: &[f64], t: f64, out: &mut [f64]) {
        for i in 0..a.len() {
            out[i] = a[i] + t * self.delta(i, a[i], b[i]);
        }
    }
    /// The point at fraction `t` along the shortest way from `a` to `b` (see [`Self::interpolate_into`]).
    pub fn interpolate(&self, a: &[f64], b: &[f64], t: f64) -> Vec<f64> {
        let mut out = vec![0.0; a.len()];
        self.interpolate_into(a, b, t, &mut out);
        out
    }
    /// `b` expressed as the nearest equivalent to `a` (continuous joints unwrapped towards `a`).
    pub fn unwrap_towards(&self, a: &[f64], b: &[f64]) -> Vec<f64> {
        (0..a.len()).map(|i| a[i] + self.delta(i, a[i], b[i])).collect()
    }
}

impl Robot {
    /// The configuration-space metric of this robot.
    pub fn config_space(&self) -> ConfigSpace {
        ConfigSpace::new(self)
    }
}
