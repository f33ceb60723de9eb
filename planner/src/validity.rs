//! What planners ask of the world, and the counted queries they make.
//!
//! [`StateValidity`] is the extension point: a configuration check, a certified motion check
//! and (optionally) a distance, with per-thread working memory. [`CollisionModel`] implements
//! it; the planners ([`crate::motion::RrtConnect`], [`crate::motion::LazyPrm`], the shortcut
//! pass, [`crate::roadmap::Roadmap`]) take any implementation.
//!
//! Inside the crate, `Validity` counts the queries of one planning run. Segments are certified
//! by default (`CollisionModel::certify`: free for the whole continuum of configurations
//! between their ends). With [`EdgeCheck::Sampled`] they are sampled at the resolution instead,
//! in bisection order (midpoint first, then quarter points...) because a colliding segment
//! usually collides somewhere in the middle: the first hit ends the check. The independent
//! checker in [`crate::verify`] walks segments its own way.
//!
//! `Validity::segment_probed` is the cheap, incomplete test of lazy RRT-Connect: plain
//! collision checks of sampled configurations, before a segment is certified (or instead of it,
//! for tree edges that never end up on a path). Its points go to the model together
//! ([`StateValidity::any_collides`]), so that a model may check them in vector lanes.

use embodied_models::collision::{CollisionModel, CollisionScratch};
use embodied_models::cspace::{bisection_order, probe_points_into};
use embodied_models::{ConfigSpace, Robot};

use crate::error::PlanError;

/// Largest joint step (rad or m) between collision-checked points of a segment, by default.
pub const DEFAULT_RESOLUTION: f64 = 0.02;

/// Default tolerance of [`EdgeCheck::Certified`] (m).
pub const CERTIFY_TOLERANCE: f64 = 1e-4;

/// How a straight segment between two free configurations is judged free.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum EdgeCheck {
    /// The conservative certificate of [`StateValidity::certify_motion`] (for a
    /// [`CollisionModel`]: [`CollisionModel::motion_is_certified_free`]): the whole continuum of
    /// configurations is free, not only sampled ones. Motions that pass within about
    /// `tolerance` (m) of contact are refused.
    Certified {
        /// Clearance below which a motion is refused, m.
        tolerance: f64,
    },
    /// Configurations no more than [`crate::motion::MotionSettings::resolution`] apart in every
    /// joint are checked (the classic discrete check; a thin obstacle between samples can be
    /// missed).
    Sampled,
}

/// The validity of robot states and motions, as a planner needs it.
///
/// Positions within the joint limits are the planner's business (it asks the [`Robot`]); an
/// implementation says whether a configuration of the right length is free, whether a straight
/// joint-space motion (the short way round on continuous joints) is certified free, and, if it
/// can, how far a configuration is from the nearest invalid one. Queries take per-thread
/// working memory ([`StateValidity::Scratch`]) so that planners can check in parallel.
pub trait StateValidity: Sync {
    /// Working memory of one thread's queries.
    type Scratch: Send;

    /// The robot whose states are checked.
    fn robot(&self) -> &Robot;

    /// Fresh working memory.
    fn scratch(&self) -> Self::Scratch;

    /// Whether `q` is invalid (in collision). A `q` of the wrong length is invalid.
    fn collides(&self, q: &[f64], scratch: &mut Self::Scratch) -> bool;

    /// Whether any of the configurations `qs` (whole configurations, one after another) is
    /// invalid: [`Self::collides`] of each by default; an implementation may check them
    /// together (in vector lanes) as long as the answer is the same.
    fn any_collides(&self, qs: &[f64], scratch: &mut Self::Scratch) -> bool {
        let dof = self.robot().dof();
        if dof == 0 {
            return !qs.is_empty() && self.collides(qs, scratch);
        }
        qs.chunks(dof).any(|q| self.collides(q, scratch))
    }

    /// Whether any point of an edge probe is invalid: `end` first when given, then the inner
    /// points `a + (i / n) delta` of the segment cut into `n` steps ([`ConfigSpace::step_into`]
    /// with `t = i / n`, `i` from 1 to `n - 1` in bisection order). By default the points are
    /// built (in a new buffer) and passed to [`Self::any_collides`]; an implementation may
    /// check them without building them, as long as the answer is the same. `a` is valid (a
    /// probe starts at a configuration already checked): an implementation may take what does
    /// not move along the probe as valid ([`CollisionModel::probe_from_free_collides`]).
    fn probe_collides(
        &self,
        a: &[f64],
        end: Option<&[f64]>,
        delta: &[f64],
        n: usize,
        scratch: &mut Self::Scratch,
    ) -> bool {
        let mut points = Vec::new();
        probe_points_into(a, end, delta, n, &mut points);
        self.any_collides(&points, scratch)
    }

