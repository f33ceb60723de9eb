//! `embodied bench mbm --versus FLAGS`: every problem planned with two sets of settings, A (the
//! command's) and B (A with `FLAGS` added), in turns, and compared problem by problem.
//!
//! On a shared machine the speed of the same binary drifts between runs by more than most
//! changes of a setting move it (a factor 0.86-1.17 between two runs planning the same paths
//! has been seen), so two separate runs cannot settle a small difference. Here each problem is
//! planned with both settings one right after the other, A first on every other problem (by its
//! place in the batch, run by run) and B first on the rest, so that a drift of the machine weighs
//! on both alike. The comparison is the geometric mean of the per-problem ratios B / A over the
//! problems both solved, with its 95% confidence interval (Student's t on the logarithms of the
//! ratios), beside the ratio of the summed times (which the tail decides) and the ratios of
//! collision checks and path lengths, which do not depend on the machine's speed. The first
//! problem is planned once with each setting before any plan is timed: a process's first plans
//! are slower, and that would weigh on the side that goes first.

use serde::Serialize;

use super::{
    MbmArgs, MbmReport, ProblemResult, Warned, aligned, assemble, check_numbers, discover, load_robot, problem_names,
    run_problem, settings_of,
};
use crate::SystemError as AppError;
use crate::batch::Shard;

/// Two-sided 95% quantiles of Student's t for 1 to 30 degrees of freedom (standard tables);
/// beyond, the normal quantile 1.96.
const T_975: [f64; 30] = [
    12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160, 2.145, 2.131, 2.120,
    2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042,
];

/// The comparison of B with A over one family (or all problems).
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Versus {
    /// The family's name, or `overall`.
    pub name: String,
    /// Problems (times runs) planned with both settings, invalid ones included.
    pub pairs: usize,
    /// Of those, solved with A.
    pub solved_a: usize,
    /// Solved with B.
    pub solved_b: usize,
    /// Solved with both: the ratios below are over these.
    pub both: usize,
    /// Geometric mean of the planning-time ratios B / A.
    pub time_ratio: Option<f64>,
    /// Its 95% confidence interval (at least two pairs).
    pub time_ratio_ci: Option<(f64, f64)>,
    /// Median of the planning-time ratios B / A.
    pub time_ratio_median: Option<f64>,
    /// B's summed planning time over A's.
    pub total_time_ratio: Option<f64>,
    /// Geometric mean of the collision-check ratios B / A (pairs where both counted some).
    pub checks_ratio: Option<f64>,
    /// Geometric mean of the path-length ratios B / A (pairs with both lengths above zero).
    pub path_ratio: Option<f64>,
    /// Share of the valid problems A solved within 1 ms (0..=1).
    pub within_1ms_a: Option<f64>,
    /// The same for B.
    pub within_1ms_b: Option<f64>,
    /// Pairs solved by both whose paths differ (the settings changed the search there).
    pub changed: usize,
}

/// What `bench mbm --versus` reports: both runs in full, and their comparison.
#[derive(Debug, Clone, Serialize)]
pub struct VersusReport {
    /// The flags B adds to A's settings, as given.
    pub flags: String,
    /// The results with A's settings.
    pub a: MbmReport,
    /// The results with B's settings.
    pub b: MbmReport,
    /// One comparison per family, in the reports' order.
    pub families: Vec<Versus>,
    /// The comparison over every problem.
    pub overall: Versus,
}

