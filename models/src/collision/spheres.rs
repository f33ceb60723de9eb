//! The fast path for robots whose collision geometry is spheres only (the "spherized" URDFs of
//! MotionBenchMaker, VAMP and cuRobo).
//!
//! Everything a query touches is flat and prepared at construction: body transforms as rotation
//! matrices (no quaternions: each body frame is turned so that its joint spins about z, and a
//! revolute joint costs one `sin_cos` and a two-column mix), sphere centres in their body
//! frames, link and body (group) bounding spheres, and obstacles in closed forms that answer
//! "how far is this point from the solid" (squared, no square root for boxes).
//!
//! A query poses the bodies and the group spheres. Against obstacles it poses a link's
//! bounding sphere, then its spheres, only when the group sphere survives the broad phase.
//! Self pairs are tested without posing anything in the world: per pair of bodies, the inner
//! body's group centre is taken into the outer body's frame and the outer spheres are tested
//! against it as stored; the few that reach it are taken into the inner body's frame and
//! tested against the inner links' bounding spheres and spheres as stored. Pairs of links on
//! one body never move relative to each other and are answered once, at construction.
//!
//! The same pass answers the *inflated* question the motion certificate needs (see
//! [`super::CollisionModel::motion_is_certified_free`]): are the spheres free even when every
//! sphere of link `l` is grown by `inflation.link[l]` against obstacles, and each
//! self-collision pair `p` by `inflation.pair[p]`? It reports [`Check::Hit`] as soon as an exact
//! contact is found, [`Check::Near`] when only grown spheres touch, else [`Check::Free`].

use nalgebra::{Matrix3, Point3, Vector3};

use super::narrow::{self, View};
use super::{Inflation, ObstacleGeom, RobotGeom, Value, World};

mod arms;
mod batch;
pub(crate) mod lanes;
pub(crate) mod simd8;
mod table;

pub(crate) use batch::LANES;

/// The answer of one (possibly inflated) query.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Check {
    Free,
    /// Free, but some inflated shapes touch.
    Near,
    Hit,
}

/// A body of the sphere path. Its frame is the robot's body frame turned by a constant rotation
/// `A` chosen so that a revolute joint turns about the frame's own z axis (`A e_z` = the joint
/// axis): posing it then costs one `sin_cos` and a 3x2 column mix instead of Rodrigues' formula
/// and a full matrix product. `pre` and `post` are rewritten to match (`A_parentᵀ pre A`,
/// `Aᵀ post A`), and so are the sphere centres (`Aᵀ c`). World positions are unchanged.
#[derive(Debug, Clone)]
struct Body {
    parent: usize,
    pre_r: Matrix3<f64>,
    /// `pre_r` as a signed permutation, when it is exactly one (every entry 0 or ±1): then
    /// `R * pre_r` is a reordering of `R`'s columns with signs, no products (the UR5's base,
    /// elbow and last two wrist joints, whose URDF rotations are exact).
    pre_perm: Option<([usize; 3], [f64; 3])>,
    /// `pre_perm` again when the body is revolute with no `post`, the UR5's every joint: `pose`
    /// then takes its shortest form.
    turn_perm: Option<([usize; 3], [f64; 3])>,
    /// `turn_perm` is the identity with no sign (three of the UR5's six joints): the turn takes
    /// no products by 1 (here and in the single-precision batch).
    plain: bool,
    pre_t: Vector3<f64>,
    /// The one coordinate of `pre_t` that is not zero, when there is one (five of the UR5's
    /// six): the translation takes one column of the parent's rotation (here and in the batch).
    t_axis: Option<usize>,
    /// The joint axis in this body's (turned) frame: `e_z` for a revolute joint; for a prismatic
    /// joint, in the frame after `pre`.
    axis: Vector3<f64>,
    prismatic: bool,
    /// Prismatic joints: the largest `|value + offset|` within the joint limits (infinite when
    /// they do not bound it).
    reach: f64,
    offset: f64,
    post: Option<(Matrix3<f64>, Vector3<f64>)>,
    value: Value,
}

/// A body's joint value as `(q[dof] * scale + add) + offset`: a degree of freedom (scale 1, add
/// 0), a mimic joint, or none (scale 0, `dof` 0).
#[derive(Debug, Clone, Copy)]
struct Angle {
    dof: usize,
    scale: f64,
    add: f64,
    offset: f64,
}

#[derive(Debug, Clone)]
struct Link {
    body: usize,
    first: usize,
    end: usize,
    c: Vector3<f64>,
    r: f64,
}

/// The links that ride on one body, with a sphere around all of their bounding spheres (body
/// frame). The broad phase tests these first: the UR5's last body carries ten links.
#[derive(Debug, Clone)]
struct Group {
    body: usize,
    /// Range into [`SphereGeom::group_links`].
    first: usize,
    end: usize,
    c: Vector3<f64>,
    r: f64,
}

/// The self pairs joining the links of two groups (possibly the same group twice). One side is
/// the *outer* one, the side with fewer distinct links (the UR5's forearm against the ten links
/// of its last body): the query tests each outer sphere against the inner group's sphere once,
/// and only the few that reach it against the inner links.
#[derive(Debug, Clone)]
struct GroupPair {
    outer: usize,
    inner: usize,
    /// The two groups' bodies.
    body_o: usize,
    body_i: usize,
    /// Sum of the two group radii, and the inner group's radius.
    rr: f64,
    r_inner: f64,
    /// Range into [`SphereGeom::runs`].
    runs: std::ops::Range<usize>,
    /// Range into [`SphereGeom::run_pairs`] (all pairs of the group pair).
    pairs: std::ops::Range<usize>,
}

/// One self pair of a [`Run`], with its inner link's bounding sphere (body frame) and spheres.
#[derive(Debug, Clone)]
struct RunPair {
    c: Vector3<f64>,
    r: f64,
    pair: u32,
    link: u32,
    first: u32,
    end: u32,
}

/// The self pairs of one group pair that share their outer link, with that link's bounding
/// sphere (body frame) and spheres.
#[derive(Debug, Clone)]
struct Run {
    outer: usize,
    c: Vector3<f64>,
    r: f64,
    /// The outer link's first sphere.
    first: usize,
    /// Range into [`SphereGeom::run_pairs`].
    pairs: std::ops::Range<usize>,
    /// One past the outer link's last sphere.
    end: usize,
}

/// The joints a probe from `a` by the steps `delta` (ending at `end`, when given) moves: bit `d`
/// for DOF `d`, bit 63 for any from 63 on. A step that is not 0 (not a number included) moves
/// its joint, and so does an end value other than the start's.
fn moving_dofs(a: &[f64], delta: &[f64], end: Option<&[f64]>) -> u64 {
    let mut moving = 0u64;
    for (d, &v) in delta.iter().enumerate() {
        if v != 0.0 {
            moving |= 1 << d.min(63);
        }
    }
    match end {
        Some(end) if moving != every_dof(delta.len()) => {
            for (d, (&e, &v)) in end.iter().zip(a).enumerate() {
                if e != v {
                    moving |= 1 << d.min(63);
                }
            }
            moving
        }
        _ => moving,
    }
}

/// The mask of [`moving_dofs`] with every one of `dof` joints moving.
#[inline]
fn every_dof(dof: usize) -> u64 {
    if dof >= 64 { u64::MAX } else { (1u64 << dof) - 1 }
}

/// A sphere robot prepared for the fast path (built from [`RobotGeom`] when every shape is a sphere).
#[derive(Debug, Clone)]
pub(crate) struct SphereGeom {
    base_r: Matrix3<f64>,
    base_t: Vector3<f64>,
    bodies: Vec<Body>,
    /// How each moving body's joint value follows from `q` (bodies 1.., in order).
    angles: Vec<Angle>,
    links: Vec<Link>,
    /// Sphere centres in their body frames and radii, grouped by link.
    centre: Vec<Vector3<f64>>,
    radius: Vec<f64>,
    /// The same spheres packed as `[x, y, z, r]`, one record per sphere: the self pass reads
    /// them in runs, as stored.
    balls: Vec<[f64; 4]>,
    self_pairs: Vec<(u32, u32)>,
    /// The deepest body carrying both links of each self pair.
    pair_common: Vec<u32>,
    groups: Vec<Group>,
    /// Per group, the degrees of freedom that move its body: bit `d` for DOF `d`, bit 63 for
    /// every DOF from 63 on (see [`Self::still_groups`]).
    group_dofs: Vec<u64>,
    /// The lowest DOF of each group's mask that has one (a group is still only when that joint
    /// is), without repeats; `None` when one of them is past 62 (see [`Self::still_along`]).
    still_keys: Option<Vec<usize>>,
    /// Link slots, grouped by body.
    group_links: Vec<u32>,
    group_pairs: Vec<GroupPair>,
    runs: Vec<Run>,
    /// Self pairs, grouped by group pair, then by outer link.
    run_pairs: Vec<RunPair>,
    /// The answer of the self pairs whose two links ride on one body (constant): `Hit` makes
    /// every query `Hit`, `Near` every inflated one at least `Near`.
    fixed: Check,
    /// Per-sphere lever arms of the motion certificate, and how the pose at a sub-interval's
    /// midpoint tightens them: see [`arms`].
    arms: arms::Arms,
    /// Per group pair, the cells of its relative joints proven free, if it has a table: see
    /// [`table`].
    tables: Vec<Option<std::sync::Arc<table::CellTable>>>,
    /// The same robot in single precision, for batches of the motion certificate (see [`lanes`]).
    lanes: lanes::Lanes,
}

