//! The certified plan checker: limits, continuous collision freedom with a distance
//! certificate, the closed-chain constraint and timing, for one agent's timed trajectory.
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

use embodied_models::ConfigSpace;
use embodied_models::Robot;
use embodied_models::collision::{CollisionModel, shape_separation};
use embodied_models::geometry::Shape;
use embodied_models::nalgebra::{Isometry3, Point3};
use serde::Serialize;

use crate::carry::ClosedChainSpan;
use crate::trajectory::Trajectory;

/// Tolerances and caps of the checker.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CheckSettings {
    /// Relative tolerance on velocity and acceleration limits (rounding in the profiles).
    pub limit_tolerance: f64,
    /// Absolute tolerance on joint position limits, rad or m.
    pub position_tolerance: f64,
    /// Pairs whose bounding spheres are closer than this (m) are measured exactly.
    pub exact_within: f64,
    /// Largest bisection depth of one sample-to-sample segment.
    pub max_depth: u32,
    /// Largest number of distance evaluations spent bisecting one segment.
    pub max_evaluations_per_segment: usize,
}

impl Default for CheckSettings {
    fn default() -> Self {
        CheckSettings {
            limit_tolerance: 1e-6,
            position_tolerance: 1e-9,
            exact_within: 0.2,
            max_depth: 30,
            max_evaluations_per_segment: 20_000,
        }
    }
}

/// The first thing wrong with a plan, and where. Times are seconds from the trajectory's start.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Finding {
    /// The trajectory itself is not well formed (lengths, DOF, non-finite values, time order,
    /// unknown end effectors).
    Malformed { message: String },
    /// A joint outside its position limits.
    Position { t: f64, joint: String, value: f64, lower: f64, upper: f64, excess: f64 },
    /// A joint faster than its velocity limit; `source`: `qd` (the stated velocity) or
    /// `finite difference of q`.
    Velocity { t: f64, joint: String, value: f64, limit: f64, excess: f64, source: String },
    /// A joint accelerating harder than its limit (finite difference of the stated `qd`).
    Acceleration { t: f64, joint: String, value: f64, limit: f64, excess: f64 },
    /// A configuration on the path in collision: the pair and how deep (m, >= 0).
    Collision { t: f64, q: Vec<f64>, a: String, b: String, penetration_m: f64 },
    /// A piece of the path that the certificate could neither prove free nor show in collision
    /// within the caps: the piece, and the pair closest at its ends.
    NotCertified {
        t_from: f64,
        t_to: f64,
        q_from: Vec<f64>,
        q_to: Vec<f64>,
        a: String,
        b: String,
        clearance_m: f64,
        reason: String,
    },
    /// The pose of the second tool frame relative to the first drifted from its value at the
    /// start of the closed-chain span.
    ClosureDrift {
        t: f64,
        span: usize,
        position_error_m: f64,
        angle_error_rad: f64,
        tolerance_m: f64,
        tolerance_rad: f64,
    },
}

impl std::fmt::Display for Finding {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Finding::Malformed { message } => write!(f, "malformed: {message}"),
            Finding::Position { t, joint, value, lower, upper, excess } => write!(
                f,
                "t = {t:.4} s: joint `{joint}` = {value:.6} is outside [{lower:.6}, {upper:.6}] by {excess:.3e}"
            ),
            Finding::Velocity { t, joint, value, limit, excess, source } => write!(
                f,
                "t = {t:.4} s: joint `{joint}` velocity {value:.6} ({source}) exceeds {limit:.6} by {excess:.3e}"
            ),
            Finding::Acceleration { t, joint, value, limit, excess } => {
                write!(f, "t = {t:.4} s: joint `{joint}` acceleration {value:.6} exceeds {limit:.6} by {excess:.3e}")
            }
            Finding::Collision { t, q, a, b, penetration_m } => {
                write!(f, "t = {t:.4} s: {a} and {b} collide (penetration {penetration_m:.3e} m) at q = {}", fmt_q(q))
            }
            Finding::NotCertified { t_from, t_to, q_from, a, b, clearance_m, reason, .. } => write!(
                f,
                "t = {t_from:.4}..{t_to:.4} s: not certified ({reason}); closest pair {a} and {b}, \
                 clearance {clearance_m:.3e} m at q = {}",
                fmt_q(q_from)
            ),
            Finding::ClosureDrift { t, span, position_error_m, angle_error_rad, tolerance_m, tolerance_rad } => {
                write!(
                    f,
                    "t = {t:.4} s: closed-chain span {span}: relative tool pose drifted by {position_error_m:.3e} m \
                     (tolerance {tolerance_m:.3e}) and {angle_error_rad:.3e} rad (tolerance {tolerance_rad:.3e})"
                )
            }
        }
    }
}

