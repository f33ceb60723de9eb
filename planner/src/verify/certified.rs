//! The certificate behind [`super::Mode::Certified`]: continuous collision freedom with a
//! distance certificate, and the closed-chain constraint, for one agent's timed trajectory.
//!
//! It shares no code path with the planner's validity checks (`certify`, `motion_is_free`,
//! `collides`): it poses the robot's shapes itself from [`Robot::forward_kinematics`], measures
//! every pair with the narrow-phase primitive [`shape_separation`], and bounds motion with
//! [`CollisionModel::travel_bounds`] (a configuration-independent bound from the kinematic
//! chain). The pairs it checks are every shape-carrying link against every obstacle and the
//! model's self-collision pairs ([`CollisionModel::self_collision_pairs`]).
//!
//! # The certificate
//! The geometric path is the polyline through the trajectory's samples (straight joint-space
//! segments, the short way round on continuous joints), which is exactly the motion of a
//! trajectory sampled at every knot of a piecewise-constant acceleration profile.
//!
//! For a pair `p` let `D_p(q)` be a lower bound on its distance at `q` (the exact signed distance
//! when the pair's bounding spheres are within [`CheckSettings::exact_within`], else the bounding
//! sphere gap), and `T_p(qa, qb)` a bound on how much its distance can shrink along the straight
//! motion `qa -> qb`: the link's travel bound for a link against an obstacle, the sum of both
//! links' travel bounds for a self-collision pair (both bodies move). Travel bounds add along a
//! polyline and split proportionally along a straight segment. Then:
//!
//! * **one end**: every point of the polyline from `qa` to `qb` is free if `D_p(qa) > T_p` for
//!   every pair (the distance cannot shrink by more than `T_p`). The checker walks the samples from
//!   an *anchor* sample, summing travel bounds, as long as this holds; then it re-anchors.
//! * **two ends**: a segment `qa -> qb` is free if `D_p(qa) + D_p(qb) > T_p` for every pair with
//!   both distances positive: at fraction `s` the distance is at least
//!   `max(D_a - s T, D_b - (1 - s) T)`, and both terms can be non-positive only if
//!   `D_a + D_b <= T`. A segment that fails both tests is bisected at its midpoint `qm` (each half
//!   again tested with both of its ends) until every piece is certified, a midpoint is in
//!   collision (reported with its time, joint values, pair and penetration depth), or the depth
//!   or evaluation cap is hit (reported as *not certified*, with where).
//!
//! A collision found at a bisection midpoint is reported at the time interpolated linearly
//! between the segment's sample times (exact to within one sample interval).
//!
//! Self-collision pairs leave out the DOFs that drive only their common ancestors: those move
//! both links rigidly together and cannot change the pair's distance.
//!
//! Touching counts as collision (`D <= 0`). The certified clearance reported is the smallest
//! lower bound on the distance these inequalities give over the whole path.

use std::time::Instant;

use super::EvaluationBudget;
use super::finding::Finding;
use super::report::{CheckSettings, ClosureReport, CollisionReport};
use crate::carry::ClosedChainSpan;
use crate::trajectory::Trajectory;
use embodied_models::ConfigSpace;
use embodied_models::Robot;
use embodied_models::collision::{CollisionModel, shape_separation};
use embodied_models::geometry::Shape;
use embodied_models::nalgebra::{Isometry3, Point3};

// ---------------------------------------------------------------------------------------------
// Collision certificate.

/// One side of a pair: a link with its shapes (local poses) or an obstacle (world poses).
#[derive(Debug, Clone)]
struct Side {
    name: String,
    /// Link index, or `None` for an obstacle.
    link: Option<usize>,
    shapes: Vec<(Isometry3<f64>, Shape, Point3<f64>, f64)>,
}

/// The pairs of a model, prepared once.
struct Pairs {
    sides: Vec<Side>,
    /// (side a, side b, link index of a, link index of b if b moves, offset of the pair's
    /// travel bounds in a travel vector).
    pairs: Vec<(usize, usize, usize, Option<usize>, usize)>,
    links: usize,
    /// For self-collision pairs: the DOFs that drive only joints carrying *both* links (their
    /// common ancestors). Those move the pair rigidly together, so they cannot bring it closer:
    /// the pair's travel bound leaves them out. A travel vector holds the links' world travel
    /// bounds, then one block of `links` bounds per mask (the motion without its frozen DOFs).
    masks: Vec<Vec<bool>>,
    space: ConfigSpace,
}

