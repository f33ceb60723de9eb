//! Certified-free cells of a group pair's relative joints.
//!
//! The distance between two bodies' spheres depends only on the joints between the bodies
//! (those with a nonzero pair lever arm: the joints above their common body move both alike).
//! When there are at most three of them and all are revolute, the pair's answer is a
//! 2π-periodic function of those joint values alone, and a grid over them can hold, per cell,
//! a proof that no sphere pair of the group pair touches anywhere in the cell: the pair
//! certificate of the motion check (each sphere pair's distance at the cell's centre exceeds
//! the sum of the radii by more than the distance can shrink over the cell). A query whose
//! relative joints fall in a proven cell skips the group pair; any other query tests it as
//! before, so answers do not change. Cells are proven coarse to fine: a cell that cannot be
//! proven is split, down to the finest level; tables that prove too little are dropped.

use std::sync::{Arc, Mutex};

use super::{LANES, SphereGeom, SphereScratch};
use crate::collision::Value;

/// At most this many relative joints per table.
const MAX_JOINTS: usize = 3;
/// Cells per joint at the coarsest level (as a power of two).
const START_LEVEL: u32 = 2;
/// A table is kept only if at least this share of its volume is proven free.
const MIN_PROVEN: f64 = 0.2;
/// At most this many cell proofs per prepared model (the spherized UR5 takes 35,440, about
/// 0.15 s): a robot with many group pairs stops proving there, with every table sound as far as
/// it got.
const MAX_PROOFS: usize = 100_000;
/// How many robots' tables [`PROVEN`] keeps.
const CACHED_ROBOTS: usize = 8;

/// The tables of the last [`CACHED_ROBOTS`] prepared models, by their `Debug` form.
type Tables = Vec<Option<Arc<CellTable>>>;
static PROVEN: Mutex<Vec<(String, Tables)>> = Mutex::new(Vec::new());

/// Joint values beyond this (rad) are not looked up (the cell index would lose precision).
const MAX_ANGLE: f64 = 1000.0;

/// Adding 1.5 * 2^52 rounds to the nearest integer; of `t - 0.5`, that is the floor of `t` (at an
/// exact integer, the cell below, whose closed box holds the value too). See [`floor_bits`].
const ROUND: f64 = 6_755_399_441_055_744.0;

/// The floor of `t` (|t| < 2^50), plus a constant that is a multiple of 2^52: the bits of
/// `t - 0.5 + ROUND`, whose low mantissa bits hold the integer, negative ones in two's
/// complement. Differences and low bits are exact, with no float-to-integer conversion (which
/// costs a saturation check each time).
#[inline(always)]
fn floor_bits(t: f64) -> i64 {
    (t - 0.5 + ROUND).to_bits() as i64
}

/// Proven-free cells over the relative joints of one group pair.
#[derive(Debug, Clone)]
pub(super) struct CellTable {
    joints: Vec<usize>,
    /// Cells per joint, as a power of two.
    level: u32,
    /// Cells per radian (cells per joint / 2π).
    scale: f64,
    /// One bit per cell, the first joint most significant.
    proven: Vec<u64>,
    /// One bit per cell `c`: every cell from `c` up one cell in each joint (the `2^n` cells
    /// `c + u`, `u` in `{0, 1}^n`, each coordinate wrapping round the turn) is proven; empty
    /// until [`Self::dilate`]. A box over two cells per joint is then one lookup, not `2^n`:
    /// public MotionBenchMaker UR5 planning spent 7.5% of its instructions in the box proofs.
    corners: Vec<u64>,
}

/// Cells per joint at the finest level (as a power of two), by the number of joints: 256, 64, 32.
fn finest_level(joints: usize) -> u32 {
    match joints {
        1 => 8,
        2 => 6,
        _ => 5,
    }
}

impl CellTable {
    /// The cell holding `q`'s relative joints, or `None` when a value is NaN or too large.
    #[inline(always)]
    fn cell(&self, q: &[f64]) -> Option<usize> {
        let mask = (1i64 << self.level) - 1;
        let mut index = 0usize;
        for &j in &self.joints {
            let v = *q.get(j)?;
            let in_range = v.abs() < MAX_ANGLE; // false for NaN
            if !in_range {
                return None;
            }
            index = (index << self.level) | (floor_bits(v * self.scale) & mask) as usize;
        }
        Some(index)
    }

    /// Whether cell `index` is proven free.
    #[inline(always)]
    fn is_proven(&self, index: usize) -> bool {
        self.proven.get(index >> 6).is_some_and(|w| (w >> (index & 63)) & 1 != 0)
    }