    /// Why `q` is invalid, in words (for errors: "link `a` and obstacle `b`"); `None` when valid.
    fn first_collision(&self, q: &[f64]) -> Option<String>;

    /// Whether the straight motion `qa -> qb` is certified valid, every point of it, with a
    /// margin of about `tolerance` (m); `check_ends`: check the end configurations too. Returns
    /// the answer and the number of configuration checks it spent.
    fn certify_motion(
        &self,
        qa: &[f64],
        qb: &[f64],
        tolerance: f64,
        check_ends: bool,
        scratch: &mut Self::Scratch,
    ) -> (bool, u32);

    /// Signed distance (m) from `q` to the nearest invalid state, when the implementation can
    /// measure it (negative: penetration depth). `None` by default.
    fn distance(&self, q: &[f64]) -> Option<f64> {
        let _ = q;
        None
    }

    /// This validity when it is a plain [`CollisionModel`] (`None` by default, and for any
    /// validity that adds to one): a race of planners then hands its other racers a clone of
    /// the model they own, and returns without waiting for them (see
    /// [`crate::motion::MotionSettings::racers`]).
    fn collision_model(&self) -> Option<&CollisionModel> {
        None
    }
}

impl StateValidity for CollisionModel {
    type Scratch = CollisionScratch;

    fn collision_model(&self) -> Option<&CollisionModel> {
        Some(self)
    }

    fn robot(&self) -> &Robot {
        CollisionModel::robot(self)
    }

    fn scratch(&self) -> CollisionScratch {
        CollisionModel::scratch(self)
    }

    fn collides(&self, q: &[f64], scratch: &mut CollisionScratch) -> bool {
        self.collides_with(q, scratch)
    }

    fn any_collides(&self, qs: &[f64], scratch: &mut CollisionScratch) -> bool {
        self.any_collides_settled(qs, scratch)
    }

    fn probe_collides(
        &self,
        a: &[f64],
        end: Option<&[f64]>,
        delta: &[f64],
        n: usize,
        scratch: &mut CollisionScratch,
    ) -> bool {
        self.probe_from_free_collides(a, end, delta, n, scratch)
    }

    fn first_collision(&self, q: &[f64]) -> Option<String> {
        CollisionModel::first_collision(self, q).map(|c| c.to_string())
    }

    fn certify_motion(
        &self,
        qa: &[f64],
        qb: &[f64],
        tolerance: f64,
        check_ends: bool,
        scratch: &mut CollisionScratch,
    ) -> (bool, u32) {
        self.certify(qa, qb, tolerance, check_ends, scratch)
    }

    fn distance(&self, q: &[f64]) -> Option<f64> {
        Some(CollisionModel::distance(self, q).distance)
    }
}

/// Check a start configuration: length, finiteness, limits, collisions.
pub(crate) fn check_start<V: StateValidity>(model: &V, start: &[f64]) -> Result<(), PlanError> {
    model.robot().check_configuration(start).map_err(|e| PlanError::InvalidInput { message: format!("start: {e}") })?;
    if let Some(contact) = model.first_collision(start) {
        return Err(PlanError::StartInCollision { contact });
    }
    Ok(())
}

/// Certificates given in one planning run, by their segments' ends (exact values): the ends
/// one after another in `ends`, entry `i`'s at `i * 2 * dof`. Segments whose ends are not
/// both `dof` long are not kept.
struct CertMemo {
    dof: usize,
    /// Per entry: a hash of its ends' bits, and its answer.
    keys: Vec<(u64, bool)>,
    ends: Vec<f64>,
}

impl CertMemo {
    /// At most this many entries: a planning run certifies some tens of segments, and a
    /// lookup scans the hashes.
    const CAPACITY: usize = 256;

    fn key(&self, a: &[f64], b: &[f64]) -> u64 {
        // FNV-1a over the bits, one value at a time (a lookup costs less than a tenth of
        // one batch of the certificate).
        a.iter().chain(b).fold(0xcbf2_9ce4_8422_2325_u64, |h, x| (h ^ x.to_bits()).wrapping_mul(0x0000_0100_0000_01b3))
    }