/// Distances of every pair at one configuration (lower bounds; exact when near).
struct Eval {
    d: Vec<f64>,
    /// The nearest pair and its (exact when near) distance.
    nearest: usize,
    min: f64,
}

impl Pairs {
    fn new(model: &CollisionModel) -> Self {
        let robot = model.robot();
        let mut sides = Vec::new();
        let mut link_side = vec![usize::MAX; robot.links().len()];
        for (l, link) in robot.links().iter().enumerate() {
            if link.shapes.is_empty() {
                continue;
            }
            link_side[l] = sides.len();
            sides.push(Side {
                name: format!("link `{}`", link.name),
                link: Some(l),
                shapes: link
                    .shapes
                    .iter()
                    .map(|ps| {
                        let (c, r) = ps.shape.bounding_sphere();
                        (ps.pose, ps.shape.clone(), c, r)
                    })
                    .collect(),
            });
        }
        let mut pairs = Vec::new();
        let moving: Vec<usize> = (0..sides.len()).collect();
        for o in model.environment().obstacles() {
            let (c, r) = o.shape.bounding_sphere();
            let side = sides.len();
            sides.push(Side {
                name: format!("obstacle `{}`", o.name),
                link: None,
                shapes: vec![(o.pose, o.shape.clone(), c, r)],
            });
            for &m in &moving {
                pairs.push((m, side, sides[m].link.unwrap_or(0), None, 0));
            }
        }
        let links = robot.links().len();
        let mut masks: Vec<Vec<bool>> = Vec::new();
        // With mimic joints a DOF may drive joints off the common chain: freeze nothing then.
        let mimic = robot.joints().iter().any(|j| j.mimic.is_some());
        for (a, b) in model.self_collision_pairs() {
            let (sa, sb) = (link_side[a], link_side[b]);
            if sa == usize::MAX || sb == usize::MAX {
                continue;
            }
            let (ca, cb) = (robot.chain_to(a), robot.chain_to(b));
            let mask: Vec<bool> =
                robot.dof_joints().iter().map(|j| !mimic && ca.contains(j) && cb.contains(j)).collect();
            let offset = if mask.iter().any(|&f| f) {
                let m = masks.iter().position(|x| *x == mask).unwrap_or_else(|| {
                    masks.push(mask);
                    masks.len() - 1
                });
                (m + 1) * links
            } else {
                0
            };
            pairs.push((sa, sb, a, Some(b), offset));
        }
        Pairs { sides, pairs, links, masks, space: robot.config_space() }
    }

    fn names(&self, p: usize) -> (String, String) {
        let (a, b, _, _, _) = self.pairs[p];
        (self.sides[a].name.clone(), self.sides[b].name.clone())
    }

    /// World poses of every shape at `q` (obstacles: as given).
    fn pose(&self, robot: &Robot, q: &[f64]) -> Vec<Vec<(Isometry3<f64>, Point3<f64>)>> {
        let fk = robot.forward_kinematics(q);
        self.sides
            .iter()
            .map(|s| {
                s.shapes
                    .iter()
                    .map(|(pose, _, c, _)| {
                        let world = match s.link {
                            Some(l) => fk[l] * pose,
                            None => *pose,
                        };
                        (world, world * c)
                    })
                    .collect()
            })
            .collect()
    }

    fn eval(&self, robot: &Robot, q: &[f64], exact_within: f64) -> Eval {
        let posed = self.pose(robot, q);
        let mut d = Vec::with_capacity(self.pairs.len());
        let (mut nearest, mut min) = (0, f64::INFINITY);
        for (p, &(a, b, _, _, _)) in self.pairs.iter().enumerate() {
            let mut best = f64::INFINITY;
            for (i, (_, sa, _, ra)) in self.sides[a].shapes.iter().enumerate() {
                for (j, (_, sb, _, rb)) in self.sides[b].shapes.iter().enumerate() {
                    let (pa, ca) = &posed[a][i];
                    let (pb, cb) = &posed[b][j];
                    let bound = (ca - cb).norm() - ra - rb;
                    let value = if bound > exact_within { bound } else { shape_separation(sa, pa, sb, pb).distance };
                    best = best.min(value);
                }
            }
            if best < min {
                min = best;
                nearest = p;
            }
            d.push(best);
        }
        Eval { d, nearest, min }
    }

