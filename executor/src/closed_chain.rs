//! Two arms holding one rigid object: the velocity-level QP solved each control step
//! (robots/README.md section 6), with clarabel.
//!
//! ```text
//! min_qd  ||J_a qd - v_a*||^2 + lambda ||qd||^2
//! s.t.    J_R qd = 0                         (closure: no relative motion of the grasps)
//!         lo <= qd <= hi                     (velocity and position bounds)
//! ```
//! `J_a = (J_1 + J_2) / 2` (absolute, cooperative task space) and
//! `J_R = [-R̄_1ᵀ Γ(p_2 - p_1) J_1, R̄_1ᵀ J_2]` (relative Jacobian, expressed in the first
//! end-effector frame, with the Γ term of Jamisola & Roberts). For one robot model holding both
//! arms (e.g. `two-irp6`), `J_1` and `J_2` are full-width Jacobians with zero columns for the
//! other arm's joints, and the two block columns add up.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT};
use embodied_models::JointLimits;
use embodied_models::nalgebra::{DMatrix, DVector, Isometry3, Matrix3, Matrix6xX, Vector3};

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
    pub lower: DVector<f64>,
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
