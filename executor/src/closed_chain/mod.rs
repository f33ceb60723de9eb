//! Two arms holding one rigid object: the velocity-level QP solved each control step
//! (robots/README.md section 6).
//!
//! ```text
//! min_qd  ||J_a qd - v_a*||^2 + lambda ||qd||^2 (+ mu ||qd - qd_prev||^2)
//! s.t.    J_R qd = -k_r e_r                  (closure: no relative motion of the grasps)
//!         lo <= qd <= hi                     (velocity, position and acceleration bounds)
//!         a_iᵀ qd <= b_i                     (collision velocity dampers)
//! ```
//! `J_a = (J_1 + J_2) / 2` (absolute, cooperative task space) and
//! `J_R = [-R̄_1ᵀ Γ(p_2 - p_1) J_1, R̄_1ᵀ J_2]` (relative Jacobian, expressed in the first
//! end-effector frame, with the Γ term of Jamisola & Roberts). For one robot model holding both
//! arms (e.g. `two-irp6`), `J_1` and `J_2` are full-width Jacobians with zero columns for the
//! other arm's joints, and the two block columns add up.
//!
//! [`ClosedChainController`] is the per-step form: made once, it solves each step with a dense
//! dual active-set solver (warm-started, no allocation) and keeps clarabel, with one solver object
//! updated in place, as fallback and cross-check ([`ClosedChainController::compare`]).
//! [`ClosedChainQp`] is the older one-shot form (a fresh clarabel solver per call).

pub mod carry;
mod controller;
mod dense;
mod reference;

pub use controller::{
    ClosedChainConfig, ClosedChainController, ClosedChainSolution, ClosureMode, DamperParams, QpBackend, QpComparison,
    StepInput, VelocityDamper, step_bounds,
};

use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT};
use embodied_models::nalgebra::{DMatrix, DVector, Isometry3, Matrix3, Matrix6xX, UnitQuaternion, Vector3, Vector6};
use embodied_models::{JointLimits, Robot};

use crate::error::ExecutorError;

fn skew(r: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -r.z, r.y, r.z, 0.0, -r.x, -r.y, r.x, 0.0)
}

/// `J_a = (J_1 + J_2) / 2`: the absolute (mean) twist of the two tool frames.
pub fn absolute_jacobian(j1: &Matrix6xX<f64>, j2: &Matrix6xX<f64>) -> DMatrix<f64> {
    let m = (j1 + j2) * 0.5;
    DMatrix::from_column_slice(6, m.ncols(), m.as_slice())
}

/// `J_R`: twist of tool 2 relative to tool 1, in tool 1's frame. Rows: linear, then angular.
pub fn relative_jacobian(
    j1: &Matrix6xX<f64>,
    j2: &Matrix6xX<f64>,
    pose1: &Isometry3<f64>,
    pose2: &Isometry3<f64>,
) -> DMatrix<f64> {
    let r1t = pose1.rotation.to_rotation_matrix().matrix().transpose();
    let r = pose2.translation.vector - pose1.translation.vector;
    let s = skew(&r);
    let n = j1.ncols();
    let mut out = DMatrix::zeros(6, n);
    for c in 0..n {
        let l1 = Vector3::new(j1[(0, c)], j1[(1, c)], j1[(2, c)]);
        let w1 = Vector3::new(j1[(3, c)], j1[(4, c)], j1[(5, c)]);
        let l2 = Vector3::new(j2[(0, c)], j2[(1, c)], j2[(2, c)]);
        let w2 = Vector3::new(j2[(3, c)], j2[(4, c)], j2[(5, c)]);
        // Γ(r) v_1 = [l1 - S(r) w1; w1]: the velocity of the point p_2 rigidly attached to tool 1.
        let lin = r1t * (l2 - (l1 - s * w1));
        let ang = r1t * (w2 - w1);
        for k in 0..3 {
            out[(k, c)] = lin[k];
            out[(k + 3, c)] = ang[k];
        }
    }
    out
}

/// Joint velocity bounds for one step `dt`: `|qd| <= max_velocity` and
/// `(lower - q)/dt <= qd <= (upper - q)/dt` (no position bound for continuous joints).
pub fn velocity_bounds(q: &[f64], limits: &[JointLimits], dt: f64) -> (DVector<f64>, DVector<f64>) {
    let n = q.len().min(limits.len());
    let lo = DVector::from_fn(n, |i, _| {
        let l = &limits[i];
        let pos = if l.lower.is_finite() { (l.lower - q[i]) / dt } else { f64::NEG_INFINITY };
        (-l.max_velocity).max(pos).min(0.0)
    });
    let hi = DVector::from_fn(n, |i, _| {
        let l = &limits[i];
        let pos = if l.upper.is_finite() { (l.upper - q[i]) / dt } else { f64::INFINITY };
        l.max_velocity.min(pos).max(0.0)
    });
    (lo, hi)
}