/// An obstacle in the closed form the sphere test needs.
#[derive(Debug, Clone)]
pub(crate) enum Solid {
    Ball {
        c: Vector3<f64>,
        r: f64,
    },
    /// World-to-box rotation (transpose of the pose's), box centre, half extents.
    Cuboid {
        rt: Matrix3<f64>,
        t: Vector3<f64>,
        half: Vector3<f64>,
    },
    Cylinder {
        rt: Matrix3<f64>,
        t: Vector3<f64>,
        r: f64,
        hh: f64,
    },
    Capsule {
        a: Vector3<f64>,
        b: Vector3<f64>,
        r: f64,
    },
    /// Anything else (meshes): the general narrow phase.
    Other,
}

impl Solid {
    pub(crate) fn new(world: &World) -> Solid {
        match world {
            World::Sphere { c, r } => Solid::Ball { c: c.coords, r: *r },
            World::Capsule { a, b, r } => Solid::Capsule { a: a.coords, b: b.coords, r: *r },
            World::Cuboid { iso, half } => Solid::Cuboid {
                rt: iso.rotation.to_rotation_matrix().matrix().transpose(),
                t: iso.translation.vector,
                half: *half,
            },
            World::Cylinder { iso, r, hh } => Solid::Cylinder {
                rt: iso.rotation.to_rotation_matrix().matrix().transpose(),
                t: iso.translation.vector,
                r: *r,
                hh: *hh,
            },
            World::Mesh { .. } => Solid::Other,
        }
    }
}

/// Squared distance from `p` to a solid (0 inside), or `None` when the solid has no closed form.
/// Written out operation by operation (no nalgebra products, whose order of summation is theirs),
/// so that the batched check ([`batch`]) computes exactly the same numbers lane by lane.
#[inline(always)]
fn dist2(solid: &Solid, p: &Vector3<f64>) -> Option<f64> {
    let p = [p.x, p.y, p.z];
    Some(match solid {
        Solid::Ball { c, r } => ball_d2(c, *r, p),
        Solid::Cuboid { rt, t, half } => cuboid_d2(rt, t, half, p),
        Solid::Cylinder { rt, t, r, hh } => cylinder_d2(rt, t, *r, *hh, p),
        Solid::Capsule { a, b, r } => capsule_d2(a, b, *r, p),
        Solid::Other => return None,
    })
}

/// `x² + y² + z²`, in that order.
#[inline(always)]
fn sq3(x: f64, y: f64, z: f64) -> f64 {
    x * x + y * y + z * z
}

/// `rt * (p - t)`, written out.
#[inline(always)]
fn local(rt: &Matrix3<f64>, t: &Vector3<f64>, p: [f64; 3]) -> [f64; 3] {
    let (x, y, z) = (p[0] - t.x, p[1] - t.y, p[2] - t.z);
    [
        rt[(0, 0)] * x + rt[(0, 1)] * y + rt[(0, 2)] * z,
        rt[(1, 0)] * x + rt[(1, 1)] * y + rt[(1, 2)] * z,
        rt[(2, 0)] * x + rt[(2, 1)] * y + rt[(2, 2)] * z,
    ]
}

/// [`dist2`] of a ball.
#[inline(always)]
fn ball_d2(c: &Vector3<f64>, r: f64, p: [f64; 3]) -> f64 {
    let d = (sq3(p[0] - c.x, p[1] - c.y, p[2] - c.z).sqrt() - r).max(0.0);
    d * d
}

/// [`dist2`] of a box.
#[inline(always)]
fn cuboid_d2(rt: &Matrix3<f64>, t: &Vector3<f64>, half: &Vector3<f64>, p: [f64; 3]) -> f64 {
    box_d2(local(rt, t, p), [half.x, half.y, half.z])
}

/// [`dist2`] of a cylinder.
#[inline(always)]
fn cylinder_d2(rt: &Matrix3<f64>, t: &Vector3<f64>, r: f64, hh: f64, p: [f64; 3]) -> f64 {
    let l = local(rt, t, p);
    let dr = ((l[0] * l[0] + l[1] * l[1]).sqrt() - r).max(0.0);
    let dz = (l[2].abs() - hh).max(0.0);
    dr * dr + dz * dz
}

/// [`dist2`] of a capsule.
#[inline(always)]
fn capsule_d2(a: &Vector3<f64>, b: &Vector3<f64>, r: f64, p: [f64; 3]) -> f64 {
    let ab = [b.x - a.x, b.y - a.y, b.z - a.z];
    let len2 = sq3(ab[0], ab[1], ab[2]);
    let ap = [p[0] - a.x, p[1] - a.y, p[2] - a.z];
    let s = if len2 > 1e-18 { ((ap[0] * ab[0] + ap[1] * ab[1] + ap[2] * ab[2]) / len2).clamp(0.0, 1.0) } else { 0.0 };
    let d = (sq3(a.x + ab[0] * s - p[0], a.y + ab[1] * s - p[1], a.z + ab[2] * s - p[2]).sqrt() - r).max(0.0);
    d * d
}

/// Squared distance from `l` to the box of half extents `half` about the origin (0 inside).
#[inline(always)]
fn box_d2(l: [f64; 3], half: [f64; 3]) -> f64 {
    let dx = (l[0].abs() - half[0]).max(0.0);
    let dy = (l[1].abs() - half[1]).max(0.0);
    let dz = (l[2].abs() - half[2]).max(0.0);
    dx * dx + dy * dy + dz * dz
}

/// Squared distance from `p` to an obstacle's world box (as `dist2_point_aabb`, written out).
#[inline(always)]
fn aabb_d2(o: &ObstacleGeom, p: [f64; 3]) -> f64 {
    let dx = (o.lo.x - p[0]).max(0.0).max(p[0] - o.hi.x);
    let dy = (o.lo.y - p[1]).max(0.0).max(p[1] - o.hi.y);
    let dz = (o.lo.z - p[2]).max(0.0).max(p[2] - o.hi.z);
    dx * dx + dy * dy + dz * dz
}

/// Whether a sphere at `p` of radius `r` is clear of obstacle `o`'s world box by more than a
/// relative 1e-9 and an absolute 1e-12 m: [`may_touch`]'s prefilter of turned boxes and
/// cylinders, cheaper than their distance (no rotation), and never true where the distance
/// test would pass (the box holds the solid; the slack is far above the rounding of either).
/// On the 296 public MotionBenchMaker UR5 problems, planning instructions 529.1 M -> 519.6 M;
/// on 10 generated cage problems 207.4 M -> 202.9 M; paths identical.
#[inline(always)]
fn far_from_box(o: &ObstacleGeom, p: [f64; 3], r: f64) -> bool {
    let r = r * (1.0 + 1e-9) + 1e-12;
    aabb_d2(o, p) > r * r
}

/// Whether a sphere at `c` of radius `r` may touch the solid (of obstacle `o`): exact for balls
/// and boxes, the box around a cylinder in its own frame, else the obstacle's world box. Tighter
/// than the world box at the same cost (a box turned 49° about z, as in MotionBenchMaker's
/// box and bookshelf scenes, has a world box twice its area).
#[inline(always)]
fn may_touch(solid: &Solid, o: &ObstacleGeom, c: &Vector3<f64>, r: f64) -> bool {
    let p = [c.x, c.y, c.z];
    match solid {
        Solid::Ball { c, r: rb } => ball_d2(c, *rb, p) <= r * r,
        Solid::Cuboid { rt, t, half } => !far_from_box(o, p, r) && cuboid_d2(rt, t, half, p) <= r * r,
        Solid::Cylinder { rt, t, r: rc, hh } => {
            !far_from_box(o, p, r) && box_d2(local(rt, t, p), [*rc, *rc, *hh]) <= r * r
        }
        _ => aabb_d2(o, p) <= r * r,
    }
}

/// `sin x` and `cos x` for joint angles, without a call into libm (whose `sincos` was a tenth of a
/// collision check): the nearest multiple `k` of π/2 is taken off in three exact parts
/// (Cody and Waite), then fdlibm's minimax polynomials of degree 13 and 14 on [-π/4, π/4]
/// (error below 2^-58), evaluated in two short chains rather than one long Horner chain. Within
/// 2 ulp of libm for |x| < 2^20 (tested); libm beyond, and for NaN.
#[inline(always)]
fn sin_cos(x: f64) -> (f64, f64) {
    if x.is_nan() || x.abs() >= SIN_COS_RANGE {
        return x.sin_cos();
    }
    sin_cos_kernel(x)
}

