//! # Collision checking: is a configuration free, and how far from contact is it?
//!
//! A [`CollisionModel`] owns a robot and an [`Environment`] of posed obstacles and answers, for a
//! configuration `q`, whether any link touches an obstacle or another link ([`CollisionModel::collides`]),
//! which pair does ([`CollisionModel::first_collision`]), the signed distance to the nearest contact
//! ([`CollisionModel::distance`]) and whether a straight joint-space motion stays free
//! ([`CollisionModel::motion_is_free`]).
//!
//! ```
//! use embodied_models::collision::{CollisionModel, Environment, Obstacle};
//! use embodied_models::{Shape, builtin, nalgebra::Isometry3};
//!
//! let robot = builtin("irp6-postument").unwrap();
//! let mut env = Environment::new();
//! env.add(Obstacle::new("table", Isometry3::translation(0.8, 0.0, 0.4), Shape::cuboid(0.3, 0.5, 0.4)));
//! let model = CollisionModel::new(&robot, env);
//! assert!(!model.collides(robot.home()));
//! ```
//!
//! ## How a query runs
//!
//! 1. **Kinematics of what carries shapes only.** Links joined by fixed joints are merged into one
//!    rigid *body* at construction (their shapes re-expressed in the body frame), and bodies that
//!    carry no shape and lead to none are dropped, so forward kinematics costs one transform per
//!    moving joint that matters.
//! 2. **Broad phase.** Every link has a bounding sphere of its shapes. Obstacles are first culled
//!    against the bounding box of all link spheres, then each (link, obstacle) pair by sphere
//!    against the obstacle's box, then each (shape, obstacle) pair the same way. Self-collision
//!    pairs are culled sphere against sphere. World poses of a link's shapes are computed only
//!    when a pair involving the link survives the cull.
//! 3. **Narrow phase** ([`narrow`]): closed forms for sphere/capsule against
//!    sphere/capsule/box/cylinder, parry3d for everything else.
//!
//! `collides` stops at the first contact and does not allocate: it uses a thread-local
//! [`CollisionScratch`] (or pass your own to [`CollisionModel::collides_with`]).
//!
//! ## Self-collision pairs
//!
//! A pair of links is checked unless it is disabled by the robot (SRDF `disable_collisions`,
//! [`Robot::disable_pair`]), or the two links are *adjacent*: joined by a joint, or joined
//! through links that carry no shapes (a shapeless link's parent and children are adjacent to
//! each other). [`disable_always_colliding`] adds pairs that touch in every sampled configuration,
//! like MoveIt's setup assistant.
//!
//! ## Wrong input
//!
//! Query methods do not validate `q` beyond its length (call [`Robot::check_configuration`] on
//! user input first, to get a message naming the offending joint). A `q` of the wrong length
//! never panics: `collides` answers `true` (in collision, the safe side), `motion_is_free`
//! answers `false`, `first_collision` answers `None`, `distance` reports `-inf`, and
//! `link_shapes_world` returns no shapes.

mod environment;
mod grid;
pub mod narrow;
mod spheres;

use std::cell::RefCell;
use std::fmt;
use std::sync::Arc;

use nalgebra::{Isometry3, Matrix3, Point3, Translation3, Unit, UnitQuaternion, Vector3};

use crate::cspace::{ConfigSpace, bisection_order, probe_points_into};
use crate::geometry::{ConvexHull, Shape};
use crate::joint::JointKind;
use crate::rng::Rng;
use crate::robot::Robot;
pub use environment::{Environment, Obstacle};
use narrow::View;
pub use narrow::{
    Separation, parry_shape_separation, parry_shapes_intersect, shape_separation, shapes_intersect, shapes_within,
};
use spheres::lanes::{self, LaneInput, LaneMargins, SegmentIn, Solids32};
use spheres::simd8::Isa;
use spheres::{Check, Scope, Solid, SphereGeom, SphereScratch};

/// How many configurations [`CollisionModel::batch_collisions_with`] checks at once (on the
/// sphere path, one per vector lane).
pub const BATCH_LANES: usize = spheres::LANES;

/// The fewest configurations [`CollisionModel::any_collides_settled`] checks in a batch: fewer
/// are checked one by one.
const SETTLE_MIN: usize = 3;

/// An edge probe of [`CollisionModel::probe_collides`]: its end (point 0) when given, and the
/// points `a + (i / n) delta`.
#[derive(Debug, Clone, Copy)]
struct Probe<'a> {
    a: &'a [f64],
    end: Option<&'a [f64]>,
    delta: &'a [f64],
    n: u32,
    /// The groups the batches need not test ([`lanes::LaneMargins::still`]).
    still: u64,
}

/// `step` := `dof` zeros (a batch of points, each in its own cell of the self-collision
/// tables), written only when it holds anything else.
#[inline(always)]
fn zero_steps(step: &mut Vec<f64>, dof: usize) {
    if step.len() != dof || step.iter().any(|&v| v != 0.0) {
        step.clear();
        step.resize(dof, 0.0);
    }
}

/// What [`CollisionModel::settle_batch`] settled: bit `i` for the `i`-th configuration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BatchSettled {
    /// Certainly free (with the margin).
    pub free: u32,
    /// Certainly in contact.
    pub colliding: u32,
}

/// One side of a contact or distance: a robot link or an obstacle.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Body {
    /// A link of the robot (`link` indexes [`Robot::links`]).
    Link {
        /// Index into [`Robot::links`].
        link: usize,
        /// The link's name.
        name: String,
    },
    /// An obstacle of the environment (`index` indexes [`Environment::obstacles`]).
    Obstacle {
        /// Index into [`Environment::obstacles`].
        index: usize,
        /// The obstacle's name.
        name: String,
    },
}

impl Body {
    /// The link's or obstacle's name.
    pub fn name(&self) -> &str {
        match self {
            Body::Link { name, .. } | Body::Obstacle { name, .. } => name,
        }
    }
    /// Whether this is a robot link (not an obstacle).
    pub fn is_link(&self) -> bool {
        matches!(self, Body::Link { .. })
    }
}

impl fmt::Display for Body {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Body::Link { name, .. } => write!(f, "link `{name}`"),
            Body::Obstacle { name, .. } => write!(f, "obstacle `{name}`"),
        }
    }
}

/// A pair in contact: "link `ot_link3` and obstacle `table`". `a` is always a link.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Contact {
    /// The robot link in contact.
    pub a: Body,
    /// The other body: an obstacle or another link of the robot.
    pub b: Body,
}

impl fmt::Display for Contact {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} and {}", self.a, self.b)
    }
}

/// The nearest pair over every checked pair (links against obstacles and non-filtered link pairs).
///
/// `distance` is signed: the gap when free, minus the penetration depth when two shapes overlap.
/// `+inf` when nothing is checked (no obstacles, no self-collision pairs); `-inf` for a `q` of
/// the wrong length. Witness points are in the world frame.
#[derive(Debug, Clone, PartialEq)]
pub struct DistanceReport {
    /// Signed distance (m): the gap when free, minus the penetration depth when overlapping.
    pub distance: f64,
    /// The robot link of the nearest pair.
    pub a: Body,
    /// The other body of the nearest pair: an obstacle or another link.
    pub b: Body,
    /// Witness point on `a`, in the world frame.
    pub point_a: Point3<f64>,
    /// Witness point on `b`, in the world frame.
    pub point_b: Point3<f64>,
}

// ---------------------------------------------------------------------------------------------
// Geometry prepared once per robot / environment.

/// A shape in its body's frame.
#[derive(Debug, Clone)]
enum Local {
    Sphere { c: Point3<f64>, r: f64 },
    Capsule { a: Point3<f64>, b: Point3<f64>, r: f64 },
    Cuboid { iso: Isometry3<f64>, half: Vector3<f64> },
    Cylinder { iso: Isometry3<f64>, r: f64, hh: f64 },
    Mesh { iso: Isometry3<f64>, hull: Arc<ConvexHull> },
}

/// A shape in the world frame.
#[derive(Debug, Clone)]
enum World {
    Sphere { c: Point3<f64>, r: f64 },
    Capsule { a: Point3<f64>, b: Point3<f64>, r: f64 },
    Cuboid { iso: Isometry3<f64>, half: Vector3<f64> },
    Cylinder { iso: Isometry3<f64>, r: f64, hh: f64 },
    Mesh { iso: Isometry3<f64>, hull: Arc<ConvexHull> },
}

impl World {
    const EMPTY: World = World::Sphere { c: Point3::new(0.0, 0.0, 0.0), r: 0.0 };

    #[inline]
    fn view(&self) -> View<'_> {
        match self {
            World::Sphere { c, r } => View::Sphere { c: *c, r: *r },
            World::Capsule { a, b, r } => View::Capsule { a: *a, b: *b, r: *r },
            World::Cuboid { iso, half } => View::Cuboid { iso, half: *half },
            World::Cylinder { iso, r, hh } => View::Cylinder { iso, r: *r, hh: *hh },
            World::Mesh { iso, hull } => View::Mesh { iso, hull },
        }
    }

    fn from_shape(shape: &Shape, pose: &Isometry3<f64>) -> World {
        match shape {
            Shape::Sphere { radius } => World::Sphere { c: Point3::from(pose.translation.vector), r: *radius },
            Shape::Capsule { a, b, radius } => World::Capsule { a: pose * a, b: pose * b, r: *radius },
            Shape::Cuboid { half_extents } => World::Cuboid { iso: *pose, half: *half_extents },
            Shape::Cylinder { radius, half_height } => World::Cylinder { iso: *pose, r: *radius, hh: *half_height },
            Shape::ConvexMesh(hull) => World::Mesh { iso: *pose, hull: hull.clone() },
        }
    }
}

/// How a moving joint gets its value from `q`.
#[derive(Debug, Clone, Copy)]
enum Value {
    Dof(usize),
    Mimic(usize, f64, f64),
    Zero,
}

/// A rigid body of the collision model: the links fixed to one moving joint's child.
/// Pose = pose(parent) * pre * motion(value + offset) * post.
#[derive(Debug, Clone)]
struct FkBody {
    parent: usize,
    pre: Isometry3<f64>,
    prismatic: bool,
    axis: Unit<Vector3<f64>>,
    offset: f64,
    post: Option<Isometry3<f64>>,
    value: Value,
    /// Prismatic joints: the largest |value + offset| within the limits (the joint's reach).
    reach: f64,
}

/// A link that carries shapes (a "slot"), with its bounding sphere in its body's frame.
#[derive(Debug, Clone)]
struct LinkGeom {
    link: usize,
    body: usize,
    shapes: std::ops::Range<usize>,
    c: Point3<f64>,
    r: f64,
}

#[derive(Debug, Clone)]
struct ShapeGeom {
    local: Local,
    /// Bounding sphere in the body frame.
    c: Point3<f64>,
    r: f64,
}

#[derive(Debug)]
struct RobotGeom {
    dof: usize,
    base: Isometry3<f64>,
    bodies: Vec<FkBody>,
    links: Vec<LinkGeom>,
    shapes: Vec<ShapeGeom>,
    self_pairs: Vec<(u32, u32)>,
    cspace: ConfigSpace,
    /// Lever arms of the motion certificate: `lever[slot * dof + i]` bounds how far any point of
    /// link slot `slot` moves per unit change of joint value `i` (m/rad, or 1 for prismatic
    /// joints), in every configuration.
    lever: Vec<f64>,
    /// The same for the relative motion of each self-collision pair:
    /// `pair_lever[p * dof + i]` bounds how much pair `p`'s distance can shrink per unit change
    /// of joint value `i`. Joints that carry both links (the pair's common ancestors) move
    /// them together and do not count.
    pair_lever: Vec<f64>,
    /// `lever`'s rows, then `pair_lever`'s, joint by joint: `lever_t[i * rows + r]` is row
    /// `r`'s arm for joint `i` (a certificate's travel bounds, row by row in vector lanes).
    lever_t: Vec<f64>,
    /// Per joint `i`, the runs `[start, end)` of rows of `lever_t` that hold its nonzero arms
    /// (runs less than [`LEVER_GAP`] rows apart joined): the rows a joint cannot move (the other
    /// arm's links and pairs) are not summed.
    lever_runs: Vec<Vec<(u32, u32)>>,
}

/// [`RobotGeom::travel_rows`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
struct TravelV3<'a> {
    geom: &'a RobotGeom,
    steps: &'a [f64],
    travel: &'a mut [f64],
    rows: usize,
}

#[cfg(target_arch = "x86_64")]
impl pulp::WithSimd for TravelV3<'_> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        self.geom.travel_rows(self.steps, self.travel, self.rows);
    }
}

/// Zero arms between two runs of [`RobotGeom::lever_runs`] below which the runs are one (a
/// few zero products cost less than a second loop).
const LEVER_GAP: usize = 8;

/// The runs of nonzero entries of `arms` (see [`RobotGeom::lever_runs`]).
fn nonzero_runs(arms: &[f64]) -> Vec<(u32, u32)> {
    let mut runs: Vec<(u32, u32)> = Vec::new();
    for (r, _) in arms.iter().enumerate().filter(|&(_, &a)| a != 0.0) {
        let r = r as u32;
        match runs.last_mut() {
            Some(last) if (r - last.1) as usize <= LEVER_GAP => last.1 = r + 1,
            _ => runs.push((r, r + 1)),
        }
    }
    runs
}

#[derive(Debug, Clone)]
struct ObstacleGeom {
    world: World,
    lo: Point3<f64>,
    hi: Point3<f64>,
}

impl ObstacleGeom {
    fn new(o: &Obstacle) -> Self {
        let world = World::from_shape(&o.shape, &o.pose);
        let (lo, hi) = narrow::aabb(&world.view());
        ObstacleGeom { world, lo, hi }
    }
}

/// Squared distance from a point to an axis-aligned box.
#[inline]
fn dist2_point_aabb(p: &Point3<f64>, lo: &Point3<f64>, hi: &Point3<f64>) -> f64 {
    let dx = (lo.x - p.x).max(0.0).max(p.x - hi.x);
    let dy = (lo.y - p.y).max(0.0).max(p.y - hi.y);
    let dz = (lo.z - p.z).max(0.0).max(p.z - hi.z);
    dx * dx + dy * dy + dz * dz
}

#[inline]
fn sphere_hits_aabb(c: &Point3<f64>, r: f64, o: &ObstacleGeom) -> bool {
    dist2_point_aabb(c, &o.lo, &o.hi) <= r * r
}

/// Centre and radius of a sphere enclosing a set of spheres (centroid-based, not minimal).
fn enclosing_sphere(spheres: &[(Point3<f64>, f64)]) -> (Point3<f64>, f64) {
    if spheres.is_empty() {
        return (Point3::origin(), 0.0);
    }
    let n = spheres.len() as f64;
    let c = Point3::from(spheres.iter().fold(Vector3::zeros(), |s, (p, _)| s + p.coords) / n);
    let r = spheres.iter().map(|(p, r)| (p - c).norm() + r).fold(0.0, f64::max);
    (c, r)
}

impl RobotGeom {
    /// `travel` := how far each link's points can travel (against obstacles), then how far each
    /// self-collision pair can close in on itself, over a motion whose joints change by
    /// `steps` (magnitudes). Joint by joint over all rows at once: each row's sum in joint
    /// order from 0, as the sum of its products would be (the same values: the products left
    /// out, of a joint that does not move or of a zero arm, are zeros added to sums that are not
    /// negative), but in vector lanes.
    /// Compiled for AVX2 where the CPU has it (pulp's run-time dispatch): four rows a step
    /// instead of two (a multiply and an add, never fused: the same values).
    fn travel_into(&self, steps: &[f64], travel: &mut Vec<f64>) {
        travel.clear();
        let rows = self.links.len() + self.self_pairs.len();
        travel.resize(rows, 0.0);
        #[cfg(target_arch = "x86_64")]
        if let Some(v3) = pulp::x86::V3::try_new() {
            return pulp::Simd::vectorize(v3, TravelV3 { geom: self, steps, travel, rows });
        }
        self.travel_rows(steps, travel, rows);
    }

    /// [`Self::travel_into`] on the instruction set of its caller, into `travel` (`rows` zeros).
    #[inline(always)]
    fn travel_rows(&self, steps: &[f64], travel: &mut [f64], rows: usize) {
        for ((arms, &d), runs) in self.lever_t.chunks_exact(rows.max(1)).zip(steps).zip(&self.lever_runs) {
            if d == 0.0 {
                continue;
            }
            for &(a, b) in runs {
                let (a, b) = (a as usize, b as usize);
                for (t, arm) in travel[a..b].iter_mut().zip(&arms[a..b]) {
                    *t += arm * d;
                }
            }
        }
    }

