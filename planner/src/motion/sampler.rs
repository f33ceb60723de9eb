//! Where RRT-Connect draws its random configurations: uniformly (pseudo-random) or from a
//! Halton sequence (low discrepancy: the samples fill the joint box evenly, without the clumps
//! and holes of independent draws).

use embodied_models::{Rng, Robot};

/// How the planner draws configurations within the joint limits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum Sampler {
    /// Independent uniform draws (xoshiro256**).
    #[default]
    Uniform,
    /// The Halton sequence in the first `dof` prime bases, shifted by a random offset drawn
    /// from the seed (a Cranley-Patterson rotation) so that every seed gives a different, still
    /// evenly spread, sequence.
    Halton,
}

impl Sampler {
    /// The sampler's name: `uniform` or `halton`.
    pub fn name(self) -> &'static str {
        match self {
            Sampler::Uniform => "uniform",
            Sampler::Halton => "halton",
        }
    }
}

impl std::fmt::Display for Sampler {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A sampler name that is neither `uniform` nor `halton`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown sampler `{0}` (expected uniform or halton)")]
pub struct UnknownSampler(pub String);

impl std::str::FromStr for Sampler {
    type Err = UnknownSampler;

    fn from_str(s: &str) -> Result<Self, UnknownSampler> {
        match s {
            "uniform" => Ok(Sampler::Uniform),
            "halton" => Ok(Sampler::Halton),
            _ => Err(UnknownSampler(s.to_string())),
        }
    }
}

/// The first primes: Halton bases for up to this many degrees of freedom; further joints fall
/// back to uniform draws.
const PRIMES: [u32; 16] = [2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37, 41, 43, 47, 53];

/// The radical inverse of `i` in `base`: its digits mirrored behind the point, in [0, 1) (what
/// [`Digits`] counts, for the tests).
#[cfg(test)]
fn radical_inverse(mut i: u64, base: u32) -> f64 {
    let b = u64::from(base);
    let inv = 1.0 / f64::from(base);
    let mut f = inv;
    let mut r = 0.0;
    while i > 0 {
        r += f * (i % b) as f64;
        i /= b;
        f *= inv;
    }
    r
}

/// The Halton sequence's index in one base, digit by digit, counted up in place, and its
/// radical inverse as an integer over a fixed power of the base: the next value without a
/// division of integers (on the generated MotionBenchMaker cage problems, [`radical_inverse`]'s
/// divisions were a fifth of the planner's instructions, a recomputed sum of the digits still
/// a sixth).
#[derive(Debug, Clone)]
struct Digits {
    base: u64,
    /// Least significant first.
    digits: Vec<u64>,
    /// `base^(len - 1 - k)` for digit `k`: the digits mirrored behind the point are
    /// `mirrored / base^len`.
    weights: Vec<u64>,
    /// `Σ digits[k] * weights[k]`, below `base^len` (so below 2^53: exact as `f64`).
    mirrored: u64,
    /// `base^len` (exact as `f64`).
    scale: f64,
}

impl Digits {
    fn new(base: u32) -> Self {
        let base = u64::from(base);
        // As many digits as keep `base^len` within 2^53.
        let mut weights = vec![1u64];
        while let Some(next) = weights[weights.len() - 1].checked_mul(base).filter(|&w| w <= 1 << 53) {
            weights.push(next);
        }
        let len = weights.len() - 1;
        let scale = weights[len] as f64;
        weights.truncate(len);
        weights.reverse();
        Self { base, digits: vec![0; len], weights, mirrored: 0, scale }
    }

