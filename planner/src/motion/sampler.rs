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

/// The radical inverse of `i` in `base`: its digits mirrored behind the point, in [0, 1).
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

/// A stream of configurations drawn with a [`Sampler`].
pub(crate) struct Draw {
    sampler: Sampler,
    index: u64,
    offset: Vec<f64>,
    /// (lower, width) of every degree of freedom.
    boxes: Vec<(f64, f64)>,
}

impl Draw {
    /// A stream for `robot`; the Halton offset is drawn from `rng`.
    pub fn new(sampler: Sampler, robot: &Robot, rng: &mut Rng) -> Self {
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
        let offset = match sampler {
            Sampler::Uniform => Vec::new(),
            Sampler::Halton => (0..robot.dof()).map(|_| rng.uniform()).collect(),
        };
        Self { sampler, index: 0, offset, boxes }
    }

    /// The next configuration into `q`.
    pub fn next_into(&mut self, robot: &Robot, rng: &mut Rng, q: &mut [f64]) {
        match self.sampler {
            // The same draws as `Robot::random_configuration_into` (`lower + width * u` is its
            // `rng.range(lower, upper)` to the bit), without its per-joint lookups; robots with
            // actuator strokes redraw there until the strokes hold.
            Sampler::Uniform if robot.actuators().is_empty() && q.len() == self.boxes.len() => {
                for (v, &(lower, width)) in q.iter_mut().zip(&self.boxes) {
                    *v = lower + width * rng.uniform();
                }
            }
            Sampler::Uniform => robot.random_configuration_into(rng, q),
            Sampler::Halton => {
                self.index += 1;
                for (i, v) in q.iter_mut().enumerate() {
                    let u = match PRIMES.get(i) {
                        Some(&base) => {
                            let x = radical_inverse(self.index, base) + self.offset[i];
                            if x >= 1.0 { x - 1.0 } else { x }
                        }
                        None => rng.uniform(),
                    };
                    let (lower, width) = self.boxes[i];
                    *v = lower + width * u;
                }
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

    #[test]
    fn names_round_trip() {
        for s in [Sampler::Uniform, Sampler::Halton] {
            assert_eq!(s.name().parse::<Sampler>(), Ok(s));
        }
        assert!("sobol".parse::<Sampler>().is_err());
    }
}
