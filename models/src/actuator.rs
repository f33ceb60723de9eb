//! Serial-parallel actuation: joints driven by linear actuators (ball screws) through triangles.
//!
//! The IRp-6 lower and upper arm and (by assumption) the RNT shoulder and elbow are not driven
//! by motors in the joints: a screw of variable length `l` closes a triangle whose angle is the
//! joint's (or a sum of joints'). The screw has its own stroke (length limits) and its own speed
//! limit, which in joint space depend on the configuration: near the ends of the stroke a small
//! joint motion is a small screw motion, elsewhere a large one. One [`ScrewTriangle`] maps the
//! configuration to the screw length, its derivative (a row of the actuator Jacobian `dl/dq`)
//! and back, in the form MRROC++ uses:
//!
//! ```text
//! l^2 = c + m cos(theta) - n sin(theta),   theta = offset + sum_k w_k q_k
//! ```
//!
//! (`l^2 = sl123 + mi cos(theta) + ni sin(-theta)` in MRROC++'s
//! `kinematic_model_irp6p_with_wrist.cc`; a plain triangle with sides `L1`, `L2` and the angle
//! `theta` between them is `c = L1^2 + L2^2`, `m = -2 L1 L2`, `n = 0`.)

/// One linear actuator driving a triangle: its length as a function of the configuration, and
/// its stroke and speed limits. Lengths in metres, speeds in m/s.
#[derive(Debug, Clone, PartialEq)]
pub struct ScrewTriangle {
    /// The actuator's name (used in findings and errors).
    pub name: String,
    /// The drive angle `theta = offset + sum w_k q_k`: `(degree of freedom, w_k)` pairs.
    pub angle: Vec<(usize, f64)>,
    /// The drive angle's constant part, rad.
    pub offset: f64,
    /// `c` of `l^2 = c + m cos(theta) - n sin(theta)`, m^2.
    pub c: f64,
    /// `m`, m^2.
    pub m: f64,
    /// `n`, m^2.
    pub n: f64,
    /// Shortest length (end of stroke), m.
    pub min_length: f64,
    /// Longest length (end of stroke), m.
    pub max_length: f64,
    /// Largest |dl/dt|, m/s.
    pub max_speed: f64,
}

impl ScrewTriangle {
    /// The drive angle at `q`.
    #[inline]
    pub fn theta(&self, q: &[f64]) -> f64 {
        self.offset + self.angle.iter().map(|&(k, w)| w * q.get(k).copied().unwrap_or(0.0)).sum::<f64>()
    }

    /// `l^2` at drive angle `theta`.
    #[inline]
    fn squared(&self, theta: f64) -> f64 {
        self.c + self.m * theta.cos() - self.n * theta.sin()
    }

    /// The actuator length at drive angle `theta` (NaN where the triangle cannot close).
    #[inline]
    pub fn length_at(&self, theta: f64) -> f64 {
        let s = self.squared(theta);
        if s >= 0.0 { s.sqrt() } else { f64::NAN }
    }

    /// The actuator length at `q`, m.
    #[inline]
    pub fn length(&self, q: &[f64]) -> f64 {
        self.length_at(self.theta(q))
    }

    /// `dl/dtheta` at drive angle `theta`, m/rad.
    #[inline]
    pub fn slope_at(&self, theta: f64) -> f64 {
        let l = self.length_at(theta);
        (-self.m * theta.sin() - self.n * theta.cos()) / (2.0 * l)
    }