    /// Count up by one, and return the radical inverse of the new index: its digits mirrored
    /// behind the point, rounded once (after `base^len - 1` indices the count starts again).
    fn next(&mut self) -> f64 {
        for (d, &w) in self.digits.iter_mut().zip(&self.weights) {
            *d += 1;
            self.mirrored += w;
            if *d < self.base {
                break;
            }
            // Carry: this digit back to zero.
            *d = 0;
            self.mirrored -= self.base * w;
        }
        self.mirrored as f64 / self.scale
    }
}

/// A stream of configurations drawn with a [`Sampler`].
pub(crate) struct Draw {
    sampler: Sampler,
    /// The Halton index per base (one per degree of freedom with a prime).
    halton: Vec<Digits>,
    offset: Vec<f64>,
    /// (lower, width) of every degree of freedom.
    boxes: Vec<(f64, f64)>,
    /// Per degree of freedom, the value it is held at in every sample (empty: none held; see
    /// [`Self::hold`]).
    held: Vec<Option<f64>>,
    /// Per joint, the bounds a local sample is clamped to: a bounded joint's limits, infinite
    /// for a continuous joint (whose value is left to wrap), so that one `clamp` serves both
    /// with no branch on the joint's kind (a finite value clamped to infinite bounds is
    /// itself).
    clamps: Vec<(f64, f64)>,
    /// Per joint, the half-width of the local box for the `(span, reach)` whose bits are
    /// `half_for` (see [`Self::near_into`]): worked out once per pair, not per draw.
    half: Vec<f64>,
    half_for: (u64, u64),
}

impl Draw {
    /// A stream for `robot`; the Halton offset is drawn from `rng`.
    pub fn new(sampler: Sampler, robot: &Robot, rng: &mut Rng) -> Self {
        let bounded: Vec<bool> = (0..robot.dof()).map(|i| robot.dof_joint(i).limits.is_bounded()).collect();
        let boxes: Vec<(f64, f64)> = (0..robot.dof())
            .map(|i| {
                let l = robot.dof_joint(i).limits;
                if l.is_bounded() {
                    (l.lower, l.upper - l.lower)
                } else {
                    (-std::f64::consts::PI, std::f64::consts::TAU)
                }
            })
            .collect();
        let (halton, offset) = match sampler {
            Sampler::Uniform => (Vec::new(), Vec::new()),
            Sampler::Halton => (
                PRIMES.iter().take(robot.dof()).map(|&b| Digits::new(b)).collect(),
                (0..robot.dof()).map(|_| rng.uniform()).collect(),
            ),
        };
        let clamps = boxes
            .iter()
            .zip(&bounded)
            .map(|(&(lower, width), &b)| if b { (lower, lower + width) } else { (f64::NEG_INFINITY, f64::INFINITY) })
            .collect();
        let half_for = (f64::NAN.to_bits(), f64::NAN.to_bits());
        Self { sampler, halton, offset, boxes, held: Vec::new(), clamps, half: Vec::new(), half_for }
    }

    /// Every later sample holds the degrees of freedom `d` with `!moving[d]` at `at[d]` and
    /// draws only the others (the uniform samples take no random number for a held one: a leg of
    /// one arm of a two-arm robot draws half of them). Slices of another length hold none.
    pub fn hold(&mut self, moving: &[bool], at: &[f64]) {
        self.held.clear();
        if moving.len() == self.boxes.len() && at.len() == self.boxes.len() && moving.contains(&false) {
            self.held.extend(moving.iter().zip(at).map(|(&m, &x)| (!m).then_some(x)));
        }
    }

    /// The held values written over `q` (see [`Self::hold`]).
    fn overwrite_held(&self, q: &mut [f64]) {
        for (v, h) in q.iter_mut().zip(&self.held) {
            if let Some(x) = h {
                *v = *x;
            }
        }
    }

