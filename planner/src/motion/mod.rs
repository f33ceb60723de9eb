//! Motion planning for any [`Robot`] among obstacles: from a start configuration to a goal
//! given as a configuration, a set of them, or a tool pose (through inverse kinematics).
//!
//! [`plan_motion`] tries, in order: the straight segment to the nearest goal; then a
//! bidirectional RRT-Connect or a lazy PRM ([`crate::roadmap`]) grown in batches until solved,
//! out of samples or out of time; then random shortcuts. All distances, interpolation and
//! segment checks use the robot's [`embodied_models::ConfigSpace`], so continuous joints take
//! the short way round (Polycrank going from 3.0 to -3.0 rad moves 0.28 rad, across +-pi).

mod buckets;
mod legs;
mod racers;
pub(crate) mod rrt_connect;
pub mod sampler;
pub(crate) mod shortcut;

pub use racers::{DEFAULT_LOOK as DEFAULT_RACER_LOOK, racer_look, set_racer_look};
pub use sampler::Sampler;

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use embodied_models::collision::CollisionModel;
use embodied_models::{IkOptions, Rng, Robot};
use nalgebra::Isometry3;
use petgraph::graph::NodeIndex;

use crate::deadline::{Budget, Deadline};
use crate::error::PlanError;
use crate::outcome::unwrap_path;
pub use crate::outcome::{MotionPlan, MotionStats, Outcome, path_length};
use crate::roadmap::{LazyOutcome, QueryCounters, Roadmap};
pub use crate::validity::{CERTIFY_TOLERANCE, DEFAULT_RESOLUTION, EdgeCheck, StateValidity};
use crate::validity::{Validity, check_start};
use rrt_connect::Certified;

/// Where a motion must end.
#[derive(Debug, Clone)]
pub enum Goal {
    /// One joint configuration.
    Configuration(Vec<f64>),
    /// Any one of these configurations (the search finds the cheapest reachable).
    AnyOf(Vec<Vec<f64>>),
    /// The tool frame of end effector `end_effector` at `pose` (world frame).
    ToolPose {
        /// Index into [`embodied_models::Robot::end_effectors`].
        end_effector: usize,
        /// Required pose of its tool frame, in the world frame.
        pose: Isometry3<f64>,
    },
}

/// Default [`MotionSettings::lazy_probe`] (rad or m).
pub const DEFAULT_LAZY_PROBE: f64 = 0.1;

/// Which search runs after the straight segment fails.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum PlannerKind {
    /// Bidirectional RRT-Connect (fastest on single queries in our measurements).
    RrtConnect,
    /// Lazy PRM grown in batches with A* and lazy edge checks.
    LazyPrm,
}

impl PlannerKind {
    /// Every planner, in the order of their names.
    pub const ALL: [PlannerKind; 2] = [PlannerKind::RrtConnect, PlannerKind::LazyPrm];

    /// The planner's name: `rrt-connect` or `lazy-prm` (what [`std::str::FromStr`] reads).
    pub fn name(self) -> &'static str {
        match self {
            PlannerKind::RrtConnect => "rrt-connect",
            PlannerKind::LazyPrm => "lazy-prm",
        }
    }
}

