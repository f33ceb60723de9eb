//! The legs of a plan by groups of joints (see `by_groups` in the parent module), searched one
//! after another or, with a racer thread free, two at a time.
//!
//! Each leg is a problem of its own, known before any is searched: one group's joints from one
//! waypoint to the next, the other groups held. Its search draws from a random stream of its own
//! ([`LegJob::seed`]), so a leg's path is the same whichever thread searches it and whichever leg
//! was searched first: a plan whose legs go two at a time is the plan of one core, unless the
//! caller's race of a leg (see [`search_legs`]) gave that leg's path.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc;

use embodied_models::Rng;
use embodied_models::collision::CollisionModel;

use super::{MotionSettings, MotionStats, Outcome, Path, racers, rrt_connect};
use crate::deadline::{Budget, Interrupt};
use crate::validity::{StateValidity, Validity};

/// One leg to search: the joints `group` from `from` to `to` (the others as they are in both).
#[derive(Debug, Clone)]
pub(super) struct LegJob {
    pub from: Vec<f64>,
    pub to: Vec<f64>,
    pub group: Vec<usize>,
    /// The seed of the leg's random stream (see [`leg_seed`]).
    pub seed: u64,
}

/// The seed of leg `leg` of order `order` in round `round` of a plan seeded `seed`: a stream of
/// its own per leg and round (SplitMix64's finaliser over the four, so that nearby seeds and
/// legs give unrelated streams).
pub(super) fn leg_seed(seed: u64, round: usize, order: usize, leg: usize) -> u64 {
    let mut z = seed ^ ((round as u64) << 48 | (order as u64) << 32 | leg as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A leg's search: its straight segment (screened, see `Validity::segment_free_screened`), else
/// RRT-Connect in its group's joints alone (`settings.max_samples` samples).
pub(super) fn search_leg<V: StateValidity>(
    validity: &mut Validity<'_, V>,
    budget: &mut Budget<'_>,
    job: &LegJob,
    settings: &MotionSettings,
    lazy: bool,
    stats: &mut MotionStats,
) -> Outcome<Path, ()> {
    if budget.spend(1, validity.collision_checks) {
        return Outcome::OutOfTime { best: None, cause: budget.cause() };
    }
    // (Asked again in a later round, the segment's answer is kept in the run's memo.)
    if validity.segment_free_screened(&job.from, &job.to) {
        return Outcome::Solved(vec![job.from.clone(), job.to.clone()]);
    }
    let mut mask = vec![false; job.from.len()];
    for &d in &job.group {
        if let Some(m) = mask.get_mut(d) {
            *m = true;
        }
    }
    let mut rng = Rng::new(job.seed);
    let goals = [job.to.clone()];
    rrt_connect::plan(validity, budget, &mut rng, &job.from, &goals, settings, (lazy, Some(&mask)), stats)
}

/// What [`search_legs`] hands the racer thread.
#[derive(Debug, Clone, Copy)]
pub(super) struct Helper<'m> {
    /// The caller's model, which the racer thread plans with a clone of.
    pub model: &'m CollisionModel,
    /// The caller lets the racer thread take the first job before it takes one (the tests' way
    /// to have the racer thread search a leg on a busy machine; planning passes `false`).
    pub first: bool,
}

/// What a leg's search on the racer thread counted, added to the caller's counters.
#[derive(Debug, Default, Clone, Copy)]
struct Counted {
    collision_checks: u64,
    edges_checked: usize,
    probe_checks: u64,
    edges_recalled: usize,
    screened: usize,
    screened_out: usize,
    samples: usize,
    cut_edges: usize,
}

impl Counted {
    /// The counts of `validity` and `stats`.
    fn of<V: StateValidity>(validity: &Validity<'_, V>, stats: &MotionStats) -> Counted {
        Counted {
            collision_checks: validity.collision_checks,
            edges_checked: validity.edges_checked,
            probe_checks: validity.probe_checks,
            edges_recalled: validity.edges_recalled,
            screened: validity.screened,
            screened_out: validity.screened_out,
            samples: stats.samples,
            cut_edges: stats.cut_edges,
        }
    }

    /// What was counted between `before` and `self`.
    fn since(self, before: Counted) -> Counted {
        Counted {
            collision_checks: self.collision_checks - before.collision_checks,
            edges_checked: self.edges_checked - before.edges_checked,
            probe_checks: self.probe_checks - before.probe_checks,
            edges_recalled: self.edges_recalled - before.edges_recalled,
            screened: self.screened - before.screened,
            screened_out: self.screened_out - before.screened_out,
            samples: self.samples - before.samples,
            cut_edges: self.cut_edges - before.cut_edges,
        }
    }

    /// Add these counts to `validity`'s and `stats`.
    fn add_to<V: StateValidity>(self, validity: &mut Validity<'_, V>, stats: &mut MotionStats) {
        validity.collision_checks += self.collision_checks;
        validity.edges_checked += self.edges_checked;
        validity.probe_checks += self.probe_checks;
        validity.edges_recalled += self.edges_recalled;
        validity.screened += self.screened;
        validity.screened_out += self.screened_out;
        stats.samples += self.samples;
        stats.cut_edges += self.cut_edges;
    }
}

/// A leg searched on the racer thread: its index among the jobs, what it found (or the panic
/// it stopped with, raised again on the caller's thread) and what it counted.
type LegDone = (usize, std::thread::Result<Outcome<Path, ()>>, Counted);

/// What the racer thread searches with: its own model and the jobs, which it takes in turn
/// with the caller through `next`.
struct Shared {
    model: CollisionModel,
    jobs: Vec<LegJob>,
    next: AtomicUsize,
    /// Per job, raised by the racer thread once it has sent the job's answer.
    sent: Vec<Arc<AtomicBool>>,
    /// The legs' settings, their deadline carrying the caller's stop flag as its race flag.
    settings: MotionSettings,
    lazy: bool,
}

/// Raises the flag when dropped: the caller leaving (with a path, out of time, a panic) stops
/// the racer thread's leg at its next unit of work.
struct StopOnDrop(Arc<AtomicBool>);

impl Drop for StopOnDrop {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Relaxed);
    }
}