    /// Length of a travel vector.
    fn width(&self) -> usize {
        self.links * (1 + self.masks.len())
    }

    /// Travel bounds of `qa -> qb` (see [`Pairs::masks`]), indexed by offset + link.
    fn travel(&self, model: &CollisionModel, qa: &[f64], qb: &[f64], out: &mut Vec<f64>) {
        out.clear();
        out.resize(self.width(), 0.0);
        let steps: Vec<f64> =
            qa.iter().zip(qb).enumerate().map(|(i, (a, b))| self.space.delta(i, *a, *b).abs()).collect();
        model.travel_bounds_of_steps(&steps, &mut out[..self.links]);
        let mut held = steps.clone();
        for (m, mask) in self.masks.iter().enumerate() {
            // The same motion with the frozen DOFs held: only the others count.
            for ((h, s), &frozen) in held.iter_mut().zip(&steps).zip(mask) {
                *h = if frozen { 0.0 } else { *s };
            }
            model.travel_bounds_of_steps(&held, &mut out[(m + 1) * self.links..(m + 2) * self.links]);
        }
    }

    fn pair_travel(&self, p: usize, travel: &[f64]) -> f64 {
        let (_, _, la, lb, offset) = self.pairs[p];
        match lb {
            Some(b) => travel[offset + la] + travel[offset + b],
            None => travel[la],
        }
    }
}

/// A margin strictly above a travel bound, against rounding.
fn above(t: f64) -> f64 {
    t * (1.0 + 1e-9) + 1e-12
}

struct Walk<'a> {
    model: &'a CollisionModel,
    pairs: Pairs,
    settings: &'a CheckSettings,
    /// The clearance required (m): distances are certified above it, not above zero.
    tolerance: f64,
    report: CollisionReport,
    scratch: Vec<f64>,
    /// The verification's evaluations left.
    budget: &'a mut EvaluationBudget,
    /// The segment being checked: its index and its end times.
    segment: (usize, f64, f64),
}

