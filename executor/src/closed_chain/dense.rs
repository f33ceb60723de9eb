//! A small dense QP solver: the dual active-set method of Goldfarb and Idnani (Math. Programming
//! 27, 1983) for strictly convex problems
//!
//! ```text
//! min_x  ½ xᵀ H x + gᵀ x
//! s.t.   e_kᵀ x = c_k          (equalities, always active)
//!        lo <= x <= hi         (box)
//!        a_jᵀ x <= b_j         (general rows)
//! ```
//!
//! The method starts at the unconstrained minimum and adds violated constraints one at a time,
//! keeping the dual variables feasible; it ends at the first primal-feasible point, which is then
//! optimal. It keeps `J = L⁻ᵀ Q` (with `H = L Lᵀ` and `L⁻¹ N = Q [R; 0]` for the active normals
//! `N`) up to date with Givens rotations, so a step costs O(n²). Warm start: among the violated
//! constraints, those active at the previous solve are added first, which usually reproduces the
//! previous active set in as many steps as it has members.
//!
//! Everything lives in buffers allocated once; a solve allocates nothing.

use embodied_models::nalgebra::{DMatrix, DVector};

/// One constraint, written internally as `σ nᵀ x >= σ c` (`σ = ±1` only for equalities).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Con {
    /// Equality `k`.
    Eq(usize),
    /// `x_i >= lo_i`.
    Lower(usize),
    /// `x_i <= hi_i`.
    Upper(usize),
    /// General row `a_jᵀ x <= b_j`.
    Row(usize),
}

/// The data of one problem, borrowed from the caller's buffers.
pub(crate) struct Problem<'a> {
    /// Hessian (n x n, symmetric positive definite).
    pub h: &'a DMatrix<f64>,
    pub g: &'a DVector<f64>,
    /// Equality normals as columns (n x at least `eq_count`).
    pub eq_t: &'a DMatrix<f64>,
    pub eq_rhs: &'a [f64],
    pub eq_count: usize,
    pub lo: &'a [f64],
    pub hi: &'a [f64],
    /// Row normals `a_j` as columns (n x at least `row_count`).
    pub rows_t: &'a DMatrix<f64>,
    pub rows_rhs: &'a [f64],
    pub row_count: usize,
}

impl Problem<'_> {
    fn normal_dot(&self, c: Con, v: &[f64]) -> f64 {
        match c {
            Con::Eq(k) => dot(col(self.eq_t, k), v),
            Con::Lower(i) => v[i],
            Con::Upper(i) => -v[i],
            Con::Row(j) => -dot(col(self.rows_t, j), v),
        }
    }
    fn rhs(&self, c: Con) -> f64 {
        match c {
            Con::Eq(k) => self.eq_rhs[k],
            Con::Lower(i) => self.lo[i],
            Con::Upper(i) => -self.hi[i],
            Con::Row(j) => -self.rows_rhs[j],
        }
    }
}