/// Plan every problem of `a` (and of `b`: the two must name the same problems) with both
/// settings in turns: the `k`-th plan of the batch (problem by problem, run by run) runs A first
/// when `k` is even and B first otherwise. `flags` is recorded as what B changes.
/// `on_progress(done, total)` counts plans of both settings.
pub fn run_versus(
    a: &MbmArgs,
    b: &MbmArgs,
    flags: &str,
    on_progress: &mut dyn FnMut(usize, usize),
) -> Result<VersusReport, AppError> {
    check_numbers(a)?;
    check_numbers(b)?;
    if a.shard != b.shard || a.runs != b.runs {
        return Err(AppError::Usage(format!(
            "--versus cannot change the shard or the runs (`{flags}`): both sides plan the same problems"
        )));
    }
    let (loaded_a, loaded_b) = (load_robot(a)?, load_robot(b)?);
    let problems = discover(a)?;
    let names = problem_names(&problems);
    let other = problem_names(&discover(b)?);
    if names != other {
        return Err(AppError::Usage(format!(
            "--versus `{flags}` changes the problems ({} against {}): both sides must plan the same ones",
            names.len(),
            other.len()
        )));
    }
    let mine: Vec<_> = problems.iter().enumerate().filter(|(i, _)| a.shard.holds(*i)).map(|(_, p)| p).collect();
    let total = 2 * mine.len() * a.runs;
    on_progress(0, total);
    let sides = [(a, &loaded_a), (b, &loaded_b)];
    let mut results: [Vec<ProblemResult>; 2] = [Vec::with_capacity(total / 2), Vec::with_capacity(total / 2)];
    // The problems' warnings once, from A's reading.
    let mut warned = [Warned::default(), Warned { silent: true, ..Warned::default() }];
    // The process's first plans pay for what later ones find ready (pages touched, tables
    // built): the first problem planned once with each setting, untimed, so that this does not
    // weigh on the side that happens to go first.
    if let Some(first) = mine.first() {
        let mut quiet = Warned { silent: true, ..Warned::default() };
        for (args, loaded) in sides {
            run_problem(args, loaded, first, 0, &mut quiet)?;
        }
    }
    let mut done = 0;
    for p in mine {
        for run in 0..a.runs as u32 {
            // The `done / 2`-th pair: A first when it is even.
            let order = if (done / 2) % 2 == 0 { [0, 1] } else { [1, 0] };
            for side in order {
                let (args, loaded) = sides[side];
                results[side].push(run_problem(args, loaded, p, run, &mut warned[side])?);
                done += 1;
                on_progress(done, total);
            }
        }
    }
    warned[0].finish();
    let [ra, rb] = results;
    let generator = crate::generator();
    let shard = (a.shard != Shard::ALL).then_some(a.shard);
    let report_a = assemble(generator.clone(), shard, settings_of(a, &loaded_a), ra);
    let report_b = assemble(generator, shard, settings_of(b, &loaded_b), rb);
    Ok(compare(flags, report_a, report_b))
}

/// The comparison of two reports of the same problems in the same order (see [`run_versus`]).
pub fn compare(flags: &str, a: MbmReport, b: MbmReport) -> VersusReport {
    let pairs: Vec<(&ProblemResult, &ProblemResult)> = a.problems.iter().zip(&b.problems).collect();
    let families = a
        .families
        .iter()
        .zip(&b.families)
        .map(|(fa, fb)| {
            let mine: Vec<_> = pairs.iter().copied().filter(|(pa, _)| pa.family == fa.name).collect();
            versus(&fa.name, &mine, (fa.within_1ms, fb.within_1ms))
        })
        .collect();
    let overall = versus("overall", &pairs, (a.overall.within_1ms, b.overall.within_1ms));
    VersusReport { flags: flags.to_string(), a, b, families, overall }
}

