//! Deliberation as search, in the terms of section 4 of the paper.
//!
//! | paper                                        | here                                     |
//! |----------------------------------------------|------------------------------------------|
//! | search space state                           | [`SearchProblem::State`]                 |
//! | initial state                                | [`SearchProblem::initial`]               |
//! | operators (production rules, predicates)     | [`SearchProblem::successors`], [`Successor`] |
//! | data structure accumulating generated states | the open heap + state table inside [`solve`] |
//! | goal test                                    | [`SearchProblem::is_goal`]               |
//! | path cost (so far + remaining estimate)      | [`Cost`] `g` + [`SearchProblem::heuristic`] `h` |
//! | plan: path from initial to goal state        | [`Plan`]                                 |
//!
//! [`solve`] is A* that watches a [`Deadline`]: when planning is late it returns
//! [`SearchOutcome::OutOfTime`] so that the agent can halt its effector, as the paper requires.
//! [`solve_astar`] runs the `pathfinding` crate's A* on the same problem; it is the reference
//! the tests compare against.

use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::collections::HashMap;
use std::collections::hash_map::Entry;
use std::hash::{BuildHasherDefault, Hash, Hasher};
use std::ops::Add;
use std::time::{Duration, Instant};

use crate::deadline::{Deadline, Interrupt};
use crate::error::PlanError;
pub use crate::outcome::Outcome;

/// A path cost: a non-negative `f64` that is never NaN, hence totally ordered.
///
/// `+inf` is allowed (an impassable edge or an unknown estimate); the sum of two costs is again
/// a cost, because non-negative non-NaN floats are closed under addition.
#[derive(Debug, Clone, Copy, Default, serde::Serialize)]
pub struct Cost(f64);

impl Cost {
    /// Zero cost.
    pub const ZERO: Cost = Cost(0.0);
    /// Unit cost.
    pub const ONE: Cost = Cost(1.0);
    /// Infinite cost.
    pub const INFINITY: Cost = Cost(f64::INFINITY);

    /// A cost from a float; NaN and negative values are rejected.
    pub fn new(value: f64) -> Result<Cost, PlanError> {
        Self::checked(value, "value")
    }

    /// As [`Cost::new`], naming what the cost is in the error (`context`).
    pub fn checked(value: f64, context: &str) -> Result<Cost, PlanError> {
        if value.is_nan() {
            Err(PlanError::NanCost { context: context.to_owned() })
        } else if value < 0.0 {
            Err(PlanError::NegativeCost { context: context.to_owned(), value })
        } else {
            // `+ 0.0` turns -0.0 into +0.0 so that `total_cmp` agrees with `==`.
            Ok(Cost(value + 0.0))
        }
    }

    /// The cost as a float.
    pub fn get(self) -> f64 {
        self.0
    }

    /// A heuristic value as a cost: NaN or negative estimates (malformed) count as 0, which is
    /// always admissible for non-negative operator costs.
    fn from_estimate(h: f64) -> Cost {
        if h > 0.0 { Cost(h) } else { Cost::ZERO }
    }
}

impl TryFrom<f64> for Cost {
    type Error = PlanError;
    fn try_from(value: f64) -> Result<Self, Self::Error> {
        Cost::new(value)
    }
}

impl From<Cost> for f64 {
    fn from(cost: Cost) -> f64 {
        cost.0
    }
}

impl PartialEq for Cost {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Cost {}
impl PartialOrd for Cost {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Cost {
    fn cmp(&self, other: &Self) -> Ordering {
        self.0.total_cmp(&other.0)
    }
}
impl Hash for Cost {
    fn hash<H: Hasher>(&self, state: &mut H) {
        self.0.to_bits().hash(state);
    }
}
impl Add for Cost {
    type Output = Cost;
    fn add(self, rhs: Cost) -> Cost {
        Cost(self.0 + rhs.0)
    }
}
impl pathfinding::num_traits::Zero for Cost {
    fn zero() -> Self {
        Cost::ZERO
    }
    fn is_zero(&self) -> bool {
        self.0 == 0.0
    }
}

/// One application of an operator: the state it generates and what it costs.
#[derive(Debug, Clone, PartialEq)]
pub struct Successor<S, O> {
    /// The operator that was applied (e.g. a ground task action; `()` for plain graphs).
    pub operator: O,
    /// The generated state.
    pub state: S,
    /// The operator's path cost.
    pub cost: Cost,
}

/// A deliberation problem: the entities the paper lists in section 4.
pub trait SearchProblem {
    /// A search space state (not the state of the agent or of the environment).
    type State: Clone + Eq + Hash;
    /// An operator label carried into the plan so that it can be refined or executed.
    type Operator: Clone;

