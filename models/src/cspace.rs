//! Configuration-space metric and interpolation.
//!
//! Continuous joints are angles: their difference is taken on the circle, so the distance from
//! -3.1 to 3.1 rad is 0.083 rad and interpolation between them crosses +-pi.

use std::f64::consts::{PI, TAU};

use crate::robot::Robot;

/// Wrap an angle into [-pi, pi). An angle already there is returned as it is (exactly, and
/// without the `fmod` of the general case: the wrapped differences of continuous joints are
/// mostly there already, and `fmod` was 3.4% of the planning instructions of a Fetch with three
/// continuous joints on its MotionBenchMaker cage problems).
#[inline]
pub fn wrap_angle(a: f64) -> f64 {
    if (-PI..PI).contains(&a) {
        return a;
    }
    let r = (a + PI).rem_euclid(TAU) - PI;
    if r >= PI { r - TAU } else { r }
}

/// Which degrees of freedom wrap, extracted once from a robot for hot loops.
#[derive(Debug, Clone, PartialEq)]
pub struct ConfigSpace {
    wraps: Vec<bool>,
    /// Some dimension wraps (otherwise every difference is a plain `b - a`).
    any_wrap: bool,
}

impl ConfigSpace {
    /// The space of `robot`'s configurations (its continuous joints wrap).
    pub fn new(robot: &Robot) -> Self {
        Self::from_wraps((0..robot.dof()).map(|i| robot.is_continuous(i)).collect())
    }
    /// A space where the flagged dimensions wrap.
    pub fn from_wraps(wraps: Vec<bool>) -> Self {
        Self { any_wrap: wraps.iter().any(|&w| w), wraps }
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
        // Without wrapping dimensions, for the common arm sizes: the same sum in the same
        // order, unrolled (no test per joint).
        if !self.any_wrap {
            if let (Ok(a), Ok(b)) = (<&[f64; 6]>::try_from(a), <&[f64; 6]>::try_from(b)) {
                return sum_sq(a, b);
            }
            if let (Ok(a), Ok(b)) = (<&[f64; 7]>::try_from(a), <&[f64; 7]>::try_from(b)) {
                return sum_sq(a, b);
            }
        }
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
        // The common arm sizes in a few vector operations (about 70 instructions a six-joint
        // segment through the iterator).
        if let (false, Ok(a6), Ok(b6)) = (self.any_wrap, <&[f64; 6]>::try_from(a), <&[f64; 6]>::try_from(b)) {
            out.extend_from_slice(&std::array::from_fn::<f64, 6, _>(|i| b6[i] - a6[i]));
        } else if !self.any_wrap && a.len() == b.len() {
            out.extend(a.iter().zip(b).map(|(a, b)| b - a));
        } else {
            out.extend((0..a.len()).map(|i| self.delta(i, a[i], b[i])));
        }
    }
    /// `a + t d` per joint, written into `out`: [`Self::interpolate_into`] with the joint steps
    /// `d` (from [`Self::deltas_into`]) worked out once for the many points of one segment; the
    /// very same numbers.
    #[inline]
    pub fn step_into(a: &[f64], d: &[f64], t: f64, out: &mut [f64]) {
        // The common arm sizes unrolled (about 50 instructions a six-joint point in a loop).
        if let (Ok(o), Ok(a6), Ok(d6)) =
            (<&mut [f64; 6]>::try_from(&mut *out), <&[f64; 6]>::try_from(a), <&[f64; 6]>::try_from(d))
        {
            *o = std::array::from_fn(|i| a6[i] + t * d6[i]);
            return;
        }
        if let (Ok(o), Ok(a7), Ok(d7)) =
            (<&mut [f64; 7]>::try_from(&mut *out), <&[f64; 7]>::try_from(a), <&[f64; 7]>::try_from(d))
        {
            *o = std::array::from_fn(|i| a7[i] + t * d7[i]);
            return;
        }
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
        if !self.any_wrap {
            for i in 0..a.len() {
                out[i] = a[i] + t * (b[i] - a[i]);
            }
            return;
        }
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

/// The points of an edge probe one after another, written over `out`: `end` first when given,
/// then the inner points `a + (i / n) delta` of the segment cut into `n` steps
/// ([`ConfigSpace::step_into`] with `t = i / n`), `i` from 1 to `n - 1` in [`bisection_order`].
pub fn probe_points_into(a: &[f64], end: Option<&[f64]>, delta: &[f64], n: usize, out: &mut Vec<f64>) {
    out.clear();
    if let Some(e) = end {
        out.extend_from_slice(e);
    }
    bisection_order(n, |i| {
        let at = out.len();
        out.resize(at + a.len(), 0.0);
        ConfigSpace::step_into(a, delta, i as f64 / n as f64, &mut out[at..]);
        true
    });
}

/// The inner points `1..n` of a segment cut into `n` equal steps, in bisection order (the
/// largest power-of-two stride below `n` first, then each finer level's new points), while
/// `visit` returns true; whether every point was visited.
pub fn bisection_order(n: usize, mut visit: impl FnMut(usize) -> bool) -> bool {
    if n < 2 {
        return true;
    }
    let mut stride = 1usize;
    while stride * 2 < n {
        stride *= 2;
    }
    // The first level takes every multiple of the stride, each finer level its odd multiples
    // (the even ones came before): no division per point.
    let mut step = stride;
    loop {
        let mut i = stride;
        while i < n {
            if !visit(i) {
                return false;
            }
            i += step;
        }
        if stride == 1 {
            return true;
        }
        stride /= 2;
        step = 2 * stride;
    }
}

/// `Σ (b_i - a_i)²` in index order, as [`ConfigSpace::distance_squared`] sums it.
#[inline(always)]
fn sum_sq<const D: usize>(a: &[f64; D], b: &[f64; D]) -> f64 {
    let mut s = 0.0;
    for i in 0..D {
        let d = b[i] - a[i];
        s += d * d;
    }
    s
}

impl Robot {
    /// The configuration-space metric of this robot.
    pub fn config_space(&self) -> ConfigSpace {
        ConfigSpace::new(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// Angles in [-pi, pi) come back as they are; others land in [-pi, pi) a whole number of
    /// turns away (within rounding), pi and odd multiples of it at -pi, NaN stays NaN.
    #[test]
    fn wrap_angle_keeps_angles_in_range_and_brings_the_others_there() {
        let mut rng = Rng::new(5);
        for _ in 0..10_000 {
            let a = rng.range(-PI, PI);
            assert_eq!(wrap_angle(a).to_bits(), a.to_bits());
            let far = a + TAU * (rng.below(41) as f64 - 20.0);
            let w = wrap_angle(far);
            assert!((-PI..PI).contains(&w), "{far} -> {w}");
            let turns = (far - w) / TAU;
            assert!((turns - turns.round()).abs() < 1e-9, "{far} -> {w}");
        }
        assert_eq!(wrap_angle(-PI), -PI);
        assert_eq!(wrap_angle(PI), -PI);
        assert_eq!(wrap_angle(3.0 * PI), -PI);
        assert!((wrap_angle(-3.0 * PI) + PI).abs() < 1e-12);
        assert!(wrap_angle(f64::NAN).is_nan());
    }

    /// The order of the inner points is the coarse-to-fine one of the division-based
    /// definition (every multiple of the largest power-of-two stride below `n`, then at each
    /// finer stride the multiples not visited yet), every inner point once, and a `false` from
    /// `visit` stops the walk.
    #[test]
    fn bisection_order_is_coarse_to_fine_and_visits_every_inner_point_once() {
        for n in 0..300usize {
            let mut expected = Vec::new();
            if n >= 2 {
                let mut stride = 1;
                while stride * 2 < n {
                    stride *= 2;
                }
                let mut first = true;
                loop {
                    expected.extend((1..n).filter(|i| i % stride == 0 && (first || (i / stride) % 2 == 1)));
                    if stride == 1 {
                        break;
                    }
                    stride /= 2;
                    first = false;
                }
            }
            let mut seen = Vec::new();
            assert!(bisection_order(n, |i| {
                seen.push(i);
                true
            }));
            assert_eq!(seen, expected, "n = {n}");
            let mut sorted = seen.clone();
            sorted.sort_unstable();
            assert_eq!(sorted, (1..n.max(1)).collect::<Vec<_>>(), "n = {n}");
            let mut count = 0usize;
            let all = bisection_order(n, |_| {
                count += 1;
                count < 3
            });
            assert_eq!((all, count), (n < 4, n.saturating_sub(1).min(3)), "n = {n}");
        }
    }

    /// The unrolled paths (no wrapping dimension; six and seven of them) give the very bits of
    /// the per-joint formulas, and a space with a wrapping dimension still wraps: on random
    /// configurations of two to nine dimensions, near and far apart.
    #[test]
    fn unrolled_metric_and_steps_are_the_per_joint_formulas_to_the_bit() {
        let mut rng = Rng::new(11);
        for dof in 2..10 {
            for wrap_at in [None, Some(0), Some(dof - 1)] {
                let wraps: Vec<bool> = (0..dof).map(|i| Some(i) == wrap_at).collect();
                let space = ConfigSpace::from_wraps(wraps.clone());
                for k in 0..200 {
                    let spread = if k % 2 == 0 { 7.0 } else { 1e-3 };
                    let a: Vec<f64> = (0..dof).map(|_| rng.range(-6.0, 6.0)).collect();
                    let b: Vec<f64> = a.iter().map(|x| x + rng.range(-spread, spread)).collect();
                    let d: Vec<f64> =
                        (0..dof).map(|i| if wraps[i] { wrap_angle(b[i] - a[i]) } else { b[i] - a[i] }).collect();
                    let sum = d.iter().fold(0.0, |s, d| s + d * d);
                    assert_eq!(space.distance_squared(&a, &b).to_bits(), sum.to_bits(), "{dof} {wrap_at:?}");
                    let mut deltas = Vec::new();
                    space.deltas_into(&a, &b, &mut deltas);
                    assert_eq!(deltas, d);
                    let t = rng.uniform();
                    let mut out = vec![0.0; dof];
                    space.interpolate_into(&a, &b, t, &mut out);
                    let expected: Vec<f64> = (0..dof).map(|i| a[i] + t * d[i]).collect();
                    assert_eq!(out, expected);
                    ConfigSpace::step_into(&a, &d, t, &mut out);
                    assert_eq!(out, expected);
                }
            }
        }
    }
}
