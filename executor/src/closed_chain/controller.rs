//! The per-step closed-chain controller: one QP per control period, built in buffers allocated
//! once, solved by the dense active-set solver with clarabel as fallback and cross-check.

use std::time::Instant;

use embodied_models::JointLimits;
use embodied_models::nalgebra::{DMatrix, DVector, Matrix6xX, Vector3, Vector6};

use super::dense::{DenseFailure, DenseQp, Problem};
use super::reference::{ClarabelQp, ReferenceFailure};
use crate::error::ExecutorError;

/// Which solver answers a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum QpBackend {
    /// The dense dual active-set solver (Goldfarb–Idnani), warm-started; falls back to
    /// [`QpBackend::Clarabel`] if it fails.
    Dense,
    /// Clarabel with one solver object whose data is updated each step.
    Clarabel,
    /// Clarabel with a new solver object each step (the pre-controller behaviour).
    ClarabelFresh,
}

/// How the closure constraint was enforced in a solution.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ClosureMode {
    /// `J_R qd = -k_r e_r` held as an equality.
    Hard,
    /// The equality was infeasible with the bounds; it became a cost term with weight
    /// [`ClosedChainConfig::closure_slack_weight`].
    Slacked,
}

/// Parameters of the controller, fixed at creation.
#[derive(Debug, Clone, PartialEq)]
pub struct ClosedChainConfig {
    /// Control period, s.
    pub dt: f64,
    /// Damping `lambda` on `||qd||²`.
    pub lambda: f64,
    /// Weight `mu` of `||qd - qd_prev||²` (smoothness).
    pub smoothness: f64,
    /// Drift-correction gain `k_r` (1/s) in `J_R qd = -k_r e_r`.
    pub closure_gain: f64,
    /// Weight of `||J_R qd + k_r e_r||²` when the closure has to be slacked.
    pub closure_slack_weight: f64,
    /// Most velocity-damper rows one step may carry.
    pub max_dampers: usize,
    /// Weight `nu` of `||qd - qd_ref||²` for a step that gives a reference velocity
    /// ([`StepInput::reference`], e.g. a planned posture with feedback): it resolves the
    /// redundancy left by the object task and the closure.
    pub reference_weight: f64,
    /// Solver used by [`ClosedChainController::step`].
    pub backend: QpBackend,
}

impl Default for ClosedChainConfig {
    fn default() -> Self {
        Self {
            dt: 1e-3,
            lambda: 1e-4,
            smoothness: 1e-3,
            closure_gain: 20.0,
            closure_slack_weight: 1e5,
            max_dampers: 16,
            reference_weight: 1e-2,
            backend: QpBackend::Dense,
        }
    }
}

/// Distances of a velocity damper (Faverjon & Tournassoud).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DamperParams {
    /// Gain `xi` (m/s): the approach speed allowed at the influence distance.
    pub xi: f64,
    /// Safety distance `d_s`: approach speed falls to zero there.
    pub safety: f64,
    /// Influence distance `d_i`: farther pairs give no row.
    pub influence: f64,
}

impl Default for DamperParams {
    fn default() -> Self {
        Self { xi: 0.2, safety: 0.01, influence: 0.1 }
    }
}

/// One inequality row `aᵀ qd <= b` (a collision velocity damper).
#[derive(Debug, Clone, PartialEq)]
pub struct VelocityDamper {
    /// Row coefficients `a` (one per joint).
    pub a: DVector<f64>,
    /// Right-hand side `b`.
    pub b: f64,
}

impl VelocityDamper {
    /// The row `aᵀ qd <= b`.
    pub fn new(a: DVector<f64>, b: f64) -> Self {
        Self { a, b }
    }

    /// The damper of a witness pair: points `p_a` (on body a) and `p_b` at `distance`, `normal`
    /// the unit vector from `p_b` to `p_a`, `jac_a`/`jac_b` the world-frame Jacobians of the two
    /// points (only the linear rows are used). The row bounds the approach speed:
    /// `-nᵀ (J_pa - J_pb) qd <= xi (d - d_s) / (d_i - d_s)`. `None` beyond the influence distance.
    pub fn from_witness(
        normal: &Vector3<f64>,
        jac_a: &Matrix6xX<f64>,
        jac_b: &Matrix6xX<f64>,
        distance: f64,
        params: &DamperParams,
    ) -> Option<Self> {
        if distance >= params.influence || jac_a.ncols() != jac_b.ncols() {
            return None;
        }
        let a = DVector::from_fn(jac_a.ncols(), |c, _| {
            -(0..3).map(|r| normal[r] * (jac_a[(r, c)] - jac_b[(r, c)])).sum::<f64>()
        });
        let b = params.xi * (distance - params.safety) / (params.influence - params.safety);
        Some(Self { a, b })
    }
}