/// Where [`sin_cos_kernel`] holds: `|x|` below 2^20.
const SIN_COS_RANGE: f64 = 1_048_576.0;

// π/2 in three parts: the first two have trailing zero bits, so that k times each is exact.
const PIO2_1: f64 = 1.570_796_326_734_125_6; // 0x3FF921FB54400000
const PIO2_2: f64 = 6.077_100_506_303_966e-11; // 0x3DD0B4611A600000
const PIO2_2T: f64 = 2.022_266_248_795_950_6e-21; // π/2 - PIO2_1 - PIO2_2
/// Adding and subtracting 1.5 * 2^52 rounds to the nearest integer (round to nearest even).
const SIN_ROUND: f64 = 6_755_399_441_055_744.0;
/// The kernels' coefficients of fdlibm (k_sin.c, k_cos.c; Sun Microsystems, 1993): minimax
/// polynomials on [-π/4, π/4], error below 2^-58.
const SIN_S: [f64; 6] = [
    -1.666_666_666_666_663_2e-1,
    8.333_333_333_322_49e-3,
    -1.984_126_982_985_795e-4,
    2.755_731_370_707_006_8e-6,
    -2.505_076_025_340_686_3e-8,
    1.589_690_995_211_55e-10,
];
/// See [`SIN_S`].
const COS_C: [f64; 6] = [
    4.166_666_666_666_66e-2,
    -1.388_888_888_887_411e-3,
    2.480_158_728_947_673e-5,
    -2.755_731_435_139_066_3e-7,
    2.087_572_321_298_175e-9,
    -1.135_964_755_778_819_5e-11,
];

/// [`sin_cos`] for `|x|` below [`SIN_COS_RANGE`] (not NaN), without a branch, so that a loop
/// over several angles runs in vector registers.
#[inline(always)]
fn sin_cos_kernel(x: f64) -> (f64, f64) {
    let shifted = x * std::f64::consts::FRAC_2_PI + SIN_ROUND;
    let k = shifted - SIN_ROUND;
    let r = ((x - k * PIO2_1) - k * PIO2_2) - k * PIO2_2T;
    let r2 = r * r;
    let r4 = r2 * r2;
    // Split evaluation (two chains of three) to shorten the dependency chain.
    let ps = (SIN_S[0] + r2 * SIN_S[1] + r4 * SIN_S[2]) + r4 * r2 * (SIN_S[3] + r2 * SIN_S[4] + r4 * SIN_S[5]);
    let pc = (COS_C[0] + r2 * COS_C[1] + r4 * COS_C[2]) + r4 * r2 * (COS_C[3] + r2 * COS_C[4] + r4 * COS_C[5]);
    let sin = r + r * r2 * ps;
    // 1 - r²/2 with its rounding error carried into the small terms.
    let hz = 0.5 * r2;
    let w = 1.0 - hz;
    let cos = w + (((1.0 - w) - hz) + r4 * pc);
    // The quadrant, without branches (random joint angles would mispredict them): swap sin
    // and cos for odd `k`, flip sin's sign for k mod 4 in {2, 3} and cos's for {1, 2}. The
    // low bits of `shifted`'s mantissa are those of `k + 2^51`, so `k mod 4` (no conversion
    // to an integer, which vector registers lack).
    let q = shifted.to_bits();
    let swap = 0u64.wrapping_sub(q & 1);
    let (sb, cb) = (sin.to_bits(), cos.to_bits());
    let a = (sb & !swap) | (cb & swap);
    let b = (cb & !swap) | (sb & swap);
    let sin_x = f64::from_bits(a ^ ((q & 2) << 62));
    let cos_x = f64::from_bits(b ^ ((q.wrapping_add(1) & 2) << 62));
    (sin_x, cos_x)
}

/// `a * b`, written out (nalgebra's generic product costs more instructions here).
#[inline(always)]
fn mul3(a: &Matrix3<f64>, b: &Matrix3<f64>) -> Matrix3<f64> {
    let mut out = Matrix3::zeros();
    for c in 0..3 {
        let (b0, b1, b2) = (b[(0, c)], b[(1, c)], b[(2, c)]);
        for r in 0..3 {
            out[(r, c)] = a[(r, 0)] * b0 + a[(r, 1)] * b1 + a[(r, 2)] * b2;
        }
    }
    out
}

/// `a * v`, written out.
#[inline(always)]
fn mul3v(a: &Matrix3<f64>, v: &Vector3<f64>) -> Vector3<f64> {
    let (x, y, z) = (v.x, v.y, v.z);
    Vector3::new(
        a[(0, 0)] * x + a[(0, 1)] * y + a[(0, 2)] * z,
        a[(1, 0)] * x + a[(1, 1)] * y + a[(1, 2)] * z,
        a[(2, 0)] * x + a[(2, 1)] * y + a[(2, 2)] * z,
    )
}

/// `aᵀ * v`, written out.
#[inline(always)]
fn mul3tv(a: &Matrix3<f64>, v: &Vector3<f64>) -> Vector3<f64> {
    let (x, y, z) = (v.x, v.y, v.z);
    Vector3::new(
        a[(0, 0)] * x + a[(1, 0)] * y + a[(2, 0)] * z,
        a[(0, 1)] * x + a[(1, 1)] * y + a[(2, 1)] * z,
        a[(0, 2)] * x + a[(1, 2)] * y + a[(2, 2)] * z,
    )
}

/// Working memory of the fast path, kept inside [`super::CollisionScratch`].
#[derive(Debug, Clone)]
pub(crate) struct SphereScratch {
    rot: Vec<Matrix3<f64>>,
    pos: Vec<Vector3<f64>>,
    /// Per body: the joint value (offset included) and its sine and cosine.
    angle: Vec<f64>,
    sin: Vec<f64>,
    cos: Vec<f64>,
    link_c: Vec<Vector3<f64>>,
    centre: Vec<Vector3<f64>>,
    posed: Vec<u32>,
    /// World centres of the group spheres, and of the link bounding spheres (posed on demand:
    /// `link_posed[l] == stamp`).
    group_c: Vec<Vector3<f64>>,
    link_posed: Vec<u32>,
    /// Per check: the largest link margin of each group (inflated queries).
    group_e: Vec<f64>,
    stamp: u32,
    /// The near items of the motion certificate's sub-intervals (see [`Item`]), in the order
    /// the checks found them: each sub-interval's own is a range of this.
    pub(crate) items: Vec<Item>,
    /// After a listing query ([`SphereGeom::check_listed`]) that answered `Near`: the smallest
    /// ratio, over what it found near, of the exact gap to the margin that gap was tested
    /// against (in `[0, 1)`; 1 when nothing was near). Every margin grows at least in
    /// proportion to the sub-interval (see `reach_of` in the certificate), so the query certifies
    /// free the part of its sub-interval within this share of its half-length of the midpoint.
    pub(crate) reach: f64,
    /// The batched path's working memory (see [`batch`]).
    pub(crate) batch: batch::BatchScratch,
    /// Configurations of a batch, one after another.
    pub(crate) batch_q: Vec<f64>,
    /// The single-precision batch's working memory (see [`lanes`]).
    pub(crate) lanes: lanes::LaneScratch,
}

/// What a listing query of the certificate tests ([`SphereGeom::check_listed`]).
#[derive(Debug, Clone)]
pub(crate) enum Scope {
    /// Every obstacle and self pair.
    Everything,
    /// The obstacles alone: the self pairs are known free over the sub-interval.
    Obstacles,
    /// The items of a sub-interval holding this one (a range of `s.items`), the only things
    /// that can be near or in contact here.
    Items(std::ops::Range<usize>),
}

/// One thing an inflated query found *near*: its grown shapes touch, its exact ones do not. A
/// query that lists them ([`SphereGeom::check_listed`]) certifies everything else free over
/// its whole sub-interval, so a check of a part of that sub-interval need test these alone.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Item {
    /// Sphere `k` of link `l` against obstacle `o`.
    Obstacle { k: u32, l: u32, o: u32 },
    /// Spheres `i` (of link `li`) and `j` (of link `lj`) of self pair `p`.
    Pair { i: u32, j: u32, p: u32, li: u32, lj: u32 },
    /// The self pairs of links on one body (constant, never in contact, but within a hair).
    Fixed,
}

