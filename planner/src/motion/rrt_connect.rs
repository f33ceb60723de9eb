//! Bidirectional RRT-Connect (Kuffner and LaValle, 2000): one tree grows from the start, one
//! from every goal at once; each iteration extends one tree a step towards a random sample and
//! lets the other tree run straight at the new node; the trees swap roles every iteration.
//!
//! Lazy (the default with certified edges): a new tree edge is only probed
//! ([`Validity::segment_probed`]), and certified when it lies on a path that joins the trees.
//! Most edges never do, and certificates of free edges are what eager RRT-Connect spent its
//! collision checks on (on the MotionBenchMaker UR5 problems, 85% of the search's checks: 32 per
//! passing edge against 2 per failing one). An edge whose certificate fails is cut off with its
//! subtree and the search goes on, so every returned path is certified.

use embodied_models::{ConfigSpace, Rng, wrap_angle};

use super::MotionSettings;
use super::buckets::{APPROX, Buckets};
use super::sampler::Draw;
use super::shortcut::{OutOfTime, farthest_visible};
use crate::deadline::Budget;
use crate::outcome::{MotionStats, Outcome};
use crate::validity::{StateValidity, Validity};

/// Dynamic domain (Yershova, Jaillet, Simeon, LaValle, ICRA 2005): the radius a node gets
/// when an extension from it first fails (rad, C-space distance).
const DD_RADIUS: f64 = 4.0;
/// Dynamic domain: the smallest radius.
const DD_MIN_RADIUS: f64 = 1.0;
/// Dynamic domain: a node's radius grows by this fraction when an extension from it succeeds
/// and shrinks by it when one fails again.
const DD_ALPHA: f64 = 1e-4;

/// Extensions from a root found trapped, while its tree is still its roots alone, before the
/// tree steps from its roots at [`STUCK_ROOT_STEP`] of the range (see [`step_from`]).
const STUCK_ROOT_TRAPS: u32 = 512;
/// The share of the range a tree still stuck at its roots steps by (see [`step_from`]).
const STUCK_ROOT_STEP: f64 = 0.3;

/// The largest step of an extension from node `node` of a tree of `len` nodes whose first
/// `roots` are its roots (the start, or the goals), `trapped` the extensions from that node
/// found trapped so far: `range`, or [`STUCK_ROOT_STEP`] of it from a root trapped
/// [`STUCK_ROOT_TRAPS`] times while the tree is still its roots alone.
///
/// A goal in a pocket (deep in a shelf, where every step of up to a radian is blocked) leaves
/// its tree the goal alone while thousands of extensions from it fail, and balance gives that
/// tree every sample; shorter steps find the way out. A tree that has grown at all keeps the
/// range: shorter steps everywhere cost far more than they save (on VAMP's spherized Fetch
/// problems, a node's steps halved after each trap: 3.4 times the time; after 256 traps in
/// trees under 16 nodes: narrow passages between grown trees lost, see `docs/benchmarks.md`).
/// On all 700 of VAMP's Fetch problems, three seeds: 255 of 2,037 runs changed, all on the
/// bookshelves, their collision checks 25.8 M -> 14.6 M, samples 6.7 M -> 3.1 M, restarts
/// 114 -> 45, the slowest run 935 -> 319 ms (per run a geometric mean of 0.98); the first 30
/// problems of each family of the UR5, the Panda and the Baxter: 2, 0 and 12 of 630, 630 and
/// 270 runs changed.
fn step_from(range: f64, len: usize, roots: usize, node: usize, trapped: u32) -> f64 {
    if len <= roots && node < roots && trapped >= STUCK_ROOT_TRAPS { range * STUCK_ROOT_STEP } else { range }
}

/// A tree of configurations stored flat (`dof` values per node), with parent links, and the
/// index its nearest-neighbour queries run on.
///
/// The nodes are kept again in blocks of [`BLOCK`] joint by joint, a wrapping joint's value
/// brought into [-pi, pi): below [`SCAN_BELOW`] nodes a query scans them all, four at a time
/// (exactly: the least distance, ties to the lowest index); from there a k-d tree of buckets
/// ([`Buckets`]) answers for the nodes it was built over, within `1 + ε` of the nearest
/// distance (`buckets::APPROX`), deterministically, and the nodes added since are scanned.
/// Wrapping joints take the shorter way round in the scans and in the buckets' bounds. The
/// k-d tree of nodes this replaced for robots with a wrapping joint spent 77% of the planning
/// instructions on the Fetch's first 10 MotionBenchMaker cage problems with its three roll
/// joints made continuous (12.67 G), most of them in `fmod` (`wrap_angle` of every difference).
struct Tree {
    dof: usize,
    coords: Vec<f64>,
    parent: Vec<u32>,
    /// The edge to the parent is certified (lazy: only probed until it lies on a path).
    certified: Vec<bool>,
    /// False for nodes cut off by an edge whose certificate failed, and their descendants.
    alive: Vec<bool>,
    /// The living nodes again, in blocks of [`BLOCK`] nodes joint by joint (block `b`, joint
    /// `j` at `b * dof + j`), a wrapping joint's value as its angle in [-pi, pi), for the scan
    /// and the buckets; a lane past the last node or of a cut node holds infinity, so no
    /// distance to it is ever below another.
    blocks: Vec<[f64; BLOCK]>,
    /// Per joint, its period: `TAU` where it wraps, infinity where not (empty when none wraps:
    /// see [`Tree::any_wrap`]).
    period: Vec<f64>,
    /// A query's values, wrapping joints brought into [-pi, pi).
    query: Vec<f64>,
    /// Dynamic domain: samples farther than this from the node are not extended from it
    /// (infinite until an extension from the node fails).
    radius: Vec<f64>,
    /// Extensions from each node found trapped (see [`step_from`]).
    trapped: Vec<u32>,
    /// The k-d tree of buckets answering from [`SCAN_BELOW`] nodes; `None` when the tree
    /// answers by a plain scan of its nodes (the tests' reference).
    buckets: Option<Buckets>,
}