fn fmt_q(q: &[f64]) -> String {
    let v: Vec<String> = q.iter().map(|x| format!("{x:.4}")).collect();
    format!("[{}]", v.join(", "))
}

/// Position, velocity and acceleration limits along the timed trajectory.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LimitsReport {
    pub ok: bool,
    /// The earliest violation.
    pub violation: Option<Finding>,
    /// Samples (and joints) over a limit, counted once per sample and joint and kind.
    pub violations: usize,
    pub samples: usize,
    /// Largest |velocity| / limit and |acceleration| / limit over the trajectory.
    pub max_velocity_ratio: f64,
    pub max_acceleration_ratio: f64,
    pub time_s: f64,
}

/// Continuous collision freedom.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CollisionReport {
    pub ok: bool,
    pub violation: Option<Finding>,
    /// Sample-to-sample segments, and how many are certified free.
    pub segments: usize,
    pub certified_segments: usize,
    /// Configurations at which every pair was measured (anchors, segment ends, midpoints).
    pub distance_evaluations: usize,
    /// Bisection midpoints evaluated, and the deepest bisection.
    pub subdivisions: usize,
    pub max_depth: u32,
    /// Pairs checked (link-obstacle plus self-collision pairs), in the plain model.
    pub pairs: usize,
    /// Smallest distance measured at any evaluated configuration (exact when below
    /// `exact_within`, m), and the smallest certified lower bound over the whole path.
    pub min_clearance_m: f64,
    pub certified_clearance_m: f64,
    /// The pair at the smallest measured distance.
    pub closest_pair: Option<[String; 2]>,
    pub time_s: f64,
}

/// The closed-chain constraint over the plan's spans.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ClosureReport {
    pub ok: bool,
    pub violation: Option<Finding>,
    pub spans: usize,
    /// Samples inside spans.
    pub samples: usize,
    pub max_position_error_m: f64,
    pub max_angle_error_rad: f64,
    pub time_s: f64,
}

/// Everything checked for one agent's trajectory.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TrajectoryReport {
    pub certified: bool,
    pub duration_s: f64,
    pub samples: usize,
    pub limits: LimitsReport,
    pub collision: CollisionReport,
    pub closure: ClosureReport,
}

impl TrajectoryReport {
    /// The first finding of each check, in the order limits, collision, closure.
    pub fn findings(&self) -> Vec<&Finding> {
        [&self.limits.violation, &self.collision.violation, &self.closure.violation].into_iter().flatten().collect()
    }
}

/// Check one agent's timed trajectory against `model` (robot and environment): the trajectory
/// is well formed; positions, velocities and accelerations within limits; the path through
/// the samples is certified collision-free; every closed-chain span keeps its relative tool
/// pose. Inside a span with an object, collisions are checked with the object attached.
pub fn check_trajectory(
    model: &CollisionModel,
    traj: &Trajectory,
    spans: &[ClosedChainSpan],
    settings: &CheckSettings,
) -> TrajectoryReport {
    let robot = model.robot();
    let samples = traj.t.len();
    let malformed = well_formed(robot, traj).err().map(|message| Finding::Malformed { message });
    let limits = match &malformed {
        Some(m) => LimitsReport {
            ok: false,
            violation: Some(m.clone()),
            violations: 1,
            samples,
            max_velocity_ratio: f64::NAN,
            max_acceleration_ratio: f64::NAN,
            time_s: 0.0,
        },
        None => check_limits(robot, traj, settings),
    };
    let (collision, closure) = match &malformed {
        Some(m) => (
            CollisionReport {
                ok: false,
                violation: Some(m.clone()),
                segments: samples.saturating_sub(1),
                certified_segments: 0,
                distance_evaluations: 0,
                subdivisions: 0,
                max_depth: 0,
                pairs: 0,
                min_clearance_m: f64::NAN,
                certified_clearance_m: f64::NAN,
                closest_pair: None,
                time_s: 0.0,
            },
            ClosureReport {
                ok: false,
                violation: Some(m.clone()),
                spans: spans.len(),
                samples: 0,
                max_position_error_m: f64::NAN,
                max_angle_error_rad: f64::NAN,
                time_s: 0.0,
            },
        ),
        None => (check_collisions(model, traj, spans, settings), check_closure(robot, traj, spans)),
    };
    TrajectoryReport {
        certified: limits.ok && collision.ok && closure.ok,
        duration_s: traj.duration(),
        samples,
        limits,
        collision,
        closure,
    }
}