/// What one control step needs. `j_a` and `j_r` are 6 x n (see [`super::ChainKinematics`]).
#[derive(Debug, Clone, Copy)]
pub struct StepInput<'a> {
    /// Current joint positions.
    pub q: &'a [f64],
    /// Absolute Jacobian `J_a`.
    pub j_a: &'a DMatrix<f64>,
    /// Relative Jacobian `J_R` (tool 2 relative to tool 1, in tool 1).
    pub j_r: &'a DMatrix<f64>,
    /// Desired absolute twist, feedback included (see [`super::pose_error`]).
    pub v_a: Vector6<f64>,
    /// Relative pose error `e_r` (see [`super::relative_pose_error`]).
    pub e_r: Vector6<f64>,
    /// Velocity-damper rows, at most [`ClosedChainConfig::max_dampers`].
    pub dampers: &'a [VelocityDamper],
    /// Reference joint velocities `qd_ref` (cost `nu ||qd - qd_ref||²`), or none.
    pub reference: Option<&'a [f64]>,
}

/// The answer of one step.
#[derive(Debug, Clone, PartialEq)]
pub struct ClosedChainSolution {
    /// Joint velocities to command; within the step's bounds (see
    /// [`ClosedChainController::bounds`]).
    pub qd: DVector<f64>,
    /// Whether the closure held as an equality or was slacked.
    pub closure: ClosureMode,
    /// `||J_R qd + k_r e_r||` (about zero when [`ClosureMode::Hard`]).
    pub closure_residual: f64,
    /// `||J_a qd - v_a||`.
    pub task_residual: f64,
    /// Cost at `qd` (including the slack term when slacked).
    pub objective: f64,
    /// The solver that produced `qd`.
    pub solver: QpBackend,
    /// Whether the dense solver failed and clarabel answered instead.
    pub fell_back: bool,
    /// Time of the step (data assembly and solve), ns.
    pub solve_ns: u64,
    /// Active constraints at the solution (equalities included).
    pub active_constraints: usize,
    /// Active-set steps (dense) or interior-point iterations (clarabel).
    pub iterations: usize,
}

/// Both solvers on the same step, for checking.
#[derive(Debug, Clone, PartialEq)]
pub struct QpComparison {
    /// The fast dense solver's solution.
    pub fast: ClosedChainSolution,
    /// Clarabel's solution of the same QP.
    pub reference: ClosedChainSolution,
    /// `||qd_fast - qd_ref||∞ / max(1, ||qd_ref||∞)`.
    pub qd_difference: f64,
    /// `|f_fast - f_ref| / max(1, |f_ref|)`.
    pub objective_difference: f64,
}

/// Per-step QP buffers shared by both solvers.
#[derive(Debug, Clone)]
struct QpData {
    h_hard: DMatrix<f64>,
    g_hard: DVector<f64>,
    h_soft: DMatrix<f64>,
    g_soft: DVector<f64>,
    soft_ready: bool,
    eq_t: DMatrix<f64>,
    eq_rhs: [f64; 6],
    lo: Vec<f64>,
    hi: Vec<f64>,
    rows_t: DMatrix<f64>,
    rows_rhs: Vec<f64>,
    row_count: usize,
}

impl QpData {
    fn problem(&self, hard: bool) -> Problem<'_> {
        Problem {
            h: if hard { &self.h_hard } else { &self.h_soft },
            g: if hard { &self.g_hard } else { &self.g_soft },
            eq_t: &self.eq_t,
            eq_rhs: &self.eq_rhs,
            eq_count: if hard { 6 } else { 0 },
            lo: &self.lo,
            hi: &self.hi,
            rows_t: &self.rows_t,
            rows_rhs: &self.rows_rhs,
            row_count: self.row_count,
        }
    }
}

/// A candidate answer before checking.
struct Candidate {
    mode: ClosureMode,
    active: Option<usize>,
    iterations: usize,
}

enum Failure {
    Infeasible(String),
    Failed(String),
}