    fn new(robot: &Robot) -> Self {
        let links = robot.links();
        let joints = robot.joints();
        let n = links.len();
        // Merge fixed-jointed links into bodies: body_of[link], and the link frame in the body frame.
        let mut body_of = vec![0usize; n];
        let mut in_body = vec![Isometry3::identity(); n];
        let mut bodies = vec![FkBody {
            parent: usize::MAX,
            pre: Isometry3::identity(),
            prismatic: false,
            axis: Vector3::z_axis(),
            offset: 0.0,
            post: None,
            value: Value::Zero,
            reach: 0.0,
        }];
        for j in joints {
            let (p, c) = (j.parent_link, j.child_link);
            if j.kind == JointKind::Fixed {
                body_of[c] = body_of[p];
                in_body[c] = in_body[p] * j.local_transform(0.0);
            } else {
                let value = match (j.dof_index, j.mimic) {
                    (Some(i), _) => Value::Dof(i),
                    (None, Some((d, m, o))) => Value::Mimic(d, m, o),
                    _ => Value::Zero,
                };
                let is_identity = |t: &Isometry3<f64>| t.translation.vector.norm() == 0.0 && t.rotation.angle() == 0.0;
                let reach = if j.kind == JointKind::Prismatic {
                    let (lo, hi) = match value {
                        Value::Dof(i) => (robot.dof_joint(i).limits.lower, robot.dof_joint(i).limits.upper),
                        Value::Mimic(d, m, o) => {
                            let l = robot.dof_joint(d).limits;
                            (l.lower * m + o, l.upper * m + o)
                        }
                        Value::Zero => (0.0, 0.0),
                    };
                    let r = (lo + j.offset).abs().max((hi + j.offset).abs());
                    if r.is_finite() { r } else { f64::INFINITY }
                } else {
                    0.0
                };
                bodies.push(FkBody {
                    parent: body_of[p],
                    pre: in_body[p] * j.origin,
                    prismatic: j.kind == JointKind::Prismatic,
                    axis: j.axis,
                    offset: j.offset,
                    post: if is_identity(&j.post) { None } else { Some(j.post) },
                    value,
                    reach,
                });
                body_of[c] = bodies.len() - 1;
                in_body[c] = Isometry3::identity();
            }
        }
        // Keep only bodies that carry shapes or lead to some.
        let mut needed = vec![false; bodies.len()];
        needed[0] = true;
        for (l, link) in links.iter().enumerate() {
            if !link.shapes.is_empty() {
                needed[body_of[l]] = true;
            }
        }
        for b in (1..bodies.len()).rev() {
            if needed[b] {
                needed[bodies[b].parent] = true;
            }
        }
        let mut remap = vec![usize::MAX; bodies.len()];
        let mut kept = Vec::new();
        for (b, body) in bodies.into_iter().enumerate() {
            if needed[b] {
                remap[b] = kept.len();
                let mut body = body;
                if b != 0 {
                    body.parent = remap[body.parent];
                }
                kept.push(body);
            }
        }
        // Shapes in body frames, grouped by link.
        let mut slots = Vec::new();
        let mut shapes = Vec::new();
        for (l, link) in links.iter().enumerate() {
            if link.shapes.is_empty() {
                continue;
            }
            let first = shapes.len();
            let mut spheres = Vec::new();
            for ps in &link.shapes {
                let pose = in_body[l] * ps.pose;
                let local = match &ps.shape {
                    Shape::Sphere { radius } => Local::Sphere { c: Point3::from(pose.translation.vector), r: *radius },
                    Shape::Capsule { a, b, radius } => Local::Capsule { a: pose * a, b: pose * b, r: *radius },
                    Shape::Cuboid { half_extents } => Local::Cuboid { iso: pose, half: *half_extents },
                    Shape::Cylinder { radius, half_height } => {
                        Local::Cylinder { iso: pose, r: *radius, hh: *half_height }
                    }
                    Shape::ConvexMesh(hull) => Local::Mesh { iso: pose, hull: hull.clone() },
                };
                let (c, r) = ps.shape.bounding_sphere();
                let c = pose * c;
                spheres.push((c, r));
                shapes.push(ShapeGeom { local, c, r });
            }
            let (c, r) = enclosing_sphere(&spheres);
            slots.push(LinkGeom { link: l, body: remap[body_of[l]], shapes: first..shapes.len(), c, r });
        }
        let self_pairs = self_collision_pairs(robot, &slots);
        let dof = robot.dof();
        let mut lever = vec![0.0; slots.len() * dof];
        for slot in 0..slots.len() {
            lever_arms(dof, &kept, &slots, &shapes, slot, 0, &mut lever[slot * dof..(slot + 1) * dof]);
        }
        let mut pair_lever = vec![0.0; self_pairs.len() * dof];
        for (p, &(a, b)) in self_pairs.iter().enumerate() {
            let (a, b) = (a as usize, b as usize);
            let stop = common_body(&kept, slots[a].body, slots[b].body);
            let out = &mut pair_lever[p * dof..(p + 1) * dof];
            lever_arms(dof, &kept, &slots, &shapes, a, stop, out);
            lever_arms(dof, &kept, &slots, &shapes, b, stop, out);
        }
        let rows: Vec<&[f64]> = lever.chunks_exact(dof.max(1)).chain(pair_lever.chunks_exact(dof.max(1))).collect();
        let lever_t: Vec<f64> = (0..dof).flat_map(|i| rows.iter().map(move |r| r[i])).collect();
        let lever_runs = lever_t.chunks_exact(rows.len().max(1)).map(nonzero_runs).take(dof).collect();
        RobotGeom {
            dof: robot.dof(),
            base: *robot.base(),
            bodies: kept,
            links: slots,
            shapes,
            self_pairs,
            cspace: ConfigSpace::new(robot),
            lever,
            pair_lever,
            lever_t,
            lever_runs,
        }
    }
}

/// Lever arms of the motion certificate (see [`RobotGeom::lever`]).
///
/// A revolute joint turning by `dq` moves a point at distance `rho` from its axis by at most
/// `rho * |dq|`; a prismatic joint moves every point below it by `|dq|`. Along a straight
/// joint-space segment the path of a point is therefore no longer than `sum_i lever[i] * |dq_i|`
/// when `lever[i]` bounds `rho` for joint `i` over every configuration. The axis of a body's
/// joint passes through the origin of the frame the joint moves in (`pre`'s), along `axis`; a
/// point `c` of the body sits at `post * c` in that frame, fixed. Walking up from the link:
///
/// * its own joint: `rho` is the distance of `post * c` from the axis, exactly (no joint in
///   between);
/// * each joint above: the origin of the child's joint frame sits at a fixed point `w` of the
///   parent's joint frame (`post * pre.translation` of the child), and the rest of the chain
///   down to the point has a length of at most `below` whatever the joints between do, so `rho`
///   is at most the distance of `w` from the axis plus `below`; then `below` grows by `|w|` and
///   the parent's prismatic reach.
///
/// Sphere shapes count by their centre (a ball turning about its centre covers the same set);
/// other shapes add their bounding radius. Each bound is at most the plain triangle bound (the
/// lengths of the fixed translations on the chain).
///
/// Adds link slot `slot`'s lever arms into `out` (one per DOF), over the joints from its body up
/// to, not including, body `stop` (0, the base, for motion in the world; the deepest common
/// ancestor for motion relative to another link).
fn lever_arms(
    dof: usize,
    bodies: &[FkBody],
    slots: &[LinkGeom],
    shapes: &[ShapeGeom],
    slot: usize,
    stop: usize,
    out: &mut [f64],
) {
    debug_assert_eq!(out.len(), dof);
    let l = &slots[slot];
    let mut b = l.body;
    if b == 0 || b == stop {
        return;
    }
    let body = &bodies[b];
    // Farthest point of the link from the origin of its joint's frame, and from the axis.
    let (mut below, mut arm) = l
        .shapes
        .clone()
        .map(|k| {
            let sh = &shapes[k];
            let w = body.post.map_or(sh.c.coords, |p| (p * sh.c).coords);
            let own = if matches!(sh.local, Local::Sphere { .. }) { 0.0 } else { sh.r };
            (w.norm() + own, off_axis(&w, body) + own)
        })
        .fold((0.0f64, 0.0f64), |(a, b), (x, y)| (a.max(x), b.max(y)));
    below += body.reach;
    loop {
        let body = &bodies[b];
        let (i, factor) = match body.value {
            Value::Dof(i) => (Some(i), 1.0),
            Value::Mimic(d, m, _) => (Some(d), m.abs()),
            Value::Zero => (None, 0.0),
        };
        if let Some(i) = i {
            out[i] += factor * if body.prismatic { 1.0 } else { arm };
        }
        let parent = body.parent;
        if parent == 0 || parent == stop {
            return;
        }
        let up = &bodies[parent];
        let at = Point3::from(body.pre.translation.vector);
        let w = up.post.map_or(at.coords, |p| (p * at).coords);
        arm = off_axis(&w, up) + below;
        below += w.norm() + up.reach;
        b = parent;
    }
}

/// Distance of `w` (in the frame `body`'s joint moves in) from that joint's axis.
fn off_axis(w: &Vector3<f64>, body: &FkBody) -> f64 {
    let a = body.axis.into_inner();
    (w - a * w.dot(&a)).norm()
}

/// The deepest body that carries both `a` and `b` (bodies are stored parents first).
fn common_body(bodies: &[FkBody], mut a: usize, mut b: usize) -> usize {
    while a != b {
        if a > b {
            a = bodies[a].parent;
        } else {
            b = bodies[b].parent;
        }
    }
    a
}

/// The link pairs to check for self-collision (as slot indices): not on the same link, not
/// disabled, not adjacent (directly, or through links without shapes).
fn self_collision_pairs(robot: &Robot, slots: &[LinkGeom]) -> Vec<(u32, u32)> {
    let links = robot.links();
    let parent = |l: usize| links[l].parent_joint.map(|j| robot.joints()[j].parent_link);
    let ancestors = |mut l: usize| {
        let mut v = vec![l];
        while let Some(p) = parent(l) {
            v.push(p);
            l = p;
        }
        v
    };
    let adjacent = |a: usize, b: usize| {
        let pa = ancestors(a);
        let pb = ancestors(b);
        let Some(lca) = pa.iter().copied().find(|x| pb.contains(x)) else { return false };
        // The links strictly between a and b on the tree path must all be shapeless.
        let between_a = pa.iter().take_while(|&&x| x != lca).skip(1);
        let between_b = pb.iter().take_while(|&&x| x != lca).skip(1);
        let lca_between = lca != a && lca != b;
        between_a.chain(between_b).all(|&x| links[x].shapes.is_empty())
            && (!lca_between || links[lca].shapes.is_empty())
    };
    let disabled = robot.disabled_pairs();
    let mut pairs = Vec::new();
    for i in 0..slots.len() {
        for j in i + 1..slots.len() {
            let (a, b) = (slots[i].link, slots[j].link);
            if a == b || disabled.contains(&(a.min(b), a.max(b))) || adjacent(a, b) {
                continue;
            }
            pairs.push((i as u32, j as u32));
        }
    }
    pairs
}

// ---------------------------------------------------------------------------------------------
// Scratch.

/// A sub-interval `t0..t1` of the motion certificate still to check and, on the sphere path,
/// the range of `spheres.items` listing what was near over the sub-interval holding it (`None`:
/// test everything).
#[derive(Debug, Clone, Copy)]
struct Span {
    t0: f64,
    t1: f64,
    within: Option<(usize, usize)>,
    /// The self pairs are certainly free over the sub-interval (a single-precision batch said
    /// so): its double-precision check tests the obstacles alone.
    pairs_free: bool,
}

/// The largest travel of a link (the first `slots` rows of `travel`) and of a self pair (the
/// rest), each 0 when there is none (a plain comparison: travels are finite).
fn travel_max(travel: &[f64], slots: usize) -> (f64, f64) {
    let (links, pairs) = travel.split_at(slots.min(travel.len()));
    let max = |v: &[f64]| v.iter().fold(0.0, |m: f64, &t| if t > m { t } else { m });
    (max(links), max(pairs))
}

/// The inflation of a sub-interval of half-length `half` (a share of the segment): `margins` :=
/// each row of `travel` (links, then self pairs) times `half`, `step` := each joint's change
/// `steps` times `half`; a relative 1e-9 and (margins) an absolute 1e-12 more than the bound,
/// against rounding.
fn span_margins(half: f64, travel: &[f64], steps: &[f64], margins: &mut Vec<f64>, step: &mut Vec<f64>) {
    let scale = half * (1.0 + 1e-9);
    margins.clear();
    margins.extend(travel.iter().map(|t| t * scale + 1e-12));
    step.clear();
    step.extend(steps.iter().map(|d| d * scale));
}

/// `dir` := the signed joint changes `delta` of a segment times the scale [`span_margins`] gives
/// a sub-interval of half-length `half` (the same relative slack).
fn span_dir(half: f64, delta: &[f64], dir: &mut Vec<f64>) {
    let scale = half * (1.0 + 1e-9);
    dir.clear();
    dir.extend(delta.iter().map(|d| d * scale));
}

/// The certificate's first level for a segment whose links travel at most `most`: equal pieces
/// small enough that the largest margin is at most [`CERTIFY_START_MARGIN`], never more than
/// 2^[`CERTIFY_START_LEVELS`].
fn first_pieces(most: f64) -> usize {
    let mut pieces = 1usize;
    while pieces < 1 << CERTIFY_START_LEVELS && most * 0.5 / pieces as f64 > CERTIFY_START_MARGIN {
        pieces *= 2;
    }
    pieces
}

/// How far either side of a sub-interval's midpoint (in segment fraction) a listing query
/// certified free, from the sub-interval's half-length `half` and the query's `reach` (the
/// smallest ratio of a near item's gap to its margin, see `SphereScratch::reach`): 0 to halve.
///
/// Sound because every margin of the sphere path grows at least in proportion to the
/// sub-interval: a margin is a sum over the moving joints of an arm times the joint's change,
/// the change is proportional to the sub-interval, and each arm (the static one, or the
/// distance from the axis at the midpoint plus how far the joints below can move the point,
/// see `spheres::arms`) does not shrink as the sub-interval grows. So over `reach * half`
/// either side of the midpoint each near item moves by at most `reach` times its margin, which
/// is at most its gap. The gaps were taken 2e-12 m short and the result 0.1% short, against
/// rounding (the query's margins already carry a relative 1e-9 and an absolute 1e-12 more
/// than the bound); below 1e-12 of the segment it is not worth a split point of its own.
fn reach_of(half: f64, reach: f64) -> f64 {
    let rho = half * reach * 0.999;
    if rho >= 1e-12 && rho < half { rho } else { 0.0 }
}

/// `spans` := the `pieces` (a power of two) equal pieces of [0, 1], middle first, then the
/// quarters, the eighths...: the ends of a certified segment are free, so a collision is
/// likeliest in the middle, and a segment that collides is refused after fewer checks. (Piece
/// `k` of the bit-reversed order, turned so that the first piece comes last.)
fn bit_reversed_pieces(spans: &mut Vec<Span>, pieces: usize) {
    // Exact: `pieces` is a power of two, so are its inverse and the products below.
    let width = 1.0 / pieces as f64;
    spans.clear();
    spans.extend((1..=pieces).map(|k| {
        let i = piece_in_order(k, pieces);
        Span { t0: i as f64 * width, t1: (i + 1) as f64 * width, within: None, pairs_free: false }
    }));
}

/// The piece taken `k`-th (from 1) of `pieces` (a power of two, at most [`LANES_MAX_PIECES`]) in
/// [`bit_reversed_pieces`]'s order.
#[inline(always)]
fn piece_in_order(k: usize, pieces: usize) -> usize {
    usize::from(BIT_REVERSED[k % pieces]) >> (LANES_MAX_PIECES.trailing_zeros() - pieces.trailing_zeros())
}

