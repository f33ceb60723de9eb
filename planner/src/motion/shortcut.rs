//! Random shortcutting: replace the stretch between two random points of the path by the
//! straight segment between them when that segment is free. Anytime: stops at the deadline
//! with the (valid) path it has.

use embodied_models::Rng;

use crate::deadline::Budget;
use crate::validity::{StateValidity, Validity};

/// Shorten `path` with the greedy pass (when `greedy`: lazy RRT-Connect has run it already)
/// and up to `attempts` shortcut tries between random points of the path (vertices or points
/// inside segments).
pub(crate) fn shortcut<V: StateValidity>(
    mut path: Vec<Vec<f64>>,
    validity: &mut Validity<'_, V>,
    budget: &mut Budget<'_>,
    rng: &mut Rng,
    greedy: bool,
    attempts: usize,
) -> Vec<Vec<f64>> {
    if greedy {
        path = greedy_pass(path, validity, budget);
    }
    let space = validity.space.clone();
    for _ in 0..attempts {
        if path.len() < 3 || budget.spend(1, validity.collision_checks) {
            break;
        }
        // Two points on different segments: segment index and fraction along it.
        let n = path.len() - 1;
        let mut s1 = rng.below(n);
        let mut s2 = rng.below(n);
        if s1 == s2 {
            continue;
        }
        if s1 > s2 {
            std::mem::swap(&mut s1, &mut s2);
        }
        let (t1, t2) = (rng.uniform(), rng.uniform());
        let p1 = space.interpolate(&path[s1], &path[s1 + 1], t1);
        let p2 = space.interpolate(&path[s2], &path[s2 + 1], t2);
        let old = space.distance(&p1, &path[s1 + 1])
            + path[s1 + 1..=s2].windows(2).map(|w| space.distance(&w[0], &w[1])).sum::<f64>()
            + space.distance(&path[s2], &p2);
        if space.distance(&p1, &p2) >= old - 1e-9 {
            continue;
        }
        if !(validity.config_free(&p1) && validity.config_free(&p2)) {
            continue;
        }
        if validity.segment_free(&p1, &p2) {
            // Path: ..path[s1], p1, p2, path[s2+1]..
            let mut next = Vec::with_capacity(path.len());
            next.extend(path[..=s1].iter().cloned());
            next.push(p1);
            next.push(p2);
            next.extend(path[s2 + 1..].iter().cloned());
            next.dedup_by(|a, b| space.distance(a, b) < 1e-12);
            path = next;
        }
    }
    path
}

/// The greedy pass from the start: skip to the farthest directly visible vertex.
fn greedy_pass<V: StateValidity>(
    path: Vec<Vec<f64>>,
    validity: &mut Validity<'_, V>,
    budget: &mut Budget<'_>,
) -> Vec<Vec<f64>> {
    let mut i = 0;
    let mut greedy = vec![path[0].clone()];
    while i + 1 < path.len() {
        // Out of time: the rest of the path as it is.
        let next = farthest_visible(&path, i, validity, budget).ok().flatten().unwrap_or(i + 1);
        greedy.push(path[next].clone());
        i = next;
        if path.len() > 12 {
            // On long paths the quadratic greedy pass costs too much; random tries follow.
            greedy.extend(path[i + 1..].iter().cloned());
            break;
        }
    }
    greedy
}

/// The budget ran out.
pub(crate) struct OutOfTime;

/// The greedy pass's step from vertex `i`: the farthest vertex `j > i + 1` whose straight
/// segment from `path[i]` is free, tried farthest first (a failing segment stops at its first
/// hit and costs a few checks); `None` when none is.
pub(crate) fn farthest_visible<V: StateValidity>(
    path: &[Vec<f64>],
    i: usize,
    validity: &mut Validity<'_, V>,
    budget: &mut Budget<'_>,
) -> Result<Option<usize>, OutOfTime> {
    for j in (i + 2..path.len()).rev() {
        if budget.spend(1, validity.collision_checks) {
            return Err(OutOfTime);
        }
        if validity.segment_free(&path[i], &path[j]) {
            return Ok(Some(j));
        }
    }
    Ok(None)
}