    /// `dl/dq_k` for every degree of freedom `k` in [`ScrewTriangle::angle`] (the actuator's row
    /// of the actuator Jacobian; the other entries are zero).
    pub fn gradient(&self, q: &[f64]) -> impl Iterator<Item = (usize, f64)> + '_ {
        let s = self.slope_at(self.theta(q));
        self.angle.iter().map(move |&(k, w)| (k, s * w))
    }

    /// `dl/dt` at `(q, qd)`, m/s.
    #[inline]
    pub fn rate(&self, q: &[f64], qd: &[f64]) -> f64 {
        let theta_dot: f64 = self.angle.iter().map(|&(k, w)| w * qd.get(k).copied().unwrap_or(0.0)).sum();
        self.slope_at(self.theta(q)) * theta_dot
    }

    /// `dl/ds` along the straight joint-space motion `q + s delta` at `q`: the actuator's speed
    /// per unit path rate.
    #[inline]
    pub fn rate_along(&self, q: &[f64], delta: &[f64]) -> f64 {
        self.rate(q, delta)
    }

    /// The drive angle at which the actuator has length `length`, on the branch nearest
    /// `near` (the inverse of [`ScrewTriangle::length_at`]); `None` when no angle gives it.
    pub fn theta_for_length(&self, length: f64, near: f64) -> Option<f64> {
        // m cos(theta) - n sin(theta) = r cos(theta + phi) with r = |(m, n)|, phi = atan2(n, m).
        let r = self.m.hypot(self.n);
        if !(length >= 0.0 && r > 0.0) {
            return None;
        }
        let x = (length * length - self.c) / r;
        if !(-1.0..=1.0).contains(&x) {
            return None;
        }
        let phi = self.n.atan2(self.m);
        let a = x.acos();
        let wrap = |t: f64| near + crate::cspace::wrap_angle(t - near);
        let (t1, t2) = (wrap(a - phi), wrap(-a - phi));
        Some(if (t1 - near).abs() <= (t2 - near).abs() { t1 } else { t2 })
    }

    /// How far `q` is outside the stroke, m (<= 0 inside; NaN gives +infinity).
    #[inline]
    pub fn stroke_excess(&self, q: &[f64]) -> f64 {
        let l = self.length(q);
        if l.is_nan() { f64::INFINITY } else { (self.min_length - l).max(l - self.max_length) }
    }
}

/// MRROC++'s ball-screw constants of one IRp-6 arm axis (`ptroja/mrrocpp`,
/// `src/robot/irp6p_m/kinematic_model_irp6p_with_wrist.cc`, `set_kinematic_parameters`), in
/// millimetres and motor radians as there.
struct MrrocScrew {
    mi: f64,
    ni: f64,
    /// Screw length at the synchronisation position (`theta[i]`, "l02"/"l03"), mm.
    l0: f64,
    /// Motor position at synchronisation (`synchro_motor_position[i]`), rad.
    synchro_motor: f64,
    /// Motor range (`lower_limit_axis[i]`, `upper_limit_axis[i]`), rad.
    axis: (f64, f64),
}

/// `sl123 = l1^2 + l2^2 + l3^2`, mm^2 (same file).
const SL123: f64 = 7.789525e4;
/// Ball-screw lead `S_r`, mm per motor turn (same file): `gear = 2 pi / S_r` motor rad per mm.
const SCREW_LEAD_MM: f64 = 5.0;
/// `motor_max_velocity = 200.0` motor rad/s: MRROC++'s ECP generator default
/// (`src/generator/ecp/ecp_g_newsmooth.cc`; README 1.6). No per-axis screw speed is published;
/// this is the only motor-speed bound in MRROC++, used here as the screw speed limit.
const MOTOR_MAX_VELOCITY: f64 = 200.0;

const LOWER_ARM: MrrocScrew =
    MrrocScrew { mi: 6.090255e4, ni: -2.934668e4, l0: 220.3374, synchro_motor: -5.0, axis: (-110.0, 100.0) };
const UPPER_ARM: MrrocScrew =
    MrrocScrew { mi: -4.41e4, ni: -5.124e4, l0: 183.8348, synchro_motor: -8.527, axis: (-80.0, 100.0) };

impl MrrocScrew {
    /// The screw as a [`ScrewTriangle`] in metres. MRROC++'s `i2mp_transform` gives the motor
    /// position `gear * (l - l0) + synchro_motor` with `l = sqrt(sl123 + mi cos(t) + ni sin(-t))`
    /// (mm), so the stroke is `l0 + (axis - synchro_motor) / gear` and the speed limit
    /// `motor_max_velocity / gear`.
    fn triangle(&self, name: String, angle: Vec<(usize, f64)>, offset: f64) -> ScrewTriangle {
        let mm = 1e-3;
        let mm2 = 1e-6;
        let gear = 2.0 * std::f64::consts::PI / SCREW_LEAD_MM;
        ScrewTriangle {
            name,
            angle,
            offset,
            c: SL123 * mm2,
            m: self.mi * mm2,
            // MRROC++ writes `+ ni sin(-t)`, i.e. `- ni sin(t)`: n = ni.
            n: self.ni * mm2,
            min_length: (self.l0 + (self.axis.0 - self.synchro_motor) / gear) * mm,
            max_length: (self.l0 + (self.axis.1 - self.synchro_motor) / gear) * mm,
            max_speed: MOTOR_MAX_VELOCITY / gear * mm,
        }
    }
}