impl std::fmt::Display for PlannerKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A planner name that is not one of [`PlannerKind::ALL`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown planner `{0}` (expected one of: rrt-connect, lazy-prm)")]
pub struct UnknownPlanner(pub String);

impl std::str::FromStr for PlannerKind {
    type Err = UnknownPlanner;

    fn from_str(s: &str) -> Result<Self, UnknownPlanner> {
        PlannerKind::ALL.into_iter().find(|k| k.name() == s).ok_or_else(|| UnknownPlanner(s.to_string()))
    }
}

/// The outcome of a motion planner: a plan, out of time (with the work done so far), or no
/// path within the sample budget.
pub type MotionOutcome = Outcome<MotionPlan, MotionStats>;

/// Bidirectional RRT-Connect (after the straight segment, then shortcuts), with its settings.
///
/// `settings.planner` is ignored: this is the RRT-Connect planner. Its own settings are
/// [`MotionSettings::rrt_range`] and [`MotionSettings::lazy_probe`]; the others are shared by
/// every planner.
#[derive(Debug, Clone, Default)]
pub struct RrtConnect {
    /// Seed, edge check, deadline, shortcuts, range and probe.
    pub settings: MotionSettings,
}

/// Lazy PRM grown in batches with A* and lazy edge checks (after the straight segment, then
/// shortcuts), with its settings.
///
/// `settings.planner` is ignored: this is the lazy PRM planner. Its own settings are
/// [`MotionSettings::batch_size`], [`MotionSettings::k_neighbours`] and
/// [`MotionSettings::parallel`]; the others are shared by every planner.
#[derive(Debug, Clone, Default)]
pub struct LazyPrm {
    /// Seed, edge check, deadline, shortcuts, batch size, neighbours and parallelism.
    pub settings: MotionSettings,
}

impl RrtConnect {
    /// RRT-Connect with `settings`.
    pub fn new(settings: MotionSettings) -> Self {
        Self { settings }
    }

    /// Plan from `start` to `goal` against `validity`. Malformed input (and a start or goal in
    /// collision) is an error; running out of time or samples is an outcome.
    pub fn plan<V: StateValidity>(&self, validity: &V, start: &[f64], goal: &Goal) -> Result<MotionOutcome, PlanError> {
        let settings = MotionSettings { planner: PlannerKind::RrtConnect, ..self.settings.clone() };
        outcome_of(plan_motion_with(validity, start, goal, &settings), &settings.deadline)
    }
}

impl LazyPrm {
    /// Lazy PRM with `settings`.
    pub fn new(settings: MotionSettings) -> Self {
        Self { settings }
    }

    /// Plan from `start` to `goal` against `validity`. Malformed input (and a start or goal in
    /// collision) is an error; running out of time or samples is an outcome.
    pub fn plan<V: StateValidity>(&self, validity: &V, start: &[f64], goal: &Goal) -> Result<MotionOutcome, PlanError> {
        let settings = MotionSettings { planner: PlannerKind::LazyPrm, ..self.settings.clone() };
        outcome_of(plan_motion_with(validity, start, goal, &settings), &settings.deadline)
    }
}

/// The planner `kind` with `settings`, as an outcome: [`RrtConnect::plan`] or [`LazyPrm::plan`].
pub fn plan_with_kind<V: StateValidity>(
    kind: PlannerKind,
    validity: &V,
    start: &[f64],
    goal: &Goal,
    settings: &MotionSettings,
) -> Result<MotionOutcome, PlanError> {
    match kind {
        PlannerKind::RrtConnect => RrtConnect::new(settings.clone()).plan(validity, start, goal),
        PlannerKind::LazyPrm => LazyPrm::new(settings.clone()).plan(validity, start, goal),
    }
}

/// Out of time and out of samples as outcomes. The limit that stopped planning is read from
/// the deadline afterwards: a passed clock and a raised flag stay so; otherwise it was the
/// expansion budget.
fn outcome_of(result: Result<MotionPlan, PlanError>, deadline: &Deadline) -> Result<MotionOutcome, PlanError> {
    match result {
        Ok(plan) => Ok(Outcome::Solved(plan)),
        Err(PlanError::OutOfTime { stats }) => Ok(Outcome::OutOfTime {
            cause: deadline
                .check(0, stats.collision_checks, true)
                .unwrap_or(crate::deadline::Interrupt::ExpansionBudget),
            best: Some(stats),
        }),
        Err(PlanError::NoPath { .. }) => Ok(Outcome::Infeasible),
        Err(e) => Err(e),
    }
}

/// Settings of [`plan_motion`].
#[derive(Debug, Clone)]
pub struct MotionSettings {
    /// Seed of every random choice: the same seed gives the same path.
    pub seed: u64,
    /// How segments are checked: certified (the default) or sampled at `resolution`.
    pub edge_check: EdgeCheck,
    /// Largest joint step between collision-checked points of a segment (rad or m), for
    /// [`EdgeCheck::Sampled`].
    pub resolution: f64,
    /// When planning must stop. Its expansion budget counts units of work: samples drawn, tree
    /// extensions and A* expansions.
    pub deadline: Deadline,
    /// Shorten the path by random shortcuts.
    pub shortcut: bool,
    /// Random shortcut attempts after the greedy pass (each is one segment check). On the
    /// MotionBenchMaker UR5 problems (one run, lazy RRT-Connect): 0 attempts, median 589
    /// collision checks and mean path length 6.82; 5 (the default), 745 and 6.57; 10, 878 and
    /// 6.45; 20, 1296 and 6.32. (Eagerly certified RRT-Connect with 10 attempts: 1279 and 6.56.)
    pub shortcut_attempts: usize,
    /// A random shortcut is tried only if it would shorten the path by at least this share of
    /// the path's length (0: any shortening): smaller ones are not worth their segment check.
    /// On the 296 public MotionBenchMaker UR5 problems, against 0: 0.005 took 4.3% fewer
    /// planning instructions and the mean path length 0.08% longer; 0.01 (the default) 6.2%
    /// fewer and 0.23% longer (medians 6.27 and 6.28 rad). With 0.01, eight attempts cost what
    /// five did with 0 (92.9 M against 92.6 M instructions on the first 30 of each family) for
    /// a 1.4% shorter mean path (6.315 against 6.407 rad): the attempts to raise for shorter
    /// paths.
    pub shortcut_min_gain: f64,
    /// With certified edges, segments likely refused that are longer than this (C-space
    /// distance, rad or m) are screened by a probe of eight evenly spaced inner points before
    /// their certificate: the shortcuts (the greedy pass's and the random attempts'), the
    /// straight segment to a goal and the legs' straight segments. A point in collision refuses
    /// one at the cost of one batch of plain checks (the same paths either way; see
    /// [`crate::validity::Validity::segment_free_screened`]). Infinite: never. Planning
    /// instructions (callgrind, one core, the greedy pass screened) against no screen, 2 rad
    /// (the default) / 1 rad: VAMP's Baxter problems (both arms, first 10 per family) -6.5% /
    /// -7.5%; the spherized Panda's three families (30 problems each) -3.5% / -4.3%, the
    /// Fetch's -4.6% / -4.4%; 160 generated UR5 problems (four families) -1.2% / -1.2%; the 90
    /// public MotionBenchMaker UR5 problems of `--limit 30` 0.0% / +0.7% (a refused
    /// certificate's set-up and first batch cost about four probe batches on the UR5, about
    /// seven on Baxter). The random attempts screened too: Baxter -0.4%, public UR5 -0.2% more;
    /// the straight segments too: Baxter -0.6%, public UR5 -1.4% more.
    pub screen_above: f64,
    /// The search after the straight segment.
    pub planner: PlannerKind,
    /// Lazy PRM: samples per batch.
    pub batch_size: usize,
    /// Lazy PRM: neighbours per vertex.
    pub k_neighbours: usize,
    /// Lazy PRM: sample and connect batches on the rayon pool.
    pub parallel: bool,
    /// RRT-Connect: largest C-space step of one extension.
    pub rrt_range: f64,
    /// RRT-Connect with [`EdgeCheck::Certified`] edges: when positive, tree edges are only
    /// probed (plain checks of configurations this far apart in every joint) as the trees grow,
    /// and certified once they lie on a path that joins the trees; an edge whose certificate
    /// fails is cut off with its subtree and the search goes on. With `shortcut`, the path is
    /// certified by the greedy shortcut pass itself, so edges it skips are never certified.
    /// 0 certifies every edge as it is added. On the MotionBenchMaker UR5 problems (one run, 10
    /// shortcut attempts): 0.1 (the default), median 878 collision checks and mean path length
    /// 6.45; 0 (eager), 1279 and 6.56; no probe at all (a step longer than any edge), 2271 and 4
    /// problems unsolved within 1 s. (With the greedy pass capped at 12 vertices: 0.07, 944; 0.1,
    /// 904; 0.15, 914.)
    pub lazy_probe: f64,
    /// RRT-Connect: dynamic domain (Yershova et al., ICRA 2005): once an extension from a node
    /// fails, samples farther than a radius from it (4 rad, adapted by 0.01% per success or
    /// failure, at least 1 rad) are not extended from it, so the tree stops pushing into
    /// obstacles from its boundary nodes. On by default: with [`MotionSettings::rrt_balance`],
    /// on the 96 valid bookshelf_small MotionBenchMaker UR5 problems the planner's instructions
    /// fell from 756 M to 270 M (callgrind, k-d tree nearest neighbours in both), the largest
    /// collision-check count of a problem from 15,963 to 2,269 and the median path length of
    /// all 296 problems from 6.53 to 6.27 (Halton samples on top: 311 M; range 2 rad on top of
    /// that: path length 6.73).
    pub rrt_dynamic_domain: bool,
    /// RRT-Connect on a robot of independent groups of joints (two arms on a fixed torso, see
    /// [`embodied_models::Robot::independent_dof_groups`]; two arms on a torso joint, which is
    /// held when it keeps its value and else moved in a leg of its own): before the search over
    /// every joint, a path that moves one group at a time, each leg searched in its group's
    /// joints alone (2,000 samples a search, in up to three rounds over both orders of the
    /// groups; the search over every joint follows when none works), then the legs side by side
    /// when that motion certifies. On by default: on the
    /// first 30 problems of each of VAMP's three Baxter families (both arms moving, 14 joints;
    /// `bench mbm`, one core), p50 4.4-4.9 -> 1.3-1.6 ms, p95 34-35 -> 4.4-5.7 ms, median path
    /// 9.39 -> 9.03 rad.
    pub rrt_by_groups: bool,
    /// With [`Self::racers`] above 1, a plan by groups of joints (see [`Self::rrt_by_groups`])
    /// searches its legs two at a time, one on the calling thread and one on a racer thread,
    /// instead of racing another seed of the whole plan (a racer is still handed over when the
    /// plan falls back to the search over every joint, or only one group moves). Each leg
    /// draws from a random stream of its own, so the path is the one of a single thread unless
    /// the caller, out of legs, raced the racer thread's leg from another stream and won. Not
    /// with an expansion or check budget (their counts would depend on the threads). On by
    /// default.
    pub parallel_legs: bool,
    /// RRT-Connect: keep growing the smaller tree while the other has twice its nodes (instead
    /// of swapping the trees every iteration). On by default (see
    /// [`MotionSettings::rrt_dynamic_domain`]).
    pub rrt_balance: bool,
    /// How RRT-Connect draws its samples.
    pub sampler: Sampler,
    /// RRT-Connect: the share of samples drawn near a node of the tree about to grow (a node
    /// picked uniformly, each joint within [`Self::rrt_local_span`] of its sampling width of
    /// the node's value); the others are drawn by [`Self::sampler`] over the whole joint box. A
    /// tree inside a narrow region (the arm reaching into a cage) grows where it is instead of
    /// towards samples its dynamic domain mostly turns down. On the UR5 (`bench mbm`, one core,
    /// three seeds, collision checks a problem, 0 -> 0.5): 100 generated cage problems 14,826
    /// -> 5,424 (per problem 0.51 of the time; within 1 ms 57% -> 86%); the 296 public ones
    /// 336 -> 302 (median path 6.27 -> 6.10 rad); generated bookshelf_tall 579 -> 422,
    /// bookshelf_thin 502 -> 430, table_under_pick 798 -> 1,630 (one problem that takes
    /// thousands to a hundred thousand samples either way). Shares of 0.1-0.7 and boxes of
    /// 0.5-3 rad are compared in `docs/benchmarks.md`; 0 draws every sample over the whole box.
    /// This share holds for an attempt's first [`Self::rrt_late_after`] samples.
    pub rrt_local_bias: f64,
    /// RRT-Connect: the share of samples drawn near the growing tree (as
    /// [`Self::rrt_local_bias`]) once an attempt has drawn [`Self::rrt_late_after`] samples. A
    /// problem that needs that many is most often a narrow passage, where the trees find the way
    /// out by growing along themselves; an easy one is solved before, with the global samples'
    /// pull across open space. On the UR5 (`bench mbm`, one core; 0.5 throughout before, 0.9
    /// after 128 samples now), the 99 solved generated cage problems over 20 seeds: collision
    /// checks a problem, mean 5,722 -> 5,332, 90th percentile 11,861 -> 10,687; time 0.84 and
    /// 0.95 of before per problem in two interleaved sets of seeds; the other six families within
    /// their spread. 0.9 throughout saves more on the cage (mean 5,031, 90th percentile 9,836),
    /// but with it the built-in scenarios' plans under `bench deadlines` reached fewer goals at a
    /// 1 ms deadline (10-12 of 13 against 12). Equal to `rrt_local_bias`: one share throughout.
    /// The best share depends on the robot: 0.7 on VAMP's problems (first 40 of a family, 16
    /// seeds, collision checks a solved problem against 0.9) took the Fetch's cage 12-24% fewer
    /// and left fewer runs without a path, the Panda's cage 6% fewer, but the UR5's cage 6% more
    /// and the Baxter's three families 6-9% more. Odd attempts and odd racers draw with
    /// `rrt_local_bias` throughout instead (see [`Self::rrt_restarts`] and [`Self::racers`]).
    pub rrt_late_local_bias: f64,
    /// RRT-Connect: samples of an attempt drawn before [`Self::rrt_late_local_bias`] applies.
    pub rrt_late_after: usize,
    /// RRT-Connect: once an attempt has drawn [`Self::rrt_late_after`] samples, each goal gets a
    /// chain of nodes in the goal's tree that pull the hand (the leaf link moved by the most
    /// searched joints) straight towards the first joint of its chain, its orientation held, 3 cm a
    /// node by damped least squares on its Jacobian, each edge checked as the tree's own are; a
    /// chain blocked before its eighth node is left out. Off by default. A goal deep in a shelf is
    /// where the goal's tree stays stuck (on the spherized Fetch's cage and bookshelves, from the
    /// goals to an open configuration p50 1.9 ms, from the tucked start 0.29 ms). On VAMP's
    /// problems (first 50 of every family, seeds 1-4, collision checks a problem, geometric mean of
    /// per-problem ratios, on against off): Baxter (both arms) 0.73, Panda 0.96, Fetch 0.97, UR5
    /// 1.00. In time (each problem planned with and without in one process, the order alternating,
    /// one core, seeds 1-3): Baxter 0.91 (within 1 ms 47% -> 61%), Panda 0.99, Fetch 1.04, UR5
    /// 1.03, so it stays off: a cage's goal is left through the front opening, which a straight
    /// retreat of the hand rarely follows (see `docs/benchmarks.md`).
    pub rrt_goal_retreat: bool,
    /// RRT-Connect: the half-width of [`Self::rrt_local_bias`]'s samples around their node, as
    /// a share of each joint's sampling width, at most [`Self::rrt_local_reach`]: 0.5 by
    /// default (1/π before). The two together: every joint of the Panda and the Fetch within half
    /// its width or 2 rad of the node, where it was within 1/π of its width (0.9-1.8 rad on the
    /// Panda, 0.8-2 rad on the Fetch); joints of one turn (the UR5's, the Fetch's continuous
    /// ones) within 2 rad as before. On VAMP's shipped problems (`bench mbm`, first 40 of every
    /// family, one core, 12 seeds of two runs): the Fetch's mean 3.79 -> 2.11 ms, p95 14.7 ->
    /// 7.1 ms, within 1 ms 55.1 -> 64.2%, its cage p50 6.0 -> 2.6 ms and p95 70 -> 15.5 ms; the
    /// Panda's mean 224 -> 176 µs, within 1 ms 95.7 -> 97.7% (cage 77.7 -> 86.5%); the
    /// Baxter's and the UR5's the same (means 935 / 937 and 156 / 160 µs). Half the width
    /// without the reach (a joint of one turn within π): the UR5's cage within 1 ms 95.4 ->
    /// 91.9% and the Fetch's cage p50 3.6 ms. The built-in `irp6-pick` scenario over 300 of its
    /// seeds (`bench deadlines`, interleaved on one core): goals reached at 0.6 / 0.8 / 1 ms
    /// 115 / 202 / 264 -> 258 / 284 / 290.
    pub rrt_local_span: f64,
    /// RRT-Connect: the most a local sample's joint is drawn from its node's value (rad, or m
    /// for a prismatic joint), whatever [`Self::rrt_local_span`] gives: 2 by default. Infinite:
    /// the span alone.
    pub rrt_local_reach: f64,
    /// Planners racing (1: no race): racer `k` plans with the seed `seed + k`; racer 0 (the
    /// single planner) on the calling thread, the others handed to threads of their own once
    /// the straight segment is found blocked (not while racer 0 certifies a path it found). The
    /// first path found stops the others through their deadline's race flag; racer 0's path is
    /// returned without waiting for the others. Every racer's path is certified as a lone
    /// planner's is. The racer threads look for work a while after their last racer before
    /// they sleep (yielding their core meanwhile; see [`set_racer_look`]), so that handing a
    /// racer over needs no system call. A validity other than a plain [`CollisionModel`]
    /// races within the call, on the rayon pool, after a head start of 1 ms. Odd racers draw
    /// with [`Self::rrt_local_bias`] throughout (a portfolio of the two shares, see
    /// [`Self::rrt_late_local_bias`]): on VAMP's Fetch bookshelf and cage problems (first 40
    /// of each, two threads on two cores, two sets of 8 seeds, interleaved) the mean time
    /// 3.29-3.53 -> 2.68-2.88 ms, the cage's 8.2-9.3 -> 6.2-6.7 ms, the slowest run 171-180 ->
    /// 90 ms, within 1 ms the same (49-51%); the UR5's cage and bookshelf_small 178-188 ->
    /// 192-194 µs (an earlier build), the Panda's and the Baxter's the same.
    pub racers: usize,
    /// Samples after which the planner gives up with [`PlanError::NoPath`] (RRT-Connect: per
    /// attempt, see [`Self::rrt_restarts`]): planning ends even without a deadline.
    pub max_samples: usize,
    /// RRT-Connect: attempts after the first, each with new trees (the random stream going
    /// on), when one draws `max_samples` samples without a path. Such an attempt is usually
    /// stuck rather than the problem infeasible: of 100 generated MotionBenchMaker cage problems
    /// every solved one took at most 39,617 samples, and problem 30, which one seed left
    /// unsolved after 50,000, other seeds solved in 1,111-8,673. A problem with no path then
    /// ends after `(1 + rrt_restarts) * max_samples` samples (or at the deadline). 64 by default
    /// (8 before, 2 before that): with [`Self::rrt_local_span`]'s wider boxes the Fetch's
    /// bookshelf_tall problem 29 (VAMP's shipped problems) took 6-37 restarts in 10 of 24 runs
    /// (56-321 ms), where the boxes before needed 0-7 (10-116 ms). 65 attempts of 50,000 samples
    /// take about 0.5-3 s without a deadline. With 8 restarts (against 2):
    /// generated table_under_pick problem 13 (the start under the table), 300 seeds,
    /// needed one restart in 66, two in 23, and 3 ran out of their three attempts after 17-27 ms
    /// with a 1 s deadline; an attempt failed in 31%, 28% and 12% of the runs that reached it.
    /// Samples are cheap where dynamic domain turns most down: 50,000 take 8-10 ms there. The
    /// cost is on problems with no path: cage problem 54 gives up after nine attempts instead
    /// of three. Every other attempt draws with [`Self::rrt_local_bias`] throughout instead of
    /// turning to [`Self::rrt_late_local_bias`]: on the first 40 problems of VAMP's spherized
    /// Fetch bookshelf and cage families (`bench mbm`, one core, two sets of 16 seeds, 4,960
    /// runs), runs left without a path after nine attempts 11 -> 1 (the cage's problem 7 took
    /// six of them in one set), the same paths where no attempt failed (about 97% of the runs).
    /// Attempts of other lengths (20,000 or 100,000 samples, Luby's sequence, doubling or x1.5
    /// from 10,000), simulated from 11,000 single attempts of the Fetch's first 40 problems per
    /// family, all have a higher mean (2.30-3.39 ms against 2.28 ms) and a p95 no better by
    /// more than 0.02 ms than 50,000 each (see `docs/benchmarks.md`).
    pub rrt_restarts: usize,
    /// Tool-pose goals: distinct IK solutions to aim for.
    pub ik_solutions: usize,
}

impl Default for MotionSettings {
    fn default() -> Self {
        Self {
            seed: 0,
            edge_check: EdgeCheck::Certified { tolerance: CERTIFY_TOLERANCE },
            resolution: DEFAULT_RESOLUTION,
            deadline: Deadline::none(),
            shortcut: true,
            shortcut_attempts: 5,
            shortcut_min_gain: 0.01,
            screen_above: 2.0,
            planner: PlannerKind::RrtConnect,
            batch_size: 200,
            k_neighbours: 10,
            parallel: false,
            rrt_range: 1.0,
            lazy_probe: DEFAULT_LAZY_PROBE,
            rrt_dynamic_domain: true,
            rrt_by_groups: true,
            parallel_legs: true,
            rrt_balance: true,
            sampler: Sampler::Uniform,
            rrt_local_bias: 0.5,
            rrt_late_local_bias: 0.9,
            rrt_late_after: 128,
            rrt_goal_retreat: false,
            rrt_local_span: 0.5,
            rrt_local_reach: 2.0,
            racers: 1,
            max_samples: 50_000,
            rrt_restarts: 64,
            ik_solutions: 4,
        }
    }
}

/// Plan a collision-free path for `model`'s robot from `start` to `goal`.
///
/// Errors say why: [`PlanError::InvalidInput`] (wrong length, NaN, start outside limits),
/// [`PlanError::StartInCollision`] and [`PlanError::GoalInCollision`] (naming the pair),
/// [`PlanError::GoalUnreachable`] (goal outside limits, IK failed), [`PlanError::OutOfTime`]
/// (the deadline passed; with the statistics so far), [`PlanError::NoPath`] (`max_samples`
/// used up).
pub fn plan_motion(
    model: &CollisionModel,
    start: &[f64],
    goal: &Goal,
    settings: &MotionSettings,
) -> Result<MotionPlan, PlanError> {
    plan_motion_with(model, start, goal, settings)
}

/// [`plan_motion`] against any [`StateValidity`] instead of a [`CollisionModel`].
pub fn plan_motion_with<V: StateValidity>(
    model: &V,
    start: &[f64],
    goal: &Goal,
    settings: &MotionSettings,
) -> Result<MotionPlan, PlanError> {
    if settings.racers > 1 {
        return match model.collision_model() {
            Some(model) => race_detached(model, start, goal, settings),
            None => race(model, start, goal, settings),
        };
    }
    plan_alone(model, start, goal, settings, Stages::All, None, false)
}

/// How long racer 0 of a race within the call ([`race`]) plans alone before the others are
/// handed to the thread pool. Most MotionBenchMaker UR5 searches end within it, so they pay
/// nothing for the race; the tail is where a second seed pays. On the 400 generated
/// narrow-passage problems (four interleaved runs on the 2-core machine), a head start of 1 ms
/// gave p50 426-464 µs (one core: 426-624), 300 µs gave 496-719 µs; p95 3.8-4.8 ms either way
/// (one core: 7.8-11.4 ms).
const RACE_HEAD_START: Duration = Duration::from_micros(1000);

/// [`RACE_HEAD_START`] of a race whose racers own what they plan with ([`race_detached`]): none.
/// Handing a racer over costs racer 0 a clone of the model and a push onto a racer thread's
/// queue (2.5 µs median, 8 µs at most over the 289 hand-overs of the three generated families
/// bookshelf_tall, bookshelf_thin and table_under_pick), and racer 0 never waits for it. Two
/// cores, five interleaved runs against a head start of 1 ms within the call (medians of the
/// runs): the 100 generated cage problems within 1 ms 80% -> 90%, p50 585 -> 426 µs, p95 2.48 ->
/// 1.42 ms; the three families above p95 450 -> 364 µs; the 296 public problems p50 119 -> 123
/// µs, p95 260 -> 260 µs. A head start of 50 µs: cage 86%, public p50 105 µs.
const DETACHED_HEAD_START: Duration = Duration::ZERO;

/// Which stages of [`plan_alone`] run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stages {
    /// The straight segment, then the search.
    All,
    /// Only the search (the straight segment is known to be blocked, or another racer tries it).
    Search,
}