    /// Whether the `2^n` cells from cell `index` up one in each joint are all proven; `None`
    /// before [`Self::dilate`].
    #[inline(always)]
    fn corners_proven(&self, index: usize) -> Option<bool> {
        if self.corners.is_empty() {
            return None;
        }
        Some(self.corners.get(index >> 6).is_some_and(|w| (w >> (index & 63)) & 1 != 0))
    }

    /// Fill [`Self::corners`] from the proven cells.
    fn dilate(&mut self) {
        let n = self.joints.len();
        let level = self.level as usize;
        let mask = (1usize << level) - 1;
        let cells = 1usize << (level * n);
        let mut corners = vec![0u64; cells.div_ceil(64)];
        for c in 0..cells {
            let all = (0..1usize << n).all(|u| {
                let mut index = 0usize;
                for d in 0..n {
                    let coord = (c >> (level * (n - 1 - d))) & mask;
                    index = (index << level) | ((coord + ((u >> d) & 1)) & mask);
                }
                self.is_proven(index)
            });
            if all {
                corners[c >> 6] |= 1 << (c & 63);
            }
        }
        self.corners = corners;
    }

    /// Whether `q`'s cell is proven free.
    #[inline(always)]
    pub(super) fn proves(&self, q: &[f64]) -> bool {
        self.cell(q).is_some_and(|i| self.is_proven(i))
    }

    /// [`Self::proves`] of each lane of `lanes` whose configuration is in `cols` (value `j` of
    /// lane `i` at `cols[j][i]`, as the single-precision batch holds them): the lanes proven.
    /// The very operations of [`Self::cell`], lane by lane in vector registers, with no rows;
    /// a lane whose value is out of range (or NaN) gets every high bit of its index set, so
    /// that it names no word and is not proven (as [`Self::cell`]'s `None`). Then
    /// only the lanes asked about are looked up, lowest first, without a branch per lane
    /// (the lookup of all eight with a test per lane was about 60% of the table's
    /// instructions in a free batch of eight).
    #[inline(always)]
    pub(super) fn proves_lanes(&self, cols: &[[f64; LANES]], lanes: u32) -> u32 {
        let mask = (1i64 << self.level) - 1;
        let mut index = [0i64; LANES];
        for &j in &self.joints {
            let Some(c) = cols.get(j) else { return 0 };
            for i in 0..LANES {
                // All ones unless `|v| < MAX_ANGLE` (false for NaN): the index stays negative.
                let bad = i64::from(c[i].abs() < MAX_ANGLE) - 1;
                index[i] = (index[i] << self.level) | (floor_bits(c[i] * self.scale) & mask) | bad;
            }
        }
        let mut out = 0;
        let mut left = lanes & ((1 << LANES) - 1);
        while left != 0 {
            let i = left.trailing_zeros() as usize;
            left &= left - 1;
            let Some(&index) = index.get(i) else { break };
            // A negative index (a value out of range): no word, not proven.
            let word = usize::try_from(index >> 6).ok().and_then(|w| self.proven.get(w)).copied().unwrap_or(0);
            out |= (((word >> (index & 63)) & 1) as u32) << i;
        }
        out
    }

    /// [`Self::proves_box`] of each lane of `lanes` whose configuration is in `cols` (value `j`
    /// of lane `i` at `cols[j][i]`): the lanes proven. The cell bounds of all lanes first, then
    /// per lane only the distinct corners (the subsets of the joints whose box spans two cells),
    /// with no rows built: the same answer (an `and` over the same corners) in about a third of
    /// the instructions of a row-by-row proof.
    #[inline(always)]
    pub(super) fn proves_box_lanes(&self, cols: &[[f64; LANES]], step: &[f64], lanes: u32) -> u32 {
        let floor = floor_bits;
        let mask = (1i64 << self.level) - 1;
        let n = self.joints.len();
        let mut lo = [[0i64; LANES]; MAX_JOINTS];
        let mut two = [0u32; LANES];
        let mut bad = [false; LANES];
        for (d, &j) in self.joints.iter().enumerate().take(MAX_JOINTS) {
            let (Some(c), Some(&e)) = (cols.get(j), step.get(j)) else { return 0 };
            for i in 0..LANES {
                let v = c[i];
                let in_range = v.abs() + e < MAX_ANGLE; // false for NaN
                let (a, b) = (floor((v - e) * self.scale), floor((v + e) * self.scale));
                bad[i] |= !in_range | (b - a > 1);
                lo[d][i] = a;
                two[i] |= u32::from(b > a) << d;
            }
        }
        let mut ok = lanes;
        for (i, &bad) in bad.iter().enumerate() {
            ok &= !(u32::from(bad) << i);
        }
        let mut out = 0;
        // The lanes left, lowest first.
        while ok != 0 {
            let i = ok.trailing_zeros() as usize;
            ok &= ok - 1;
            let Some(&twos) = two.get(i) else { break };
            if twos != 0 {
                // The box from the lowest corner up one cell in every joint, in one lookup: it
                // holds every corner, so proven means proven; with two cells in every joint it
                // is the lane's box itself, so not proven means not proven.
                let mut index = 0usize;
                for lo in lo.iter().take(n) {
                    index = (index << self.level) | (lo[i] & mask) as usize;
                }
                match self.corners_proven(index) {
                    Some(true) => {
                        out |= 1 << i;
                        continue;
                    }
                    Some(false) if twos == (1 << n) - 1 => continue,
                    _ => {}
                }
            }
            // Every distinct corner: each subset of the joints that span two cells.
            let mut up = twos;
            let proven = loop {
                let mut index = 0usize;
                for (d, lo) in lo.iter().enumerate().take(n) {
                    let cell = lo[i] + i64::from((up >> d) & 1);
                    index = (index << self.level) | (cell & mask) as usize;
                }
                if !self.is_proven(index) {
                    break false;
                }
                if up == 0 {
                    break true;
                }
                up = (up - 1) & twos;
            };
            out |= u32::from(proven) << i;
        }
        out
    }

