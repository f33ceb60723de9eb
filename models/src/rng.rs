//! A small deterministic random number generator (xoshiro256**, seeded by SplitMix64).
//!
//! Our own so that a seed gives the same samples in every version of every dependency:
//! runs and logs must replay bit for bit.

/// Deterministic PRNG; not for cryptography.
#[derive(Debug, Clone)]
pub struct Rng {
    s: [u64; 4],
}

impl Rng {
    /// A generator seeded by `seed` (the same seed gives the same sequence).
    pub fn new(seed: u64) -> Self {
        let mut x = seed;
        let mut next = || {
            x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = x;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        };
        Self { s: [next(), next(), next(), next()] }
    }
    #[inline]
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        let result = self.s[1].wrapping_mul(5).rotate_left(7).wrapping_mul(9);
        let t = self.s[1] << 17;
        self.s[2] ^= self.s[0];
        self.s[3] ^= self.s[1];
        self.s[1] ^= self.s[2];
        self.s[0] ^= self.s[3];
        self.s[2] ^= t;
        self.s[3] = self.s[3].rotate_left(45);
        result
    }
    /// Uniform in [0, 1).
    #[inline]
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }
    /// Uniform in [lo, hi).
    #[inline]
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }
    /// Uniform integer in [0, n).
    #[inline]
    pub fn below(&mut self, n: usize) -> usize {
        ((self.next_u64() >> 11) % (n.max(1) as u64)) as usize
    }
    /// Standard normal (Box-Muller).
    pub fn normal(&mut self) -> f64 {
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
    /// A fresh generator derived from this one (for parallel streams).
    pub fn fork(&mut self, stream: u64) -> Rng {
        Rng::new(self.next_u64() ^ stream.wrapping_mul(0xA24B_AED4_963E_E407))
    }
}

impl crate::Robot {
    /// A configuration drawn uniformly within the position limits (continuous joints in [-pi, pi))
    /// and, for a robot with screws driving joints, within their strokes (rejection sampling; after
    /// 1,000 rejections the last draw is kept as it is).
    pub fn random_configuration(&self, rng: &mut Rng) -> Vec<f64> {
        let mut q = vec![0.0; self.dof()];
        self.random_configuration_into(rng, &mut q);
        q
    }
    /// [`crate::Robot::random_configuration`] into a buffer.
    pub fn random_configuration_into(&self, rng: &mut Rng, q: &mut [f64]) {
        self.randomise_dofs_into(rng, |_| true, q);
    }

    /// Draw the degrees of freedom `i` with `which(i)` as [`crate::Robot::random_configuration`]
    /// does, leaving the others of `q` as they are (the strokes checked of the screws that drive
    /// a degree of freedom drawn: the others' do not change).
    pub fn randomise_dofs_into(&self, rng: &mut Rng, which: impl Fn(usize) -> bool, q: &mut [f64]) {
        let screws = self.actuators_driving(&which);
        for _ in 0..1000 {
            for (i, v) in q.iter_mut().enumerate().filter(|(i, _)| which(*i)) {
                let l = self.dof_joint(i).limits;
                *v = if l.is_bounded() {
                    rng.range(l.lower, l.upper)
                } else {
                    rng.range(-std::f64::consts::PI, std::f64::consts::PI)
                };
            }
            if screws.iter().all(|a| a.stroke_excess(q) <= 0.0) {
                return;
            }
        }
    }
}
