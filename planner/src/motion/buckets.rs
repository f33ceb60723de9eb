//! Nearest neighbours of a large RRT-Connect tree: a k-d tree of buckets, rebuilt as the tree
//! grows, its leaves scanned four nodes at a time.
//!
//! A k-d tree with a node per configuration visits, in seven or eight joints, most of its nodes
//! for a query far from the tree (a uniform sample, most of which dynamic domain then turns
//! away), each with a branch per joint: on the Fetch's MotionBenchMaker cage problem 5 (31,789
//! samples, trees of 2,017 and 1,008 nodes) the queries took 329 M of 575 M planning
//! instructions. Here the nodes are split at medians (along the joint whose nodes spread widest)
//! down to leaves of at most [`LEAF`] nodes, laid out as the scan's blocks, so a visited leaf
//! costs a few vector operations per joint and no branch per node. Nodes added since the last
//! rebuild are scanned in the tree's own blocks; the buckets are rebuilt once those reach a
//! quarter of the nodes in them (at least [`PENDING`]). That problem: 575 M -> 464 M (queries
//! 205 M, rebuilds 22 M); leaves of 8 and 32 nodes 481 M and 468 M, rebuilt at an eighth 481 M.
//! With rebuilds reading each node's values once (the Fetch's first 70 cage problems, seed 2:
//! rebuilds 161 M -> 104 M, planning 7,118 M -> 7,067 M, every path the same), rebuilt at an
//! eighth a query took 2,250 -> 2,175 instructions and at a sixteenth 2,266, each with other
//! searches (8 of 70 paths changed): a quarter stays.
//!
//! *Approximate answers.* A cell is pruned when its bound (its largest gap to the query along a
//! split, which is at most the difference along that joint to any of its nodes) times
//! `(1 + ε)` exceeds the best distance, ε = [`APPROX`]: the node returned is then at most `1 + ε`
//! times as far as the nearest (Arya, Mount, Netanyahu, Silverman and Wu, "An optimal algorithm
//! for approximate nearest neighbor searching in fixed dimensions", JACM 1998; each pruned
//! cell's nodes are farther than the best then found over `1 + ε`, and the best only
//! shrinks). RRT-Connect needs a node near the sample, not the nearest: Plaku and Kavraki
//! ("Quantitative analysis of nearest-neighbors search in high-dimensional sampling-based
//! motion planning", WAFR 2006) found approximate neighbours speed planners up in high
//! dimensions at no cost in their success. On the Fetch's 40 MotionBenchMaker cage problems
//! (eight runs each, seeds 1-8) a query took 5,088 -> 2,975 instructions (ε 1: 2,833); p95 62-63
//! -> 45-47 ms, max 434-456 -> 255-257 ms, p50 and the problems solved the same within the
//! noise. With ε 0 (the tests) the answer is exactly the scan's (`rrt_connect::scan`): every
//! distance is the same sum in the same order and ties go to the lowest index. Either way the
//! answer is deterministic: the same tree and query give the same node.
//!
//! *Wrapping joints* hold their angles in [-pi, pi) (as the tree's blocks do): a split on one
//! cuts the circle at its value and at pi, and a far side's gap is the shorter way round to
//! its arc, less [`WRAP_MARGIN`] for the rounding of the wrapped differences; the leaves take
//! each difference the shorter way round (`rrt_connect::gap2`).

/// Most nodes in a leaf.
const LEAF: usize = 16;

/// Fewest nodes added since the last rebuild that trigger the next one.
const PENDING: usize = 32;

/// The approximation ε of the planner's queries (module documentation): the node returned is at
/// most `1 + ε` times as far as the nearest.
pub(crate) const APPROX: f64 = 0.5;

use std::f64::consts::PI;

use super::rrt_connect::{BLOCK, gap2};

/// Slack on a wrapped joint's bound (rad): the wrapped differences the distances sum round by
/// far less, so a far side is never pruned for a rounding.
const WRAP_MARGIN: f64 = 1e-9;

const NONE: u32 = u32::MAX;

/// A cell: a split (joint, value; `child` below and at or above it) or a leaf (`child[0]` is
/// `NONE`) holding blocks `first..first + blocks` of [`Buckets::leaves`].
#[derive(Clone, Copy)]
struct Cell {
    split: u32,
    value: f64,
    child: [u32; 2],
    first: u32,
    blocks: u32,
}