/// One closed-chain velocity problem.
#[derive(Debug, Clone)]
pub struct ClosedChainQp {
    /// Absolute task Jacobian (6 x n).
    pub j_a: DMatrix<f64>,
    /// Desired absolute twist `v_a*`.
    pub v_a: DVector<f64>,
    /// Closure Jacobian (6 x n).
    pub j_r: DMatrix<f64>,
    /// Damping `lambda`.
    pub lambda: f64,
    /// Lower bounds of `qd` (rad/s or m/s), one per joint.
    pub lower: DVector<f64>,
    /// Upper bounds of `qd` (rad/s or m/s), one per joint.
    pub upper: DVector<f64>,
}

fn csc(m: &DMatrix<f64>, upper_only: bool) -> CscMatrix<f64> {
    let (rows, cols) = m.shape();
    let mut colptr = Vec::with_capacity(cols + 1);
    let mut rowval = Vec::new();
    let mut nzval = Vec::new();
    colptr.push(0);
    for c in 0..cols {
        let last = if upper_only { (c + 1).min(rows) } else { rows };
        for r in 0..last {
            let v = m[(r, c)];
            if v != 0.0 {
                rowval.push(r);
                nzval.push(v);
            }
        }
        colptr.push(rowval.len());
    }
    CscMatrix::new(rows, cols, colptr, rowval, nzval)
}

impl ClosedChainQp {
    /// Solve for the joint velocities `qd`.
    pub fn solve(&self) -> Result<DVector<f64>, ExecutorError> {
        let n = self.j_a.ncols();
        if self.j_r.ncols() != n || self.lower.len() != n || self.upper.len() != n || self.v_a.len() != 6 {
            return Err(ExecutorError::DimensionMismatch {
                what: "closed-chain QP (J_R columns, bounds, v_a)".into(),
                expected: n,
                got: self.j_r.ncols(),
            });
        }
        // ½ xᵀ P x + cᵀ x with P = 2 (J_aᵀ J_a + λ I), c = -2 J_aᵀ v_a.
        let p = (self.j_a.transpose() * &self.j_a + DMatrix::identity(n, n) * self.lambda) * 2.0;
        let c = -(self.j_a.transpose() * &self.v_a) * 2.0;
        // Rows: 6 closure equalities, then x <= hi and -x <= -lo for the finite bounds.
        let mut rows: Vec<(Vec<(usize, f64)>, f64)> = Vec::with_capacity(2 * n);
        for i in 0..n {
            if self.upper[i].is_finite() {
                rows.push((vec![(i, 1.0)], self.upper[i]));
            }
            if self.lower[i].is_finite() {
                rows.push((vec![(i, -1.0)], -self.lower[i]));
            }
        }
        let m = 6 + rows.len();
        let mut a = DMatrix::zeros(m, n);
        let mut b = vec![0.0; m];
        a.view_mut((0, 0), (6, n)).copy_from(&self.j_r);
        for (k, (entries, rhs)) in rows.iter().enumerate() {
            for &(i, v) in entries {
                a[(6 + k, i)] = v;
            }
            b[6 + k] = *rhs;
        }
        let cones = [SupportedConeT::ZeroConeT(6), SupportedConeT::NonnegativeConeT(rows.len())];
        let settings =
            DefaultSettingsBuilder::default().verbose(false).build().map_err(|e| ExecutorError::Qp(e.to_string()))?;
        let mut solver = DefaultSolver::new(&csc(&p, true), c.as_slice(), &csc(&a, false), &b, &cones, settings)
            .map_err(|e| ExecutorError::Qp(e.to_string()))?;
        solver.solve();
        match solver.solution.status {
            SolverStatus::Solved | SolverStatus::AlmostSolved => Ok(DVector::from_vec(solver.solution.x.clone())),
            status => Err(ExecutorError::Qp(format!("{status:?}"))),
        }
    }
}

/// Pose of tool 2 in tool 1's frame: `T_1⁻¹ T_2`.
pub fn relative_pose(pose1: &Isometry3<f64>, pose2: &Isometry3<f64>) -> Isometry3<f64> {
    pose1.inverse() * pose2
}

