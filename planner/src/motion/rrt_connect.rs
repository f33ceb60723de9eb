//! Bidirectional RRT-Connect (Kuffner and LaValle, 2000): one tree grows from the start, one
//! from every goal at once; each iteration extends one tree a step towards a random sample and
//! lets the other tree run straight at the new node; the trees swap roles every iteration.

use embodied_models::{ConfigSpace, Rng};

use super::validity::{Budget, Validity};
use super::{MotionSettings, MotionStats, Search};

/// A tree of configurations stored flat (`dof` values per node), with parent links.
struct Tree {
    dof: usize,
    coords: Vec<f64>,
    parent: Vec<u32>,
}

const ROOT: u32 = u32::MAX;

impl Tree {
    fn new(dof: usize) -> Self {
        Self { dof, coords: Vec::new(), parent: Vec::new() }
    }
    fn len(&self) -> usize {
        self.parent.len()
    }
    fn node(&self, i: usize) -> &[f64] {
        &self.coords[i * self.dof..(i + 1) * self.dof]
    }
    fn push(&mut self, q: &[f64], parent: u32) -> usize {
        self.coords.extend_from_slice(q);
        self.parent.push(parent);
        self.len() - 1
    }
    fn nearest(&self, space: &ConfigSpace, q: &[f64]) -> usize {
        let mut best = (f64::INFINITY, 0);
        for i in 0..self.len() {
            let d = space.distance_squared(self.node(i), q);
            if d < best.0 {
                best = (d, i);
            }
        }
        best.1
    }
    /// Root-to-node path.
    fn path_to(&self, mut i: usize) -> Vec<Vec<f64>> {
        let mut out = vec![self.node(i).to_vec()];
        while self.parent[i] != ROOT {
            i = self.parent[i] as usize;
            out.push(self.node(i).to_vec());
        }
        out.reverse();
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

/// One extension of `tree` from its node nearest to `target` by at most `range`.
fn extend(
    tree: &mut Tree,
    validity: &mut Validity<'_>,
    target: &[f64],
    range: f64,
    from: Option<usize>,
    buf: &mut Vec<f64>,
) -> Step {
    let near = from.unwrap_or_else(|| tree.nearest(&validity.space, target));
    let d = validity.space.distance(tree.node(near), target);
    let reached = d <= range;
    buf.clear();
    buf.resize(tree.dof, 0.0);
    if reached {
        validity.space.interpolate_into(tree.node(near), target, 1.0, buf);
    } else {
        validity.space.interpolate_into(tree.node(near), target, range / d, buf);
        if !validity.config_free(buf) {
            return Step::Trapped;
        }
    }
    let q_near = tree.node(near).to_vec();
    if !validity.segment_free(&q_near, buf) {
        return Step::Trapped;
    }
    let i = tree.push(buf, near as u32);
    if reached { Step::Reached(i) } else { Step::Advanced(i) }
}

/// Plan from `start` to any of `goals` (all valid). The path runs start -> goal.
pub(crate) fn plan(
    validity: &mut Validity<'_>,
    budget: &mut Budget<'_>,
    rng: &mut Rng,
    start: &[f64],
    goals: &[Vec<f64>],
    settings: &MotionSettings,
    stats: &mut MotionStats,
) -> Search<Vec<Vec<f64>>> {
    let robot = validity.model.robot();
    let dof = robot.dof();
    let range = if settings.rrt_range.is_finite() && settings.rrt_range > 0.0 { settings.rrt_range } else { 1.0 };
    let mut from_start = Tree::new(dof);
    from_start.push(start, ROOT);
    let mut from_goal = Tree::new(dof);
    for g in goals {
        from_goal.push(g, ROOT);
    }
    let mut sample = vec![0.0; dof];
    let mut buf = Vec::with_capacity(dof);
    let mut connect_buf = Vec::with_capacity(dof);
    let mut start_is_a = true;
    loop {
        if stats.samples >= settings.max_samples {
            return Search::Exhausted;
        }
        if budget.spend(1) {
            return Search::OutOfTime;
        }
        stats.samples += 1;
        robot.random_configuration_into(rng, &mut sample);
        let (a, b) = if start_is_a { (&mut from_start, &mut from_goal) } else { (&mut from_goal, &mut from_start) };
        let new = match extend(a, validity, &sample, range, None, &mut buf) {
            Step::Trapped => None,
            Step::Reached(i) | Step::Advanced(i) => Some(i),
        };
        if let Some(new) = new {
            let target = a.node(new).to_vec();
            // Connect: b runs straight at the new node until it gets there or is blocked.
            let mut from = None;
            loop {
                match extend(b, validity, &target, range, from, &mut connect_buf) {
                    Step::Reached(j) => {
                        let (si, gi) = if start_is_a { (new, j) } else { (j, new) };
                        let mut path = from_start.path_to(si);
                        let mut tail = from_goal.path_to(gi);
                        tail.reverse();
                        // The meeting configuration appears at the end of one half and the
                        // start of the other.
                        tail.remove(0);
                        path.extend(tail);
                        return Search::Found(path);
                    }
                    Step::Advanced(j) => from = Some(j),
                    Step::Trapped => break,
                }
                if budget.spend(1) {
                    return Search::OutOfTime;
                }
            }
        }
        start_is_a = !start_is_a;
    }
}