/// The pieces of a first level of batches of `pieces` pieces (a multiple of [`lanes::LANES`], at
/// most [`LANES_MAX_PIECES`]) in the order the batches take them: with `m = pieces / 8`, each
/// batch takes every `m`-th piece from an offset below `m`, so that its lanes spread over the
/// whole segment; the offsets come in bit-reversed order (for 16 pieces: the odd ones, then the
/// even ones). A contact anywhere is met in the first batch or soon after.
fn lane_pieces_in_order(pieces: usize) -> impl Iterator<Item = usize> {
    // The bit reversals of 1, 2, ..., 8 in three bits (of 8 as 0).
    const SPREAD: [usize; 8] = [4, 2, 6, 1, 5, 3, 7, 0];
    let m = pieces / lanes::LANES;
    SPREAD.into_iter().filter(move |&o| o < m).flat_map(move |o| (0..lanes::LANES).map(move |j| o + m * j))
}

/// Per-thread working memory of a query (link poses, world shapes, candidate lists). Reuse one
/// per thread to keep queries allocation-free; it adapts itself to whichever model uses it.
#[derive(Debug, Clone)]
pub struct CollisionScratch {
    body_iso: Vec<Isometry3<f64>>,
    body_rot: Vec<Matrix3<f64>>,
    link_c: Vec<Point3<f64>>,
    link_stamp: Vec<u32>,
    stamp: u32,
    world: Vec<World>,
    world_c: Vec<Point3<f64>>,
    candidates: Vec<u32>,
    /// Per obstacle, the grid query that last visited it (a link's cells may list it twice).
    visited: Vec<u32>,
    visit: u32,
    q: Vec<f64>,
    intervals: Vec<(u32, u32)>,
    spans: Vec<Span>,
    /// The pieces a level of single-precision batches leaves (index at the level's cut, self
    /// pairs free, the groups found near an obstacle), and those of the level before while the
    /// next runs.
    lanes_left: Vec<(u32, bool, u64)>,
    lanes_parents: Vec<(u32, bool, u64)>,
    /// Whether a level of the certificate's batches tests only what the level before left
    /// near (the groups near an obstacle, the self pairs not found free); false: everything,
    /// for tests that compare the two.
    scoped_levels: bool,
    /// Batches of the certificate's levels that skipped a group's obstacle tests or the self
    /// pairs (for tests).
    #[cfg(test)]
    pub(crate) scoped_batches: u64,
    steps: Vec<f64>,
    /// The joint steps of the segment a certificate checks (signed).
    delta: Vec<f64>,
    step: Vec<f64>,
    /// The signed counterpart of `step` (see [`Inflation::dir`]).
    dir: Vec<f64>,
    inflation: Vec<f64>,
    margins: Vec<f64>,
    /// The points of an edge probe, or one of them (see [`CollisionModel::probe_collides`]).
    probe: Vec<f64>,
    /// Per shape and obstacle, then per pair of shapes, the direction that last separated the
    /// pair, where GJK starts (see [`narrow::intersects_from`]; zero: none yet). Only a start:
    /// any value is sound.
    hints: Vec<narrow::Hint>,
    /// The model (its geometry and scene, by address) `hints` are of.
    hints_of: (usize, usize),
    /// How many of `hints` are of a shape and an obstacle (the self pairs' follow, if any).
    hints_env: usize,
    /// The items a certificate's grown checks on the general path found near, level after
    /// level (see [`CollisionModel::check_items`]): link slot `l` against obstacle `o` as
    /// `l * obstacles + o`, self pair `p` as `links * obstacles + p`.
    near_items: Vec<u32>,
    /// Whether grown scans record their near items in `near_items` (in certificates only).
    record_near: bool,
    /// Per link slot, whether no joint moves it along an edge probe (see
    /// [`CollisionModel::still_links`]); while `skip_still`, exact scans skip such links
    /// against obstacles and pairs of two such links (edge probes from a free start only).
    still: Vec<bool>,
    skip_still: bool,
    /// Per body, whether it is still (working memory of `still`).
    still_bodies: Vec<bool>,
    spheres: SphereScratch,
}

impl Default for CollisionScratch {
    fn default() -> Self {
        Self::new()
    }
}

impl CollisionScratch {
    /// This scratch with every level of the certificate's batches testing everything (see
    /// `scoped_levels`), for tests that compare the two.
    #[cfg(test)]
    pub(crate) fn with_unscoped_levels(mut self) -> Self {
        self.scoped_levels = false;
        self
    }

    /// An empty scratch space; it grows to the size the first query needs.
    pub const fn new() -> Self {
        Self {
            body_iso: Vec::new(),
            body_rot: Vec::new(),
            link_c: Vec::new(),
            link_stamp: Vec::new(),
            stamp: 0,
            world: Vec::new(),
            world_c: Vec::new(),
            candidates: Vec::new(),
            visited: Vec::new(),
            visit: 0,
            q: Vec::new(),
            intervals: Vec::new(),
            spans: Vec::new(),
            lanes_left: Vec::new(),
            lanes_parents: Vec::new(),
            scoped_levels: true,
            #[cfg(test)]
            scoped_batches: 0,
            steps: Vec::new(),
            delta: Vec::new(),
            step: Vec::new(),
            dir: Vec::new(),
            inflation: Vec::new(),
            margins: Vec::new(),
            probe: Vec::new(),
            hints: Vec::new(),
            hints_of: (0, 0),
            hints_env: 0,
            near_items: Vec::new(),
            record_near: false,
            still: Vec::new(),
            skip_still: false,
            still_bodies: Vec::new(),
            spheres: SphereScratch::new(),
        }
    }

    /// This working memory's single-precision batches (the motion certificate's first pieces,
    /// [`CollisionModel::settle_batch`]) run on the x86-64 baseline's vector instructions (SSE2)
    /// even where the CPU has AVX2, which they use by default: for tests and measurements that
    /// compare the two. Exact queries answer the same; a certificate's batches may settle other
    /// pieces near a threshold (AVX2 fuses products into sums), so its work may differ.
    pub fn with_baseline_vectors(mut self) -> Self {
        self.spheres.lanes.isa = Isa::Baseline;
        self
    }

    /// Size the buffers for a model (no allocation once they are big enough) and start a query.
    fn begin(&mut self, g: &RobotGeom) {
        if self.body_iso.len() != g.bodies.len() {
            self.body_iso.resize(g.bodies.len(), Isometry3::identity());
            self.body_rot.resize(g.bodies.len(), Matrix3::identity());
        }
        if self.link_c.len() != g.links.len() {
            self.link_c.resize(g.links.len(), Point3::origin());
            self.link_stamp.resize(g.links.len(), 0);
        }
        if self.world.len() != g.shapes.len() {
            self.world.resize(g.shapes.len(), World::EMPTY);
            self.world_c.resize(g.shapes.len(), Point3::origin());
        }
        self.stamp = self.stamp.wrapping_add(1);
        if self.stamp == 0 {
            self.link_stamp.iter_mut().for_each(|s| *s = 0);
            self.stamp = 1;
        }
    }
}

/// Two posed shapes grown by `e` (`GROW`), answered as [`CollisionModel::link_hits_obstacle`]
/// answers a link: `Err(())` for an exact contact, `Ok(true)` when only the grown shapes may
/// touch. Grown, one GJK run answers proximity and overlap together; `hint` is the pair's
/// kept separating direction, if it has one.
#[inline]
fn shapes_hit<const GROW: bool>(a: &View, b: &View, e: f64, hint: Option<&mut narrow::Hint>) -> Result<bool, ()> {
    let mut none = narrow::Hint::NONE;
    let hint = hint.unwrap_or(&mut none);
    if GROW && e > 0.0 {
        return match narrow::proximity_from(a, b, e, hint) {
            narrow::Proximity::Farther => Ok(false),
            narrow::Proximity::Near => Ok(true),
            narrow::Proximity::Touching => Err(()),
        };
    }
    if narrow::intersects_from(a, b, hint) { Err(()) } else { Ok(false) }
}

/// Robots with more shapes than this keep no separating directions for their self pairs (one
/// per pair of shapes would be too many).
const HINTED_SHAPES_MAX: usize = 128;

/// Models with more pairs of a shape and an obstacle than this keep no separating directions
/// for them (the scratch's directions are set to none at the start of every plan: about 0.4
/// MB at most, with the self pairs').
const HINTED_ENV_MAX: usize = 1 << 14;

/// At most this many spare scratch spaces per thread (see [`CollisionModel::scratch`]).
const SPARE_SCRATCHES: usize = 4;

thread_local! {
    static SCRATCH: RefCell<CollisionScratch> = const { RefCell::new(CollisionScratch::new()) };
    /// Scratch spaces dropped on this thread, for [`CollisionModel::scratch`] to hand out again
    /// with their buffers grown.
    static SPARE: RefCell<Vec<CollisionScratch>> = const { RefCell::new(Vec::new()) };
}

impl Drop for CollisionScratch {
    /// A scratch that holds buffers goes to its thread's spares (when there is room), so that
    /// the next [`CollisionModel::scratch`] on the thread starts with them: a planner takes a
    /// fresh one per query, and growing its buffers again cost about 3% of a MotionBenchMaker
    /// UR5 query. Otherwise (no room, or during the thread's exit) it is freed as usual.
    fn drop(&mut self) {
        if self.body_iso.capacity() == 0 {
            return;
        }
        let _ = SPARE.try_with(|spare| {
            if let Ok(mut spare) = spare.try_borrow_mut()
                && spare.len() < SPARE_SCRATCHES
            {
                spare.push(std::mem::take(self));
            }
        });
    }
}

// ---------------------------------------------------------------------------------------------
// The model.

/// The motion certificate's first level (see [`CollisionModel::motion_is_certified_free`]): the
/// segment is cut into equal pieces until the largest margin (the farthest any link can travel
/// in half a piece) is at most this many metres, or into `2^CERTIFY_START_LEVELS` pieces. A
/// sub-interval whose shapes grow by more is all but never free among the obstacles of an arm's
/// workspace, and testing it only to split it cost the planner about 10% of its instructions on
/// the MotionBenchMaker UR5 problems. 0.3 m and 16 pieces measured best of 0.08-1.0 m and 4-32
/// pieces (since halves are checked against only what was near over the whole; 8 pieces before:
/// 16 take 4% fewer instructions, 4 take 20% more). In open space it costs up to 16 checks where
/// one would do.
pub const CERTIFY_START_MARGIN: f64 = 0.3;

/// See [`CERTIFY_START_MARGIN`].
pub const CERTIFY_START_LEVELS: u32 = 4;

/// A certificate on the sphere path checks its first pieces in single-precision batches of eight
/// (see `CollisionModel::batched_levels`), cut finer than the double-precision first level
/// ([`CERTIFY_START_MARGIN`]): into as few whole batches of pieces as keep every link's travel in
/// half a piece within this many metres, or into [`LANES_MAX_PIECES`]. A batch costs about four
/// double-precision checks and proves most pieces this small free; the rest go on to the
/// double-precision checks with their tighter per-sphere margins. Over the first 30
/// MotionBenchMaker UR5 problems of each family, planning instructions (double-precision only:
/// 191.5 M): 0.02 m 206.6 M, 0.04 m 189.9 M, 0.08 m 180.7 M, 0.15 m 187.6 M, 0.3 m 218.0 M; a
/// second or third level of batches over what the first leaves (halved) 182.8 M and 186.5 M then.
/// Today further levels that fill their batches pay (see [`LANES_LEVELS`]), and with them (same 90
/// paths): 0.05 m 67.41 M, 0.08 m 63.98 M, 0.10 m 62.14 M, 0.12 m 61.59 M, 0.14 m 61.93 M, 0.16 m
/// 62.79 M; 40 generated cage problems 183.2 M at 0.08 m, 183.1 M at 0.12 m. With whole batches of
/// pieces instead of powers of two (public 90, the same paths as 0.12 m in powers of two, 58.02 M):
/// 0.08 m 57.92 M, 0.09 m 57.17 M, 0.10 m 56.64 M, 0.11 m 56.84 M, 0.12 m 57.19 M, 0.14 m 58.04 M,
/// 0.16 m 58.56 M; 40 generated cage problems 173.80 M at 0.10 m, 174.51 M at 0.12 m (174.09 M
/// before).
const LANES_START_MARGIN: f64 = 0.10;

/// See [`LANES_START_MARGIN`].
const LANES_MAX_PIECES: usize = 64;

/// `k` with its [`LANES_MAX_PIECES`]`.trailing_zeros()` bits reversed, for every `k` below
/// [`LANES_MAX_PIECES`]; of `2^b` pieces, `k`'s bit reversal is this shifted right by the
/// difference in bits.
const BIT_REVERSED: [u8; LANES_MAX_PIECES] = {
    let bits = LANES_MAX_PIECES.trailing_zeros();
    let mut out = [0u8; LANES_MAX_PIECES];
    let mut k = 0;
    while k < LANES_MAX_PIECES {
        out[k] = (k.reverse_bits() >> (usize::BITS - bits)) as u8;
        k += 1;
    }
    out
};

// Every first level (the double-precision one and the batches') has a table entry per piece.
const _: () = assert!(1 << CERTIFY_START_LEVELS <= LANES_MAX_PIECES && LANES_MAX_PIECES <= 256);
// A first level of batches has at most eight batches (see `lane_pieces_in_order`).
const _: () = assert!(LANES_MAX_PIECES.is_multiple_of(lanes::LANES) && LANES_MAX_PIECES <= 8 * lanes::LANES);

/// Fewer pieces than this are left to the double-precision checks.
const LANES_MIN_PIECES: usize = 2;

/// Levels of single-precision batches in a certificate before the double-precision checks
/// take what is left: the first cuts the segment into equal pieces, each further one cuts each
/// piece left into as many parts as fill one batch (at least halves). Over the first 30
/// MotionBenchMaker UR5 problems of each public family, planning instructions with 1 level
/// 66.02 M, 2: 64.39 M, 3: 63.98 M, 4: 64.11 M (the same 90 paths); 40 generated cage problems
/// 184.2 M -> 183.2 M with 3. With first pieces of 0.12 m and self pairs tested on the last
/// level only: 3 levels 61.42 M (cage 182.94 M), 4: 61.10 M (182.83 M), 5: 61.12 M (182.69 M).
/// Since further levels test only what the coarser piece left near, they cost less: all 296
/// public UR5 problems 174.5 M with 4 levels, 172.5 M with 6, 172.7 M with 8; Panda's first 10 of
/// each family 137.1 -> 136.8 M, the Fetch's first 5 593.4 -> 588.6 M with 6 (the same paths).
const LANES_LEVELS: u32 = 6;

/// Most checks one certificate may spend before it gives up and answers "not free" (sound: a
/// planner only loses a segment it could not prove). A segment that grazes an obstacle over a
/// long stretch is bisected breadth first down to the tolerance: about twice its travel over
/// the tolerance in checks (2 m sliding 1e-6 m from a wall at 1e-4: 40,000, each a GJK query),
/// which made a shortcut pass run for minutes. Free certificates take about 30 checks on the
/// MotionBenchMaker UR5 problems, the largest problem 2,269 checks in all.
pub const CERTIFY_MAX_CHECKS: u32 = 4096;

/// Margins of an inflated query: `link[slot]` against obstacles, `pair[p]` for self-collision
/// pair `p` (the two links together).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Inflation<'a> {
    pub link: &'a [f64],
    pub pair: &'a [f64],
    /// `|dq_i|` over the whole segment times the scale of the sub-interval (half its share of
    /// the segment): the sphere path computes its tighter per-sphere margins from it.
    pub step: &'a [f64],
    /// `dq_i` (signed) times the same scale: the sub-interval is `q(tm) + s dir`, `|s| <= 1`.
    pub dir: &'a [f64],
}

/// What [`CollisionModel::segment_for_tests`] gives.
#[cfg(test)]
struct SegmentForTests<'a> {
    fast: &'a SphereGeom,
    delta: Vec<f64>,
    steps: Vec<f64>,
    travel: Vec<f64>,
}

/// Which pair collided, by slot/obstacle index (no allocation on the hot path).
#[derive(Debug, Clone, Copy)]
enum Hit {
    Env { slot: usize, obstacle: usize },
    Pair { a: usize, b: usize },
}

/// A robot and its environment, prepared for fast collision queries. Cheap to clone (the robot
/// geometry and the prepared environment are shared, the latter until a clone changes it);
/// `Send + Sync`.
#[derive(Debug, Clone)]
pub struct CollisionModel {
    robot: Arc<Robot>,
    geom: Arc<RobotGeom>,
    /// The sphere fast path, when every shape of the robot is a sphere (and it is not switched off).
    fast: Option<Arc<SphereGeom>>,
    /// The environment and what is prepared from it, shared by clones until one of them changes
    /// it: a clone of the model is a few reference counts (a race of planners hands one to each
    /// racer; cloning the environment's parts took 2.8 µs on a MotionBenchMaker scene).
    scene: Arc<Scene>,
}