/// The buckets of a tree's first `built` nodes (see the module documentation).
pub(crate) struct Buckets {
    dof: usize,
    /// Nodes `0..built` are in the leaves (a multiple of [`BLOCK`]).
    pub(crate) built: usize,
    cells: Vec<Cell>,
    /// The leaves' nodes, [`BLOCK`] at a time joint by joint (block `b`, joint `j` at
    /// `b * dof + j`); a lane of padding or of a cut node holds infinity.
    leaves: Vec<[f64; BLOCK]>,
    /// The node of each lane of `leaves` (`NONE` for padding).
    ids: Vec<u32>,
    /// The lane of each node in `leaves` (`NONE` for a node cut before the rebuild).
    lane: Vec<u32>,
    stack: Vec<(u32, f64)>,
    /// The built nodes' values node by node (`dof` each), kept for the next rebuild.
    xs: Vec<f64>,
    /// The living built nodes, kept for the next rebuild.
    order: Vec<u32>,
    /// `(1 + ε)²`: a cell is pruned when its squared bound times this exceeds the best.
    loose: f64,
}

impl Buckets {
    /// Buckets over `dof` joints answering within `1 + approx` of the nearest distance (0:
    /// exactly the scan's answer).
    pub(crate) fn new(dof: usize, approx: f64) -> Self {
        let approx = if approx.is_finite() { approx.max(0.0) } else { 0.0 };
        Self {
            loose: (1.0 + approx) * (1.0 + approx),
            dof,
            built: 0,
            cells: Vec::new(),
            leaves: Vec::new(),
            ids: Vec::new(),
            lane: Vec::new(),
            stack: Vec::new(),
            xs: Vec::new(),
            order: Vec::new(),
        }
    }

    /// Whether a tree of `len` nodes should rebuild its buckets.
    pub(crate) fn stale(&self, len: usize) -> bool {
        len - self.built >= PENDING.max(self.built / 4) + BLOCK
    }

    /// Rebuilt over the living nodes among the first `len` rounded down to a whole block, their
    /// values read from the tree's `blocks` (`rrt_connect::Tree::blocks`).
    pub(crate) fn rebuild(&mut self, blocks: &[[f64; BLOCK]], alive: &[bool], len: usize) {
        let dof = self.dof;
        self.built = len / BLOCK * BLOCK;
        self.cells.clear();
        self.leaves.clear();
        self.ids.clear();
        self.lane.clear();
        self.lane.resize(self.built, NONE);
        let mut order = std::mem::take(&mut self.order);
        order.clear();
        order.extend((0..self.built as u32).filter(|&i| alive[i as usize]));
        if !order.is_empty() && dof > 0 {
            // The nodes' values node by node, read once: the splits below read each many times
            // (read through the blocks, a division and two bounds checks each time).
            let mut xs = std::mem::take(&mut self.xs);
            xs.clear();
            for block in blocks.chunks_exact(dof).take(self.built / BLOCK) {
                for l in 0..BLOCK {
                    xs.extend(block.iter().map(|lanes| lanes[l]));
                }
            }
            let _ = self.build(&mut order, &xs, dof);
            self.xs = xs;
        }
        self.order = order;
    }

    /// The cells over nodes `idx`, their values node by node in `xs` (`dof` each).
    fn build(&mut self, idx: &mut [u32], xs: &[f64], dof: usize) -> u32 {
        let x = |i: u32, s: usize| xs[i as usize * dof + s];
        let at = self.cells.len() as u32;
        self.cells.push(Cell { split: 0, value: 0.0, child: [NONE; 2], first: 0, blocks: 0 });
        if idx.len() <= LEAF {
            // Lowest index first in each leaf (no rule needs it: ties are settled by index).
            idx.sort_unstable();
            let first = self.leaves.len() / dof;
            let blocks = idx.len().div_ceil(BLOCK);
            self.leaves.resize(self.leaves.len() + blocks * dof, [f64::INFINITY; BLOCK]);
            self.ids.resize(self.ids.len() + blocks * BLOCK, NONE);
            for (k, &i) in idx.iter().enumerate() {
                let (b, l) = (first + k / BLOCK, k % BLOCK);
                for j in 0..dof {
                    self.leaves[b * dof + j][l] = x(i, j);
                }
                self.ids[b * BLOCK + l] = i;
                self.lane[i as usize] = (b * BLOCK + l) as u32;
            }
            self.cells[at as usize].first = first as u32;
            self.cells[at as usize].blocks = blocks as u32;
            return at;
        }
        let split = widest_joint(idx, xs, dof);
        let mid = idx.len() / 2;
        idx.select_nth_unstable_by(mid, |&a, &b| x(a, split).total_cmp(&x(b, split)));
        // Below `mid` at most the value, from `mid` at least.
        let value = x(idx[mid], split);
        let (left, right) = idx.split_at_mut(mid);
        let l = self.build(left, xs, dof);
        let r = self.build(right, xs, dof);
        self.cells[at as usize] = Cell { split: split as u32, value, child: [l, r], first: 0, blocks: 0 };
        at
    }

    /// Node `k` (below `built`) was cut: its lanes hold infinity.
    pub(crate) fn hide(&mut self, k: usize) {
        if let Some(&lane) = self.lane.get(k)
            && lane != NONE
        {
            let (b, l) = (lane as usize / BLOCK, lane as usize % BLOCK);
            for j in 0..self.dof {
                self.leaves[b * self.dof + j][l] = f64::INFINITY;
            }
        }
    }