    /// Room for this many entries from the start, so that a planning run does not grow the two
    /// lists entry by entry (with the k-d index's room and `Tree::chain_to` counting first: 1.0%
    /// fewer planning instructions on the 296 public MotionBenchMaker UR5 problems).
    const START: usize = 32;

    fn new(dof: usize) -> Self {
        CertMemo { dof, keys: Vec::with_capacity(Self::START), ends: Vec::with_capacity(Self::START * 2 * dof) }
    }

    fn get(&self, key: u64, a: &[f64], b: &[f64]) -> Option<bool> {
        if a.len() != self.dof || b.len() != self.dof {
            return None;
        }
        let n = 2 * self.dof;
        self.keys.iter().enumerate().find_map(|(i, &(k, free))| {
            let ends = self.ends.get(i * n..(i + 1) * n)?;
            let same = ends.iter().zip(a.iter().chain(b)).all(|(x, y)| x.to_bits() == y.to_bits());
            (k == key && same).then_some(free)
        })
    }

    fn put(&mut self, key: u64, a: &[f64], b: &[f64], free: bool) {
        if self.keys.len() >= Self::CAPACITY || a.len() != self.dof || b.len() != self.dof {
            return;
        }
        self.keys.push((key, free));
        self.ends.extend_from_slice(a);
        self.ends.extend_from_slice(b);
    }
}

/// Counted validity queries against one collision model at one resolution.
pub(crate) struct Validity<'m, V: StateValidity> {
    pub model: &'m V,
    pub space: ConfigSpace,
    pub resolution: f64,
    /// `Some(tolerance)`: segments are certified, not sampled.
    certify: Option<f64>,
    scratch: V::Scratch,
    buf: Vec<f64>,
    /// Joint steps of the segment being sampled.
    delta: Vec<f64>,
    pub collision_checks: u64,
    pub edges_checked: usize,
    /// Collision checks of [`Self::segment_probed`] (also counted in `collision_checks`).
    pub probe_checks: u64,
    /// Per degree of freedom, the bounds [`Robot::within_limits`] tests a value against (its
    /// `lower - 1e-9` and `upper + 1e-9`, the same numbers); `None` for a robot with actuators,
    /// whose strokes need the whole test.
    end_bounds: Option<Vec<(f64, f64)>>,
    /// Certificates already given in this run (see [`Self::segment_free`]).
    memo: CertMemo,
    /// Segments answered from `memo` (not counted in `edges_checked`).
    pub edges_recalled: usize,
    /// Segments screened by [`Self::segment_free_screened`], and those the screen refused.
    pub screened: usize,
    pub screened_out: usize,
    /// [`Self::segment_free_screened`] screens the certificates of segments longer than this
    /// (C-space distance); infinite: never.
    screen_above: f64,
}

impl<'m, V: StateValidity> Validity<'m, V> {
    pub fn new(model: &'m V, resolution: f64) -> Self {
        let robot = model.robot();
        Self {
            model,
            space: robot.config_space(),
            resolution,
            certify: None,
            scratch: model.scratch(),
            buf: vec![0.0; robot.dof()],
            delta: Vec::new(),
            collision_checks: 0,
            edges_checked: 0,
            probe_checks: 0,
            end_bounds: robot.actuators().is_empty().then(|| {
                let joints = robot.joints();
                robot
                    .dof_joints()
                    .iter()
                    .map(|&j| (joints[j].limits.lower - 1e-9, joints[j].limits.upper + 1e-9))
                    .collect()
            }),
            memo: CertMemo::new(robot.dof()),
            edges_recalled: 0,
            screened: 0,
            screened_out: 0,
            screen_above: f64::INFINITY,
        }
    }

    /// Screen the certificates of segments longer than `above` (see
    /// [`Self::segment_free_screened`]; NaN or infinite: never).
    pub fn with_screen_above(mut self, above: f64) -> Self {
        self.screen_above = if above.is_nan() { f64::INFINITY } else { above };
        self
    }

