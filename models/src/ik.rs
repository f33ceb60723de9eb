//! Inverse kinematics: damped least squares with joint limits and seeded restarts.

use nalgebra::{DMatrix, DVector, Isometry3, Vector6};

use crate::error::ModelError;
use crate::rng::Rng;
use crate::robot::Robot;

/// Settings of [`Robot::inverse_kinematics`].
#[derive(Debug, Clone)]
pub struct IkOptions {
    /// Position tolerance, metres.
    pub position_tolerance: f64,
    /// Orientation tolerance, radians.
    pub orientation_tolerance: f64,
    /// Iterations per attempt.
    pub max_iterations: usize,
    /// Attempts from random seeds after the first (from the given seed).
    pub restarts: usize,
    /// Damping of the least-squares step.
    pub damping: f64,
    /// Seed of the restart generator (deterministic).
    pub seed: u64,
    /// Solve for position only (3 DOF task), ignoring orientation.
    pub position_only: bool,
}

impl Default for IkOptions {
    fn default() -> Self {
        Self {
            position_tolerance: 1e-6,
            orientation_tolerance: 1e-6,
            max_iterations: 100,
            restarts: 20,
            damping: 1e-4,
            seed: 0x1c0ffee,
            position_only: false,
        }
    }
}

/// 6D pose error (position; orientation as rotation vector), both in the world frame.
pub fn pose_error(current: &Isometry3<f64>, target: &Isometry3<f64>) -> Vector6<f64> {
    let dp = target.translation.vector - current.translation.vector;
    let dr = (target.rotation * current.rotation.inverse()).scaled_axis();
    Vector6::new(dp.x, dp.y, dp.z, dr.x, dr.y, dr.z)
}

impl Robot {
    /// Joint values placing end effector `ee`'s tool frame at `target`, within the position limits.
    ///
    /// Damped least squares (Levenberg-Marquardt style), clamping every step into the limits, with
    /// deterministic random restarts. Continuous joints are returned wrapped near the seed.
    pub fn inverse_kinematics(
        &self,
        ee: usize,
        target: &Isometry3<f64>,
        seed: &[f64],
        options: &IkOptions,
    ) -> Result<Vec<f64>, ModelError> {
        let Some(effector) = self.end_effectors().get(ee) else {
            return Err(ModelError::NoSuchName {
                robot: self.name().to_string(),
                what: "end effector",
                name: ee.to_string(),
            });
        };
        self.check_configuration(seed)?;
        let limits = self.limits();
        let mut rng = Rng::new(options.seed);
        let mut best = (f64::INFINITY, seed.to_vec());
        let rows = if options.position_only { 3 } else { 6 };
        let mut poses = self.forward_kinematics(seed);
        let residual_of = |poses: &mut Vec<Isometry3<f64>>, q: &[f64]| -> (Vector6<f64>, f64, f64) {
            self.forward_kinematics_into(q, poses);
            let e = pose_error(&(poses[effector.link] * effector.tool), target);
            let pos = e.fixed_rows::<3>(0).norm();
            let rot = if options.position_only { 0.0 } else { e.fixed_rows::<3>(3).norm() };
            (e, pos, rot)
        };
        let mut trial = seed.to_vec();
        for attempt in 0..=options.restarts {
            let mut q = if attempt == 0 { seed.to_vec() } else { self.random_configuration(&mut rng) };
            // Levenberg-Marquardt: accept a step only if it lowers the error, adapt the damping.
            let mut lambda = options.damping.max(1e-9);
            let (mut e, mut pos_err, mut rot_err) = residual_of(&mut poses, &q);
            let mut cost = pos_err * pos_err + rot_err * rot_err;
            for _ in 0..options.max_iterations {
                if pos_err + rot_err < best.0 {
                    best = (pos_err + rot_err, q.clone());
                }
                if pos_err <= options.position_tolerance && rot_err <= options.orientation_tolerance {
                    return Ok(q);
                }
                residual_of(&mut poses, &q);
                let jac = self.jacobian_with_poses(&poses, effector.link, &effector.tool);
                // Active set: a joint at a bound that the step would push further out is frozen
                // (its column removed) and the step solved again, so bounds do not stall progress.
                let err = DVector::from_fn(rows, |r, _| e[r]);
                let mut frozen = vec![false; self.dof()];
                let mut dq = DVector::zeros(self.dof());
                let mut solved = false;
                for _ in 0..3 {
                    let j: DMatrix<f64> =
                        DMatrix::from_fn(rows, self.dof(), |r, c| if frozen[c] { 0.0 } else { jac[(r, c)] });
                    let jjt = &j * j.transpose() + DMatrix::identity(rows, rows) * lambda;
                    let Some(chol) = jjt.cholesky() else { break };
                    dq = j.transpose() * chol.solve(&err);
                    solved = true;
                    let mut changed = false;
                    for i in 0..q.len() {
                        let at_lower = q[i] <= limits[i].lower + 1e-12 && dq[i] < 0.0;
                        let at_upper = q[i] >= limits[i].upper - 1e-12 && dq[i] > 0.0;
                        if !frozen[i] && (at_lower || at_upper) {
                            frozen[i] = true;
                            changed = true;
                        }
                    }
                    if !changed {
                        break;
                    }
                }
                if !solved {
                    lambda *= 10.0;
                    continue;
                }
                // Limit the step so that the linearisation stays valid.
                let scale = (0.5 / dq.amax().max(1e-12)).min(1.0);
                for i in 0..q.len() {
                    trial[i] = limits[i].clamp(q[i] + scale * dq[i]);
                }
                let (e2, p2, r2) = residual_of(&mut poses, &trial);
                let cost2 = p2 * p2 + r2 * r2;
                if cost2 < cost {
                    q.copy_from_slice(&trial);
                    (e, pos_err, rot_err, cost) = (e2, p2, r2, cost2);
                    lambda = (lambda / 3.0).max(1e-12);
                } else {
                    lambda *= 4.0;
                    if lambda > 1e6 {
                        break; // stuck (a limit or a local minimum): restart elsewhere
                    }
                }
            }
        }
        Err(ModelError::IkFailed {
            frame: effector.name.clone(),
            residual: best.0,
            iterations: options.max_iterations * (options.restarts + 1),
        })
    }
}