/// The settings of racer `k` of a race whose flag is `flag` (see [`MotionSettings::racers`]).
fn racer_settings(settings: &MotionSettings, k: usize, flag: &Arc<AtomicBool>) -> MotionSettings {
    MotionSettings {
        seed: settings.seed.wrapping_add(k as u64),
        deadline: settings.deadline.clone().with_race_flag(Arc::clone(flag)),
        racers: 1,
        rrt_late_local_bias: if k % 2 == 1 { settings.rrt_local_bias } else { settings.rrt_late_local_bias },
        ..settings.clone()
    }
}

/// The answer of a race from its racers' results: the shortest path, or else the first error
/// (racer 0's when it is first).
fn race_answer(results: Vec<Result<MotionPlan, PlanError>>) -> Result<MotionPlan, PlanError> {
    let mut best: Option<MotionPlan> = None;
    let mut first_error = None;
    for result in results {
        match result {
            Ok(plan) => {
                if best.as_ref().is_none_or(|b| plan.stats.path_length < b.stats.path_length) {
                    best = Some(plan);
                }
            }
            Err(e) => {
                first_error.get_or_insert(e);
            }
        }
    }
    match (best, first_error) {
        (Some(plan), _) => Ok(plan),
        (None, Some(e)) => Err(e),
        (None, None) => Err(PlanError::NoPath { samples: 0 }),
    }
}