impl SphereScratch {
    pub(crate) const fn new() -> Self {
        Self {
            rot: Vec::new(),
            pos: Vec::new(),
            angle: Vec::new(),
            sin: Vec::new(),
            cos: Vec::new(),
            link_c: Vec::new(),
            centre: Vec::new(),
            posed: Vec::new(),
            group_c: Vec::new(),
            link_posed: Vec::new(),
            group_e: Vec::new(),
            stamp: 0,
            items: Vec::new(),
            reach: 1.0,
            batch: batch::BatchScratch::new(),
            batch_q: Vec::new(),
            lanes: lanes::LaneScratch::new(),
        }
    }
}

/// `reach` lowered to `gap / margin`: a near item's exact gap (distance less the radii, not
/// negative) over the margin it was tested against.
#[inline]
fn note_gap(reach: &mut f64, gap: f64, margin: f64) {
    let r = (gap - 2e-12).max(0.0) / margin;
    if r < *reach {
        *reach = r;
    }
}

/// `m` as a signed permutation: for each column, the row of its one nonzero entry and that
/// entry (±1); `None` unless every entry is exactly 0 or ±1, one nonzero per row and column.
fn signed_permutation(m: &Matrix3<f64>) -> Option<([usize; 3], [f64; 3])> {
    let mut perm = [0; 3];
    let mut sign = [0.0; 3];
    for c in 0..3 {
        let mut found = false;
        for r in 0..3 {
            let v = m[(r, c)];
            if v == 0.0 {
                continue;
            }
            if found || v.abs() != 1.0 {
                return None;
            }
            found = true;
            perm[c] = r;
            sign[c] = v;
        }
        if !found {
            return None;
        }
    }
    (perm[0] != perm[1] && perm[1] != perm[2] && perm[0] != perm[2]).then_some((perm, sign))
}

/// `m` as `p * Rz(g)`: a signed permutation `p` after a turn by `g` about z, when `m` maps z
/// exactly onto a signed coordinate axis and so turns the rest about it (within 1e-12 per
/// entry; `None` otherwise). A joint's pre-rotation of this form turns about the joint's own
/// axis, so `g` joins the joint's offset and `p` costs no products (the UR5's shoulder lift
/// and first wrist joints, whose URDF origins turn by 1.570796325 rad about their axes).
fn split_about_z(m: &Matrix3<f64>) -> Option<(Matrix3<f64>, f64)> {
    let k = (0..3).find(|&r| m[(r, 2)] != 0.0)?;
    let sigma = m[(k, 2)];
    if sigma.abs() != 1.0 || (0..3).any(|r| r != k && m[(r, 2)] != 0.0) || m[(k, 0)] != 0.0 || m[(k, 1)] != 0.0 {
        return None;
    }
    let (a, b) = match k {
        0 => (1, 2),
        1 => (0, 2),
        _ => (0, 1),
    };
    let mut p = Matrix3::zeros();
    p[(a, 0)] = 1.0;
    p[(b, 1)] = 1.0;
    p[(k, 2)] = sigma;
    if p.determinant() < 0.0 {
        p[(b, 1)] = -1.0;
    }
    let t = p.transpose() * m;
    let g = t[(1, 0)].atan2(t[(0, 0)]);
    let (sn, cs) = g.sin_cos();
    let rz = Matrix3::new(cs, -sn, 0.0, sn, cs, 0.0, 0.0, 0.0, 1.0);
    ((t - rz).amax() <= 1e-12).then_some((p, g))
}

/// A rotation whose third column is the unit vector `a` (right-handed).
fn frame_with_z(a: &Vector3<f64>) -> Matrix3<f64> {
    // Start from the world axis least aligned with `a`.
    let pick = if a.x.abs() <= a.y.abs() && a.x.abs() <= a.z.abs() {
        Vector3::x()
    } else if a.y.abs() <= a.z.abs() {
        Vector3::y()
    } else {
        Vector3::z()
    };
    let u = (pick - a * pick.dot(a)).normalize();
    let v = a.cross(&u);
    Matrix3::from_columns(&[u, v, *a])
}

/// Turn every revolute body's frame so that its joint turns about the frame's z axis (see
/// [`Body`]); sphere and link centres follow their body.
fn turn_to_z(
    mut bodies: Vec<Body>,
    mut centre: Vec<Vector3<f64>>,
    mut links: Vec<Link>,
) -> (Vec<Body>, Vec<Vector3<f64>>, Vec<Link>) {
    let turn: Vec<Matrix3<f64>> = bodies
        .iter()
        .enumerate()
        .map(|(i, b)| if i == 0 || b.prismatic { Matrix3::identity() } else { frame_with_z(&b.axis) })
        .collect();
    for (i, b) in bodies.iter_mut().enumerate().skip(1) {
        let (tp, tb) = (turn[b.parent].transpose(), turn[i]);
        b.pre_r = tp * b.pre_r * tb;
        b.pre_t = tp * b.pre_t;
        if !b.prismatic {
            b.axis = Vector3::z();
            b.post = b.post.map(|(r, t)| (tb.transpose() * r * tb, tb.transpose() * t));
        }
    }
    for link in &mut links {
        let t = turn[link.body].transpose();
        link.c = t * link.c;
        for c in &mut centre[link.first..link.end] {
            *c = t * *c;
        }
    }
    (bodies, centre, links)
}

/// The links grouped by body (see [`Group`]) and their self pairs grouped by group pair and
/// outer link (see [`GroupPair`]).
struct Grouping {
    groups: Vec<Group>,
    group_links: Vec<u32>,
    group_pairs: Vec<GroupPair>,
    runs: Vec<Run>,
    run_pairs: Vec<RunPair>,
}

/// Group the links by body (see [`Group`]) and the self pairs by the groups they join.
fn group_by_body(links: &[Link], self_pairs: &[(u32, u32)]) -> Grouping {
    let mut bodies: Vec<usize> = links.iter().map(|l| l.body).collect();
    bodies.sort_unstable();
    bodies.dedup();
    let mut groups = Vec::new();
    let mut group_links = Vec::new();
    let mut group_of = vec![0usize; links.len()];
    for &body in &bodies {
        let first = group_links.len();
        for (l, link) in links.iter().enumerate() {
            if link.body == body {
                group_of[l] = groups.len();
                group_links.push(l as u32);
            }
        }
        let members: Vec<(Point3<f64>, f64)> =
            group_links[first..].iter().map(|&l| (Point3::from(links[l as usize].c), links[l as usize].r)).collect();
        let (c, r) = super::enclosing_sphere(&members);
        // A hair more, so that rounding in the group test never drops a link the link test keeps.
        groups.push(Group { body, first, end: group_links.len(), c: c.coords, r: r * (1.0 + 1e-12) + 1e-12 });
    }
    // Each pair with its link in the lower group first: (groups, links, pair index).
    type Keyed = ((usize, usize), (u32, u32), u32);
    let mut keyed: Vec<Keyed> = self_pairs
        .iter()
        .enumerate()
        .map(|(p, &(a, b))| {
            let (ga, gb) = (group_of[a as usize], group_of[b as usize]);
            if ga <= gb { ((ga, gb), (a, b), p as u32) } else { ((gb, ga), (b, a), p as u32) }
        })
        .collect();
    keyed.sort_unstable_by_key(|&(g, _, p)| (g, p));
    let mut grouping =
        Grouping { groups, group_links, group_pairs: Vec::new(), runs: Vec::new(), run_pairs: Vec::new() };
    for block in keyed.chunk_by(|x, y| x.0 == y.0) {
        let (lower, upper) = block[0].0;
        let distinct = |side: fn(&(u32, u32)) -> u32| {
            let mut v: Vec<u32> = block.iter().map(|(_, l, _)| side(l)).collect();
            v.sort_unstable();
            v.dedup();
            v.len()
        };
        // Outer: the side with fewer distinct links.
        let lower_outer = distinct(|l| l.0) <= distinct(|l| l.1);
        let mut oriented: Vec<(u32, u32, u32)> =
            block.iter().map(|&(_, (a, b), p)| if lower_outer { (a, b, p) } else { (b, a, p) }).collect();
        oriented.sort_unstable();
        let (outer, inner) = if lower_outer { (lower, upper) } else { (upper, lower) };
        let (runs_first, pairs_first) = (grouping.runs.len(), grouping.run_pairs.len());
        for run in oriented.chunk_by(|x, y| x.0 == y.0) {
            let first = grouping.run_pairs.len();
            grouping.run_pairs.extend(run.iter().map(|&(_, b, p)| {
                let l = &links[b as usize];
                RunPair { c: l.c, r: l.r, pair: p, link: b, first: l.first as u32, end: l.end as u32 }
            }));
            let outer = run[0].0 as usize;
            let la = &links[outer];
            grouping.runs.push(Run {
                outer,
                c: la.c,
                r: la.r,
                first: la.first,
                pairs: first..grouping.run_pairs.len(),
                end: la.end,
            });
        }
        let rr = grouping.groups[outer].r + grouping.groups[inner].r;
        grouping.group_pairs.push(GroupPair {
            outer,
            inner,
            body_o: grouping.groups[outer].body,
            body_i: grouping.groups[inner].body,
            rr,
            r_inner: grouping.groups[inner].r,
            runs: runs_first..grouping.runs.len(),
            pairs: pairs_first..grouping.run_pairs.len(),
        });
    }
    grouping
}