/// The comparison over `pairs` (A's result, B's result of one problem and run).
fn versus(name: &str, pairs: &[(&ProblemResult, &ProblemResult)], within: (Option<f64>, Option<f64>)) -> Versus {
    let both: Vec<_> = pairs.iter().filter(|(a, b)| a.solved && b.solved).collect();
    let times: Vec<(f64, f64)> = both.iter().filter_map(|(a, b)| Some((a.planning_us?, b.planning_us?))).collect();
    let logs: Vec<f64> = times.iter().filter(|(a, b)| *a > 0.0 && *b > 0.0).map(|(a, b)| (b / a).ln()).collect();
    let checks: Vec<f64> = both
        .iter()
        .filter_map(|(a, b)| Some((checks_of(a)?, checks_of(b)?)))
        .filter(|&(a, b)| a > 0.0 && b > 0.0)
        .map(|(a, b)| (b / a).ln())
        .collect();
    let paths: Vec<f64> = both
        .iter()
        .filter_map(|(a, b)| Some((a.path_length?, b.path_length?)))
        .filter(|&(a, b)| a > 0.0 && b > 0.0)
        .map(|(a, b)| (b / a).ln())
        .collect();
    let (sum_a, sum_b) = times.iter().fold((0.0, 0.0), |(x, y), (a, b)| (x + a, y + b));
    Versus {
        name: name.to_string(),
        pairs: pairs.len(),
        solved_a: pairs.iter().filter(|(a, _)| a.solved).count(),
        solved_b: pairs.iter().filter(|(_, b)| b.solved).count(),
        both: both.len(),
        time_ratio: geometric_mean(&logs),
        time_ratio_ci: interval(&logs),
        time_ratio_median: median(&logs).map(f64::exp),
        total_time_ratio: (sum_a > 0.0).then(|| sum_b / sum_a),
        checks_ratio: geometric_mean(&checks),
        path_ratio: geometric_mean(&paths),
        within_1ms_a: within.0,
        within_1ms_b: within.1,
        changed: both.iter().filter(|(a, b)| a.path != b.path).count(),
    }
}

/// The collision checks a solved problem's planner reports.
fn checks_of(r: &ProblemResult) -> Option<f64> {
    r.stats.as_ref()?.get("collision_checks")?.as_f64()
}

/// `exp` of the mean of `logs`.
fn geometric_mean(logs: &[f64]) -> Option<f64> {
    (!logs.is_empty()).then(|| (logs.iter().sum::<f64>() / logs.len() as f64).exp())
}

/// The 95% confidence interval of the geometric mean `exp(mean(logs))`: Student's t on the
/// logarithms (at least two).
fn interval(logs: &[f64]) -> Option<(f64, f64)> {
    let n = logs.len();
    if n < 2 {
        return None;
    }
    let mean = logs.iter().sum::<f64>() / n as f64;
    let var = logs.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    let t = T_975.get(n - 2).copied().unwrap_or(1.96);
    let half = t * (var / n as f64).sqrt();
    Some(((mean - half).exp(), (mean + half).exp()))
}

/// The median of `values` (the mean of the middle two for an even count).
fn median(values: &[f64]) -> Option<f64> {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    match n {
        0 => None,
        _ if n % 2 == 1 => Some(v[n / 2]),
        _ => Some(0.5 * (v[n / 2 - 1] + v[n / 2])),
    }
}