/// What a racer on a racer thread sends back: its result, or the panic it stopped with (raised
/// again on the caller's thread when it is read).
type RacerOutcome = std::thread::Result<Result<MotionPlan, PlanError>>;

/// [`race`] for a [`CollisionModel`], whose racers on the racer threads (`racers`) own what
/// they plan with (a clone of the model, shared among them, and of the start and goal), so
/// that the caller never waits for them: racer 0's path is returned at once, and racers still
/// running stop at their next reading of the race flag. They are handed over as soon as racer
/// 0's search begins ([`DETACHED_HEAD_START`]; not while it tries the straight segment, nor
/// while it certifies or shortens a path it found).
/// (Within a scope on the rayon pool, a path of racer 0 waited for every racer it had handed
/// over to start, see the flag and return, and for this thread to be woken: with a head start
/// of 150 µs, public MotionBenchMaker p95 339-416 µs against 206-285 µs at 1 ms.)
fn race_detached(
    model: &CollisionModel,
    start: &[f64],
    goal: &Goal,
    settings: &MotionSettings,
) -> Result<MotionPlan, PlanError> {
    let Some(racers) = racers::Racers::get() else { return race(model, start, goal, settings) };
    let flag = Arc::new(AtomicBool::new(false));
    let (sender, receiver) = std::sync::mpsc::channel::<RacerOutcome>();
    let handed = std::cell::Cell::new(false);
    let hand_over = || {
        if handed.replace(true) {
            return;
        }
        let shared = Arc::new((model.clone(), start.to_vec(), goal.clone()));
        for k in 1..settings.racers {
            let racer = racer_settings(settings, k, &flag);
            let (shared, flag, sender) = (Arc::clone(&shared), Arc::clone(&flag), sender.clone());
            racers.spawn(move || {
                if flag.load(Ordering::Relaxed) {
                    return;
                }
                let (model, start, goal) = &*shared;
                let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                    plan_alone(model, start, goal, &racer, Stages::Search, None, false)
                }));
                if matches!(outcome, Ok(Ok(_))) {
                    flag.store(true, Ordering::Relaxed);
                }
                // The caller may have gone with racer 0's path: nobody to tell.
                let _ = sender.send(outcome);
            });
        }
    };
    // Racer 0 tries the straight segment, then searches, in one run as a lone planner does (the
    // hand-over waits for its search): one start check, one set of goals, one memo of its
    // certificates. (The straight segment in a run of its own, then the search in another, cost
    // the public MotionBenchMaker UR5 problems that took under 150 µs on one core 9% with two,
    // with no racer handed over at all: interleaved, each problem's fastest of ten runs.)
    let racer = racer_settings(settings, 0, &flag);
    let legs = settings.parallel_legs
        && settings.deadline.expansion_budget().is_none()
        && settings.deadline.check_budget().is_none();
    let first = plan_alone(model, start, goal, &racer, Stages::All, Some((&hand_over, DETACHED_HEAD_START)), legs);
    let mut results = Vec::with_capacity(settings.racers);
    if first.is_ok() {
        flag.store(true, Ordering::Relaxed);
        // Paths the others found already compete with racer 0's; none is waited for.
        results.push(first);
        for outcome in receiver.try_iter() {
            results.push(outcome.unwrap_or_else(|panic| std::panic::resume_unwind(panic)));
        }
        return race_answer(results);
    }
    // An error before the search (the input, the start, the deadline on the straight segment)
    // is the answer: no other racer was handed over, and none would do better.
    if !handed.get() && !matches!(first, Err(PlanError::NoPath { .. })) {
        return first;
    }
    // An error of racer 0 is not the race's answer while another may still find a path: they
    // are handed over now if they were not yet, and waited for until one finds a path.
    hand_over();
    drop(sender);
    results.push(first);
    for outcome in receiver.iter().take(settings.racers - 1) {
        let result = outcome.unwrap_or_else(|panic| std::panic::resume_unwind(panic));
        let found = result.is_ok();
        results.push(result);
        if found {
            break;
        }
    }
    race_answer(results)
}

/// [`MotionSettings::racers`] planners on the rayon pool, racer `k` with seed `seed + k`; the
/// first to find a (certified) path raises the race flag that stops the others. When several
/// finish, the shortest path wins; when none does, racer 0's error is returned.
fn race<V: StateValidity>(
    model: &V,
    start: &[f64],
    goal: &Goal,
    settings: &MotionSettings,
) -> Result<MotionPlan, PlanError> {
    let flag = Arc::new(AtomicBool::new(false));
    // Racer 0 tries the straight segment first (most problems end there and need no race; the
    // hand-over waits for its search), the others search only.
    let run = |k: usize, hand_over: Option<(&dyn Fn(), Duration)>| {
        let racer = racer_settings(settings, k, &flag);
        let stages = if k == 0 { Stages::All } else { Stages::Search };
        let result = plan_alone(model, start, goal, &racer, stages, hand_over, false);
        if result.is_ok() {
            flag.store(true, Ordering::Relaxed);
        }
        result
    };
    // Racer 0 plans on this thread at once; the others are handed to the rayon pool (a
    // parallel iterator called from outside the pool would park this thread until two pool
    // threads woke up) only once racer 0 has planned for `RACE_HEAD_START` (at its next clock
    // read): most searches end before, and then nothing was handed over and nothing is waited
    // for. (Handed over at once, each waiting out the head start on its own core, they cost
    // the public MotionBenchMaker UR5 problems the waking of a pool thread and the join: with
    // two racers, each problem's fastest of six interleaved runs, p50 131 µs against 110 µs
    // now, per problem 0.855; cage unchanged, 0.97-0.99.) A racer that is certifying a path
    // when the race is won finishes its certificate first (the race flag is read between units
    // of work).
    let others: Vec<std::sync::Mutex<Option<Result<MotionPlan, PlanError>>>> =
        (1..settings.racers).map(|_| std::sync::Mutex::new(None)).collect();
    let first = rayon::in_place_scope(|scope| {
        let handed = std::cell::Cell::new(false);
        let hand_over = || {
            if handed.replace(true) {
                return;
            }
            for (k, slot) in others.iter().enumerate() {
                let (run, flag) = (&run, &flag);
                scope.spawn(move |_| {
                    if flag.load(Ordering::Relaxed) {
                        return;
                    }
                    let result = run(k + 1, None);
                    if let Ok(mut slot) = slot.lock() {
                        *slot = Some(result);
                    }
                });
            }
        };
        // A path of racer 0 raises the flag (in `run`), so racers not yet started never plan;
        // an error of racer 0 is not the race's answer while another may still find a path,
        // so they are handed over then if they were not yet.
        let first = run(0, Some((&hand_over, RACE_HEAD_START)));
        // Not after an error before the search (see `race_detached`).
        if matches!(first, Err(PlanError::NoPath { .. })) {
            hand_over();
        }
        first
    });
    let mut results = vec![first];
    results.extend(others.into_iter().filter_map(|slot| slot.into_inner().ok().flatten()));
    race_answer(results)
}