/// A [`CollisionModel`]'s environment and what is prepared from it.
#[derive(Debug, Clone)]
struct Scene {
    env: Environment,
    obstacles: Vec<ObstacleGeom>,
    solids: Vec<Solid>,
    /// The obstacles in single precision for the certificate's batches (`None` when one has
    /// no closed form there, or the robot is not on the sphere path).
    solids32: Option<Arc<Solids32>>,
    /// The broad phase over many obstacles (from [`GRID_MIN_OBSTACLES`] on; fewer are tested
    /// against the box around the whole robot, then link by link).
    grid: Option<grid::ObstacleGrid>,
}

/// From this many obstacles on, the general path finds the obstacles near each link through a
/// grid instead of testing every obstacle that overlaps the robot's box against every link.
const GRID_MIN_OBSTACLES: usize = 128;

impl CollisionModel {
    /// The collision model of `robot` in `env`: geometry prepared once, queried per configuration.
    pub fn new(robot: &Robot, env: Environment) -> Self {
        Self::build(robot, env, true)
    }

    /// [`Self::new`]; `prove_cells`: whether the sphere path proves its self-collision cells
    /// (see `spheres::table`), which pays only for a model that answers many queries.
    fn build(robot: &Robot, env: Environment, prove_cells: bool) -> Self {
        let geom = Arc::new(RobotGeom::new(robot));
        let fast = SphereGeom::new(&geom, prove_cells).map(Arc::new);
        let obstacles: Vec<ObstacleGeom> = env.obstacles().iter().map(ObstacleGeom::new).collect();
        let solids = obstacles.iter().map(|o| Solid::new(&o.world)).collect();
        let scene = Arc::new(Scene { env, obstacles, solids, solids32: None, grid: None });
        let mut model = Self { robot: Arc::new(robot.clone()), geom, fast, scene };
        model.grid_obstacles();
        model
    }

    /// (Re)build the obstacle grid of the general path, for [`GRID_MIN_OBSTACLES`] or more.
    /// Cells are about as wide as a typical link's bounding sphere, so a link's box overlaps a
    /// few cells.
    fn grid_obstacles(&mut self) {
        let sphere_geom = self.fast.clone();
        let fast = sphere_geom.is_some();
        let geom = Arc::clone(&self.geom);
        let scene = Arc::make_mut(&mut self.scene);
        scene.solids32 = sphere_geom.and_then(|g| {
            let mut solids32 = Solids32::new(&scene.solids)?;
            solids32.set_fixed_clearance(&g, &scene.solids);
            Some(Arc::new(solids32))
        });
        scene.grid = None;
        if scene.obstacles.len() < GRID_MIN_OBSTACLES || fast {
            return;
        }
        let mut widths: Vec<f64> = geom.links.iter().map(|l| 2.0 * l.r).filter(|w| w.is_finite()).collect();
        widths.sort_by(f64::total_cmp);
        let cell = widths.get(widths.len() / 2).copied().unwrap_or(0.5).clamp(0.05, 1.0);
        let boxes: Vec<(Point3<f64>, Point3<f64>)> = scene.obstacles.iter().map(|o| (o.lo, o.hi)).collect();
        scene.grid = grid::ObstacleGrid::new(&boxes, cell);
    }
    /// Whether queries take the sphere fast path (every shape of the robot is a sphere).
    pub fn uses_sphere_path(&self) -> bool {
        self.fast.is_some()
    }
    /// The same model answering every query through the general path (shape by shape, as for
    /// robots with capsules and meshes): for comparisons and benchmarks of the fast path.
    pub fn general_path_only(mut self) -> Self {
        self.fast = None;
        self.grid_obstacles();
        self
    }
    /// The same model with the general path's obstacle grid switched off (every obstacle that
    /// overlaps the robot's box tested against every link), for tests and benchmarks that
    /// compare the two.
    pub fn without_obstacle_grid(mut self) -> Self {
        Arc::make_mut(&mut self.scene).grid = None;
        self
    }
    /// The robot this model checks.
    pub fn robot(&self) -> &Robot {
        &self.robot
    }
    /// The obstacles this model checks against.
    pub fn environment(&self) -> &Environment {
        &self.scene.env
    }
    /// Replace the environment (rebuilds the obstacle broad phase).
    pub fn set_environment(&mut self, env: Environment) {
        let obstacles: Vec<ObstacleGeom> = env.obstacles().iter().map(ObstacleGeom::new).collect();
        let solids = obstacles.iter().map(|o| Solid::new(&o.world)).collect();
        self.scene = Arc::new(Scene { env, obstacles, solids, solids32: None, grid: None });
        self.grid_obstacles();
    }
    /// Move the obstacle(s) of this name, updating the broad phase; `false` if there is none.
    pub fn set_obstacle_pose(&mut self, name: &str, pose: Isometry3<f64>) -> bool {
        if !self.scene.env.obstacles().iter().any(|o| o.name == name) {
            return false;
        }
        let scene = Arc::make_mut(&mut self.scene);
        scene.env.set_pose(name, pose);
        for ((o, g), solid) in scene.env.obstacles().iter().zip(scene.obstacles.iter_mut()).zip(scene.solids.iter_mut())
        {
            if o.name == name {
                *g = ObstacleGeom::new(o);
                *solid = Solid::new(&g.world);
            }
        }
        self.grid_obstacles();
        true
    }
    /// A fresh scratch for [`CollisionModel::collides_with`] (one per thread).
    /// It is one this thread dropped before, when there is one (its buffers already grown;
    /// working memory adapts itself to any model, so answers do not change).
    pub fn scratch(&self) -> CollisionScratch {
        let spare = SPARE.try_with(|spare| spare.try_borrow_mut().ok().and_then(|mut v| v.pop())).ok().flatten();
        let mut s = spare.unwrap_or_default();
        // A spare may have been set to the baseline vectors: a new scratch uses the best.
        s.spheres.lanes.isa = Isa::Best;
        // Its separating directions start afresh: a planner's answers depend on its own
        // queries alone.
        s.hints_of = (0, 0);
        s.begin(&self.geom);
        // Room for a typical certificate, so that planning does not grow them piece by piece.
        let (dof, rows) = (self.geom.dof, self.geom.links.len() + self.geom.self_pairs.len());
        for v in [&mut s.q, &mut s.steps, &mut s.step, &mut s.delta] {
            v.reserve(dof);
        }
        s.inflation.reserve(rows);
        s.margins.reserve(rows);
        s.spans.reserve(4 * LANES_MAX_PIECES);
        s.lanes_left.reserve(LANES_MAX_PIECES);
        s.lanes_parents.reserve(LANES_MAX_PIECES);
        s.spheres.items.reserve(1024);
        s.spheres.batch_q.reserve(lanes::LANES * dof);
        s
    }
    /// The self-collision pairs that are checked, as link indices (low, high).
    pub fn self_collision_pairs(&self) -> Vec<(usize, usize)> {
        let l = &self.geom.links;
        self.geom.self_pairs.iter().map(|&(a, b)| (l[a as usize].link, l[b as usize].link)).collect()
    }

    fn with_scratch<R>(&self, f: impl FnOnce(&mut CollisionScratch) -> R) -> R {
        SCRATCH.with(|cell| match cell.try_borrow_mut() {
            Ok(mut s) => f(&mut s),
            Err(_) => f(&mut self.scratch()),
        })
    }

    /// Whether `q` puts any link into an obstacle or into another (checked) link.
    /// A `q` of the wrong length counts as colliding.
    pub fn collides(&self, q: &[f64]) -> bool {
        self.with_scratch(|s| self.collides_with(q, s))
    }

    /// [`CollisionModel::collides`] with caller-owned working memory.
    pub fn collides_with(&self, q: &[f64], scratch: &mut CollisionScratch) -> bool {
        if q.len() != self.geom.dof {
            return true;
        }
        match &self.fast {
            Some(fast) => {
                fast.check(q, &self.scene.obstacles, &self.scene.solids, None, &mut scratch.spheres) == Check::Hit
            }
            None => self.find_hit(q, scratch).is_some(),
        }
    }

    /// Which of the configurations `qs` collide, as bits (bit `i` for the `i`-th): `qs` holds
    /// one to [`BATCH_LANES`] configurations, one after another. Each bit is exactly what
    /// [`Self::collides_with`] answers for its configuration. On the sphere path (among
    /// boxes, balls, cylinders and capsules) the configurations are checked together, one per
    /// vector lane (see `spheres::batch` in the source); elsewhere one by one. A `qs` whose
    /// length is not a whole number (1 to [`BATCH_LANES`]) of configurations gives `u32::MAX`.
    pub fn batch_collisions_with(&self, qs: &[f64], scratch: &mut CollisionScratch) -> u32 {
        let dof = self.geom.dof;
        if dof == 0 || !qs.len().is_multiple_of(dof) || qs.is_empty() || qs.len() > BATCH_LANES * dof {
            return u32::MAX;
        }
        self.batch_mask::<false>(qs, scratch)
    }

    /// Whether any of the configurations `qs` (any number of them, one after another)
    /// collides: [`Self::collides_with`] of each, in order, [`BATCH_LANES`] at a time on the
    /// sphere path, stopping at the first batch with a contact. A `qs` whose length is not a
    /// multiple of the number of DOFs counts as colliding.
    pub fn any_collides_with(&self, qs: &[f64], scratch: &mut CollisionScratch) -> bool {
        let dof = self.geom.dof;
        if dof == 0 {
            return !qs.is_empty() || self.collides_with(qs, scratch);
        }
        if !qs.len().is_multiple_of(dof) {
            return true;
        }
        qs.chunks(BATCH_LANES * dof).any(|chunk| self.batch_mask::<true>(chunk, scratch) != 0)
    }

    /// Whether any of the configurations `qs` (any number of them, one after another)
    /// collides, exactly as [`Self::collides_with`] of each would say: on the sphere path among
    /// balls, boxes and cylinders, eight at a time in single precision ([`Self::settle_batch`]
    /// with no margin), the few configurations a batch leaves unsettled one by one; elsewhere
    /// one by one. Configurations are taken in order and the first contact ends the query.
    pub fn any_collides_settled(&self, qs: &[f64], scratch: &mut CollisionScratch) -> bool {
        let dof = self.geom.dof;
        if dof == 0 || !qs.len().is_multiple_of(dof) {
            return self.any_collides_with(qs, scratch);
        }
        for chunk in qs.chunks(BATCH_LANES * dof) {
            // A batch costs about what two or three single checks do, whatever its lanes.
            let settled = if chunk.len() >= SETTLE_MIN * dof { self.settle_batch(chunk, 0.0, scratch) } else { None };
            let Some(settled) = settled else {
                if chunk.chunks_exact(dof).any(|q| self.collides_with(q, scratch)) {
                    return true;
                }
                continue;
            };
            if settled.colliding != 0 {
                return true;
            }
            for (i, q) in chunk.chunks_exact(dof).enumerate() {
                if settled.free & (1 << i) == 0 && self.collides_with(q, scratch) {
                    return true;
                }
            }
        }
        false
    }

    /// Whether the motion certificate checks its first pieces in single-precision batches
    /// (the sphere path among balls, boxes and cylinders only; see `spheres::lanes` in the
    /// source).
    pub fn certifies_in_batches(&self) -> bool {
        self.scene.solids32.is_some()
    }

    /// One to [`BATCH_LANES`] configurations (`qs`, one after another) checked together in
    /// single precision, each sphere grown by `margin` (m) against obstacles and each self pair
    /// by `margin`: which of them it settles (see `spheres::lanes` in the source for the error
    /// bound that makes this sound). A configuration in `free` has every sphere farther than
    /// `margin` from every obstacle and every checked self pair farther than `margin` apart; one
    /// in `colliding` is in contact (without margins). Neither: within the rounding bound of
    /// the question, ask [`Self::collides_with`]. Once a contact is found the batch stops, so
    /// `free` is then empty. `None` when the model does not answer in batches
    /// ([`Self::certifies_in_batches`]), for a `qs` that is not 1 to [`BATCH_LANES`] whole
    /// configurations, or a `margin` that is not finite and at least 0. With a `margin` above 0
    /// the self-collision cell tables are not used (they prove contact-freedom, not clearance).
    pub fn settle_batch(&self, qs: &[f64], margin: f64, s: &mut CollisionScratch) -> Option<BatchSettled> {
        let dof = self.geom.dof;
        if dof == 0 || qs.is_empty() || !qs.len().is_multiple_of(dof) || qs.len() > lanes::LANES * dof {
            return None;
        }
        let n = qs.len() / dof;
        // A full batch as it is; fewer configurations padded with copies of the last.
        if n == lanes::LANES {
            return self.settle_lanes(LaneInput::Rows(qs), n, margin, s);
        }
        let mut buf = std::mem::take(&mut s.spheres.batch_q);
        buf.clear();
        buf.extend_from_slice(qs);
        for _ in n..lanes::LANES {
            buf.extend_from_slice(&qs[(n - 1) * dof..]);
        }
        let answer = self.settle_lanes(LaneInput::Rows(&buf), n, margin, s);
        s.spheres.batch_q = buf;
        answer
    }

    /// [`Self::settle_batch`] of a full batch (`input`), of which the first `n` lanes are used.
    fn settle_lanes(
        &self,
        input: LaneInput<'_>,
        n: usize,
        margin: f64,
        s: &mut CollisionScratch,
    ) -> Option<BatchSettled> {
        let dof = self.geom.dof;
        let (Some(fast), Some(solids32)) = (&self.fast, &self.scene.solids32) else { return None };
        if !(margin.is_finite() && margin >= 0.0) || n == 0 || n > lanes::LANES {
            return None;
        }
        zero_steps(&mut s.step, dof);
        let step = (margin == 0.0).then_some(&s.step[..]);
        let grow = LaneMargins {
            link: &[],
            pair: &[],
            uniform: Some(margin),
            step,
            pairs_of_near: false,
            along: false,
            still: 0,
            settled: 0,
            pairs_settled: false,
        };
        let answer = fast.free_lanes(input, dof, solids32, grow, &mut s.spheres.lanes);
        let used = (1u32 << n) - 1;
        Some(BatchSettled { free: answer.free & used, colliding: answer.hit & used })
    }

    /// Whether any point of an edge probe collides, exactly as [`Self::any_collides_settled`]
    /// of the points one after another says: `end` first when given, then the inner points of
    /// the segment from `a` by the joint steps `delta` cut into `n` steps, `a + (i / n) delta`
    /// for `i` from 1 to `n - 1` in [`bisection_order`] (each value as
    /// [`ConfigSpace::step_into`] computes it). On the sphere path among balls, boxes and
    /// cylinders the points are written into the batch's lanes joint by joint, straight from
    /// `a` and `delta`, with no rows to build and turn. `a`, `delta` and `end` of another
    /// length than the robot's DOFs, and more than `u32::MAX` steps, count as colliding.
    pub fn probe_collides(
        &self,
        a: &[f64],
        end: Option<&[f64]>,
        delta: &[f64],
        n: usize,
        s: &mut CollisionScratch,
    ) -> bool {
        self.probe(a, end, delta, n, false, s)
    }

    /// [`Self::probe_collides`] of a probe whose start `a` is collision-free (a planner's
    /// probes start at configurations it has checked): the bodies that no joint moves along it
    /// (`delta` 0 for every joint up their chain) keep their free poses at `a`, and the batches
    /// test neither them against obstacles nor them against each other. On a robot of two arms
    /// searched one arm at a time, the still arm's tests are about half of each batch. The
    /// answer is that of [`Self::probe_collides`] whenever `a` is free; for an `a` in
    /// collision it may miss a contact of a body that does not move.
    pub fn probe_from_free_collides(
        &self,
        a: &[f64],
        end: Option<&[f64]>,
        delta: &[f64],
        n: usize,
        s: &mut CollisionScratch,
    ) -> bool {
        self.probe(a, end, delta, n, true, s)
    }