    /// Whether every cell of the box `q ± step` (over the relative joints) is proven free, the
    /// box spanning at most two cells per joint (else `false`).
    #[inline]
    pub(super) fn proves_box(&self, q: &[f64], step: &[f64]) -> bool {
        // As in `cell` (a box edge on a cell edge is in both closed cells).
        let floor = floor_bits;
        let mask = (1i64 << self.level) - 1;
        let mut lo = [0i64; MAX_JOINTS];
        let mut two = [false; MAX_JOINTS];
        for (d, &j) in self.joints.iter().enumerate() {
            let (Some(&v), Some(&e)) = (q.get(j), step.get(j)) else { return false };
            let in_range = v.abs() + e < MAX_ANGLE; // false for NaN
            if !in_range {
                return false;
            }
            let (a, b) = (floor((v - e) * self.scale), floor((v + e) * self.scale));
            if b - a > 1 {
                return false;
            }
            lo[d] = a;
            two[d] = b > a;
        }
        let n = self.joints.len();
        // As in `proves_box_lanes`: the box up one cell in every joint first.
        if two[..n].iter().any(|&t| t) {
            let index = lo[..n].iter().fold(0usize, |index, &lo| (index << self.level) | (lo & mask) as usize);
            match self.corners_proven(index) {
                Some(true) => return true,
                Some(false) if two[..n].iter().all(|&t| t) => return false,
                _ => {}
            }
        }
        (0..1usize << n).all(|c| {
            let mut index = 0usize;
            for d in 0..n {
                let up = (c >> d) & 1 == 1;
                if up && !two[d] {
                    // This corner repeats another.
                    return true;
                }
                index = (index << self.level) | ((lo[d] + up as i64) & mask) as usize;
            }
            self.is_proven(index)
        })
    }

    /// The share of cells proven free.
    fn proven_share(&self) -> f64 {
        let cells = 1usize << (self.level as usize * self.joints.len());
        self.proven.iter().map(|w| w.count_ones() as usize).sum::<usize>() as f64 / cells as f64
    }
}

impl SphereGeom {
    /// A table for every group pair that can have one and for which it proves enough: at most
    /// [`MAX_JOINTS`] relative joints (`pair_lever[p * dof + i] > 0` for one of its pairs), each a
    /// revolute DOF that no mimic joint follows. Proving takes a while (0.15 s for the spherized
    /// UR5), so the tables of the last few robots are kept for the process, keyed by the whole
    /// prepared model (its `Debug` form: every number exactly), and shared.
    pub(super) fn build_tables(&mut self, pair_lever: &[f64], dof: usize) {
        let key = format!("{self:?}{pair_lever:?}");
        if let Ok(cache) = PROVEN.lock()
            && let Some((_, tables)) = cache.iter().find(|(k, _)| *k == key)
        {
            self.tables = tables.clone();
            return;
        }
        let tables = self.prove_tables(pair_lever, dof, MAX_PROOFS);
        if let Ok(mut cache) = PROVEN.lock() {
            // Another thread may have proven the same robot meanwhile: share its tables, so that
            // every model of one robot holds the same ones.
            if let Some((_, theirs)) = cache.iter().find(|(k, _)| *k == key) {
                self.tables = theirs.clone();
                return;
            }
            if cache.len() >= CACHED_ROBOTS {
                cache.remove(0);
            }
            cache.push((key, tables.clone()));
        }
        self.tables = tables;
    }