fn plan_alone<V: StateValidity>(
    model: &V,
    start: &[f64],
    goal: &Goal,
    settings: &MotionSettings,
    stages: Stages,
    hand_over: Option<(&dyn Fn(), Duration)>,
    legs_helper: bool,
) -> Result<MotionPlan, PlanError> {
    let robot = model.robot();
    if !(settings.resolution.is_finite() && settings.resolution > 0.0) {
        return Err(PlanError::InvalidInput {
            message: format!("resolution must be positive and finite, got {}", settings.resolution),
        });
    }
    check_start(model, start)?;
    let mut budget = Budget::new(&settings.deadline);
    if let Some((f, after)) = hand_over {
        budget = budget.with_hand_over(f, after);
    }
    // Nothing is handed over before the search (released there): a problem the straight segment
    // solves hands over nothing.
    budget.hold_hand_over(true);
    if let EdgeCheck::Certified { tolerance } = settings.edge_check
        && !(tolerance.is_finite() && tolerance > 0.0)
    {
        return Err(PlanError::InvalidInput {
            message: format!("the certificate tolerance must be positive and finite, got {tolerance}"),
        });
    }
    if !(settings.shortcut_min_gain.is_finite() && settings.shortcut_min_gain >= 0.0) {
        return Err(PlanError::InvalidInput {
            message: format!(
                "shortcut_min_gain must be zero or positive and finite, got {}",
                settings.shortcut_min_gain
            ),
        });
    }
    if settings.screen_above.is_nan() {
        return Err(PlanError::InvalidInput { message: "screen_above must not be NaN".to_string() });
    }
    if settings.lazy_probe.is_nan() || settings.lazy_probe < 0.0 {
        return Err(PlanError::InvalidInput {
            message: format!("lazy_probe must be zero or positive, got {}", settings.lazy_probe),
        });
    }
    let mut validity = Validity::new(model, settings.resolution)
        .with_edge_check(settings.edge_check)
        .with_screen_above(settings.screen_above);
    let mut rng = Rng::new(settings.seed);
    let goals = resolve_goals(model, start, goal, settings, &mut rng)?;
    let mut stats = MotionStats::default();
    let out_of_time = |budget: &Budget<'_>, validity: &Validity<'_, V>, stats: &MotionStats| PlanError::OutOfTime {
        stats: MotionStats {
            elapsed: budget.started.elapsed(),
            edges_checked: validity.edges_checked,
            collision_checks: validity.collision_checks,
            probe_checks: validity.probe_checks,
            ..stats.clone()
        },
    };
    if budget.expired() {
        return Err(out_of_time(&budget, &validity, &stats));
    }
    let space = robot.config_space();

    // 1. The straight segment, nearest goal first.
    let mut order: Vec<usize> = (0..goals.len()).collect();
    order.sort_by(|&a, &b| space.distance(start, &goals[a]).total_cmp(&space.distance(start, &goals[b])));
    let mut raw: Option<(Vec<Vec<f64>>, &'static str)> = None;
    if stages == Stages::Search {
        order.clear();
    }
    for &i in &order {
        if validity.segment_free_screened(start, &goals[i]) {
            raw = Some((vec![start.to_vec(), goals[i].clone()], "direct"));
            break;
        }
        if budget.spend(1, validity.collision_checks) {
            return Err(out_of_time(&budget, &validity, &stats));
        }
    }

    // 2. The search: on a robot of independent groups of joints, first one group at a time.
    let mut greedy_done = false;
    let lazy = matches!(settings.edge_check, EdgeCheck::Certified { .. }) && settings.lazy_probe > 0.0;
    let nearest = goals.iter().min_by(|a, b| space.distance(start, a).total_cmp(&space.distance(start, b)));
    if let (None, PlannerKind::RrtConnect, Some(goal), true) = (&raw, settings.planner, nearest, settings.rrt_by_groups)
    {
        budget.hold_hand_over(false);
        let found = by_groups(&mut validity, &mut budget, start, goal, settings, lazy, legs_helper, &mut stats);
        budget.suspend_hand_over(false);
        match found {
            Some(Outcome::Solved((p, greedy))) => {
                raw = Some((p, "rrt-connect-groups"));
                greedy_done = greedy;
            }
            Some(Outcome::OutOfTime { .. }) => return Err(out_of_time(&budget, &validity, &stats)),
            Some(Outcome::Infeasible) | None => {}
        }
    }
    if raw.is_none() {
        budget.hold_hand_over(false);
        let found = match settings.planner {
            PlannerKind::RrtConnect => {
                greedy_done = lazy && settings.shortcut;
                // An attempt that drew `max_samples` samples without a path is stuck more often
                // than the problem is infeasible: new trees, the random stream going on.
                let mut outcome = Outcome::Infeasible;
                for attempt in 0..=settings.rrt_restarts {
                    if attempt > 0 {
                        if !matches!(outcome, Outcome::Infeasible) || settings.max_samples == 0 {
                            break;
                        }
                        stats.restarts += 1;
                    }
                    outcome = rrt_connect::plan(
                        &mut validity,
                        &mut budget,
                        &mut rng,
                        start,
                        &goals,
                        &attempt_settings(settings, attempt),
                        (lazy, None),
                        &mut stats,
                    );
                }
                outcome.map(|p| (p, "rrt-connect"))
            }
            PlannerKind::LazyPrm => lazy_prm(model, &mut validity, &mut budget, start, &goals, settings, &mut stats)
                .map(|p| (p, "lazy-prm")),
        };
        match found {
            Outcome::Solved(p) => raw = Some(p),
            Outcome::OutOfTime { .. } => return Err(out_of_time(&budget, &validity, &stats)),
            Outcome::Infeasible => return Err(PlanError::NoPath { samples: stats.samples }),
        }
    }
    let Some((mut path, mut planner)) = raw else {
        return Err(PlanError::NoPath { samples: stats.samples });
    };

    // 3. Shortcuts (anytime: a deadline here returns the path found so far).
    if settings.shortcut && (path.len() > 2 || greedy_done) {
        if path.len() > 2 {
            let greedy = !greedy_done;
            let tries = (settings.shortcut_attempts, settings.shortcut_min_gain);
            path = shortcut::shortcut(path, &mut validity, &mut budget, &mut rng, greedy, tries);
        }
        planner = match planner {
            "rrt-connect" => "rrt-connect+shortcut",
            "rrt-connect-groups" => "rrt-connect-groups+shortcut",
            "lazy-prm" => "lazy-prm+shortcut",
            other => other,
        };
    }
    let path = unwrap_path(&space, path);
    stats.path_length = path_length(&space, &path);
    stats.planner = planner;
    stats.edges_checked = validity.edges_checked;
    stats.collision_checks = validity.collision_checks;
    stats.probe_checks = validity.probe_checks;
    stats.elapsed = budget.started.elapsed();
    Ok(MotionPlan { path, stats })
}

/// The settings of RRT-Connect's attempt `attempt` (0: the first; see
/// [`MotionSettings::rrt_restarts`]): every other attempt draws with the early share
/// ([`MotionSettings::rrt_local_bias`]) throughout, so that a problem whose trees the late share
/// keeps growing along themselves in a trap is next searched with more samples over the whole
/// box. Only attempts after one that drew `max_samples` samples without a path see the change.
fn attempt_settings(settings: &MotionSettings, attempt: usize) -> std::borrow::Cow<'_, MotionSettings> {
    if attempt % 2 == 1 && settings.rrt_late_local_bias != settings.rrt_local_bias {
        std::borrow::Cow::Owned(MotionSettings { rrt_late_local_bias: settings.rrt_local_bias, ..settings.clone() })
    } else {
        std::borrow::Cow::Borrowed(settings)
    }
}

/// A path: its configurations in order.
type Path = Vec<Vec<f64>>;

/// An order of [`by_groups`]: its waypoints, whether they were found free, and its legs
/// (`None`: not found yet).
type OrderState = (Path, bool, Vec<Option<Path>>);

/// Samples of one leg's search in [`by_groups`] before it gives the search up (for this round,
/// see [`GROUP_LEG_ROUNDS`]).
const GROUP_LEG_SAMPLES: usize = 2_000;

/// Rounds of [`by_groups`]: in each, every order whose waypoints are free searches the legs it
/// lacks, with new trees, [`GROUP_LEG_SAMPLES`] samples each; the search over every joint
/// follows when no round gave a path. With one round, one of VAMP's 1,470 Baxter problems
/// (both arms) fell to the search over every joint in each of two builds, and took it 105,335
/// samples (18-24 ms) in one; its legs need a few thousand.
const GROUP_LEG_ROUNDS: usize = 3;