    /// [`Self::probe_collides`]; with `a_free`, [`Self::probe_from_free_collides`].
    fn probe(
        &self,
        a: &[f64],
        end: Option<&[f64]>,
        delta: &[f64],
        n: usize,
        a_free: bool,
        s: &mut CollisionScratch,
    ) -> bool {
        let dof = self.geom.dof;
        if a.len() != dof || delta.len() != dof || end.is_some_and(|e| e.len() != dof) {
            return true;
        }
        if dof == 0 || !self.certifies_in_batches() {
            let mut points = std::mem::take(&mut s.probe);
            probe_points_into(a, end, delta, n, &mut points);
            // On the general path from a free start, the links no joint moves are skipped.
            s.skip_still = a_free && self.fast.is_none() && self.still_links(a, end, delta, s);
            let hit = self.any_collides_settled(&points, s);
            s.skip_still = false;
            s.probe = points;
            return hit;
        }
        let Ok(n) = u32::try_from(n) else { return true };
        let still = match &self.fast {
            Some(fast) if a_free => fast.still_along(a, delta, end),
            _ => 0,
        };
        let probe = Probe { a, end, delta, n, still };
        // The points of the next batch: 0 for the end, `i` for inner point `i` (below `n`).
        let mut ids = [0u32; lanes::LANES];
        let mut count = usize::from(end.is_some());
        let mut hit = false;
        bisection_order(n as usize, |i| {
            ids[count] = i as u32;
            count += 1;
            if count < lanes::LANES {
                return true;
            }
            count = 0;
            hit = self.probe_batch(&probe, &ids, lanes::LANES, s);
            !hit
        });
        hit || (count > 0 && self.probe_batch(&probe, &ids, count, s))
    }

    /// Whether any of the first `count` points `ids` of `probe` collides: in one batch, its
    /// unused lanes copies of the last point, or one by one when they are few. Straight to the
    /// kernel: through `settle_lanes` (its checks of the margin and the lane count) about 65
    /// instructions a probe more on cage problems, and with closures built for every batch,
    /// through `settle_batch`, about 120.
    fn probe_batch(
        &self,
        probe: &Probe<'_>,
        ids: &[u32; lanes::LANES],
        count: usize,
        s: &mut CollisionScratch,
    ) -> bool {
        let used = (1u32 << count) - 1;
        let (Some(fast), Some(solids32), true) = (&self.fast, &self.scene.solids32, count >= SETTLE_MIN) else {
            return self.probe_one_by_one(probe, ids, used, s);
        };
        let &Probe { a, end, delta, n, still } = probe;
        let end = end.filter(|_| ids[0] == 0);
        // Unused lanes repeat the last point (the end only ever comes first).
        let mut lane_ids = [ids[count - 1]; lanes::LANES];
        lane_ids[..count].copy_from_slice(&ids[..count]);
        // No step: each lane's own cell of the self-collision tables.
        let dof = a.len();
        zero_steps(&mut s.step, dof);
        let margins = LaneMargins {
            link: &[],
            pair: &[],
            uniform: Some(0.0),
            step: Some(&s.step),
            pairs_of_near: false,
            along: false,
            still,
            settled: 0,
            pairs_settled: false,
        };
        let input = LaneInput::Segment(SegmentIn { a, delta, n, ids: lane_ids, end });
        let answer = fast.free_lanes(input, dof, solids32, margins, &mut s.spheres.lanes);
        if answer.hit & used != 0 {
            return true;
        }
        let rest = used & !answer.free;
        rest != 0 && self.probe_one_by_one(probe, ids, rest, s)
    }

    /// Whether any of the points `ids` of `probe` whose bits are set in `lanes` collides,
    /// checked one by one in double precision.
    fn probe_one_by_one(
        &self,
        probe: &Probe<'_>,
        ids: &[u32; lanes::LANES],
        lanes: u32,
        s: &mut CollisionScratch,
    ) -> bool {
        let &Probe { a, end, delta, n, .. } = probe;
        let mut row = std::mem::take(&mut s.probe);
        let hit = ids.iter().enumerate().any(|(l, &i)| {
            lanes & (1 << l) != 0 && {
                row.clear();
                match end {
                    // Point 0 is the end only in a probe's first batch.
                    Some(e) if i == 0 => row.extend_from_slice(e),
                    _ => {
                        row.resize(a.len(), 0.0);
                        ConfigSpace::step_into(a, delta, f64::from(i) / f64::from(n), &mut row);
                    }
                }
                self.collides_with(&row, s)
            }
        });
        s.probe = row;
        hit
    }

    /// The colliding configurations of a batch (1 to [`BATCH_LANES`] whole configurations);
    /// with `ANY`, at least one of them if any collides.
    fn batch_mask<const ANY: bool>(&self, qs: &[f64], s: &mut CollisionScratch) -> u32 {
        let dof = self.geom.dof;
        let n = qs.len() / dof;
        match &self.fast {
            Some(fast) if fast.batch_supported(&self.scene.solids, dof) && qs.iter().all(|v| v.is_finite()) => {
                // Unused lanes repeat the first configuration (and are masked off).
                let mut buf = std::mem::take(&mut s.spheres.batch_q);
                buf.clear();
                buf.extend_from_slice(qs);
                for _ in n..BATCH_LANES {
                    buf.extend_from_slice(&qs[..dof]);
                }
                let active = (1u32 << n) - 1;
                let hit = fast.check_batch::<ANY>(
                    &buf,
                    dof,
                    active,
                    &self.scene.obstacles,
                    &self.scene.solids,
                    &mut s.spheres.batch,
                );
                s.spheres.batch_q = buf;
                hit
            }
            _ => {
                let mut hit = 0;
                for (i, q) in qs.chunks_exact(dof).enumerate() {
                    if self.collides_with(q, s) {
                        hit |= 1 << i;
                        if ANY {
                            break;
                        }
                    }
                }
                hit
            }
        }
    }

    /// Self-collision pair `p` alone at `q`, its shapes grown by how far they can move relative
    /// to each other when the joints change by at most `step` (per DOF).
    fn pair_check(&self, q: &[f64], p: usize, step: &[f64], s: &mut CollisionScratch) -> Check {
        match &self.fast {
            Some(fast) => fast.pair_check(q, p, step, &mut s.spheres),
            None => {
                let g = &*self.geom;
                let (a, b) = g.self_pairs[p];
                let arms = &g.pair_lever[p * g.dof..(p + 1) * g.dof];
                let grow = arms.iter().zip(step).map(|(a, d)| a * d).sum::<f64>() + 1e-12;
                self.pose_bodies(q, s);
                match self.pair_hits::<true>(a as usize, b as usize, grow, s) {
                    Err(()) => Check::Hit,
                    Ok(true) => Check::Near,
                    Ok(false) => Check::Free,
                }
            }
        }
    }

    /// `still` := per link slot, whether its body keeps its pose at every point of the probe
    /// from `a` by `delta` (and at `end`): no joint on its chain changes value there (to the
    /// bit: a point is `a + k delta`, so a joint of zero step keeps `a`'s value). Whether any
    /// link is still (and any moves: a probe that moves nothing skips nothing).
    fn still_links(&self, a: &[f64], end: Option<&[f64]>, delta: &[f64], s: &mut CollisionScratch) -> bool {
        let g = &*self.geom;
        let moves = |i: usize| delta.get(i).is_none_or(|&d| d != 0.0) || end.is_some_and(|e| e.get(i) != a.get(i));
        // Bodies come after their parents.
        let body_still = &mut s.still_bodies;
        body_still.clear();
        body_still.resize(g.bodies.len(), true);
        for (b, body) in g.bodies.iter().enumerate().skip(1) {
            let own = match body.value {
                Value::Dof(i) | Value::Mimic(i, ..) => !moves(i),
                Value::Zero => true,
            };
            body_still[b] = own && body_still.get(body.parent).copied().unwrap_or(false);
        }
        let still = &mut s.still;
        still.clear();
        still.extend(g.links.iter().map(|l| body_still.get(l.body).copied().unwrap_or(false)));
        still.iter().any(|&x| x) && still.iter().any(|&x| !x)
    }

    /// A certificate's grown check on the general path: with `scope` `None` every item, as
    /// [`Self::check`], else only the items `near_items[a..b]` (those a coarser sub-interval
    /// around this one left near: every other item was proven farther than its margin over
    /// that whole sub-interval, which holds this one). The items found near are appended to
    /// `near_items`.
    fn check_items(
        &self,
        q: &[f64],
        inflation: Inflation<'_>,
        scope: Option<(usize, usize)>,
        s: &mut CollisionScratch,
    ) -> Check {
        let Some((a, b)) = scope else {
            s.record_near = true;
            let answer = self.scan::<true>(q, Some(inflation), s);
            s.record_near = false;
            return match answer {
                Err(_) => Check::Hit,
                Ok(true) => Check::Near,
                Ok(false) => Check::Free,
            };
        };
        self.pose_bodies(q, s);
        self.fit_hints(s);
        let g = &*self.geom;
        let n_obs = self.scene.obstacles.len();
        let env = self.pair_item(0) as usize;
        let mut near = false;
        for i in a..b {
            let Some(&item) = s.near_items.get(i) else { break };
            let it = item as usize;
            let answer = if it < env {
                let slot = it / n_obs;
                self.link_hits_obstacle::<true>(slot, it % n_obs, inflation.link[slot], s)
            } else {
                let p = it - env;
                let (pa, pb) = g.self_pairs[p];
                self.pair_hits::<true>(pa as usize, pb as usize, inflation.pair[p], s)
            };
            match answer {
                Err(()) => return Check::Hit,
                Ok(true) => {
                    s.near_items.push(item);
                    near = true;
                }
                Ok(false) => {}
            }
        }
        if near { Check::Near } else { Check::Free }
    }

    /// Exact or inflated query, by either path.
    fn check(&self, q: &[f64], inflation: Option<Inflation<'_>>, s: &mut CollisionScratch) -> Check {
        match &self.fast {
            Some(fast) => fast.check(q, &self.scene.obstacles, &self.scene.solids, inflation, &mut s.spheres),
            None => match self.scan_grown(q, inflation, s) {
                Err(_) => Check::Hit,
                Ok(true) => Check::Near,
                Ok(false) => Check::Free,
            },
        }
    }

    /// The first colliding pair found at `q` (for messages), `None` if `q` is free. On the
    /// sphere path a configuration the fast check finds free is answered by it alone: the
    /// shape-by-shape pass that names the pair runs only for a colliding one (on the spherized
    /// UR5 about 19,000 instructions against 3,700 for the fast check; planners ask this of
    /// every start and goal).
    pub fn first_collision(&self, q: &[f64]) -> Option<Contact> {
        if q.len() != self.geom.dof {
            return None;
        }
        if self.fast.is_some() && !self.collides(q) {
            return None;
        }
        let hit = self.with_scratch(|s| self.find_hit(q, s))?;
        Some(match hit {
            Hit::Env { slot, obstacle } => Contact { a: self.link_body(slot), b: self.obstacle_body(obstacle) },
            Hit::Pair { a, b } => Contact { a: self.link_body(a), b: self.link_body(b) },
        })
    }

    fn link_body(&self, slot: usize) -> Body {
        let link = self.geom.links[slot].link;
        Body::Link { link, name: self.robot.links()[link].name.clone() }
    }
    fn obstacle_body(&self, index: usize) -> Body {
        Body::Obstacle { index, name: self.scene.env.obstacles()[index].name.clone() }
    }

    /// Forward kinematics of the bodies that carry shapes, and the links' world bounding spheres.
    #[inline]
    fn pose_bodies(&self, q: &[f64], s: &mut CollisionScratch) {
        let g = &*self.geom;
        s.begin(g);
        s.body_iso[0] = g.base;
        for (b, body) in g.bodies.iter().enumerate().skip(1) {
            let v = match body.value {
                Value::Dof(i) => q[i],
                Value::Mimic(d, m, o) => q[d] * m + o,
                Value::Zero => 0.0,
            } + body.offset;
            let local = if body.prismatic {
                Isometry3::from_parts(
                    Translation3::from(body.pre.translation.vector + body.pre.rotation * (body.axis.into_inner() * v)),
                    body.pre.rotation,
                )
            } else {
                Isometry3::from_parts(
                    body.pre.translation,
                    body.pre.rotation * UnitQuaternion::from_axis_angle(&body.axis, v),
                )
            };
            let local = match &body.post {
                Some(post) => local * post,
                None => local,
            };
            s.body_iso[b] = s.body_iso[body.parent] * local;
        }
        for b in 0..g.bodies.len() {
            s.body_rot[b] = *s.body_iso[b].rotation.to_rotation_matrix().matrix();
        }
        for (slot, l) in g.links.iter().enumerate() {
            s.link_c[slot] = s.body_rot[l.body] * l.c + s.body_iso[l.body].translation.vector;
        }
    }

    /// The item of link slot `slot` against obstacle `oi` in `CollisionScratch::near_items`.
    fn env_item(&self, slot: usize, oi: usize) -> u32 {
        (slot * self.scene.obstacles.len() + oi) as u32
    }

    /// The item of self pair `p` in `CollisionScratch::near_items`.
    fn pair_item(&self, p: usize) -> u32 {
        (self.geom.links.len() * self.scene.obstacles.len() + p) as u32
    }

    /// The scratch's separating directions made this model's (all none when they were another's
    /// or are new): one per shape and obstacle (when there are at most [`HINTED_ENV_MAX`] such
    /// pairs), and, for robots of at most [`HINTED_SHAPES_MAX`] shapes, one per pair of shapes.
    #[inline]
    fn fit_hints(&self, s: &mut CollisionScratch) {
        let of = (Arc::as_ptr(&self.geom) as usize, Arc::as_ptr(&self.scene) as usize);
        if s.hints_of != of {
            let n = self.geom.shapes.len();
            let pairs = if n <= HINTED_SHAPES_MAX { n * n } else { 0 };
            let env = n * self.scene.obstacles.len();
            s.hints_env = if env <= HINTED_ENV_MAX { env } else { 0 };
            s.hints.clear();
            s.hints.resize(s.hints_env + pairs, narrow::Hint::NONE);
            s.hints_of = of;
        }
    }

    /// World poses of a link's shapes, computed once per query.
    #[inline]
    fn pose_link(&self, slot: usize, s: &mut CollisionScratch) {
        if s.link_stamp[slot] == s.stamp {
            return;
        }
        s.link_stamp[slot] = s.stamp;
        let g = &*self.geom;
        let l = &g.links[slot];
        let rot = s.body_rot[l.body];
        let iso = s.body_iso[l.body];
        let t = iso.translation.vector;
        for k in l.shapes.clone() {
            let sh = &g.shapes[k];
            s.world_c[k] = rot * sh.c + t;
            s.world[k] = match &sh.local {
                Local::Sphere { c, r } => World::Sphere { c: rot * c + t, r: *r },
                Local::Capsule { a, b, r } => World::Capsule { a: rot * a + t, b: rot * b + t, r: *r },
                Local::Cuboid { iso: li, half } => World::Cuboid { iso: iso * li, half: *half },
                Local::Cylinder { iso: li, r, hh } => World::Cylinder { iso: iso * li, r: *r, hh: *hh },
                Local::Mesh { iso: li, hull } => World::Mesh { iso: iso * li, hull: hull.clone() },
            };
        }
    }

    /// Whether link `slot` (grown by `e`) touches obstacle `o`: `Err(())` for an exact contact,
    /// `Ok(true)` when only the grown shapes touch.
    #[inline]
    fn link_hits_obstacle<const GROW: bool>(
        &self,
        slot: usize,
        oi: usize,
        e: f64,
        s: &mut CollisionScratch,
    ) -> Result<bool, ()> {
        let o = &self.scene.obstacles[oi];
        let l = &self.geom.links[slot];
        if !sphere_hits_aabb(&s.link_c[slot], l.r + e, o) {
            return Ok(false);
        }
        self.pose_link(slot, s);
        let ov = o.world.view();
        let mut near = false;
        for k in l.shapes.clone() {
            if !sphere_hits_aabb(&s.world_c[k], self.geom.shapes[k].r + e, o) {
                continue;
            }
            let kv = s.world[k].view();
            let at = k * self.scene.obstacles.len() + oi;
            let hint = if at < s.hints_env { s.hints.get_mut(at) } else { None };
            near |= shapes_hit::<GROW>(&kv, &ov, e, hint)?;
        }
        Ok(near)
    }

    /// Self-collision pair `a`-`b`, grown by `ea` and `eb`; answers as [`Self::link_hits_obstacle`].
    #[inline]
    fn pair_hits<const GROW: bool>(&self, a: usize, b: usize, grow: f64, s: &mut CollisionScratch) -> Result<bool, ()> {
        let g = &*self.geom;
        let (la, lb) = (&g.links[a], &g.links[b]);
        let rr = la.r + lb.r + grow;
        if (s.link_c[a] - s.link_c[b]).norm_squared() > rr * rr {
            return Ok(false);
        }
        self.pose_link(a, s);
        self.pose_link(b, s);
        let mut near = false;
        for i in la.shapes.clone() {
            for j in lb.shapes.clone() {
                let rr = g.shapes[i].r + g.shapes[j].r + grow;
                if (s.world_c[i] - s.world_c[j]).norm_squared() > rr * rr {
                    continue;
                }
                let (vi, vj) = (s.world[i].view(), s.world[j].view());
                let hint = s.hints.get_mut(s.hints_env + i * g.shapes.len() + j);
                near |= shapes_hit::<GROW>(&vi, &vj, grow, hint)?;
            }
        }
        Ok(near)
    }