/// Largest bound violation a solver answer may have before clipping (larger means a failed solve).
const CLIP_TOLERANCE: f64 = 1e-6;

/// The closed-chain velocity controller (robots/README.md section 6). Made once, then
/// [`ClosedChainController::step`] each control period:
///
/// ```text
/// min_qd  ||J_a qd - v_a||² + lambda ||qd||² + mu ||qd - qd_prev||² (+ nu ||qd - qd_ref||²)
/// s.t.    J_R qd = -k_r e_r                       (closure with drift correction)
///         lo <= qd <= hi                          (velocity, position-with-braking, acceleration)
///         a_iᵀ qd <= b_i                          (velocity dampers)
/// ```
///
/// When the closure equality cannot hold inside the bounds it moves into the cost with a large
/// weight ([`ClosureMode::Slacked`]). `qd_prev` is the previous answer; a failed step returns an
/// error and leaves it unchanged, and the caller halts.
#[derive(Debug)]
pub struct ClosedChainController {
    limits: Vec<JointLimits>,
    config: ClosedChainConfig,
    qd_prev: DVector<f64>,
    qd: DVector<f64>,
    data: QpData,
    dense: DenseQp,
    clarabel_hard: ClarabelQp,
    clarabel_soft: ClarabelQp,
}

fn invalid(what: &str, reason: impl Into<String>) -> ExecutorError {
    ExecutorError::InvalidParameter { what: what.to_string(), reason: reason.into() }
}

impl ClosedChainController {
    /// A controller for joints with `limits` (one per variable). Every joint needs finite positive
    /// velocity and acceleration limits and `lower <= upper`.
    pub fn new(limits: Vec<JointLimits>, config: ClosedChainConfig) -> Result<Self, ExecutorError> {
        let c = &config;
        if !(c.dt > 0.0 && c.dt.is_finite()) {
            return Err(invalid("dt", format!("{} is not a positive time", c.dt)));
        }
        let reg = c.lambda + c.smoothness;
        if !(c.lambda >= 0.0 && c.smoothness >= 0.0 && reg > 0.0 && reg.is_finite()) {
            return Err(invalid("lambda/smoothness", "need lambda, mu >= 0 with lambda + mu > 0 (strict convexity)"));
        }
        if !(c.closure_gain >= 0.0 && c.closure_gain.is_finite()) {
            return Err(invalid("closure_gain", format!("{} is not a gain >= 0", c.closure_gain)));
        }
        if !(c.closure_slack_weight > 0.0 && c.closure_slack_weight.is_finite()) {
            return Err(invalid("closure_slack_weight", format!("{} is not a weight > 0", c.closure_slack_weight)));
        }
        if limits.is_empty() {
            return Err(invalid("limits", "no joints"));
        }
        for (i, l) in limits.iter().enumerate() {
            let reason = if !(l.max_velocity > 0.0 && l.max_velocity.is_finite()) {
                Some("max_velocity must be finite and > 0")
            } else if !(l.max_acceleration > 0.0 && l.max_acceleration.is_finite()) {
                Some("max_acceleration must be finite and > 0")
            } else if l.lower.is_nan() || l.upper.is_nan() || l.lower > l.upper {
                Some("need lower <= upper")
            } else {
                None
            };
            if let Some(reason) = reason {
                return Err(ExecutorError::InvalidLimits { joint: i, reason: reason.into() });
            }
        }
        let n = limits.len();
        let m = c.max_dampers;
        let data = QpData {
            h_hard: DMatrix::zeros(n, n),
            g_hard: DVector::zeros(n),
            h_soft: DMatrix::zeros(n, n),
            g_soft: DVector::zeros(n),
            soft_ready: false,
            eq_t: DMatrix::zeros(n, 6),
            eq_rhs: [0.0; 6],
            lo: vec![0.0; n],
            hi: vec![0.0; n],
            rows_t: DMatrix::zeros(n, m),
            rows_rhs: vec![0.0; m],
            row_count: 0,
        };
        let clarabel_hard = ClarabelQp::new(n, 6, m).map_err(ExecutorError::Qp)?;
        let clarabel_soft = ClarabelQp::new(n, 0, m).map_err(ExecutorError::Qp)?;
        Ok(Self {
            limits,
            qd_prev: DVector::zeros(n),
            qd: DVector::zeros(n),
            data,
            dense: DenseQp::new(n, m),
            clarabel_hard,
            clarabel_soft,
            config,
        })
    }