/// On a robot of independent groups of joints ([`Robot::independent_dof_groups`]: two arms on a
/// fixed torso), a path from `start` to `goal` that moves one group at a time: the groups that
/// must move, in their order and then in the reverse order, each leg a straight segment or an
/// RRT-Connect search in that group's joints alone (at most [`GROUP_LEG_SAMPLES`] samples). Each
/// leg's search is as hard as one arm's problem, where the search over every joint draws
/// samples in all of them (on VAMP's Baxter problems, both arms moving). The legs' paths are
/// certified as any; the shortcuts that follow may move several groups at once. The groups are
/// those of [`groups_for_legs`]. `Solved` with the path and whether the greedy shortcut pass
/// has run over it (the legs side by side); `None` when they are one group of every joint or no
/// group must move (the goal is the start); `Infeasible` when no order gave a path (a waypoint
/// in collision, a leg out of samples).
#[allow(clippy::too_many_arguments)]
fn by_groups<V: StateValidity>(
    validity: &mut Validity<'_, V>,
    budget: &mut Budget<'_>,
    start: &[f64],
    goal: &[f64],
    settings: &MotionSettings,
    lazy: bool,
    parallel: bool,
    stats: &mut MotionStats,
) -> Option<Outcome<(Path, bool), ()>> {
    let robot = validity.model.robot();
    let mut delta = vec![0.0; start.len()];
    validity.space.deltas_into(start, goal, &mut delta);
    let groups = groups_for_legs(robot, &delta);
    // One group of every joint: nothing to take apart.
    if groups.len() < 2 && groups.iter().map(Vec::len).sum::<usize>() == robot.dof() {
        return None;
    }
    let moving: Vec<&Vec<usize>> = groups.iter().filter(|g| g.iter().any(|&d| delta[d] != 0.0)).collect();
    if moving.is_empty() {
        return None;
    }
    // Two legs or more at a time on the racer thread: no racer is handed over meanwhile (the
    // caller ends the suspension).
    let parallel = parallel && moving.len() > 1;
    budget.suspend_hand_over(parallel);
    let leg_settings = MotionSettings { max_samples: GROUP_LEG_SAMPLES, ..settings.clone() };
    let orders: Vec<Vec<&Vec<usize>>> = if moving.len() == 1 {
        vec![moving]
    } else {
        let reversed = moving.iter().rev().copied().collect();
        vec![moving, reversed]
    };
    // Per order, its waypoints, whether they were found free (checked at the order's first turn)
    // and its legs (`None`: not found yet), or `None` when a waypoint is in collision.
    let mut found: Vec<Option<OrderState>> = orders
        .iter()
        .map(|order| {
            // The waypoints: each group in turn moved to the goal.
            let mut points = vec![start.to_vec()];
            for group in order {
                let mut q = points.last().cloned().unwrap_or_default();
                for &d in group.iter() {
                    q[d] = goal[d];
                }
                points.push(q);
            }
            if let Some(last) = points.last_mut() {
                // The goal itself (its values, not a copy put together joint by joint).
                last.copy_from_slice(goal);
            }
            Some((points, false, vec![None; order.len()]))
        })
        .collect();
    // A leg that runs out of samples is most often stuck rather than impossible: after the other
    // order's turn, it is searched again with new trees (a stream of its own for the round),
    // up to `GROUP_LEG_ROUNDS` times, the legs found kept. Every leg an order lacks is searched
    // in its turn, two at a time with `parallel` (each leg's path that of one thread unless
    // raced, see `legs::search_legs`).
    for round in 0..GROUP_LEG_ROUNDS {
        'orders: for (o, (order, state)) in orders.iter().zip(found.iter_mut()).enumerate() {
            let Some((points, checked, legs)) = state else { continue };
            if !*checked {
                *checked = true;
                for q in &points[1..points.len() - 1] {
                    if budget.spend(1, validity.collision_checks) {
                        return Some(Outcome::OutOfTime { best: None, cause: budget.cause() });
                    }
                    if !validity.config_free(q) {
                        *state = None;
                        continue 'orders;
                    }
                }
            }
            let missing: Vec<usize> = (0..legs.len()).filter(|&i| legs[i].is_none()).collect();
            let jobs = missing
                .iter()
                .map(|&i| legs::LegJob {
                    from: points[i].clone(),
                    to: points[i + 1].clone(),
                    group: order[i].clone(),
                    seed: legs::leg_seed(settings.seed, round, o, i),
                })
                .collect();
            let helper = if parallel {
                validity.model.collision_model().map(|model| legs::Helper { model, first: false })
            } else {
                None
            };
            match legs::search_legs(validity, budget, jobs, &leg_settings, lazy, stats, helper) {
                Ok(paths) => {
                    for (&i, path) in missing.iter().zip(paths) {
                        legs[i] = path;
                    }
                }
                Err(cause) => return Some(Outcome::OutOfTime { best: None, cause }),
            }
            if legs.iter().any(Option::is_none) {
                continue 'orders;
            }
            let legs: Vec<Path> = std::mem::take(legs).into_iter().flatten().collect();
            // The legs side by side when that motion is free too (the groups only meet each
            // other there: each moves among the obstacles as in its leg), else one after the
            // other. With shortcuts, the greedy pass checks the side-by-side path: from each
            // vertex the farthest one it sees, the next vertex's edge checked only when it sees
            // none, so the edges it skips are never checked (as on a path of lazy RRT-Connect).
            if legs.len() > 1 {
                let together = side_by_side(&validity.space, start, &legs, order);
                let mut checked = vec![false; together.len().saturating_sub(1)];
                match rrt_connect::certify_path(together, &mut checked, validity, budget, settings.shortcut) {
                    Certified::Path(p) => return Some(Outcome::Solved((p, settings.shortcut))),
                    Certified::OutOfTime => return Some(Outcome::OutOfTime { best: None, cause: budget.cause() }),
                    Certified::Blocked(_) => {}
                }
            }
            let mut path = vec![start.to_vec()];
            for leg in legs {
                path.extend(leg.into_iter().skip(1));
            }
            return Some(Outcome::Solved((path, false)));
        }
    }
    Some(Outcome::Infeasible)
}

/// The independent groups of joints of [`by_groups`] for a motion by the joint steps `delta`:
/// [`Robot::independent_dof_groups`], except that
/// - a joint the motion does not move (`delta` 0) is held ([`Robot::dof_groups_holding`]: in no
///   group) where two groups would meet on its chain (a lifting torso under two arms: the lift
///   at the same height at start and goal; the groups part there) or where no joint that moves
///   shares its links (an arm that stays where it is). A joint that does not move inside one
///   moving group's chain stays in that group: a leg may still move it on its way;
/// - a joint where groups meet that moves ([`Robot::branch_dofs`]: a turning torso under two
///   arms) is a group of its own, so its leg moves it alone (the arms riding along, as they are),
///   and the groups below it part.
///
/// The groups come in the order of their first joint.
fn groups_for_legs<'r>(robot: &'r Robot, delta: &[f64]) -> std::borrow::Cow<'r, [Vec<usize>]> {
    let plain = std::borrow::Cow::Borrowed(robot.independent_dof_groups());
    if delta.len() != robot.dof() {
        return plain;
    }
    // Every joint moving and none where groups meet (a one-arm robot's plan): as they are,
    // with nothing allocated.
    let any_still = delta.contains(&0.0);
    if !any_still && robot.branch_dofs().is_empty() {
        return plain;
    }
    let still: Vec<bool> = delta.iter().map(|&d| d == 0.0).collect();
    let mut held = vec![false; delta.len()];
    if any_still {
        // Every joint that does not move held: the groups that are left.
        let parted = robot.dof_groups_holding(&still);
        let mut group_of = vec![usize::MAX; delta.len()];
        for (k, g) in parted.iter().enumerate() {
            for &d in g {
                group_of[d] = k;
            }
        }
        // A still joint stays held unless the links it moves are moved by joints of one group.
        let mut meets: Vec<Vec<usize>> = vec![Vec::new(); delta.len()];
        for link in 0..robot.links().len() {
            let movers = robot.dofs_moving(link);
            let groups_here: Vec<usize> =
                movers.iter().enumerate().filter(|&(d, &m)| m && !still[d]).map(|(d, _)| group_of[d]).collect();
            for (d, _) in movers.iter().enumerate().filter(|&(d, &m)| m && still[d]) {
                for &k in &groups_here {
                    if !meets[d].contains(&k) {
                        meets[d].push(k);
                    }
                }
            }
        }
        for (d, h) in held.iter_mut().enumerate() {
            *h = still[d] && meets[d].len() != 1;
        }
    }
    let own: Vec<usize> = robot.branch_dofs().iter().copied().filter(|&d| !still[d]).collect();
    if !held.contains(&true) && own.is_empty() {
        return plain;
    }
    for &d in &own {
        held[d] = true;
    }
    let mut groups = robot.dof_groups_holding(&held);
    groups.extend(own.into_iter().map(|d| vec![d]));
    groups.sort_unstable_by_key(|g| g.first().copied());
    std::borrow::Cow::Owned(groups)
}

/// The legs of [`by_groups`] (leg `i` moves the joints `groups[i]` alone) run at once: each
/// group along its leg at the same share of the leg's length, with a vertex wherever some leg
/// has one. The path is as long as `sqrt(sum of squared leg lengths)` where one leg after the
/// other is the plain sum (two equal legs: 0.71 of it).
fn side_by_side(
    space: &embodied_models::ConfigSpace,
    start: &[f64],
    legs: &[Vec<Vec<f64>>],
    groups: &[&Vec<usize>],
) -> Vec<Vec<f64>> {
    // Each leg's vertices as shares of its length.
    let shares: Vec<Vec<f64>> = legs
        .iter()
        .map(|leg| {
            let mut at = vec![0.0];
            for w in leg.windows(2) {
                at.push(at.last().copied().unwrap_or(0.0) + space.distance(&w[0], &w[1]));
            }
            let total = at.last().copied().unwrap_or(0.0);
            if total > 0.0 { at.iter().map(|a| a / total).collect() } else { vec![0.0; leg.len()] }
        })
        .collect();
    let mut cuts: Vec<f64> = shares.iter().flatten().copied().chain([1.0]).collect();
    cuts.sort_by(f64::total_cmp);
    cuts.dedup_by(|a, b| *a - *b < 1e-12);
    cuts.into_iter()
        .map(|s| {
            let mut q = start.to_vec();
            for ((leg, at), group) in legs.iter().zip(&shares).zip(groups) {
                // The leg's segment holding the share `s`, and the point there.
                let j = at.partition_point(|&a| a <= s).clamp(1, leg.len().max(2) - 1);
                let (a0, a1) = (at[j - 1], at.get(j).copied().unwrap_or(1.0));
                let t = if a1 > a0 { ((s - a0) / (a1 - a0)).clamp(0.0, 1.0) } else { 1.0 };
                // The ends exactly (the start, and each group's goal values).
                let p = match (leg.get(j), leg.last()) {
                    (_, Some(last)) if s >= 1.0 => last.clone(),
                    _ if s <= 0.0 => start.to_vec(),
                    (Some(next), _) => space.interpolate(&leg[j - 1], next, t),
                    (None, _) => leg[j - 1].clone(),
                };
                for &d in group.iter() {
                    q[d] = p[d];
                }
            }
            q
        })
        .collect()
}