/// The two ball screws of an IRp-6 arm whose lower-arm joint is degree of freedom `lower` (the
/// upper arm is `lower + 1`), named `{prefix}lower_arm_screw` and `{prefix}upper_arm_screw`.
///
/// MRROC++ maps the DH joint coordinates to the screws' drive angles in `i2mp_transform`
/// ("poprawka w celu uwzglednienia konwencji DH"): the lower-arm angle is `q1` itself, the
/// upper-arm angle is the upper arm's absolute angle from the horizontal, `q2 + q1 + pi/2`. At
/// the synchronisation ("front") position `q1 = -pi/2, q2 = 0` both screws have MRROC++'s
/// synchronisation lengths `l02 = 220.3374` and `l03 = 183.8348` mm.
pub fn irp6_arm_screws(prefix: &str, lower: usize) -> Vec<ScrewTriangle> {
    vec![
        LOWER_ARM.triangle(format!("{prefix}lower_arm_screw"), vec![(lower, 1.0)], 0.0),
        UPPER_ARM.triangle(
            format!("{prefix}upper_arm_screw"),
            vec![(lower, 1.0), (lower + 1, 1.0)],
            std::f64::consts::FRAC_PI_2,
        ),
    ]
}

/// A plain triangle actuator: the screw joins a point at distance `l1` from the joint axis on
/// one link to a point at distance `l2` on the other, and `q + phi` is the angle between the two
/// sides: `l^2 = l1^2 + l2^2 - 2 l1 l2 cos(q + phi)`.
pub fn triangle(
    name: impl Into<String>,
    dof: usize,
    l1: f64,
    l2: f64,
    phi: f64,
    stroke: (f64, f64),
    max_speed: f64,
) -> ScrewTriangle {
    ScrewTriangle {
        name: name.into(),
        angle: vec![(dof, 1.0)],
        offset: phi,
        c: l1 * l1 + l2 * l2,
        m: -2.0 * l1 * l2,
        n: 0.0,
        min_length: stroke.0,
        max_length: stroke.1,
        max_speed,
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn irp6_screws_have_mrroc_synchronisation_lengths_at_the_front_position() {
        let s = irp6_arm_screws("", 1);
        let front = [0.0, -std::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0, 0.0];
        assert!((s[0].length(&front) - 0.2203374).abs() < 2e-4, "{}", s[0].length(&front));
        assert!((s[1].length(&front) - 0.1838348).abs() < 2e-4, "{}", s[1].length(&front));
        // Stroke from the motor range: 220.34 -+ 83.56 mm, 183.83 - 56.88 / + 86.36 mm.
        assert!((s[0].min_length - 0.136781).abs() < 1e-5 && (s[0].max_length - 0.303894).abs() < 1e-5);
        assert!((s[1].min_length - 0.126958).abs() < 1e-5 && (s[1].max_length - 0.270198).abs() < 1e-5);
        assert!((s[0].max_speed - 0.159155).abs() < 1e-5);
    }

    #[test]
    fn inverse_and_derivative_agree_with_finite_differences() {
        let mut screws = irp6_arm_screws("", 1);
        screws.push(triangle("t", 0, 0.5, 0.9, 0.7, (0.3, 1.3), 0.1));
        let qs = [[0.3, -1.2, 0.2], [-0.4, -2.0, 0.6], [1.0, -1.0, -0.3]];
        for s in &screws {
            for q in &qs {
                let theta = s.theta(q);
                let l = s.length(q);
                let back = s.theta_for_length(l, theta + 0.05).unwrap();
                assert!((back - theta).abs() < 1e-9, "{}: {back} vs {theta}", s.name);
                let h = 1e-6;
                let qd = [0.7, -0.4, 1.1];
                let ahead: Vec<f64> = q.iter().zip(&qd).map(|(a, b)| a + h * b).collect();
                let behind: Vec<f64> = q.iter().zip(&qd).map(|(a, b)| a - h * b).collect();
                let fd = (s.length(&ahead) - s.length(&behind)) / (2.0 * h);
                assert!((fd - s.rate(q, &qd)).abs() < 1e-8, "{}: {fd} vs {}", s.name, s.rate(q, &qd));
                let grad: f64 = s.gradient(q).map(|(k, g)| g * qd[k]).sum();
                assert!((grad - s.rate(q, &qd)).abs() < 1e-12);
            }
        }
    }
}