    /// The tables of [`Self::build_tables`], with at most `budget` cell proofs in all.
    fn prove_tables(&self, pair_lever: &[f64], dof: usize, budget: usize) -> Tables {
        let mut s = SphereScratch::new();
        let home = vec![0.0; dof];
        let revolute = |i: usize| {
            self.bodies.iter().all(|b| match b.value {
                Value::Dof(d) => d != i || !b.prismatic,
                Value::Mimic(d, _, _) => d != i,
                Value::Zero => true,
            })
        };
        let mut tables = Vec::with_capacity(self.group_pairs.len());
        let mut budget = budget;
        for k in 0..self.group_pairs.len() {
            let gp = &self.group_pairs[k];
            let joints: Vec<usize> = (0..dof)
                .filter(|&i| {
                    self.run_pairs[gp.pairs.clone()].iter().any(|rp| pair_lever[rp.pair as usize * dof + i] > 0.0)
                })
                .collect();
            let table = if joints.is_empty() || joints.len() > MAX_JOINTS || !joints.iter().all(|&i| revolute(i)) {
                None
            } else {
                Some(self.prove_cells(k, joints, &home, &mut budget, &mut s))
                    .filter(|t| t.proven_share() >= MIN_PROVEN)
                    .map(|mut t| {
                        t.dilate();
                        Arc::new(t)
                    })
            };
            tables.push(table);
        }
        tables
    }

    /// Prove the cells of group pair `k` over `joints`, coarse to fine, at most `budget` proofs
    /// (counted down).
    fn prove_cells(
        &self,
        k: usize,
        joints: Vec<usize>,
        home: &[f64],
        budget: &mut usize,
        s: &mut SphereScratch,
    ) -> CellTable {
        let n = joints.len();
        let level = finest_level(n);
        let cells = 1usize << (level as usize * n);
        let mut table = CellTable {
            level,
            scale: (1u64 << level) as f64 / std::f64::consts::TAU,
            proven: vec![0; cells.div_ceil(64)],
            corners: Vec::new(),
            joints,
        };
        let mut q = home.to_vec();
        let mut step = vec![0.0; home.len()];
        // (level, cell coordinates at that level)
        let mut todo: Vec<(u32, [usize; MAX_JOINTS])> = Vec::new();
        let start = 1usize << START_LEVEL;
        for c in 0..start.pow(n as u32) {
            let mut at = [0; MAX_JOINTS];
            for (d, a) in at.iter_mut().enumerate().take(n) {
                *a = (c >> (START_LEVEL as usize * (n - 1 - d))) & (start - 1);
            }
            todo.push((START_LEVEL, at));
        }
        while let Some((l, at)) = todo.pop() {
            if *budget == 0 {
                break;
            }
            *budget -= 1;
            let w = std::f64::consts::TAU / (1u64 << l) as f64;
            for (d, &j) in table.joints.iter().enumerate() {
                q[j] = (at[d] as f64 + 0.5) * w;
                // A hair more than half a cell: a value on a cell's edge may be looked up in
                // either neighbour, and its multiples of 2π differ by rounding.
                step[j] = 0.5 * w * (1.0 + 1e-9) + 1e-12;
            }
            if self.group_pair_proven(k, &q, &step, s) {
                // Every finest cell inside.
                let shift = level - l;
                let span = 1usize << shift;
                for c in 0..span.pow(n as u32) {
                    let mut index = 0usize;
                    for (d, a) in at.iter().enumerate().take(n) {
                        let sub = (c >> (shift as usize * (n - 1 - d))) & (span - 1);
                        index = (index << level) | ((a << shift) + sub);
                    }
                    table.proven[index >> 6] |= 1 << (index & 63);
                }
            } else if l < level {
                for c in 0..(1usize << n) {
                    let mut child = [0; MAX_JOINTS];
                    for d in 0..n {
                        child[d] = 2 * at[d] + ((c >> (n - 1 - d)) & 1);
                    }
                    todo.push((l + 1, child));
                }
            }
        }
        table
    }