/// Lazy PRM grown in batches: add start and goals, then grow, search, grow...
fn lazy_prm<V: StateValidity>(
    model: &V,
    validity: &mut Validity<'_, V>,
    budget: &mut Budget<'_>,
    start: &[f64],
    goals: &[Vec<f64>],
    settings: &MotionSettings,
    stats: &mut MotionStats,
) -> Outcome<Vec<Vec<f64>>, ()> {
    let mut roadmap = Roadmap::new(model.robot(), settings.k_neighbours, settings.seed ^ 0x5eed_f9a7);
    let s = roadmap.add_vertex(start.to_vec());
    let gs: Vec<NodeIndex> = goals.iter().map(|g| roadmap.add_vertex(g.clone())).collect();
    let batch = settings.batch_size.max(1);
    let mut counters = QueryCounters::default();
    loop {
        if roadmap.samples() >= settings.max_samples {
            stats.samples = roadmap.samples();
            return Outcome::Infeasible;
        }
        let n = batch.min(settings.max_samples - roadmap.samples());
        roadmap.grow(model, n, settings.parallel);
        stats.samples = roadmap.samples();
        validity.collision_checks += n as u64;
        if budget.spend(n as u64, validity.collision_checks) {
            return Outcome::OutOfTime { best: None, cause: budget.cause() };
        }
        let outcome = roadmap.lazy_search(validity, budget, s, &gs, &mut counters);
        stats.astar_expansions = counters.astar_expansions;
        stats.searches = counters.searches;
        match outcome {
            LazyOutcome::Found(p) => return Outcome::Solved(roadmap.path_configurations(&p)),
            LazyOutcome::Interrupted => return Outcome::OutOfTime { best: None, cause: budget.cause() },
            LazyOutcome::Disconnected => {}
        }
    }
}

/// The goal configurations to aim for: valid (within limits, collision-free) members of the
/// goal, or IK solutions of a tool pose.
fn resolve_goals<V: StateValidity>(
    model: &V,
    start: &[f64],
    goal: &Goal,
    settings: &MotionSettings,
    rng: &mut Rng,
) -> Result<Vec<Vec<f64>>, PlanError> {
    let robot = model.robot();
    let candidates: Vec<Vec<f64>> = match goal {
        Goal::Configuration(q) => vec![q.clone()],
        Goal::AnyOf(qs) if qs.is_empty() => {
            return Err(PlanError::InvalidInput { message: "the goal set is empty".into() });
        }
        Goal::AnyOf(qs) => qs.clone(),
        Goal::ToolPose { end_effector, pose } => tool_pose_goals(robot, start, *end_effector, pose, settings, rng)?,
    };
    let mut first_error = None;
    let mut valid = Vec::with_capacity(candidates.len());
    for (index, q) in candidates.into_iter().enumerate() {
        if q.len() != robot.dof() || q.iter().any(|v| !v.is_finite()) {
            return Err(PlanError::InvalidInput {
                message: format!("goal {index}: expected {} finite joint values, got {:?}", robot.dof(), q),
            });
        }
        let error = if let Err(e) = robot.check_configuration(&q) {
            Some(PlanError::GoalUnreachable { reason: format!("goal {index} is outside the joint limits: {e}") })
        } else {
            model.first_collision(&q).map(|contact| PlanError::GoalInCollision { index, contact })
        };
        match error {
            None => valid.push(q),
            Some(e) => {
                first_error.get_or_insert(e);
            }
        }
    }
    match (valid.is_empty(), first_error) {
        (true, Some(e)) => Err(e),
        (true, None) => Err(PlanError::InvalidInput { message: "no goal configuration".into() }),
        (false, _) => {
            if matches!(goal, Goal::ToolPose { .. }) {
                valid.truncate(settings.ik_solutions.max(1));
            }
            Ok(valid)
        }
    }
}

/// IK solutions for a tool pose. Where the end effector has a closed form: every solution it
/// lists (nearest the start first; `resolve_goals` keeps the first `ik_solutions` valid ones).
/// Otherwise, or when the closed form finds none with the start's other joints (a track held
/// where it is): up to `ik_solutions` distinct numerical solutions, the first seeded at the
/// start, the others at the start with the joints that move the end effector drawn at random
/// (a goal for one arm of two leaves the other where it starts).
fn tool_pose_goals(
    robot: &Robot,
    start: &[f64],
    ee: usize,
    pose: &Isometry3<f64>,
    settings: &MotionSettings,
    rng: &mut Rng,
) -> Result<Vec<Vec<f64>>, PlanError> {
    if ee >= robot.end_effectors().len() {
        return Err(PlanError::InvalidInput { message: format!("robot `{}` has no end effector {ee}", robot.name()) });
    }
    if robot.closed_form(ee).is_some() {
        let all = robot
            .inverse_kinematics_all(ee, pose, start)
            .map_err(|e| PlanError::InvalidInput { message: format!("tool-pose goal: {e}") })?;
        if !all.is_empty() {
            return Ok(all);
        }
    }
    let space = robot.config_space();
    let wanted = settings.ik_solutions.max(1);
    let mut solutions: Vec<Vec<f64>> = Vec::new();
    let mut last_error = None;
    let attempts = 2 * wanted + 2;
    let moving = robot.dofs_moving(robot.end_effectors()[ee].link);
    for attempt in 0..attempts {
        if solutions.len() >= wanted {
            break;
        }
        // Later seeds draw only the joints that move the end effector: the others stay at the
        // start, where a goal for this end effector must leave them.
        let mut seed = start.to_vec();
        if attempt > 0 {
            robot.randomise_dofs_into(rng, |i| moving[i], &mut seed);
        }
        let options = IkOptions {
            seed: settings.seed.wrapping_add(attempt as u64),
            restarts: if attempt == 0 { 20 } else { 2 },
            ..IkOptions::default()
        };
        match robot.inverse_kinematics(ee, pose, &seed, &options) {
            Ok(q) => {
                if solutions.iter().all(|s| space.distance(s, &q) > 1e-3) {
                    solutions.push(q);
                }
            }
            Err(e) => last_error = Some(e),
        }
        // Stop early if the pose is out of reach: the first, thorough attempt failed.
        if attempt == 0 && solutions.is_empty() {
            break;
        }
    }
    if solutions.is_empty() {
        let reason = match last_error {
            Some(e) => format!("no inverse-kinematics solution for the tool pose: {e}"),
            None => "no inverse-kinematics solution for the tool pose".into(),
        };
        return Err(PlanError::GoalUnreachable { reason });
    }
    Ok(solutions)
}

/// The Polycrank beside a post, the motion tests' small problem: the robot and its model.
#[cfg(test)]
pub(crate) fn polycrank_by_a_post() -> (Robot, CollisionModel) {
    use embodied_models::collision::{Environment, Obstacle};
    use embodied_models::{Shape, builtin};
    let robot = builtin("polycrank").expect("robot");
    let mut env = Environment::new();
    env.add(Obstacle::new("post", Isometry3::translation(0.45, 0.1, 0.4), Shape::cuboid(0.06, 0.06, 0.4)));
    let model = CollisionModel::new(&robot, env);
    (robot, model)
}

#[cfg(test)]
mod tests {
    use std::cell::Cell;

    use super::*;

    /// Odd attempts draw with the early share throughout; even ones as set; nothing is copied
    /// when the two shares are one.
    #[test]
    fn every_other_attempt_draws_with_the_early_share() {
        let settings = MotionSettings { rrt_local_bias: 0.4, rrt_late_local_bias: 0.8, ..MotionSettings::default() };
        for attempt in 0..6 {
            let s = attempt_settings(&settings, attempt);
            let late = if attempt % 2 == 1 { 0.4 } else { 0.8 };
            assert_eq!((s.rrt_local_bias, s.rrt_late_local_bias), (0.4, late), "attempt {attempt}");
            assert_eq!(
                (s.seed, s.max_samples, s.rrt_late_after),
                (settings.seed, settings.max_samples, settings.rrt_late_after)
            );
        }
        let one = MotionSettings { rrt_local_bias: 0.6, rrt_late_local_bias: 0.6, ..MotionSettings::default() };
        assert!(matches!(attempt_settings(&one, 1), std::borrow::Cow::Borrowed(_)));
    }

    /// Racers plan with seeds of their own, one planner each; odd racers draw with the early
    /// share throughout.
    #[test]
    fn odd_racers_draw_with_the_early_share() {
        let settings = MotionSettings {
            seed: 7,
            racers: 3,
            rrt_local_bias: 0.3,
            rrt_late_local_bias: 0.9,
            ..MotionSettings::default()
        };
        let flag = Arc::new(AtomicBool::new(false));
        for k in 0..4 {
            let r = racer_settings(&settings, k, &flag);
            let late = if k % 2 == 1 { 0.3 } else { 0.9 };
            assert_eq!(
                (r.seed, r.racers, r.rrt_local_bias, r.rrt_late_local_bias),
                (7 + k as u64, 1, 0.3, late),
                "racer {k}"
            );
        }
    }

    /// A racer's run hands the other racers over only once its search has begun: not while it
    /// tries the straight segments to ten goals, nine of them blocked (more than enough clock
    /// reads for a hand-over due at once), and once in a search of many samples.
    #[test]
    fn the_hand_over_waits_for_the_search() {
        let (robot, model) = polycrank_by_a_post();
        let space = robot.config_space();
        let settings =
            MotionSettings { deadline: Deadline::after(Duration::from_secs(60)), ..MotionSettings::default() };
        let calls = Cell::new(0);
        let count = || calls.set(calls.get() + 1);
        let certified = |a: &[f64], b: &[f64]| model.motion_is_certified_free(a, b, 1e-4);
        let mut rng = Rng::new(11);
        let mut free_config = || loop {
            let q = robot.random_configuration(&mut rng);
            if !model.collides(&q) {
                return q;
            }
        };
        // Goals the straight segment reaches only at the tenth try (nearest first).
        let (mut direct, mut searched) = (0, 0);
        for _ in 0..400 {
            if direct > 0 && searched > 0 {
                break;
            }
            let start = free_config();
            let candidates: Vec<Vec<f64>> = (0..60).map(|_| free_config()).collect();
            let dist = |q: &Vec<f64>| space.distance(&start, q);
            let far_free =
                candidates.iter().filter(|g| certified(&start, g)).max_by(|a, b| dist(a).total_cmp(&dist(b)));
            let Some(far_free) = far_free else { continue };
            let mut goals: Vec<Vec<f64>> = candidates
                .iter()
                .filter(|g| dist(g) < dist(far_free) && !certified(&start, g))
                .take(9)
                .cloned()
                .collect();
            if direct == 0 && goals.len() == 9 {
                goals.push(far_free.clone());
                calls.set(0);
                let plan = plan_alone(
                    &model,
                    &start,
                    &Goal::AnyOf(goals),
                    &settings,
                    Stages::All,
                    Some((&count, Duration::ZERO)),
                    false,
                )
                .expect("a straight segment");
                assert_eq!(plan.path.len(), 2, "the straight segment to the tenth goal");
                assert_eq!(calls.get(), 0, "handed over before the search");
                direct += 1;
            } else if searched == 0 && !goals.is_empty() {
                calls.set(0);
                let plan = plan_alone(
                    &model,
                    &start,
                    &Goal::Configuration(goals[0].clone()),
                    &settings,
                    Stages::All,
                    Some((&count, Duration::ZERO)),
                    false,
                )
                .expect("a path");
                if plan.stats.samples >= 16 {
                    assert_eq!(calls.get(), 1, "handed over once in the search");
                    searched += 1;
                }
            }
        }
        assert!(direct > 0 && searched > 0, "problems of both kinds found: {direct} direct, {searched} searched");
    }