    /// Number of joint variables.
    pub fn dof(&self) -> usize {
        self.limits.len()
    }

    /// The parameters fixed at creation.
    pub fn config(&self) -> &ClosedChainConfig {
        &self.config
    }

    /// The velocity commanded at the previous step (zero at creation).
    pub fn previous_velocity(&self) -> &DVector<f64> {
        &self.qd_prev
    }

    /// Set the velocity the next step starts from (e.g. the measured one when taking over).
    pub fn set_previous_velocity(&mut self, qd: &[f64]) -> Result<(), ExecutorError> {
        if qd.len() != self.dof() {
            return Err(ExecutorError::DimensionMismatch {
                what: "previous velocity".into(),
                expected: self.dof(),
                got: qd.len(),
            });
        }
        if qd.iter().any(|v| !v.is_finite()) {
            return Err(ExecutorError::NotFinite { what: "previous velocity".into() });
        }
        self.qd_prev.copy_from_slice(qd);
        self.dense.clear_warm_start();
        Ok(())
    }

    /// The bound box `(lo, hi)` of the last step.
    pub fn bounds(&self) -> (&[f64], &[f64]) {
        (&self.data.lo, &self.data.hi)
    }

    /// One control step with the configured backend.
    pub fn step(&mut self, input: &StepInput) -> Result<ClosedChainSolution, ExecutorError> {
        self.step_with(input, self.config.backend)
    }

    /// One control step with `backend`. On success the answer becomes the previous velocity.
    pub fn step_with(&mut self, input: &StepInput, backend: QpBackend) -> Result<ClosedChainSolution, ExecutorError> {
        let start = Instant::now();
        self.prepare(input)?;
        let mut sol = self.solve_prepared(input, backend)?;
        self.qd_prev.copy_from(&sol.qd);
        sol.solve_ns = elapsed_ns(start);
        Ok(sol)
    }

    /// Solve the step with the dense solver and with clarabel (data update) from the same state;
    /// the dense answer becomes the previous velocity. Either failing is an error.
    pub fn compare(&mut self, input: &StepInput) -> Result<QpComparison, ExecutorError> {
        let start = Instant::now();
        self.prepare(input)?;
        let prep = elapsed_ns(start);
        let t = Instant::now();
        let mut fast = self.solve_prepared(input, QpBackend::Dense)?;
        fast.solve_ns = prep + elapsed_ns(t);
        let t = Instant::now();
        let mut reference = self.solve_prepared(input, QpBackend::Clarabel)?;
        reference.solve_ns = prep + elapsed_ns(t);
        self.qd_prev.copy_from(&fast.qd);
        let qd_difference = (&fast.qd - &reference.qd).amax() / reference.qd.amax().max(1.0);
        let objective_difference = (fast.objective - reference.objective).abs() / reference.objective.abs().max(1.0);
        Ok(QpComparison { fast, reference, qd_difference, objective_difference })
    }