/// Lengths, DOF, finite values and strictly increasing times.
fn well_formed(robot: &Robot, traj: &Trajectory) -> Result<(), String> {
    let n = traj.t.len();
    if n == 0 {
        return Err("the trajectory has no samples".into());
    }
    if traj.q.len() != n || traj.qd.len() != n {
        return Err(format!("{} times, {} positions and {} velocities", n, traj.q.len(), traj.qd.len()));
    }
    let dof = robot.dof();
    for k in 0..n {
        for (what, v) in [("q", &traj.q[k]), ("qd", &traj.qd[k])] {
            if v.len() != dof {
                return Err(format!("sample {k}: {what} has {} values, the robot has {dof} joints", v.len()));
            }
            if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                return Err(format!("sample {k}: {what}[{i}] = {} is not a finite number", v[i]));
            }
        }
        if !traj.t[k].is_finite() {
            return Err(format!("sample {k}: t = {} is not a finite number", traj.t[k]));
        }
        if k > 0 && traj.t[k] <= traj.t[k - 1] {
            return Err(format!("sample {k}: t = {} s does not come after t = {} s", traj.t[k], traj.t[k - 1]));
        }
    }
    Ok(())
}

fn check_limits(robot: &Robot, traj: &Trajectory, settings: &CheckSettings) -> LimitsReport {
    let start = Instant::now();
    let limits = robot.limits();
    let names = robot.joint_names();
    let space = robot.config_space();
    let rel = 1.0 + settings.limit_tolerance;
    let mut first: Option<Finding> = None;
    let mut violations = 0;
    let (mut vr, mut ar) = (0.0f64, 0.0f64);
    let mut note = |f: Finding, first: &mut Option<Finding>| {
        violations += 1;
        if first.is_none() {
            *first = Some(f);
        }
    };
    for k in 0..traj.t.len() {
        let t = traj.t[k];
        let h = if k > 0 { t - traj.t[k - 1] } else { f64::NAN };
        for (i, l) in limits.iter().enumerate() {
            let joint = || names[i].clone();
            let value = traj.q[k][i];
            let excess = (l.lower - value).max(value - l.upper);
            if excess > settings.position_tolerance {
                let f = Finding::Position { t, joint: joint(), value, lower: l.lower, upper: l.upper, excess };
                note(f, &mut first);
            }
            let mut velocity = |value: f64, source: &str, first: &mut Option<Finding>| {
                vr = vr.max(value.abs() / l.max_velocity);
                if value.abs() > l.max_velocity * rel + 1e-12 {
                    let excess = value.abs() - l.max_velocity;
                    let f = Finding::Velocity {
                        t,
                        joint: joint(),
                        value,
                        limit: l.max_velocity,
                        excess,
                        source: source.into(),
                    };
                    note(f, first);
                }
            };
            velocity(traj.qd[k][i], "qd", &mut first);
            if k > 0 {
                velocity(space.delta(i, traj.q[k - 1][i], value) / h, "finite difference of q", &mut first);
                let a = (traj.qd[k][i] - traj.qd[k - 1][i]) / h;
                ar = ar.max(a.abs() / l.max_acceleration);
                if a.abs() > l.max_acceleration * rel + 1e-12 {
                    let excess = a.abs() - l.max_acceleration;
                    note(
                        Finding::Acceleration { t, joint: joint(), value: a, limit: l.max_acceleration, excess },
                        &mut first,
                    );
                }
            }
        }
    }
    LimitsReport {
        ok: first.is_none(),
        violation: first,
        violations,
        samples: traj.t.len(),
        max_velocity_ratio: vr,
        max_acceleration_ratio: ar,
        time_s: start.elapsed().as_secs_f64(),
    }
}

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
    report: CollisionReport,
    scratch: Vec<f64>,
}