/// The seed of the stream a leg is raced with on the caller's thread (see [`search_legs`]):
/// another than the leg's own.
fn raced_seed(seed: u64) -> u64 {
    leg_seed(seed.rotate_left(29), usize::MAX, usize::MAX, usize::MAX)
}

/// Every leg of `jobs` searched, in the order of the jobs: `Ok` with each leg's path (`None`
/// for a leg that ran out of samples), or `Err` with the cause when planning is out of time.
/// The counts of every search are added to `validity`'s and `stats`.
///
/// With `helper` and a racer thread, the thread takes jobs in turn with the caller, each
/// searching the next one not yet taken. When none is left and the racer thread is still
/// searching one, the caller races it: it searches the same leg from another random stream
/// ([`raced_seed`]), and the first path found is the leg's (the other search stops at its next
/// unit of work). A leg's paths are then either its own stream's, as one thread finds them, or
/// the raced stream's.
pub(super) fn search_legs<V: StateValidity>(
    validity: &mut Validity<'_, V>,
    budget: &mut Budget<'_>,
    jobs: Vec<LegJob>,
    settings: &MotionSettings,
    lazy: bool,
    stats: &mut MotionStats,
    helper: Option<Helper<'_>>,
) -> Result<Vec<Option<Path>>, Interrupt> {
    let mut found: Vec<Option<Path>> = vec![None; jobs.len()];
    let racers = if jobs.len() > 1 { helper.and_then(|h| racers::Racers::get().map(|r| (h, r))) } else { None };
    let Some((Helper { model, first: helper_first }, racers)) = racers else {
        for (job, slot) in jobs.iter().zip(found.iter_mut()) {
            keep(search_leg(validity, budget, job, settings, lazy, stats), slot)?;
        }
        return Ok(found);
    };
    let stop = Arc::new(AtomicBool::new(false));
    let _stop_on_drop = StopOnDrop(Arc::clone(&stop));
    let n = jobs.len();
    let shared = Arc::new(Shared {
        model: model.clone(),
        jobs,
        next: AtomicUsize::new(0),
        sent: (0..n).map(|_| Arc::new(AtomicBool::new(false))).collect(),
        settings: MotionSettings {
            deadline: settings.deadline.clone().with_race_flag(Arc::clone(&stop)),
            ..settings.clone()
        },
        lazy,
    });
    let (sender, receiver) = mpsc::channel::<LegDone>();
    {
        let shared = Arc::clone(&shared);
        racers.spawn(move || helper_legs(&shared, &sender));
    }
    let mut answered = vec![false; n];
    while helper_first && shared.next.load(Ordering::Acquire) == 0 {
        std::thread::yield_now();
    }
    loop {
        let k = shared.next.fetch_add(1, Ordering::AcqRel);
        if k >= n {
            break;
        }
        answered[k] = true;
        keep(search_leg(validity, budget, &shared.jobs[k], settings, lazy, stats), &mut found[k])?;
    }
    // The racer thread's answers: those it sent; then the leg it is still searching, if any
    // (it searches one at a time), raced.
    for done in receiver.try_iter() {
        take(done, &mut found, &mut answered, validity, stats)?;
    }
    while let Some(k) = answered.iter().position(|&a| !a) {
        let job = &shared.jobs[k];
        let raced = LegJob { seed: raced_seed(job.seed), ..job.clone() };
        let deadline = settings.deadline.clone().with_race_flag(Arc::clone(&shared.sent[k]));
        let mut race_budget = Budget::new(&deadline);
        let mine = search_leg(validity, &mut race_budget, &raced, settings, lazy, stats);
        let theirs_first = shared.sent[k].load(Ordering::Acquire);
        match mine {
            // First: the racer thread's search stops (`stop` raised as this call returns).
            Outcome::Solved(p) if !theirs_first => {
                stats.legs_raced += 1;
                found[k] = Some(p);
                answered[k] = true;
            }
            Outcome::OutOfTime { cause, .. } if !theirs_first => return Err(cause),
            // The racer thread answered first, or this search gave up while it goes on: its
            // answer, unless it found no path where this search did.
            mine => {
                let Ok(done) = receiver.recv() else { break };
                let theirs = take(done, &mut found, &mut answered, validity, stats);
                if let (None, Outcome::Solved(p)) = (&found[k], mine) {
                    stats.legs_raced += 1;
                    found[k] = Some(p);
                    continue;
                }
                theirs?;
            }
        }
    }
    Ok(found)
}