    /// Whether no sphere pair of group pair `k` can touch when the joints move by at most
    /// `step` either side of `q`: link pairs whose bounding spheres stay apart by more than
    /// both links' motion bounds are skipped, the rest sphere by sphere with the pair margin.
    fn group_pair_proven(&self, k: usize, q: &[f64], step: &[f64], s: &mut SphereScratch) -> bool {
        self.pose(q, s);
        let gp = &self.group_pairs[k];
        for run in &self.runs[gp.runs.clone()] {
            let a = run.outer;
            let ca = self.link_centre(a, s);
            let ma = self.link_margin(a, step, s);
            self.pose_link(a, s);
            for rp in &self.run_pairs[run.pairs.clone()] {
                let b = rp.link as usize;
                let cb = self.link_centre(b, s);
                let mb = self.link_margin(b, step, s);
                let reach = run.r + rp.r + ma + mb;
                if (ca - cb).norm_squared() > reach * reach {
                    continue;
                }
                self.pose_link(b, s);
                let stop = self.pair_common[rp.pair as usize] as usize;
                let la = &self.links[a];
                for i in la.first..la.end {
                    for j in rp.first as usize..rp.end as usize {
                        let d2: f64 = (s.centre[i] - s.centre[j]).norm_squared();
                        let r = self.radius[i] + self.radius[j];
                        let re = r + self.pair_margin(i, j, stop, step, None, s);
                        // (A NaN distance proves nothing.)
                        if d2.partial_cmp(&(re * re)) != Some(std::cmp::Ordering::Greater) {
                            return false;
                        }
                    }
                }
            }
        }
        true
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use std::f64::consts::TAU;
    use std::path::PathBuf;

    use super::super::super::{Environment, RobotGeom, disable_always_colliding};
    use super::super::{Check, SphereGeom, SphereScratch};
    use super::{CellTable, MAX_JOINTS, ROUND, finest_level};
    use crate::rng::Rng;
    use crate::urdf::load_urdf;

    fn ur5_geom() -> (crate::robot::Robot, RobotGeom) {
        let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures");
        let mut robot = load_urdf(&dir.join("ur5_spherized.urdf"), Some(&dir.join("ur5.srdf"))).unwrap();
        disable_always_colliding(&mut robot, 300, 3);
        let g = RobotGeom::new(&robot);
        (robot, g)
    }

    /// Two models of one robot meet in the cache: the second takes the first's tables, not
    /// proving them again (which took 17 s over the 296 public MotionBenchMaker problems when a
    /// number unique to each model showed in the key).
    #[test]
    fn models_of_one_robot_share_their_tables() {
        let (_, g) = ur5_geom();
        let (a, b) = (SphereGeom::new(&g, true).unwrap(), SphereGeom::new(&g, true).unwrap());
        let shared = a.tables.iter().zip(&b.tables).filter(|(x, y)| match (x, y) {
            (Some(x), Some(y)) => std::sync::Arc::ptr_eq(x, y),
            _ => false,
        });
        let proven = a.tables.iter().flatten().count();
        assert!(proven > 0 && shared.count() == proven, "{proven} tables");
    }

    /// Models of one robot built at once on several threads share their tables too: a thread
    /// that finishes proving after another has cached the robot takes the cached tables. (When
    /// each pushed its own, the models held copies, and `models_of_one_robot_share_their_tables`
    /// failed whenever another test built the same robot at the same moment.) The base is moved
    /// so that no other test has cached this robot.
    #[test]
    fn models_built_at_once_share_their_tables() {
        let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures");
        let mut robot = load_urdf(&dir.join("ur5_spherized.urdf"), Some(&dir.join("ur5.srdf"))).unwrap();
        disable_always_colliding(&mut robot, 300, 3);
        robot.set_base(nalgebra::Isometry3::translation(0.125, -0.5, 0.25));
        let g = RobotGeom::new(&robot);
        let models: Vec<SphereGeom> = std::thread::scope(|scope| {
            let built: Vec<_> = (0..4).map(|_| scope.spawn(|| SphereGeom::new(&g, true).unwrap())).collect();
            built.into_iter().map(|h| h.join().unwrap()).collect()
        });
        let later = SphereGeom::new(&g, true).unwrap();
        let proven = later.tables.iter().flatten().count();
        assert!(proven > 0);
        for m in &models {
            for (x, y) in m.tables.iter().zip(&later.tables) {
                match (x, y) {
                    (Some(x), Some(y)) => assert!(std::sync::Arc::ptr_eq(x, y)),
                    (None, None) => {}
                    _ => panic!("a table in one model only"),
                }
            }
        }
    }

    /// Table `k` of a test at `level`: over one to three of six joints (`1 + k % 3`), its
    /// cells proven at random, densely for even `k` and sparsely for odd (a corner left out
    /// would change the answer of some).
    fn random_table(rng: &mut Rng, k: usize, level: u32) -> CellTable {
        let n = 1 + k % 3;
        let cells = 1usize << (level as usize * n);
        let proven = (0..cells.div_ceil(64))
            .map(|_| if k.is_multiple_of(2) { rng.next_u64() | rng.next_u64() } else { rng.next_u64() })
            .collect();
        let joints: Vec<usize> = (0..n).map(|d| (d * 2 + k) % 6).collect();
        CellTable { joints, level, scale: (1u64 << level) as f64 / TAU, proven, corners: Vec::new() }
    }

    /// Six joints' values over the lanes, lane `i` of joint `j` drawn by `value(rng, i + j)`
    /// (lane by lane within a joint, joint after joint).
    fn lane_columns(rng: &mut Rng, mut value: impl FnMut(&mut Rng, usize) -> f64) -> [[f64; super::LANES]; 6] {
        let mut cols = [[0.0; super::LANES]; 6];
        for (j, col) in cols.iter_mut().enumerate() {
            for (i, v) in col.iter_mut().enumerate() {
                *v = value(rng, i + j);
            }
        }
        cols
    }

    /// The lanes' box proof answers as the row-by-row one, lane by lane: on tables of one to
    /// three joints with random proven cells, on values anywhere in a few turns, on cell edges,
    /// with steps that span one, two and more cells, and on values that are NaN or too large,
    /// for any set of lanes asked.
    #[test]
    fn box_proofs_of_lanes_answer_as_row_by_row() {
        use super::LANES;
        let mut rng = Rng::new(31);
        let mut proven_lanes = 0;
        for k in 0..3000 {
            let level = [2u32, 3, 5][k % 3];
            let mut t = random_table(&mut rng, k, level);
            // Half the tables answer through their dilated cells.
            if k % 4 < 2 {
                t.dilate();
            }
            let w = TAU / (1u64 << level) as f64;
            let cols = lane_columns(&mut rng, |rng, at| match (at + k) % 7 {
                0 => (rng.below(40) as f64 - 20.0) * w,
                1 => f64::NAN,
                2 => 1500.0,
                _ => rng.range(-10.0, 10.0),
            });
            let step: Vec<f64> = (0..6).map(|j| [0.0, 0.3 * w, 0.9 * w, 2.5 * w, 0.6 * w][(j + k / 3) % 5]).collect();
            let lanes = rng.next_u64() as u32 & 0xff;
            let by_lanes = t.proves_box_lanes(&cols, &step, lanes);
            for i in 0..LANES {
                let q: Vec<f64> = cols.iter().map(|c| c[i]).collect();
                let expected = lanes & (1 << i) != 0 && t.proves_box(&q, &step);
                assert_eq!(by_lanes & (1 << i) != 0, expected, "table {k}, lane {i}: {q:?} ± {step:?}");
                proven_lanes += usize::from(expected);
            }
            assert_eq!(
                t.proves_box_lanes(&cols[..1], &step, lanes),
                if t.joints.iter().all(|&j| j < 1) { by_lanes } else { 0 }
            );
        }
        assert!(proven_lanes > 500, "{proven_lanes} lanes proven");
    }

    /// The lanes' point lookups answer as [`CellTable::proves`] of each lane's row, lanes asked
    /// or not, with values NaN, out of range, negative, far past a turn and on cell edges.
    #[test]
    fn point_proofs_of_lanes_answer_as_row_by_row() {
        use super::LANES;
        let mut rng = Rng::new(37);
        let mut proven_lanes = 0;
        for k in 0..3000 {
            let level = [2u32, 3, 5, 8][k % 4];
            let t = random_table(&mut rng, k, level);
            let w = TAU / (1u64 << level) as f64;
            let cols = lane_columns(&mut rng, |rng, at| match (at + k) % 9 {
                0 => (rng.below(40) as f64 - 20.0) * w,
                1 => f64::NAN,
                2 => [1500.0, -1500.0, f64::INFINITY, 999.0][rng.below(4)],
                3 => rng.range(-900.0, 900.0),
                _ => rng.range(-10.0, 10.0),
            });
            let lanes = rng.next_u64() as u32 & 0xff;
            let by_lanes = t.proves_lanes(&cols, lanes);
            for i in 0..LANES {
                let q: Vec<f64> = cols.iter().map(|c| c[i]).collect();
                let expected = lanes & (1 << i) != 0 && t.proves(&q);
                assert_eq!(by_lanes & (1 << i) != 0, expected, "table {k}, lane {i}: {q:?}");
                proven_lanes += usize::from(expected);
            }
            assert_eq!(t.proves_lanes(&cols[..1], lanes), if t.joints.iter().all(|&j| j < 1) { by_lanes } else { 0 });
        }
        assert!(proven_lanes > 500, "{proven_lanes} lanes proven");
    }

    #[test]
    fn a_value_falls_in_the_cell_that_holds_it_modulo_a_turn() {
        let level = 6;
        let t = CellTable { joints: vec![1, 0], level, scale: 64.0 / TAU, proven: vec![0; 64], corners: Vec::new() };
        let w = TAU / 64.0;
        // First joint listed (q[1]) most significant; -0.001 rad is in the last cell of the turn.
        assert_eq!(t.cell(&[TAU + 0.001, -0.001]), Some(63 << level));
        assert_eq!(t.cell(&[2.5 * w, 1.5 * w - 2.0 * TAU]), Some((1 << level) | 2));
        assert_eq!(t.cell(&[f64::NAN, 0.1]), None);
        assert_eq!(t.cell(&[0.1, 2000.0]), None);
        assert_eq!(t.cell(&[0.1]), None);
        let mut rng = Rng::new(3);
        for _ in 0..100_000 {
            let v = rng.range(-20.0, 20.0);
            let k = t.cell(&[0.0, v]).unwrap() >> level;
            let base = v.rem_euclid(TAU);
            // (base may round to exactly TAU: the last cell's upper edge.)
            assert!(k as f64 * w <= base + 1e-12 && base <= (k + 1) as f64 * w + 1e-12, "{v}: cell {k}");
        }
    }

    #[test]
    fn a_box_is_proven_when_every_cell_it_touches_is() {
        let level = 6;
        let w = TAU / 64.0;
        let mut t =
            CellTable { joints: vec![0, 2], level, scale: 64.0 / TAU, proven: vec![0; 64], corners: Vec::new() };
        let mut prove = |a: usize, b: usize| {
            let i = (a << level) | b;
            t.proven[i >> 6] |= 1 << (i & 63);
        };
        // Cells (63, 0), (0, 0) and (0, 1) of the (q[0], q[2]) grid.
        prove(63, 0);
        prove(0, 0);
        prove(0, 1);
        let step = [0.1 * w, 9.0, 0.1 * w];
        // Inside cell (0, 0); across q[2]'s edge into (0, 1); across q[0]'s wrap into (63, 0).
        assert!(t.proves_box(&[0.5 * w, 7.0, 0.5 * w], &step));
        assert!(t.proves_box(&[0.5 * w, 7.0, 0.95 * w], &step));
        assert!(t.proves_box(&[0.05 * w - TAU, 7.0, 0.5 * w], &step));
        // Across q[2]'s edge into (0, 63), not proven; into (63, 1), not proven.
        assert!(!t.proves_box(&[0.5 * w, 7.0, 0.05 * w], &step));
        assert!(!t.proves_box(&[0.05 * w, 7.0, 0.95 * w], &step));
        // More than two cells per joint; NaN; the single cell of a zero step.
        assert!(!t.proves_box(&[0.5 * w, 0.0, 1.0 * w], &[0.1 * w, 0.0, 1.2 * w]));
        assert!(!t.proves_box(&[f64::NAN, 0.0, 0.5 * w], &step));
        assert!(t.proves_box(&[0.5 * w, 0.0, 1.5 * w], &[0.0; 3]));
        assert!(!t.proves_box(&[0.5 * w, 0.0, 2.5 * w], &[0.0; 3]));
    }

    /// On random tables of one to three joints (nine cells in ten proven) and random boxes,
    /// some wrapping past a turn, some spanning three cells: a box is proven exactly when the
    /// cell of each of its corners is (corners on a cell edge count in both cells), the
    /// reference taking every corner's cell through `cell`.
    #[test]
    fn a_box_is_proven_exactly_when_each_corners_cell_is() {
        let mut rng = Rng::new(9);
        let (mut yes, mut no) = (0, 0);
        for n in 1..=MAX_JOINTS {
            let level = finest_level(n);
            let cells = 1usize << (level as usize * n);
            let joints: Vec<usize> = [2, 0, 1][..n].to_vec();
            let scale = (1u64 << level) as f64 / TAU;
            let w = 1.0 / scale;
            for _ in 0..20 {
                let proven = vec![0; cells.div_ceil(64)];
                let mut t = CellTable { joints: joints.clone(), level, scale, proven, corners: Vec::new() };
                for i in 0..cells {
                    if rng.uniform() < 0.9 {
                        t.proven[i >> 6] |= 1 << (i & 63);
                    }
                }
                // Every other table answers through its dilated cells too.
                let mut dilated = t.clone();
                dilated.dilate();
                for _ in 0..2000 {
                    let q: Vec<f64> = (0..3).map(|_| rng.range(-8.0, 8.0)).collect();
                    let step: Vec<f64> = (0..3).map(|_| rng.range(0.0, 1.2 * w)).collect();
                    // Every corner `q ± step`; a span over three cells is never proven.
                    let spans = joints.iter().all(|&j| {
                        let cell = |x: f64| (x * scale - 0.5 + ROUND).to_bits() as i64;
                        cell(q[j] + step[j]) - cell(q[j] - step[j]) <= 1
                    });
                    let corners = (0..1usize << 3).all(|c| {
                        let corner: Vec<f64> =
                            (0..3).map(|i| if (c >> i) & 1 == 1 { q[i] + step[i] } else { q[i] - step[i] }).collect();
                        t.proves(&corner)
                    });
                    let expected = spans && corners;
                    assert_eq!(t.proves_box(&q, &step), expected, "{n} joints: {q:?} ± {step:?}");
                    assert_eq!(dilated.proves_box(&q, &step), expected, "{n} joints, dilated: {q:?} ± {step:?}");
                    if expected { yes += 1 } else { no += 1 }
                }
            }
        }
        assert!(yes > 1000 && no > 1000, "{yes} proven, {no} not");
    }

    /// Asserts that no sphere pair of group pair `gp` touches in the pose of `s`.
    fn assert_apart(fast: &SphereGeom, gp: &super::super::GroupPair, s: &mut SphereScratch, what: &str) {
        for run in &fast.runs[gp.runs.clone()] {
            fast.pose_link(run.outer, s);
            for rp in &fast.run_pairs[run.pairs.clone()] {
                fast.pose_link(rp.link as usize, s);
                let la = &fast.links[run.outer];
                for i in la.first..la.end {
                    for j in rp.first as usize..rp.end as usize {
                        let d = (s.centre[i] - s.centre[j]).norm();
                        assert!(d > fast.radius[i] + fast.radius[j], "{what}: spheres {i}, {j}");
                    }
                }
            }
        }
    }

    /// A budget cut short proves a subset of the cells the full build proves (the same proofs,
    /// in the same order), and later group pairs get no table.
    #[test]
    fn a_small_budget_proves_a_subset() {
        let (_, g) = ur5_geom();
        let fast = SphereGeom::new(&g, false).unwrap();
        let full = fast.prove_tables(&g.pair_lever, g.dof, usize::MAX);
        let cut = fast.prove_tables(&g.pair_lever, g.dof, 3_000);
        let count = |t: &super::Tables| -> usize {
            t.iter().flatten().map(|t| t.proven.iter().map(|w| w.count_ones() as usize).sum::<usize>()).sum()
        };
        assert!(count(&cut) > 0 && count(&cut) < count(&full), "{} of {}", count(&cut), count(&full));
        assert!(cut.iter().flatten().count() < full.iter().flatten().count());
        for (a, b) in cut.iter().zip(&full) {
            if let (Some(a), Some(b)) = (a, b) {
                assert!(a.proven.iter().zip(&b.proven).all(|(x, y)| x & !y == 0));
            }
        }
    }

    /// Every query a table proves free has its group pair's spheres apart, also on the cell edges
    /// of every table (multiples of 2π/256), and the tables change no answer of the model.
    #[test]
    fn proven_cells_hold_no_contact_and_change_no_answer() {
        let (robot, g) = ur5_geom();
        let with = SphereGeom::new(&g, true).unwrap();
        let without = SphereGeom::new(&g, false).unwrap();
        let tables = with.tables.iter().filter(|t| t.is_some()).count();
        assert!(tables >= 5, "only {tables} tables");
        let (mut s, mut s2) = (SphereScratch::new(), SphereScratch::new());
        let mut rng = Rng::new(11);
        let (mut proven, mut hits) = (0usize, 0usize);
        let env = Environment::new();
        assert!(env.obstacles().is_empty());
        for n in 0..20_000 {
            let mut q = robot.random_configuration(&mut rng);
            if n % 2 == 0 {
                for v in &mut q {
                    *v = (*v / (TAU / 256.0)).round() * (TAU / 256.0);
                }
            }
            let answer = with.check(&q, &[], &[], None, &mut s);
            assert_eq!(answer, without.check(&q, &[], &[], None, &mut s2), "q = {q:?}");
            hits += (answer == Check::Hit) as usize;
            with.pose(&q, &mut s);
            for (k, gp) in with.group_pairs.iter().enumerate() {
                let Some(Some(table)) = with.tables.get(k) else { continue };
                if !table.proves(&q) {
                    continue;
                }
                proven += 1;
                assert_apart(&with, gp, &mut s, &format!("{q:?}: group pair {k}"));
            }
        }
        // Boxes: every configuration sampled in a proven box has the group pair's spheres apart.
        let mut boxes = 0usize;
        for _ in 0..3_000 {
            let q = robot.random_configuration(&mut rng);
            let step: Vec<f64> = q.iter().map(|_| rng.range(0.0, 0.1)).collect();
            for (k, gp) in with.group_pairs.iter().enumerate() {
                let Some(Some(table)) = with.tables.get(k) else { continue };
                if !table.proves_box(&q, &step) {
                    continue;
                }
                boxes += 1;
                for _ in 0..20 {
                    let p: Vec<f64> = q.iter().zip(&step).map(|(v, e)| v + rng.range(-e, *e)).collect();
                    with.pose(&p, &mut s);
                    assert_apart(&with, gp, &mut s, &format!("{p:?} in a proven box of {k}"));
                }
            }
        }
        assert!(boxes > 3_000, "only {boxes} boxes proven");
        // Both answers occur, and the tables prove most group pairs they are asked about.
        assert!(hits > 1_000 && hits < 19_000, "{hits} of 20000 collide");
        assert!(proven > 40_000, "only {proven} proofs used");
    }
}