    /// [`Robot::within_limits`] of `q`, from the bounds kept at construction where the robot
    /// has no actuators (the robot's test looks each joint's limits up through its joint: on
    /// the generated cage problems 165 instructions per edge probe).
    fn within_limits(&self, q: &[f64]) -> bool {
        match &self.end_bounds {
            Some(bounds) => {
                // Unrolled for the common arm sizes (the same test).
                if let (Ok(q), Ok(b)) = (<&[f64; 6]>::try_from(q), <&[(f64, f64); 6]>::try_from(&bounds[..])) {
                    return within_bounds(q, b);
                }
                if let (Ok(q), Ok(b)) = (<&[f64; 7]>::try_from(q), <&[(f64, f64); 7]>::try_from(&bounds[..])) {
                    return within_bounds(q, b);
                }
                q.len() == bounds.len() && within_bounds(q, bounds)
            }
            None => self.model.robot().within_limits(q),
        }
    }

    /// Check segments as `check` says.
    pub fn with_edge_check(mut self, check: EdgeCheck) -> Self {
        self.certify = match check {
            EdgeCheck::Certified { tolerance } => Some(tolerance),
            EdgeCheck::Sampled => None,
        };
        self
    }

    /// Whether [`Self::segment_free`] certifies segments (every point of a segment it passes is
    /// free) rather than sampling them.
    pub fn certifies(&self) -> bool {
        self.certify.is_some()
    }

    /// Within the position limits and collision-free.
    pub fn config_free(&mut self, q: &[f64]) -> bool {
        if !self.model.robot().within_limits(q) {
            return false;
        }
        self.collision_checks += 1;
        !self.model.collides(q, &mut self.scratch)
    }

    /// The straight C-space segment `a`-`b` (short way on continuous joints) is collision-free
    /// at `resolution` (largest joint step between checked points). The end points are taken as
    /// already checked.
    ///
    /// With certificates, a segment asked for again (the same ends, bit for bit, in the same
    /// order) gets the answer it got before without a new certificate: lazy RRT-Connect's
    /// greedy pass tries the start-goal segment the direct check has refused, and tries again,
    /// after a blocked edge is cut, the segments it certified or refused on the path before.
    pub fn segment_free(&mut self, a: &[f64], b: &[f64]) -> bool {
        self.segment_checked(a, b, false)
    }

    /// [`Self::segment_free`] of a segment from a valid point `a` that is likely refused: a
    /// shortcut of the greedy pass or of a random attempt (from a vertex, or a point of a
    /// certified segment), the straight segment to a goal, a leg's straight segment. With
    /// certificates, a segment longer than [`Self::with_screen_above`]'s length whose answer is
    /// not kept is screened first by a probe of [`SCREEN_POINTS`] evenly spaced inner points:
    /// one of them in collision refuses it (kept as refused) without its certificate. The answer
    /// is the certificate's either way: a segment with a point in collision has none. The
    /// probe's one batch of plain checks costs a fraction of a certificate's set-up and first
    /// batch with its margins.
    pub fn segment_free_screened(&mut self, a: &[f64], b: &[f64]) -> bool {
        self.segment_checked(a, b, true)
    }

    /// [`Self::segment_free`], screened first when `screen` (see [`Self::segment_free_screened`]).
    fn segment_checked(&mut self, a: &[f64], b: &[f64], screen: bool) -> bool {
        let Some(tolerance) = self.certify else {
            self.edges_checked += 1;
            return self.sampled(a, b, self.resolution);
        };
        let key = self.memo.key(a, b);
        if let Some(free) = self.memo.get(key, a, b) {
            self.edges_recalled += 1;
            return free;
        }
        if screen && a.len() == b.len() && self.space.distance(a, b) > self.screen_above {
            self.space.deltas_into(a, b, &mut self.delta);
            self.collision_checks += SCREEN_POINTS as u64;
            self.screened += 1;
            if self.model.probe_collides(a, None, &self.delta, SCREEN_POINTS + 1, &mut self.scratch) {
                self.memo.put(key, a, b, false);
                self.screened_out += 1;
                return false;
            }
        }
        self.edges_checked += 1;
        let (free, checks) = self.model.certify_motion(a, b, tolerance, false, &mut self.scratch);
        self.collision_checks += u64::from(checks);
        self.memo.put(key, a, b, free);
        free
    }