    /// Validate `input` and fill the QP buffers (cost, closure, bounds, dampers).
    fn prepare(&mut self, input: &StepInput) -> Result<(), ExecutorError> {
        let n = self.dof();
        let dims = |what: &str, expected: usize, got: usize| {
            if expected == got {
                Ok(())
            } else {
                Err(ExecutorError::DimensionMismatch { what: what.to_string(), expected, got })
            }
        };
        dims("q", n, input.q.len())?;
        dims("J_a columns", n, input.j_a.ncols())?;
        dims("J_a rows", 6, input.j_a.nrows())?;
        dims("J_R columns", n, input.j_r.ncols())?;
        dims("J_R rows", 6, input.j_r.nrows())?;
        if input.dampers.len() > self.config.max_dampers {
            return Err(ExecutorError::DimensionMismatch {
                what: "velocity dampers (at most max_dampers)".into(),
                expected: self.config.max_dampers,
                got: input.dampers.len(),
            });
        }
        let finite =
            |what: &str, ok: bool| if ok { Ok(()) } else { Err(ExecutorError::NotFinite { what: what.into() }) };
        finite("q", input.q.iter().all(|v| v.is_finite()))?;
        finite("J_a", input.j_a.iter().all(|v| v.is_finite()))?;
        finite("J_R", input.j_r.iter().all(|v| v.is_finite()))?;
        finite("v_a", input.v_a.iter().all(|v| v.is_finite()))?;
        finite("e_r", input.e_r.iter().all(|v| v.is_finite()))?;
        if let Some(r) = input.reference {
            dims("reference velocity", n, r.len())?;
            finite("reference velocity", r.iter().all(|v| v.is_finite()))?;
        }
        for d in input.dampers {
            dims("velocity damper row", n, d.a.len())?;
            finite("velocity damper row", d.a.iter().all(|v| v.is_finite()) && !d.b.is_nan())?;
        }

        let c = &self.config;
        let data = &mut self.data;
        step_bounds(input.q, self.qd_prev.as_slice(), &self.limits, c.dt, &mut data.lo, &mut data.hi);
        // H = 2 (J_aᵀ J_a + (lambda + mu) I), g = -2 (J_aᵀ v_a + mu qd_prev).
        data.h_hard.gemm_tr(2.0, input.j_a, input.j_a, 0.0);
        for i in 0..n {
            data.h_hard[(i, i)] += 2.0 * (c.lambda + c.smoothness);
        }
        data.g_hard.gemv_tr(-2.0, input.j_a, &input.v_a, 0.0);
        data.g_hard.axpy(-2.0 * c.smoothness, &self.qd_prev, 1.0);
        if let Some(r) = input.reference {
            for (i, v) in r.iter().enumerate().take(n) {
                data.h_hard[(i, i)] += 2.0 * c.reference_weight;
                data.g_hard[i] -= 2.0 * c.reference_weight * v;
            }
        }
        data.eq_t.tr_copy_from(input.j_r);
        for k in 0..6 {
            data.eq_rhs[k] = -c.closure_gain * input.e_r[k];
        }
        data.soft_ready = false;
        data.row_count = input.dampers.len();
        for (j, d) in input.dampers.iter().enumerate() {
            data.rows_t.column_mut(j).copy_from(&d.a);
            // A row with b = +inf never binds; keep the numbers finite for clarabel.
            data.rows_rhs[j] = d.b.min(1e9);
        }
        Ok(())
    }

    /// Build the slacked cost `H + 2w J_RᵀJ_R`, `g - 2w J_Rᵀ rhs` (once per step).
    fn prepare_soft(&mut self, input: &StepInput) {
        let data = &mut self.data;
        if data.soft_ready {
            return;
        }
        let w = self.config.closure_slack_weight;
        data.h_soft.copy_from(&data.h_hard);
        data.h_soft.gemm_tr(2.0 * w, input.j_r, input.j_r, 1.0);
        data.g_soft.copy_from(&data.g_hard);
        let rhs = Vector6::from_column_slice(&data.eq_rhs);
        data.g_soft.gemv_tr(-2.0 * w, input.j_r, &rhs, 1.0);
        data.soft_ready = true;
    }

    fn solve_prepared(&mut self, input: &StepInput, backend: QpBackend) -> Result<ClosedChainSolution, ExecutorError> {
        let outcome = match backend {
            QpBackend::Dense => match self.solve_dense(input) {
                Ok(c) => Ok((c, QpBackend::Dense, false)),
                Err(_) => self.solve_reference(input, false).map(|c| (c, QpBackend::Clarabel, true)),
            },
            QpBackend::Clarabel => self.solve_reference(input, false).map(|c| (c, backend, false)),
            QpBackend::ClarabelFresh => self.solve_reference(input, true).map(|c| (c, backend, false)),
        };
        match outcome {
            Ok((cand, solver, fell_back)) => Ok(self.finish(input, cand, solver, fell_back)),
            Err(Failure::Infeasible(why)) => Err(ExecutorError::QpInfeasible(why)),
            Err(Failure::Failed(why)) => Err(ExecutorError::Qp(why)),
        }
    }

    fn solve_dense(&mut self, input: &StepInput) -> Result<Candidate, Failure> {
        let hard = self.dense.solve(&self.data.problem(true));
        let mode = match hard {
            Ok(()) => ClosureMode::Hard,
            Err(DenseFailure::Infeasible) => {
                self.prepare_soft(input);
                self.dense.solve(&self.data.problem(false)).map_err(dense_failure)?;
                ClosureMode::Slacked
            }
            Err(e) => return Err(dense_failure(e)),
        };
        self.qd.copy_from_slice(self.dense.x());
        let cand = Candidate { mode, active: Some(self.dense.active_count()), iterations: self.dense.iterations };
        self.check(input, cand)
    }