/// Trees with fewer nodes than this answer nearest-neighbour queries by a scan of every node,
/// the k-d tree of buckets above. RRT-Connect's trees stay small where dynamic
/// domain turns most samples away: on the 100 generated cage problems, 65 nodes in both trees
/// at the median when a path is found (219 at most), on the 296 public MotionBenchMaker UR5
/// problems 12 (107 at most), where a k-d tree's descent and bookkeeping cost more than the
/// distances they save. Planning instructions on 10 cage problems: 234.1 M with a k-d tree
/// throughout, 216.2 M scanning below 32 nodes, 207.4 M below 128 (and below 256, and always).
/// Measured again with the block scan ([`scan`]), in time: below 512 and 1,024 nodes, per-problem
/// ratios 0.992 and 1.009 on the cage problems against 128 (the slow problems' trees are larger,
/// and there the k-d tree wins). With a k-d tree rebuilt balanced as it doubles, planning
/// instructions on the first 30 MotionBenchMaker cage problems: Panda 254.5 M below 64 nodes,
/// 231.2 M below 128, 225.2 M below 256; UR5 84.2 / 84.0 / 84.0 M.
const SCAN_BELOW: usize = 256;

/// Nodes per block of [`Tree::blocks`].
pub(crate) const BLOCK: usize = 4;

/// The living node of `blocks` (see [`Tree::blocks`]; `q.len()` joints) nearest to `q` as
/// (squared distance, index), ties to the lowest index: exactly [`Buckets::nearest`]'s answer
/// with no approximation (the same sums, in the same order, and the same tie rule). `DOF`, when
/// not 0, is `q.len()`; `q` is not empty (a tree over no joints has no index and never comes
/// here). With `WRAP`, each joint's difference `d` is taken the shorter way round its
/// `period` (`q` and the blocks hold wrapping joints' values in [-pi, pi)): `min(|d|, period -
/// |d|)`, which is `|d|` where the period is infinite; without, `period` is not read.
///
/// Block by block with no branch per node or block: the four distances at once (each lane's
/// sum in joint order, a multiply and an add, never fused, so the scalar sum to the bit), each
/// lane keeping its own best (see [`scan_lanes`]). The scan over node rows it replaces stopped
/// each sum as soon as it passed the best, one unpredictable branch per joint and node: the 98
/// cage problems that solve spent 23% of their planning time in it. Compiled
/// for AVX2 where the CPU has it (pulp's run-time dispatch, as the collision batch): one
/// 256-bit operation per step instead of two SSE2 ones, the 10 cage problems' nearest-neighbour
/// instructions 15.5 M -> 8.1 M (`wide`'s four lanes in the AVX2 function: 10.9 M; on the
/// baseline these plain arrays and `wide` cost the same).
fn scan<const DOF: usize, const WRAP: bool>(blocks: &[[f64; BLOCK]], q: &[f64], period: &[f64]) -> (f64, usize) {
    #[cfg(target_arch = "x86_64")]
    if let Some(v3) = pulp::x86::V3::try_new() {
        return pulp::Simd::vectorize(v3, ScanV3::<DOF, WRAP> { blocks, q, period });
    }
    scan_lanes::<DOF, WRAP>(blocks, q, period)
}

/// [`scan_lanes`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
struct ScanV3<'a, const DOF: usize, const WRAP: bool> {
    blocks: &'a [[f64; BLOCK]],
    q: &'a [f64],
    period: &'a [f64],
}

#[cfg(target_arch = "x86_64")]
impl<const DOF: usize, const WRAP: bool> pulp::WithSimd for ScanV3<'_, DOF, WRAP> {
    type Output = (f64, usize);
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> (f64, usize) {
        scan_lanes::<DOF, WRAP>(self.blocks, self.q, self.period)
    }
}

/// The squared difference of a joint whose values (in [-pi, pi) where it wraps) are `q` and
/// `p`: with `WRAP`, the shorter way round `period` (infinite: the plain difference). A lane
/// of infinity gives infinity either way (`period - |d|` is then minus infinity or not a
/// number, and the comparison keeps `|d|` for the latter).
#[inline(always)]
pub(crate) fn gap2<const WRAP: bool>(q: f64, p: f64, period: f64) -> f64 {
    let d = q - p;
    if WRAP {
        let a = d.abs();
        let around = period - a;
        let w = if around < a { around } else { a };
        w * w
    } else {
        d * d
    }
}

/// A joint's value `x` as the blocks hold it: a wrapping joint's (finite `period`) as its
/// angle in [-pi, pi), another's as it is.
#[inline(always)]
fn block_value(x: f64, period: f64) -> f64 {
    if period.is_finite() { wrap_angle(x) } else { x }
}

/// [`scan`] on the instruction set of its caller. Each lane keeps its own best (distance and
/// block) with a strict `<`, so its earliest block among equals, without a branch; the four are
/// then reduced to the least distance, ties to the lowest node index.
#[inline(always)]
fn scan_lanes<const DOF: usize, const WRAP: bool>(blocks: &[[f64; BLOCK]], q: &[f64], period: &[f64]) -> (f64, usize) {
    let dof = if DOF == 0 { q.len() } else { DOF };
    let q = &q[..dof];
    let period = if WRAP { &period[..dof] } else { &[][..] };
    let mut best = [f64::INFINITY; BLOCK];
    let mut at = [0u64; BLOCK];
    for (b, block) in blocks.chunks_exact(dof).enumerate() {
        let mut s = [0.0f64; BLOCK];
        for (j, (&qj, lanes)) in q.iter().zip(block).enumerate() {
            let pj = if WRAP { period[j] } else { 0.0 };
            for (s, &p) in s.iter_mut().zip(lanes) {
                *s += gap2::<WRAP>(qj, p, pj);
            }
        }
        // A NaN lane is never below the best.
        for l in 0..BLOCK {
            let below = s[l] < best[l];
            best[l] = if below { s[l] } else { best[l] };
            at[l] = if below { b as u64 } else { at[l] };
        }
    }
    let mut out = (f64::INFINITY, 0);
    for l in 0..BLOCK {
        let i = at[l] as usize * BLOCK + l;
        if best[l] < out.0 || (best[l] == out.0 && i < out.1) {
            out = (best[l], i);
        }
    }
    out
}

const ROOT: u32 = u32::MAX;