impl Walk<'_> {
    fn eval(&mut self, q: &[f64]) -> Eval {
        self.report.distance_evaluations += 1;
        let e = self.pairs.eval(self.model.robot(), q, self.settings.exact_within);
        if e.min < self.report.min_clearance_m {
            self.report.min_clearance_m = e.min;
            let (a, b) = self.pairs.names(e.nearest);
            self.report.closest_pair = Some([a, b]);
        }
        e
    }

    fn collision(&self, t: f64, q: &[f64], e: &Eval) -> Option<Box<Finding>> {
        if e.min > 0.0 {
            return None;
        }
        let (a, b) = self.pairs.names(e.nearest);
        Some(Box::new(Finding::Collision { t, q: q.to_vec(), a, b, penetration_m: -e.min }))
    }

    /// Certify samples `i0..=i1` of the trajectory (one model throughout).
    fn run(&mut self, t: &[f64], q: &[Vec<f64>], i0: usize, i1: usize) -> Result<(), Box<Finding>> {
        let mut anchor = i0;
        let mut da = self.eval(&q[i0]);
        if let Some(f) = self.collision(t[i0], &q[i0], &da) {
            return Err(f);
        }
        let mut acc = vec![0.0; self.pairs.width()];
        let mut seg = Vec::new();
        let mut k = i0;
        while k < i1 {
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
                self.report.certified_clearance_m = self.report.certified_clearance_m.min(lowest);
                k += 1;
                continue;
            }
            if anchor != k {
                anchor = k;
                da = self.eval(&q[k]);
                if let Some(f) = self.collision(t[k], &q[k], &da) {
                    return Err(f);
                }
                acc.iter_mut().for_each(|a| *a = 0.0);
                continue;
            }
            // One end does not cover the segment: measure the other end and bisect.
            let db = self.eval(&q[k + 1]);
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
            self.report.certified_clearance_m = self.report.certified_clearance_m.min(lowest);
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
                clearance_m: e.min,
                reason,
            }));
        }
        *budget -= 1;
        self.report.subdivisions += 1;
        let qm = self.pairs.space.interpolate(qa, qb, 0.5);
        let tm = 0.5 * (ta + tb);
        let dm = self.eval(&qm);
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

/// Certify the polyline through the trajectory's samples free of collisions.
pub fn check_collisions(
    model: &CollisionModel,
    traj: &Trajectory,
    spans: &[ClosedChainSpan],
    settings: &CheckSettings,
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
    let mut models: Vec<CollisionModel> = Vec::new();
    let mut which = vec![usize::MAX; n.saturating_sub(1)];
    for span in spans {
        match span_model(model, span) {
            Ok(Some(m)) => {
                models.push(m);
                let id = models.len() - 1;
                for (k, w) in which.iter_mut().enumerate() {
                    if traj.t[k + 1] > span.from_s && traj.t[k] < span.to_s {
                        *w = id;
                    }
                }
            }
            Ok(None) => {}
            Err(message) => {
                report.ok = false;
                report.violation = Some(Finding::Malformed { message });
                report.time_s = start.elapsed().as_secs_f64();
                return report;
            }
        }
    }
    let mut result = Ok(());
    if n == 1 {
        let mut walk = Walk { model, pairs: plain, settings, report, scratch: Vec::new() };
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
            let mut walk = Walk { model: m, pairs, settings, report, scratch: Vec::new() };
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
                .with(Obstacle::new("ball", Isometry3::translation(-0.5, 0.3, 1.0), Shape::sphere(0.15)));
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
                let r = check_collisions(
                    &model,
                    &two_samples(&robot, qa.clone(), qb.clone()),
                    &[],
                    &CheckSettings::default(),
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