    /// The initial state, from which the search commences.
    fn initial(&self) -> Self::State;

    /// Applies every applicable operator to `state`, pushing the generated states onto `out`
    /// (which arrives empty). The order of `out` is the tie-break order: keep it deterministic.
    fn successors(&self, state: &Self::State, out: &mut Vec<Successor<Self::State, Self::Operator>>);

    /// The goal test.
    fn is_goal(&self, state: &Self::State) -> bool;

    /// An admissible estimate of the remaining path cost to a goal (never more than the truth).
    /// `+inf` marks a state from which no goal is reachable (it is pruned); NaN or negative
    /// values are treated as 0. The default, 0, turns A* into Dijkstra's algorithm.
    fn heuristic(&self, _state: &Self::State) -> f64 {
        0.0
    }
}

/// A plan: the path from the initial state, with the operators applied along it.
///
/// `states.len() == operators.len() + 1`; `states[0]` is the initial state.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan<S, O> {
    /// Visited search states, initial first.
    pub states: Vec<S>,
    /// `operators[i]` transforms `states[i]` into `states[i + 1]`.
    pub operators: Vec<O>,
    /// Total path cost.
    pub cost: f64,
}

impl<S, O> Plan<S, O> {
    /// The last state of the plan.
    pub fn last_state(&self) -> Option<&S> {
        self.states.last()
    }

    /// Number of operators.
    pub fn len(&self) -> usize {
        self.operators.len()
    }

    /// True when the plan applies no operator.
    pub fn is_empty(&self) -> bool {
        self.operators.is_empty()
    }
}

/// A partial plan: the path to the expanded state that looked closest to a goal. It does NOT
/// reach a goal; executing it is the caller's gamble.
#[derive(Debug, Clone, PartialEq)]
pub struct PartialPlan<S, O> {
    /// The path to that state.
    pub plan: Plan<S, O>,
    /// The heuristic estimate of the cost still missing at its end.
    pub remaining_estimate: f64,
}

/// What a search produced: the crate's one [`Outcome`], with a [`Plan`] when solved and the
/// best [`PartialPlan`] when stopped.
pub type SearchOutcome<S, O> = Outcome<Plan<S, O>, PartialPlan<S, O>>;

/// Counters of one search.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct SearchStats {
    /// States taken off the open list and expanded (goal test + operators applied).
    pub expansions: u64,
    /// Successor states generated by operators (including ones already known).
    pub generated: u64,
    /// Wall-clock time spent in the search.
    pub elapsed: Duration,
    /// How long after the wall-clock deadline the search returned (only when the clock stopped it).
    pub overshoot: Option<Duration>,
}

/// An outcome with its counters.
#[derive(Debug, Clone, PartialEq)]
pub struct SearchReport<S, O> {
    /// What the search produced.
    pub outcome: SearchOutcome<S, O>,
    /// How much work it took.
    pub stats: SearchStats,
}

/// The wall clock and the cancellation flag are read once every this many expansions
/// (`Instant::now()` costs ~20 ns; an expansion on a grid ~100 ns). The expansion budget is
/// checked on every expansion. Measured in `benches/search.rs`.
pub const CLOCK_CHECK_INTERVAL: u64 = 4;

const NO_PARENT: usize = usize::MAX;

/// FxHash-style multiplicative hasher: lookups only (the search never iterates a map for
/// order), so a fast non-keyed hash is safe and keeps results deterministic.
#[derive(Default, Clone, Copy)]
struct FastHasher(u64);

impl FastHasher {
    const K: u64 = 0x51_7c_c1_b7_27_22_0a_95;
    #[inline]
    fn mix(&mut self, word: u64) {
        self.0 = (self.0.rotate_left(5) ^ word).wrapping_mul(Self::K);
    }
}