impl SphereGeom {
    /// The fast form of `g`, or `None` when some shape is not a sphere; with its self-collision
    /// cell tables when `prove_cells` (see [`table`]).
    pub(crate) fn new(g: &RobotGeom, prove_cells: bool) -> Option<SphereGeom> {
        let mut centre = Vec::new();
        let mut radius = Vec::new();
        let mut links = Vec::new();
        for l in &g.links {
            let first = centre.len();
            for k in l.shapes.clone() {
                match &g.shapes[k].local {
                    super::Local::Sphere { c, r } => {
                        centre.push(c.coords);
                        radius.push(*r);
                    }
                    _ => return None,
                }
            }
            links.push(Link { body: l.body, first, end: centre.len(), c: l.c.coords, r: l.r });
        }
        let mat = |r: &nalgebra::UnitQuaternion<f64>| *r.to_rotation_matrix().matrix();
        let bodies = g
            .bodies
            .iter()
            .map(|b| Body {
                parent: b.parent,
                pre_r: mat(&b.pre.rotation),
                pre_perm: None,
                turn_perm: None,
                plain: false,
                t_axis: None,
                pre_t: b.pre.translation.vector,
                axis: b.axis.into_inner(),
                prismatic: b.prismatic,
                reach: b.reach,
                offset: b.offset,
                post: b.post.map(|p| (mat(&p.rotation), p.translation.vector)),
                value: b.value,
            })
            .collect();
        let mut arms = arms::Arms::new(g, &links, &centre);
        let pair_common = g
            .self_pairs
            .iter()
            .map(|&(a, b)| super::common_body(&g.bodies, links[a as usize].body, links[b as usize].body) as u32)
            .collect();
        let (mut bodies, centre, links) = turn_to_z(bodies, centre, links);
        for b in bodies.iter_mut().skip(1) {
            // A turn about the joint's own axis before it joins the joint's offset.
            if !b.prismatic
                && signed_permutation(&b.pre_r).is_none()
                && let Some((p, g)) = split_about_z(&b.pre_r)
            {
                b.pre_r = p;
                b.offset += g;
            }
            b.pre_perm = signed_permutation(&b.pre_r);
            b.turn_perm = b.pre_perm.filter(|_| !b.prismatic && b.post.is_none());
            b.plain = b.turn_perm == Some(([0, 1, 2], [1.0; 3]));
            let mut nonzero = (0..3).filter(|&k| b.pre_t[k] != 0.0);
            b.t_axis = match (nonzero.next(), nonzero.next()) {
                (Some(k), None) => Some(k),
                _ => None,
            };
        }
        arms.use_turned_axes(&bodies);
        let angles = bodies
            .iter()
            .skip(1)
            .map(|b| {
                let (dof, scale, add) = match b.value {
                    Value::Dof(d) => (d, 1.0, 0.0),
                    Value::Mimic(d, m, o) => (d, m, o),
                    Value::Zero => (0, 0.0, 0.0),
                };
                Angle { dof, scale, add, offset: b.offset }
            })
            .collect();
        let Grouping { groups, group_links, mut group_pairs, runs, run_pairs } = group_by_body(&links, &g.self_pairs);
        // Pairs of links on one body never move relative to each other: answered once here.
        let mut fixed = Check::Free;
        group_pairs.retain(|gp| {
            if gp.outer != gp.inner {
                return true;
            }
            for run in &runs[gp.runs.clone()] {
                let la = &links[run.outer];
                for rp in &run_pairs[run.pairs.clone()] {
                    for i in la.first..la.end {
                        for j in rp.first as usize..rp.end as usize {
                            let d2 = (centre[i] - centre[j]).norm_squared();
                            let r = radius[i] + radius[j];
                            // As the query would: an exact contact, or within the slack of
                            // a pair margin (nothing moves between the two links).
                            if d2 <= r * r {
                                fixed = Check::Hit;
                            } else if d2 <= (r + 2e-12) * (r + 2e-12) && fixed == Check::Free {
                                fixed = Check::Near;
                            }
                        }
                    }
                }
            }
            false
        });
        // What moves each body: its parent's DOFs and its own joint's (bodies come after their
        // parents).
        let mut body_dofs = vec![0u64; bodies.len()];
        for (b, body) in bodies.iter().enumerate().skip(1) {
            let own = match body.value {
                Value::Dof(d) | Value::Mimic(d, _, _) => 1u64 << d.min(63),
                Value::Zero => 0,
            };
            body_dofs[b] = body_dofs.get(body.parent).copied().unwrap_or(u64::MAX) | own;
        }
        let group_dofs: Vec<u64> = groups.iter().map(|g| body_dofs[g.body]).collect();
        let mut keys: Vec<usize> =
            group_dofs.iter().filter(|&&m| m != 0).map(|m| m.trailing_zeros() as usize).collect();
        keys.sort_unstable();
        keys.dedup();
        let still_keys = keys.iter().all(|&d| d < 63).then_some(keys);
        let balls = centre.iter().zip(&radius).map(|(c, &r)| [c.x, c.y, c.z, r]).collect();
        let mut fast = SphereGeom {
            base_r: mat(&g.base.rotation),
            base_t: g.base.translation.vector,
            bodies,
            angles,
            links,
            centre,
            radius,
            balls,
            self_pairs: g.self_pairs.clone(),
            groups,
            group_dofs,
            still_keys,
            group_links,
            group_pairs,
            runs,
            run_pairs,
            pair_common,
            arms,
            fixed,
            tables: Vec::new(),
            lanes: lanes::Lanes::empty(),
        };
        fast.lanes = lanes::Lanes::new(&fast);
        if prove_cells {
            fast.build_tables(&g.pair_lever, g.dof);
        }
        Some(fast)
    }

    /// The groups that none of the joints `moving` moves (bit `d` for DOF `d`, bit 63 for any
    /// from 63 on): bit `g` for group `g` (of the first 64). Along a motion that moves only
    /// those joints, their bodies keep their poses at its start. Empty at once when every DOF
    /// of `dof` moves (a random edge of a one-arm robot).
    pub(crate) fn still_groups(&self, moving: u64, dof: usize) -> u64 {
        if moving == every_dof(dof) {
            return 0;
        }
        let mut still = 0;
        for (g, &dofs) in self.group_dofs.iter().enumerate().take(64) {
            if dofs & moving == 0 {
                still |= 1 << g;
            }
        }
        still
    }

    /// [`Self::still_groups`] along the straight motion from `a` by the joint steps `delta`
    /// (ending at `end`, when given), each of one value per DOF (the caller checks). At once 0
    /// when the lowest joint of every group's mask moves (then only the groups no joint moves
    /// at all, the base, would be still: few tests, the world-fixed body's skipped anyway when
    /// clear of every obstacle): a random edge of a one-arm robot costs a compare (the full
    /// mask cost the public MotionBenchMaker UR5 problems 0.4% of their planning instructions).
    pub(crate) fn still_along(&self, a: &[f64], delta: &[f64], end: Option<&[f64]>) -> u64 {
        if let Some(keys) = &self.still_keys {
            let held = |d: usize| delta.get(d) == Some(&0.0) && end.is_none_or(|e| e.get(d) == a.get(d));
            if !keys.iter().any(|&d| held(d)) {
                return 0;
            }
        }
        self.still_groups(moving_dofs(a, delta, end), delta.len())
    }

    fn begin(&self, s: &mut SphereScratch) {
        if s.rot.len() != self.bodies.len() {
            s.rot.resize(self.bodies.len(), Matrix3::identity());
            s.pos.resize(self.bodies.len(), Vector3::zeros());
            s.angle.resize(self.angles.len(), 0.0);
            s.sin.resize(self.angles.len(), 0.0);
            s.cos.resize(self.angles.len(), 1.0);
        }
        if s.link_c.len() != self.links.len() {
            s.link_c.resize(self.links.len(), Vector3::zeros());
            s.posed.resize(self.links.len(), 0);
        }
        if s.group_c.len() != self.groups.len() {
            s.group_c.resize(self.groups.len(), Vector3::zeros());
            s.group_e.resize(self.groups.len(), 0.0);
        }
        if s.link_posed.len() != self.links.len() {
            s.link_posed.resize(self.links.len(), 0);
        }
        if s.centre.len() != self.centre.len() {
            s.centre.resize(self.centre.len(), Vector3::zeros());
        }
        s.stamp = s.stamp.wrapping_add(1);
        if s.stamp == 0 {
            s.posed.iter_mut().for_each(|p| *p = 0);
            s.link_posed.iter_mut().for_each(|p| *p = 0);
            s.stamp = 1;
        }
    }