    /// The first colliding pair; `q` has the right length.
    fn find_hit(&self, q: &[f64], s: &mut CollisionScratch) -> Option<Hit> {
        self.scan::<false>(q, None, s).err()
    }

    /// The general path: `Err(hit)` at the first exact contact, else `Ok(near)` where `near`
    /// says that some shapes grown by `inflation` touch.
    fn scan_grown(&self, q: &[f64], inflation: Option<Inflation<'_>>, s: &mut CollisionScratch) -> Result<bool, Hit> {
        match inflation {
            Some(_) => self.scan::<true>(q, inflation, s),
            None => self.scan::<false>(q, None, s),
        }
    }

    /// [`Self::scan_grown`], compiled separately for exact queries (`GROW` = false) so the
    /// hot path carries none of the margin work.
    #[inline]
    fn scan<const GROW: bool>(
        &self,
        q: &[f64],
        inflation: Option<Inflation<'_>>,
        s: &mut CollisionScratch,
    ) -> Result<bool, Hit> {
        self.pose_bodies(q, s);
        self.fit_hints(s);
        let g = &*self.geom;
        let grow = |slot: usize| if GROW { inflation.map_or(0.0, |e| e.link[slot]) } else { 0.0 };
        let mut near = false;
        if let Some(grid) = &self.scene.grid {
            // Many obstacles: each link against those listed in the cells its box overlaps.
            let mut visited = std::mem::take(&mut s.visited);
            visited.resize(self.scene.obstacles.len(), 0);
            let mut hit = None;
            for (slot, l) in g.links.iter().enumerate() {
                if !GROW && s.skip_still && s.still[slot] {
                    continue;
                }
                s.visit = s.visit.wrapping_add(1);
                if s.visit == 0 {
                    visited.fill(0);
                    s.visit = 1;
                }
                let visit = s.visit;
                let e = grow(slot);
                let r = Vector3::repeat(l.r + e);
                let (lo, hi) = (s.link_c[slot] - r, s.link_c[slot] + r);
                grid.near(&lo, &hi, self.scene.obstacles.len(), |oi| {
                    let seen = &mut visited[oi as usize];
                    if *seen == visit {
                        return true;
                    }
                    *seen = visit;
                    match self.link_hits_obstacle::<GROW>(slot, oi as usize, e, s) {
                        Err(()) => {
                            hit = Some(Hit::Env { slot, obstacle: oi as usize });
                            false
                        }
                        Ok(n) => {
                            if GROW && n && s.record_near {
                                s.near_items.push(self.env_item(slot, oi as usize));
                            }
                            near |= n;
                            true
                        }
                    }
                });
                if hit.is_some() {
                    break;
                }
            }
            s.visited = visited;
            if let Some(h) = hit {
                return Err(h);
            }
        } else if !self.scene.obstacles.is_empty() && !g.links.is_empty() {
            // Obstacles near the robot at all: against the box around every link sphere.
            let mut lo = Point3::from(Vector3::repeat(f64::INFINITY));
            let mut hi = Point3::from(Vector3::repeat(f64::NEG_INFINITY));
            let skip = !GROW && s.skip_still;
            for (slot, l) in g.links.iter().enumerate() {
                if skip && s.still[slot] {
                    continue;
                }
                let c = s.link_c[slot];
                let r = Vector3::repeat(l.r + grow(slot));
                lo = lo.inf(&(c - r));
                hi = hi.sup(&(c + r));
            }
            s.candidates.clear();
            for (i, o) in self.scene.obstacles.iter().enumerate() {
                if o.lo.x <= hi.x
                    && o.hi.x >= lo.x
                    && o.lo.y <= hi.y
                    && o.hi.y >= lo.y
                    && o.lo.z <= hi.z
                    && o.hi.z >= lo.z
                {
                    s.candidates.push(i as u32);
                }
            }
            for ci in 0..s.candidates.len() {
                let oi = s.candidates[ci] as usize;
                for slot in 0..g.links.len() {
                    if skip && s.still[slot] {
                        continue;
                    }
                    match self.link_hits_obstacle::<GROW>(slot, oi, grow(slot), s) {
                        Err(()) => return Err(Hit::Env { slot, obstacle: oi }),
                        Ok(n) => {
                            if GROW && n && s.record_near {
                                s.near_items.push(self.env_item(slot, oi));
                            }
                            near |= n;
                        }
                    }
                }
            }
        }
        let skip = !GROW && s.skip_still;
        for (p, &(a, b)) in g.self_pairs.iter().enumerate() {
            let (a, b) = (a as usize, b as usize);
            if skip && s.still[a] && s.still[b] {
                continue;
            }
            match self.pair_hits::<GROW>(a, b, if GROW { inflation.map_or(0.0, |e| e.pair[p]) } else { 0.0 }, s) {
                Err(()) => return Err(Hit::Pair { a, b }),
                Ok(n) => {
                    if GROW && n && s.record_near {
                        s.near_items.push(self.pair_item(p));
                    }
                    near |= n;
                }
            }
        }
        Ok(near)
    }

    /// Signed distance to the nearest contact over all checked pairs (see [`DistanceReport`]).
    pub fn distance(&self, q: &[f64]) -> DistanceReport {
        self.with_scratch(|s| self.distance_with(q, s))
    }

    /// [`CollisionModel::distance`] with caller-owned working memory.
    pub fn distance_with(&self, q: &[f64], s: &mut CollisionScratch) -> DistanceReport {
        let g = &*self.geom;
        let nobody = || Body::Link { link: 0, name: self.robot.links()[0].name.clone() };
        if q.len() != g.dof {
            let o = Point3::origin();
            return DistanceReport { distance: f64::NEG_INFINITY, a: nobody(), b: nobody(), point_a: o, point_b: o };
        }
        self.pose_bodies(q, s);
        let mut best = f64::INFINITY;
        let mut best_sep: Option<(Separation, Hit)> = None;
        for (oi, o) in self.scene.obstacles.iter().enumerate() {
            let ov = o.world.view();
            for (slot, l) in g.links.iter().enumerate() {
                if dist2_point_aabb(&s.link_c[slot], &o.lo, &o.hi).sqrt() - l.r >= best {
                    continue;
                }
                self.pose_link(slot, s);
                for k in l.shapes.clone() {
                    if dist2_point_aabb(&s.world_c[k], &o.lo, &o.hi).sqrt() - g.shapes[k].r >= best {
                        continue;
                    }
                    // A capsule is no nearer the obstacle than its core is to the obstacle's box:
                    // cheaper than the exact distance, and far tighter than its bounding sphere.
                    if let World::Capsule { a, b, r } = &s.world[k] {
                        let (centre, half) = ((o.lo.coords + o.hi.coords) * 0.5, (o.hi - o.lo) * 0.5);
                        if narrow::segment_box_dist2(&(a.coords - centre), &(b - a), &half).0.sqrt() - r >= best {
                            continue;
                        }
                    }
                    let sep = narrow::separation(&s.world[k].view(), &ov);
                    if sep.distance < best {
                        best = sep.distance;
                        best_sep = Some((sep, Hit::Env { slot, obstacle: oi }));
                    }
                }
            }
        }
        for &(a, b) in &g.self_pairs {
            let (a, b) = (a as usize, b as usize);
            let (la, lb) = (&g.links[a], &g.links[b]);
            if (s.link_c[a] - s.link_c[b]).norm() - la.r - lb.r >= best {
                continue;
            }
            self.pose_link(a, s);
            self.pose_link(b, s);
            for i in la.shapes.clone() {
                for j in lb.shapes.clone() {
                    if (s.world_c[i] - s.world_c[j]).norm() - g.shapes[i].r - g.shapes[j].r >= best {
                        continue;
                    }
                    let sep = narrow::separation(&s.world[i].view(), &s.world[j].view());
                    if sep.distance < best {
                        best = sep.distance;
                        best_sep = Some((sep, Hit::Pair { a, b }));
                    }
                }
            }
        }
        match best_sep {
            Some((sep, hit)) => {
                let (a, b) = match hit {
                    Hit::Env { slot, obstacle } => (self.link_body(slot), self.obstacle_body(obstacle)),
                    Hit::Pair { a, b } => (self.link_body(a), self.link_body(b)),
                };
                DistanceReport { distance: sep.distance, a, b, point_a: sep.point_a, point_b: sep.point_b }
            }
            None => {
                let o = Point3::origin();
                DistanceReport { distance: f64::INFINITY, a: nobody(), b: nobody(), point_a: o, point_b: o }
            }
        }
    }

    /// Whether the straight joint-space motion from `qa` to `qb` (the short way round on
    /// continuous joints) is free: configurations no more than `resolution` apart in every joint
    /// (rad or m) are checked, endpoints first, then midpoints in bisection order so that a
    /// collision is usually found after few checks. A non-positive or non-finite `resolution`,
    /// or configurations of the wrong length, give `false`.
    pub fn motion_is_free(&self, qa: &[f64], qb: &[f64], resolution: f64) -> bool {
        self.with_scratch(|s| self.motion_is_free_with(qa, qb, resolution, s))
    }

    /// [`CollisionModel::motion_is_free`] with caller-owned working memory.
    pub fn motion_is_free_with(&self, qa: &[f64], qb: &[f64], resolution: f64, s: &mut CollisionScratch) -> bool {
        let g = &*self.geom;
        if qa.len() != g.dof
            || qb.len() != g.dof
            || resolution.is_nan()
            || resolution <= 0.0
            || resolution.is_infinite()
        {
            return false;
        }
        let steps = (g.cspace.max_joint_step(qa, qb) / resolution).ceil().max(1.0);
        if !steps.is_finite() || steps > u32::MAX as f64 / 2.0 {
            return false;
        }
        let n = steps as u32;
        if self.find_hit(qa, s).is_some() || self.find_hit(qb, s).is_some() {
            return false;
        }
        let mut q = std::mem::take(&mut s.q);
        let mut queue = std::mem::take(&mut s.intervals);
        q.clear();
        q.resize(g.dof, 0.0);
        queue.clear();
        queue.push((0, n));
        let mut head = 0;
        let mut free = true;
        while head < queue.len() {
            let (lo, hi) = queue[head];
            head += 1;
            if hi - lo < 2 {
                continue;
            }
            let mid = lo + (hi - lo) / 2;
            g.cspace.interpolate_into(qa, qb, mid as f64 / n as f64, &mut q);
            if self.find_hit(&q, s).is_some() {
                free = false;
                break;
            }
            queue.push((lo, mid));
            queue.push((mid, hi));
        }
        s.q = q;
        s.intervals = queue;
        free
    }

    /// Whether the straight joint-space motion from `qa` to `qb` (the short way round on
    /// continuous joints) is free *for the whole continuum of configurations in between*, not
    /// only at sampled points: a conservative certificate.
    ///
    /// Along the segment no point of link `l` travels further than
    /// `sum_i lever[l][i] * |qb_i - qa_i|` (see the lever arms in this module's source: a
    /// configuration-independent bound from the kinematic chain). So if, at the midpoint of a
    /// sub-interval, every shape grown by the distance its points can travel in half that
    /// sub-interval is free, the whole sub-interval is free. The check starts with the whole
    /// segment cut into up to 16 equal pieces, so that no shape grows by more than
    /// [`CERTIFY_START_MARGIN`], and halves only the sub-intervals that cannot be certified,
    /// breadth first (a collision is usually found after few checks); far from obstacles a few
    /// checks certify a long motion. On the sphere fast path the margins of the spheres a query
    /// actually tests are tighter, from the pose at the sub-interval's midpoint (each joint
    /// counts the sphere's distance from its axis there, plus how far the joints below can move
    /// it), and a self-collision pair counts how much the distance between two spheres can shrink rather
    /// than how far each moves (see `spheres::arms` in the source); the link bounds stay the
    /// pre-filter. There, too, the halves of a sub-interval that could not be certified are
    /// checked against only what was near over the whole (sphere-obstacle and sphere-sphere
    /// pairs): everything else is already certified free over both. And a sub-interval is not
    /// halved there but cut around the part its query certified free: the nearest item's gap
    /// against its margin says how much of the sub-interval around the midpoint is free (see
    /// `reach_of`), and only the two pieces either side are checked (against halving, on the
    /// public MotionBenchMaker UR5 problems: 8% fewer checks, 4.6% fewer planning
    /// instructions). A sub-interval that still
    /// cannot be certified when its margin is below `tolerance` (m) makes the answer `false`
    /// (among balls, boxes and cylinders the sphere path first checks finer pieces eight at a
    /// time in single precision, with a proven rounding allowance, and only what those batches
    /// cannot prove free goes through the checks above; see [`Self::certifies_in_batches`]):
    /// motions that pass closer than about `tolerance` to contact are rejected, never let through.
    ///
    /// Configurations of the wrong length, non-finite values, or a `tolerance` that is not
    /// positive and finite give `false`.
    pub fn motion_is_certified_free(&self, qa: &[f64], qb: &[f64], tolerance: f64) -> bool {
        self.with_scratch(|s| self.motion_is_certified_free_with(qa, qb, tolerance, s))
    }

    /// [`CollisionModel::motion_is_certified_free`] with caller-owned working memory.
    pub fn motion_is_certified_free_with(
        &self,
        qa: &[f64],
        qb: &[f64],
        tolerance: f64,
        s: &mut CollisionScratch,
    ) -> bool {
        self.certify(qa, qb, tolerance, true, s).0
    }

    /// For each link that carries shapes (as `(link index, bound)`): how far, at most, any point
    /// of its shapes travels along the straight joint-space motion from `qa` to `qb`, whatever
    /// the configurations (the bound the motion certificate grows shapes by). Empty for
    /// configurations of the wrong length.
    pub fn travel_bounds(&self, qa: &[f64], qb: &[f64]) -> Vec<(usize, f64)> {
        let g = &*self.geom;
        if qa.len() != g.dof || qb.len() != g.dof {
            return Vec::new();
        }
        let dq: Vec<f64> = (0..g.dof).map(|i| g.cspace.delta(i, qa[i], qb[i]).abs()).collect();
        g.links
            .iter()
            .enumerate()
            .map(|(slot, l)| (l.link, (0..g.dof).map(|i| g.lever[slot * g.dof + i] * dq[i]).sum()))
            .collect()
    }

    /// [`Self::travel_bounds`] from joint steps given as magnitudes (`steps[i]` = |qb_i - qa_i|,
    /// the short way on continuous joints), written as `out[link] = bound` for every link that
    /// carries shapes; other entries are left as they are. No allocation, so a checker can
    /// bound many motions (or one motion with some joints held: a zero step) cheaply. Steps of
    /// the wrong length write nothing.
    pub fn travel_bounds_of_steps(&self, steps: &[f64], out: &mut [f64]) {
        let g = &*self.geom;
        if steps.len() != g.dof {
            return;
        }
        for (slot, l) in g.links.iter().enumerate() {
            if let Some(o) = out.get_mut(l.link) {
                *o = g.lever[slot * g.dof..(slot + 1) * g.dof].iter().zip(steps).map(|(a, d)| a * d).sum();
            }
        }
    }