/// The text report: A's and B's tables ([`super::render_table`]), then the comparison.
pub fn render_versus(report: &VersusReport) -> String {
    let header = [
        "family",
        "pairs",
        "both",
        "time B/A",
        "95% CI",
        "median",
        "sum B/A",
        "checks B/A",
        "path B/A",
        "<=1 ms A",
        "<=1 ms B",
        "changed",
    ];
    let ratio = |r: Option<f64>| r.map_or("-".to_string(), |r| format!("{r:.3}"));
    let share = |w: Option<f64>| w.map_or("-".to_string(), |w| format!("{:.1}%", 100.0 * w));
    let row = |v: &Versus| -> Vec<String> {
        vec![
            v.name.clone(),
            v.pairs.to_string(),
            v.both.to_string(),
            ratio(v.time_ratio),
            v.time_ratio_ci.map_or("-".to_string(), |(lo, hi)| format!("{lo:.3}-{hi:.3}")),
            ratio(v.time_ratio_median),
            ratio(v.total_time_ratio),
            ratio(v.checks_ratio),
            ratio(v.path_ratio),
            share(v.within_1ms_a),
            share(v.within_1ms_b),
            v.changed.to_string(),
        ]
    };
    let mut rows: Vec<Vec<String>> = report.families.iter().map(row).collect();
    rows.push(row(&report.overall));
    let mut out = format!("A: the settings given\n{}\n", super::render_table(&report.a));
    out.push_str(&format!("B: A with `{}`\n{}\n", report.flags, super::render_table(&report.b)));
    out.push_str(&format!(
        "B against A, each problem planned with both in turns (A first on every other one):\n{}",
        aligned(&header, &rows)
    ));
    out.push_str(
        "pairs = problems (and runs) planned with both; both = solved by both, over which the ratios are taken; \
         time B/A = geometric mean of the per-problem ratios, with its 95% confidence interval and median; \
         sum B/A = summed times; changed = paths that differ\n",
    );
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mbm::ProblemStatus;

    fn result(family: &str, index: u32, us: Option<f64>, checks: u64, length: f64) -> ProblemResult {
        ProblemResult {
            family: family.into(),
            index,
            run: 0,
            solved: us.is_some(),
            status: if us.is_some() { ProblemStatus::Solved } else { ProblemStatus::OutOfTime },
            planning_us: us,
            joint_names: vec!["j".into()],
            path: vec![vec![0.0], vec![length]],
            path_length: us.map(|_| length),
            verified: us.map(|_| true),
            stats: Some(serde_json::json!({ "collision_checks": checks })),
            message: None,
        }
    }

    /// The ratios are over the problems both solved: geometric and median time ratios, the
    /// summed times, checks and path lengths; paths that differ are counted.
    #[test]
    fn ratios_are_over_the_problems_both_solved() {
        let a = [
            result("f", 1, Some(100.0), 10, 1.0),
            result("f", 2, Some(200.0), 20, 2.0),
            result("f", 3, Some(400.0), 40, 1.0),
            result("f", 4, None, 0, 1.0),
        ];
        let b = [
            result("f", 1, Some(200.0), 10, 1.0),
            result("f", 2, Some(100.0), 40, 2.0),
            result("f", 3, Some(800.0), 40, 2.0),
            result("f", 4, Some(50.0), 5, 1.0),
        ];
        let pairs: Vec<_> = a.iter().zip(&b).collect();
        let v = versus("f", &pairs, (Some(0.75), Some(1.0)));
        assert_eq!((v.pairs, v.solved_a, v.solved_b, v.both), (4, 3, 4, 3));
        // Ratios 2, 0.5, 2: geometric mean 2^(1/3), median 2; sums 1100 / 700.
        let close = |x: Option<f64>, y: f64| x.is_some_and(|x| (x - y).abs() < 1e-12);
        assert!(close(v.time_ratio, 2f64.powf(1.0 / 3.0)), "{:?}", v.time_ratio);
        assert!(close(v.time_ratio_median, 2.0));
        assert!(close(v.total_time_ratio, 1100.0 / 700.0));
        // Checks 1, 2, 1; paths 1, 1, 2 (the first two the same path, the third not).
        assert!(close(v.checks_ratio, 2f64.powf(1.0 / 3.0)));
        assert!(close(v.path_ratio, 2f64.powf(1.0 / 3.0)));
        assert_eq!(v.changed, 1);
        let (lo, hi) = v.time_ratio_ci.expect("an interval");
        assert!(lo < v.time_ratio.unwrap_or(0.0) && v.time_ratio.unwrap_or(0.0) < hi);
    }

    /// The interval is Student's: for two logarithms ±1 of ln 2, the mean 0, the standard
    /// deviation √2 ln 2, t = 12.706 over √2: exp(±12.706 ln 2).
    #[test]
    fn the_interval_is_students_t_on_the_logarithms() {
        let l = 2f64.ln();
        let (lo, hi) = interval(&[l, -l]).expect("two values");
        assert!((hi.ln() - 12.706 * l).abs() < 1e-9 && (lo.ln() + 12.706 * l).abs() < 1e-9, "{lo} {hi}");
        assert_eq!(interval(&[l]), None);
        // Equal ratios: an interval of width zero around them.
        let (lo, hi) = interval(&[l; 40]).expect("forty values");
        assert!((lo - 2.0).abs() < 1e-12 && (hi - 2.0).abs() < 1e-12);
        assert_eq!(median(&[3.0, 1.0, 2.0, 10.0]), Some(2.5));
        assert_eq!(median(&[]), None);
    }
}