    /// Two six-joint arms 2 m apart on one base, from URDF (no closed-form IK).
    fn two_small_arms() -> Robot {
        let mut urdf = String::from(r#"<robot name="two-arms"><link name="base"/>"#);
        for (arm, y) in [("a", 0.0), ("b", 2.0)] {
            let mut parent = "base".to_string();
            for (k, axis) in ["0 0 1", "0 1 0", "0 1 0", "0 0 1", "0 1 0", "0 0 1"].iter().enumerate() {
                let link = format!("{arm}{k}");
                let origin = if k == 0 { format!("0 {y} 0.1") } else { "0 0 0.25".into() };
                urdf += &format!(
                    r#"<link name="{link}"><collision><origin xyz="0 0 0.15"/><geometry><sphere radius="0.05"/></geometry></collision></link>
<joint name="{link}_j" type="revolute"><parent link="{parent}"/><child link="{link}"/><origin xyz="{origin}"/><axis xyz="{axis}"/><limit lower="-2.5" upper="2.5" velocity="1"/></joint>"#
                );
                parent = link;
            }
        }
        urdf += "</robot>";
        embodied_models::urdf::parse_urdf(&urdf, std::path::Path::new("two-arms.urdf"), &Default::default())
            .expect("two arms load")
    }

    /// Every IK goal for one arm's tool pose, the start-seeded one and the randomly seeded ones,
    /// leaves the other arm where it starts; and the plan ends there too.
    #[test]
    fn tool_pose_goals_of_one_arm_leave_the_other_where_it_starts() {
        let robot = two_small_arms();
        assert_eq!((robot.dof(), robot.end_effectors().len()), (12, 2));
        let model = CollisionModel::new(&robot, embodied_models::Environment::new());
        let mut rng = Rng::new(5);
        let mut several = 0;
        for case in 0..10 {
            let start = robot.random_configuration(&mut rng);
            let goal_q = robot.random_configuration(&mut rng);
            let (_, pose) = robot.end_effector_poses(&goal_q, 1);
            let settings = MotionSettings { seed: case, ..MotionSettings::default() };
            let goals = tool_pose_goals(&robot, &start, 1, &pose, &settings, &mut Rng::new(case)).expect("IK");
            for q in &goals {
                assert_eq!(q[..6], start[..6], "case {case}: arm a moved for a goal of arm b");
                let (_, reached) = robot.end_effector_poses(q, 1);
                assert!((reached.translation.vector - pose.translation.vector).norm() < 1e-4, "case {case}");
            }
            several += usize::from(goals.len() > 1);
            if let Ok(plan) = plan_motion(&model, &start, &Goal::ToolPose { end_effector: 1, pose }, &settings) {
                assert_eq!(plan.path.last().expect("path")[..6], start[..6], "case {case}: the plan moved arm a");
            }
        }
        // The randomly seeded solutions are what the property is about.
        assert!(several >= 5, "only {several} of 10 cases found more than one solution");
    }
}

#[cfg(test)]
mod side_by_side_tests {
    use embodied_models::ConfigSpace;

    use super::side_by_side;

    /// Two legs of other vertex counts run at once: the ends are the start and the goal to the
    /// bit, each group's values lie on its leg at the same share of its length, and the path is
    /// as long as the root of the legs' squared lengths.
    #[test]
    fn legs_side_by_side_keep_each_leg_and_shorten_the_path() {
        let space = ConfigSpace::from_wraps(vec![false; 5]);
        let start = vec![0.0, 0.0, 0.0, 0.0, 0.7];
        // Group [0, 1] along an L of lengths 1 and 2; group [2, 3] along three steps of 1.
        let a = vec![start.clone(), vec![1.0, 0.0, 0.0, 0.0, 0.7], vec![1.0, 2.0, 0.0, 0.0, 0.7]];
        let b = vec![
            a[2].clone(),
            vec![1.0, 2.0, 1.0, 0.0, 0.7],
            vec![1.0, 2.0, 1.0, 1.0, 0.7],
            vec![1.0, 2.0, 2.0, 1.0, 0.7],
        ];
        let (ga, gb) = (vec![0, 1], vec![2, 3]);
        let path = side_by_side(&space, &start, &[a.clone(), b.clone()], &[&ga, &gb]);
        assert_eq!(path.first(), Some(&start));
        assert_eq!(path.last(), b.last());
        // Cuts at the shares 0, 1/3 (both legs), 2/3 (b), 1.
        assert_eq!(path.len(), 4);
        let length: f64 = path.windows(2).map(|w| space.distance(&w[0], &w[1])).sum();
        assert!((length - (3.0f64 * 3.0 + 3.0 * 3.0).sqrt()).abs() < 1e-12, "{length}");
        for q in &path {
            assert_eq!(q[4], 0.7, "a joint of no group moved: {q:?}");
            // Group a at share s: along its L (x first, then y).
            let s_a = q[0] + q[1];
            let s_b = q[2] + q[3];
            assert!((s_a - s_b).abs() < 1e-12, "the legs are at other shares: {q:?}");
            assert!(q[1] == 0.0 || q[0] == 1.0, "group a left its leg: {q:?}");
            assert!(q[3] == 0.0 || q[2] == 1.0 || q[3] == 1.0, "group b left its leg: {q:?}");
        }
    }
}

#[cfg(test)]
mod holding_tests {
    use embodied_models::nalgebra::{Isometry3, Vector3};
    use embodied_models::{JointKind, JointLimits, RobotBuilder};

    use super::groups_for_legs;

    /// A lift (DOF 0) under two arms of three joints (1-3 and 4-6).
    fn lifted_arms() -> embodied_models::Robot {
        let mut b = RobotBuilder::new("lifted");
        let id = Isometry3::identity();
        let lim = JointLimits::new(-1.0, 1.0, 1.0, 1.0);
        let base = b.link("base", vec![]);
        let lift = b.link("lift", vec![]);
        b.joint("lift", JointKind::Prismatic, base, lift, id, Vector3::z(), 0.0, id, lim);
        for side in ["l", "r"] {
            let mut parent = lift;
            for k in 0..3 {
                let link = b.link(format!("{side}{k}"), vec![]);
                b.joint(format!("{side}_j{k}"), JointKind::Revolute, parent, link, id, Vector3::z(), 0.0, id, lim);
                parent = link;
            }
        }
        b.build().expect("a robot")
    }

    /// The still lift is held and the arms part; a still joint inside an arm stays in its
    /// group (a leg may move it); a moving lift is a group of its own.
    #[test]
    fn only_still_joints_where_groups_meet_are_held() {
        let robot = lifted_arms();
        let groups = |delta: &[f64]| groups_for_legs(&robot, delta).into_owned();
        assert_eq!(groups(&[0.0, 0.1, 0.2, 0.3, 0.1, 0.2, 0.3]), vec![vec![1, 2, 3], vec![4, 5, 6]]);
        assert_eq!(groups(&[0.0, 0.1, 0.0, 0.3, 0.1, 0.2, 0.0]), vec![vec![1, 2, 3], vec![4, 5, 6]]);
        // One arm still as a whole: held, and the lift with the arm that moves.
        assert_eq!(groups(&[0.0, 0.0, 0.0, 0.0, 0.1, 0.2, 0.3]), vec![vec![0, 4, 5, 6]]);
        // Nothing moves: every joint held.
        assert!(groups(&[0.0; 7]).is_empty());
        // The lift moving: a group of its own, the arms apart.
        assert_eq!(robot.branch_dofs(), [0]);
        assert_eq!(groups(&[0.1, 0.1, 0.2, 0.3, 0.1, 0.2, 0.3]), vec![vec![0], vec![1, 2, 3], vec![4, 5, 6]]);
        assert_eq!(groups(&[0.1; 7]), vec![vec![0], vec![1, 2, 3], vec![4, 5, 6]]);
        // The lift and one arm moving, the other arm still (a group of no leg: none of its
        // joints moves).
        assert_eq!(groups(&[0.1, 0.0, 0.0, 0.0, 0.1, 0.2, 0.3]), vec![vec![0], vec![1, 2, 3], vec![4, 5, 6]]);
        // Steps of another length than the robot's: the plain groups.
        assert_eq!(groups(&[0.0; 3]), vec![(0..7).collect::<Vec<_>>()]);
    }
}