impl Walk<'_> {
    fn eval(&mut self, q: &[f64]) -> Result<Eval, Box<Finding>> {
        if !self.budget.allows() {
            let (segment, t_from, t_to) = self.segment;
            return Err(Box::new(Finding::BudgetExhausted {
                budget: self.budget.limit.unwrap_or(usize::MAX),
                segment,
                t_from,
                t_to,
                agent: String::new(),
            }));
        }
        self.budget.used += 1;
        self.report.distance_evaluations += 1;
        let mut e = self.pairs.eval(self.model.robot(), q, self.settings.exact_within);
        if e.min < self.report.min_clearance_m {
            self.report.min_clearance_m = e.min;
            let (a, b) = self.pairs.names(e.nearest);
            self.report.closest_pair = Some([a, b]);
        }
        // The certificate proves every distance above the required clearance.
        if self.tolerance > 0.0 {
            e.d.iter_mut().for_each(|d| *d -= self.tolerance);
            e.min -= self.tolerance;
        }
        Ok(e)
    }

    /// Make segment `k` (samples `k` to `k + 1`, or the single sample) the one being checked.
    fn at_segment(&mut self, t: &[f64], k: usize) {
        self.segment = (k, t[k], t[(k + 1).min(t.len() - 1)]);
    }

    fn collision(&self, t: f64, q: &[f64], e: &Eval) -> Option<Box<Finding>> {
        if e.min > 0.0 {
            return None;
        }
        let (a, b) = self.pairs.names(e.nearest);
        let distance = e.min + self.tolerance;
        Some(Box::new(if distance <= 0.0 {
            Finding::Collision { t, q: q.to_vec(), a, b, penetration_m: -distance }
        } else {
            Finding::TooClose { t, q: q.to_vec(), a, b, distance_m: distance, required_m: self.tolerance }
        }))
    }

    /// Certify samples `i0..=i1` of the trajectory (one model throughout).
    fn run(&mut self, t: &[f64], q: &[Vec<f64>], i0: usize, i1: usize) -> Result<(), Box<Finding>> {
        let mut anchor = i0;
        self.at_segment(t, i0);
        let mut da = self.eval(&q[i0])?;
        if let Some(f) = self.collision(t[i0], &q[i0], &da) {
            return Err(f);
        }
        let mut acc = vec![0.0; self.pairs.width()];
        let mut seg = Vec::new();
        let mut k = i0;
        while k < i1 {
            self.at_segment(t, k);
            self.pairs.travel(self.model, &q[k], &q[k + 1], &mut seg);
            let mut lowest = f64::INFINITY;
            let mut ok = true;
            for (p, d) in da.d.iter().enumerate() {
                let total: f64 = self.pairs.pair_travel(p, &acc) + self.pairs.pair_travel(p, &seg);
                // Extend from the anchor while half the clearance is left (so that the certified
                // clearance means something); the bare certificate needs only `d > total`.
                if *d <= above(total) || (total > 0.0 && *d - total < 0.5 * d) {
                    ok = false;
                    break;
                }
                lowest = lowest.min(d - total);
            }
            if ok {
                acc.iter_mut().zip(&seg).for_each(|(a, s)| *a += s);
                self.report.certified_segments += 1;
                self.report.certified_clearance_m = self.report.certified_clearance_m.min(lowest + self.tolerance);
                k += 1;
                continue;
            }
            if anchor != k {
                anchor = k;
                da = self.eval(&q[k])?;
                if let Some(f) = self.collision(t[k], &q[k], &da) {
                    return Err(f);
                }
                acc.iter_mut().for_each(|a| *a = 0.0);
                continue;
            }
            // One end does not cover the segment: measure the other end and bisect.
            let db = self.eval(&q[k + 1])?;
            if let Some(f) = self.collision(t[k + 1], &q[k + 1], &db) {
                return Err(f);
            }
            let mut budget = self.settings.max_evaluations_per_segment;
            let (qa, qb) = (q[k].clone(), q[k + 1].clone());
            self.bisect((t[k], &qa, &da), (t[k + 1], &qb, &db), 0, &mut budget)?;
            self.report.certified_segments += 1;
            anchor = k + 1;
            da = db;
            acc.iter_mut().for_each(|a| *a = 0.0);
            k += 1;
        }
        Ok(())
    }

    /// Certify the straight segment between two measured ends, bisecting as needed.
    fn bisect(
        &mut self,
        (ta, qa, da): (f64, &[f64], &Eval),
        (tb, qb, db): (f64, &[f64], &Eval),
        depth: u32,
        budget: &mut usize,
    ) -> Result<(), Box<Finding>> {
        self.report.max_depth = self.report.max_depth.max(depth);
        let mut travel = std::mem::take(&mut self.scratch);
        self.pairs.travel(self.model, qa, qb, &mut travel);
        let mut lowest = f64::INFINITY;
        let mut ok = true;
        for p in 0..da.d.len() {
            let tp = self.pairs.pair_travel(p, &travel);
            let (a, b) = (da.d[p], db.d[p]);
            if a + b <= above(tp) {
                ok = false;
                break;
            }
            lowest = lowest.min(((a + b - tp) / 2.0).max(a - tp).max(b - tp));
        }
        self.scratch = travel;
        if ok {
            self.report.certified_clearance_m = self.report.certified_clearance_m.min(lowest + self.tolerance);
            return Ok(());
        }
        if depth >= self.settings.max_depth || *budget == 0 {
            let e = if da.min <= db.min { da } else { db };
            let (a, b) = self.pairs.names(e.nearest);
            let reason = if depth >= self.settings.max_depth {
                format!("bisection depth cap {} reached", self.settings.max_depth)
            } else {
                format!("evaluation cap {} reached", self.settings.max_evaluations_per_segment)
            };
            return Err(Box::new(Finding::NotCertified {
                t_from: ta,
                t_to: tb,
                q_from: qa.to_vec(),
                q_to: qb.to_vec(),
                a,
                b,
                clearance_m: e.min + self.tolerance,
                reason,
            }));
        }
        *budget -= 1;
        self.report.subdivisions += 1;
        let qm = self.pairs.space.interpolate(qa, qb, 0.5);
        let tm = 0.5 * (ta + tb);
        let dm = self.eval(&qm)?;
        if let Some(f) = self.collision(tm, &qm, &dm) {
            return Err(f);
        }
        self.bisect((ta, qa, da), (tm, &qm, &dm), depth + 1, budget)?;
        self.bisect((tm, &qm, &dm), (tb, qb, db), depth + 1, budget)
    }
}