fn col(m: &DMatrix<f64>, j: usize) -> &[f64] {
    let n = m.nrows();
    &m.as_slice()[j * n..(j + 1) * n]
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Why a dense solve stopped without a solution.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum DenseFailure {
    /// The constraints admit no point (a violated constraint cannot be added).
    Infeasible,
    /// The Hessian is not numerically positive definite.
    NotConvex,
    /// More add/drop steps than the bound allows (cycling from round-off).
    IterationLimit,
    /// A triangular factor became singular.
    Numerical,
}

/// Workspace of the solver; reuse one per problem size.
#[derive(Debug, Clone)]
pub(crate) struct DenseQp {
    n: usize,
    l: DMatrix<f64>,
    /// `J = L⁻ᵀ Q`, column-major.
    jm: DMatrix<f64>,
    r: DMatrix<f64>,
    x: Vec<f64>,
    z: Vec<f64>,
    d: Vec<f64>,
    rv: Vec<f64>,
    u: Vec<f64>,
    active: Vec<(Con, f64)>,
    warm: Vec<Con>,
    row_norm: Vec<f64>,
    /// Add/drop steps of the last solve.
    pub iterations: usize,
}

const MAX_STEPS_FACTOR: usize = 8;

impl DenseQp {
    pub fn new(n: usize, max_rows: usize) -> Self {
        Self {
            n,
            l: DMatrix::zeros(n, n),
            jm: DMatrix::zeros(n, n),
            r: DMatrix::zeros(n, n),
            x: vec![0.0; n],
            z: vec![0.0; n],
            d: vec![0.0; n],
            rv: vec![0.0; n],
            u: Vec::with_capacity(n + 1),
            active: Vec::with_capacity(n + 1),
            warm: Vec::with_capacity(n + 1),
            row_norm: vec![0.0; max_rows],
            iterations: 0,
        }
    }

    /// The solution of the last successful solve.
    pub fn x(&self) -> &[f64] {
        &self.x
    }

    /// Number of active constraints (equalities included) at the last solution.
    pub fn active_count(&self) -> usize {
        self.active.len()
    }

    /// Forget the warm-start active set.
    pub fn clear_warm_start(&mut self) {
        self.warm.clear();
    }

    /// Solve `p`; on success the solution is [`DenseQp::x`].
    pub fn solve(&mut self, p: &Problem) -> Result<(), DenseFailure> {
        let n = self.n;
        self.iterations = 0;
        self.active.clear();
        self.u.clear();
        self.factor(p.h)?;
        // x = -H⁻¹ g = -J Jᵀ g.
        for j in 0..n {
            self.d[j] = dot(col(&self.jm, j), p.g.as_slice());
        }
        self.x.fill(0.0);
        for j in 0..n {
            let dj = self.d[j];
            for (xi, jij) in self.x.iter_mut().zip(col(&self.jm, j)) {
                *xi -= jij * dj;
            }
        }
        for j in 0..p.row_count {
            self.row_norm[j] = dot(col(p.rows_t, j), col(p.rows_t, j)).sqrt().max(f64::MIN_POSITIVE);
        }
        let max_steps = MAX_STEPS_FACTOR * (n + p.eq_count + 2 * n + p.row_count) + 10;
        for k in 0..p.eq_count {
            let c = Con::Eq(k);
            let s = p.normal_dot(c, &self.x) - p.rhs(c);
            let sigma = if s > 0.0 { -1.0 } else { 1.0 };
            self.add(p, c, sigma, max_steps)?;
        }
        while let Some(c) = self.most_violated(p) {
            self.add(p, c, 1.0, max_steps)?;
        }
        self.warm.clear();
        for &(c, _) in &self.active {
            if !matches!(c, Con::Eq(_)) {
                self.warm.push(c);
            }
        }
        Ok(())
    }

    /// Cholesky `H = L Lᵀ`, then `J = L⁻ᵀ` (upper triangular).
    fn factor(&mut self, h: &DMatrix<f64>) -> Result<(), DenseFailure> {
        let n = self.n;
        let l = &mut self.l;
        l.fill(0.0);
        for j in 0..n {
            let mut diag = h[(j, j)];
            for k in 0..j {
                diag -= l[(j, k)] * l[(j, k)];
            }
            if diag.is_nan() || diag <= 0.0 || diag.is_infinite() {
                return Err(DenseFailure::NotConvex);
            }
            let ljj = diag.sqrt();
            l[(j, j)] = ljj;
            for i in j + 1..n {
                let mut v = h[(i, j)];
                for k in 0..j {
                    v -= l[(i, k)] * l[(j, k)];
                }
                l[(i, j)] = v / ljj;
            }
        }
        // Column c of L⁻¹ by forward substitution; J = (L⁻¹)ᵀ, so J[c, i] = L⁻¹[i, c].
        let jm = &mut self.jm;
        jm.fill(0.0);
        for c in 0..n {
            // y = L⁻¹ e_c has y_i = 0 for i < c.
            for i in c..n {
                let mut v = if i == c { 1.0 } else { 0.0 };
                for k in c..i {
                    v -= l[(i, k)] * jm[(c, k)];
                }
                jm[(c, i)] = v / l[(i, i)];
            }
        }
        Ok(())
    }

    /// The most violated inequality (normalised by the normal's length), preferring those active
    /// at the previous solve.
    fn most_violated(&self, p: &Problem) -> Option<Con> {
        let tol = 1e-11;
        let mut best: Option<(Con, f64)> = None;
        // Warm start: a previously active constraint that is violated now goes first.
        for &c in &self.warm {
            let valid = match c {
                Con::Row(j) => j < p.row_count,
                Con::Lower(i) | Con::Upper(i) => i < self.n,
                Con::Eq(_) => false,
            };
            if valid && !self.is_active(c) {
                let v = self.violation(p, c);
                if v > tol && best.is_none_or(|(_, b)| v > b) {
                    best = Some((c, v));
                }
            }
        }
        if let Some((c, _)) = best {
            return Some(c);
        }
        for i in 0..self.n {
            for c in [Con::Lower(i), Con::Upper(i)] {
                let v = self.violation(p, c);
                if v > tol * (1.0 + p.rhs(c).abs()) && best.is_none_or(|(_, b)| v > b) && !self.is_active(c) {
                    best = Some((c, v));
                }
            }
        }
        for j in 0..p.row_count {
            let c = Con::Row(j);
            let v = self.violation(p, c);
            if v > tol * (1.0 + p.rhs(c).abs()) && best.is_none_or(|(_, b)| v > b) && !self.is_active(c) {
                best = Some((c, v));
            }
        }
        best.map(|(c, _)| c)
    }

    fn violation(&self, p: &Problem, c: Con) -> f64 {
        let s = p.rhs(c) - p.normal_dot(c, &self.x);
        match c {
            Con::Row(j) => s / self.row_norm[j],
            _ => s,
        }
    }

    fn is_active(&self, c: Con) -> bool {
        self.active.iter().any(|&(a, _)| a == c)
    }

    /// Add constraint `c` (with sign `sigma`) to the active set, dropping blocking ones on the way.
    fn add(&mut self, p: &Problem, c: Con, sigma: f64, max_steps: usize) -> Result<(), DenseFailure> {
        let n = self.n;
        let is_eq = matches!(c, Con::Eq(_));
        let mut s = sigma * (p.normal_dot(c, &self.x) - p.rhs(c));
        let mut u_plus = 0.0;
        loop {
            self.iterations += 1;
            if self.iterations > max_steps {
                return Err(DenseFailure::IterationLimit);
            }
            let q = self.active.len();
            // d = Jᵀ n.
            let mut dn2 = 0.0;
            for j in 0..n {
                self.d[j] = sigma * p.normal_dot(c, col(&self.jm, j));
                dn2 += self.d[j] * self.d[j];
            }
            // Primal direction z = J₂ d₂ and its curvature zᵀn = |d₂|².
            self.z.fill(0.0);
            let mut zn = 0.0;
            for j in q..n {
                let dj = self.d[j];
                zn += dj * dj;
                for (zi, jij) in self.z.iter_mut().zip(col(&self.jm, j)) {
                    *zi += jij * dj;
                }
            }
            // Dual direction r = R⁻¹ d₁.
            for i in (0..q).rev() {
                let mut v = self.d[i];
                for k in i + 1..q {
                    v -= self.r[(i, k)] * self.rv[k];
                }
                let rii = self.r[(i, i)];
                if rii == 0.0 {
                    return Err(DenseFailure::Numerical);
                }
                self.rv[i] = v / rii;
            }
            // Largest dual step keeping inequality multipliers non-negative.
            let mut t1 = f64::INFINITY;
            let mut drop_at = None;
            for j in 0..q {
                if matches!(self.active[j].0, Con::Eq(_)) {
                    continue;
                }
                let rj = self.rv[j];
                if rj > 1e-12 {
                    let ratio = self.u[j] / rj;
                    if ratio < t1 {
                        t1 = ratio;
                        drop_at = Some(j);
                    }
                }
            }
            let has_primal = zn > 1e-20 * dn2.max(f64::MIN_POSITIVE) && zn > 0.0;
            let t2 = if has_primal { (-s / zn).max(0.0) } else { f64::INFINITY };
            let t = t1.min(t2);
            if !t.is_finite() {
                if is_eq && s.abs() <= 1e-10 * (1.0 + p.rhs(c).abs()) {
                    // A dependent equality that already holds.
                    return Ok(());
                }
                return Err(DenseFailure::Infeasible);
            }
            for j in 0..q {
                self.u[j] -= t * self.rv[j];
            }
            u_plus += t;
            if has_primal {
                for (xi, zi) in self.x.iter_mut().zip(&self.z) {
                    *xi += t * zi;
                }
                s += t * zn;
                if t2 <= t1 {
                    self.append(c, sigma, u_plus)?;
                    return Ok(());
                }
            }
            match drop_at {
                Some(k) => self.remove(k),
                None => return Err(DenseFailure::Numerical),
            }
        }
    }

    /// Append the constraint whose `d = Jᵀ n` is in `self.d` to the factorisation.
    fn append(&mut self, c: Con, sigma: f64, u: f64) -> Result<(), DenseFailure> {
        let n = self.n;
        let q = self.active.len();
        for j in (q + 1..n).rev() {
            let (a, b) = (self.d[j - 1], self.d[j]);
            if b == 0.0 {
                continue;
            }
            let h = a.hypot(b);
            let (cs, sn) = (a / h, b / h);
            self.d[j - 1] = h;
            self.d[j] = 0.0;
            rotate_columns(&mut self.jm, j - 1, j, cs, sn);
        }
        for i in 0..=q {
            self.r[(i, q)] = self.d[i];
        }
        if self.r[(q, q)].abs() <= 1e-14 {
            return Err(DenseFailure::Numerical);
        }
        self.active.push((c, sigma));
        self.u.push(u);
        Ok(())
    }

    /// Drop the active constraint at position `k` and re-triangularise `R`.
    fn remove(&mut self, k: usize) {
        let q = self.active.len();
        self.active.remove(k);
        self.u.remove(k);
        for cidx in k..q - 1 {
            for i in 0..=cidx + 1 {
                self.r[(i, cidx)] = self.r[(i, cidx + 1)];
            }
        }
        let newq = q - 1;
        for j in k..newq {
            let (a, b) = (self.r[(j, j)], self.r[(j + 1, j)]);
            if b == 0.0 {
                continue;
            }
            let h = a.hypot(b);
            let (cs, sn) = (a / h, b / h);
            for cidx in j..newq {
                let (x, y) = (self.r[(j, cidx)], self.r[(j + 1, cidx)]);
                self.r[(j, cidx)] = cs * x + sn * y;
                self.r[(j + 1, cidx)] = -sn * x + cs * y;
            }
            self.r[(j + 1, j)] = 0.0;
            rotate_columns(&mut self.jm, j, j + 1, cs, sn);
        }
    }
}

/// Columns `(a, b)` of `m` become `(c a + s b, -s a + c b)`.
fn rotate_columns(m: &mut DMatrix<f64>, a: usize, b: usize, c: f64, s: f64) {
    let n = m.nrows();
    let data = m.as_mut_slice();
    let (lo, hi) = data.split_at_mut(b * n);
    let ca = &mut lo[a * n..(a + 1) * n];
    let cb = &mut hi[..n];
    for (x, y) in ca.iter_mut().zip(cb.iter_mut()) {
        let (u, v) = (*x, *y);
        *x = c * u + s * v;
        *y = -s * u + c * v;
    }
}