impl Tree {
    /// An empty tree over `space`; with `indexed`, nearest-neighbour queries run on the blocks
    /// and, from [`SCAN_BELOW`] nodes, the buckets, within `1 + approx` of the nearest distance
    /// (0: exactly; see `buckets`), else on a plain scan of the nodes (the tests' reference).
    fn new(space: &ConfigSpace, indexed: bool, approx: f64) -> Self {
        let dof = space.dof();
        // Room for the nodes of most searches (trees hold a few dozen at the median).
        const NODES: usize = 64;
        let period: Vec<f64> = match (0..dof).any(|i| space.wraps(i)) {
            true => (0..dof).map(|i| if space.wraps(i) { std::f64::consts::TAU } else { f64::INFINITY }).collect(),
            false => Vec::new(),
        };
        Self {
            dof,
            coords: Vec::with_capacity(NODES * dof),
            parent: Vec::with_capacity(NODES),
            certified: Vec::with_capacity(NODES),
            alive: Vec::with_capacity(NODES),
            blocks: Vec::with_capacity(NODES / BLOCK * dof),
            period,
            query: Vec::new(),
            radius: Vec::with_capacity(NODES),
            trapped: Vec::with_capacity(NODES),
            buckets: (indexed && dof > 0).then(|| Buckets::new(dof, approx)),
        }
    }
    fn len(&self) -> usize {
        self.parent.len()
    }
    /// Some joint wraps.
    fn any_wrap(&self) -> bool {
        !self.period.is_empty()
    }
    fn node(&self, i: usize) -> &[f64] {
        &self.coords[i * self.dof..(i + 1) * self.dof]
    }
    fn push(&mut self, q: &[f64], parent: u32, certified: bool) -> usize {
        let i = self.len();
        self.coords.extend_from_slice(q);
        if i.is_multiple_of(BLOCK) {
            self.blocks.resize(self.blocks.len() + self.dof, [f64::INFINITY; BLOCK]);
        }
        let b = i / BLOCK * self.dof;
        if self.any_wrap() {
            for ((lanes, &x), &p) in self.blocks[b..b + self.dof].iter_mut().zip(q).zip(&self.period) {
                lanes[i % BLOCK] = block_value(x, p);
            }
        } else {
            for (lanes, &x) in self.blocks[b..b + self.dof].iter_mut().zip(q) {
                lanes[i % BLOCK] = x;
            }
        }
        self.parent.push(parent);
        self.certified.push(certified);
        self.alive.push(true);
        self.radius.push(f64::INFINITY);
        self.trapped.push(0);
        if let Some(b) = &mut self.buckets
            && i + 1 >= SCAN_BELOW
            && b.stale(i + 1)
        {
            b.rebuild(&self.blocks, &self.alive, i + 1);
        }
        i
    }
    /// Cut node `i` off with its descendants (children are pushed after their parents).
    fn cut(&mut self, i: usize) {
        self.hide(i);
        for k in i + 1..self.len() {
            let p = self.parent[k];
            if p != ROOT && !self.alive[p as usize] {
                self.hide(k);
            }
        }
    }
    /// Node `k` is no longer alive: its lanes of the scan's blocks hold infinity.
    fn hide(&mut self, k: usize) {
        self.alive[k] = false;
        if let Some(b) = &mut self.buckets {
            b.hide(k);
        }
        let b = k / BLOCK * self.dof;
        for lanes in &mut self.blocks[b..b + self.dof] {
            lanes[k % BLOCK] = f64::INFINITY;
        }
    }
    /// The living node nearest to `q`.
    fn nearest(&mut self, space: &ConfigSpace, q: &[f64]) -> usize {
        self.nearest_with_distance(space, q).1
    }
    /// The living node nearest to `q` as (squared distance, index); ties go to the lowest
    /// index. From [`SCAN_BELOW`] nodes, within the tree's approximation.
    fn nearest_with_distance(&mut self, space: &ConfigSpace, q: &[f64]) -> (f64, usize) {
        if self.buckets.is_none() {
            let mut best = (f64::INFINITY, 0);
            for i in 0..self.len() {
                if !self.alive[i] {
                    continue;
                }
                let d = space.distance_squared(self.node(i), q);
                if d < best.0 {
                    best = (d, i);
                }
            }
            return best;
        }
        match (q.len(), self.any_wrap()) {
            (6, false) => self.nearest_indexed::<6, false>(q),
            (7, false) => self.nearest_indexed::<7, false>(q),
            (8, false) => self.nearest_indexed::<8, false>(q),
            (12, false) => self.nearest_indexed::<12, false>(q),
            (14, false) => self.nearest_indexed::<14, false>(q),
            (_, false) => self.nearest_indexed::<0, false>(q),
            (6, true) => self.nearest_indexed::<6, true>(q),
            (7, true) => self.nearest_indexed::<7, true>(q),
            (8, true) => self.nearest_indexed::<8, true>(q),
            (_, true) => self.nearest_indexed::<0, true>(q),
        }
    }
    /// [`Self::nearest_with_distance`] on the blocks: the nodes added since the buckets were
    /// built by the block scan (every node while the tree has fewer than [`SCAN_BELOW`]), then
    /// the buckets, which answer a node as near only when its index is lower.
    fn nearest_indexed<const DOF: usize, const WRAP: bool>(&mut self, q: &[f64]) -> (f64, usize) {
        let Some(b) = &mut self.buckets else { return (f64::INFINITY, 0) };
        let q = if WRAP {
            self.query.clear();
            self.query.extend(q.iter().zip(&self.period).map(|(&x, &p)| block_value(x, p)));
            &self.query[..]
        } else {
            q
        };
        let (d, i) = scan::<DOF, WRAP>(&self.blocks[b.built / BLOCK * self.dof..], q, &self.period);
        let best = b.nearest::<DOF, WRAP>(q, (d, i + b.built), &self.period);
        // The scan's answer when no living node is nearer than infinity.
        if best.0 == f64::INFINITY { (f64::INFINITY, 0) } else { best }
    }
    /// Root-to-node node indices.
    fn chain_to(&self, i: usize) -> Vec<usize> {
        // Counted first, then written from the end: one allocation of the right size.
        let up = |i: usize| (self.parent[i] != ROOT).then(|| self.parent[i] as usize);
        let depth = std::iter::successors(Some(i), |&j| up(j)).count();
        let mut out = vec![0; depth];
        for (slot, node) in out.iter_mut().rev().zip(std::iter::successors(Some(i), |&j| up(j))) {
            *slot = node;
        }
        out
    }
}

enum Step {
    /// Reached the target exactly (node index).
    Reached(usize),
    /// Moved towards the target (node index).
    Advanced(usize),
    Trapped,
}