    /// What a certificate of `qa`-`qb` starts from on the sphere path: the geometry, the joint
    /// changes, their magnitudes and how far each link and self pair can travel (`None` off the
    /// sphere path or for configurations of the wrong length).
    #[cfg(test)]
    fn segment_for_tests(&self, qa: &[f64], qb: &[f64]) -> Option<SegmentForTests<'_>> {
        let (g, fast) = (&*self.geom, self.fast.as_ref()?);
        if qa.len() != g.dof || qb.len() != g.dof {
            return None;
        }
        let mut delta = Vec::new();
        g.cspace.deltas_into(qa, qb, &mut delta);
        let steps: Vec<f64> = delta.iter().map(|d| d.abs()).collect();
        let mut travel = Vec::new();
        g.travel_into(&steps, &mut travel);
        Some(SegmentForTests { fast, delta, steps, travel })
    }

    /// The pieces the certificate's first `levels` levels of single-precision batches leave of
    /// `qa`-`qb` to the double-precision checks, each with whether its self pairs were found
    /// free: `(t0, t1, pairs free)`; `None` when the segment runs no batch, or a batch finds a
    /// contact.
    #[cfg(test)]
    pub(crate) fn batches_left(
        &self,
        qa: &[f64],
        qb: &[f64],
        levels: u32,
        s: &mut CollisionScratch,
    ) -> Option<Vec<(f64, f64, bool)>> {
        let solids32 = self.scene.solids32.as_ref()?;
        let SegmentForTests { fast, delta, steps, travel } = self.segment_for_tests(qa, qb)?;
        let most = travel_max(&travel, self.geom.links.len());
        let pieces = first_pieces(most.0.max(most.1));
        let (mut margins, mut step, mut dir, mut spans) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let first = (&travel[..], &steps[..], most, pieces);
        let still = fast.still_along(qa, &delta, None);
        let (batches, hit) = self.batched_levels(
            fast,
            solids32,
            (qa, &delta, still),
            first,
            levels,
            &mut spans,
            (&mut margins, &mut step, &mut dir),
            s,
        );
        (batches > 0 && !hit).then(|| spans.iter().map(|sp| (sp.t0, sp.t1, sp.pairs_free)).collect())
    }

    /// The query the certificate makes of the sub-interval `[t0, t1]` of `qa`-`qb` on the sphere
    /// path, listing what is near, and how far either side of its midpoint it certified free
    /// (`None` off the sphere path or for configurations of the wrong length).
    #[cfg(test)]
    pub(crate) fn span_query(
        &self,
        qa: &[f64],
        qb: &[f64],
        (t0, t1): (f64, f64),
        s: &mut CollisionScratch,
    ) -> Option<(Check, f64)> {
        let g = &*self.geom;
        let SegmentForTests { fast, delta, steps, travel } = self.segment_for_tests(qa, qb)?;
        let half = 0.5 * (t1 - t0);
        let (mut margins, mut step) = (Vec::new(), Vec::new());
        span_margins(half, &travel, &steps, &mut margins, &mut step);
        let mut dir = Vec::new();
        span_dir(half, &delta, &mut dir);
        let slots = g.links.len();
        let inflation = Inflation { link: &margins[..slots], pair: &margins[slots..], step: &step, dir: &dir };
        let mut q = vec![0.0; g.dof];
        ConfigSpace::step_into(qa, &delta, t0 + half, &mut q);
        s.spheres.items.clear();
        let answer = fast.check_listed(
            &q,
            &self.scene.obstacles,
            &self.scene.solids,
            inflation,
            Scope::Everything,
            &mut s.spheres,
        );
        let rho = if answer == Check::Near { reach_of(half, s.spheres.reach) } else { 0.0 };
        Some((answer, rho))
    }

    /// The certificate of [`CollisionModel::motion_is_certified_free`], and the number of
    /// configurations it checked. `check_ends`: check the end configurations too (a planner
    /// that has already checked them passes `false`). Without the check the ends must be free:
    /// the bodies that no joint moves along the motion are then taken as free all along it
    /// (on the sphere path they are not tested in the single-precision batches).
    pub fn certify(
        &self,
        qa: &[f64],
        qb: &[f64],
        tolerance: f64,
        check_ends: bool,
        s: &mut CollisionScratch,
    ) -> (bool, u32) {
        self.certify_in(qa, qb, tolerance, check_ends, true, s)
    }

    /// [`Self::certify`]; `listed` false checks every sub-interval in full on the sphere path
    /// too (for tests that compare the two).
    pub(crate) fn certify_in(
        &self,
        qa: &[f64],
        qb: &[f64],
        tolerance: f64,
        check_ends: bool,
        listed: bool,
        s: &mut CollisionScratch,
    ) -> (bool, u32) {
        let g = &*self.geom;
        let dof = g.dof;
        if qa.len() != dof
            || qb.len() != dof
            || !(tolerance.is_finite() && tolerance > 0.0)
            || qa.iter().chain(qb).any(|v| !v.is_finite())
        {
            return (false, 0);
        }
        let mut checks = 0;
        if check_ends {
            checks += 2;
            if self.collides_with(qa, s) || self.collides_with(qb, s) {
                return (false, checks);
            }
        }
        let mut steps = std::mem::take(&mut s.steps);
        let mut step = std::mem::take(&mut s.step);
        let mut dir = std::mem::take(&mut s.dir);
        let mut travel = std::mem::take(&mut s.inflation);
        let mut margins = std::mem::take(&mut s.margins);
        let mut spans = std::mem::take(&mut s.spans);
        let mut q = std::mem::take(&mut s.q);
        steps.clear();
        let mut delta = std::mem::take(&mut s.delta);
        g.cspace.deltas_into(qa, qb, &mut delta);
        steps.extend(delta.iter().map(|d| d.abs()));
        // How far each link's points can travel over the whole segment (against obstacles),
        // then how far each self-collision pair can close in on itself.
        g.travel_into(&steps, &mut travel);
        let slots = g.links.len();
        let most_each = travel_max(&travel, slots);
        let most = most_each.0.max(most_each.1);
        q.clear();
        q.resize(dof, 0.0);
        spans.clear();
        let pieces = first_pieces(most);
        s.spheres.items.clear();
        s.near_items.clear();
        let mut free = true;
        if listed && let (Some(fast), Some(solids32)) = (&self.fast, &self.scene.solids32) {
            // The batches cut their own pieces (finer), or leave these to the loop below.
            let bufs = (&mut margins, &mut step, &mut dir);
            let first = (&travel[..], &steps[..], most_each, pieces);
            // The ends are free (checked here or by the caller): the bodies no joint moves keep
            // their free poses all along, and the batches skip them.
            let still = fast.still_along(qa, &delta, None);
            let (batches, hit) =
                self.batched_levels(fast, solids32, (qa, &delta, still), first, LANES_LEVELS, &mut spans, bufs, s);
            checks += batches;
            if hit {
                // A piece's midpoint is in contact: nothing left to check.
                free = false;
                spans.clear();
            }
        } else {
            bit_reversed_pieces(&mut spans, pieces);
        }
        let mut head = 0;
        // The half-length (its bits) `margins` and `step` hold; none yet (the batches
        // used them for their own pieces).
        let mut margins_for = f64::NAN.to_bits();
        while head < spans.len() {
            if checks >= CERTIFY_MAX_CHECKS {
                free = false;
                break;
            }
            let Span { t0, t1, within, pairs_free } = spans[head];
            head += 1;
            let half = 0.5 * (t1 - t0);
            let tm = t0 + half;
            // Spans of the first level share one length, and so their margins.
            if half.to_bits() != margins_for {
                margins_for = half.to_bits();
                span_margins(half, &travel, &steps, &mut margins, &mut step);
                span_dir(half, &delta, &mut dir);
            }
            ConfigSpace::step_into(qa, &delta, tm, &mut q);
            checks += 1;
            let inflation = Inflation { link: &margins[..slots], pair: &margins[slots..], step: &step, dir: &dir };
            // A half is checked against only what was near over the whole.
            let first_item = s.spheres.items.len();
            let first_general = s.near_items.len();
            let answer = match &self.fast {
                Some(fast) if listed => {
                    let scope = match within {
                        Some((a, b)) => Scope::Items(a..b),
                        None if pairs_free => Scope::Obstacles,
                        None => Scope::Everything,
                    };
                    fast.check_listed(&q, &self.scene.obstacles, &self.scene.solids, inflation, scope, &mut s.spheres)
                }
                Some(_) => self.check(&q, Some(inflation), s),
                None if listed => self.check_items(&q, inflation, within, s),
                None => self.check(&q, Some(inflation), s),
            };
            let near_items = match &self.fast {
                Some(_) => Some((first_item, s.spheres.items.len())),
                None => Some((first_general, s.near_items.len())),
            }
            .filter(|_| listed);
            match answer {
                Check::Free => {}
                Check::Hit => {
                    free = false;
                    break;
                }
                Check::Near if most * half < tolerance => {
                    free = false;
                    break;
                }
                Check::Near => {
                    // On the sphere path the query also says how much of the sub-interval
                    // around `tm` it certified free: only the rest is checked again.
                    let reach = if near_items.is_some() && self.fast.is_some() { s.spheres.reach } else { 0.0 };
                    let rho = reach_of(half, reach);
                    spans.push(Span { t0, t1: tm - rho, within: near_items, pairs_free });
                    spans.push(Span { t0: tm + rho, t1, within: near_items, pairs_free });
                }
            }
        }
        s.steps = steps;
        s.delta = delta;
        s.step = step;
        s.dir = dir;
        s.inflation = travel;
        s.margins = margins;
        s.spans = spans;
        s.q = q;
        (free, checks)
    }

    /// The first `levels` levels of a certificate on the sphere path, [`lanes::LANES`] pieces
    /// at a time in single precision (see `spheres::lanes` in the source): `spans` := the
    /// pieces none of them proved free, for the double-precision checks (each level cuts the
    /// previous one's pieces left, see [`LANES_LEVELS`]). Returns the number of batches (each
    /// counted as one check: it costs about one) and whether one found a contact (then `spans`
    /// is empty).
    #[allow(clippy::too_many_arguments)]
    fn batched_levels(
        &self,
        fast: &SphereGeom,
        solids32: &Solids32,
        (qa, delta, still): (&[f64], &[f64], u64),
        (travel, steps, (most_link, most_pair), first): (&[f64], &[f64], (f64, f64), usize),
        levels: u32,
        spans: &mut Vec<Span>,
        (margins, step, dir): (&mut Vec<f64>, &mut Vec<f64>, &mut Vec<f64>),
        s: &mut CollisionScratch,
    ) -> (u32, bool) {
        let dof = self.geom.dof;
        // Finer pieces than the double-precision first level (`first` pieces): a batch costs
        // about one check.
        let most = most_link.max(most_pair);
        // As few pieces as keep every margin within `LANES_START_MARGIN` (at most
        // `LANES_MAX_PIECES`, at least `first`), made whole batches: the lanes a smaller count
        // leaves empty cost the same, and more pieces have smaller margins. (Powers of two, as
        // before, cut a passing certificate into 20 pieces on average over the 296 public
        // MotionBenchMaker UR5 problems, where about 14 would have kept within 0.12 m.)
        let need = (most * 0.5 / LANES_START_MARGIN).ceil().min(LANES_MAX_PIECES as f64);
        let need = if need >= 1.0 { (need as usize).max(first) } else { first };
        if need < LANES_MIN_PIECES || dof == 0 {
            bit_reversed_pieces(spans, first);
            return (0, false);
        }
        let pieces = need.next_multiple_of(lanes::LANES).min(LANES_MAX_PIECES);
        let mut left = std::mem::take(&mut s.lanes_left);
        left.clear();
        let first_ids = lane_pieces_in_order(pieces).map(|i| (i as u32, false, u64::MAX));
        let (mut batches, mut hit) = self.pieces_in_lanes(
            fast,
            solids32,
            (qa, delta, still),
            (travel, steps),
            pieces,
            first_ids,
            &mut left,
            (&mut *margins, &mut *step, &mut *dir),
            s,
        );
        // Level by level, the pieces left are cut again and batched: each into `cut` parts, as
        // many as fill the lanes of one batch (at least halves). Their margins shrink in
        // proportion, so most come out free; a batch costs less time than the double-precision
        // checks of one piece and its halves.
        let mut at = pieces;
        let mut done = 1;
        while !hit && !left.is_empty() && done < levels {
            // A power of two: `LANES` (8) over 1, 2, 3 or 4 pieces, or 2.
            let cut = (lanes::LANES / left.len()).max(2);
            // The level's pieces move to the spare buffer; `left` takes the next level's.
            let mut parents = std::mem::take(&mut s.lanes_parents);
            std::mem::swap(&mut parents, &mut left);
            left.clear();
            let next = parents
                .iter()
                .flat_map(|&(i, pairs, near)| (0..cut as u32).map(move |j| (i * cut as u32 + j, pairs, near)));
            at *= cut;
            let bufs = (&mut *margins, &mut *step, &mut *dir);
            let (b, h) =
                self.pieces_in_lanes(fast, solids32, (qa, delta, still), (travel, steps), at, next, &mut left, bufs, s);
            batches += b;
            hit = h;
            done += 1;
            parents.clear();
            s.lanes_parents = parents;
        }
        spans.clear();
        if !hit {
            let width = 1.0 / at as f64;
            spans.extend(left.iter().map(|&(i, pairs_free, _)| Span {
                t0: i as f64 * width,
                t1: (i + 1) as f64 * width,
                within: None,
                pairs_free,
            }));
        }
        s.lanes_left = left;
        (batches, hit)
    }

    /// One level of the certificate's single-precision batches: the pieces `ids` of `qa`-`qb`
    /// cut into `pieces` equal pieces (a power of two), [`lanes::LANES`] at a time, each lane
    /// at its piece's midpoint and grown by the piece's margins. Each id comes with what the
    /// coarser piece holding it left: whether its self pairs are free, and the groups it had
    /// near an obstacle (every group on the first level). A batch tests only those groups
    /// against obstacles, and the self pairs only when some lane's are not free
    /// ([`lanes::LaneMargins::settled`], `pairs_settled`): the coarser piece's test, with its
    /// larger margins, covers all of it. Pushes onto `left` each piece not proven free, with
    /// whether its self pairs are free (given, or found here) and the groups found near here.
    /// Returns the batches run and whether one found a contact (then it stopped). The groups
    /// `still` are not tested ([`lanes::LaneMargins::still`]).
    #[allow(clippy::too_many_arguments)]
    fn pieces_in_lanes(
        &self,
        fast: &SphereGeom,
        solids32: &Solids32,
        (qa, delta, still): (&[f64], &[f64], u64),
        (travel, steps): (&[f64], &[f64]),
        pieces: usize,
        mut ids: impl Iterator<Item = (u32, bool, u64)>,
        left: &mut Vec<(u32, bool, u64)>,
        (margins, step, dir): (&mut Vec<f64>, &mut Vec<f64>, &mut Vec<f64>),
        s: &mut CollisionScratch,
    ) -> (u32, bool) {
        let g = &*self.geom;
        let (dof, slots) = (g.dof, g.links.len());
        // Their margins (as the double-precision loop computes them).
        span_margins(0.5 / pieces as f64, travel, steps, margins, step);
        // Every piece is a straight motion of one length: spheres near with their link's margin
        // are tested again with their own along it.
        span_dir(0.5 / pieces as f64, delta, dir);
        fast.set_lane_motion((step, dir), &mut s.spheres.lanes);
        let mut batches = 0;
        let mut lane = [(0u32, false, u64::MAX); lanes::LANES];
        loop {
            let mut n = 0;
            for slot in lane.iter_mut() {
                match ids.next() {
                    Some(id) => {
                        *slot = id;
                        n += 1;
                    }
                    None => break,
                }
            }
            if n == 0 {
                return (batches, false);
            }
            // Lanes past the last piece repeat it.
            for k in n..lanes::LANES {
                lane[k] = lane[n - 1];
            }
            // Piece `i`'s midpoint is `(2i + 1) / 2 pieces` of the way (exact for a power of
            // two; otherwise the quotient is rounded, by at most 2^-53, far within the relative
            // 1e-9 of a half-length, at least 1/128 of the segment, that `span_margins` adds),
            // written into the lanes from the segment (rows built first and turned cost
            // about 300 instructions a batch more).
            let points =
                SegmentIn { a: qa, delta, n: 2 * pieces as u32, ids: lane.map(|(i, ..)| 2 * i + 1), end: None };
            // Each piece lies in a coarser one whose batch proved the groups it did not find near
            // free of every obstacle, and perhaps the self pairs free: only the rest is tested.
            let scoped = s.scoped_levels;
            let near = if scoped { lane.iter().fold(0u64, |m, &(_, _, nr)| m | nr) } else { u64::MAX };
            let pairs_settled = scoped && lane.iter().all(|&(_, pairs, _)| pairs);
            #[cfg(test)]
            if near != u64::MAX || pairs_settled {
                s.scoped_batches += 1;
            }
            let grow = LaneMargins {
                link: &margins[..slots],
                pair: &margins[slots..],
                uniform: None,
                step: Some(step),
                // Which lanes' self pairs are free, at every level: the next level's batches
                // and the double-precision checks then skip them.
                pairs_of_near: true,
                along: true,
                still,
                settled: !near,
                pairs_settled,
            };
            let answer = fast.free_lanes(LaneInput::Segment(points), dof, solids32, grow, &mut s.spheres.lanes);
            batches += 1;
            if answer.hit & ((1u32 << n) - 1) != 0 {
                return (batches, true);
            }
            for (k, &(i, pairs, _)) in lane[..n].iter().enumerate() {
                if answer.free & (1 << k) == 0 {
                    left.push((i, pairs || answer.pairs_free & (1 << k) != 0, s.spheres.lanes.near[k]));
                }
            }
        }
    }

    /// The robot's shapes posed in the world at `q`, as obstacles for another agent's model.
    /// Names are the link names (`link#k` for the k-th shape of a link with several).
    pub fn link_shapes_world(&self, q: &[f64]) -> Vec<Obstacle> {
        if q.len() != self.geom.dof {
            return Vec::new();
        }
        let poses = self.robot.forward_kinematics(q);
        let mut out = Vec::new();
        for (l, link) in self.robot.links().iter().enumerate() {
            for (k, ps) in link.shapes.iter().enumerate() {
                let name = if link.shapes.len() == 1 { link.name.clone() } else { format!("{}#{k}", link.name) };
                out.push(Obstacle { name, pose: poses[l] * ps.pose, shape: ps.shape.clone() });
            }
        }
        out
    }
}

