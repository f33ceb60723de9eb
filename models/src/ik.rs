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
            max_iterations: 200,
            restarts: 20,
            damping: 1e-3,
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
        for attempt in 0..=options.restarts {
            let mut q = if attempt == 0 { seed.to_vec() } else { self.random_configuration(&mut rng) };
            let mut lambda = options.damping;
            for _ in 0..options.max_iterations {
                self.forward_kinematics_into(&q, &mut poses);
                let tool = poses[effector.link] * effector.tool;
                let e = pose_error(&tool, target);
                let pos_err = e.fixed_rows::<3>(0).norm();
                let rot_err = if options.position_only { 0.0 } else { e.fixed_rows::<3>(3).norm() };
                let residual = pos_err + rot_err;
                if residual < best.0 {
                    best = (residual, q.clone());
                }
                if pos_err <= options.position_tolerance && rot_err <= options.orientation_tolerance {
                    return Ok(q);
                }
                let jac = self.jacobian_with_poses(&poses, effector.link, &effector.tool);
                let j: DMatrix<f64> = DMatrix::from_fn(rows, self.dof(), |r, c| jac[(r, c)]);
                let err = DVector::from_fn(rows, |r, _| e[r]);
                let jjt = &j * j.transpose() + DMatrix::identity(rows, rows) * (lambda * lambda);
                let Some(chol) = jjt.cholesky() else {
                    lambda *= 10.0;
                    continue;
                };
                let dq = j.transpose() * chol.solve(&err);
                // Limit the step so that the linearisation stays valid.
                let scale = (0.5 / dq.amax().max(1e-12)).min(1.0);
                for i in 0..q.len() {
                    q[i] = limits[i].clamp(q[i] + scale * dq[i]);
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