/// One extension of `tree` from its node nearest to `target` by at most `range`. `lazy`: the
/// new edge is probed at this joint step instead of certified; `target_checked`: `target` is
/// known to be free (a tree node).
#[allow(clippy::too_many_arguments)]
fn extend<V: StateValidity>(
    tree: &mut Tree,
    validity: &mut Validity<'_, V>,
    target: &[f64],
    range: f64,
    from: Option<usize>,
    buf: &mut Vec<f64>,
    lazy: Option<f64>,
    target_checked: bool,
) -> Step {
    let near = from.unwrap_or_else(|| tree.nearest(&validity.space, target));
    let d = validity.space.distance(tree.node(near), target);
    let reached = d <= range;
    buf.clear();
    buf.resize(tree.dof, 0.0);
    let t = if reached { 1.0 } else { range / d };
    validity.space.interpolate_into(tree.node(near), target, t, buf);
    let q_near = tree.node(near);
    match lazy {
        Some(step) => {
            // The end (unless it is the checked target; the certificate covers its ends, a
            // probe does not), then the probe.
            let check_end = !reached || !target_checked;
            if !validity.segment_probed(q_near, buf, step, check_end) {
                return Step::Trapped;
            }
        }
        None => {
            if !reached && !validity.config_free(buf) {
                return Step::Trapped;
            }
            if !validity.segment_free(q_near, buf) {
                return Step::Trapped;
            }
        }
    }
    let i = tree.push(buf, near as u32, lazy.is_none());
    if reached { Step::Reached(i) } else { Step::Advanced(i) }
}

/// Plan from `start` to any of `goals` (all valid). The path runs start -> goal. `lazy`: probe
/// tree edges at `settings.lazy_probe` and certify them once on a path, there with the greedy
/// shortcut pass when `settings.shortcut`. With `moving`, only the degrees of freedom `d` with
/// `moving[d]` are drawn: the others keep `start`'s values in every sample (the goals must
/// have them too), so the trees grow in that subspace.
#[allow(clippy::too_many_arguments)]
pub(crate) fn plan<V: StateValidity>(
    validity: &mut Validity<'_, V>,
    budget: &mut Budget<'_>,
    rng: &mut Rng,
    start: &[f64],
    goals: &[Vec<f64>],
    settings: &MotionSettings,
    (lazy, moving): (bool, Option<&[bool]>),
    stats: &mut MotionStats,
) -> Outcome<Vec<Vec<f64>>, ()> {
    let robot = validity.model.robot();
    let dof = robot.dof();
    let range = if settings.rrt_range.is_finite() && settings.rrt_range > 0.0 { settings.rrt_range } else { 1.0 };
    let mut from_start = Tree::new(&validity.space, true, APPROX);
    from_start.push(start, ROOT, true);
    let mut from_goal = Tree::new(&validity.space, true, APPROX);
    for g in goals {
        from_goal.push(g, ROOT, true);
    }
    let probe = lazy.then_some(settings.lazy_probe);
    let mut draw = Draw::new(settings.sampler, robot, rng);
    if let Some(moving) = moving {
        // The others keep `start`'s values in every sample, and take no random draws.
        draw.hold(moving, start);
    }
    let mut sample = vec![0.0; dof];
    let mut buf = Vec::with_capacity(dof);
    let mut connect_buf = Vec::with_capacity(dof);
    let mut target = Vec::with_capacity(dof);
    let mut start_is_a = true;
    // This attempt's samples (a restart begins again at zero; see `MotionSettings::rrt_restarts`).
    let first_sample = stats.samples;
    let share = |p: f64| if p.is_finite() { p.clamp(0.0, 1.0) } else { 0.0 };
    let (early_bias, late_bias) = (share(settings.rrt_local_bias), share(settings.rrt_late_local_bias));
    let local_span = if settings.rrt_local_span.is_finite() { settings.rrt_local_span.max(0.0) } else { 0.0 };
    let local_reach = if settings.rrt_local_reach.is_nan() { f64::INFINITY } else { settings.rrt_local_reach.max(0.0) };
    loop {
        if settings.rrt_goal_retreat && stats.samples - first_sample == settings.rrt_late_after {
            goal_retreats(robot, moving, &mut from_goal, goals.len(), validity, probe);
        }
        if stats.samples - first_sample >= settings.max_samples {
            return Outcome::Infeasible;
        }
        if budget.spend(1, validity.collision_checks) {
            return Outcome::OutOfTime { best: None, cause: budget.cause() };
        }
        stats.samples += 1;
        let (a, b) = if start_is_a { (&mut from_start, &mut from_goal) } else { (&mut from_goal, &mut from_start) };
        // Near a node of the tree about to grow, or over the whole box: with the late share once
        // this attempt has drawn `rrt_late_after` samples.
        let local_bias = if stats.samples - first_sample > settings.rrt_late_after { late_bias } else { early_bias };
        let near_node = (local_bias > 0.0 && rng.uniform() < local_bias).then(|| rng.below(a.len()));
        match near_node {
            Some(k) if a.alive[k] => draw.near_into(robot, rng, a.node(k), (local_span, local_reach), &mut sample),
            _ => draw.next_into(robot, rng, &mut sample),
        }
        let mut new = None;
        // Dynamic domain: a sample outside the nearest node's radius is not extended towards.
        let near = if settings.rrt_dynamic_domain {
            let (d2, near) = a.nearest_with_distance(&validity.space, &sample);
            (d2.sqrt() <= a.radius[near]).then_some(near)
        } else {
            Some(a.nearest(&validity.space, &sample))
        };
        if let Some(near) = near {
            let a_roots = if start_is_a { 1 } else { goals.len() };
            let step = step_from(range, a.len(), a_roots, near, a.trapped[near]);
            match extend(a, validity, &sample, step, Some(near), &mut buf, probe, false) {
                Step::Trapped => {
                    a.trapped[near] = a.trapped[near].saturating_add(1);
                    if settings.rrt_dynamic_domain {
                        let r = &mut a.radius[near];
                        *r = if r.is_finite() { (*r * (1.0 - DD_ALPHA)).max(DD_MIN_RADIUS) } else { DD_RADIUS };
                    }
                }
                Step::Reached(i) | Step::Advanced(i) => {
                    if settings.rrt_dynamic_domain && a.radius[near].is_finite() {
                        a.radius[near] *= 1.0 + DD_ALPHA;
                    }
                    new = Some(i);
                }
            }
        }
        if let Some(new) = new {
            target.clear();
            target.extend_from_slice(a.node(new));
            // Connect: b runs straight at the new node until it gets there or is blocked (from
            // a tree stuck at its roots, by the shorter step).
            let b_roots = if start_is_a { goals.len() } else { 1 };
            let mut from = None;
            loop {
                let roots = 0..b_roots.min(b.len());
                let b_step = roots.map(|r| step_from(range, b.len(), b_roots, r, b.trapped[r])).fold(range, f64::min);
                match extend(b, validity, &target, b_step, from, &mut connect_buf, probe, true) {
                    Step::Reached(j) => {
                        let (si, gi) = if start_is_a { (new, j) } else { (j, new) };
                        // Path nodes as (in the start tree, index). The meeting configuration
                        // ends one half and starts the other: the start tree's copy stays.
                        let mut refs: Vec<(bool, usize)> =
                            from_start.chain_to(si).into_iter().map(|k| (true, k)).collect();
                        let mut tail = from_goal.chain_to(gi);
                        tail.reverse();
                        refs.extend(tail.into_iter().skip(1).map(|k| (false, k)));
                        let path: Vec<Vec<f64>> = refs
                            .iter()
                            .map(|&(s, k)| if s { from_start.node(k) } else { from_goal.node(k) }.to_vec())
                            .collect();
                        if !lazy {
                            return Outcome::Solved(path);
                        }
                        // The tree edge (in the start tree, child node) behind path edge `e`.
                        let edge = |e: usize| -> (bool, usize) {
                            match (refs[e], refs[e + 1]) {
                                (_, (true, child)) => (true, child),
                                ((false, child), _) => (false, child),
                                ((true, _), (false, _)) => (false, gi),
                            }
                        };
                        let mut certified: Vec<bool> = (0..path.len() - 1)
                            .map(|e| match edge(e) {
                                (true, k) => from_start.certified[k],
                                (false, k) => from_goal.certified[k],
                            })
                            .collect();
                        // A path to certify: no other racer is handed over meanwhile (held
                        // again from here on once it is certified, while it is shortened).
                        budget.hold_hand_over(true);
                        let outcome = certify_path(path, &mut certified, validity, budget, settings.shortcut);
                        for (e, &c) in certified.iter().enumerate() {
                            match edge(e) {
                                (true, k) => from_start.certified[k] |= c,
                                (false, k) => from_goal.certified[k] |= c,
                            }
                        }
                        match outcome {
                            Certified::Path(p) => return Outcome::Solved(p),
                            Certified::OutOfTime => return Outcome::OutOfTime { best: None, cause: budget.cause() },
                            Certified::Blocked(e) => {
                                budget.hold_hand_over(false);
                                stats.cut_edges += 1;
                                match edge(e) {
                                    (true, k) => from_start.cut(k),
                                    (false, k) => from_goal.cut(k),
                                }
                                break;
                            }
                        }
                    }
                    Step::Advanced(j) => from = Some(j),
                    Step::Trapped => break,
                }
                if budget.spend(1, validity.collision_checks) {
                    return Outcome::OutOfTime { best: None, cause: budget.cause() };
                }
            }
        }
        // Balanced trees: the smaller tree keeps growing while the other has twice its nodes.
        let (a_len, b_len) =
            if start_is_a { (from_start.len(), from_goal.len()) } else { (from_goal.len(), from_start.len()) };
        if !settings.rrt_balance || b_len < 2 * a_len {
            start_is_a = !start_is_a;
        }
    }
}