    /// A sample near `node`: each joint uniform within `span` times its sampling width of the
    /// node's value, and within `reach` of it (rad, or m for a prismatic joint; the nearer of
    /// the two), clamped to a bounded joint's limits (a continuous joint's value is left to
    /// wrap). On a robot with actuator strokes, redrawn until the strokes hold, in a box halved
    /// every four draws (16 in all), then a sample of [`Self::next_into`] instead.
    pub fn near_into(&mut self, robot: &Robot, rng: &mut Rng, node: &[f64], (span, reach): (f64, f64), q: &mut [f64]) {
        if node.len() != q.len() || q.len() != self.boxes.len() {
            return self.next_into(robot, rng, q);
        }
        for k in 0..16 {
            let shrink = f64::from(1u32 << (k / 4));
            let (span, reach) = (span / shrink, reach / shrink);
            if self.half_for != (span.to_bits(), reach.to_bits()) {
                self.half_for = (span.to_bits(), reach.to_bits());
                self.half.clear();
                self.half.extend(self.boxes.iter().map(|&(_, width)| (span * width).min(reach)));
            }
            // A local copy of the generator for the loop, as in `next_into`. (Each draw as
            // `x + (2u - 1) h`, clamped: 354 -> 283 instructions a six-joint sample on the
            // MotionBenchMaker UR5 cage problems, 532 -> 346 an eight-joint one on the Fetch's,
            // the same numbers, with the half-widths and the bounds looked up instead of worked
            // out and branched on per draw.)
            let mut local = rng.clone();
            if self.held.is_empty() {
                for (((v, &x), &h), &(lo, hi)) in q.iter_mut().zip(node).zip(&self.half).zip(&self.clamps) {
                    *v = (x + (2.0 * local.uniform() - 1.0) * h).clamp(lo, hi);
                }
            } else {
                let held = self.held.iter();
                for ((((v, &x), &h), &(lo, hi)), at) in
                    q.iter_mut().zip(node).zip(&self.half).zip(&self.clamps).zip(held)
                {
                    *v = match at {
                        Some(at) => *at,
                        None => (x + (2.0 * local.uniform() - 1.0) * h).clamp(lo, hi),
                    };
                }
            }
            *rng = local;
            if robot.strokes_hold(q) {
                return;
            }
        }
        self.next_into(robot, rng, q);
    }