    fn solve_reference(&mut self, input: &StepInput, fresh: bool) -> Result<Candidate, Failure> {
        let (x, mode, iterations) = match self.clarabel_hard.solve(&self.data.problem(true), fresh) {
            Ok((x, it)) => (x, ClosureMode::Hard, it),
            Err(ReferenceFailure::Infeasible(_)) => {
                self.prepare_soft(input);
                match self.clarabel_soft.solve(&self.data.problem(false), fresh) {
                    Ok((x, it)) => (x, ClosureMode::Slacked, it),
                    Err(ReferenceFailure::Infeasible(why)) => {
                        return Err(Failure::Infeasible(format!("bounds and damper rows admit no velocity ({why})")));
                    }
                    Err(ReferenceFailure::Failed(why)) => return Err(Failure::Failed(why)),
                }
            }
            Err(ReferenceFailure::Failed(why)) => return Err(Failure::Failed(why)),
        };
        self.qd.copy_from_slice(x);
        self.check(input, Candidate { mode, active: None, iterations })
    }

    /// Check a candidate in `self.qd`: finite, within the box up to [`CLIP_TOLERANCE`] (then
    /// clipped exactly into it), damper rows and (hard mode) closure satisfied.
    fn check(&mut self, input: &StepInput, cand: Candidate) -> Result<Candidate, Failure> {
        let data = &self.data;
        for i in 0..self.qd.len() {
            let v = self.qd[i];
            if !v.is_finite() {
                return Err(Failure::Failed("solver returned a non-finite velocity".into()));
            }
            let excess = (data.lo[i] - v).max(v - data.hi[i]);
            if excess > CLIP_TOLERANCE {
                return Err(Failure::Failed(format!("joint {i}: velocity {v} outside the step bounds by {excess}")));
            }
            self.qd[i] = v.clamp(data.lo[i], data.hi[i]);
        }
        for j in 0..data.row_count {
            let lhs = data.rows_t.column(j).dot(&self.qd);
            let b = data.rows_rhs[j];
            if lhs - b > CLIP_TOLERANCE * (1.0 + b.abs()) {
                return Err(Failure::Failed(format!("damper row {j} violated: {lhs} > {b}")));
            }
        }
        if cand.mode == ClosureMode::Hard {
            let res = closure_residual(input.j_r, &self.qd, &data.eq_rhs);
            let rhs = Vector6::from_column_slice(&data.eq_rhs).norm();
            if res > 1e-6 * (1.0 + rhs) {
                return Err(Failure::Failed(format!("closure residual {res} after a hard solve")));
            }
        }
        Ok(cand)
    }

    fn finish(&self, input: &StepInput, cand: Candidate, solver: QpBackend, fell_back: bool) -> ClosedChainSolution {
        let c = &self.config;
        let data = &self.data;
        let qd = self.qd.clone();
        let task = input.j_a * &qd - input.v_a;
        let task_residual = task.norm();
        let closure_residual = closure_residual(input.j_r, &qd, &data.eq_rhs);
        let mut objective =
            task_residual.powi(2) + c.lambda * qd.norm_squared() + c.smoothness * (&qd - &self.qd_prev).norm_squared();
        if let Some(r) = input.reference {
            objective += c.reference_weight * qd.iter().zip(r).map(|(a, b)| (a - b) * (a - b)).sum::<f64>();
        }
        if cand.mode == ClosureMode::Slacked {
            objective += c.closure_slack_weight * closure_residual.powi(2);
        }
        let active_constraints = cand.active.unwrap_or_else(|| {
            let tol = 1e-8;
            let eq = if cand.mode == ClosureMode::Hard { 6 } else { 0 };
            let boxes = (0..qd.len()).filter(|&i| qd[i] - data.lo[i] <= tol || data.hi[i] - qd[i] <= tol).count();
            let rows = (0..data.row_count)
                .filter(|&j| data.rows_rhs[j] - data.rows_t.column(j).dot(&qd) <= tol * (1.0 + data.rows_rhs[j].abs()))
                .count();
            eq + boxes + rows
        });
        ClosedChainSolution {
            qd,
            closure: cand.mode,
            closure_residual,
            task_residual,
            objective,
            solver,
            fell_back,
            solve_ns: 0,
            active_constraints,
            iterations: cand.iterations,
        }
    }
}