/// The racer thread's answer `done` kept: its path in `found`, its counts added.
fn take<V: StateValidity>(
    done: LegDone,
    found: &mut [Option<Path>],
    answered: &mut [bool],
    validity: &mut Validity<'_, V>,
    stats: &mut MotionStats,
) -> Result<(), Interrupt> {
    let (k, outcome, counted) = done;
    counted.add_to(validity, stats);
    answered[k] = true;
    let outcome = outcome.unwrap_or_else(|panic| std::panic::resume_unwind(panic));
    stats.legs_on_racer += usize::from(matches!(outcome, Outcome::Solved(_)));
    keep(outcome, &mut found[k])
}

/// A leg's search's outcome kept: its path in `slot` when solved; out of time, the cause.
fn keep(outcome: Outcome<Path, ()>, slot: &mut Option<Path>) -> Result<(), Interrupt> {
    match outcome {
        Outcome::Solved(p) => *slot = Some(p),
        Outcome::OutOfTime { cause, .. } => return Err(cause),
        Outcome::Infeasible => {}
    }
    Ok(())
}

/// The racer thread's side of [`search_legs`]: the next job not yet taken, until none is left.
fn helper_legs(shared: &Shared, sender: &mpsc::Sender<LegDone>) {
    let settings = &shared.settings;
    let mut validity: Option<Validity<'_, CollisionModel>> = None;
    let mut budget = Budget::new(&settings.deadline);
    loop {
        let k = shared.next.fetch_add(1, Ordering::AcqRel);
        let Some(job) = shared.jobs.get(k) else { return };
        let v = validity.get_or_insert_with(|| {
            Validity::new(&shared.model, settings.resolution)
                .with_edge_check(settings.edge_check)
                .with_screen_above(settings.screen_above)
        });
        let before = Counted::of(v, &MotionStats::default());
        let mut stats = MotionStats::default();
        let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            search_leg(v, &mut budget, job, settings, shared.lazy, &mut stats)
        }));
        let done = Counted::of(v, &stats).since(before);
        let panicked = outcome.is_err();
        // The caller may have left (a path of its own, out of time): nobody to tell.
        let gone = sender.send((k, outcome, done)).is_err();
        shared.sent[k].store(true, Ordering::Release);
        if gone || panicked {
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use embodied_models::collision::{Environment, Obstacle};
    use embodied_models::nalgebra::Isometry3;
    use embodied_models::{Shape, builtin};

    use super::*;
    use crate::deadline::Deadline;
    use crate::validity::CERTIFY_TOLERANCE;

    /// The two-IRp-6 cell between two posts.
    fn cell() -> CollisionModel {
        let robot = builtin("two-irp6").expect("built-in robot");
        let mut env = Environment::new();
        for (name, c, h) in
            [("post", [0.8, 1.05, 0.5], [0.15, 0.15, 0.5]), ("post2", [-0.7, 1.0, 0.4], [0.1, 0.1, 0.4])]
        {
            env.add(Obstacle::new(name, Isometry3::translation(c[0], c[1], c[2]), Shape::cuboid(h[0], h[1], h[2])));
        }
        CollisionModel::new(&robot, env)
    }

    /// Legs of the cell's two arms, one after the other, from seeded draws: every waypoint
    /// free, and at least one leg's straight segment blocked (a search runs).
    fn leg_jobs(model: &CollisionModel, seed: u64) -> Option<Vec<LegJob>> {
        let robot = model.robot();
        let groups = robot.independent_dof_groups().to_vec();
        let mut rng = Rng::new(seed);
        let (start, goal) = (robot.random_configuration(&mut rng), robot.random_configuration(&mut rng));
        let mut points = vec![start];
        for g in &groups {
            let mut q = points.last()?.clone();
            for &d in g {
                q[d] = goal[d];
            }
            points.push(q);
        }
        if points.iter().any(|q| model.collides(q)) {
            return None;
        }
        let jobs: Vec<LegJob> = points
            .windows(2)
            .zip(&groups)
            .enumerate()
            .map(|(i, (w, g))| LegJob {
                from: w[0].clone(),
                to: w[1].clone(),
                group: g.clone(),
                seed: leg_seed(seed, 0, 0, i),
            })
            .collect();
        let blocked = jobs.iter().any(|j| !model.motion_is_certified_free(&j.from, &j.to, CERTIFY_TOLERANCE));
        blocked.then_some(jobs)
    }

    /// The racer thread searches the leg it takes, and the caller races it from another
    /// stream: each leg's path is the one a single thread finds unless the race gave it, and
    /// every path is certified, moves its group's joints alone and joins its leg's ends.
    #[test]
    fn legs_on_the_racer_thread_are_the_single_threads_unless_raced() {
        let model = cell();
        let settings = MotionSettings { max_samples: super::super::GROUP_LEG_SAMPLES, ..MotionSettings::default() };
        let deadline = Deadline::none();
        let mut problems = 0;
        for seed in 0..400 {
            let Some(jobs) = leg_jobs(&model, seed) else { continue };
            problems += 1;
            let validity = || {
                Validity::new(&model, settings.resolution)
                    .with_edge_check(settings.edge_check)
                    .with_screen_above(settings.screen_above)
            };
            let (mut v1, mut s1) = (validity(), MotionStats::default());
            let alone = search_legs(&mut v1, &mut Budget::new(&deadline), jobs.clone(), &settings, true, &mut s1, None)
                .expect("no deadline");
            let (mut v2, mut s2) = (validity(), MotionStats::default());
            let helper = Some(Helper { model: &model, first: true });
            let both =
                search_legs(&mut v2, &mut Budget::new(&deadline), jobs.clone(), &settings, true, &mut s2, helper)
                    .expect("no deadline");
            assert_eq!((s1.legs_on_racer, s1.legs_raced), (0, 0));
            // The racer thread took the first leg (and the second too if it was done before the
            // caller took one): its path, or the race's.
            let solved = both.iter().filter(|p| p.is_some()).count();
            let beside = s2.legs_on_racer + s2.legs_raced;
            assert!(beside >= usize::from(both[0].is_some()) && beside <= solved, "seed {seed}: {beside} legs beside");
            for (k, (job, (a, b))) in jobs.iter().zip(alone.iter().zip(&both)).enumerate() {
                if s2.legs_raced == 0 {
                    assert_eq!(a, b, "seed {seed}, leg {k}: another path than a single thread's");
                }
                let Some(path) = b else { continue };
                assert_eq!((path.first(), path.last()), (Some(&job.from), Some(&job.to)), "seed {seed}, leg {k}");
                for w in path.windows(2) {
                    assert!(model.motion_is_certified_free(&w[0], &w[1], CERTIFY_TOLERANCE), "seed {seed}, leg {k}");
                    for d in (0..job.from.len()).filter(|d| !job.group.contains(d)) {
                        assert_eq!(w[1][d], job.from[d], "seed {seed}, leg {k}: joint {d} of no group moved");
                    }
                }
            }
            if problems == 6 {
                break;
            }
        }
        assert_eq!(problems, 6, "test setup: problems with a leg to search");
    }
}