/// Disable every self-collision pair that is in contact in all of `samples` random
/// configurations (within limits), as MoveIt's setup assistant does for "always in collision"
/// pairs: such pairs are modelling artefacts (overlapping shapes of neighbouring links), and
/// checking them would make every configuration invalid. Returns the pairs disabled (link indices).
pub fn disable_always_colliding(robot: &mut Robot, samples: usize, seed: u64) -> Vec<(usize, usize)> {
    if samples == 0 {
        return Vec::new();
    }
    let model = CollisionModel::build(robot, Environment::new(), false);
    let g = &*model.geom;
    let mut counts = vec![0usize; g.self_pairs.len()];
    let mut rng = Rng::new(seed);
    let mut s = model.scratch();
    let mut q = vec![0.0; robot.dof()];
    for _ in 0..samples {
        robot.random_configuration_into(&mut rng, &mut q);
        model.pose_bodies(&q, &mut s);
        for (p, &(a, b)) in g.self_pairs.iter().enumerate() {
            if model.pair_hits::<false>(a as usize, b as usize, 0.0, &mut s).is_err() {
                counts[p] += 1;
            }
        }
    }
    let mut disabled = Vec::new();
    for (p, &(a, b)) in g.self_pairs.iter().enumerate() {
        if counts[p] == samples {
            let (la, lb) = (g.links[a as usize].link, g.links[b as usize].link);
            robot.disable_pair(la, lb);
            disabled.push((la.min(lb), la.max(lb)));
        }
    }
    disabled
}

/// Disable every self-collision pair that is *proven* never to touch anywhere within the joint
/// limits, and return them (link indices). Unlike MoveIt's "never in collision" pairs, which
/// are guessed from random samples, the proof is a certificate over the whole box of joint
/// values that move the two links relative to each other: at the centre of a box the pair's
/// shapes, each grown by how far its points can move within the box (the lever-arm bound of
/// [`CollisionModel::motion_is_certified_free`]), must be apart; boxes that cannot be
/// certified are halved along their widest motion, until the pair is proven free, found in
/// contact, or `max_checks` pair checks are spent (then the pair stays checked).
///
/// Only pairs moved relative to each other by at most `max_relative_dofs` joints are tried
/// (the number of boxes grows with the power of that count). Continuous joints span
/// [-pi, pi]. A pair that touches in some configuration, or that keeps closer than about
/// 1e-5 m somewhere, is never disabled.
///
/// Checking such a pair during planning costs every motion through it many refinements of the
/// certificate when the pair keeps a few millimetres apart (the spherized UR5's `base_link`
/// and `upper_arm_link` stay 2.5 mm apart whatever the arm does): proving it once saves them.
pub fn disable_never_colliding(robot: &mut Robot, max_relative_dofs: usize, max_checks: usize) -> Vec<(usize, usize)> {
    let model = CollisionModel::build(robot, Environment::new(), false);
    let g = &*model.geom;
    let dof = g.dof;
    let mut s = model.scratch();
    let limits = robot.limits();
    let span = |i: usize| {
        let l = limits[i];
        if l.is_bounded() { (l.lower, l.upper) } else { (-std::f64::consts::PI, std::f64::consts::PI) }
    };
    let mut disabled = Vec::new();
    for (p, &(a, b)) in g.self_pairs.iter().enumerate() {
        let arms = &g.pair_lever[p * dof..(p + 1) * dof];
        let moving: Vec<usize> = (0..dof).filter(|&i| arms[i] > 0.0).collect();
        if moving.len() > max_relative_dofs {
            continue;
        }
        let mut q = robot.home().to_vec();
        let mut step = vec![0.0; dof];
        // Boxes as (lo, hi) over the moving joints.
        let mut boxes: Vec<Vec<(f64, f64)>> = vec![moving.iter().map(|&i| span(i)).collect()];
        let mut checks = 0usize;
        let proven = loop {
            let Some(bx) = boxes.pop() else { break true };
            checks += 1;
            if checks > max_checks {
                break false;
            }
            for (k, &i) in moving.iter().enumerate() {
                let (lo, hi) = bx[k];
                q[i] = 0.5 * (lo + hi);
                step[i] = 0.5 * (hi - lo) * (1.0 + 1e-9);
            }
            match model.pair_check(&q, p, &step, &mut s) {
                Check::Free => {}
                Check::Hit => break false,
                Check::Near => {
                    let (k, motion) = moving
                        .iter()
                        .enumerate()
                        .map(|(k, &i)| (k, arms[i] * step[i]))
                        .fold((0, 0.0), |best, x| if x.1 > best.1 { x } else { best });
                    if motion < 1e-5 {
                        break false;
                    }
                    let (lo, hi) = bx[k];
                    let mid = 0.5 * (lo + hi);
                    let mut left = bx.clone();
                    left[k] = (lo, mid);
                    let mut right = bx;
                    right[k] = (mid, hi);
                    boxes.push(left);
                    boxes.push(right);
                }
            }
        };
        if proven {
            let (la, lb) = (g.links[a as usize].link, g.links[b as usize].link);
            robot.disable_pair(la, lb);
            disabled.push((la.min(lb), la.max(lb)));
        }
    }
    disabled
}

#[cfg(test)]
mod tests {
    use super::*;

    /// On the general path a certificate's halves test only the items (a link against an
    /// obstacle, a self pair) the coarser piece around them left near. On the UR5 of meshes
    /// (example-robot-data's) among boxes, cylinders and hulls, certificates answer as when
    /// every half tests everything, with as many checks; what they certify is free at a fine
    /// resolution; and the halves' scopes are narrower than everything.
    #[test]
    fn general_path_halves_test_only_what_was_near() {
        let corpus = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/corpus");
        let urdf = corpus.join("example-robot-data/robots/ur_description/urdf/ur5_robot.urdf");
        let options = crate::urdf::UrdfOptions { package_dirs: vec![corpus.clone()], ..Default::default() };
        let mut robot = crate::urdf::load_urdf_with(&urdf, None, &options).expect("the UR5 of meshes");
        disable_always_colliding(&mut robot, 300, 3);
        let mut rng = crate::Rng::new(41);
        let mut env = Environment::new();
        for k in 0..12 {
            let p = Vector3::new(rng.range(-0.9, 0.9), rng.range(-0.9, 0.9), rng.range(-0.2, 1.0));
            if p.xy().norm() < 0.3 {
                continue;
            }
            let rot = UnitQuaternion::from_euler_angles(rng.range(-3.0, 3.0), rng.range(-3.0, 3.0), 0.0);
            let shape = match k % 3 {
                0 => Shape::cuboid(rng.range(0.02, 0.15), rng.range(0.02, 0.15), rng.range(0.02, 0.15)),
                1 => Shape::cylinder(rng.range(0.02, 0.1), rng.range(0.05, 0.2)),
                _ => {
                    let cloud: Vec<Point3<f64>> = (0..30)
                        .map(|_| Point3::new(rng.range(-0.1, 0.1), rng.range(-0.1, 0.1), rng.range(-0.1, 0.1)))
                        .collect();
                    Shape::ConvexMesh(Arc::new(crate::geometry::ConvexHull::from_points(&cloud).expect("a hull")))
                }
            };
            env.add(Obstacle::new(format!("o{k}"), Isometry3::from_parts(p.into(), rot), shape));
        }
        let model = CollisionModel::new(&robot, env);
        assert!(model.fast.is_none(), "meshes take the general path");
        let space = robot.config_space();
        let (mut listed, mut everything) = (model.scratch(), model.scratch());
        let (mut certified, mut refused, mut tried, mut narrower) = (0, 0, 0, 0);
        while tried < 80 {
            let qa = robot.random_configuration(&mut rng);
            let far = robot.random_configuration(&mut rng);
            let qb = space.interpolate(&qa, &far, 0.3);
            if model.collides(&qa) || model.collides(&qb) {
                continue;
            }
            tried += 1;
            let answer = model.certify_in(&qa, &qb, 1e-4, false, true, &mut listed);
            assert_eq!(answer, model.certify_in(&qa, &qb, 1e-4, false, false, &mut everything), "{qa:?} -> {qb:?}");
            // Fewer items listed at the end than a full scan of every item would test.
            let items = robot_items(&model);
            narrower += usize::from(answer.1 > 1 && listed.near_items.len() < items * answer.1 as usize);
            if answer.0 {
                certified += 1;
                assert!(model.motion_is_free(&qa, &qb, 0.0005), "certified but collides: {qa:?} -> {qb:?}");
            } else {
                refused += 1;
            }
        }
        assert!(certified > 10 && refused > 5, "{certified} certified, {refused} refused");
        assert!(narrower > 5, "{narrower} certificates scoped their halves");
    }

    /// Every item a general-path scan can test: each link against each obstacle, each self pair.
    fn robot_items(model: &CollisionModel) -> usize {
        model.geom.links.len() * model.scene.obstacles.len() + model.geom.self_pairs.len()
    }

    /// A dropped scratch comes back from the thread's spares with its buffers, and with the best
    /// vector instructions even if it was set to the baseline ones.
    #[test]
    fn spare_scratches_come_back_grown_and_on_the_best_vectors() {
        let robot = crate::builtin("polycrank").expect("robot");
        let model = CollisionModel::new(&robot, Environment::new());
        let s = model.scratch().with_baseline_vectors();
        let grown = s.body_iso.capacity();
        assert!(grown > 0);
        drop(s);
        let again = model.scratch();
        assert_eq!(again.body_iso.capacity(), grown, "the spare is handed out");
        assert_eq!(again.spheres.lanes.isa, Isa::Best);
    }

    /// The clearance of the world-fixed body's spheres (the UR5's base sphere, radius 0.08 m,
    /// 0.9144 m up) is the double-precision gap to the nearest obstacle, worked out again when
    /// an obstacle moves: none is infinite, an overlap is negative.
    #[test]
    fn the_world_fixed_spheres_clearance_follows_the_obstacles() {
        let path = |f: &str| std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures").join(f);
        let robot = crate::urdf::load_urdf(&path("ur5_spherized.urdf"), Some(&path("ur5.srdf"))).expect("the UR5");
        let clear = |m: &CollisionModel| m.scene.solids32.as_ref().expect("balls have closed forms").fixed_clear;
        let mut model = CollisionModel::new(&robot, Environment::new());
        assert_eq!(clear(&model), f64::INFINITY);
        let mut env = Environment::new();
        let at = |x: f64| Isometry3::translation(x, 0.0, 0.9144);
        env.add(Obstacle::new("ball", at(0.08 + 0.05 + 0.2), Shape::sphere(0.05)));
        env.add(Obstacle::new("far", at(3.0), Shape::sphere(0.05)));
        model.set_environment(env);
        assert!((clear(&model) - 0.2).abs() < 1e-12, "{}", clear(&model));
        assert!(model.set_obstacle_pose("ball", at(0.08 + 0.05 - 0.01)));
        assert!((clear(&model) + 0.01).abs() < 1e-12, "{}", clear(&model));
    }

    /// The travel bounds summed over each joint's runs of nonzero arms are the rows' sums in
    /// joint order, bit for bit, for joints held (zero steps) or moving, on robots whose joints
    /// move a part of the rows (two arms, a track under an arm) or all of them.
    #[test]
    fn travel_over_the_nonzero_runs_is_each_rows_sum() {
        let path = |f: &str| std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures").join(f);
        let ur5 = crate::urdf::load_urdf(&path("ur5_spherized.urdf"), Some(&path("ur5.srdf"))).expect("the UR5");
        let robots = ["two-irp6", "irp6-on-track", "polycrank", "rnt"].map(|n| crate::builtin(n).expect("robot"));
        let mut rng = crate::Rng::new(3);
        let mut skipped = 0;
        for robot in robots.iter().chain([&ur5]) {
            let model = CollisionModel::new(robot, Environment::new());
            let g = &*model.geom;
            let rows: Vec<&[f64]> = g.lever.chunks_exact(g.dof).chain(g.pair_lever.chunks_exact(g.dof)).collect();
            skipped += usize::from(
                g.lever_runs.iter().flatten().map(|&(a, b)| (b - a) as usize).sum::<usize>() < rows.len() * g.dof,
            );
            for k in 0..50 {
                let steps: Vec<f64> =
                    (0..g.dof).map(|i| if (k + i) % 3 == 0 { 0.0 } else { rng.uniform() * 2.0 }).collect();
                let mut travel = Vec::new();
                g.travel_into(&steps, &mut travel);
                let direct: Vec<f64> =
                    rows.iter().map(|r| r.iter().zip(&steps).fold(0.0, |t, (a, d)| t + a * d)).collect();
                assert_eq!(travel.len(), direct.len());
                // On the baseline instructions too (`travel_into` takes AVX2 where it can).
                let mut base = vec![0.0; direct.len()];
                g.travel_rows(&steps, &mut base, direct.len());
                assert_eq!(base, travel);
                for (r, (t, d)) in travel.iter().zip(&direct).enumerate() {
                    assert_eq!(t.to_bits(), d.to_bits(), "{}: row {r}, steps {steps:?}", robot.name());
                }
            }
        }
        assert!(skipped >= 1, "no robot left a row out of a joint's runs");
    }

    /// The table's order is the bit reversal of each piece's index, for every power-of-two
    /// count a first level can have: the middle first, then the quarters, and every piece once.
    #[test]
    fn pieces_come_in_bit_reversed_order() {
        let mut pieces = 1;
        while pieces <= LANES_MAX_PIECES {
            let bits = pieces.trailing_zeros();
            let order: Vec<usize> = (1..=pieces).map(|k| piece_in_order(k, pieces)).collect();
            let reversed: Vec<usize> = (1..=pieces)
                .map(|k| (k % pieces).reverse_bits().checked_shr(usize::BITS - bits).unwrap_or(0))
                .collect();
            assert_eq!(order, reversed, "{pieces} pieces");
            let mut sorted = order.clone();
            sorted.sort_unstable();
            assert_eq!(sorted, (0..pieces).collect::<Vec<_>>(), "{pieces} pieces, each once");
            pieces *= 2;
        }
        assert_eq!((1..=4).map(|k| piece_in_order(k, 4)).collect::<Vec<_>>(), [2, 1, 3, 0]);
    }

    /// A first level of batches takes every piece once, for every count it can have, and each
    /// batch one piece of each eighth of the segment.
    #[test]
    fn each_batch_of_a_first_level_spreads_over_the_segment() {
        for pieces in (lanes::LANES..=LANES_MAX_PIECES).step_by(lanes::LANES) {
            let order: Vec<usize> = lane_pieces_in_order(pieces).collect();
            let mut sorted = order.clone();
            sorted.sort_unstable();
            assert_eq!(sorted, (0..pieces).collect::<Vec<_>>(), "{pieces} pieces, each once");
            let m = pieces / lanes::LANES;
            for batch in order.chunks(lanes::LANES) {
                let eighths: Vec<usize> = batch.iter().map(|&i| i / m).collect();
                assert_eq!(eighths, (0..lanes::LANES).collect::<Vec<_>>(), "{pieces} pieces: {batch:?}");
            }
        }
        assert_eq!(lane_pieces_in_order(16).collect::<Vec<_>>()[..9], [1, 3, 5, 7, 9, 11, 13, 15, 0]);
    }
}