    /// Body transforms and group bounding-sphere centres at `q` (of the right length).
    #[inline]
    fn pose(&self, q: &[f64], s: &mut SphereScratch) {
        self.pose_with::<true>(q, s);
    }

    /// [`Self::pose`]; the group centres only with `GROUPS` (queries of listed items and of
    /// one self pair use none: about a fifth of the work).
    #[inline]
    fn pose_with<const GROUPS: bool>(&self, q: &[f64], s: &mut SphereScratch) {
        self.begin(s);
        s.rot[0] = self.base_r;
        s.pos[0] = self.base_t;
        let n = self.bodies.len();
        // Every joint value first, then their sines and cosines in one branch-free loop (in
        // vector registers), then the frames.
        let m = self.angles.len();
        let (angle, sin, cos) = (&mut s.angle[..m], &mut s.sin[..m], &mut s.cos[..m]);
        let mut in_range = true;
        for (a, v) in self.angles.iter().zip(angle.iter_mut()) {
            // (As cheap as an index's bounds check; 0 for a robot with no degree of freedom.)
            let x = q.get(a.dof).copied().unwrap_or(0.0);
            *v = (x * a.scale + a.add) + a.offset;
            in_range &= v.abs() < SIN_COS_RANGE; // false for NaN
        }
        if in_range {
            for ((v, sn), cs) in angle.iter().zip(sin.iter_mut()).zip(cos.iter_mut()) {
                (*sn, *cs) = sin_cos_kernel(*v);
            }
        } else {
            for ((v, sn), cs) in angle.iter().zip(sin.iter_mut()).zip(cos.iter_mut()) {
                (*sn, *cs) = sin_cos(*v);
            }
        }
        let (rot, pos) = (&mut s.rot[..n], &mut s.pos[..n]);
        for (i, b) in self.bodies.iter().enumerate().skip(1) {
            let (v, sn, cs) = (angle[i - 1], sin[i - 1], cos[i - 1]);
            let (pr, pp) = (&rot[b.parent], pos[b.parent]);
            // The parent's rotation times `pre_t`: along one axis, that axis's column (the
            // other products are by zero, and adding their zeros changes no value).
            let along = |pr: &Matrix3<f64>| match b.t_axis {
                Some(k) => pr.column(k) * b.pre_t[k],
                None => mul3v(pr, &b.pre_t),
            };
            if b.plain {
                // The turn below with the identity and no signs: no products by 1 (the same
                // values).
                let col = |k: usize| Vector3::new(pr[(0, k)], pr[(1, k)], pr[(2, k)]);
                let (a, bb, c) = (col(0), col(1), col(2));
                let x = a * cs + bb * sn;
                let y = bb * cs - a * sn;
                pos[i] = along(pr) + pp;
                rot[i] = Matrix3::from_columns(&[x, y, c]);
                continue;
            }
            if let Some((cols, sign)) = &b.turn_perm {
                // pr * P * Rz(v), P a signed permutation: the columns are the parent's columns
                // `cols` with signs, the first two mixed by the joint's cosine and sine.
                let col = |k: usize| Vector3::new(pr[(0, k)], pr[(1, k)], pr[(2, k)]);
                let (a, bb, c) = (col(cols[0]), col(cols[1]), col(cols[2]));
                let (k0, k1, k2, k3) = (sign[0] * cs, sign[1] * sn, sign[1] * cs, sign[0] * sn);
                let x = a * k0 + bb * k1;
                let y = bb * k2 - a * k3;
                let z = c * sign[2];
                pos[i] = along(pr) + pp;
                rot[i] = Matrix3::from_columns(&[x, y, z]);
                continue;
            }
            let pr = *pr;
            let m = match &b.pre_perm {
                // Exactly `mul3`: the other two products are zeros.
                Some((perm, sign)) => Matrix3::from_columns(&[
                    pr.column(perm[0]) * sign[0],
                    pr.column(perm[1]) * sign[1],
                    pr.column(perm[2]) * sign[2],
                ]),
                None => mul3(&pr, &b.pre_r),
            };
            let (mut r, mut t) = if b.prismatic {
                let a = b.axis * v;
                (m, mul3v(&pr, &b.pre_t) + mul3v(&m, &a) + pp)
            } else {
                // m * Rz(v): only the first two columns change.
                let mut r = m;
                for row in 0..3 {
                    let (c0, c1) = (m[(row, 0)], m[(row, 1)]);
                    r[(row, 0)] = c0 * cs + c1 * sn;
                    r[(row, 1)] = c1 * cs - c0 * sn;
                }
                (r, mul3v(&pr, &b.pre_t) + pp)
            };
            if let Some((qr, qt)) = &b.post {
                t += mul3v(&r, qt);
                r = mul3(&r, qr);
            }
            rot[i] = r;
            pos[i] = t;
        }
        if GROUPS {
            for (g, c) in self.groups.iter().zip(s.group_c.iter_mut()) {
                *c = mul3v(&rot[g.body], &g.c) + pos[g.body];
            }
        }
    }

    /// World centre of link `l`'s bounding sphere, computed once per query.
    #[inline(always)]
    fn link_centre(&self, l: usize, s: &mut SphereScratch) -> Vector3<f64> {
        if s.link_posed[l] != s.stamp {
            s.link_posed[l] = s.stamp;
            let link = &self.links[l];
            s.link_c[l] = mul3v(&s.rot[link.body], &link.c) + s.pos[link.body];
        }
        s.link_c[l]
    }

    /// World centres of link `l`'s spheres, computed once per query.
    #[inline]
    fn pose_link(&self, l: usize, s: &mut SphereScratch) {
        if s.posed[l] == s.stamp {
            return;
        }
        s.posed[l] = s.stamp;
        let link = &self.links[l];
        let (r, t) = (s.rot[link.body], s.pos[link.body]);
        let (local, world) = (&self.centre[link.first..link.end], &mut s.centre[link.first..link.end]);
        for (w, c) in world.iter_mut().zip(local) {
            *w = mul3v(&r, c) + t;
        }
    }

    /// World centre of sphere `k` of link `l`, into `s.centre[k]` (the link is not marked posed).
    #[inline(always)]
    fn pose_sphere(&self, k: usize, l: usize, s: &mut SphereScratch) -> Vector3<f64> {
        let b = self.links[l].body;
        let c = mul3v(&s.rot[b], &self.centre[k]) + s.pos[b];
        s.centre[k] = c;
        c
    }

    /// Self-collision pair `p` alone, each sphere grown by its motion relative to the pair's
    /// common body when the joints move by at most `step`.
    pub(crate) fn pair_check(&self, q: &[f64], p: usize, step: &[f64], s: &mut SphereScratch) -> Check {
        self.pose_with::<false>(q, s);
        let (a, b) = self.self_pairs[p];
        let (a, b) = (a as usize, b as usize);
        self.pose_link(a, s);
        self.pose_link(b, s);
        let stop = self.pair_common[p] as usize;
        let (la, lb) = (&self.links[a], &self.links[b]);
        let mut near = false;
        for i in la.first..la.end {
            let ei = self.margin(i, stop, step, None, None);
            for j in lb.first..lb.end {
                let d2 = (s.centre[i] - s.centre[j]).norm_squared();
                let r = self.radius[i] + self.radius[j];
                if d2 <= r * r {
                    return Check::Hit;
                }
                let re = r + ei + self.margin(j, stop, step, None, None);
                near |= d2 <= re * re;
            }
        }
        if near { Check::Near } else { Check::Free }
    }

    /// Exact (`inflation` = `None`) or inflated query; see the module documentation.
    /// `q` has the right length.
    pub(crate) fn check(
        &self,
        q: &[f64],
        obstacles: &[ObstacleGeom],
        solids: &[Solid],
        inflation: Option<Inflation<'_>>,
        s: &mut SphereScratch,
    ) -> Check {
        match inflation {
            Some(_) => self.check_impl::<true, false>(q, obstacles, solids, inflation, false, s),
            None => self.check_impl::<false, false>(q, obstacles, solids, None, false, s),
        }
    }

    /// An inflated query of the motion certificate that lists what it finds near (see
    /// [`Item`]) at the end of `s.items`; what it tests is `scope`'s. The answer is
    /// [`Self::check`]'s, but for things certified free over a larger sub-interval, which stay
    /// free even where the smaller one's bounds would not say so.
    pub(crate) fn check_listed(
        &self,
        q: &[f64],
        obstacles: &[ObstacleGeom],
        solids: &[Solid],
        inflation: Inflation<'_>,
        scope: Scope,
        s: &mut SphereScratch,
    ) -> Check {
        match scope {
            Scope::Everything => self.check_impl::<true, true>(q, obstacles, solids, Some(inflation), false, s),
            Scope::Obstacles => self.check_impl::<true, true>(q, obstacles, solids, Some(inflation), true, s),
            Scope::Items(range) => self.check_items(q, obstacles, solids, inflation, range, s),
        }
    }