    /// No sampled configuration of the segment `a`-`b` collides, at `resolution` (largest joint
    /// step), ends excluded; with `check_end`, the end `b` too (within the position limits and
    /// free). `a` is valid (a tree node): the model may take the bodies that do not move as
    /// free. A probe, not a certificate: an obstacle between samples is missed. The points go
    /// to the model in one query ([`StateValidity::probe_collides`]: in vector lanes for a
    /// [`CollisionModel`] on the sphere path), the end first, then the inner points in
    /// bisection order. (The end checked alone first, then the inner points: on the 296 public
    /// MotionBenchMaker UR5 problems, where 39% of the extensions end blocked, 3.0% more
    /// planning instructions; on 10 cage problems, 65% blocked, 3.4% more: a batch of eight
    /// costs about two single checks.)
    pub fn segment_probed(&mut self, a: &[f64], b: &[f64], resolution: f64, check_end: bool) -> bool {
        // The end within the limits, then in the same query as the inner points, first: a
        // blocked extension usually ends there, and a batch of lanes checks it with them.
        if a.len() != b.len() || (check_end && !self.within_limits(b)) {
            return false;
        }
        self.space.deltas_into(a, b, &mut self.delta);
        let n = steps(&self.delta, resolution);
        let inner = n.saturating_sub(1) as u64;
        self.collision_checks += inner + u64::from(check_end);
        self.probe_checks += inner;
        // The points go to the model as the segment's ends and steps: a `CollisionModel`
        // writes them into its lanes joint by joint (built as rows here and turned into
        // columns there, they cost about 400 instructions a probe more).
        let end = check_end.then_some(b);
        !self.model.probe_collides(a, end, &self.delta, n, &mut self.scratch)
    }

    /// Sampled check of the segment's inner points, in bisection order.
    fn sampled(&mut self, a: &[f64], b: &[f64], resolution: f64) -> bool {
        // The joint steps once; each point is `a + t delta` (what `interpolate_into` computes).
        self.space.deltas_into(a, b, &mut self.delta);
        let n = steps(&self.delta, resolution);
        let (delta, buf) = (&self.delta, &mut self.buf);
        let (model, scratch, checks) = (self.model, &mut self.scratch, &mut self.collision_checks);
        bisection_order(n, |i| {
            ConfigSpace::step_into(a, delta, i as f64 / n as f64, buf);
            *checks += 1;
            !model.collides(buf, scratch)
        })
    }
}

/// Inner points of [`Validity::segment_free_screened`]'s screen: one batch of vector lanes.
pub const SCREEN_POINTS: usize = 8;

/// Every value finite and within its bounds (no branch per value).
#[inline(always)]
fn within_bounds<'a>(q: impl IntoIterator<Item = &'a f64>, bounds: impl IntoIterator<Item = &'a (f64, f64)>) -> bool {
    q.into_iter().zip(bounds).fold(true, |ok, (&v, &(lo, hi))| ok & v.is_finite() & (v >= lo) & (v <= hi))
}

/// Number of equal steps so that no joint moves more than `resolution` per step (at least 1),
/// for a segment of joint steps `delta`. The largest step is found by comparisons (`f64::max`'s
/// NaN handling cost about 90 instructions an edge probe); a NaN step is passed over by both.
/// At most 10^7 steps. The ceiling is the truncation plus one when that falls short (exact below
/// 2^53; `f64::ceil` is a call into the C library on the x86-64 baseline).
fn steps(delta: &[f64], resolution: f64) -> usize {
    let max = delta.iter().fold(0.0, |m: f64, d| if d.abs() > m { d.abs() } else { m });
    let q = max / resolution;
    if !(q.is_finite() && q > 0.0) {
        return 1;
    }
    let q = q.min(1e7);
    let whole = q as usize;
    (whole + usize::from((whole as f64) < q)).max(1)
}

#[cfg(test)]
mod tests {
    use embodied_models::collision::{CollisionModel, Environment, Obstacle};
    use embodied_models::nalgebra::Isometry3;
    use embodied_models::{Rng, Shape, builtin};

    use super::*;

    /// The probe's answer point by point: the end within the limits and free, then every
    /// inner point free.
    fn probe_by_points(model: &CollisionModel, a: &[f64], b: &[f64], resolution: f64, check_end: bool) -> bool {
        let space = model.robot().config_space();
        if check_end && (!model.robot().within_limits(b) || model.collides(b)) {
            return false;
        }
        let mut delta = Vec::new();
        space.deltas_into(a, b, &mut delta);
        let n = steps(&delta, resolution);
        let mut q = vec![0.0; a.len()];
        (1..n).all(|i| {
            ConfigSpace::step_into(a, &delta, i as f64 / n as f64, &mut q);
            !model.collides(&q)
        })
    }