impl Hasher for FastHasher {
    fn write(&mut self, bytes: &[u8]) {
        let mut chunks = bytes.chunks_exact(8);
        for chunk in &mut chunks {
            let mut word = [0u8; 8];
            word.copy_from_slice(chunk);
            self.mix(u64::from_le_bytes(word));
        }
        let rest = chunks.remainder();
        if !rest.is_empty() {
            let mut word = [0u8; 8];
            word[..rest.len()].copy_from_slice(rest);
            self.mix(u64::from_le_bytes(word) ^ ((rest.len() as u64) << 59));
        }
    }
    fn write_u8(&mut self, i: u8) {
        self.mix(u64::from(i));
    }
    fn write_u16(&mut self, i: u16) {
        self.mix(u64::from(i));
    }
    fn write_u32(&mut self, i: u32) {
        self.mix(u64::from(i));
    }
    fn write_u64(&mut self, i: u64) {
        self.mix(i);
    }
    fn write_usize(&mut self, i: usize) {
        self.mix(i as u64);
    }
    fn finish(&self) -> u64 {
        self.0
    }
}

type StateTable<S> = HashMap<S, usize, BuildHasherDefault<FastHasher>>;

/// One generated state in the search graph, with its best known path (parent link).
struct Node<S, O> {
    state: S,
    parent: usize,
    operator: Option<O>,
    g: Cost,
    h: Cost,
}

/// An open-list entry. Stale entries (whose `g` is worse than the node's) are skipped when
/// popped: lazy deletion instead of decrease-key.
#[derive(PartialEq, Eq)]
struct Open {
    f: Cost,
    g: Cost,
    seq: u64,
    node: usize,
}

