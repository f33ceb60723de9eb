//! Closed-form inverse kinematics of the IRp-6 arm.
//!
//! Geometry (shared/robots/README.md 1.3, MRROC++ `kinematic_model_irp6p_with_wrist`): a vertical
//! column (q0), three parallel horizontal axes (lower arm q1, upper arm q2, wrist pitch q3), then
//! the wrist rotation V (q4) about an axis in the arm's vertical plane and N (q5) at the flange,
//! `d5` from the pitch axis. With the absolute angles `t1 = q0, t2 = q1, t3 = q1 + q2 + pi/2,
//! t4 = t3 + q3, t5 = q4, t6 = q5` the flange, in the shoulder frame, is at
//! `P = (c1 rho, s1 rho, z)` with `rho = a2 c2 + a3 c3 + d5 c4`, `z = -(a2 s2 + a3 s3 + d5 s4)`,
//! and its approach axis is `a = (c1 s4 s5 - s1 c5, s1 s4 s5 + c1 c5, c4 s5)`.
//!
//! So, given a flange pose:
//! 1. the column angle points the arm's plane at `P` (two ways: facing it or reaching back over);
//! 2. in that plane, with `u` its horizontal direction and `m` its normal, `c5 = a.m`,
//!    `s4 s5 = a.u`, `c4 s5 = a.z`: two wrist solutions (the sign of `s5`);
//! 3. the pitch point is `P - d5 (c4 u - s4 z)`, reached by the planar two-link arm `a2`, `a3`
//!    (elbow up or down);
//! 4. `t6` from the flange's x axis `x = b c6 + c s6`, with `b, c` orthonormal functions of t1, t4, t5.
//!
//! Up to eight solutions. At the wrist singularity (`s5 = 0`: pitch and N axes parallel) only
//! `t4 + t6` is determined and t4 is kept from the seed; with the flange on the column axis the
//! column angle is kept from the seed.

use std::f64::consts::{FRAC_PI_2, TAU};

use nalgebra::Isometry3;

use crate::joint::Dh;

/// The standard DH table of the IRp-6 arm's six revolute joints (shared/robots/README.md 1.3.1,
/// derived from MRROC++): the built-in IRp-6 robots are made from it and the closed form below
/// solves it.
pub(crate) const IRP6_DH: [Dh; 6] = [
    Dh::new(0.0, 0.0, 0.0, -FRAC_PI_2),
    Dh::new(0.0, 0.0, 0.455, 0.0),
    Dh::new(FRAC_PI_2, 0.0, 0.67, 0.0),
    Dh::new(-FRAC_PI_2, 0.0, 0.0, -FRAC_PI_2),
    Dh::new(0.0, 0.19, 0.0, FRAC_PI_2),
    Dh::new(0.0, 0.0, 0.0, 0.0),
];

/// The lengths of [`IRP6_DH`] that the IRp-6's closed-form inverse kinematics needs.
pub(crate) const IRP6_LENGTHS: Irp6Lengths = Irp6Lengths { a2: IRP6_DH[1].a, a3: IRP6_DH[2].a, d5: IRP6_DH[4].d };

/// Below this a quantity is treated as zero (a singular direction).
const SINGULAR: f64 = 1e-10;

/// The three lengths the arm's inverse kinematics needs, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Irp6Lengths {
    /// Lower arm.
    pub a2: f64,
    /// Upper arm.
    pub a3: f64,
    /// Wrist pitch axis to flange.
    pub d5: f64,
}

/// Push every solution of the six arm joints for `flange` (flange pose in the shoulder frame,
/// DH frame 0) into `out`, as raw angles in (-pi, pi] except where the seed fixes them. `seed`
/// holds the six arm joint values; it decides the angles a singularity leaves free. At the wrist
/// singularity `pitch_samples` more wrist pitch angles, evenly spaced over a turn, are tried.
/// Returns whether the wrist was singular.
pub(crate) fn solve(
    len: &Irp6Lengths,
    flange: &Isometry3<f64>,
    seed: &[f64; 6],
    pitch_samples: usize,
    out: &mut Vec<[f64; 6]>,
) -> bool {
    let p = flange.translation.vector;
    let rot = flange.rotation.to_rotation_matrix();
    let m = rot.matrix();
    let (x, a) = (m.column(0), m.column(2));
    let horizontal = p.x.hypot(p.y);
    let facing = p.y.atan2(p.x);
    let columns: &[f64] = if horizontal < SINGULAR { &[seed[0]] } else { &[facing, facing + std::f64::consts::PI] };
    let mut singular = false;
    let mut wrists = Vec::with_capacity(2 + pitch_samples);
    for &t1 in columns {
        let (s1, c1) = t1.sin_cos();
        let rho = c1 * p.x + s1 * p.y;
        let c5 = -s1 * a.x + c1 * a.y;
        let (au, az) = (c1 * a.x + s1 * a.y, a.z);
        let s5_abs = au.hypot(az);
        wrists.clear();
        if s5_abs < SINGULAR {
            singular = true;
            let t5 = 0.0f64.atan2(c5);
            let t4 = seed[1] + seed[2] + FRAC_PI_2 + seed[3];
            wrists.push((t4, t5));
            wrists.extend((0..pitch_samples).map(|k| (t4 + TAU * (k + 1) as f64 / (pitch_samples + 1) as f64, t5)));
        } else {
            for sign in [1.0, -1.0] {
                wrists.push(((sign * au).atan2(sign * az), (sign * s5_abs).atan2(c5)));
            }
        }
        for &(t4, t5) in &wrists {
            let (s4, c4) = t4.sin_cos();
            let (s5, c5) = t5.sin_cos();
            // The planar two-link arm reaches the pitch point (rw, -zw) of the arm's plane.
            let rw = rho - len.d5 * c4;
            let zw = -(p.z + len.d5 * s4);
            let cos_elbow = (rw * rw + zw * zw - len.a2 * len.a2 - len.a3 * len.a3) / (2.0 * len.a2 * len.a3);
            if !(-1.0 - 1e-12..=1.0 + 1e-12).contains(&cos_elbow) {
                continue; // out of reach on this branch
            }
            let cos_elbow = cos_elbow.clamp(-1.0, 1.0);
            let sin_abs = (1.0 - cos_elbow * cos_elbow).sqrt();
            let elbows: &[f64] = if sin_abs < SINGULAR { &[0.0] } else { &[sin_abs, -sin_abs] };
            // Wrist N: x = b c6 + c s6.
            let b = [c1 * s4 * c5 + s1 * s5, s1 * s4 * c5 - c1 * s5, c4 * c5];
            let c = [c1 * c4, s1 * c4, -s4];
            let t6 = (x[0] * c[0] + x[1] * c[1] + x[2] * c[2]).atan2(x[0] * b[0] + x[1] * b[1] + x[2] * b[2]);
            for &sin_elbow in elbows {
                let elbow = sin_elbow.atan2(cos_elbow);
                let t2 = zw.atan2(rw) - (len.a3 * sin_elbow).atan2(len.a2 + len.a3 * cos_elbow);
                let t3 = t2 + elbow;
                out.push([t1, t2, t3 - t2 - FRAC_PI_2, t4 - t3, t5, t6]);
            }
        }
    }
    singular
}
