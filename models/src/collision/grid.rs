//! The obstacle broad phase for many obstacles: a uniform grid over the obstacles' boxes.
//!
//! Each obstacle is listed in every cell its axis-aligned box overlaps (an obstacle that would
//! fill too many cells, a floor say, is kept on a short list that every query visits). A
//! query visits the cells overlapped by a box around one link, so its cost follows the number
//! of obstacles near that link, not the number in the scene. Cells are stored flat (`start`,
//! `items`: the obstacles of cell `k` are `items[start[k]..start[k + 1]]`), so a query does no
//! hashing and no allocation.

use nalgebra::Point3;

/// At most this many cells along an axis (the cell grows to fit the obstacles' extent).
const MAX_CELLS_PER_AXIS: usize = 64;
/// An obstacle overlapping more cells than this is visited by every query instead.
const MAX_CELLS_PER_OBSTACLE: usize = 64;

/// Where a box lies in the grid.
enum Overlap {
    /// Not finite: it could be anywhere (a query then visits every obstacle).
    Unknown,
    /// Beyond the grid on some axis: near no gridded obstacle.
    Outside,
    /// These cells along x, y and z.
    Cells([std::ops::RangeInclusive<usize>; 3]),
}

#[derive(Debug, Clone)]
pub(crate) struct ObstacleGrid {
    origin: Point3<f64>,
    inv_cell: f64,
    dims: [usize; 3],
    start: Vec<u32>,
    items: Vec<u32>,
    big: Vec<u32>,
}

impl ObstacleGrid {
    /// The grid over obstacle boxes `(lo, hi)` with cells of about `cell` metres; `None` when
    /// there is nothing finite to grid.
    pub(crate) fn new(boxes: &[(Point3<f64>, Point3<f64>)], cell: f64) -> Option<Self> {
        let finite = |p: &Point3<f64>| p.iter().all(|v| v.is_finite());
        let mut lo = Point3::from([f64::INFINITY; 3]);
        let mut hi = Point3::from([f64::NEG_INFINITY; 3]);
        for (a, b) in boxes.iter().filter(|(a, b)| finite(a) && finite(b)) {
            lo = lo.inf(a);
            hi = hi.sup(b);
        }
        if !(finite(&lo) && finite(&hi) && cell.is_finite() && cell > 0.0) {
            return None;
        }
        let extent = (hi - lo).max();
        let cell = cell.max(extent / MAX_CELLS_PER_AXIS as f64).max(1e-9);
        let inv_cell = 1.0 / cell;
        let dims = [0, 1, 2].map(|i| (((hi[i] - lo[i]) * inv_cell).floor() as usize + 1).min(MAX_CELLS_PER_AXIS));
        let mut grid =
            ObstacleGrid { origin: lo, inv_cell, dims, start: Vec::new(), items: Vec::new(), big: Vec::new() };
        let ncells = dims[0] * dims[1] * dims[2];
        // Two passes: count each cell's obstacles, then place them.
        let mut count = vec![0u32; ncells + 1];
        let mut placed: Vec<(u32, [std::ops::RangeInclusive<usize>; 3])> = Vec::new();
        for (o, (a, b)) in boxes.iter().enumerate() {
            let Overlap::Cells(range) = grid.cells(a, b) else {
                grid.big.push(o as u32);
                continue;
            };
            let covered: usize = range.iter().map(|r| r.end() - r.start() + 1).product();
            if covered > MAX_CELLS_PER_OBSTACLE {
                grid.big.push(o as u32);
                continue;
            }
            for k in grid.indices(&range) {
                count[k + 1] += 1;
            }
            placed.push((o as u32, range));
        }
        for k in 0..ncells {
            count[k + 1] += count[k];
        }
        let mut next = count.clone();
        grid.items = vec![0; count[ncells] as usize];
        for (o, range) in &placed {
            for k in grid.indices(range) {
                grid.items[next[k] as usize] = *o;
                next[k] += 1;
            }
        }
        grid.start = count;
        Some(grid)
    }

    /// The cells a box overlaps, clamped into the grid.
    fn cells(&self, lo: &Point3<f64>, hi: &Point3<f64>) -> Overlap {
        let mut out = [0..=0, 0..=0, 0..=0];
        for i in 0..3 {
            let (a, b) = ((lo[i] - self.origin[i]) * self.inv_cell, (hi[i] - self.origin[i]) * self.inv_cell);
            if !(a.is_finite() && b.is_finite()) {
                return Overlap::Unknown;
            }
            let last = (self.dims[i] - 1) as f64;
            if b < 0.0 || a > last + 1.0 {
                return Overlap::Outside;
            }
            out[i] = (a.floor().clamp(0.0, last) as usize)..=(b.floor().clamp(0.0, last) as usize);
        }
        Overlap::Cells(out)
    }

    fn indices(&self, range: &[std::ops::RangeInclusive<usize>; 3]) -> impl Iterator<Item = usize> + use<> {
        let [x, y, z] = range.clone();
        let (dx, dy) = (self.dims[0], self.dims[1]);
        z.flat_map(move |k| {
            let (x, y) = (x.clone(), y.clone());
            y.flat_map(move |j| x.clone().map(move |i| (k * dy + j) * dx + i))
        })
    }

    /// Every obstacle whose cells overlap the box `lo`-`hi`, and every obstacle on the short list
    /// of large ones, some perhaps more than once; every obstacle when the box is not finite
    /// (`all` obstacles in the scene).
    pub(crate) fn near(
        &self,
        lo: &Point3<f64>,
        hi: &Point3<f64>,
        all: usize,
        mut visit: impl FnMut(u32) -> bool,
    ) -> bool {
        for &o in &self.big {
            if !visit(o) {
                return false;
            }
        }
        match self.cells(lo, hi) {
            Overlap::Outside => {}
            Overlap::Unknown => {
                for o in 0..all as u32 {
                    if !visit(o) {
                        return false;
                    }
                }
            }
            Overlap::Cells([x, y, z]) => {
                let (dx, dy) = (self.dims[0], self.dims[1]);
                for k in z {
                    for j in y.clone() {
                        let row = (k * dy + j) * dx;
                        let cells = row + x.start()..row + x.end() + 1;
                        let (from, to) = (self.start[cells.start] as usize, self.start[cells.end] as usize);
                        // The cells of a row are stored one after another: one slice for the row.
                        for &o in &self.items[from..to] {
                            if !visit(o) {
                                return false;
                            }
                        }
                    }
                }
            }
        }
        true
    }
}