impl Ord for Open {
    /// `BinaryHeap` pops the greatest: least `f` first, then greatest `g` (deeper first), then
    /// the earliest generated. Entirely deterministic.
    fn cmp(&self, other: &Self) -> Ordering {
        other.f.cmp(&self.f).then(self.g.cmp(&other.g)).then(other.seq.cmp(&self.seq))
    }
}
impl PartialOrd for Open {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

fn path_to<S: Clone, O: Clone>(nodes: &[Node<S, O>], mut index: usize) -> Plan<S, O> {
    let cost = nodes[index].g.get();
    let mut states = Vec::new();
    let mut operators = Vec::new();
    loop {
        let node = &nodes[index];
        states.push(node.state.clone());
        if let Some(op) = &node.operator {
            operators.push(op.clone());
        }
        if node.parent == NO_PARENT {
            break;
        }
        index = node.parent;
    }
    states.reverse();
    operators.reverse();
    Plan { states, operators, cost }
}

/// A* under a [`Deadline`]: deliberation that knows when it is late.
///
/// Preconditions: operator costs are non-negative (guaranteed by [`Cost`]) and the heuristic is
/// admissible; then [`SearchOutcome::Solved`] carries a least-cost plan. Inconsistent but
/// admissible heuristics are handled (closed states are reopened on a cheaper path).
/// The goal test is applied when a state is expanded, which is what makes the plan optimal.
///
/// The deadline is checked before every expansion (the clock every
/// [`CLOCK_CHECK_INTERVAL`] expansions); a deadline already past returns
/// [`SearchOutcome::OutOfTime`] with zero expansions. Ties are broken deterministically, so an
/// expansion-budget deadline gives the same outcome on every run.
pub fn solve<P: SearchProblem>(problem: &P, deadline: &Deadline) -> SearchReport<P::State, P::Operator> {
    let started = Instant::now();
    let mut stats = SearchStats::default();
    let watch_clock = deadline.has_clock();

    let finish = |outcome, mut stats: SearchStats| {
        let now = Instant::now();
        stats.elapsed = now.duration_since(started);
        if let SearchOutcome::OutOfTime { cause: Interrupt::WallClock, .. } = &outcome {
            stats.overshoot = deadline.instant().map(|at| now.saturating_duration_since(at));
        }
        SearchReport { outcome, stats }
    };

    if let Some(cause) = deadline.check(0, 0, true) {
        return finish(SearchOutcome::OutOfTime { best: None, cause }, stats);
    }

    let initial = problem.initial();
    let h0 = problem.heuristic(&initial);
    if h0 == f64::INFINITY {
        return finish(SearchOutcome::Infeasible, stats);
    }
    let h0 = Cost::from_estimate(h0);
    let mut nodes: Vec<Node<P::State, P::Operator>> = Vec::new();
    let mut table: StateTable<P::State> = StateTable::default();
    let mut open = BinaryHeap::new();
    let mut seq = 0u64;
    table.insert(initial.clone(), 0);
    nodes.push(Node { state: initial, parent: NO_PARENT, operator: None, g: Cost::ZERO, h: h0 });
    open.push(Open { f: h0, g: Cost::ZERO, seq, node: 0 });

    // The expanded node with least h (ties: the first such), for a partial plan when late.
    let mut best: Option<usize> = None;
    let mut out = Vec::new();

    while let Some(Open { g, node: index, .. }) = open.pop() {
        if g > nodes[index].g {
            continue; // stale entry: a cheaper path to this state was found after it was pushed
        }
        let read_clock = watch_clock && stats.expansions % CLOCK_CHECK_INTERVAL == 0;
        if let Some(cause) = deadline.check(stats.expansions, 0, read_clock) {
            let best_so_far =
                best.map(|b| PartialPlan { plan: path_to(&nodes, b), remaining_estimate: nodes[b].h.get() });
            return finish(SearchOutcome::OutOfTime { best: best_so_far, cause }, stats);
        }
        stats.expansions += 1;
        if problem.is_goal(&nodes[index].state) {
            let plan = path_to(&nodes, index);
            return finish(SearchOutcome::Solved(plan), stats);
        }
        if best.is_none_or(|b| nodes[index].h < nodes[b].h) {
            best = Some(index);
        }

        out.clear();
        problem.successors(&nodes[index].state, &mut out);
        stats.generated += out.len() as u64;
        for Successor { operator, state, cost } in out.drain(..) {
            let g_new = g + cost;
            let child = match table.entry(state) {
                Entry::Occupied(entry) => {
                    let child = *entry.get();
                    let node = &mut nodes[child];
                    if g_new >= node.g {
                        continue;
                    }
                    node.g = g_new;
                    node.parent = index;
                    node.operator = Some(operator);
                    child
                }
                Entry::Vacant(entry) => {
                    let h = problem.heuristic(entry.key());
                    if h == f64::INFINITY {
                        continue; // dead end: no goal reachable from here
                    }
                    let child = nodes.len();
                    let state = entry.key().clone();
                    entry.insert(child);
                    nodes.push(Node {
                        state,
                        parent: index,
                        operator: Some(operator),
                        g: g_new,
                        h: Cost::from_estimate(h),
                    });
                    child
                }
            };
            seq += 1;
            open.push(Open { f: g_new + nodes[child].h, g: g_new, seq, node: child });
        }
    }
    finish(SearchOutcome::Infeasible, stats)
}

/// The reference solver: the `pathfinding` crate's A* on the same problem, no deadline.
///
/// Returns `None` when no goal is reachable. The operators of the plan are recovered by
/// re-applying the operators along the path (the cheapest one leading to the next state).
pub fn solve_astar<P: SearchProblem>(problem: &P) -> Option<Plan<P::State, P::Operator>> {
    let mut out = Vec::new();
    let (states, cost) = pathfinding::directed::astar::astar(
        &problem.initial(),
        |state| {
            out.clear();
            problem.successors(state, &mut out);
            out.drain(..).map(|s| (s.state, s.cost)).collect::<Vec<_>>()
        },
        |state| {
            let h = problem.heuristic(state);
            if h == f64::INFINITY { Cost::INFINITY } else { Cost::from_estimate(h) }
        },
        |state| problem.is_goal(state),
    )?;
    let mut operators = Vec::with_capacity(states.len().saturating_sub(1));
    for pair in states.windows(2) {
        let mut succ = Vec::new();
        problem.successors(&pair[0], &mut succ);
        let op = succ.into_iter().filter(|s| s.state == pair[1]).min_by(|a, b| a.cost.cmp(&b.cost))?;
        operators.push(op.operator);
    }
    Some(Plan { states, operators, cost: cost.get() })
}

pub mod grid {
    //! A large golden search problem: an 8-connected grid with random obstacles, used by the
    //! benchmarks and by [`super::deadline_overshoot_samples`].

    use super::{Cost, SearchProblem, Successor};

    /// A cell `(x, y)`.
    pub type Cell = (u32, u32);

    /// An 8-connected occupancy grid; straight moves cost 1, diagonal moves `sqrt(2)`
    /// (no corner cutting past obstacles). The heuristic is the octile distance (consistent).
    #[derive(Debug, Clone)]
    pub struct GridWorld {
        width: u32,
        height: u32,
        blocked: Vec<bool>,
        start: Cell,
        goal: Cell,
    }