    /// The node of the buckets nearest to `q` as (squared distance, index), or `best` when none
    /// is nearer (ties to the lowest index; `best`'s index is above every node here), within
    /// the approximation (module documentation). Compiled for AVX2 where the CPU has it, as the
    /// scan.
    /// With `WRAP`, `q`'s wrapping joints (finite `period`) are in [-pi, pi) and their
    /// differences go the shorter way round.
    pub(crate) fn nearest<const DOF: usize, const WRAP: bool>(
        &mut self,
        q: &[f64],
        best: (f64, usize),
        period: &[f64],
    ) -> (f64, usize) {
        #[cfg(target_arch = "x86_64")]
        if let Some(v3) = pulp::x86::V3::try_new() {
            return pulp::Simd::vectorize(v3, NearestV3::<DOF, WRAP> { buckets: self, q, best, period });
        }
        self.nearest_in::<DOF, WRAP>(q, best, period)
    }

    /// [`Self::nearest`] on the instruction set of its caller.
    #[inline(always)]
    fn nearest_in<const DOF: usize, const WRAP: bool>(
        &mut self,
        q: &[f64],
        mut best: (f64, usize),
        period: &[f64],
    ) -> (f64, usize) {
        let dof = if DOF == 0 { q.len() } else { DOF };
        let q = &q[..dof];
        let period = if WRAP { &period[..dof] } else { &[][..] };
        if self.cells.is_empty() {
            return best;
        }
        let loose = self.loose;
        let stack = &mut self.stack;
        stack.clear();
        stack.push((0, 0.0));
        while let Some((mut c, bound)) = stack.pop() {
            if bound * loose > best.0 {
                continue;
            }
            loop {
                let cell = self.cells[c as usize];
                if cell.child[0] == NONE {
                    let first = cell.first as usize;
                    for b in first..first + cell.blocks as usize {
                        let block = &self.leaves[b * dof..(b + 1) * dof];
                        let mut s = [0.0f64; BLOCK];
                        for (j, (&qj, lanes)) in q.iter().zip(block).enumerate() {
                            let pj = if WRAP { period[j] } else { 0.0 };
                            for (s, &p) in s.iter_mut().zip(lanes) {
                                *s += gap2::<WRAP>(qj, p, pj);
                            }
                        }
                        // Most blocks hold no node as near as the best: one test for the four.
                        if s[0].min(s[1]).min(s[2].min(s[3])) > best.0 {
                            continue;
                        }
                        for (l, &d) in s.iter().enumerate() {
                            let id = self.ids[b * BLOCK + l] as usize;
                            if d < best.0 || (d == best.0 && id < best.1) {
                                best = (d, id);
                            }
                        }
                    }
                    break;
                }
                let s = cell.split as usize;
                let diff = q[s] - cell.value;
                let (near, far) =
                    if diff < 0.0 { (cell.child[0], cell.child[1]) } else { (cell.child[1], cell.child[0]) };
                let gap = if WRAP && period[s].is_finite() {
                    // The far side is the arc [value, pi) below the split's value, [-pi, value)
                    // at or above it: the shorter way round to it.
                    let around = if diff < 0.0 { (-diff).min(q[s] + PI) } else { diff.min(PI - q[s]) };
                    (around - WRAP_MARGIN).max(0.0)
                } else {
                    diff
                };
                let far_bound = bound.max(gap * gap);
                if far_bound * loose <= best.0 {
                    stack.push((far, far_bound));
                }
                c = near;
            }
        }
        best
    }
}

/// The joint (of `dof`) along which the nodes `idx` spread widest, their values node by node in
/// `xs`; the first of equals.
fn widest_joint(idx: &[u32], xs: &[f64], dof: usize) -> usize {
    let (mut split, mut widest) = (0, f64::NEG_INFINITY);
    for s in 0..dof {
        // Comparisons, not `f64::min` and `max` with their NaN handling (a tree's values are
        // finite; both pass a NaN over).
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for &i in idx {
            let v = xs.get(i as usize * dof + s).copied().unwrap_or(f64::NAN);
            if v < lo {
                lo = v;
            }
            if v > hi {
                hi = v;
            }
        }
        if hi - lo > widest {
            (widest, split) = (hi - lo, s);
        }
    }
    split
}

/// [`Buckets::nearest_in`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
struct NearestV3<'a, const DOF: usize, const WRAP: bool> {
    buckets: &'a mut Buckets,
    q: &'a [f64],
    best: (f64, usize),
    period: &'a [f64],
}

#[cfg(target_arch = "x86_64")]
impl<const DOF: usize, const WRAP: bool> pulp::WithSimd for NearestV3<'_, DOF, WRAP> {
    type Output = (f64, usize);
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> (f64, usize) {
        self.buckets.nearest_in::<DOF, WRAP>(self.q, self.best, self.period)
    }
}