    /// The next configuration into `q`.
    #[inline]
    pub fn next_into(&mut self, robot: &Robot, rng: &mut Rng, q: &mut [f64]) {
        match self.sampler {
            // The same draws as `Robot::random_configuration_into` (`lower + width * u` is its
            // `rng.range(lower, upper)` to the bit), without its per-joint lookups; robots with
            // actuator strokes redraw there until the strokes hold.
            Sampler::Uniform if robot.actuators().is_empty() && q.len() == self.boxes.len() => {
                // A local copy of the generator for the loop, written back after it, and the
                // draw inlined: 163 -> about 130 instructions a six-joint sample on the
                // generated MotionBenchMaker cage problems (the same numbers).
                let mut local = rng.clone();
                if self.held.is_empty() {
                    for (v, &(lower, width)) in q.iter_mut().zip(&self.boxes) {
                        *v = lower + width * local.uniform();
                    }
                } else {
                    for ((v, &(lower, width)), h) in q.iter_mut().zip(&self.boxes).zip(&self.held) {
                        *v = match h {
                            Some(at) => *at,
                            None => lower + width * local.uniform(),
                        };
                    }
                }
                *rng = local;
            }
            Sampler::Uniform => {
                robot.random_configuration_into(rng, q);
                self.overwrite_held(q);
            }
            Sampler::Halton => {
                for (i, v) in q.iter_mut().enumerate() {
                    let u = match self.halton.get_mut(i) {
                        Some(digits) => {
                            let x = digits.next() + self.offset[i];
                            if x >= 1.0 { x - 1.0 } else { x }
                        }
                        None => rng.uniform(),
                    };
                    let (lower, width) = self.boxes[i];
                    *v = lower + width * u;
                }
                self.overwrite_held(q);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn radical_inverse_mirrors_the_digits() {
        assert_eq!(radical_inverse(1, 2), 0.5);
        assert_eq!(radical_inverse(2, 2), 0.25);
        assert_eq!(radical_inverse(3, 2), 0.75);
        assert!((radical_inverse(5, 3) - (2.0 / 3.0 + 1.0 / 9.0)).abs() < 1e-15);
    }

    /// The digit counter gives the radical inverse of 1, 2, 3, ...: exactly in base 2 (every
    /// sum is exact there), within rounding in the others; and it wraps to 0 after the last
    /// index it holds.
    #[test]
    fn counted_digits_give_the_radical_inverse() {
        for &base in &PRIMES {
            let mut digits = Digits::new(base);
            for i in 1..50_000u64 {
                let (got, want) = (digits.next(), radical_inverse(i, base));
                if base == 2 {
                    assert_eq!(got.to_bits(), want.to_bits(), "index {i}");
                } else {
                    assert!((got - want).abs() <= 4.0 * f64::EPSILON * want, "base {base}, index {i}: {got} {want}");
                }
                assert!((0.0..1.0).contains(&got));
            }
        }
        // A counter near its end: the largest index, then 0 again.
        let mut digits = Digits::new(53);
        for d in &mut digits.digits {
            *d = 52;
        }
        digits.mirrored = digits.weights.iter().map(|w| 52 * w).sum::<u64>() - digits.weights[0];
        digits.digits[0] = 51;
        assert_eq!(digits.next(), (digits.scale - 1.0) / digits.scale);
        assert_eq!(digits.next(), 0.0);
    }

    #[test]
    fn halton_fills_every_stratum_of_a_base_2_split() {
        // The first 2^k points of the base-2 component hit each of the 2^k strata once.
        let mut seen = [0u32; 16];
        for i in 0..16u64 {
            seen[(radical_inverse(i, 2) * 16.0) as usize] += 1;
        }
        assert!(seen.iter().all(|&n| n == 1), "{seen:?}");
    }

    /// Uniform draws are the robot's own (`Robot::random_configuration_into`) to the bit, with
    /// and without joint limits (Polycrank's continuous joints), and with actuator strokes (the
    /// IRp-6, which the fast path leaves to the robot).
    #[test]
    fn uniform_draws_are_the_robots_own() {
        for robot in [
            embodied_models::builtin::polycrank(),
            embodied_models::builtin::rnt(),
            embodied_models::builtin::irp6_postument(),
        ] {
            let robot = robot.expect("built-in robot");
            let (mut a, mut b) = (Rng::new(9), Rng::new(9));
            let mut draw = Draw::new(Sampler::Uniform, &robot, &mut a);
            let (mut qa, mut qb) = (vec![0.0; robot.dof()], vec![0.0; robot.dof()]);
            for _ in 0..200 {
                draw.next_into(&robot, &mut a, &mut qa);
                robot.random_configuration_into(&mut b, &mut qb);
                assert_eq!(
                    qa.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                    qb.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
                );
            }
        }
    }

    /// Held degrees of freedom keep their values in every sample (uniform and Halton, over the
    /// box and near a node, with and without actuator strokes), the others still spread over
    /// their box; a uniform draw takes one random number per moving degree of freedom only.
    #[test]
    fn held_dofs_keep_their_values_and_take_no_draws() {
        let mut counted = 0;
        for robot in [
            embodied_models::builtin::two_irp6(),
            embodied_models::builtin::polycrank(),
            embodied_models::builtin::irp6_postument(),
        ] {
            let robot = robot.expect("built-in robot");
            let n = robot.dof();
            let moving: Vec<bool> = (0..n).map(|d| d % 3 != 1).collect();
            let at: Vec<f64> = (0..n).map(|d| 0.01 * d as f64 - 0.02).collect();
            for sampler in [Sampler::Uniform, Sampler::Halton] {
                let mut rng = Rng::new(4);
                let mut draw = Draw::new(sampler, &robot, &mut rng);
                draw.hold(&moving, &at);
                let node = robot.random_configuration(&mut rng);
                let mut q = vec![0.0; n];
                let (mut lo, mut hi) = (vec![f64::INFINITY; n], vec![f64::NEG_INFINITY; n]);
                for k in 0..400 {
                    if k % 2 == 0 {
                        draw.next_into(&robot, &mut rng, &mut q);
                    } else {
                        draw.near_into(&robot, &mut rng, &node, (0.3, f64::INFINITY), &mut q);
                    }
                    for d in 0..n {
                        if moving[d] {
                            (lo[d], hi[d]) = (lo[d].min(q[d]), hi[d].max(q[d]));
                        } else {
                            assert_eq!(q[d].to_bits(), at[d].to_bits(), "{} {sampler}: dof {d}", robot.name());
                        }
                    }
                }
                for d in (0..n).filter(|&d| moving[d]) {
                    assert!(hi[d] - lo[d] > 0.1, "{} {sampler}: dof {d} spread {}..{}", robot.name(), lo[d], hi[d]);
                }
            }
            if robot.actuators().is_empty() {
                let (mut a, mut b) = (Rng::new(9), Rng::new(9));
                let mut draw = Draw::new(Sampler::Uniform, &robot, &mut a);
                draw.hold(&moving, &at);
                let mut q = vec![0.0; n];
                draw.next_into(&robot, &mut a, &mut q);
                for _ in moving.iter().filter(|&&m| m) {
                    b.uniform();
                }
                assert_eq!(a.next_u64(), b.next_u64(), "{}: one draw per moving dof", robot.name());
                counted += 1;
            }
        }
        assert!(counted > 0, "no robot without strokes");
    }

    /// Samples near a node stay within the span of each joint's width around it: clamped into
    /// the limits of bounded joints (and reaching them from a node at a limit), left unclamped
    /// on continuous ones (Polycrank), with actuator strokes held (the IRp-6), and spread over
    /// the box (both halves of every joint's interval are drawn).
    #[test]
    fn near_draws_stay_around_their_node() {
        for robot in [
            embodied_models::builtin::polycrank(),
            embodied_models::builtin::rnt(),
            embodied_models::builtin::irp6_postument(),
            embodied_models::builtin::irp6_on_track(),
        ] {
            let robot = robot.expect("built-in robot");
            let mut rng = Rng::new(4);
            let mut draw = Draw::new(Sampler::Uniform, &robot, &mut rng);
            let n = robot.dof();
            let mut node = vec![0.0; n];
            let mut q = vec![0.0; n];
            for round in 0..50 {
                robot.random_configuration_into(&mut rng, &mut node);
                // Every tenth node at its joints' lower limits.
                if round % 10 == 0 {
                    for (i, v) in node.iter_mut().enumerate() {
                        let l = robot.dof_joint(i).limits;
                        if l.is_bounded() {
                            *v = l.lower;
                        }
                    }
                }
                // A node the planner holds is a valid configuration: its strokes hold.
                if !robot.strokes_hold(&node) {
                    continue;
                }
                let (mut below, mut above) = (vec![false; n], vec![false; n]);
                // Half the draws within a reach of 0.3 (rad or m), nearer than a quarter of
                // most joints' widths.
                let mut reached = vec![false; n];
                for j in 0..200 {
                    let reach = if j % 2 == 0 { f64::INFINITY } else { 0.3 };
                    draw.near_into(&robot, &mut rng, &node, (0.25, reach), &mut q);
                    for i in 0..n {
                        let (lower, width) = draw.boxes[i];
                        let off = q[i] - node[i];
                        let most = (0.25 * width).min(reach) * (1.0 + 1e-12);
                        assert!(off.abs() <= most, "{}: joint {i} moved {off} (reach {reach})", robot.name());
                        reached[i] |= off.abs() > 0.3 && 0.25 * width > 0.3;
                        if robot.dof_joint(i).limits.is_bounded() {
                            assert!(
                                q[i] >= lower && q[i] <= lower + width,
                                "{}: joint {i} out of limits",
                                robot.name()
                            );
                        }
                        below[i] |= off < 0.0;
                        above[i] |= off > 0.0;
                    }
                    assert!(robot.strokes_hold(&q), "{}: a stroke", robot.name());
                }
                for i in 0..n {
                    let at_lower = robot.dof_joint(i).limits.is_bounded() && node[i] <= draw.boxes[i].0;
                    assert!(above[i] && (below[i] || at_lower), "{}: joint {i} drawn on one side only", robot.name());
                    // Without a reach a wide joint goes past 0.3 from its node (so the bound
                    // above tests something).
                    let (lower, width) = draw.boxes[i];
                    let room = if robot.dof_joint(i).limits.is_bounded() {
                        (node[i] - lower).max(lower + width - node[i])
                    } else {
                        width
                    };
                    if 0.25 * width > 0.6 && room > 0.6 {
                        assert!(reached[i], "{}: joint {i} never drawn past 0.3", robot.name());
                    }
                }
            }
            let wraps = (0..n).any(|i| !robot.dof_joint(i).limits.is_bounded());
            if wraps {
                // A continuous joint near +-pi goes past it.
                let node = vec![3.1; n];
                let past = (0..200).any(|_| {
                    draw.near_into(&robot, &mut rng, &node, (0.25, 0.3), &mut q);
                    (0..n).any(|i| !robot.dof_joint(i).limits.is_bounded() && q[i] > std::f64::consts::PI)
                });
                assert!(past, "{}: a continuous joint was clamped", robot.name());
            }
        }
    }

    #[test]
    fn names_round_trip() {
        for s in [Sampler::Uniform, Sampler::Halton] {
            assert_eq!(s.name().parse::<Sampler>(), Ok(s));
        }
        assert!("sobol".parse::<Sampler>().is_err());
    }
    /// A local draw is, to the bit, the node's value plus `(2u - 1)` times the nearer of `span`
    /// times the joint's width and `reach`, clamped to a bounded joint's limits (a continuous
    /// joint's value left unclamped), for changing `(span, reach)` pairs (the half-widths kept
    /// between calls are worked out again when the pair changes).
    #[test]
    fn local_draws_are_the_node_plus_a_share_of_the_half_width_to_the_bit() {
        // Polycrank's joints are continuous; a two-joint arm's one bounded, one continuous.
        let arm = r#"<robot name="arm"><link name="a"/><link name="b"/><link name="c"/>
            <joint name="j1" type="revolute"><parent link="a"/><child link="b"/>
              <axis xyz="0 0 1"/><limit lower="-1.2" upper="2.5" effort="1" velocity="1"/></joint>
            <joint name="j2" type="continuous"><parent link="b"/><child link="c"/>
              <origin xyz="0 0 0.3"/><axis xyz="0 1 0"/></joint></robot>"#;
        let arm = embodied_models::urdf::parse_urdf(arm, std::path::Path::new("arm.urdf"), &Default::default());
        for robot in [embodied_models::builtin::polycrank(), arm] {
            let robot = robot.expect("robot");
            assert!(robot.actuators().is_empty());
            let mut rng = Rng::new(11);
            let mut draw = Draw::new(Sampler::Uniform, &robot, &mut rng);
            let n = robot.dof();
            let (mut node, mut q) = (vec![0.0; n], vec![0.0; n]);
            for j in 0..300 {
                robot.random_configuration_into(&mut rng, &mut node);
                let pair = [(0.5, 2.0), (0.25, f64::INFINITY), (1.0, 0.3)][j % 3];
                let mut reference = rng.clone();
                draw.near_into(&robot, &mut rng, &node, pair, &mut q);
                for i in 0..n {
                    let l = robot.dof_joint(i).limits;
                    let width = if l.is_bounded() { l.upper - l.lower } else { std::f64::consts::TAU };
                    let y = node[i] + (2.0 * reference.uniform() - 1.0) * (pair.0 * width).min(pair.1);
                    let want = if l.is_bounded() { y.clamp(l.lower, l.lower + width) } else { y };
                    assert_eq!(q[i].to_bits(), want.to_bits(), "{}: joint {i}, draw {j}", robot.name());
                }
                // The generator moved on by exactly the draws.
                assert_eq!(rng.next_u64(), reference.next_u64());
            }
        }
    }
}