    /// The step count is the ceiling of the largest step over the resolution, at least 1 and at
    /// most 10^7, as `f64::ceil` gives it: on exact multiples, values a hair either side,
    /// random ones, and steps that are zero, NaN, infinite or huge.
    #[test]
    fn step_counts_are_the_ceiling_of_the_largest_step() {
        let by_ceil = |delta: &[f64], resolution: f64| {
            let max = delta.iter().fold(0.0, |m: f64, d| if d.abs() > m { d.abs() } else { m });
            let n = (max / resolution).ceil();
            if n.is_finite() && n >= 1.0 { n.min(1e7) as usize } else { 1 }
        };
        let mut rng = Rng::new(9);
        let mut cases: Vec<(Vec<f64>, f64)> = Vec::new();
        for k in 0..2000 {
            let r = [0.02, 0.1, 0.05, 1e-9, 0.3][k % 5];
            let exact = (k % 97) as f64 * r;
            for d in [exact, f64::from_bits(exact.to_bits() + 1), f64::from_bits(exact.to_bits().saturating_sub(1))] {
                cases.push((vec![d, -rng.range(0.0, d.abs().max(1e-300))], r));
            }
            cases.push(((0..6).map(|_| rng.range(-7.0, 7.0)).collect(), r));
        }
        for d in [0.0, f64::NAN, f64::INFINITY, 1e300, 5e-324] {
            cases.push((vec![d, 0.0], 0.02));
        }
        cases.push((vec![1.0], -0.5));
        for (delta, r) in &cases {
            assert_eq!(steps(delta, *r), by_ceil(delta, *r), "{delta:?} at {r}");
        }
    }