    /// [`Self::check_listed`] of the items `range` of `s.items` alone.
    fn check_items(
        &self,
        q: &[f64],
        obstacles: &[ObstacleGeom],
        solids: &[Solid],
        inf: Inflation<'_>,
        range: std::ops::Range<usize>,
        s: &mut SphereScratch,
    ) -> Check {
        self.pose_with::<false>(q, s);
        s.reach = 1.0;
        let mut near = false;
        for n in range {
            let item = s.items[n];
            match item {
                Item::Fixed => {
                    near = true;
                    s.reach = 0.0;
                }
                Item::Obstacle { k, l, o } => {
                    let (k, l, o) = (k as usize, l as usize, o as usize);
                    let p = self.pose_sphere(k, l, s);
                    let r = self.radius[k];
                    match dist2(&solids[o], &p) {
                        Some(d2) => {
                            if d2 <= r * r {
                                return Check::Hit;
                            }
                            let rel = r + inf.link[l];
                            if d2 > rel * rel {
                                continue;
                            }
                            let m = self.margin(k, 0, inf.step, Some(s), Some(inf.dir));
                            let re = r + m;
                            if d2 > re * re {
                                continue;
                            }
                            note_gap(&mut s.reach, d2.sqrt() - r, m);
                        }
                        None => {
                            let sep =
                                narrow::separation(&View::Sphere { c: Point3::from(p), r }, &obstacles[o].world.view());
                            if sep.distance <= 0.0 {
                                return Check::Hit;
                            }
                            let m = self.margin(k, 0, inf.step, Some(s), Some(inf.dir));
                            if sep.distance > m {
                                continue;
                            }
                            note_gap(&mut s.reach, sep.distance, m);
                        }
                    }
                    near = true;
                }
                Item::Pair { i, j, p, li, lj } => {
                    let (i, j, p) = (i as usize, j as usize, p as usize);
                    let d2 = (self.pose_sphere(i, li as usize, s) - self.pose_sphere(j, lj as usize, s)).norm_squared();
                    let r = self.radius[i] + self.radius[j];
                    if d2 <= r * r {
                        return Check::Hit;
                    }
                    let grown = r + inf.pair[p];
                    if d2 > grown * grown {
                        continue;
                    }
                    let m = self.pair_margin(i, j, self.pair_common[p] as usize, inf.step, Some(inf.dir), s);
                    let re = r + m;
                    if d2 > re * re {
                        continue;
                    }
                    note_gap(&mut s.reach, d2.sqrt() - r, m);
                    near = true;
                }
            }
            s.items.push(item);
        }
        if near { Check::Near } else { Check::Free }
    }