/// The model a closed-chain span's collisions are checked with: the object attached.
fn span_model(model: &CollisionModel, span: &ClosedChainSpan) -> Result<Option<CollisionModel>, String> {
    let Some(object) = &span.object else { return Ok(None) };
    let robot = model.robot();
    let [e0, e1] = ee_indices(robot, span)?;
    let touching = robot.end_effectors()[e1].link;
    let attached = object
        .attach(robot, e0, &[touching])
        .ok_or_else(|| format!("object `{}` cannot be attached (bad size or pose)", object.name))?;
    Ok(Some(CollisionModel::new(&attached, model.environment().clone())))
}

fn ee_indices(robot: &Robot, span: &ClosedChainSpan) -> Result<[usize; 2], String> {
    let find = |name: &str| {
        robot.end_effectors().iter().position(|e| e.name == name).ok_or_else(|| {
            let names: Vec<&str> = robot.end_effectors().iter().map(|e| e.name.as_str()).collect();
            format!("robot `{}` has no end effector `{name}` (it has: {})", robot.name(), names.join(", "))
        })
    };
    Ok([find(&span.end_effectors[0])?, find(&span.end_effectors[1])?])
}

/// For each sample-to-sample segment of `traj`, the model its collisions are checked with: an
/// index into the returned models (the span's, object attached) when the segment overlaps a
/// closed-chain span with an object, else `usize::MAX` (the plain model).
pub(crate) fn segment_models(
    model: &CollisionModel,
    traj: &Trajectory,
    spans: &[ClosedChainSpan],
) -> Result<(Vec<CollisionModel>, Vec<usize>), String> {
    let n = traj.t.len();
    let mut models: Vec<CollisionModel> = Vec::new();
    let mut which = vec![usize::MAX; n.saturating_sub(1)];
    for span in spans {
        if let Some(m) = span_model(model, span)? {
            models.push(m);
            let id = models.len() - 1;
            for (k, w) in which.iter_mut().enumerate() {
                if traj.t[k + 1] > span.from_s && traj.t[k] < span.to_s {
                    *w = id;
                }
            }
        }
    }
    Ok((models, which))
}

/// Certify the polyline through the trajectory's samples free of collisions, every pair at
/// least `tolerance` (m) apart (0: touching counts as collision).
pub(crate) fn certify_collisions(
    model: &CollisionModel,
    traj: &Trajectory,
    spans: &[ClosedChainSpan],
    settings: &CheckSettings,
    tolerance: f64,
    budget: &mut EvaluationBudget,
) -> CollisionReport {
    let start = Instant::now();
    let n = traj.t.len();
    let plain = Pairs::new(model);
    let mut report = CollisionReport {
        ok: true,
        violation: None,
        segments: n.saturating_sub(1),
        certified_segments: 0,
        distance_evaluations: 0,
        subdivisions: 0,
        max_depth: 0,
        pairs: plain.pairs.len(),
        min_clearance_m: f64::INFINITY,
        certified_clearance_m: f64::INFINITY,
        closest_pair: None,
        time_s: 0.0,
    };
    // Which model each segment uses: the span's (object attached) when the segment overlaps a
    // span with an object, else the plain one. Runs of segments with one model are walked.
    let (models, which) = match segment_models(model, traj, spans) {
        Ok(m) => m,
        Err(message) => {
            report.ok = false;
            report.violation = Some(Finding::Malformed { message });
            report.time_s = start.elapsed().as_secs_f64();
            return report;
        }
    };
    let mut result = Ok(());
    if n == 1 {
        let mut walk = Walk {
            model,
            pairs: plain,
            settings,
            tolerance,
            report,
            scratch: Vec::new(),
            budget,
            segment: (0, 0.0, 0.0),
        };
        result = walk.run(&traj.t, &traj.q, 0, 0);
        report = walk.report;
    } else {
        let mut i = 0;
        let mut plain = Some(plain);
        while i + 1 < n && result.is_ok() {
            let id = which[i];
            let mut j = i + 1;
            while j + 1 < n && which[j] == id {
                j += 1;
            }
            let (m, pairs) = if id == usize::MAX {
                (model, plain.take().unwrap_or_else(|| Pairs::new(model)))
            } else {
                (&models[id], Pairs::new(&models[id]))
            };
            let mut walk = Walk {
                model: m,
                pairs,
                settings,
                tolerance,
                report,
                scratch: Vec::new(),
                budget: &mut *budget,
                segment: (i, 0.0, 0.0),
            };
            result = walk.run(&traj.t, &traj.q, i, j);
            report = walk.report;
            if id == usize::MAX {
                plain = Some(walk.pairs);
            }
            i = j;
        }
    }
    if let Err(f) = result {
        report.ok = false;
        report.violation = Some(*f);
    }
    report.time_s = start.elapsed().as_secs_f64();
    report
}