/// Length of a goal retreat's step, m (see [`MotionSettings::rrt_goal_retreat`]). 2 cm steps
/// (8 of them) and 5 cm (10) compared on the Fetch's cage and bookshelves: 0.80 and 0.84 of
/// the collision checks with chains kept however short.
pub(crate) const RETREAT_STEP: f64 = 0.03;

/// Nodes of a goal retreat's chain; a chain blocked before this many is left out.
pub(crate) const RETREAT_STEPS: usize = 8;

/// The links of a goal retreat: the hand, the leaf link moved by the most searched joints (those
/// `d` with `moving[d]`, every joint without `moving`; the last of equals), and the anchor it is
/// pulled towards, the child link of the first joint with a degree of freedom on its chain.
/// `None` when no searched joint moves a leaf link.
fn retreat_links(robot: &embodied_models::Robot, moving: Option<&[bool]>) -> Option<(usize, usize)> {
    let n = robot.links().len();
    let mut has_child = vec![false; n];
    for j in robot.joints() {
        if let Some(h) = has_child.get_mut(j.parent_link) {
            *h = true;
        }
    }
    let searched = |d: usize| moving.is_none_or(|m| m.get(d).copied().unwrap_or(false));
    let count = |l: usize| robot.dofs_moving(l).iter().enumerate().filter(|&(d, &m)| m && searched(d)).count();
    let hand = (0..n).filter(|&l| !has_child[l]).max_by_key(|&l| count(l))?;
    if count(hand) == 0 {
        return None;
    }
    let joints = robot.joints();
    let anchor = robot.chain_to(hand).into_iter().find(|&ji| joints[ji].dof_index.is_some())?;
    Some((hand, joints[anchor].child_link))
}

