//! The reference solver: clarabel (interior point) on the same QP data as the dense solver.
//!
//! The sparsity pattern is fixed when the object is made: dense Hessian (upper triangle), dense
//! equality and general rows (padded rows are `0ᵀ x <= 1`), two unit rows per box. Presolve and
//! zero dropping are off, so clarabel 0.11 accepts `update_P/q/A/b` on its one solver object and
//! each step only overwrites values (the equilibration computed for the first step is reused).

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettings, DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};

use super::dense::Problem;

/// How a reference solve stopped without a solution.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum ReferenceFailure {
    Infeasible(String),
    Failed(String),
}

/// One clarabel problem of fixed shape (`n` variables, `eq` equalities, `max_rows` general rows).
pub(crate) struct ClarabelQp {
    n: usize,
    eq: usize,
    max_rows: usize,
    p: CscMatrix<f64>,
    a: CscMatrix<f64>,
    q: Vec<f64>,
    b: Vec<f64>,
    cones: Vec<SupportedConeT<f64>>,
    settings: DefaultSettings<f64>,
    solver: Option<DefaultSolver<f64>>,
    /// Interior-point iterations of the last solve.
    pub iterations: usize,
}

impl std::fmt::Debug for ClarabelQp {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ClarabelQp")
            .field("n", &self.n)
            .field("eq", &self.eq)
            .field("max_rows", &self.max_rows)
            .field("built", &self.solver.is_some())
            .finish()
    }
}

impl ClarabelQp {
    pub fn new(n: usize, eq: usize, max_rows: usize) -> Result<Self, String> {
        // P: upper triangle, column c holds rows 0..=c.
        let mut colptr = vec![0];
        let mut rowval = Vec::new();
        for c in 0..n {
            rowval.extend(0..=c);
            colptr.push(rowval.len());
        }
        let p = CscMatrix::new(n, n, colptr, rowval.clone(), vec![0.0; rowval.len()]);
        // A rows: equalities, then (x_i <= hi_i, -x_i <= -lo_i) per joint, then general rows.
        let m = eq + 2 * n + max_rows;
        let mut colptr = vec![0];
        let mut rowval = Vec::new();
        for c in 0..n {
            rowval.extend(0..eq);
            rowval.push(eq + 2 * c);
            rowval.push(eq + 2 * c + 1);
            rowval.extend(eq + 2 * n..m);
            colptr.push(rowval.len());
        }
        let a = CscMatrix::new(m, n, colptr, rowval.clone(), vec![0.0; rowval.len()]);
        let mut cones = Vec::new();
        if eq > 0 {
            cones.push(SupportedConeT::ZeroConeT(eq));
        }
        cones.push(SupportedConeT::NonnegativeConeT(2 * n + max_rows));
        let settings = DefaultSettingsBuilder::default()
            .verbose(false)
            .presolve_enable(false)
            .input_sparse_dropzeros(false)
            .tol_gap_abs(1e-10)
            .tol_gap_rel(1e-10)
            .tol_feas(1e-10)
            .tol_ktratio(1e-8)
            .max_iter(100)
            .build()
            .map_err(|e| e.to_string())?;
        Ok(Self {
            n,
            eq,
            max_rows,
            p,
            a,
            q: vec![0.0; n],
            b: vec![0.0; m],
            cones,
            settings,
            solver: None,
            iterations: 0,
        })
    }

    /// Copy `prob` into the value arrays of the fixed pattern.
    fn load(&mut self, prob: &Problem) {
        let (n, eq) = (self.n, self.eq);
        let mut k = 0;
        for c in 0..n {
            for r in 0..=c {
                self.p.nzval[k] = prob.h[(r, c)];
                k += 1;
            }
        }
        self.q.copy_from_slice(prob.g.as_slice());
        let mut k = 0;
        for c in 0..n {
            for e in 0..eq {
                self.a.nzval[k] = prob.eq_t[(c, e)];
                k += 1;
            }
            self.a.nzval[k] = 1.0;
            self.a.nzval[k + 1] = -1.0;
            k += 2;
            for j in 0..self.max_rows {
                self.a.nzval[k] = if j < prob.row_count { prob.rows_t[(c, j)] } else { 0.0 };
                k += 1;
            }
        }
        self.b[..eq].copy_from_slice(&prob.eq_rhs[..eq]);
        for i in 0..n {
            self.b[eq + 2 * i] = prob.hi[i];
            self.b[eq + 2 * i + 1] = -prob.lo[i];
        }
        for j in 0..self.max_rows {
            self.b[eq + 2 * n + j] = if j < prob.row_count { prob.rows_rhs[j] } else { 1.0 };
        }
    }

    /// Solve `prob`; `fresh` builds a new solver object (as a per-step rebuild would), otherwise
    /// the kept one gets the new values. Returns the solution and the iteration count.
    pub fn solve(&mut self, prob: &Problem, fresh: bool) -> Result<(&[f64], usize), ReferenceFailure> {
        self.load(prob);
        let reuse = !fresh && self.solver.is_some();
        if reuse {
            let solver = self.solver.as_mut().ok_or_else(|| ReferenceFailure::Failed("no solver".into()))?;
            solver
                .update_P(&self.p.nzval)
                .and_then(|()| solver.update_q(&self.q))
                .and_then(|()| solver.update_A(&self.a.nzval))
                .and_then(|()| solver.update_b(&self.b))
                .map_err(|e| ReferenceFailure::Failed(format!("clarabel data update: {e}")))?;
        } else {
            let solver = DefaultSolver::new(&self.p, &self.q, &self.a, &self.b, &self.cones, self.settings.clone())
                .map_err(|e| ReferenceFailure::Failed(e.to_string()))?;
            self.solver = Some(solver);
        }
        let solver = self.solver.as_mut().ok_or_else(|| ReferenceFailure::Failed("no solver".into()))?;
        solver.solve();
        self.iterations = solver.solution.iterations as usize;
        match solver.solution.status {
            SolverStatus::Solved | SolverStatus::AlmostSolved => Ok((&solver.solution.x, self.iterations)),
            s @ (SolverStatus::PrimalInfeasible | SolverStatus::AlmostPrimalInfeasible) => {
                Err(ReferenceFailure::Infeasible(format!("clarabel: {s:?}")))
            }
            s => Err(ReferenceFailure::Failed(format!("clarabel: {s:?}"))),
        }
    }
}