/// Closure error `e_r` of the relative pose `T_1⁻¹ T_2` against `reference` (its value at grasp
/// time), in tool 1's frame and in the units of `J_R qd`: `[p_r - p_ref; log(R_r R_refᵀ)]`
/// (position, then rotation vector). `J_R qd = -k_r e_r` makes it decay at rate `k_r`.
pub fn relative_pose_error(pose1: &Isometry3<f64>, pose2: &Isometry3<f64>, reference: &Isometry3<f64>) -> Vector6<f64> {
    let rel = relative_pose(pose1, pose2);
    let dp = rel.translation.vector - reference.translation.vector;
    let dr = (rel.rotation * reference.rotation.inverse()).scaled_axis();
    Vector6::new(dp.x, dp.y, dp.z, dr.x, dr.y, dr.z)
}

/// Absolute (cooperative) pose of the two tools: the midpoint of the tool origins, oriented half
/// way along the relative rotation from tool 1 to tool 2 (`R_a = R_1 Rot(k_12, θ_12 / 2)`).
pub fn absolute_pose(pose1: &Isometry3<f64>, pose2: &Isometry3<f64>) -> Isometry3<f64> {
    let p = (pose1.translation.vector + pose2.translation.vector) * 0.5;
    let half = (pose1.rotation.inverse() * pose2.rotation).powf(0.5);
    Isometry3::from_parts(p.into(), pose1.rotation * half)
}

/// World-frame error of `actual` against `desired`, `[p* - p; log(R* Rᵀ)]`: the twist that
/// closes the gap in unit time. Feedback for the absolute task: `v_a = v_a* + K_a e_a`.
pub fn pose_error(desired: &Isometry3<f64>, actual: &Isometry3<f64>) -> Vector6<f64> {
    let dp = desired.translation.vector - actual.translation.vector;
    let dr = (desired.rotation * actual.rotation.inverse()).scaled_axis();
    Vector6::new(dp.x, dp.y, dp.z, dr.x, dr.y, dr.z)
}

/// Rotate a pose by a constant world-frame twist `v` for time `t` (rotation about its own origin).
pub fn integrate_pose(pose: &Isometry3<f64>, v: &Vector6<f64>, t: f64) -> Isometry3<f64> {
    let lin = Vector3::new(v[0], v[1], v[2]) * t;
    let rot = UnitQuaternion::from_scaled_axis(Vector3::new(v[3], v[4], v[5]) * t);
    Isometry3::from_parts((pose.translation.vector + lin).into(), rot * pose.rotation)
}

/// The two-arm kinematic quantities one step needs, for end effectors 0 and 1 of a robot.
#[derive(Debug, Clone, PartialEq)]
pub struct ChainKinematics {
    /// Absolute Jacobian (6 x n).
    pub j_a: DMatrix<f64>,
    /// Relative Jacobian (6 x n).
    pub j_r: DMatrix<f64>,
    /// Tool poses of end effectors 0 and 1.
    pub tool1: Isometry3<f64>,
    /// Tool pose of end effector 1 (world frame); see `tool1`.
    pub tool2: Isometry3<f64>,
}

impl ChainKinematics {
    /// Jacobians and tool poses at `q` (one forward-kinematics pass).
    pub fn new(robot: &Robot, q: &[f64]) -> Result<Self, ExecutorError> {
        if q.len() != robot.dof() {
            return Err(ExecutorError::DimensionMismatch { what: "q".into(), expected: robot.dof(), got: q.len() });
        }
        if robot.end_effectors().len() < 2 {
            return Err(ExecutorError::DimensionMismatch {
                what: format!("end effectors of {}", robot.name()),
                expected: 2,
                got: robot.end_effectors().len(),
            });
        }
        if q.iter().any(|v| !v.is_finite()) {
            return Err(ExecutorError::NotFinite { what: "q".into() });
        }
        let poses = robot.forward_kinematics(q);
        let (e1, e2) = (&robot.end_effectors()[0], &robot.end_effectors()[1]);
        let j1 = robot.jacobian_with_poses(&poses, e1.link, &e1.tool);
        let j2 = robot.jacobian_with_poses(&poses, e2.link, &e2.tool);
        let tool1 = poses[e1.link] * e1.tool;
        let tool2 = poses[e2.link] * e2.tool;
        Ok(Self { j_a: absolute_jacobian(&j1, &j2), j_r: relative_jacobian(&j1, &j2, &tool1, &tool2), tool1, tool2 })
    }

    /// [`absolute_pose`] of the two tools.
    pub fn absolute_pose(&self) -> Isometry3<f64> {
        absolute_pose(&self.tool1, &self.tool2)
    }

    /// [`relative_pose`] of the two tools.
    pub fn relative_pose(&self) -> Isometry3<f64> {
        relative_pose(&self.tool1, &self.tool2)
    }
}