/// [`MotionSettings::rrt_goal_retreat`]: to each of the first `roots` nodes of `tree` (the goals),
/// a chain of [`RETREAT_STEPS`] nodes moving the hand [`RETREAT_STEP`] a node towards the first
/// joint of its chain, its orientation held: each step `J^T (J J^T + λ I)^{-1} (v, 0)` for the
/// hand's linear step `v` and no turn (the joints not searched, `moving[d]` false, held), clamped
/// to the position limits, each edge probed at `probe` (or certified when `None`), as the tree's
/// own edges are. A chain blocked before its last node adds nothing. No robot with a moving leaf
/// link, nothing.
fn goal_retreats<V: StateValidity>(
    robot: &embodied_models::Robot,
    moving: Option<&[bool]>,
    tree: &mut Tree,
    roots: usize,
    validity: &mut Validity<'_, V>,
    probe: Option<f64>,
) {
    let Some((hand, anchor)) = retreat_links(robot, moving) else { return };
    let searched = |d: usize| moving.is_none_or(|m| m.get(d).copied().unwrap_or(false));
    let n = robot.links().len();
    let dof = robot.dof();
    let mut poses = vec![nalgebra::Isometry3::identity(); n];
    let mut chain: Vec<Vec<f64>> = Vec::with_capacity(RETREAT_STEPS);
    for root in 0..roots.min(tree.len()) {
        if !tree.alive[root] {
            continue;
        }
        chain.clear();
        let mut q = tree.node(root).to_vec();
        for _ in 0..RETREAT_STEPS {
            robot.forward_kinematics_into(&q, &mut poses);
            let towards = poses[anchor].translation.vector - poses[hand].translation.vector;
            let norm = towards.norm();
            if norm.is_nan() || norm <= 1e-9 {
                break;
            }
            let v = towards * (RETREAT_STEP / norm);
            let mut jac = robot.jacobian_with_poses(&poses, hand, &nalgebra::Isometry3::identity());
            for d in (0..dof).filter(|&d| !searched(d)) {
                jac.column_mut(d).fill(0.0);
            }
            let jjt = &jac * jac.transpose() + nalgebra::Matrix6::identity() * 1e-4;
            let Some(y) = jjt.try_inverse().map(|m| m * nalgebra::Vector6::new(v.x, v.y, v.z, 0.0, 0.0, 0.0)) else {
                break;
            };
            let dq = jac.transpose() * y;
            let mut next = q.clone();
            for (d, x) in next.iter_mut().enumerate().filter(|&(d, _)| searched(d)) {
                *x += dq[d];
                let l = robot.dof_joint(d).limits;
                if l.is_bounded() {
                    *x = x.clamp(l.lower, l.upper);
                }
            }
            // A step that is not a number ends the chain before any check.
            if next.iter().any(|x| !x.is_finite()) {
                break;
            }
            let free = match probe {
                Some(step) => validity.segment_probed(&q, &next, step, true),
                None => validity.config_free(&next) && validity.segment_free(&q, &next),
            };
            if !free {
                break;
            }
            chain.push(next.clone());
            q = next;
        }
        if chain.len() == RETREAT_STEPS {
            let mut parent = root;
            for q in &chain {
                parent = tree.push(q, parent as u32, probe.is_none());
            }
        }
    }
}

/// What [`certify_path`] found.
pub(crate) enum Certified {
    /// The certified path (shortcut by the greedy pass if asked).
    Path(Vec<Vec<f64>>),
    /// Path edge `e` (`path[e]`-`path[e + 1]`) failed its certificate.
    Blocked(usize),
    OutOfTime,
}

/// Certify a path found by lazy RRT-Connect: each edge not yet certified (`certified[e]`; set
/// here for the edges that pass). With `greedy`, the greedy shortcut pass does it: from each
/// vertex, the farthest vertex whose straight segment certifies (tried farthest first: failing
/// certificates stop at their first hit and cost a few checks), then the edge to the next vertex
/// when none does; edges skipped are never certified. Unlike the eager greedy pass, there is
/// no cap on the path's length: skipping edges here saves their certificates.
pub(crate) fn certify_path<V: StateValidity>(
    path: Vec<Vec<f64>>,
    certified: &mut [bool],
    validity: &mut Validity<'_, V>,
    budget: &mut Budget<'_>,
    greedy: bool,
) -> Certified {
    let mut out = vec![path[0].clone()];
    let mut i = 0;
    while i + 1 < path.len() {
        let mut next = i + 1;
        if greedy {
            match farthest_visible(&path, i, validity, budget) {
                Ok(Some(j)) => next = j,
                Ok(None) => {}
                Err(OutOfTime) => return Certified::OutOfTime,
            }
        }
        if next == i + 1 && !certified[i] {
            if budget.spend(1, validity.collision_checks) {
                return Certified::OutOfTime;
            }
            if !validity.segment_free(&path[i], &path[i + 1]) {
                return Certified::Blocked(i);
            }
            certified[i] = true;
        }
        out.push(path[next].clone());
        i = next;
    }
    Certified::Path(out)
}

#[cfg(test)]
mod tests {
    use std::f64::consts::PI;

    use super::*;

    /// A goal retreat adds a chain of [`RETREAT_STEPS`] nodes to each goal,
    /// each a child of the one before and each moving the hand about [`RETREAT_STEP`] straight
    /// towards its anchor; a chain blocked on the way (a post between the hand and its anchor)
    /// adds nothing.
    #[test]
    fn goal_retreats_pull_the_hand_in_and_leave_out_blocked_chains() {
        use embodied_models::collision::{Environment, Obstacle};
        use embodied_models::{CollisionModel, Shape};
        let robot = embodied_models::builtin("polycrank").expect("robot");
        let (hand, anchor) = retreat_links(&robot, None).expect("a hand");
        let goal = vec![0.4, 0.7, -0.9, 0.5, 0.3, -0.2, 0.1];
        assert_eq!(goal.len(), robot.dof());
        let poses = robot.forward_kinematics(&goal);
        let (h, a) = (poses[hand].translation.vector, poses[anchor].translation.vector);
        assert!((a - h).norm() > 0.4, "the hand starts {} m from its anchor", (a - h).norm());
        let at = |q: &[f64]| {
            let p = robot.forward_kinematics(q);
            (p[hand].translation.vector, p[anchor].translation.vector)
        };
        // Nothing in the way: a whole chain.
        let free = CollisionModel::new(&robot, Environment::new());
        let mut validity = Validity::new(&free, 0.05);
        let mut free_tree = Tree::new(&validity.space, true, APPROX);
        free_tree.push(&goal, ROOT, true);
        goal_retreats(&robot, None, &mut free_tree, 1, &mut validity, Some(0.1));
        assert_eq!(free_tree.len(), 1 + RETREAT_STEPS);
        let tree = &free_tree;
        for k in 1..tree.len() {
            assert_eq!(tree.parent[k], k as u32 - 1);
            assert!(!tree.certified[k], "probed, not certified");
            // The hand's move: about a step long, along the line to the anchor (the first
            // order of a small step: within 20% in length, 20 degrees in direction).
            let ((h0, a0), (h1, _)) = (at(tree.node(k - 1)), at(tree.node(k)));
            let moved = h1 - h0;
            assert!((moved.norm() - RETREAT_STEP).abs() < 0.2 * RETREAT_STEP, "step {k}: {} m", moved.norm());
            let cos = moved.normalize().dot(&(a0 - h0).normalize());
            assert!(cos > 20f64.to_radians().cos(), "step {k}: {} degrees off", cos.acos().to_degrees());
        }
        // A small box where the hand would be after its fifth step (clear of the arm at the
        // goal): the chain is blocked there and left out.
        let (p5, _) = at(free_tree.node(5));
        let mut env = Environment::new();
        env.add(Obstacle::new(
            "box",
            nalgebra::Isometry3::translation(p5.x, p5.y, p5.z),
            Shape::cuboid(0.02, 0.02, 0.02),
        ));
        let blocked = CollisionModel::new(&robot, env);
        let mut validity = Validity::new(&blocked, 0.05);
        assert!(validity.config_free(&goal), "the goal itself is free");
        assert!(!validity.config_free(free_tree.node(5)), "the fifth node meets the box");
        let mut tree = Tree::new(&validity.space, true, APPROX);
        tree.push(&goal, ROOT, true);
        goal_retreats(&robot, None, &mut tree, 1, &mut validity, Some(0.1));
        assert_eq!(tree.len(), 1, "a blocked chain adds nothing");
        // No searched joint moves the hand: no chain.
        assert_eq!(retreat_links(&robot, Some(&vec![false; robot.dof()])), None);
    }