    /// [`Self::check`], compiled separately for exact queries (`GROW` = false), and for the
    /// inflated ones that list every near item rather than stop growing at the first
    /// (`COLLECT`, see [`Self::check_listed`]).
    #[inline]
    fn check_impl<const GROW: bool, const COLLECT: bool>(
        &self,
        q: &[f64],
        obstacles: &[ObstacleGeom],
        solids: &[Solid],
        inflation: Option<Inflation<'_>>,
        pairs_free: bool,
        s: &mut SphereScratch,
    ) -> Check {
        self.pose(q, s);
        // Once some grown shapes touch, the answer is at least `Near`: from then on only an
        // exact contact matters, so the rest of the query runs without margins.
        let mut inf = if GROW { inflation } else { None };
        let mut near = false;
        if COLLECT {
            s.reach = 1.0;
        }
        match self.fixed {
            Check::Hit => return Check::Hit,
            Check::Near if inf.is_some() => {
                near = true;
                if COLLECT {
                    s.reach = 0.0;
                    s.items.push(Item::Fixed);
                } else {
                    inf = None;
                }
            }
            _ => {}
        }
        // The largest link margin of each group.
        if let Some(i) = inf {
            for (g, e) in self.groups.iter().zip(s.group_e.iter_mut()) {
                *e = self.group_links[g.first..g.end].iter().map(|&l| i.link[l as usize]).fold(0.0, f64::max);
            }
        }
        // The box around every (grown) group sphere: obstacles outside it are skipped whole.
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for (k, (g, c)) in self.groups.iter().zip(&s.group_c).enumerate() {
            let r = g.r + if inf.is_some() { s.group_e[k] } else { 0.0 };
            for d in 0..3 {
                // Comparisons, not `f64::min`: no NaN handling on the hot path (a NaN centre
                // leaves the box as it is, as `min` would).
                let (l, h) = (c[d] - r, c[d] + r);
                if l < lo[d] {
                    lo[d] = l;
                }
                if h > hi[d] {
                    hi[d] = h;
                }
            }
        }
        for (oi, (o, solid)) in obstacles.iter().zip(solids).enumerate() {
            // One branch for the six comparisons (`|`, not `||`): which of them decides is
            // unpredictable, whether the obstacle is skipped much less so.
            let outside = (o.lo.x > hi[0])
                | (o.hi.x < lo[0])
                | (o.lo.y > hi[1])
                | (o.hi.y < lo[1])
                | (o.lo.z > hi[2])
                | (o.hi.z < lo[2]);
            if outside {
                continue;
            }
            let n_groups = self.groups.len();
            for k in 0..n_groups {
                // The plain query tests the bodies farthest down the chain first: they meet
                // obstacles most often, so a contact ends the query sooner (the answer is the
                // same in any order; the inflated one keeps the order its lists follow).
                let gi = if GROW { k } else { n_groups - 1 - k };
                let g = &self.groups[gi];
                let eg = if inf.is_some() { s.group_e[gi] } else { 0.0 };
                if !may_touch(solid, o, &s.group_c[gi], g.r + eg) {
                    continue;
                }
                for gl in g.first..g.end {
                    let l = self.group_links[gl] as usize;
                    let link = &self.links[l];
                    let el = inf.map_or(0.0, |i| i.link[l]);
                    let c = self.link_centre(l, s);
                    if !may_touch(solid, o, &c, link.r + el) {
                        continue;
                    }
                    self.pose_link(l, s);
                    // The link's midpoint margin, once a sphere needs more than the static one
                    // (infinite: not computed yet; an `Option` here cost 0.8% of planning).
                    let mut ml = f64::INFINITY;
                    for k in link.first..link.end {
                        let p = &s.centre[k];
                        let r = self.radius[k];
                        let item = Item::Obstacle { k: k as u32, l: l as u32, o: oi as u32 };
                        // The obstacle's box first (it holds the obstacle): cheaper than the
                        // exact distance to a turned box or cylinder, and most spheres miss it.
                        let rel = r + el;
                        if aabb_d2(o, [p.x, p.y, p.z]) > rel * rel {
                            continue;
                        }
                        match dist2(solid, p) {
                            Some(d2) => {
                                if d2 <= r * r {
                                    return Check::Hit;
                                }
                                if let Some(i) = inf {
                                    // The link's margin bounds the sphere's: test the tight one
                                    // only when the loose one touches.
                                    let rel = r + el;
                                    if d2 <= rel * rel {
                                        if ml == f64::INFINITY {
                                            ml = self.link_margin(l, i.step, s);
                                        }
                                        let rl = r + ml;
                                        if d2 > rl * rl {
                                            continue;
                                        }
                                        let m = self.margin(k, 0, i.step, Some(s), Some(i.dir));
                                        let re = r + m;
                                        if d2 <= re * re {
                                            near = true;
                                            if COLLECT {
                                                note_gap(&mut s.reach, d2.sqrt() - r, m);
                                                s.items.push(item);
                                            } else {
                                                inf = None;
                                            }
                                        }
                                    }
                                }
                            }
                            None => {
                                let sep = narrow::separation(&View::Sphere { c: Point3::from(*p), r }, &o.world.view());
                                if sep.distance <= 0.0 {
                                    return Check::Hit;
                                }
                                if let Some(i) = inf {
                                    let m = self.margin(k, 0, i.step, Some(s), Some(i.dir));
                                    if sep.distance <= m {
                                        near = true;
                                        if COLLECT {
                                            note_gap(&mut s.reach, sep.distance, m);
                                            s.items.push(item);
                                        } else {
                                            inf = None;
                                        }
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
        if !pairs_free && self.self_pass::<GROW, COLLECT>(q, &mut inf, &mut near, s) {
            return Check::Hit;
        }
        if near { Check::Near } else { Check::Free }
    }

    /// The self-collision part of [`Self::check_impl`]: true on an exact contact; sets `near`
    /// (and drops `inf`) when only grown spheres touch.
    ///
    /// Nothing is posed in the world here: the inner group's centre is taken into the outer
    /// body's frame, where each outer sphere is tested against it as stored; the few that reach
    /// it are taken into the inner body's frame, where the inner links' bounding spheres and
    /// spheres are tested as stored.
    #[inline(never)]
    fn self_pass<const GROW: bool, const COLLECT: bool>(
        &self,
        q: &[f64],
        inf: &mut Option<Inflation<'_>>,
        near: &mut bool,
        s: &mut SphereScratch,
    ) -> bool {
        if !GROW {
            *inf = None;
        }
        // (Group pairs within one group were answered at construction: `outer != inner`.)
        for (k, gp) in self.group_pairs.iter().enumerate() {
            let eg = if GROW {
                inf.map_or(0.0, |i| {
                    self.run_pairs[gp.pairs.clone()].iter().map(|rp| i.pair[rp.pair as usize]).fold(0.0, f64::max)
                })
            } else {
                0.0
            };
            let c_inner = s.group_c[gp.inner];
            let rr = if GROW { gp.rr + eg } else { gp.rr };
            if (s.group_c[gp.outer] - c_inner).norm_squared() > rr * rr {
                continue;
            }
            // The group pair's relative joints in a cell proven free (exact queries), or all
            // their values over the sub-interval in cells proven free (inflated ones).
            if let Some(Some(table)) = self.tables.get(k) {
                let proven = match *inf {
                    Some(i) if GROW => table.proves_box(q, i.step),
                    _ => table.proves(q),
                };
                if proven {
                    continue;
                }
            }
            // Any sphere that can touch (grown) a sphere of an inner link reaches this far from
            // the inner group's centre: the group sphere holds every inner sphere.
            let r_inner = if GROW { gp.r_inner + eg } else { gp.r_inner };
            let (rot_o, pos_o) = (s.rot[gp.body_o], s.pos[gp.body_o]);
            let g = mul3tv(&rot_o, &(c_inner - pos_o));
            for run in &self.runs[gp.runs.clone()] {
                let reach = run.r + r_inner;
                if (run.c - g).norm_squared() > reach * reach {
                    continue;
                }
                for (n, bi) in self.balls[run.first..run.end].iter().enumerate() {
                    let (dx, dy, dz) = (bi[0] - g.x, bi[1] - g.y, bi[2] - g.z);
                    let reach = bi[3] + r_inner;
                    if dx * dx + dy * dy + dz * dz > reach * reach {
                        continue;
                    }
                    // Sphere `i` in the inner body's frame.
                    let (i, ri) = (run.first + n, bi[3]);
                    let ci = Vector3::new(bi[0], bi[1], bi[2]);
                    let (rot_i, pos_i) = (s.rot[gp.body_i], s.pos[gp.body_i]);
                    let u = mul3tv(&rot_i, &(mul3v(&rot_o, &ci) + pos_o - pos_i));
                    for rp in &self.run_pairs[run.pairs.clone()] {
                        // Link b's bounding sphere holds all its spheres, and `ep` bounds the
                        // growth of any two spheres of the pair.
                        let ep = if GROW { inf.map_or(0.0, |i| i.pair[rp.pair as usize]) } else { 0.0 };
                        let reach = if GROW { ri + rp.r + ep } else { ri + rp.r };
                        if (rp.c - u).norm_squared() > reach * reach {
                            continue;
                        }
                        let first = rp.first as usize;
                        for (m, bj) in self.balls[first..rp.end as usize].iter().enumerate() {
                            let (dx, dy, dz) = (bj[0] - u.x, bj[1] - u.y, bj[2] - u.z);
                            let d2 = dx * dx + dy * dy + dz * dz;
                            let r = ri + bj[3];
                            if d2 <= r * r {
                                return true;
                            }
                            if GROW && let Some(inf_now) = *inf {
                                let grown = r + ep;
                                if d2 <= grown * grown {
                                    let p = rp.pair as usize;
                                    let item = Item::Pair {
                                        i: i as u32,
                                        j: (first + m) as u32,
                                        p: p as u32,
                                        li: run.outer as u32,
                                        lj: rp.link,
                                    };
                                    self.pose_link(run.outer, s);
                                    self.pose_link(rp.link as usize, s);
                                    let stop = self.pair_common[p] as usize;
                                    let pm = self.pair_margin(i, first + m, stop, inf_now.step, Some(inf_now.dir), s);
                                    let re = r + pm;
                                    if d2 <= re * re {
                                        *near = true;
                                        if COLLECT {
                                            note_gap(&mut s.reach, d2.sqrt() - r, pm);
                                            s.items.push(item);
                                        } else {
                                            *inf = None;
                                        }
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::{mul3, signed_permutation, sin_cos, split_about_z};
    use nalgebra::{Matrix3, Rotation3, Vector3};

    #[test]
    fn signed_permutations_are_found_exactly_and_multiply_like_mul3() {
        let p = Matrix3::new(0.0, -1.0, 0.0, 0.0, 0.0, 1.0, -1.0, 0.0, 0.0);
        assert_eq!(signed_permutation(&p), Some(([2, 0, 1], [-1.0, -1.0, 1.0])));
        assert_eq!(signed_permutation(&Matrix3::identity()), Some(([0, 1, 2], [1.0; 3])));
        // 1.570796325 rad, as in the UR5's URDF: nearly, not exactly, a permutation.
        let almost = *Rotation3::from_axis_angle(&Vector3::y_axis(), 1.570_796_325).matrix();
        assert_eq!(signed_permutation(&almost), None);
        assert_eq!(signed_permutation(&(p * 2.0)), None);
        assert_eq!(signed_permutation(&Matrix3::new(1.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)), None);
        let a = *Rotation3::from_euler_angles(0.3, -1.2, 2.5).matrix();
        let (perm, sign) = signed_permutation(&p).unwrap();
        let by_columns = Matrix3::from_columns(&[
            a.column(perm[0]) * sign[0],
            a.column(perm[1]) * sign[1],
            a.column(perm[2]) * sign[2],
        ]);
        assert_eq!(by_columns, mul3(&a, &p));
    }

    #[test]
    fn a_turn_about_the_axis_splits_off_exactly_and_nothing_else_does() {
        // The UR5's shoulder lift: Ry(1.570796325) about the joint's own axis, in turned frames.
        for (k, g) in [(1usize, 1.570_796_325f64), (0, -0.4), (2, 2.9)] {
            let axis = Vector3::ith_axis(k);
            let m = *Rotation3::from_axis_angle(&axis, g).matrix();
            // Turned so that the axis is the frame's z: m * T with T e_z = axis.
            let t = super::frame_with_z(&axis.into_inner());
            let turned = m * t;
            let (p, got) = split_about_z(&turned).unwrap();
            assert!(signed_permutation(&p).is_some());
            assert!((p.determinant() - 1.0).abs() < 1e-15);
            let rz = *Rotation3::from_axis_angle(&Vector3::z_axis(), got).matrix();
            assert!((p * rz - turned).amax() < 1e-15, "{k} {g}: {}", (p * rz - turned).amax());
        }
        // A turn about another axis does not split.
        let tilt = *Rotation3::from_euler_angles(0.3, 0.0, 0.0).matrix();
        assert!(split_about_z(&tilt).is_none());
        assert!(split_about_z(Rotation3::from_euler_angles(0.0, 0.2, 1.0).matrix()).is_none());
    }

    fn ulps(a: f64, b: f64) -> f64 {
        let scale = a.abs().max(b.abs()).max(f64::MIN_POSITIVE);
        (a - b).abs() / (scale * f64::EPSILON)
    }

    #[test]
    fn sin_cos_matches_libm() {
        let mut worst: (f64, f64) = (0.0, 0.0);
        let mut check = |x: f64| {
            let (s, c) = sin_cos(x);
            let (s0, c0) = x.sin_cos();
            // Near a zero of sin or cos the result is judged against 1 (absolute error in ulps of 1).
            let es = ulps(s, s0).min((s - s0).abs() / f64::EPSILON);
            let ec = ulps(c, c0).min((c - c0).abs() / f64::EPSILON);
            assert!(
                es <= 2.0 && ec <= 2.0,
                "x = {x:e}: sin {s:e} vs {s0:e} ({es} ulp), cos {c:e} vs {c0:e} ({ec} ulp)"
            );
            worst = (worst.0.max(es), worst.1.max(ec));
        };
        for i in -200_000..=200_000 {
            check(i as f64 * 1e-4); // [-20, 20] rad, every 0.1 mrad
        }
        for &x in &[
            0.0,
            -0.0,
            1e-300,
            1e-8,
            std::f64::consts::FRAC_PI_4,
            std::f64::consts::FRAC_PI_2,
            std::f64::consts::PI,
            -std::f64::consts::PI,
            1000.123,
            -54321.5,
            1_048_575.9,
        ] {
            check(x);
        }
        let (s, c) = sin_cos(f64::NAN);
        assert!(s.is_nan() && c.is_nan());
        assert_eq!(sin_cos(3e7), 3e7f64.sin_cos());
        println!("largest difference from libm: sin {} ulp, cos {} ulp", worst.0, worst.1);
    }
}