    impl GridWorld {
        /// A `width x height` grid (each at least 1) with each cell blocked with probability
        /// `density` (a seeded, platform-independent generator), start at `(0, 0)` and goal at
        /// the opposite corner, both kept free.
        pub fn random(width: u32, height: u32, density: f64, seed: u64) -> Self {
            let (width, height) = (width.max(1), height.max(1));
            let mut rng = seed ^ 0x9e37_79b9_7f4a_7c15;
            let mut next = || {
                // splitmix64
                rng = rng.wrapping_add(0x9e37_79b9_7f4a_7c15);
                let mut z = rng;
                z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
                z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
                z ^ (z >> 31)
            };
            let cells = width as usize * height as usize;
            let blocked = (0..cells).map(|_| ((next() >> 11) as f64 / (1u64 << 53) as f64) < density).collect();
            let mut grid = GridWorld { width, height, blocked, start: (0, 0), goal: (width - 1, height - 1) };
            let (s, g) = (grid.index(grid.start), grid.index(grid.goal));
            grid.blocked[s] = false;
            grid.blocked[g] = false;
            grid
        }

        /// Moves the goal (kept free).
        pub fn with_goal(mut self, goal: Cell) -> Self {
            let goal = (goal.0.min(self.width - 1), goal.1.min(self.height - 1));
            self.goal = goal;
            let i = self.index(goal);
            self.blocked[i] = false;
            self
        }

        /// Walls off the goal completely (its 8 neighbours blocked): an infeasible instance
        /// that makes the search explore the whole reachable grid.
        pub fn with_goal_walled_off(mut self) -> Self {
            let (gx, gy) = (i64::from(self.goal.0), i64::from(self.goal.1));
            for dx in -1..=1i64 {
                for dy in -1..=1i64 {
                    let (x, y) = (gx + dx, gy + dy);
                    if (dx, dy) != (0, 0) && self.inside(x, y) {
                        let i = self.index((x as u32, y as u32));
                        self.blocked[i] = true;
                    }
                }
            }
            self
        }

        fn inside(&self, x: i64, y: i64) -> bool {
            x >= 0 && y >= 0 && x < i64::from(self.width) && y < i64::from(self.height)
        }

        fn index(&self, (x, y): Cell) -> usize {
            y as usize * self.width as usize + x as usize
        }

        fn free(&self, x: i64, y: i64) -> bool {
            self.inside(x, y) && !self.blocked[self.index((x as u32, y as u32))]
        }
    }

    impl SearchProblem for GridWorld {
        type State = Cell;
        type Operator = ();

        fn initial(&self) -> Cell {
            self.start
        }

        fn successors(&self, &(x, y): &Cell, out: &mut Vec<Successor<Cell, ()>>) {
            const DIAGONAL: Cost = Cost(std::f64::consts::SQRT_2);
            let (x, y) = (i64::from(x), i64::from(y));
            for (dx, dy) in [(1, 0), (0, 1), (-1, 0), (0, -1), (1, 1), (-1, 1), (-1, -1), (1, -1)] {
                let (nx, ny) = (x + dx, y + dy);
                if !self.free(nx, ny) {
                    continue;
                }
                let diagonal = dx != 0 && dy != 0;
                if diagonal && !(self.free(x + dx, y) && self.free(x, y + dy)) {
                    continue;
                }
                let cost = if diagonal { DIAGONAL } else { Cost::ONE };
                out.push(Successor { operator: (), state: (nx as u32, ny as u32), cost });
            }
        }

        fn is_goal(&self, state: &Cell) -> bool {
            *state == self.goal
        }

        fn heuristic(&self, &(x, y): &Cell) -> f64 {
            let dx = f64::from(x.abs_diff(self.goal.0));
            let dy = f64::from(y.abs_diff(self.goal.1));
            let (lo, hi) = if dx < dy { (dx, dy) } else { (dy, dx) };
            // Slightly shrunk so that rounding never makes it inadmissible.
            (hi + (std::f64::consts::SQRT_2 - 1.0) * lo) * (1.0 - 1e-12)
        }
    }
}

/// Deadline overshoot: for each of `n` runs of [`solve`] on a 2000x2000 grid (20% obstacles)
/// with a wall-clock deadline `deadline` from the call, how long after that instant `solve` had
/// returned (measured by the caller, so dropping the search structures is included).
/// Runs whose search finishes before the deadline are not counted (shorten `deadline` if so).
pub fn deadline_overshoot_samples(n: usize, deadline: Duration) -> Vec<Duration> {
    let world = grid::GridWorld::random(2000, 2000, 0.2, 7).with_goal_walled_off();
    (0..n)
        .filter_map(|_| {
            let limit = Deadline::after(deadline);
            let at = limit.instant()?;
            let report = solve(&world, &limit);
            let returned = Instant::now();
            report.outcome.is_out_of_time().then(|| returned.saturating_duration_since(at))
        })
        .collect()
}