    #[test]
    fn cut_removes_a_subtree_from_nearest_and_keeps_the_rest() {
        for kd in [false, true] {
            let space = ConfigSpace::from_wraps(vec![false]);
            let mut t = Tree::new(&space, kd, 0.0);
            let root = t.push(&[0.0], ROOT, true);
            let a = t.push(&[1.0], root as u32, false);
            let b = t.push(&[-1.0], root as u32, false);
            let a1 = t.push(&[2.0], a as u32, false);
            let a2 = t.push(&[3.0], a1 as u32, false);
            let b1 = t.push(&[-2.0], b as u32, false);
            assert_eq!(t.nearest(&space, &[2.9]), a2);
            t.cut(a1);
            assert_eq!(t.alive, vec![true, true, true, false, false, true]);
            assert_eq!(t.nearest(&space, &[2.9]), a);
            assert_eq!(t.nearest(&space, &[-5.0]), b1);
            assert_eq!(t.chain_to(b1), vec![root, b, b1]);
        }
    }

    #[test]
    fn kd_tree_answers_exactly_what_the_scan_does() {
        // Six, seven, eight, twelve and fourteen joints run the unrolled searches, three and
        // nine the general one.
        for dof in [6, 7, 8, 12, 14, 3, 9] {
            kd_tree_matches_scan(vec![false; dof], 3.0);
        }
    }

    /// Over wrapping joints the blocks hold angles in [-pi, pi): the distances they sum differ
    /// from the reference's (`ConfigSpace::distance_squared` of the raw values) by roundings.
    #[test]
    fn kd_tree_over_wrapping_joints_answers_what_the_scan_does() {
        // Four of six joints wrap; the coordinates reach past +-2 pi (paths leave continuous
        // joints unwrapped), and points sit on and near the seam at +-pi. Seven joints run the
        // unrolled search.
        kd_tree_matches_scan(vec![true, false, true, true, false, true], 9.0);
        kd_tree_matches_scan(vec![true; 3], PI);
        kd_tree_matches_scan(vec![false, true, false, true, false, true, false], 7.0);
    }

    /// A tree rebuilt when most of its nodes are cut (they are left out) answers as the scan.
    #[test]
    fn kd_tree_rebuilt_over_cut_nodes_answers_what_the_scan_does() {
        let space = ConfigSpace::from_wraps(vec![false; 3]);
        let mut rng = Rng::new(3);
        let (mut scan, mut kd) = (Tree::new(&space, false, 0.0), Tree::new(&space, true, 0.0));
        let mut q = vec![0.0; 3];
        for i in 0..600usize {
            for v in q.iter_mut() {
                *v = rng.range(-3.0, 3.0);
            }
            let parent = if i == 0 || i == 200 { ROOT } else { i as u32 - 1 };
            scan.push(&q, parent, false);
            kd.push(&q, parent, false);
            // Everything so far (a chain from node 0) is cut; the buckets, first built at 256
            // nodes, take only the new chain from node 200.
            if i == 199 {
                scan.cut(0);
                kd.cut(0);
            }
            if i >= 150 {
                let query: Vec<f64> = (0..3).map(|_| rng.range(-4.0, 4.0)).collect();
                assert_eq!(
                    scan.nearest_with_distance(&space, &query),
                    kd.nearest_with_distance(&space, &query),
                    "after {i}"
                );
            }
        }
    }

    /// The planner's k-d trees (approximate): every answer is a living node at most `1 + ε`
    /// times as far as the nearest, the same node for the same query, and the exact answer
    /// below [`SCAN_BELOW`] nodes; some answers differ from the scan's (so the pruning is looser
    /// than the exact search's, else this test would not test it). Over plain joints and over
    /// wrapping ones (coordinates past +-pi as paths leave them; below [`SCAN_BELOW`] nodes
    /// their answers differ from the reference's by roundings only).
    #[test]
    fn approximate_trees_answer_within_their_factor_of_the_nearest() {
        let loose = (1.0 + APPROX) * (1.0 + APPROX);
        let cases = [vec![false; 3], vec![false; 7], vec![false; 8], vec![true, false, true, true, false, true]];
        for wraps in cases {
            let dof = wraps.len();
            let space = ConfigSpace::from_wraps(wraps);
            let mut rng = Rng::new(11);
            let (mut scan, mut approx) = (Tree::new(&space, false, 0.0), Tree::new(&space, true, APPROX));
            let mut q = vec![0.0; dof];
            let mut differ = 0;
            for i in 0..3000usize {
                // Chains of short steps from random nodes, as RRT-Connect grows its trees.
                let parent = if i == 0 { ROOT } else { rng.below(i) as u32 };
                if i > 0 && i % 3 != 0 {
                    for (v, &x) in q.iter_mut().zip(scan.node(parent as usize)) {
                        *v = x + rng.range(-0.3, 0.3);
                    }
                } else {
                    for v in q.iter_mut() {
                        *v = rng.range(-4.0, 4.0);
                    }
                }
                let victim = (i % 700 == 699).then(|| 1 + rng.below(i));
                grow_both([&mut scan, &mut approx], &q, parent, victim);
                for _ in 0..3 {
                    for v in q.iter_mut() {
                        *v = rng.range(-5.0, 5.0);
                    }
                    let exact = scan.nearest_with_distance(&space, &q);
                    let got = approx.nearest_with_distance(&space, &q);
                    assert!(approx.alive[got.1], "a cut node answered after {i} nodes");
                    let d = space.distance_squared(approx.node(got.1), &q);
                    assert!((got.0 - d).abs() <= 1e-12 * (1.0 + d), "{got:?}: {d}");
                    // Wrapped differences round differently from the reference's.
                    assert!(got.0 <= exact.0 * loose + 1e-12, "{got:?} against {exact:?} after {i} nodes");
                    assert_eq!(got, approx.nearest_with_distance(&space, &q), "the same query again");
                    if i + 1 < SCAN_BELOW && !approx.any_wrap() {
                        assert_eq!(got, exact, "scanned trees answer exactly");
                    }
                    differ += usize::from(got != exact);
                }
            }
            assert!(differ > 0, "{dof} joints: no answer differed from the exact one");
        }
    }