fn dense_failure(e: DenseFailure) -> Failure {
    match e {
        DenseFailure::Infeasible => Failure::Infeasible("dense solver: infeasible".into()),
        e => Failure::Failed(format!("dense solver: {e:?}")),
    }
}

fn elapsed_ns(t: Instant) -> u64 {
    u64::try_from(t.elapsed().as_nanos()).unwrap_or(u64::MAX)
}

/// `||J_R qd - rhs||` with `rhs = -k_r e_r`.
fn closure_residual(j_r: &DMatrix<f64>, qd: &DVector<f64>, rhs: &[f64; 6]) -> f64 {
    (0..6).map(|k| (j_r.row(k).dot(&qd.transpose()) - rhs[k]).powi(2)).sum::<f64>().sqrt()
}

/// The largest speed toward a position limit `distance` ahead (> 0) from which the joint can
/// still stop in time braking at `a` with steps of `dt`: `v` with `v² + 2 a dt v = 2 a d`, i.e.
/// braking room measured after this step's motion. It is below both `sqrt(2 a d)` and `d / dt`,
/// and stays feasible from one step to the next under maximal braking.
fn braking_speed(distance: f64, a: f64, dt: f64) -> f64 {
    let adt = a * dt;
    (-adt + (adt * adt + 2.0 * a * distance).sqrt()).min(distance / dt).max(0.0)
}

/// `p - dv` and `p + dv`, each moved one ulp toward `p` when rounding put it farther than `dv`
/// from `p`: the velocity change of a step, as computed, never exceeds `dv` (at 3.8 rad/s a
/// change of 1e-5 rad/s rounds by up to 4e-16, 4e-11 of the change).
fn acceleration_window(p: f64, dv: f64) -> (f64, f64) {
    let mut lo = p - dv;
    if p - lo > dv {
        lo = lo.next_up();
    }
    let mut hi = p + dv;
    if hi - p > dv {
        hi = hi.next_down();
    }
    (lo, hi)
}

/// Bounds of one step's joint velocities into `lo`/`hi`, from positions `q`, the previous velocity
/// `qd_prev`, `limits` and period `dt`:
///
/// * `|qd| <= max_velocity` and `|qd - qd_prev| <= max_acceleration dt`;
/// * near a finite position limit, at most the braking speed (see the source), which also keeps
///   `q + qd dt` inside the limits; continuous joints have no position bound.
///
/// The box is never empty. The acceleration bound comes first: if the previous velocity is
/// outside the velocity bound, or too fast to respect a position limit, the box is the single
/// velocity of hardest deceleration. Slices shorter than the joint count are only partly filled.
pub fn step_bounds(q: &[f64], qd_prev: &[f64], limits: &[JointLimits], dt: f64, lo: &mut [f64], hi: &mut [f64]) {
    let n = q.len().min(qd_prev.len()).min(limits.len()).min(lo.len()).min(hi.len());
    for i in 0..n {
        let l = &limits[i];
        let (p, dv) = (qd_prev[i], l.max_acceleration * dt);
        let (slowest, fastest) = acceleration_window(p, dv);
        // Velocity and acceleration; if they do not meet, decelerate as hard as allowed.
        let (mut vlo, mut vhi) = ((-l.max_velocity).max(slowest), l.max_velocity.min(fastest));
        if vlo > vhi {
            let v = if p > 0.0 { slowest } else { fastest };
            (vlo, vhi) = (v, v);
        }
        // Position with braking room.
        let ph = if l.upper.is_finite() {
            let d = l.upper - q[i];
            if d > 0.0 { braking_speed(d, l.max_acceleration, dt) } else { d / dt }
        } else {
            f64::INFINITY
        };
        let pl = if l.lower.is_finite() {
            let d = q[i] - l.lower;
            if d > 0.0 { -braking_speed(d, l.max_acceleration, dt) } else { -d / dt }
        } else {
            f64::NEG_INFINITY
        };
        // Beyond one limit, only that one matters (the way back is toward the other).
        let (pl, ph) = if ph < 0.0 {
            (f64::NEG_INFINITY, ph)
        } else if pl > 0.0 {
            (pl, f64::INFINITY)
        } else {
            (pl, ph)
        };
        let (a, b) = (vlo.max(pl), vhi.min(ph));
        (lo[i], hi[i]) = if a <= b {
            (a, b)
        } else if ph < vlo {
            (vlo, vlo)
        } else {
            (vhi, vhi)
        };
    }
}