    /// The probe's limits test answers as the robot's, on two arms without actuators (its own
    /// bounds) and one with (the robot's test): values at and just past each limit, not
    /// finite, and configurations of the wrong length.
    #[test]
    fn the_probe_limits_test_answers_as_the_robot_does() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/tests/fixtures");
        let ur5 = embodied_models::urdf::load_urdf(&dir.join("ur5_spherized.urdf"), Some(&dir.join("ur5.srdf")))
            .expect("UR5 fixture loads");
        let mut kinds = Vec::new();
        // The UR5's limits are finite, the Polycrank's joints have none (an infinite value is
        // still refused), the IRp-6 has actuators.
        let arms = [
            ("ur5", ur5),
            ("polycrank", builtin("polycrank").expect("robot")),
            ("irp6-postument", builtin("irp6-postument").expect("robot")),
        ];
        for (name, robot) in arms {
            let model = CollisionModel::new(&robot, Environment::new());
            let validity = Validity::new(&model, 0.1);
            assert_eq!(validity.end_bounds.is_some(), robot.actuators().is_empty(), "{name}: test setup");
            let mut rng = Rng::new(3);
            let mut q = vec![0.0; robot.dof()];
            let (mut inside, mut outside) = (0, 0);
            for k in 0..4000 {
                robot.random_configuration_into(&mut rng, &mut q);
                let j = k % robot.dof();
                let l = robot.limits()[j];
                q[j] = match (k / robot.dof()) % 9 {
                    0 => l.lower - 1e-9,
                    1 => l.upper + 1e-9,
                    2 => l.upper + 2e-9,
                    3 => l.lower - 1e-6,
                    4 => f64::NAN,
                    5 => f64::INFINITY,
                    _ => q[j],
                };
                let expected = robot.within_limits(&q);
                assert_eq!(validity.within_limits(&q), expected, "{name}: {q:?}");
                if expected { inside += 1 } else { outside += 1 }
            }
            assert!(inside > 100 && outside > 100, "{name}: {inside} inside, {outside} outside");
            assert!(!validity.within_limits(&q[1..]), "{name}: a short configuration");
            kinds.push(robot.actuators().is_empty());
        }
        assert_eq!(kinds, [true, true, false], "two arms without actuators, one with");
    }

    /// The spherized UR5 fixture, without the self pairs that touch in every configuration.
    fn ur5_without_touching_pairs() -> Robot {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/tests/fixtures");
        let mut ur5 = embodied_models::urdf::load_urdf(&dir.join("ur5_spherized.urdf"), Some(&dir.join("ur5.srdf")))
            .expect("UR5 fixture loads");
        embodied_models::collision::disable_always_colliding(&mut ur5, 2000, 0x5eed);
        ur5
    }

    /// `count` segments between random free configurations of `model`'s robot, drawn from `seed`.
    fn free_ends(model: &CollisionModel, seed: u64, count: usize) -> Vec<(Vec<f64>, Vec<f64>)> {
        let robot = model.robot();
        let mut rng = Rng::new(seed);
        let mut segments = Vec::new();
        while segments.len() < count {
            let (a, b) = (robot.random_configuration(&mut rng), robot.random_configuration(&mut rng));
            if !model.collides(&a) && !model.collides(&b) {
                segments.push((a, b));
            }
        }
        segments
    }

    /// A certified segment asked for again gets the answer of its certificate without a new
    /// one; a segment with other ends (reversed, or one value a bit apart) gets its own. The
    /// answers are the model's, free and refused segments both occur, and the counts add up.
    #[test]
    fn segments_asked_again_get_their_certificates_answer() {
        let robot = ur5_without_touching_pairs();
        let mut env = Environment::new();
        env.add(Obstacle::new("wall", Isometry3::translation(0.4, 0.0, 0.3), Shape::cuboid(0.15, 0.4, 0.3)));
        let model = CollisionModel::new(&robot, env);
        let mut validity = Validity::new(&model, 0.05).with_edge_check(EdgeCheck::Certified { tolerance: 1e-3 });
        let segments = free_ends(&model, 11, 40);
        let answers: Vec<bool> = segments.iter().map(|(a, b)| validity.segment_free(a, b)).collect();
        let (checked, checks) = (validity.edges_checked, validity.collision_checks);
        assert_eq!((checked, validity.edges_recalled), (segments.len(), 0));
        let free = answers.iter().filter(|&&f| f).count();
        assert!(free > 3 && free < segments.len() - 3, "{free} of {} free", segments.len());
        for ((a, b), &answer) in segments.iter().zip(&answers) {
            assert_eq!(answer, model.motion_is_certified_free(a, b, 1e-3));
            assert_eq!(validity.segment_free(a, b), answer);
        }
        assert_eq!((validity.edges_checked, validity.collision_checks), (checked, checks), "a certificate again");
        assert_eq!(validity.edges_recalled, segments.len());
        // Other ends: a new certificate each.
        for (a, b) in &segments {
            let mut moved = b.clone();
            moved[0] = f64::from_bits(moved[0].to_bits() ^ 1);
            assert_eq!(validity.segment_free(b, a), model.motion_is_certified_free(b, a, 1e-3));
            assert_eq!(validity.segment_free(a, &moved), model.motion_is_certified_free(a, &moved, 1e-3));
        }
        assert_eq!(validity.edges_checked, 3 * segments.len());
        assert_eq!(validity.edges_recalled, segments.len());
        // Wrong lengths are refused and not kept.
        assert!(!validity.segment_free(&segments[0].0[1..], &segments[0].1[1..]));
        assert!(!validity.segment_free(&segments[0].0[1..], &segments[0].1[1..]));
        assert_eq!(validity.edges_recalled, segments.len());
    }

    /// A screened shortcut gets its certificate's answer: a segment the screen refuses has a
    /// point in collision, and is kept as refused (asked again: no new check); one it passes is
    /// certified as unscreened. Short segments and an infinite length are never screened.
    #[test]
    fn screened_segments_get_their_certificates_answer() {
        let robot = ur5_without_touching_pairs();
        let mut env = Environment::new();
        env.add(Obstacle::new("wall", Isometry3::translation(0.4, 0.0, 0.3), Shape::cuboid(0.15, 0.4, 0.3)));
        env.add(Obstacle::new("post", Isometry3::translation(-0.3, 0.4, 0.4), Shape::cuboid(0.08, 0.08, 0.4)));
        let model = CollisionModel::new(&robot, env);
        let certified = EdgeCheck::Certified { tolerance: 1e-3 };
        let segments = free_ends(&model, 5, 60);
        let mut screened = Validity::new(&model, 0.05).with_edge_check(certified).with_screen_above(0.5);
        let mut never = Validity::new(&model, 0.05).with_edge_check(certified).with_screen_above(f64::INFINITY);
        let (mut free, mut short, mut certificates) = (0, 0, 0);
        for (a, b) in &segments {
            let answer = model.motion_is_certified_free(a, b, 1e-3);
            let (out, edges) = (screened.screened_out, screened.edges_checked);
            assert_eq!(screened.segment_free_screened(a, b), answer, "{a:?} -> {b:?}");
            certificates += screened.edges_checked - edges;
            assert_eq!(never.segment_free_screened(a, b), answer);
            if screened.screened_out > out {
                assert_eq!(screened.edges_checked, edges, "a refused screen needs no certificate");
                let checks = screened.collision_checks;
                assert!(!screened.segment_free_screened(a, b));
                assert_eq!(screened.collision_checks, checks, "refused again without a check");
            }
            free += usize::from(answer);
            // A short piece of the segment: never screened.
            let near: Vec<f64> = a.iter().zip(b).map(|(x, y)| x + 0.05 * (y - x)).collect();
            let before = screened.screened;
            if screened.space.distance(a, &near) <= 0.5 {
                screened.segment_free_screened(a, &near);
                assert_eq!(screened.screened, before, "a short segment was screened");
                short += 1;
            }
        }
        assert!(screened.screened_out > 3, "{} refused by the screen", screened.screened_out);
        assert!(free > 3, "{free} free");
        assert!(short > 3, "test setup: {short} short segments");
        assert_eq!((never.screened, never.screened_out), (0, 0));
        assert_eq!(never.edges_checked, segments.len());
        assert_eq!(certificates + screened.screened_out, segments.len());
    }

    /// The end goes into the same batched query as the inner points: the answer is the
    /// point-by-point one, blocked ends and limits included, and the counts are the end's one
    /// check plus one per inner point.
    #[test]
    fn a_probe_with_its_end_answers_as_its_points_do() {
        // The spherized UR5 (its probes in vector lanes) and a built-in arm of boxes and
        // cylinders (one by one).
        let ur5 = ur5_without_touching_pairs();
        let irp6 = builtin("irp6-postument").expect("robot");
        let boxes = [
            (ur5, true, [([0.4, 0.0, 0.3], [0.15, 0.4, 0.3]), ([-0.2, 0.4, 0.4], [0.1, 0.1, 0.4])]),
            (irp6, false, [([0.9, 0.0, 0.5], [0.2, 0.3, 0.5]), ([-0.2, 0.8, 0.6], [0.1, 0.1, 0.6])]),
        ];
        for (robot, batched, obstacles) in boxes {
            let mut env = Environment::new();
            for (k, (c, h)) in obstacles.into_iter().enumerate() {
                env.add(Obstacle::new(
                    format!("box{k}"),
                    Isometry3::translation(c[0], c[1], c[2]),
                    Shape::cuboid(h[0], h[1], h[2]),
                ));
            }
            let model = CollisionModel::new(&robot, env);
            assert_eq!(model.certifies_in_batches(), batched, "test setup");
            probes_answer_as_their_points_do(&model);
        }
    }

    fn probes_answer_as_their_points_do(model: &CollisionModel) {
        let robot = model.robot();
        let mut validity = Validity::new(model, 0.1);
        let mut rng = Rng::new(7);
        let (mut a, mut b) = (vec![0.0; robot.dof()], vec![0.0; robot.dof()]);
        let (mut blocked_ends, mut blocked_inside, mut free) = (0, 0, 0);
        for k in 0..600 {
            robot.random_configuration_into(&mut rng, &mut a);
            while model.collides(&a) {
                robot.random_configuration_into(&mut rng, &mut a);
            }
            robot.random_configuration_into(&mut rng, &mut b);
            // Short and long segments, and some ends out of the limits.
            let t = [0.05, 0.2, 0.6, 1.0][k % 4];
            let mut end: Vec<f64> = a.iter().zip(&b).map(|(x, y)| x + t * (y - x)).collect();
            if k % 10 == 9 {
                end[1] = robot.limits()[1].upper + 0.01;
            }
            for check_end in [true, false] {
                let expected = probe_by_points(model, &a, &end, 0.1, check_end);
                let (checks, probes) = (validity.collision_checks, validity.probe_checks);
                let got = validity.segment_probed(&a, &end, 0.1, check_end);
                assert_eq!(got, expected, "segment {k} (end checked: {check_end}): {a:?} -> {end:?}");
                if check_end && expected {
                    let inner = validity.probe_checks - probes;
                    assert_eq!(validity.collision_checks - checks, inner + 1, "segment {k}: checks");
                }
                if check_end {
                    match (expected, model.collides(&end)) {
                        (true, _) => free += 1,
                        (false, true) => blocked_ends += 1,
                        (false, false) => blocked_inside += 1,
                    }
                }
            }
        }
        // The segments exercise every answer.
        assert!(free > 50 && blocked_ends > 50 && blocked_inside > 20, "{free} {blocked_ends} {blocked_inside}");
    }
}