    #[test]
    fn only_a_tree_stuck_at_its_roots_steps_shorter() {
        let t = STUCK_ROOT_TRAPS;
        let short = 1.0 * STUCK_ROOT_STEP;
        // A lone root trapped often enough: the shorter step; a hair less: the range.
        assert_eq!(step_from(1.0, 1, 1, 0, t), short);
        assert_eq!(step_from(1.0, 1, 1, 0, t - 1), 1.0);
        // Two goals, the tree still the two: each root by its own count.
        assert_eq!(step_from(1.0, 2, 2, 1, t), short);
        assert_eq!(step_from(1.0, 2, 2, 0, 0), 1.0);
        // A tree that has grown, or a node that is not a root: the range, however trapped.
        assert_eq!(step_from(1.0, 2, 1, 0, u32::MAX), 1.0);
        assert_eq!(step_from(1.0, 3, 2, 2, u32::MAX), 1.0);
        const { assert!(STUCK_ROOT_STEP > 0.0 && STUCK_ROOT_STEP < 1.0) };
    }

    /// Node `q` (child of `parent`) added to both trees, then node `victim` cut from both.
    fn grow_both(trees: [&mut Tree; 2], q: &[f64], parent: u32, victim: Option<usize>) {
        for t in trees {
            t.push(q, parent, false);
            if let Some(v) = victim {
                t.cut(v);
            }
        }
    }

    /// Random trees (clustered, collinear, duplicate and seam points; cut subtrees): the k-d
    /// tree and the block scan give the scan's (distance, index) for every query; where a
    /// joint wraps, its distance within rounding (and a node at that distance), and exactly
    /// the block scan's answer.
    fn kd_tree_matches_scan(wraps: Vec<bool>, spread: f64) {
        let dof = wraps.len();
        let space = ConfigSpace::from_wraps(wraps);
        let mut rng = Rng::new(7);
        let (mut scan, mut kd) = (Tree::new(&space, false, 0.0), Tree::new(&space, true, 0.0));
        let mut q = vec![0.0; dof];
        for i in 0..3000usize {
            // Clustered and collinear points too (RRT-Connect's chains), and exact duplicates.
            for v in q.iter_mut() {
                *v = match i % 7 {
                    0 => (rng.uniform() * 4.0).round(),
                    3 => PI * (rng.below(5) as f64 - 2.0) + rng.range(-1e-12, 1e-12),
                    _ => rng.range(-spread, spread),
                };
            }
            // A copy of an earlier node now and then: equal distances, to the lower index.
            if i % 11 == 5 {
                q.copy_from_slice(scan.node(rng.below(i)));
            }
            // Runs of steps along a line, as RRT-Connect's connections lay them.
            if i % 100 >= 60 && i % 100 < 90 {
                for (v, &x) in q.iter_mut().zip(scan.node(i - 1)) {
                    *v = x + 0.05;
                }
            }
            let parent = if i == 0 { ROOT } else { rng.below(i) as u32 };
            let victim = (i % 500 == 499).then(|| 1 + rng.below(i));
            grow_both([&mut scan, &mut kd], &q, parent, victim);
            for k in 0..4 {
                for v in q.iter_mut() {
                    *v = match rng.below(5) {
                        0 => (rng.uniform() * 4.0).round(),
                        1 => PI * (rng.below(5) as f64 - 2.0),
                        _ => rng.range(-spread - 1.0, spread + 1.0),
                    };
                }
                // Near a node (near its copies too, if it has one).
                if k == 3 {
                    let near = rng.below(i + 1);
                    for (v, &x) in q.iter_mut().zip(scan.node(near)) {
                        *v = x + rng.range(-1e-3, 1e-3);
                    }
                }
                let (a, b) = (scan.nearest_with_distance(&space, &q), kd.nearest_with_distance(&space, &q));
                if kd.any_wrap() {
                    let close = |x: f64, y: f64| (x - y).abs() <= 1e-12 * (1.0 + x.abs());
                    assert!(close(a.0, b.0), "query {q:?} after {i} nodes: {a:?} against {b:?}");
                    assert!(close(space.distance_squared(kd.node(b.1), &q), b.0), "query {q:?}: {b:?}");
                    assert!(kd.alive[b.1], "query {q:?}: a cut node {b:?}");
                    let qw: Vec<f64> = q.iter().zip(&kd.period).map(|(&x, &p)| block_value(x, p)).collect();
                    assert_eq!(
                        super::scan::<0, true>(&kd.blocks, &qw, &kd.period),
                        b,
                        "block scan, query {q:?} after {i} nodes"
                    );
                    assert_eq!(
                        scan_lanes::<0, true>(&kd.blocks, &qw, &kd.period),
                        b,
                        "baseline scan, query {q:?} after {i} nodes"
                    );
                } else {
                    assert_eq!(a, b, "query {q:?} after {i} nodes");
                    // The block scan on the whole tree too (the buckets answer from 256 nodes).
                    assert_eq!(
                        super::scan::<0, false>(&kd.blocks, &q, &[]),
                        a,
                        "block scan, query {q:?} after {i} nodes"
                    );
                    // And on the baseline's instructions (the dispatch takes AVX2 where it can).
                    assert_eq!(
                        scan_lanes::<0, false>(&kd.blocks, &q, &[]),
                        a,
                        "baseline scan, query {q:?} after {i} nodes"
                    );
                }
            }
        }
    }
}
