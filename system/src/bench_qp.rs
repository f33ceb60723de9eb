//! `embodied bench qp`: the closed-chain QPs of one carry run, each solved by the fast dense
//! solver and by clarabel.

use embodied_executor::closed_chain::carry::percentiles_us;
use serde::Serialize;

use crate::SystemError;
use crate::system::{RunArgs, RunOptions, run_scenario};

/// `embodied bench qp`: the closed-chain QPs of one carry run, both solvers.
#[derive(Debug, Clone, Serialize)]
pub struct QpBenchReport {
    /// The scenario run.
    pub scenario: String,
    /// Held steps whose QP both solvers solved.
    pub steps: usize,
    /// Fast dense solver (Goldfarb–Idnani, warm-started): data assembly and solve, µs.
    pub dense_p50_us: f64,
    /// Fast dense solver, 99th percentile, µs.
    pub dense_p99_us: f64,
    /// Fast dense solver, largest, µs.
    pub dense_max_us: f64,
    /// Clarabel (one solver, data updated in place) on the same QPs, µs.
    pub clarabel_p50_us: f64,
    /// Clarabel, 99th percentile, µs.
    pub clarabel_p99_us: f64,
    /// Clarabel, largest, µs.
    pub clarabel_max_us: f64,
    /// Clarabel p50 / dense p50.
    pub speedup_p50: f64,
    /// Steps whose QP (dense) alone took longer than the 1 ms control step.
    pub dense_late_steps: usize,
    /// Steps whose QP (clarabel) alone took longer than the 1 ms control step.
    pub clarabel_late_steps: usize,
    /// Largest `||qd_dense - qd_clarabel||∞ / max(1, ||qd_clarabel||∞)` over the steps.
    pub max_qd_difference: f64,
    /// Largest `|f_dense - f_clarabel| / max(1, |f_clarabel|)` over the steps (objective values).
    pub max_objective_difference: f64,
    /// Safe halts begun during the run.
    pub halts: usize,
    /// Largest drift of the relative pose of the two tools from its value at the grasp, m.
    pub max_closure_error_m: f64,
}

/// Run the carry of `scenario` with every QP solved by both solvers.
pub fn bench_qp(scenario: &str) -> Result<QpBenchReport, SystemError> {
    if crate::scenario::load_scenario(scenario)?.carry.is_none() {
        return Err(SystemError::Usage(format!(
            "scenario `{scenario}` has no [carry] table: no closed-chain QP to time"
        )));
    }
    let options = RunOptions { qp_compare: true, ..RunOptions::default() };
    let args = RunArgs { scenario: scenario.to_string(), options, ..RunArgs::default() };
    let (summary, system) = run_scenario(&args)?;
    let (Some(c), Some(record)) = (&summary.closed_chain, system.carry_record()) else {
        return Err(SystemError::Usage(format!(
            "scenario `{scenario}` has no [carry] table: no closed-chain QP to time"
        )));
    };
    let r = record.lock().map_err(|_| SystemError::Failed("carry record poisoned".into()))?;
    let (dense_p50_us, dense_p99_us, dense_max_us) = percentiles_us(&r.fast_ns);
    let (clarabel_p50_us, clarabel_p99_us, clarabel_max_us) = percentiles_us(&r.reference_ns);
    let late = |ns: &[u64]| ns.iter().filter(|v| **v > 1_000_000).count();
    Ok(QpBenchReport {
        scenario: summary.scenario.clone(),
        steps: r.fast_ns.len(),
        dense_p50_us,
        dense_p99_us,
        dense_max_us,
        clarabel_p50_us,
        clarabel_p99_us,
        clarabel_max_us,
        speedup_p50: clarabel_p50_us / dense_p50_us.max(1e-9),
        dense_late_steps: late(&r.fast_ns),
        clarabel_late_steps: late(&r.reference_ns),
        max_qd_difference: r.max_qd_difference,
        max_objective_difference: r.max_objective_difference,
        halts: c.halts,
        max_closure_error_m: c.max_closure_error_m,
    })
}

/// The report as text.
pub fn render_bench_qp(r: &QpBenchReport) -> String {
    format!(
        "closed-chain QP of `{}`: {} held steps, each solved by both solvers\n\
         \x20 dense (Goldfarb-Idnani, warm start): p50 {:.1} us, p99 {:.1} us, max {:.1} us, {} steps over 1 ms\n\
         \x20 clarabel (data updated in place):   p50 {:.1} us, p99 {:.1} us, max {:.1} us, {} steps over 1 ms\n\
         \x20 clarabel / dense at p50: {:.1}x; largest difference: qd {:.1e} (relative), objective {:.1e}\n\
         \x20 halts {}, largest closure error {:.2e} m\n",
        r.scenario,
        r.steps,
        r.dense_p50_us,
        r.dense_p99_us,
        r.dense_max_us,
        r.dense_late_steps,
        r.clarabel_p50_us,
        r.clarabel_p99_us,
        r.clarabel_max_us,
        r.clarabel_late_steps,
        r.speedup_p50,
        r.max_qd_difference,
        r.max_objective_difference,
        r.halts,
        r.max_closure_error_m,
    )
}
