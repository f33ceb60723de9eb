//! Random shortcutting: replace the stretch between two random points of the path by the
//! straight segment between them when that segment is free. Anytime: stops at the deadline
//! with the (valid) path it has.

use embodied_models::Rng;

use crate::deadline::Budget;
use crate::validity::{StateValidity, Validity};

/// Shorten `path` with the greedy pass (when `greedy`: lazy RRT-Connect has run it already)
/// and up to `attempts` shortcut tries between random points of the path (vertices or points
/// inside segments), each checked only if it would shorten the path by at least `min_gain`
/// times its length (see [`super::MotionSettings::shortcut_min_gain`]).
pub(crate) fn shortcut<V: StateValidity>(
    mut path: Vec<Vec<f64>>,
    validity: &mut Validity<'_, V>,
    budget: &mut Budget<'_>,
    rng: &mut Rng,
    greedy: bool,
    (attempts, min_gain): (usize, f64),
) -> Vec<Vec<f64>> {
    if greedy {
        path = greedy_pass(path, validity, budget);
    }
    let space = validity.space.clone();
    let mut length: f64 = path.windows(2).map(|w| space.distance(&w[0], &w[1])).sum();
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
        let gain = old - space.distance(&p1, &p2);
        if gain <= 1e-9 || gain < min_gain * length {
            continue;
        }
        // Certified segments are free at every point, so `p1` and `p2` are: then the new
        // segment's certificate (which covers its ends too) is the only check (checking them
        // alone first cost about 2% of the planning instructions on the public
        // MotionBenchMaker UR5 problems). Sampled segments may hide a collision between samples.
        let ends_free = validity.certifies() || (validity.config_free(&p1) && validity.config_free(&p2));
        if !ends_free {
            continue;
        }
        if validity.segment_free_screened(&p1, &p2) {
            // Path: ..path[s1], p1, p2, path[s2+1]..
            let mut next = Vec::with_capacity(path.len());
            next.extend(path[..=s1].iter().cloned());
            next.push(p1);
            next.push(p2);
            next.extend(path[s2 + 1..].iter().cloned());
            next.dedup_by(|a, b| space.distance(a, b) < 1e-12);
            path = next;
            length -= gain;
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
        if validity.segment_free_screened(&path[i], &path[j]) {
            return Ok(Some(j));
        }
    }
    Ok(None)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::deadline::Deadline;
    use crate::motion::{EdgeCheck, polycrank_by_a_post};

    /// With certified segments the shortcuts check no end point alone: every segment of the
    /// shortened path still certifies (its ends included), the path keeps its ends and gets no
    /// longer, and some shortcut was taken.
    #[test]
    fn certified_shortcuts_keep_every_segment_certified() {
        let (robot, model) = polycrank_by_a_post();
        let mut rng = Rng::new(5);
        let (mut taken, mut paths) = (0, 0);
        for _ in 0..10 {
            let mut validity = Validity::new(&model, 0.05).with_edge_check(EdgeCheck::Certified { tolerance: 1e-3 });
            assert!(validity.certifies());
            // A zigzag of certified segments between free configurations.
            let mut path = vec![robot.random_configuration(&mut rng)];
            let mut tries = 0;
            while path.len() < 5 {
                tries += 1;
                assert!(tries < 100_000, "no free zigzag found");
                let q = robot.random_configuration(&mut rng);
                let last = path.last().expect("a start");
                if validity.config_free(&q) && validity.segment_free(last, &q) {
                    path.push(q);
                }
                if !validity.config_free(&path[0]) {
                    path = vec![robot.random_configuration(&mut rng)];
                }
            }
            let space = validity.space.clone();
            let length = |p: &[Vec<f64>]| p.windows(2).map(|w| space.distance(&w[0], &w[1])).sum::<f64>();
            let deadline = Deadline::none();
            let mut budget = Budget::new(&deadline);
            let short = shortcut(path.clone(), &mut validity, &mut budget, &mut rng, false, (20, 0.0));
            assert_eq!((short.first(), short.last()), (path.first(), path.last()));
            assert!(length(&short) <= length(&path) + 1e-9);
            for w in short.windows(2) {
                assert!(model.motion_is_certified_free(&w[0], &w[1], 1e-3), "{:?} -> {:?}", w[0], w[1]);
            }
            taken += usize::from(short.len() != path.len() || length(&short) < length(&path) - 1e-9);
            paths += 1;
            // No shortcut can gain the whole length: none is checked, the path stays.
            let edges = validity.edges_checked;
            let kept = shortcut(short.clone(), &mut validity, &mut budget, &mut rng, false, (20, 1.0));
            assert_eq!(kept, short);
            assert_eq!(validity.edges_checked, edges, "a shortcut below the least gain was checked");
        }
        assert!(taken > paths / 4, "shortcuts taken on {taken} of {paths} paths");
    }
}