// ---------------------------------------------------------------------------------------------
// Closed chain.

/// Pose of end effector `e1`'s tool frame in `e0`'s tool frame.
fn relative_tool_pose(robot: &Robot, q: &[f64], e0: usize, e1: usize) -> Isometry3<f64> {
    let (_, t0) = robot.end_effector_poses(q, e0);
    let (_, t1) = robot.end_effector_poses(q, e1);
    t0.inverse() * t1
}

/// Position and angle error of `pose` against `reference`.
pub fn pose_error(reference: &Isometry3<f64>, pose: &Isometry3<f64>) -> (f64, f64) {
    let dp = (pose.translation.vector - reference.translation.vector).norm();
    let da = reference.rotation.rotation_to(&pose.rotation).angle();
    (dp, da)
}

/// At every sample in each span, the relative tool pose stays within tolerance of its value at
/// the span's first sample (the first at or after `from_s`).
pub fn check_closure(robot: &Robot, traj: &Trajectory, spans: &[ClosedChainSpan]) -> ClosureReport {
    let start = Instant::now();
    let mut report = ClosureReport {
        ok: true,
        violation: None,
        spans: spans.len(),
        samples: 0,
        max_position_error_m: 0.0,
        max_angle_error_rad: 0.0,
        time_s: 0.0,
    };
    let mut first: Option<Finding> = None;
    for (s, span) in spans.iter().enumerate() {
        let bad = |message: String| Finding::Malformed { message: format!("closed-chain span {s}: {message}") };
        let [e0, e1] = match ee_indices(robot, span) {
            Ok(e) => e,
            Err(m) => {
                first.get_or_insert(bad(m));
                continue;
            }
        };
        if !(span.from_s <= span.to_s && span.tolerance_m >= 0.0 && span.tolerance_rad >= 0.0) {
            first.get_or_insert(bad(format!(
                "from_s {} .. to_s {} with tolerances {} m, {} rad is not a span",
                span.from_s, span.to_s, span.tolerance_m, span.tolerance_rad
            )));
            continue;
        }
        let eps = 1e-9;
        let inside: Vec<usize> =
            (0..traj.t.len()).filter(|&k| traj.t[k] >= span.from_s - eps && traj.t[k] <= span.to_s + eps).collect();
        let Some(&k0) = inside.first() else {
            first.get_or_insert(bad(format!("no sample in [{}, {}] s", span.from_s, span.to_s)));
            continue;
        };
        let reference = relative_tool_pose(robot, &traj.q[k0], e0, e1);
        let mut span_first = None;
        for &k in &inside {
            report.samples += 1;
            let (dp, da) = pose_error(&reference, &relative_tool_pose(robot, &traj.q[k], e0, e1));
            report.max_position_error_m = report.max_position_error_m.max(dp);
            report.max_angle_error_rad = report.max_angle_error_rad.max(da);
            if span_first.is_none() && (dp > span.tolerance_m || da > span.tolerance_rad) {
                span_first = Some(Finding::ClosureDrift {
                    t: traj.t[k],
                    span: s,
                    position_error_m: dp,
                    angle_error_rad: da,
                    tolerance_m: span.tolerance_m,
                    tolerance_rad: span.tolerance_rad,
                });
            }
        }
        if let Some(f) = span_first {
            let earlier = match (&first, &f) {
                (Some(Finding::ClosureDrift { t: t0, .. }), Finding::ClosureDrift { t, .. }) => t < t0,
                (None, _) => true,
                _ => false,
            };
            if earlier {
                first = Some(f);
            }
        }
    }
    report.ok = first.is_none();
    report.violation = first;
    report.time_s = start.elapsed().as_secs_f64();
    report
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use embodied_models::collision::{Environment, Obstacle};
    use embodied_models::{Rng, Shape, builtin};

    use super::*;

    fn two_samples(robot: &Robot, qa: Vec<f64>, qb: Vec<f64>) -> Trajectory {
        Trajectory { joint_names: robot.joint_names(), t: vec![0.0, 1.0], q: vec![qa, qb], qd: vec![] }
    }

    /// Whatever the certificate says is checked against the model's own sampled queries: a
    /// certified segment has no colliding sample, a reported collision is one.
    #[test]
    fn certificate_agrees_with_dense_sampling() {
        for name in ["irp6-postument", "polycrank", "two-irp6"] {
            let robot = builtin(name).unwrap();
            let env = Environment::new()
                .with(Obstacle::new("pillar", Isometry3::translation(0.6, 0.4, 0.5), Shape::cuboid(0.08, 0.08, 0.5)))
                .with(Obstacle::new("ball", Isometry3::translation(-0.5, 0.3, 1.0), Shape::sphere(0.15)))
                // In front of the IRp-6 arms, where their screws' strokes let them go.
                .with(Obstacle::new("block", Isometry3::translation(0.8, 0.0, 1.1), Shape::cuboid(0.1, 0.3, 0.1)));
            let model = CollisionModel::new(&robot, env);
            let space = robot.config_space();
            let mut rng = Rng::new(7);
            let mut random = || robot.random_configuration(&mut rng);
            let (mut certified, mut collisions) = (0, 0);
            for _ in 0..60 {
                let qa = random();
                let dir = random();
                // Short and long segments.
                let qb = space.interpolate(&qa, &dir, 0.3);
                let r = certify_collisions(
                    &model,
                    &two_samples(&robot, qa.clone(), qb.clone()),
                    &[],
                    &CheckSettings::default(),
                    0.0,
                    &mut EvaluationBudget::new(None),
                );
                // A budget of what it spent changes nothing; one less, and it is not certified.
                let with_budget = |limit: usize| {
                    certify_collisions(
                        &model,
                        &two_samples(&robot, qa.clone(), qb.clone()),
                        &[],
                        &CheckSettings::default(),
                        0.0,
                        &mut EvaluationBudget::new(Some(limit)),
                    )
                };
                let same = with_budget(r.distance_evaluations);
                assert_eq!((same.ok, &same.violation), (r.ok, &r.violation), "{name}");
                let short = with_budget(r.distance_evaluations - 1);
                assert!(
                    !short.ok && matches!(short.violation, Some(Finding::BudgetExhausted { .. })),
                    "{name}: {:?}",
                    short.violation
                );
                match &r.violation {
                    None => {
                        certified += 1;
                        for k in 0..=400 {
                            let q = space.interpolate(&qa, &qb, k as f64 / 400.0);
                            assert!(!model.collides(&q), "{name}: certified segment collides at {}", k as f64 / 400.0);
                        }
                        assert!(r.certified_clearance_m > 0.0);
                    }
                    Some(Finding::Collision { q, penetration_m, .. }) => {
                        collisions += 1;
                        assert!(model.collides(q), "{name}: reported collision is free");
                        assert!(*penetration_m >= 0.0);
                    }
                    Some(f) => panic!("{name}: {f}"),
                }
            }
            assert!(certified > 5 && collisions > 5, "{name}: {certified} certified, {collisions} collisions");
        }
    }
}
