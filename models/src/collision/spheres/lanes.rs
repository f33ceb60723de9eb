//! Eight configurations at once in single precision, for the motion certificate's first pieces
//! and the planner's edge probes (`CollisionModel::any_collides_settled`): which of
//! them are *certainly free* when every sphere of link `l` is grown by a margin `m_l` against
//! obstacles and every self pair `p` by `m_p` (the inflated query of
//! [`super::SphereGeom::check`], with the link and pair margins only).
//!
//! After VAMP (Thomason, Kingston and Kavraki, "Motions in Microseconds via Vectorized
//! Sampling-Based Planning", ICRA 2024): one `f32` lane of eight per configuration (one AVX2
//! register where the CPU has it, two SSE registers on the x86-64 baseline: see `simd8`), the
//! forward kinematics as the robot's prepared program over the lanes (a signed permutation or
//! a matrix per body, the joint turning about the frame's z axis), group, link and sphere
//! bounding tests as lane masks, and an early end as soon as no lane can be free. The answer
//! is one-sided: a lane it calls free is free; any other lane is left to the double-precision
//! query, which also lists what is near (see [`super::Item`]). So the batch may only save work,
//! never change what the certificate proves.
//!
//! # Why single precision stays sound
//!
//! Let `u = 2^-24` (the unit roundoff of `f32`, round to nearest). A product the kernel adds
//! to a sum (`mul_add`) is fused into it, with one rounding, where the CPU has FMA3 (with AVX2),
//! and rounded before the addition on the baseline; elsewhere Rust never fuses. Each bound below
//! counts, for every term of a sum, the most roundings it goes through either way, so it holds
//! for both (a term of a sum of `n` products goes through at most `n` roundings). Joint values
//! are computed in `f64` (as the scalar query does), and their sines and cosines in `f32` from
//! the scalar kernel's reduced argument, with an error of at most [`SIN_COS_ERR`] `= 4u` each
//! (proven at [`sin_cos_f32`]).
//!
//! *Forward kinematics.* [`Lanes::new`] runs a running error bound through the robot's
//! program, once per robot, in `f64` (rounded up by a relative 10^-6 at the end). For a dot
//! product `Σ_{j≤n} x_j y_j` computed from `x̂`, `ŷ` with `|x̂_j - x_j| ≤ e_x`, `|ŷ_j - y_j| ≤
//! e_y`, `Σ|x_j| ≤ X1`, `Σ|y_j| ≤ Y1` and `Σ|x_j y_j| ≤ XY`, the computed value differs from
//! the true one by at most `e_x Y1 + e_y X1 + n e_x e_y + γ_n (XY + e_x Y1 + e_y X1 + n e_x
//! e_y)`, `γ_n = n u / (1 - n u)` (the perturbation expanded, plus recursive summation's bound:
//! Higham, *Accuracy and Stability of Numerical Algorithms*, 2nd ed., §3.1). Rotation entries
//! are at most 1 and every row and column is a unit vector (so `X1 ≤ √3` and `XY ≤ 1` for a
//! row against a column), sines and cosines at most 1 (`|m0 c| + |m1 s| ≤ 1`), a point's
//! coordinates at most the sum of the translations above it (`|base|` plus each `|pre_t|` and
//! `|post_t|`, and each prismatic joint's travel: its reach within its limits, at most
//! [`PRISMATIC_BOUND`]; see [`prismatic_travel`]). A point `r t + p` is one
//! sum of four terms, the origin's coordinate and three products, each of which goes through
//! at most four roundings: its error is the products' from their factors' errors, plus the
//! origin's, plus `γ_4` times the sum of the terms' magnitudes. Applied to every body's
//! rotation and origin and then to every sphere and bounding centre, this gives `e_c`, a bound
//! on the error of any coordinate of any centre the batch computes, whatever the joint values.
//! A rotation before a joint within `δ ≤` [`NEAR_PERMUTATION`] of a signed permutation (a
//! quarter turn written in decimals) is taken as that permutation, exactly; the bound adds its
//! `√3 δ` to the entries' error there.
//!
//! *Distances.* Each test asks whether a point `p` (a sphere's or bounding sphere's centre) is
//! farther than `R` (its radius plus the margin) from a solid, or two centres farther than `R`
//! apart. Its distance is the norm of a *gap vector* `a` of `k ≤ 3` components: a box's
//! `max(|l_i| - h_i, 0)` with `l = Rᵀ(p - t)`; a cylinder's `max(|(l_0, l_1)| - r, 0)` and
//! `max(|l_2| - h, 0)`; a ball's `max(|p - c| - r, 0)`; two centres' difference. Suppose the
//! true distance is at most `R`. Then every quantity in the formula is bounded: `|p - t| ≤
//! |h| + R` and so on, so each component is computed with an error of at most `η` (below), and
//! the computed sum of squares `s` is at most `(1 + γ_3)(R + √3 η)²`. The batch calls a lane
//! free only when `s` exceeds that threshold (computed in `f64` and rounded *up* to `f32`):
//! so the true distance exceeds `R`. With `T` the largest coordinate of an obstacle's centre,
//! `H` its largest size (half extent, radius, half height) and `R_max` the largest `R` of the
//! query, the component error is at most
//!
//! `η = 3 e_c + 32 u (T + H + R_max)`:
//!
//! for a box `l`'s components carry at most `√3` times the centre's error plus the rounding of
//! `p - t` (`u(|t| + |p - t|)` per coordinate), of the rotation's entries (`u` each) and of the
//! products and sums (`γ_3 |p - t|`), and the subtraction of `h` adds `u(2h + R)`: `√3 e_c +
//! 1.8 u T + 14 u H + 8 u R` in all. A cylinder's radial component takes the norm of two of
//! those (`√2 √3 e_c ≤ 2.5 e_c`) and a square root (`u(r + R)`); a ball's and a self pair's
//! fewer. The tests compare both exact question and computation on random and near-contact
//! configurations against the `f64` query, and check that a lane called free is free there.
//!
//! A lane whose prismatic joint travels more than the bound covers (outside the joint's limits,
//! or past [`PRISMATIC_BOUND`]), or whose configuration is not finite, is never called free (the
//! `f64` query answers).

use super::simd8::{self, F8, Isa, Kernel, L, Ops};
use super::{Check, SIN_COS_RANGE, Solid, SphereGeom};

/// Configurations per batch.
pub(crate) const LANES: usize = 8;

/// The largest prismatic joint travel (m) the error bound covers.
pub(crate) const PRISMATIC_BOUND: f64 = 16.0;

/// The largest entry-wise deviation of a rotation the batch takes for the signed permutation
/// nearest it. URDF files write quarter turns in decimals (`rpy="1.57079632679 0 0"` in the
/// Panda's, `1.5708` in many): the rotation is then `δ` off a permutation (`|cos 1.57079632679|
/// ≈ 5e-12`), and taking the permutation saves the batch a matrix product per body and its
/// error bound a factor of about √3 per body, for `√3 δ` per body (module documentation).
const NEAR_PERMUTATION: f64 = 1e-6;

/// The signed permutation the batch takes for body `b`'s rotation before its joint, with the
/// largest entry-wise deviation `δ` from it (0 when exact): see [`NEAR_PERMUTATION`].
fn lane_permutation(b: &super::Body) -> Option<([usize; 3], [f64; 3], f64)> {
    if let Some((perm, sign)) = b.pre_perm {
        return Some((perm, sign, 0.0));
    }
    let m = &b.pre_r;
    let (mut perm, mut sign) = ([0usize; 3], [0.0; 3]);
    for c in 0..3 {
        let r = (0..3).max_by(|&x, &y| m[(x, c)].abs().total_cmp(&m[(y, c)].abs()))?;
        perm[c] = r;
        sign[c] = if m[(r, c)] < 0.0 { -1.0 } else { 1.0 };
    }
    if perm[0] == perm[1] || perm[1] == perm[2] || perm[0] == perm[2] {
        return None;
    }
    let mut delta: f64 = 0.0;
    for c in 0..3 {
        for r in 0..3 {
            let p = if r == perm[c] { sign[c] } else { 0.0 };
            delta = delta.max((m[(r, c)] - p).abs());
        }
    }
    // `delta` is computed in `f64`: rounded up by a relative 2^-50 (well above its few roundings).
    (delta <= NEAR_PERMUTATION).then_some((perm, sign, delta * (1.0 + 1.0 / 1_125_899_906_842_624.0)))
}

/// The travel the error bound of a prismatic joint of this reach covers: the reach with a
/// relative 10^-9 to spare (a value computed at a limit may round past the reach computed from
/// it), at most [`PRISMATIC_BOUND`]. A joint of 0.4 m adds 0.4 m, not 16 m, to the coordinates'
/// bound, and so to every error term that scales with it.
fn prismatic_travel(reach: f64) -> f64 {
    if reach.is_finite() { (reach * (1.0 + 1e-9) + 1e-12).min(PRISMATIC_BOUND) } else { PRISMATIC_BOUND }
}

type F<O> = L<O>;
/// A point per lane (struct of arrays).
type P<O> = [F<O>; 3];
/// A rotation per lane, row-major.
type R<O> = [F<O>; 9];

const U: f64 = 1.0 / 16_777_216.0;

const fn gamma(n: f64) -> f64 {
    n * U / (1.0 - n * U)
}

/// The error bound of a dot product: see the module documentation.
fn dot_err(ex: f64, ey: f64, x1: f64, y1: f64, xy: f64, n: f64) -> f64 {
    let e = ex * y1 + ey * x1 + n * ex * ey;
    e + gamma(n) * (xy + e)
}

/// `x` rounded to the nearest `f32`.
#[inline(always)]
fn f(x: f64) -> f32 {
    x as f32
}

/// A matrix rounded to `f32`, row-major.
fn m9(m: &nalgebra::Matrix3<f64>) -> [f32; 9] {
    std::array::from_fn(|k| f(m[(k / 3, k % 3)]))
}

/// A vector rounded to `f32`.
#[inline(always)]
fn v3(v: &nalgebra::Vector3<f64>) -> [f32; 3] {
    [f(v.x), f(v.y), f(v.z)]
}

/// An `f32` at most `x`.
#[inline(always)]
fn down(x: f64) -> f32 {
    let y = x as f32;
    if (y as f64) > x { y.next_down() } else { y }
}

/// An `f32` at least `x` (for thresholds).
#[inline(always)]
fn up(x: f64) -> f32 {
    let y = x as f32;
    if (y as f64) < x { y.next_up() } else { y }
}

/// A column of a rotation: an index the compiler knows to be below 3 (read from memory as a
/// one-byte enum), so that `3 * row + column` needs no bounds check.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
enum Col {
    X = 0,
    Y = 1,
    Z = 2,
}

impl Col {
    fn of(k: usize) -> Col {
        match k {
            0 => Col::X,
            1 => Col::Y,
            _ => Col::Z,
        }
    }
}

#[derive(Debug, Clone)]
enum Pre {
    /// A signed permutation: column `c` of the product is `sign[c]` times the parent's column
    /// `perm[c]`.
    Perm([Col; 3], [f32; 3]),
    Mat([f32; 9]),
}

#[derive(Debug, Clone)]
struct Body {
    parent: usize,
    pre: Pre,
    pre_t: [f32; 3],
    prismatic: bool,
    /// Prismatic joints: the largest travel `|v|` the error bound covers (the joint's reach
    /// within its limits, at most [`PRISMATIC_BOUND`]); a lane past it is left to the `f64` query.
    travel: f64,
    axis: [f32; 3],
    post: Option<([f32; 9], [f32; 3])>,
    /// A revolute joint right after the parent's frame: no permutation, no sign, nothing after.
    plain: bool,
    /// The one coordinate of `pre_t` that is not zero, if only one is.
    t_axis: Option<usize>,
    /// The joint's angle is its value as it is (scale 1, nothing added): read, not computed.
    value_is_angle: bool,
}

/// A sphere robot's program and geometry in single precision, with its error bound.
#[derive(Debug, Clone)]
pub(crate) struct Lanes {
    base_r: [f32; 9],
    base_t: [f32; 3],
    /// Bodies 1.. (body 0 is the base).
    bodies: Vec<Body>,
    /// Sphere centres in their body frames.
    balls: Vec<[f32; 3]>,
    /// Per link: bounding centre (body frame).
    links: Vec<[f32; 3]>,
    /// Per group: bounding centre.
    groups: Vec<[f32; 3]>,
    /// Sphere radii and link bounding radii, rounded up.
    radius_up: Vec<f32>,
    link_r_up: Vec<f32>,
    /// The self pairs between bodies: (pair, outer link, inner link), grouped by group pair.
    pairs: Vec<[u32; 3]>,
    /// Per group pair, its range of `pairs`.
    pair_ranges: Vec<std::ops::Range<usize>>,
    /// The runs of `pairs` that share their outer link: (outer link, first pair, one past the
    /// last), and per group pair its range of them.
    runs: Vec<[u32; 3]>,
    run_ranges: Vec<std::ops::Range<usize>>,
    /// Per group, its bounding radius rounded up.
    group_r_up: Vec<f32>,
    /// Bound on the error of any coordinate of any centre the batch computes (m).
    pub(crate) centre_err: f64,
    /// The largest group bounding radius (m).
    max_group_r: f64,
    /// `√3 ε` of [`LaneMotion`]; infinite when the robot gets no motion terms.
    twist_err: f64,
    /// This program's number: a scratch keeps thresholds derived from it under this number
    /// (see [`Grown`]).
    id: ProgramId,
}

/// A number unique in the process, given to each [`Lanes`] built (a clone carries the number
/// of what it copies: the same program).
/// Its `Debug` form is the same for all: a model's `Debug` form keys the cache of the
/// self-collision cell tables (see `table`), and equal models must meet there.
#[derive(Clone, Copy, PartialEq, Eq)]
struct ProgramId(u64);

impl ProgramId {
    fn next() -> ProgramId {
        static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
        ProgramId(NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed))
    }
}

impl std::fmt::Debug for ProgramId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("ProgramId")
    }
}

/// Obstacles in single precision, and what their rounding adds to the error bound.
#[derive(Debug, Clone)]
pub(crate) struct Solids32 {
    solids: Vec<Solid32>,
    /// Per solid, a sphere holding it (tested before the solid itself): its centre in every
    /// lane, so that a batch's test reads it as it is (broadcast in the obstacle loop, three
    /// instructions a group and solid), and its radius.
    bound_c: Vec<[F8; 3]>,
    bound_r: Vec<f32>,
    /// This set's number: a scratch keeps thresholds derived from it under this number (see
    /// [`Grown`]; a clone carries the number of what it copies).
    id: ProgramId,
    /// The largest obstacle coordinate and size (`T + H` of the module documentation).
    scale: f64,
    /// How far the spheres of the robot's world-fixed body (the links no joint moves) are from
    /// every obstacle beyond their radii, in double precision (see
    /// [`Solids32::set_fixed_clearance`]); minus infinity until it is worked out.
    pub(crate) fixed_clear: f64,
}

#[derive(Debug, Clone)]
enum Solid32 {
    Ball {
        c: [f32; 3],
        r: f32,
    },
    /// `yaw`: the rotation turns about z only (see [`is_yaw`]).
    Cuboid {
        rt: [f32; 9],
        t: [f32; 3],
        half: [f32; 3],
        yaw: bool,
    },
    Cylinder {
        rt: [f32; 9],
        t: [f32; 3],
        r: f32,
        hh: f32,
        yaw: bool,
    },
}

impl Solids32 {
    /// The obstacles, or `None` when one has no closed form here (capsules, meshes).
    pub(crate) fn new(solids: &[Solid]) -> Option<Solids32> {
        let mut scale: f64 = 0.0;
        let mut bound = Vec::with_capacity(solids.len());
        let out = solids
            .iter()
            .map(|s| {
                Some(match s {
                    Solid::Ball { c, r } => {
                        scale = scale.max(c.amax() + r);
                        bound.push((v3(c), up(*r)));
                        Solid32::Ball { c: v3(c), r: f(*r) }
                    }
                    Solid::Cuboid { rt, t, half } => {
                        scale = scale.max(t.amax() + half.amax());
                        bound.push((v3(t), up(half.norm() * (1.0 + 1e-12))));
                        Solid32::Cuboid { rt: m9(rt), t: v3(t), half: v3(half), yaw: is_yaw(&m9(rt)) }
                    }
                    Solid::Cylinder { rt, t, r, hh } => {
                        scale = scale.max(t.amax() + r.max(*hh));
                        bound.push((v3(t), up(r.hypot(*hh) * (1.0 + 1e-12))));
                        Solid32::Cylinder { rt: m9(rt), t: v3(t), r: f(*r), hh: f(*hh), yaw: is_yaw(&m9(rt)) }
                    }
                    Solid::Capsule { .. } | Solid::Other => return None,
                })
            })
            .collect::<Option<Vec<_>>>()?;
        // The largest first: a batch that ends in a contact most often meets a large solid, and
        // ends the sooner for meeting it first. The order changes no conclusion (see
        // `free_lanes`); on the generated MotionBenchMaker UR5 families it saved 1-4.5% of the
        // planning instructions, and 0.2% on the public ones.
        let mut both: Vec<(Solid32, ([f32; 3], f32))> = out.into_iter().zip(bound).collect();
        both.sort_by(|a, b| (b.1).1.total_cmp(&(a.1).1));
        let (out, bound): (Vec<Solid32>, Vec<([f32; 3], f32)>) = both.into_iter().unzip();
        let bound_c = bound.iter().map(|(c, _)| c.map(|v| F8([v; LANES]))).collect();
        let bound_r = bound.iter().map(|&(_, r)| r).collect();
        scale.is_finite().then_some(Solids32 {
            solids: out,
            bound_c,
            bound_r,
            scale,
            fixed_clear: f64::NEG_INFINITY,
            id: ProgramId::next(),
        })
    }

    /// Work out how far the spheres of `geom`'s world-fixed body are from `solids` (the
    /// obstacles these were made of), beyond their radii: plus infinity when the body has no
    /// sphere or there is no obstacle, minus infinity when a distance is not a number. A batch
    /// whose margins and allowance this clearance exceeds skips that body's obstacle tests
    /// (see `free_lanes`): they could settle nothing.
    pub(crate) fn set_fixed_clearance(&mut self, geom: &SphereGeom, solids: &[Solid]) {
        let mut clear = f64::INFINITY;
        for link in geom.links.iter().filter(|l| l.body == 0) {
            for k in link.first..link.end {
                let c = geom.base_r * geom.centre[k] + geom.base_t;
                for solid in solids {
                    let gap = match super::dist2(solid, &c) {
                        Some(d2) => d2.sqrt() - geom.radius[k],
                        None => f64::NEG_INFINITY,
                    };
                    // A gap that is not a number leaves minus infinity: never skipped.
                    clear = if gap.is_nan() { f64::NEG_INFINITY } else { clear.min(gap) };
                }
            }
        }
        self.fixed_clear = clear;
    }
}

/// What a batch grows the spheres by: each sphere of link `l` by `link[l]` against obstacles,
/// self pair `p` by `pair[p]`; the self-collision tables may prove a group pair over
/// `q ± step` (as the inflated query; `None`: no tables).
#[derive(Debug, Clone, Copy)]
pub(crate) struct LaneMargins<'a> {
    /// Per link; not read when `uniform`.
    pub link: &'a [f64],
    /// Per self pair; not read when `uniform`.
    pub pair: &'a [f64],
    /// Every link and pair margin is this one (the plain checks of a planner: 0).
    pub uniform: Option<f64>,
    pub step: Option<&'a [f64]>,
    /// Test the self pairs of the lanes already near an obstacle too (unless every lane is),
    /// and say which lanes' pairs are free ([`Lanes8::pairs_free`]): the certificate's next
    /// level of batches and its double-precision check of a piece then skip its self pairs.
    pub pairs_of_near: bool,
    /// Every lane is the midpoint of a piece of one straight motion, whose terms the scratch
    /// holds ([`SphereGeom::set_lane_motion`]): a sphere near an obstacle
    /// with its link's margin is tested again with its own margin along the motion (see
    /// [`LaneMotion`]).
    pub along: bool,
    /// Groups free in every lane without a test (bit `g` for group `g`): the caller knows the
    /// configuration the lanes move from is free and that no joint moves these groups' bodies
    /// ([`SphereGeom::still_groups`]), so each lane poses them as there. None of their spheres
    /// is tested against an obstacle, nor against another such group's. 0: every group is tested.
    pub still: u64,
    /// In a batch along a motion ([`Self::along`]): groups free of every obstacle over each
    /// lane's piece without a test (bit `g` for group `g`). A coarser piece holding each
    /// lane's found them so: its midpoint test with its (larger) margins covers all of it, so
    /// it covers every part. None of their spheres is tested against an obstacle; their self
    /// pairs are. 0 otherwise.
    pub settled: u64,
    /// In a batch along a motion: every lane's self pairs are free over its piece without a
    /// test (a coarser piece holding it found them free): none is tested, and with
    /// [`Self::pairs_of_near`] every lane's pairs are called free.
    pub pairs_settled: bool,
}

/// A straight motion's terms for the batches of its pieces (all of one length, see
/// [`LaneMargins::along`]).
///
/// Every lane is the midpoint `q(tm)` of a piece `q(tm) + s dir`, `|s| <= 1`. A sphere centre
/// `p` then moves by at most `|v| + S` over the piece (`spheres::arms`, "along the straight
/// motion"), where `v` is its velocity `dp/ds` at the midpoint and `S` the second-order term,
/// here with the static arms (valid at every pose, so one value per sphere for all pieces).
///
/// The batch computes `v` in each lane from the frames it posed, as a twist: every body's
/// angular velocity `ω = sum_j ḋ_j w_j` and the velocity `ν = sum_j ḋ_j (o_j × w_j)` of the
/// point at the world's origin moving with it, over the joints `j` up its chain (`w_j` the
/// axis, `o_j` a point on it, `ḋ_j` the joint's change over `dir`; a prismatic joint adds
/// `ḋ_j w_j` to `ν` only), so that `v = ν + ω × p`. In exact arithmetic this is
/// `sum_j ḋ_j w_j × (p - o_j)`, the velocity `spheres::arms` sums.
///
/// *Rounding.* Let `e_R`, `e_o` and `e_c` bound the errors of the batch's rotation entries,
/// body origins and centres, `M` every origin's and centre's coordinates (plus one), `n` the
/// bodies and `D = sum_j |ḋ_j|` over the sphere's chain. Each term's cross product errs by at
/// most `2 (e_R M + e_o)` or `2 (e_R M + e_c)` per coordinate from its inputs (two products of
/// entries at most 1 and coordinates at most `M`), rounding `ḋ_j` to `f32` by `u |ḋ_j| 2M`,
/// and the products, the cross products' differences and the sums of at most `n + 2` terms of
/// magnitude at most `|ḋ_j| 2M` (then `ω × p`, whose `ω` already carries the sums' error) add
/// at most `γ_{n+4} D 4M`. Summed, every coordinate of the computed `v̂` is within
/// `D (4 e_R M + 2 e_o + 2 e_c + (4n + 20) u M)` of `v`'s, half of `D ε` with
/// `ε = 8 e_R M + 4 (e_o + e_c) + 8 (n + 4) u M`, and
/// `|v| ≤ |v̂| + √3 D ε`; the computed norm `n̂` (a sum of three squares and a square root)
/// has `|v̂| ≤ (1 + 4u) n̂`. The margin is taken as `n̂ K + A` in `f32` with
/// `K = 1 + 2^-16` and `A` at least `(1 + 2^-20)(S + √3 D ε + √3 η)` rounded up (`√3 η` the
/// distance test's allowance, as in every margin of the batch): the two roundings lose at
/// most a factor `(1 - u)²` of `n̂ K` and `(1 - u)` of `A`, which `K` and `2^-20` cover. The
/// threshold is then formed as [`thr`]'s. Robots with a body posed after its joint (`post`)
/// get no motion terms (their joint's frame is not stored).
#[derive(Debug, Clone)]
pub(crate) struct LaneMotion {
    /// Terms are held (for the motion numbered `seg`), of the robot program with this number.
    ready: Option<ProgramId>,
    /// The motion's number, counted from 1; a sphere's `A` is worked out in the first batch
    /// that needs it, and kept for the motion's other batches.
    seg: u32,
    /// The allowance's bits the `A`s kept hold.
    grow: u64,
    /// Per moving body (body `k + 1` at `k`), its joint's change over `dir`.
    speed: Vec<f32>,
    /// Per body, the factors of the second-order term and the steps of the joints at and above
    /// it (`SphereGeom::second_factors`).
    factor: Vec<f64>,
    above: Vec<f64>,
    /// Per sphere, `A` above, for the motion `add_at`.
    add: Vec<f32>,
    add_at: Vec<u32>,
}

impl LaneMotion {
    /// A new number: every sphere's `A` kept is worked out again when next needed.
    fn renumber(&mut self) {
        self.seg = self.seg.wrapping_add(1);
        if self.seg == 0 {
            self.add_at.fill(0);
            self.seg = 1;
        }
    }
}

/// `K` of [`LaneMotion`].
const ALONG_K: f32 = 1.0 + 1.0 / 65_536.0;

/// The thresholds a batch derives from a uniform margin (the planner's probes), kept in the
/// scratch for the next batch with the same robot, margin and obstacle scale (kept, with the
/// point-cell flag worked out only where a table is read: planning instructions on 40
/// MotionBenchMaker cage problems 758.9 M -> 749.9 M, on 90 public ones 76.7 M -> 76.1 M).
#[derive(Debug, Clone)]
struct Grown {
    /// What they were derived from: the robot's [`Lanes::id`], the margin's bits and the
    /// obstacles' [`Solids32::id`]; `None` when nothing is kept.
    key: Option<(ProgramId, u64, ProgramId)>,
    /// The rounding allowance `√3 η` of the module documentation.
    grow: f64,
    /// The margin plus the allowance, rounded up: every link's and every self pair's.
    margin: f32,
    /// Per group, its radius plus the margin and the allowance, rounded up.
    group: Vec<f32>,
    /// Per group pair, the threshold of its two group spheres.
    group_pair: Vec<f32>,
    /// Per group and solid (the solids of a group in a row), the threshold of the group's
    /// sphere against the solid's bounding sphere: worked out in the obstacle loop of every
    /// batch, four operations of each of its tests (public MotionBenchMaker planning spends
    /// most of its obstacle tests there).
    solid: Vec<f32>,
}

/// The answer of a batch: bit `i` for lane `i`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Lanes8 {
    /// Lanes certainly free (inflated).
    pub free: u32,
    /// Lanes certainly in contact (exact); when not empty, the batch stopped there and `free`
    /// is empty.
    pub hit: u32,
    /// With [`LaneMargins::pairs_of_near`], the lanes whose self pairs are certainly free
    /// (inflated), near an obstacle or not; otherwise empty.
    pub pairs_free: u32,
}

impl Lanes8 {
    /// Nothing settled, nothing in contact.
    const NONE: Lanes8 = Lanes8 { free: 0, hit: 0, pairs_free: 0 };

    /// The lanes `hit` certainly in contact.
    const fn hit(hit: u32) -> Lanes8 {
        Lanes8 { hit, ..Lanes8::NONE }
    }
}

/// Where a batch's [`LANES`] configurations are.
#[derive(Debug, Clone, Copy)]
pub(crate) enum LaneInput<'a> {
    /// One after another, `dof` values each.
    Rows(&'a [f64]),
    /// Points of a segment ([`SegmentIn`]).
    Segment(SegmentIn<'a>),
}

/// A batch's configurations as the kernel reads them (one kernel compiled for each kind, so
/// that neither pays for the other's branches).
trait Source: Copy {
    /// The lanes are configurations scattered over the joint space (rows a caller gives), not
    /// points of one motion: their self pairs go in the scalar query's order (see
    /// `free_lanes_in`).
    const SCATTERED: bool;
    /// Writes value `j` of every lane over `cols[j]` (sized here); `false` (the batch gives up)
    /// unless the configurations hold `dof` values each.
    fn columns(&self, dof: usize, cols: &mut Vec<[f64; LANES]>) -> bool;
}

#[derive(Debug, Clone, Copy)]
struct RowsIn<'a>(&'a [f64]);

impl Source for RowsIn<'_> {
    const SCATTERED: bool = true;
    #[inline(always)]
    fn columns(&self, dof: usize, cols: &mut Vec<[f64; LANES]>) -> bool {
        // For the common arm sizes one unrolled pass over rows of known length (reading each
        // body's value from the rows cost about 40 instructions a body).
        match dof {
            6 => transpose::<6>(self.0, cols),
            7 => transpose::<7>(self.0, cols),
            8 => transpose::<8>(self.0, cols),
            _ => transpose_any(self.0, dof, cols),
        }
    }
}

/// Points of a segment from `a` by the joint steps `delta` cut into `n` steps: lane `i` holds
/// `a + (ids[i] / n) delta` (each value as `ConfigSpace::step_into` computes it), except lane
/// 0, which holds `end` when it is given. Worked out joint by joint in the batch's vector
/// registers: no rows to build and turn.
#[derive(Debug, Clone, Copy)]
pub(crate) struct SegmentIn<'a> {
    pub a: &'a [f64],
    pub delta: &'a [f64],
    pub n: u32,
    pub ids: [u32; LANES],
    pub end: Option<&'a [f64]>,
}

impl Source for SegmentIn<'_> {
    const SCATTERED: bool = false;
    /// Joint by joint in the registers, the end over lane 0: about 50 instructions for six
    /// joints (rows built outside the batch took about 160 here to turn, besides building them).
    #[inline(always)]
    fn columns(&self, dof: usize, cols: &mut Vec<[f64; LANES]>) -> bool {
        let SegmentIn { a, delta, n, ids, end } = *self;
        if dof == 0 || a.len() != dof || delta.len() != dof || end.is_some_and(|e| e.len() != dof) {
            return false;
        }
        // The very quotients and sums of `ConfigSpace::step_into` (exact division).
        let t = ids.map(|i| i as f64 / n as f64);
        // For the common arm sizes, loops of known length (unrolled): about 100 instructions
        // a probe less on a six-joint arm than the loop over `dof`.
        match dof {
            6 => segment_columns::<6>(a, delta, end, &t, cols),
            7 => segment_columns::<7>(a, delta, end, &t, cols),
            8 => segment_columns::<8>(a, delta, end, &t, cols),
            _ => {
                if cols.len() != dof {
                    cols.resize(dof, [0.0; LANES]);
                }
                // Four joints at a time, each as the unrolled sizes' (a lane per point in the
                // vector registers), then the rest one by one: a loop over single joints left
                // each lane to a scalar multiply and add (26 instructions a joint on Baxter's
                // fourteen, against 8).
                let (chunks, rest) = cols.as_chunks_mut::<4>();
                let (a4, a_rest) = a.as_chunks::<4>();
                let (d4, d_rest) = delta.as_chunks::<4>();
                for ((c, aj), dj) in chunks.iter_mut().zip(a4).zip(d4) {
                    for j in 0..4 {
                        c[j] = t.map(|t| aj[j] + t * dj[j]);
                    }
                }
                for ((col, &aj), &dj) in rest.iter_mut().zip(a_rest).zip(d_rest) {
                    *col = t.map(|t| aj + t * dj);
                }
                if let Some(e) = end {
                    for (col, &v) in cols.iter_mut().zip(e) {
                        col[0] = v;
                    }
                }
                true
            }
        }
    }
}

/// [`SegmentIn::columns`] for `D` joints: lane `i` of joint `j` is `a[j] + t[i] delta[j]`, the
/// end over lane 0. `false` unless `a`, `delta` and `end` hold `D` values.
#[inline(always)]
fn segment_columns<const D: usize>(
    a: &[f64],
    delta: &[f64],
    end: Option<&[f64]>,
    t: &[f64; LANES],
    cols: &mut Vec<[f64; LANES]>,
) -> bool {
    let (Ok(a), Ok(delta)) = (<&[f64; D]>::try_from(a), <&[f64; D]>::try_from(delta)) else { return false };
    if cols.len() != D {
        cols.resize(D, [0.0; LANES]);
    }
    let Ok(cols) = <&mut [[f64; LANES]; D]>::try_from(&mut cols[..]) else { return false };
    for j in 0..D {
        cols[j] = t.map(|t| a[j] + t * delta[j]);
    }
    if let Some(e) = end {
        let Ok(e) = <&[f64; D]>::try_from(e) else { return false };
        for j in 0..D {
            cols[j][0] = e[j];
        }
    }
    true
}

/// Working memory of the single-precision batch.
#[derive(Debug, Clone)]
pub(crate) struct LaneScratch {
    rot: Vec<[F8; 9]>,
    pos: Vec<[F8; 3]>,
    group_c: Vec<[F8; 3]>,
    link_c: Vec<[F8; 3]>,
    /// Per link, the batch ([`Self::batch`]) whose bounding-sphere centre `link_c` holds.
    link_posed: Vec<u32>,
    centre: Vec<[F8; 3]>,
    /// Per link, the batch whose sphere centres `centre` holds.
    posed: Vec<u32>,
    /// Per sphere of a self-pair run's outer link, the lanes where it reaches the inner group's
    /// sphere (scattered batches).
    reach: Vec<u32>,
    /// Per moving body (body `k + 1` at `k`), the sine and cosine of its joint's angle in each
    /// lane (a prismatic joint's travel in `sin`).
    sin: Vec<F8>,
    cos: Vec<F8>,
    /// Per degree of freedom, its values in the lanes (see `transpose`).
    cols: Vec<[f64; LANES]>,
    /// The batch now posed, counted from 1: the marks above need no clearing per batch (a
    /// clear and fill went through two `memset` calls a batch, and their `vzeroupper`s in the
    /// AVX2 kernel).
    batch: u32,
    /// Per link, its margin plus the rounding allowance, rounded up, for a batch whose
    /// margins are not uniform (derived anew in each).
    link_g: Vec<f32>,
    /// The thresholds of the last uniform margin.
    grown: Grown,
    /// Per solid, a group's threshold against its bounding sphere, for a batch whose margins
    /// are not uniform (derived anew for each group).
    solid_t: Vec<f32>,
    /// The straight motion of the batches with [`LaneMargins::along`].
    motion: LaneMotion,
    /// Per body, its twist `ω`, `ν` (see [`LaneMotion`]) in the batch `twisted` (marked as
    /// `posed`).
    omega: Vec<[F8; 3]>,
    nu: Vec<[F8; 3]>,
    /// Per sphere, its threshold with its margin along the motion, in the batch `along_at`.
    along: Vec<F8>,
    along_at: Vec<u32>,
    /// The instruction set of the batches (see `simd8`).
    pub(crate) isa: Isa,
    /// The bodies, groups, links and spheres the buffers above are sized for.
    shape: [usize; 4],
    /// The frames `rot` and `pos` as the last batch left them, when it was an edge probe's with
    /// still groups and posed every body: its program, those groups and every joint's value
    /// (lane 0; each still joint's in every lane). The next such batch keeps the frames of the
    /// bodies of groups still in both, with the same values (see `SphereGeom::pose_lanes`).
    kept_frames: Option<ProgramId>,
    kept_groups: u64,
    kept_values: Vec<f64>,
    /// After a batch along a motion ([`LaneMargins::along`]), per lane, the groups (bit `g`
    /// for group `g`) whose spheres it may have near an obstacle: those it found near (every
    /// other group it proved free of every obstacle, or was told so by
    /// [`LaneMargins::settled`]); every group when it stopped early.
    pub(crate) near: [u64; LANES],
}

impl LaneScratch {
    pub(crate) const fn new() -> Self {
        Self {
            rot: Vec::new(),
            pos: Vec::new(),
            group_c: Vec::new(),
            link_c: Vec::new(),
            link_posed: Vec::new(),
            centre: Vec::new(),
            posed: Vec::new(),
            reach: Vec::new(),
            sin: Vec::new(),
            cos: Vec::new(),
            cols: Vec::new(),
            batch: 0,
            link_g: Vec::new(),
            solid_t: Vec::new(),
            grown: Grown {
                key: None,
                grow: 0.0,
                margin: 0.0,
                group: Vec::new(),
                group_pair: Vec::new(),
                solid: Vec::new(),
            },
            motion: LaneMotion {
                ready: None,
                seg: 0,
                grow: 0,
                speed: Vec::new(),
                factor: Vec::new(),
                above: Vec::new(),
                add: Vec::new(),
                add_at: Vec::new(),
            },
            omega: Vec::new(),
            nu: Vec::new(),
            along: Vec::new(),
            along_at: Vec::new(),
            isa: Isa::Best,
            shape: [0; 4],
            kept_frames: None,
            kept_groups: 0,
            kept_values: Vec::new(),
            near: [u64::MAX; LANES],
        }
    }

    /// Size the buffers for `shape` (see [`Self::shape`]) and clear the marks, numbering
    /// batches from 1 again.
    #[cold]
    fn fit(&mut self, shape: [usize; 4]) {
        let [bodies, groups, links, centres] = shape;
        self.rot.resize(bodies, [F8::ZERO; 9]);
        self.pos.resize(bodies, [F8::ZERO; 3]);
        self.sin.resize(bodies, F8::ZERO);
        self.cos.resize(bodies, F8::ZERO);
        self.group_c.resize(groups, [F8::ZERO; 3]);
        self.link_c.resize(links, [F8::ZERO; 3]);
        self.centre.resize(centres, [F8::ZERO; 3]);
        self.reach.resize(centres, 0);
        self.posed.clear();
        self.posed.resize(links, 0);
        self.link_posed.clear();
        self.link_posed.resize(links, 0);
        self.omega.resize(bodies, [F8::ZERO; 3]);
        self.nu.resize(bodies, [F8::ZERO; 3]);
        self.along.resize(centres, F8::ZERO);
        self.along_at.clear();
        self.along_at.resize(centres, 0);
        self.batch = 1;
        self.shape = shape;
        self.kept_frames = None;
    }
}

/// A batch's view of its working memory ([`LaneScratch`]): each buffer as a slice of its own,
/// taken once per batch. Reached through `&mut LaneScratch`, the kernel loaded buffers'
/// pointers and lengths again inside its loops: public MotionBenchMaker planning instructions
/// 61.12 M -> 59.85 M with the slices, a free batch of eight 14,558 -> 13,602; the time moved
/// within the noise of interleaved runs (per problem 0.985-1.020).
struct Work<'a> {
    batch: u32,
    rot: &'a mut [[F8; 9]],
    pos: &'a mut [[F8; 3]],
    sin: &'a mut [F8],
    cos: &'a mut [F8],
    cols: &'a [[f64; LANES]],
    group_c: &'a mut [[F8; 3]],
    link_c: &'a mut [[F8; 3]],
    link_posed: &'a mut [u32],
    centre: &'a mut [[F8; 3]],
    posed: &'a mut [u32],
    reach: &'a mut [u32],
    link_g: &'a [f32],
    grown: &'a Grown,
    solid_t: &'a mut [f32],
    motion: &'a mut LaneMotion,
    omega: &'a mut [[F8; 3]],
    nu: &'a mut [[F8; 3]],
    /// The batch whose twists `omega` and `nu` hold (none yet: batches count from 1).
    twisted: u32,
    along: &'a mut [F8],
    along_at: &'a mut [u32],
    /// [`LaneScratch::kept_frames`].
    kept_frames: &'a mut Option<ProgramId>,
    /// [`LaneScratch::near`].
    near: &'a mut [u64; LANES],
}

impl LaneScratch {
    /// The buffers of the batch now numbered, as [`Work`].
    #[inline(always)]
    fn work(&mut self) -> Work<'_> {
        Work {
            batch: self.batch,
            rot: &mut self.rot,
            pos: &mut self.pos,
            sin: &mut self.sin,
            cos: &mut self.cos,
            cols: &self.cols,
            group_c: &mut self.group_c,
            link_c: &mut self.link_c,
            link_posed: &mut self.link_posed,
            centre: &mut self.centre,
            posed: &mut self.posed,
            reach: &mut self.reach,
            link_g: &self.link_g,
            grown: &self.grown,
            solid_t: &mut self.solid_t,
            motion: &mut self.motion,
            omega: &mut self.omega,
            nu: &mut self.nu,
            twisted: 0,
            along: &mut self.along,
            along_at: &mut self.along_at,
            kept_frames: &mut self.kept_frames,
            near: &mut self.near,
        }
    }
}

#[inline(always)]
fn splat<O: Ops>(o: O, x: f32) -> F<O> {
    L::splat(o, x)
}

#[inline(always)]
fn splat3<O: Ops>(o: O, x: &[f32; 3]) -> P<O> {
    x.map(|v| L::splat(o, v))
}

#[inline(always)]
fn load<O: Ops, const K: usize>(o: O, x: &[F8; K]) -> [F<O>; K] {
    x.map(|v| L::load(o, v))
}

/// Lane vectors written to working memory one by one (a whole array would go through
/// `memcpy`).
#[inline(always)]
fn store<O: Ops, const K: usize>(x: &[F<O>; K], out: &mut [F8; K]) {
    for (o, v) in out.iter_mut().zip(x) {
        *o = v.store();
    }
}

/// `rot * c + pos` per lane, for a constant `c`: each coordinate a sum of four terms, the
/// origin's first, each product fused into the sum of the terms before it (see `point` in
/// [`Lanes::new`] for its error).
#[inline(always)]
fn place<O: Ops>(o: O, rot: &R<O>, pos: &P<O>, c: &[f32; 3]) -> P<O> {
    let [x, y, z] = splat3(o, c);
    let row = |r: usize| rot[3 * r].mul_add(x, rot[3 * r + 1].mul_add(y, rot[3 * r + 2].mul_add(z, pos[r])));
    [row(0), row(1), row(2)]
}

/// [`place`] for a point whose only coordinate not zero is `K`: the products by the zeros are
/// left out. Each is a zero, and adding a zero to a sum leaves it as it is (up to the sign of a
/// zero result, which the squares and absolute values of the tests ignore), so the values are
/// the full product's, with a third of its operations.
#[inline(always)]
fn place_on<O: Ops, const K: usize>(o: O, rot: &R<O>, pos: &P<O>, c: &[f32; 3]) -> P<O> {
    let x = splat(o, c[K]);
    [rot[K].mul_add(x, pos[0]), rot[3 + K].mul_add(x, pos[1]), rot[6 + K].mul_add(x, pos[2])]
}

/// Column `c` of the rotation `r` (row-major).
#[inline(always)]
fn column<O: Ops>(r: &R<O>, c: Col) -> [F<O>; 3] {
    match c {
        Col::X => [r[0], r[3], r[6]],
        Col::Y => [r[1], r[4], r[7]],
        Col::Z => [r[2], r[5], r[8]],
    }
}

/// `rot * m` for a constant matrix `m` (row-major).
#[inline(always)]
fn mul_m<O: Ops>(o: O, rot: &R<O>, m: &[f32; 9]) -> R<O> {
    let e = |k: usize| {
        let (r, c) = (k / 3, k % 3);
        rot[3 * r]
            .mul_add(splat(o, m[c]), rot[3 * r + 1].mul_add(splat(o, m[3 + c]), rot[3 * r + 2] * splat(o, m[6 + c])))
    };
    [e(0), e(1), e(2), e(3), e(4), e(5), e(6), e(7), e(8)]
}

/// The error bound of [`sin_cos_f32`]'s sines and cosines.
const SIN_COS_ERR: f64 = 4.0 * U;

/// Taylor coefficients of `(sin r - r) / r³` in powers of `r²` (through `r⁹`), and of
/// `(cos r - 1 + r²/2) / r⁴` (through `r¹⁰`), rounded to `f32`.
const SIN_T: [f32; 4] = [-1.0 / 6.0, 1.0 / 120.0, -1.0 / 5040.0, 1.0 / 362_880.0];
const COS_T: [f32; 4] = [1.0 / 24.0, -1.0 / 720.0, 1.0 / 40_320.0, -1.0 / 3_628_800.0];

/// The sine and cosine of every lane's angle (`|x|` below `SIN_COS_RANGE`) in single precision,
/// each within [`SIN_COS_ERR`] `= 4u` of the exact value.
///
/// *Proof.* The reduction is the scalar kernel's, in `f64`: `k` is `x·2/π` (within `2^-32` of
/// exact for `|x| < 2^20`) rounded to an integer, so `|x - kπ/2| ≤ π/4 + 2^-31 < 0.786`; `k`
/// times each of the first two parts of π/2 is exact (their trailing zero bits), the first
/// subtraction is exact (Sterbenz: `x` and `k·PIO2_1` are within a factor of two), and the
/// other two round by at most `2^-54` each, the third product by far less: `r` is within
/// `2^-52` of `x - kπ/2`, `|r| < 0.786`. Rounding `r` to `f32` moves it by at most
/// `u |r| ≤ 0.79u`, and sine and cosine by no more (their slopes are at most 1). The Taylor polynomials of degree 9 (sine) and 10 (cosine) differ from
/// sine and cosine at `|r| ≤ 0.786` by at most the first term left out (the series alternate
/// with falling terms): `0.786¹¹/11! < 1.8·10⁻⁹ < 0.04u` and `0.786¹²/12! < 0.01u`. Evaluated
/// in `f32` (Horner's rule in `r²` of degree 3 perturbs each term by at most `γ_6`, Higham,
/// *Accuracy and Stability*, §5.1): for the sine, the term `S_i r^{2i+3}` of `t = r·r²·P(r²)`
/// carries at most `10 + i` roundings (Horner's 6, its coefficient's, `r²`'s `i + 1` and the
/// two products), so `|t̂ - t| ≤ Σ γ_{10+i} |S_i| 0.786^{2i+3} < 0.85u`, and the last sum
/// `r + t̂` rounds by at most `u |sin r| ≤ 0.71u`: `0.79u + 0.04u + 0.85u + 0.71u < 2.4u` in
/// all. For the cosine, `1 - r²/2` (the halving exact) errs by at most `0.31u` from `r²`'s
/// rounding and `u` from the subtraction; the term `C_i r^{2i+4}` of `r⁴·Q(r²)` carries at most
/// `11 + i` roundings, `|r⁴Q| ≤ 0.016`, so under `0.18u`; the last sum `u`; the argument
/// `0.79u · 0.71 < 0.56u`: under `3.1u`. The quadrant swaps sine and cosine and flips signs,
/// exactly. Both bounds are below `4u`; the tests check them against `f64` on dense samples.
/// With `fused` (AVX2 with FMA3), each product and the sum after it round once instead of
/// twice. In the reduction, `x·2/π + 2^52·1.5` still rounds to `k` plus that constant, `k` an
/// integer within `2^-32 + 1/2` of `x·2/π`; the first two steps give the very values of the
/// unfused form (their products are exact: the first step's result is exact, the second's
/// rounded once either way); the third rounds once, not twice. In the
/// polynomials every term goes through fewer roundings than counted above. So the bounds hold
/// for both forms (the tests check both).
#[inline(always)]
fn sin_cos_f32(x: &[f64; LANES], fused: bool) -> ([f32; LANES], [f32; LANES]) {
    use super::{PIO2_1, PIO2_2, PIO2_2T, SIN_ROUND};
    // `a b + c`, fused where the instruction set fuses (one rounding fewer: within the bounds
    // above, which count the roundings of the unfused form).
    // (`fused` is a constant of each kernel: the branch goes once the kernel is inlined.)
    let fma64 = |a: f64, b: f64, c: f64| if fused { a.mul_add(b, c) } else { a * b + c };
    let fma = |a: f32, b: f32, c: f32| if fused { a.mul_add(b, c) } else { a * b + c };
    let mut r = [0.0f32; LANES];
    let mut quadrant = [0u32; LANES];
    for i in 0..LANES {
        let shifted = fma64(x[i], std::f64::consts::FRAC_2_PI, SIN_ROUND);
        let k = shifted - SIN_ROUND;
        r[i] = fma64(-k, PIO2_2T, fma64(-k, PIO2_2, fma64(-k, PIO2_1, x[i]))) as f32;
        // The low bits of `shifted` hold `k` (two's complement).
        quadrant[i] = shifted.to_bits() as u32;
    }
    let (s, c) = (SIN_T, COS_T);
    let mut sin = [0.0f32; LANES];
    let mut cos = [0.0f32; LANES];
    for i in 0..LANES {
        let r1 = r[i];
        let r2 = r1 * r1;
        let ps = fma(r2, fma(r2, fma(r2, s[3], s[2]), s[1]), s[0]);
        sin[i] = fma(r1 * r2, ps, r1);
        let pc = fma(r2, fma(r2, fma(r2, c[3], c[2]), c[1]), c[0]);
        cos[i] = fma(r2 * r2, pc, 1.0 - 0.5 * r2);
    }
    let mut out_s = [0.0f32; LANES];
    let mut out_c = [0.0f32; LANES];
    for i in 0..LANES {
        let q = quadrant[i];
        let swap = 0u32.wrapping_sub(q & 1);
        let (sb, cb) = (sin[i].to_bits(), cos[i].to_bits());
        let a = (sb & !swap) | (cb & swap);
        let b = (cb & !swap) | (sb & swap);
        out_s[i] = f32::from_bits(a ^ ((q & 2) << 30));
        out_c[i] = f32::from_bits(b ^ ((q.wrapping_add(1) & 2) << 30));
    }
    (out_s, out_c)
}

/// The [`LANES`] configurations `qs` of `D` values each, written joint by joint over `cols`
/// (sized here): `cols[j][i]` is value `j` of configuration `i`. `false` (nothing written)
/// unless `qs` holds exactly that many values.
#[inline(always)]
fn transpose<const D: usize>(qs: &[f64], cols: &mut Vec<[f64; LANES]>) -> bool {
    let (rows, rest) = qs.as_chunks::<D>();
    let (Ok(rows), true) = (<&[[f64; D]; LANES]>::try_from(rows), rest.is_empty()) else { return false };
    cols.resize(D, [0.0; LANES]);
    for (j, col) in cols.iter_mut().enumerate() {
        *col = std::array::from_fn(|i| rows[i][j]);
    }
    true
}

/// [`transpose`] for any number of values `dof` a configuration (a loop).
fn transpose_any(qs: &[f64], dof: usize, cols: &mut Vec<[f64; LANES]>) -> bool {
    if dof == 0 || qs.len() != LANES * dof {
        return false;
    }
    cols.resize(dof, [0.0; LANES]);
    for (i, row) in qs.chunks_exact(dof).enumerate() {
        for (col, &v) in cols.iter_mut().zip(row) {
            col[i] = v;
        }
    }
    true
}

/// `(1 + 2^-21)`: see [`thr`].
const WIDEN: f32 = 1.0 + 1.0 / 2_097_152.0;

/// Whether group `g` is set in the mask `still` ([`LaneMargins::still`]).
#[inline(always)]
fn is_still(still: u64, g: usize) -> bool {
    g < 64 && still >> g & 1 != 0
}

/// A threshold at least `(1 + γ_3)(a + b + c)²` for `a`, `b`, `c` ≥ 0 (each already holding its
/// share of the rounding allowance, rounded up), in three `f32` operations and a square: the
/// two sums and the product lose at most a factor `(1 - u)³` before the square, which squares
/// it and loses another `(1 - u)`, and `(1 - u)^7 (1 + 8u)² > 1 + γ_3`.
#[inline(always)]
fn thr(a: f32, b: f32, c: f32) -> f32 {
    let x = ((a + b) + c) * WIDEN;
    x * x
}

/// Lanes where the sum of squares `s` is at most the threshold `t` (possibly touching).
#[inline(always)]
fn within<O: Ops>(s: F<O>, t: f32) -> u32 {
    s.le_mask(t)
}

/// Squared gap of each lane's point to a solid (see the module documentation).
#[inline(always)]
fn gap2<O: Ops>(o: O, solid: &Solid32, p: &P<O>) -> F<O> {
    let zero = splat(o, 0.0);
    match solid {
        Solid32::Ball { c, r } => {
            let c = splat3(o, c);
            let (dx, dy, dz) = (p[0] - c[0], p[1] - c[1], p[2] - c[2]);
            let d = dx.mul_add(dx, dy.mul_add(dy, dz * dz)).sqrt() - splat(o, *r);
            let d = d.max(zero);
            d * d
        }
        Solid32::Cuboid { rt, t, half, yaw } => {
            let l = local(o, rt, t, *yaw, p);
            let ax = (l[0].abs() - splat(o, half[0])).max(zero);
            let ay = (l[1].abs() - splat(o, half[1])).max(zero);
            let az = (l[2].abs() - splat(o, half[2])).max(zero);
            ax.mul_add(ax, ay.mul_add(ay, az * az))
        }
        Solid32::Cylinder { rt, t, r, hh, yaw } => {
            let l = local(o, rt, t, *yaw, p);
            let ar = (l[0].mul_add(l[0], l[1] * l[1]).sqrt() - splat(o, *r)).max(zero);
            let az = (l[2].abs() - splat(o, *hh)).max(zero);
            ar.mul_add(ar, az * az)
        }
    }
}

/// Whether the rotation `rt` (row-major) turns about z only: its third row and column are
/// exactly `e_z`. Then `rt * v` takes four products and two sums, and gives the very values of
/// the full product (the terms dropped are products by zero, and `1 * z` is `z`), up to the
/// sign of a zero, which the gaps' `abs` and squares ignore. Obstacles placed with a yaw only
/// (MotionBenchMaker's scenes) take this form.
fn is_yaw(rt: &[f32; 9]) -> bool {
    rt[2] == 0.0 && rt[5] == 0.0 && rt[6] == 0.0 && rt[7] == 0.0 && rt[8] == 1.0
}

/// `rt * (p - t)` per lane; `yaw`: [`is_yaw`] holds for `rt`.
#[inline(always)]
fn local<O: Ops>(o: O, rt: &[f32; 9], t: &[f32; 3], yaw: bool, p: &P<O>) -> P<O> {
    let (x, y, z) = (p[0] - splat(o, t[0]), p[1] - splat(o, t[1]), p[2] - splat(o, t[2]));
    if yaw {
        let (c0, c1, c3, c4) = (splat(o, rt[0]), splat(o, rt[1]), splat(o, rt[3]), splat(o, rt[4]));
        return [c0.mul_add(x, c1 * y), c3.mul_add(x, c4 * y), z];
    }
    // Written out (as a closure it was sometimes left a call in the batch's loop).
    let (r0, r1, r2) = (splat(o, rt[0]), splat(o, rt[1]), splat(o, rt[2]));
    let (r3, r4, r5) = (splat(o, rt[3]), splat(o, rt[4]), splat(o, rt[5]));
    let (r6, r7, r8) = (splat(o, rt[6]), splat(o, rt[7]), splat(o, rt[8]));
    [r0.mul_add(x, r1.mul_add(y, r2 * z)), r3.mul_add(x, r4.mul_add(y, r5 * z)), r6.mul_add(x, r7.mul_add(y, r8 * z))]
}

#[inline(always)]
fn dist2<O: Ops>(a: &P<O>, b: &P<O>) -> F<O> {
    let (dx, dy, dz) = (a[0] - b[0], a[1] - b[1], a[2] - b[2]);
    dx.mul_add(dx, dy.mul_add(dy, dz * dz))
}

impl Lanes {
    /// No program: every batch leaves all its lanes to the `f64` query.
    pub(super) fn empty() -> Lanes {
        Lanes {
            base_r: [0.0; 9],
            base_t: [0.0; 3],
            bodies: Vec::new(),
            balls: Vec::new(),
            links: Vec::new(),
            groups: Vec::new(),
            radius_up: Vec::new(),
            link_r_up: Vec::new(),
            pairs: Vec::new(),
            pair_ranges: Vec::new(),
            runs: Vec::new(),
            run_ranges: Vec::new(),
            group_r_up: Vec::new(),
            centre_err: f64::INFINITY,
            max_group_r: 0.0,
            twist_err: f64::INFINITY,
            id: ProgramId::next(),
        }
    }

    /// The single-precision program of `g` (its bodies already turned so that each joint
    /// spins about z), with its error bound.
    pub(super) fn new(g: &SphereGeom) -> Lanes {
        let bodies: Vec<Body> = g
            .bodies
            .iter()
            .skip(1)
            .zip(&g.angles)
            .map(|(b, a)| Body {
                parent: b.parent,
                pre: match lane_permutation(b) {
                    Some((perm, sign, _)) => Pre::Perm(perm.map(Col::of), [f(sign[0]), f(sign[1]), f(sign[2])]),
                    None => Pre::Mat(m9(&b.pre_r)),
                },
                pre_t: v3(&b.pre_t),
                prismatic: b.prismatic,
                travel: prismatic_travel(b.reach),
                axis: v3(&b.axis),
                post: b.post.as_ref().map(|(r, t)| (m9(r), v3(t))),
                // The double-precision body's forms (a zero coordinate stays zero in `f32`).
                t_axis: b.t_axis,
                plain: b.plain,
                value_is_angle: a.scale == 1.0 && a.add == 0.0 && a.offset == 0.0,
            })
            .collect();
        // The running error bound (module documentation): per body, the error of a rotation
        // entry, of an origin coordinate, and the largest origin coordinate.
        let sc = SIN_COS_ERR;
        let s3 = 3f64.sqrt();
        let n = g.bodies.len();
        let (mut er, mut ep, mut mp) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        let t_err = |t: &nalgebra::Vector3<f64>| U * t.amax();
        // A point `r t + p` from a rotation with entry error `e_r`, an origin with error `e_p`
        // and magnitude `m_p`: its coordinates' error.
        // A coordinate is a sum of four terms, the origin's and three products (see `place`):
        // the products' error from their factors' (as in `dot_err`), the origin's, and the
        // rounding of four operations at most on any term (three fused, or three products and
        // their three sums with the origin's: each term goes through at most four roundings).
        let point = |e_r: f64, e_p: f64, m_p: f64, t: &nalgebra::Vector3<f64>| {
            let (t1, te) = (t.abs().sum(), t_err(t));
            let e = e_r * t1 + te * s3 + 3.0 * e_r * te;
            e + e_p + gamma(4.0) * (t.norm() + e + m_p + e_p)
        };
        er[0] = U;
        ep[0] = t_err(&g.base_t);
        mp[0] = g.base_t.amax();
        for (k, b) in g.bodies.iter().enumerate().skip(1) {
            let p = b.parent;
            // A permutation picks the parent's entries exactly; one standing in for a rotation
            // `δ` off it adds `|R (M - P)| ≤ √3 δ` (a rotation's row sums to at most √3).
            let em = match lane_permutation(b) {
                Some((_, _, delta)) => er[p] + s3 * delta * (1.0 + 4.0 * U),
                None => dot_err(er[p], U, s3, s3, 1.0, 3.0),
            };
            let mut r_err = if b.prismatic { em } else { dot_err(em, sc, 2f64.sqrt(), 2f64.sqrt(), 1.0, 2.0).max(em) };
            let mut p_err = point(er[p], ep[p], mp[p], &b.pre_t);
            let mut m = mp[p] + b.pre_t.norm();
            if b.prismatic {
                // `m (axis v)`, `|v| ≤` the joint's travel, then added to the origin.
                let a = b.axis * prismatic_travel(b.reach);
                let a_err = gamma(3.0) * a.amax();
                let dot = dot_err(em, a_err, s3, a.abs().sum(), a.norm(), 3.0);
                p_err += dot + gamma(1.0) * (m + a.norm() + p_err + dot);
                m += a.norm();
            }
            if let Some((_, qt)) = &b.post {
                p_err = point(r_err, p_err, m, qt);
                m += qt.norm();
                r_err = dot_err(r_err, U, s3, s3, 1.0, 3.0);
            }
            er[k] = r_err;
            ep[k] = p_err;
            mp[k] = m;
        }
        let mut centre_err: f64 = 0.0;
        for l in &g.links {
            let b = l.body;
            centre_err = centre_err.max(point(er[b], ep[b], mp[b], &l.c));
            for c in &g.centre[l.first..l.end] {
                centre_err = centre_err.max(point(er[b], ep[b], mp[b], c));
            }
        }
        for gr in &g.groups {
            let b = gr.body;
            centre_err = centre_err.max(point(er[b], ep[b], mp[b], &gr.c));
        }
        let centre_err = if centre_err.is_finite() { centre_err * (1.0 + 1e-6) } else { f64::INFINITY };
        // `√3 ε` of `LaneMotion`: `M` bounds every origin and every centre (an origin's
        // coordinates plus the farthest centre from it), plus one.
        let far = g.centre.iter().chain(g.links.iter().map(|l| &l.c)).map(|c| c.norm()).fold(0.0, f64::max);
        let big_m = mp.iter().copied().fold(0.0, f64::max) + far + 1.0;
        let e_r = er.iter().copied().fold(0.0, f64::max);
        let e_o = ep.iter().copied().fold(0.0, f64::max);
        let eps = 8.0 * e_r * big_m + 4.0 * (e_o + centre_err) + 8.0 * (n as f64 + 4.0) * U * big_m;
        let posted = g.bodies.iter().skip(1).any(|b| b.post.is_some());
        let twist_err = if eps.is_finite() && !posted { 3f64.sqrt() * eps * (1.0 + 1e-6) } else { f64::INFINITY };
        let (mut pairs, mut pair_ranges, mut runs, mut run_ranges) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for gp in &g.group_pairs {
            let (first, first_run) = (pairs.len(), runs.len());
            for run in &g.runs[gp.runs.clone()] {
                let from = pairs.len() as u32;
                for rp in &g.run_pairs[run.pairs.clone()] {
                    pairs.push([rp.pair, run.outer as u32, rp.link]);
                }
                runs.push([run.outer as u32, from, pairs.len() as u32]);
            }
            pair_ranges.push(first..pairs.len());
            run_ranges.push(first_run..runs.len());
        }
        Lanes {
            base_r: m9(&g.base_r),
            base_t: v3(&g.base_t),
            bodies,
            balls: g.centre.iter().map(v3).collect(),
            links: g.links.iter().map(|l| v3(&l.c)).collect(),
            groups: g.groups.iter().map(|gr| v3(&gr.c)).collect(),
            radius_up: g.radius.iter().map(|&r| up(r)).collect(),
            link_r_up: g.links.iter().map(|l| up(l.r)).collect(),
            pairs,
            pair_ranges,
            runs,
            run_ranges,
            group_r_up: g.groups.iter().map(|gr| up(gr.r)).collect(),
            centre_err,
            max_group_r: g.groups.iter().map(|gr| gr.r).fold(0.0, f64::max),
            twist_err,
            id: ProgramId::next(),
        }
    }
}

/// An `f32` at most `(1 - γ_3)(r - grow)²`: a sum of squares at most this is certainly within
/// `r` (see the module documentation); -1 when `r ≤ grow`.
fn contact_thr(r: f64, grow: f64) -> f32 {
    let r = r - grow;
    if r > 0.0 { down((1.0 - gamma(3.0)) * r * r) } else { -1.0 }
}

impl SphereGeom {
    /// The allowance `√3 η` of a query whose largest link and pair margins are these, among
    /// `obstacles` (see the module documentation); `None` when it is not finite.
    fn allowance(&self, obstacles: &Solids32, max_link_m: f64, max_pair_m: f64) -> Option<f64> {
        let lanes = &self.lanes;
        let max_group_r = lanes.max_group_r;
        let r_max = (max_group_r + max_link_m).max(2.0 * max_group_r + max_pair_m);
        let eta = 3.0 * lanes.centre_err + 32.0 * U * (obstacles.scale + r_max);
        eta.is_finite().then(|| 3f64.sqrt() * eta)
    }

    /// The thresholds of the uniform margin `m` among `obstacles` in `out` (see [`Grown`]);
    /// `false` (and nothing kept) when the allowance is not finite.
    #[cold]
    #[inline(never)]
    fn grow_uniform(&self, obstacles: &Solids32, m: f64, out: &mut Grown) -> bool {
        out.key = None;
        let Some(grow) = self.allowance(obstacles, m, m) else { return false };
        out.grow = grow;
        out.group.clear();
        out.group.extend(self.groups.iter().map(|g| up(g.r + m + grow)));
        out.group_pair.clear();
        out.group_pair.extend(self.group_pairs.iter().map(|gp| thr(up(gp.rr + m + grow), 0.0, 0.0)));
        out.solid.clear();
        for &gg in &out.group {
            out.solid.extend(obstacles.bound_r.iter().map(|&br| thr(gg, br, 0.0)));
        }
        out.margin = up(m + grow);
        out.key = Some((self.lanes.id, m.to_bits(), obstacles.id));
        true
    }
}

impl SphereGeom {
    /// Hold in `s` the terms of the straight motion `q(tm) + s dir` (`step`: `|dir|`) for the
    /// batches of its pieces (see [`LaneMotion`]); none are held (and such batches test no
    /// sphere again) when the robot gets none or a value is missing or not finite. Each
    /// sphere's own term is worked out only in a batch that needs it (for all spheres here:
    /// 5% of the planning instructions on the public MotionBenchMaker UR5 problems).
    pub(crate) fn set_lane_motion(&self, (step, dir): (&[f64], &[f64]), s: &mut LaneScratch) {
        let mo = &mut s.motion;
        mo.ready = None;
        if mo.add_at.len() != self.centre.len() {
            mo.add_at.clear();
            mo.add_at.resize(self.centre.len(), 0);
            mo.add.resize(self.centre.len(), 0.0);
        }
        mo.renumber();
        if !self.lanes.twist_err.is_finite() {
            return;
        }
        mo.speed.clear();
        for b in 1..self.bodies.len() {
            match self.body_dir(b, dir) {
                Some(d) if d.is_finite() => mo.speed.push(f(d)),
                _ => return,
            }
        }
        let held = self.second_factors(step, &mut mo.factor, &mut mo.above)
            && mo.factor.iter().chain(&mo.above).all(|v| v.is_finite());
        mo.ready = held.then_some(self.lanes.id);
    }

    /// Sphere `k`'s `A` (see [`LaneMotion`]) with the allowance `grow`, kept for the motion;
    /// infinite (no sphere is settled by it) when not finite.
    #[inline]
    fn along_add(&self, k: usize, grow: f64, mo: &mut LaneMotion) -> f32 {
        if mo.add_at[k] != mo.seg {
            let (second, sum) = self.static_second(k, &mo.factor, &mo.above);
            let a = (second + sum * self.lanes.twist_err + grow) * (1.0 + 1.0 / 1_048_576.0);
            mo.add[k] = if a.is_finite() { up(a) } else { f32::INFINITY };
            mo.add_at[k] = mo.seg;
        }
        mo.add[k]
    }

    /// Every body's twist in every lane (see [`LaneMotion`]), from the frames posed.
    #[inline(always)]
    fn pose_twists<O: Ops>(&self, o: O, s: &mut Work<'_>) {
        s.omega[0] = [F8::ZERO; 3];
        s.nu[0] = [F8::ZERO; 3];
        for (k, b) in self.lanes.bodies.iter().enumerate() {
            let d = s.motion.speed[k];
            if d == 0.0 {
                (s.omega[k + 1], s.nu[k + 1]) = (s.omega[b.parent], s.nu[b.parent]);
                continue;
            }
            let (w, n) = (load(o, &s.omega[b.parent]), load(o, &s.nu[b.parent]));
            let r = load(o, &s.rot[k + 1]);
            let d = splat(o, d);
            if b.prismatic {
                let ax = splat3(o, &b.axis);
                let row = |i: usize| r[3 * i] * ax[0] + r[3 * i + 1] * ax[1] + r[3 * i + 2] * ax[2];
                let u = [row(0), row(1), row(2)];
                store(&[n[0] + d * u[0], n[1] + d * u[1], n[2] + d * u[2]], &mut s.nu[k + 1]);
                s.omega[k + 1] = s.omega[b.parent];
            } else {
                // The frame is the joint's: z along its axis, the origin on it.
                let z = [r[2], r[5], r[8]];
                let p = load(o, &s.pos[k + 1]);
                let oz = [p[1] * z[2] - p[2] * z[1], p[2] * z[0] - p[0] * z[2], p[0] * z[1] - p[1] * z[0]];
                store(&[w[0] + d * z[0], w[1] + d * z[1], w[2] + d * z[2]], &mut s.omega[k + 1]);
                store(&[n[0] + d * oz[0], n[1] + d * oz[1], n[2] + d * oz[2]], &mut s.nu[k + 1]);
            }
        }
    }

    /// Sphere `k`'s (of link `l`, posed) threshold against an obstacle with its own margin
    /// along the motion, once per batch (see [`LaneMotion`]).
    #[inline(always)]
    fn along_thr<O: Ops>(&self, o: O, l: usize, k: usize, grow: f64, s: &mut Work<'_>) -> F<O> {
        if s.along_at[k] != s.batch {
            if s.twisted != s.batch {
                self.pose_twists(o, s);
                s.twisted = s.batch;
            }
            let b = self.links[l].body;
            let (w, n, p) = (load(o, &s.omega[b]), load(o, &s.nu[b]), load(o, &s.centre[k]));
            let v = [
                n[0] + (w[1] * p[2] - w[2] * p[1]),
                n[1] + (w[2] * p[0] - w[0] * p[2]),
                n[2] + (w[0] * p[1] - w[1] * p[0]),
            ];
            let norm = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            let add = self.along_add(k, grow, s.motion);
            let m = norm * splat(o, ALONG_K) + splat(o, add);
            let x = (splat(o, self.lanes.radius_up[k]) + m) * splat(o, WIDEN);
            s.along[k] = (x * x).store();
            s.along_at[k] = s.batch;
        }
        L::load(o, s.along[k])
    }
}

/// One call of [`SphereGeom::free_lanes`], compiled for each instruction set.
/// `ALONG`: [`LaneMargins::along`] (a kernel of its own: the test it adds in the sphere loop
/// made the other batches' code slower). `STILL`: some [`LaneMargins::still`] group (a kernel
/// of its own too: its tests in the group and group-pair loops cost the public
/// MotionBenchMaker UR5 problems, where no group but the base is ever still, 2.4% of their
/// planning instructions).
struct Batch<'a, S, const ALONG: bool, const STILL: bool> {
    geom: &'a SphereGeom,
    qs: S,
    dof: usize,
    obstacles: &'a Solids32,
    margins: LaneMargins<'a>,
    s: &'a mut LaneScratch,
}

impl<S: Source, const ALONG: bool, const STILL: bool> Kernel for Batch<'_, S, ALONG, STILL> {
    type Output = Lanes8;

    #[inline(always)]
    fn run<O: Ops>(self, o: O) -> Lanes8 {
        let Batch { geom, qs, dof, obstacles, margins, s } = self;
        geom.free_lanes_in::<O, S, ALONG, STILL>(o, qs, dof, obstacles, margins, s)
    }
}

impl SphereGeom {
    /// Of the [`LANES`] configurations `qs` (`dof` values each), the lanes
    /// certainly free when grown by `margins` (see [`LaneMargins`]): bit `i` for lane `i`. See
    /// the module documentation; lanes not set may or may not be free. A lane certainly in
    /// contact (exactly, without margins) ends the batch: then only `hit` is set. The
    /// instruction set is the scratch's (see `simd8`; the answer is the same with either).
    pub(crate) fn free_lanes(
        &self,
        qs: LaneInput<'_>,
        dof: usize,
        obstacles: &Solids32,
        margins: LaneMargins<'_>,
        s: &mut LaneScratch,
    ) -> Lanes8 {
        let isa = s.isa;
        // Rows are never pieces of one motion here: their batches leave `along` out (it only
        // settles more lanes, never changes what a settled lane means), and hold no still group.
        match (qs, margins.along, margins.still != 0) {
            (LaneInput::Rows(qs), ..) => {
                let margins = LaneMargins { still: 0, ..margins };
                simd8::dispatch(
                    Batch::<_, false, false> { geom: self, qs: RowsIn(qs), dof, obstacles, margins, s },
                    isa,
                )
            }
            (LaneInput::Segment(qs), true, false) => {
                simd8::dispatch(Batch::<_, true, false> { geom: self, qs, dof, obstacles, margins, s }, isa)
            }
            (LaneInput::Segment(qs), true, true) => {
                simd8::dispatch(Batch::<_, true, true> { geom: self, qs, dof, obstacles, margins, s }, isa)
            }
            (LaneInput::Segment(qs), false, false) => {
                simd8::dispatch(Batch::<_, false, false> { geom: self, qs, dof, obstacles, margins, s }, isa)
            }
            (LaneInput::Segment(qs), false, true) => {
                simd8::dispatch(Batch::<_, false, true> { geom: self, qs, dof, obstacles, margins, s }, isa)
            }
        }
    }

    /// [`Self::free_lanes`] on the instruction set of `o`.
    #[inline(always)]
    fn free_lanes_in<O: Ops, S: Source, const ALONG: bool, const STILL: bool>(
        &self,
        o: O,
        qs: S,
        dof: usize,
        obstacles: &Solids32,
        margins: LaneMargins<'_>,
        s: &mut LaneScratch,
    ) -> Lanes8 {
        let LaneMargins {
            link: link_m,
            pair: pair_m,
            uniform,
            step,
            pairs_of_near,
            along,
            still,
            settled,
            pairs_settled,
        } = margins;
        let none = Lanes8::NONE;
        if ALONG {
            s.near = [u64::MAX; LANES];
        }
        let lanes = &self.lanes;
        let margins_fit =
            uniform.is_some() || (link_m.len() == self.links.len() && pair_m.len() == self.self_pairs.len());
        if !margins_fit || self.fixed != Check::Free || !lanes.centre_err.is_finite() {
            return none;
        }
        // The allowance, and per link its margin plus the allowance: for a uniform margin
        // kept from the last batch with the same (see `Grown`), otherwise derived here.
        let grow = match uniform {
            Some(m) => {
                let key = Some((lanes.id, m.to_bits(), obstacles.id));
                if s.grown.key != key && !self.grow_uniform(obstacles, m, &mut s.grown) {
                    return none;
                }
                s.grown.grow
            }
            None => {
                // The largest radius any test asks about, and the component error bound η.
                let max_link_m = link_m.iter().copied().fold(0.0, f64::max);
                let max_pair_m = pair_m.iter().copied().fold(0.0, f64::max);
                let Some(grow) = self.allowance(obstacles, max_link_m, max_pair_m) else { return none };
                s.link_g.clear();
                s.link_g.extend(link_m.iter().map(|&m| up(m + grow)));
                grow
            }
        };
        let kept = uniform.is_some();
        // Spheres near with their link's margin are tested again with their own along the
        // motion, when the scratch holds its terms for these margins.
        let along = ALONG
            && along
            && !kept
            && s.motion.ready == Some(lanes.id)
            && s.motion.speed.len() + 1 == self.bodies.len()
            && s.motion.add_at.len() == self.centre.len();
        if along && s.motion.grow != grow.to_bits() {
            // Other margins than the terms kept were worked out with: work them out again.
            s.motion.grow = grow.to_bits();
            s.motion.renumber();
        }
        // Certainly in contact: at most this (rounded down), see the module documentation.
        let contact = |r: f64| contact_thr(r, grow);
        // The world-fixed body (group 0 when it carries spheres) never moves: when its spheres
        // clear every obstacle by more than their largest margin here, twice the allowance and
        // a hair for the thresholds' rounding up, no test of theirs against an obstacle can
        // pass (a computed distance is within the allowance of the true one), so none is made.
        // (Skipping them saved 1.2% of the planning instructions on the public MotionBenchMaker
        // UR5 problems and 1.6% on the spherized Fetch's tables, the same answers.)
        let skip_fixed = self.groups.first().is_some_and(|g0| {
            g0.body == 0 && {
                let m = match uniform {
                    Some(m) => m,
                    None => self.group_links[g0.first..g0.end].iter().map(|&l| link_m[l as usize]).fold(0.0, f64::max),
                };
                obstacles.fixed_clear > m + 2.0 * grow + 1e-6 * (1.0 + obstacles.scale)
            }
        });
        // Edge probes (no `along`) with still groups keep those groups' frames from batch to
        // batch while their joints' values stay.
        let keep = (STILL && !ALONG).then_some(still);
        let n_ob = obstacles.solids.len();
        if s.solid_t.len() < n_ob {
            s.solid_t.resize(n_ob, 0.0);
        }
        let Some(mut w) = self.pose_lanes(o, qs, dof, keep, s) else { return none };
        let grown_solid: &[f32] = &w.grown.solid;
        let ob_buf = std::mem::take(&mut w.solid_t);
        let s = &mut w;
        let mut live: u32 = (1 << LANES) - 1;
        // Along a motion, `live` keeps every lane through the groups, so that each lane's near
        // groups are known (`LaneScratch::near`: the next level's pieces test only those), and
        // `clear` the lanes with no sphere near yet. (Otherwise a lane leaves `live` at its
        // first near sphere.)
        let mut clear = live;
        let mut near = [0u64; LANES];
        // Against obstacles: group, link, sphere; the groups farthest down the chain first
        // (they meet obstacles most often, so a contact ends the batch sooner). The order may
        // change which lanes a batch settles, never what its callers conclude: a lane left
        // unsettled is answered in double precision.
        for (gi, g) in self.groups.iter().enumerate().rev() {
            let links = &self.group_links[g.first..g.end];
            let single = links.len() == 1;
            // The group's centre, kept for the self pairs below (which run only after every
            // group has been here): a batch that ends in a contact skips the groups after it.
            let gc = place(o, &load(o, &s.rot[g.body]), &load(o, &s.pos[g.body]), &lanes.groups[gi]);
            store(&gc, &mut s.group_c[gi]);
            if (gi == 0 && skip_fixed) || (STILL && is_still(still, gi)) || (ALONG && is_still(settled, gi)) {
                continue;
            }
            // The lanes every group is tested in (along a motion, `live` is these again after
            // this group).
            let before = live;
            let gg = if kept {
                s.grown.group[gi]
            } else {
                up(g.r + links.iter().map(|&l| link_m[l as usize]).fold(0.0, f64::max) + grow)
            };
            let tg = thr(gg, 0.0, 0.0);
            // Per solid, the threshold against its bounding sphere (kept with a uniform margin,
            // else worked out for this group first) or, in the batches along a motion (whose
            // margins are never uniform), the bounding radius, the threshold worked out in the
            // loop (a buffer filled first cost their planning more than it saved).
            let per_solid: &[f32] = if ALONG {
                &obstacles.bound_r
            } else {
                match grown_solid.get(gi * n_ob..(gi + 1) * n_ob) {
                    Some(t) if kept => t,
                    _ => {
                        let Some(buf) = ob_buf.get_mut(..n_ob) else { return none };
                        for (t, &br) in buf.iter_mut().zip(&obstacles.bound_r) {
                            *t = thr(gg, br, 0.0);
                        }
                        buf
                    }
                }
            };
            // Every solid is met (one left out could leave a lane called free).
            if per_solid.len() != n_ob || obstacles.bound_c.len() != n_ob {
                return none;
            }
            'solids: for ((ob, bc), &x) in obstacles.solids.iter().zip(&obstacles.bound_c).zip(per_solid) {
                let tb = if ALONG { thr(gg, x, 0.0) } else { x };
                // The spheres around the group and the solid first.
                if live & within(dist2(&gc, &load(o, bc)), tb) == 0 {
                    continue;
                }
                let mg = live & within(gap2(o, ob, &gc), tg);
                if mg == 0 {
                    continue;
                }
                for &l in links {
                    let l = l as usize;
                    let link = &self.links[l];
                    let lg = if kept { s.grown.margin } else { s.link_g[l] };
                    // A group of one link is that link's bounding sphere (a hair larger): the
                    // link's own test would repeat the group's, so its lanes go on as they are.
                    let ml = if single {
                        mg
                    } else {
                        let lc = self.lane_link_centre(o, l, s);
                        mg & within(gap2(o, ob, &lc), thr(lanes.link_r_up[l], lg, 0.0))
                    };
                    if ml == 0 {
                        continue;
                    }
                    self.pose_lane_link(o, l, s);
                    for k in link.first..link.end {
                        let d2 = gap2(o, ob, &load(o, &s.centre[k]));
                        let mut mk = ml & within(d2, thr(lanes.radius_up[k], lg, 0.0));
                        if mk != 0 {
                            let hit = mk & within(d2, contact(self.radius[k]));
                            if hit != 0 {
                                return Lanes8::hit(hit);
                            }
                            if along {
                                // A threshold that is not a number (a motion too large for
                                // `f32`) settles nothing.
                                let t = self.along_thr(o, l, k, grow, s);
                                mk &= d2.le_mask_v(t) | !t.le_mask(f32::INFINITY);
                            }
                        }
                        live &= !mk;
                        if live == 0 {
                            if ALONG {
                                break 'solids;
                            }
                            return none;
                        }
                    }
                }
            }
            if ALONG && live != before {
                // The lanes near with this group.
                clear &= live;
                let mut m = before & !live;
                while m != 0 {
                    let k = m.trailing_zeros() as usize;
                    near[k] |= 1u64.checked_shl(gi as u32).unwrap_or(u64::MAX);
                    m &= m - 1;
                }
                live = before;
            }
        }
        if ALONG {
            live = clear;
        }
        // Self pairs, by group pair (as the scalar query): the two group spheres, the cell
        // table, then each pair's link spheres and spheres. With `pairs_of_near`, of every lane,
        // those near an obstacle too (unless all were: the batch stopped there, most often at
        // a segment that does not certify).
        let all: u32 = (1 << LANES) - 1;
        let tested = if pairs_of_near { all } else { live };
        let mut pairs_near = 0;
        // No step (the edge probes): a lane's own cell, not a box of cells.
        let point_cells = step.is_some_and(|st| st.iter().all(|&d| d == 0.0));
        // Pairs the caller knows free: none tested.
        let group_pairs = if ALONG && pairs_settled { &self.group_pairs[..0] } else { &self.group_pairs[..] };
        for (k, gp) in group_pairs.iter().enumerate() {
            let Some(range) = lanes.pair_ranges.get(k) else { break };
            if STILL && is_still(still, gp.outer) && is_still(still, gp.inner) {
                continue;
            }
            let pairs = &lanes.pairs[range.clone()];
            let tg = if kept {
                s.grown.group_pair[k]
            } else {
                thr(up(gp.rr + pairs.iter().map(|pr| pair_m[pr[0] as usize]).fold(0.0, f64::max) + grow), 0.0, 0.0)
            };
            let mut near = (tested & !pairs_near)
                & within(dist2(&load(o, &s.group_c[gp.outer]), &load(o, &s.group_c[gp.inner])), tg);
            if near == 0 {
                continue;
            }
            // The lanes whose cells the table does not prove free, then whose spheres come near.
            if let (Some(Some(table)), Some(step)) = (self.tables.get(k), step) {
                near &= !if point_cells {
                    table.proves_lanes(s.cols, near)
                } else {
                    table.proves_box_lanes(s.cols, step, near)
                };
                if near == 0 {
                    continue;
                }
            }
            let mut touch = 0;
            if S::SCATTERED {
                // Scattered lanes: as the scalar query, each outer sphere against the inner
                // group's sphere once (it holds every inner sphere: a sphere beyond `r_i + R +
                // m` of its centre is beyond `r_i + r_j + m` of every inner sphere `j`), then
                // only those that reach it against the inner links. On the MotionBenchMaker
                // UR5 the forearm's nine spheres and the upper arm's five meet the ten small
                // links past the wrist this way once, not once per link: a free batch 16,220 ->
                // 14,558 instructions. Pieces of one motion keep the order below (their lanes
                // rarely bring those links close; this order cost their planning 0.2-1%).
                let gi = load(o, &s.group_c[gp.inner]);
                let r_in = lanes.group_r_up[gp.inner];
                let pgk = if kept {
                    s.grown.margin
                } else {
                    up(pairs.iter().map(|pr| pair_m[pr[0] as usize]).fold(0.0, f64::max) + grow)
                };
                let runs = lanes.run_ranges.get(k).map_or(&[][..], |r| &lanes.runs[r.clone()]);
                'runs: for &[a, from, to] in runs {
                    let a = a as usize;
                    let la = &self.links[a];
                    let ca = self.lane_link_centre(o, a, s);
                    let run_near = near & !touch & within(dist2(&ca, &gi), thr(lanes.link_r_up[a], r_in, pgk));
                    if run_near == 0 {
                        continue;
                    }
                    self.pose_lane_link(o, a, s);
                    let mut any = 0;
                    for i in la.first..la.end {
                        let m =
                            run_near & within(dist2(&load(o, &s.centre[i]), &gi), thr(lanes.radius_up[i], r_in, pgk));
                        s.reach[i] = m;
                        any |= m;
                    }
                    if any == 0 {
                        continue;
                    }
                    for &[p, _, b] in lanes.pairs.get(from as usize..to as usize).unwrap_or(&[]) {
                        let (p, b) = (p as usize, b as usize);
                        let pg = if kept { s.grown.margin } else { up(pair_m[p] + grow) };
                        let cb = self.lane_link_centre(o, b, s);
                        let rb = lanes.link_r_up[b];
                        let close = any & !touch & within(dist2(&ca, &cb), thr(lanes.link_r_up[a], rb, pg));
                        if close == 0 {
                            continue;
                        }
                        for i in la.first..la.end {
                            let ri = close & s.reach[i];
                            if ri == 0 {
                                continue;
                            }
                            let ci = load(o, &s.centre[i]);
                            if ri & within(dist2(&ci, &cb), thr(lanes.radius_up[i], rb, pg)) == 0 {
                                continue;
                            }
                            self.pose_lane_link(o, b, s);
                            match self.sphere_against_link(o, (i, &ci), b, ri, pg, grow, s) {
                                Ok(t) => touch |= t,
                                Err(hit) => return Lanes8::hit(hit),
                            }
                        }
                        if touch == near {
                            break 'runs;
                        }
                    }
                }
            } else {
                for &[p, a, b] in pairs {
                    let (p, a, b) = (p as usize, a as usize, b as usize);
                    let pg = if kept { s.grown.margin } else { up(pair_m[p] + grow) };
                    let la = &self.links[a];
                    let ca = self.lane_link_centre(o, a, s);
                    let cb = self.lane_link_centre(o, b, s);
                    let tl = thr(lanes.link_r_up[a], lanes.link_r_up[b], pg);
                    let close = near & !touch & within(dist2(&ca, &cb), tl);
                    if close == 0 {
                        continue;
                    }
                    self.pose_lane_link(o, a, s);
                    self.pose_lane_link(o, b, s);
                    let rb = lanes.link_r_up[b];
                    for i in la.first..la.end {
                        // The sphere against the other link's bounding sphere first.
                        let ci = load(o, &s.centre[i]);
                        if close & within(dist2(&ci, &cb), thr(lanes.radius_up[i], rb, pg)) == 0 {
                            continue;
                        }
                        match self.sphere_against_link(o, (i, &ci), b, close, pg, grow, s) {
                            Ok(t) => touch |= t,
                            Err(hit) => return Lanes8::hit(hit),
                        }
                    }
                    if touch == near {
                        break;
                    }
                }
            }
            live &= !touch;
            pairs_near |= touch;
            if live == 0 && (!pairs_of_near || pairs_near == all) {
                if ALONG {
                    break;
                }
                return none;
            }
        }
        if ALONG {
            *s.near = near;
        }
        Lanes8 { free: live, hit: 0, pairs_free: if pairs_of_near { all & !pairs_near } else { 0 } }
    }

    /// Bodies of the configurations `qs`, in the batch's working memory; `None` when a joint
    /// value is not finite or a prismatic travel exceeds its joint's bound ([`prismatic_travel`]).
    #[inline(always)]
    /// With `keep` (the still groups of an edge probe, see [`LaneMargins::still`]), the frames
    /// of the bodies of groups still here and in the last batch (when it was such a batch of
    /// this program and posed every body), whose joints hold the same values (to the bit), are
    /// the ones that batch left: not posed again. A still joint holds one value in every lane
    /// (the probe's start's), so those frames are this batch's too.
    fn pose_lanes<'s, O: Ops, S: Source>(
        &self,
        o: O,
        qs: S,
        dof: usize,
        keep: Option<u64>,
        s: &'s mut LaneScratch,
    ) -> Option<Work<'s>> {
        let lanes = &self.lanes;
        let n = self.bodies.len();
        // Sized once per model shape: seven `resize` calls a batch cost about 300 instructions.
        let shape = [n, self.groups.len(), self.links.len(), self.centre.len()];
        s.batch = s.batch.wrapping_add(1);
        if s.shape != shape || s.batch == 0 {
            s.fit(shape);
        }
        // Each joint's values in the lanes, one row per joint.
        let ready = qs.columns(dof, &mut s.cols);
        // The frames kept from the last batch, then none until this one has posed every body.
        let kept = s.kept_frames.take();
        if !ready {
            return None;
        }
        let mut reuse = 0u64;
        // Whether the comparison below wrote this batch's values over the kept ones.
        let mut compared = false;
        if let (Some(still), Some(id)) = (keep, kept)
            && id == lanes.id
            && dof < 64
            && s.kept_values.len() == dof
        {
            let mut same = 0u64;
            for (d, (c, v)) in s.cols.iter().zip(s.kept_values.iter_mut()).enumerate() {
                same |= u64::from(c[0].to_bits() == v.to_bits()) << d;
                // This batch's values, kept for the next (see below).
                *v = c[0];
            }
            compared = s.cols.len() == dof;
            let both = still & s.kept_groups;
            for (g, (gr, &dofs)) in self.groups.iter().zip(&self.group_dofs).enumerate().take(64) {
                if both >> g & 1 != 0 && dofs & !same == 0 && gr.body < 64 {
                    reuse |= 1 << gr.body;
                }
            }
        }
        if let Some(still) = keep {
            s.kept_groups = still;
            // Written over in the comparison above when it ran.
            if !compared {
                s.kept_values.clear();
                s.kept_values.extend(s.cols.iter().map(|c| c[0]));
            }
        }
        let mut w = s.work();
        let s = &mut w;
        s.rot[0] = lanes.base_r.map(|v| F8([v; LANES]));
        s.pos[0] = lanes.base_t.map(|v| F8([v; LANES]));
        // First every joint's sine and cosine (a prismatic joint's travel in `sin`): they depend
        // neither on one another nor on the frames, so their long chains of dependent operations
        // can overlap; the frames below only read them. (Computed body by body between the
        // frames: about 1% slower per MotionBenchMaker cage problem, 30 alternating rounds.)
        let kept = |k: usize| k + 1 < 64 && reuse >> (k + 1) & 1 != 0;
        for (k, (b, a)) in lanes.bodies.iter().zip(&self.angles).enumerate() {
            if kept(k) {
                continue;
            }
            // The joint's value in each lane, read first, then turned into the angle in one
            // vectorisable pass (reading and arithmetic lane by lane in one loop was not).
            // (`x · 1 + 0 + 0` is `x` but for the sign of a zero, which no test reads.)
            let x = s.cols.get(a.dof)?;
            let v = if b.value_is_angle { *x } else { x.map(|x| (x * a.scale + a.add) + a.offset) };
            // `fold` with `&`, not `all`: no branch per lane.
            let finite = v.iter().fold(true, |f, v| f & (v.abs() < SIN_COS_RANGE));
            if !finite || (b.prismatic && v.iter().any(|x| x.abs() > b.travel)) {
                return None;
            }
            if b.prismatic {
                s.sin[k] = F8(v.map(|x| x as f32));
            } else {
                // Every `|v|` is below `SIN_COS_RANGE` (checked above).
                let (sn, cs) = sin_cos_f32(&v, O::FUSED);
                (s.sin[k], s.cos[k]) = (F8(sn), F8(cs));
            }
        }
        // The frame just computed (its index in `s.rot`), still in registers.
        let mut last: Option<(usize, R<O>, P<O>)> = None;
        for (k, b) in lanes.bodies.iter().enumerate() {
            if kept(k) {
                // The frame the last batch left; the next body reads its parent's from memory.
                last = None;
                continue;
            }
            // The parent's frame in registers, built entry by entry (an array built by
            // `from_fn` went through `memcpy`); the previous body's as it was computed.
            let (pr, pp): (R<O>, P<O>) = match last {
                Some((i, r, p)) if i == b.parent => (r, p),
                _ => (load(o, &s.rot[b.parent]), load(o, &s.pos[b.parent])),
            };
            // A translation along one axis (five of the UR5's six): its one column (the same
            // values, see `place_on`).
            let mut out_p = match b.t_axis {
                Some(0) => place_on::<O, 0>(o, &pr, &pp, &b.pre_t),
                Some(1) => place_on::<O, 1>(o, &pr, &pp, &b.pre_t),
                Some(2) => place_on::<O, 2>(o, &pr, &pp, &b.pre_t),
                _ => place(o, &pr, &pp, &b.pre_t),
            };
            // A revolute joint right after the parent's frame, with no permutation, no sign and
            // nothing after (three of the UR5's six joints): the fused turn below without its
            // products by 1, which leave their factors as they are (the same bits).
            if b.plain {
                let (sn, cs) = (L::load(o, s.sin[k]), L::load(o, s.cos[k]));
                // `-sn`, exactly, for the differences as fused sums.
                let ns = sn * splat(o, -1.0);
                let out_r = [
                    pr[0].mul_add(cs, pr[1] * sn),
                    pr[1].mul_add(cs, pr[0] * ns),
                    pr[2],
                    pr[3].mul_add(cs, pr[4] * sn),
                    pr[4].mul_add(cs, pr[3] * ns),
                    pr[5],
                    pr[6].mul_add(cs, pr[7] * sn),
                    pr[7].mul_add(cs, pr[6] * ns),
                    pr[8],
                ];
                store(&out_r, &mut s.rot[k + 1]);
                store(&out_p, &mut s.pos[k + 1]);
                last = Some((k + 1, out_r, out_p));
                continue;
            }
            // A revolute joint after a signed permutation, with nothing after it (every joint
            // of the UR5): the turn reads the parent's columns as picked and takes their signs
            // into the sine and cosine. `(s c) x` is `s (c x)` and `s x` exactly for `s = ±1`,
            // so the entries are the general path's below, to the bit.
            if let (Pre::Perm(perm, sign), false, None) = (&b.pre, b.prismatic, &b.post) {
                let (sn, cs) = (L::load(o, s.sin[k]), L::load(o, s.cos[k]));
                let (s0, s1) = (splat(o, sign[0]), splat(o, sign[1]));
                // `-s s0` (exactly: the signs are ±1), for the differences as fused sums.
                let (c0, m0, c1, n1) = (cs * s0, sn * splat(o, -sign[0]), cs * s1, sn * s1);
                let s2 = splat(o, sign[2]);
                // The columns picked from the registers (indexing memory by the column made the
                // compiler copy the parent's frame to the stack), and the product as one array
                // expression (entries assigned in a loop went through `memcpy`).
                let [a0, a1, a2] = column(&pr, perm[0]);
                let [b0, b1, b2] = column(&pr, perm[1]);
                let [d0, d1, d2] = column(&pr, perm[2]);
                let out_r = [
                    a0.mul_add(c0, b0 * n1),
                    b0.mul_add(c1, a0 * m0),
                    d0 * s2,
                    a1.mul_add(c0, b1 * n1),
                    b1.mul_add(c1, a1 * m0),
                    d1 * s2,
                    a2.mul_add(c0, b2 * n1),
                    b2.mul_add(c1, a2 * m0),
                    d2 * s2,
                ];
                store(&out_r, &mut s.rot[k + 1]);
                store(&out_p, &mut s.pos[k + 1]);
                last = Some((k + 1, out_r, out_p));
                continue;
            }
            // `parent * pre` (for a signed permutation: the parent's columns, picked and
            // signed, read from memory as picked).
            let mut out_r = match &b.pre {
                Pre::Perm(perm, sign) => {
                    let parent_r = &s.rot[b.parent];
                    let e = |r: usize, c: usize| L::load(o, parent_r[3 * r + perm[c] as usize]) * splat(o, sign[c]);
                    [e(0, 0), e(0, 1), e(0, 2), e(1, 0), e(1, 1), e(1, 2), e(2, 0), e(2, 1), e(2, 2)]
                }
                Pre::Mat(m) => mul_m(o, &pr, m),
            };
            if b.prismatic {
                let vf = L::load(o, s.sin[k]);
                let ax = [splat(o, b.axis[0]) * vf, splat(o, b.axis[1]) * vf, splat(o, b.axis[2]) * vf];
                for r in 0..3 {
                    let along = out_r[3 * r] * ax[0] + out_r[3 * r + 1] * ax[1] + out_r[3 * r + 2] * ax[2];
                    out_p[r] += along;
                }
            } else {
                let (sn, cs) = (L::load(o, s.sin[k]), L::load(o, s.cos[k]));
                let ns = sn * splat(o, -1.0);
                for r in 0..3 {
                    let (c0, c1) = (out_r[3 * r], out_r[3 * r + 1]);
                    out_r[3 * r] = c0.mul_add(cs, c1 * sn);
                    out_r[3 * r + 1] = c1.mul_add(cs, c0 * ns);
                }
            }
            if let Some((qr, qt)) = &b.post {
                out_p = place(o, &out_r, &out_p, qt);
                out_r = mul_m(o, &out_r, qr);
            }
            store(&out_r, &mut s.rot[k + 1]);
            store(&out_p, &mut s.pos[k + 1]);
            last = Some((k + 1, out_r, out_p));
        }
        // Every body posed: the next probe batch may keep these frames.
        *s.kept_frames = keep.map(|_| lanes.id);
        Some(w)
    }

    /// World centre of link `l`'s bounding sphere per lane, once per batch.
    #[inline(always)]
    fn lane_link_centre<O: Ops>(&self, o: O, l: usize, s: &mut Work<'_>) -> P<O> {
        if s.link_posed[l] != s.batch {
            s.link_posed[l] = s.batch;
            let b = self.links[l].body;
            let (rot, pos) = (load(o, &s.rot[b]), load(o, &s.pos[b]));
            store(&place(o, &rot, &pos, &self.lanes.links[l]), &mut s.link_c[l]);
        }
        load(o, &s.link_c[l])
    }

    /// Sphere `i` (centre `ci`) against each sphere of link `b` (posed) in the lanes `mask`
    /// with the pair margin `pg` (plus the allowance, rounded up): `Err` with the lanes certainly
    /// in contact, else `Ok` with the lanes within the margin.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn sphere_against_link<O: Ops>(
        &self,
        o: O,
        (i, ci): (usize, &P<O>),
        b: usize,
        mask: u32,
        pg: f32,
        grow: f64,
        s: &Work<'_>,
    ) -> Result<u32, u32> {
        let lanes = &self.lanes;
        let lb = &self.links[b];
        // The other link's spheres as slices, so that the loop indexes nothing (a bounds check
        // per sphere and slice was about 2% of the Fetch's planning instructions). Were one
        // short, every lane of `mask` would be left within the margin: settled by nobody here.
        let span = lb.first..lb.end;
        let (Some(centres), Some(up_j), Some(r_j), Some(&up_i), Some(&r_i)) = (
            s.centre.get(span.clone()),
            lanes.radius_up.get(span.clone()),
            self.radius.get(span),
            lanes.radius_up.get(i),
            self.radius.get(i),
        ) else {
            return Ok(mask);
        };
        let mut touch = 0;
        for ((c, &up_j), &r_j) in centres.iter().zip(up_j).zip(r_j) {
            let d2 = dist2(ci, &load(o, c));
            let t = mask & within(d2, thr(up_i, up_j, pg));
            if t != 0 {
                let hit = t & within(d2, contact_thr(r_i + r_j, grow));
                if hit != 0 {
                    return Err(hit);
                }
                touch |= t;
            }
        }
        Ok(touch)
    }

    /// World centres of link `l`'s spheres per lane, once per batch.
    #[inline(always)]
    fn pose_lane_link<O: Ops>(&self, o: O, l: usize, s: &mut Work<'_>) {
        if s.posed[l] == s.batch {
            return;
        }
        s.posed[l] = s.batch;
        let link = &self.links[l];
        let (rot, pos) = (load(o, &s.rot[link.body]), load(o, &s.pos[link.body]));
        for k in link.first..link.end {
            store(&place(o, &rot, &pos, &self.lanes.balls[k]), &mut s.centre[k]);
        }
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::{Isometry3, UnitQuaternion, Vector3};

    use super::super::simd8::Base;
    use super::*;
    use crate::collision::World;

    fn cuboid(rot: UnitQuaternion<f64>) -> Solid32 {
        let iso = Isometry3::from_parts(Vector3::new(0.3, -0.2, 0.5).into(), rot);
        let solid = Solid::new(&World::Cuboid { iso, half: Vector3::new(0.1, 0.2, 0.05) });
        let s32 = Solids32::new(&[solid]).expect("a box has a closed form");
        s32.solids[0].clone()
    }

    /// A box turned about z only takes the short form of `local`, and it gives the full
    /// product's values; a tilted box does not take it.
    #[test]
    fn yaw_boxes_take_the_short_form_with_the_same_values() {
        let mut rng = crate::Rng::new(5);
        for _ in 0..50 {
            let yaw = rng.range(-3.2, 3.2);
            let Solid32::Cuboid { rt, t, yaw: short, .. } = cuboid(UnitQuaternion::from_euler_angles(0.0, 0.0, yaw))
            else {
                panic!("a cuboid")
            };
            assert!(short, "yaw {yaw}: {rt:?}");
            let p: P<Base> =
                std::array::from_fn(|_| L::load(Base, F8(std::array::from_fn(|_| rng.range(-2.0, 2.0) as f32))));
            let (a, b) = (local(Base, &rt, &t, true, &p), local(Base, &rt, &t, false, &p));
            for k in 0..3 {
                let (a, b) = (a[k].store().0, b[k].store().0);
                for i in 0..LANES {
                    assert_eq!(a[i].abs(), b[i].abs(), "coordinate {k}, lane {i}");
                }
            }
            let tilted = cuboid(UnitQuaternion::from_euler_angles(rng.range(0.1, 1.0), 0.0, yaw));
            assert!(matches!(tilted, Solid32::Cuboid { yaw: false, .. }));
        }
    }

    /// The solids go largest first, and their order changes no conclusion: on random batches
    /// among solids of three kinds, with the solids in the order given (unsorted) and sorted, a
    /// batch with no certain contact in either settles the same lanes, and every lane a batch
    /// finds in certain contact collides in double precision.
    #[test]
    fn solids_go_largest_first_and_their_order_changes_no_conclusion() {
        use crate::Shape;
        use crate::collision::{CollisionModel, Environment, Obstacle, RobotGeom};
        let robot = every_body_form();
        let dof = robot.dof();
        let geom = SphereGeom::new(&RobotGeom::new(&robot), false).expect("a sphere robot");
        let mut rng = crate::Rng::new(41);
        let mut env = Environment::new();
        let mut solids = Vec::new();
        for k in 0..8 {
            let at = Isometry3::from_parts(
                Vector3::new(rng.range(-0.6, 0.6), rng.range(-0.6, 0.6), rng.range(0.0, 0.9)).into(),
                UnitQuaternion::from_euler_angles(0.0, 0.0, rng.range(-3.0, 3.0)),
            );
            // Sizes growing with `k`: the order given is smallest first.
            let size = 0.03 + 0.02 * k as f64;
            let shape = match k % 3 {
                0 => Shape::cuboid(size, 0.5 * size, size),
                1 => Shape::sphere(size),
                _ => Shape::cylinder(0.5 * size, size),
            };
            solids.push(Solid::new(&World::from_shape(&shape, &at)));
            env.add(Obstacle::new(format!("o{k}"), at, shape));
        }
        let sorted = Solids32::new(&solids).expect("closed forms");
        let radii = sorted.bound_r.clone();
        assert!(radii.windows(2).all(|w| w[0] >= w[1]), "largest first: {radii:?}");
        // The order given, as `new` found it before sorting.
        let mut given = sorted.clone();
        given.solids.reverse();
        given.bound_c.reverse();
        given.bound_r.reverse();
        given.id = ProgramId::next();
        assert!(given.bound_r.windows(2).any(|w| w[0] < w[1]), "test setup: an unsorted order");
        let model = CollisionModel::new(&robot, env);
        let margins = LaneMargins {
            link: &[],
            pair: &[],
            uniform: Some(0.02),
            step: None,
            pairs_of_near: false,
            along: false,
            still: 0,
            settled: 0,
            pairs_settled: false,
        };
        let (mut s1, mut s2) = (LaneScratch::new(), LaneScratch::new());
        let (mut same, mut hits) = (0, 0);
        for _ in 0..400 {
            // Eight configurations near one another, as a planner's batches are.
            let q0 = robot.random_configuration(&mut rng);
            let qs: Vec<f64> =
                (0..LANES).flat_map(|_| q0.iter().map(|v| v + rng.range(-0.05, 0.05)).collect::<Vec<_>>()).collect();
            let a = geom.free_lanes(LaneInput::Rows(&qs), dof, &sorted, margins, &mut s1);
            let b = geom.free_lanes(LaneInput::Rows(&qs), dof, &given, margins, &mut s2);
            for answer in [a, b] {
                for (i, q) in qs.chunks(dof).enumerate() {
                    if answer.hit & (1 << i) != 0 {
                        assert!(model.collides(q), "lane {i} in contact but free: {q:?}");
                        hits += 1;
                    }
                }
            }
            if a.hit == 0 && b.hit == 0 {
                assert_eq!(a.free, b.free, "{qs:?}");
                same += 1;
            }
        }
        assert!(same > 50 && hits > 50, "{same} batches without contact, {hits} lanes in contact");
    }

    /// A sphere arm with every form of body the batch poses: revolute joints after signed
    /// permutations with either sign (the fused turn), after a skewed origin (a matrix) and
    /// with a DH-style turn after the joint, a prismatic joint and a mimic joint.
    fn every_body_form() -> crate::Robot {
        every_body_form_of(0.04)
    }

    /// [`every_body_form`] with spheres of radius `r`.
    fn every_body_form_of(r: f64) -> crate::Robot {
        every_body_form_with(r, true)
    }

    /// [`every_body_form_of`], with the DH-style turn after the last arm joint or without it.
    fn every_body_form_with(r: f64, turn_after: bool) -> crate::Robot {
        use crate::{JointKind, JointLimits, PlacedShape, RobotBuilder, Shape};
        let balls = |points: &[[f64; 3]]| -> Vec<PlacedShape> {
            points
                .iter()
                .map(|p| PlacedShape::new(Isometry3::translation(p[0], p[1], p[2]), Shape::sphere(r)))
                .collect()
        };
        let at = |x: f64, y: f64, z: f64, r: f64, p: f64, w: f64| {
            Isometry3::from_parts(Vector3::new(x, y, z).into(), UnitQuaternion::from_euler_angles(r, p, w))
        };
        let half = std::f64::consts::FRAC_PI_2;
        let lim = JointLimits::new(-3.0, 3.0, 1.0, 1.0);
        let id = Isometry3::identity();
        let mut b = RobotBuilder::new("every-body-form").base(at(0.1, -0.2, 0.3, 0.0, 0.0, 0.4));
        let mut parent = b.link("base", balls(&[[0.0, 0.0, 0.05]]));
        // (origin, axis, kind, after the joint); the last a DH-style turn and shift.
        let dh = if turn_after { at(0.02, 0.0, 0.01, 0.2, 0.0, 0.0) } else { id };
        let joints = [
            (at(0.0, 0.0, 0.1, 0.0, 0.0, 0.0), Vector3::z(), JointKind::Revolute, id),
            (at(0.0, 0.13, 0.0, 0.0, half, 0.0), Vector3::y(), JointKind::Revolute, id),
            (at(0.0, -0.12, 0.42, half, 0.0, 0.0), -Vector3::x(), JointKind::Revolute, id),
            (at(0.05, 0.0, 0.3, 0.3, -0.7, 1.1), Vector3::z(), JointKind::Revolute, id),
            (at(0.0, 0.09, 0.0, -half, 0.0, half), Vector3::y(), JointKind::Prismatic, id),
            (at(0.0, 0.0, 0.09, 0.0, 0.0, 0.0), -Vector3::z(), JointKind::Revolute, dh),
        ];
        for (k, (origin, axis, kind, post)) in joints.into_iter().enumerate() {
            let link = b.link(format!("l{k}"), balls(&[[0.0, 0.0, 0.0], [0.1, 0.02, 0.05], [0.0, 0.2, -0.03]]));
            b.joint(format!("j{k}"), kind, parent, link, origin, axis, 0.0, post, lim);
            parent = link;
        }
        let finger = b.link("finger", balls(&[[0.03, 0.0, 0.02]]));
        let j = b.joint(
            "finger",
            JointKind::Revolute,
            parent,
            finger,
            at(0.0, 0.0, 0.05, 0.0, half, 0.0),
            Vector3::z(),
            0.0,
            id,
            lim,
        );
        b.mimic(j, "j5".to_string(), -0.5, 0.1);
        b.build().expect("a valid arm")
    }

    /// The lanes' joint rows are the configurations' values, for six and seven joints; other
    /// lengths write nothing (the batch then reads the configurations body by body).
    #[test]
    fn joint_rows_hold_each_configurations_values() {
        let mut rng = crate::Rng::new(23);
        for d in [6usize, 7] {
            let qs: Vec<f64> = (0..LANES * d).map(|_| rng.range(-4.0, 4.0)).collect();
            let mut cols = Vec::new();
            let ok = if d == 6 { transpose::<6>(&qs, &mut cols) } else { transpose::<7>(&qs, &mut cols) };
            assert!(ok && cols.len() == d, "{d}");
            for (i, q) in qs.chunks(d).enumerate() {
                for (j, &v) in q.iter().enumerate() {
                    assert_eq!(cols[j][i].to_bits(), v.to_bits(), "joint {j} of configuration {i}");
                }
            }
            let mut untouched = vec![[1.0; LANES]; 2];
            assert!(!transpose::<6>(&qs[..LANES * d - 1], &mut untouched), "{d}: one value short");
            assert!(!transpose::<7>(&[qs.clone(), vec![0.0; 9]].concat(), &mut untouched), "{d}: too many");
            assert_eq!(untouched, vec![[1.0; LANES]; 2], "nothing written");
        }
    }

    /// The sphere centres of a posed batch against double precision, lane by lane in `lanes`:
    /// each coordinate within the batch's error bound. The largest error.
    fn centres_within_bound(
        geom: &SphereGeom,
        w: &mut Work<'_>,
        qs: &[f64],
        lanes: std::ops::Range<usize>,
        f: &mut super::super::SphereScratch,
    ) -> f64 {
        let (bound, dof) = (geom.lanes.centre_err, qs.len() / LANES);
        for l in 0..geom.links.len() {
            geom.pose_lane_link(Base, l, w);
        }
        let mut worst: f64 = 0.0;
        for i in lanes {
            geom.pose(&qs[i * dof..(i + 1) * dof], f);
            for (k, c) in geom.centre.iter().enumerate() {
                let b = geom.links.iter().find(|l| (l.first..l.end).contains(&k)).expect("a link").body;
                let exact = f.rot[b] * c + f.pos[b];
                for d in 0..3 {
                    let e = (f64::from(w.centre[k][d].0[i]) - exact[d]).abs();
                    assert!(e <= bound, "sphere {k}, coordinate {d}, lane {i}: off by {e:e} (bound {bound:e})");
                    worst = worst.max(e);
                }
            }
        }
        worst
    }

    /// A group is still when the joints that move leave its body's pose as it was, and only
    /// then: each joint moved alone, then pairs of joints, against the double-precision poses.
    #[test]
    fn still_groups_are_those_whose_bodies_keep_their_poses() {
        let robot = every_body_form();
        let geom = SphereGeom::new(&crate::collision::RobotGeom::new(&robot), false).expect("a sphere robot");
        let dof = robot.dof();
        let mut rng = crate::Rng::new(3);
        let mut f = super::super::SphereScratch::new();
        for trial in 0..40 {
            let a = robot.random_configuration(&mut rng);
            let mut b = a.clone();
            let mut moving = 0u64;
            for (d, v) in b.iter_mut().enumerate() {
                if d == trial % dof || (trial >= dof && rng.range(0.0, 1.0) < 0.3) {
                    *v += 0.3;
                    moving |= 1 << d;
                }
            }
            geom.pose(&a, &mut f);
            let before: Vec<_> = geom.groups.iter().map(|g| (f.rot[g.body], f.pos[g.body])).collect();
            geom.pose(&b, &mut f);
            let still = geom.still_groups(moving, dof);
            // From the steps, with and without the end: the same groups, or none when only
            // those no joint moves (the base) would be.
            let fixed = geom.group_dofs.iter().enumerate().filter(|(_, m)| **m == 0).fold(0, |f, (g, _)| f | 1 << g);
            let along = if still & !fixed == 0 { 0 } else { still };
            let delta: Vec<f64> = a.iter().zip(&b).map(|(x, y)| y - x).collect();
            assert_eq!(geom.still_along(&a, &delta, None), along, "trial {trial}");
            assert_eq!(geom.still_along(&a, &delta, Some(&b)), along, "trial {trial}");
            // An end that leaves the segment moves the joints it changes.
            let mut off = a.clone();
            off[dof - 1] += 1.0;
            let last = geom.still_groups(1 << (dof - 1), dof);
            assert_ne!(last & !fixed, 0);
            assert_eq!(geom.still_along(&a, &vec![0.0; dof], Some(&off)), last);
            for (gi, g) in geom.groups.iter().enumerate() {
                let kept = before[gi] == (f.rot[g.body], f.pos[g.body]);
                assert_eq!(still >> gi & 1 != 0, kept, "trial {trial}, joints {moving:b}, group {gi}");
            }
        }
        // Every joint moving: nothing is still, not even the base (answered at once).
        assert_eq!(geom.still_groups((1 << dof) - 1, dof), 0);
    }

    /// The batch's sphere centres lie within its error bound of the double-precision ones, on
    /// every form of body (a wrong column, sign or product would be off by centimetres).
    #[test]
    fn batch_centres_are_within_their_bound_of_double_precision() {
        let robot = every_body_form();
        let geom = SphereGeom::new(&crate::collision::RobotGeom::new(&robot), false).expect("a sphere robot");
        let bound = geom.lanes.centre_err;
        assert!(bound.is_finite() && bound > 0.0 && bound < 1e-3, "bound {bound:e}");
        // The fused turn (a permutation, revolute, nothing after), a permutation on the general
        // path, and a matrix.
        let bodies = &geom.lanes.bodies;
        let fused = |b: &Body| matches!(b.pre, Pre::Perm(..)) && !b.prismatic && b.post.is_none();
        assert!(bodies.iter().any(fused), "{bodies:?}");
        assert!(bodies.iter().any(|b| matches!(b.pre, Pre::Perm(..)) && !fused(b)), "{bodies:?}");
        assert!(bodies.iter().any(|b| matches!(b.pre, Pre::Mat(..))), "{bodies:?}");
        // A plain turn (no permutation), a fused one that is not plain, translations along one
        // axis and not.
        assert!(bodies.iter().any(|b| b.plain) && bodies.iter().any(|b| fused(b) && !b.plain), "{bodies:?}");
        assert!(bodies.iter().any(|b| b.t_axis.is_some()), "{bodies:?}");
        assert!(bodies.iter().any(|b| b.t_axis.is_none()), "{bodies:?}");
        let dof = robot.dof();
        let mut rng = crate::Rng::new(17);
        let mut s = LaneScratch::new();
        let mut f = super::super::SphereScratch::new();
        let mut worst: f64 = 0.0;
        for k in 0..200 {
            let qs: Vec<f64> = (0..LANES).flat_map(|_| robot.random_configuration(&mut rng)).collect();
            // The batch numbers wrap here, with marks as new (0): a link's centres kept from
            // the batch before would be off by far more than the bound.
            if k == 1 {
                s.batch = u32::MAX;
                s.posed.fill(0);
                s.link_posed.fill(0);
            }
            let mut w = geom.pose_lanes(Base, RowsIn(&qs), dof, None, &mut s).expect("posed");
            worst = worst.max(centres_within_bound(&geom, &mut w, &qs, 0..LANES, &mut f));
        }
        eprintln!("largest centre error {worst:e} of a bound {bound:e}");
    }

    /// Quarter turns written in decimals (URDF style) take the permutation nearest them, within
    /// [`NEAR_PERMUTATION`]: the centres stay within the error bound of double precision (which
    /// counts each permutation's deviation); a turn further off (1.5708) keeps its matrix.
    #[test]
    fn near_quarter_turns_take_permutations_within_their_bound() {
        use crate::{JointKind, JointLimits, PlacedShape, RobotBuilder, Shape};
        // The decimals of URDF files as offsets from a quarter turn (clippy refuses the literals):
        // 1.570796 (3.3e-7 off), 1.57079632679 (4.9e-12 off), 1.5708 (3.7e-6 off).
        let quarter = std::f64::consts::FRAC_PI_2;
        let q = quarter - 3.267_948_966e-7;
        let turns = [
            (q, 0.0, 0.0),
            (-q, 0.0, 0.0),
            (quarter - 4.896_6e-12, 0.0, 0.0),
            (0.0, q, 0.0),
            (0.0, 0.0, -q),
            (quarter + 3.673_205e-6, 0.0, 0.0),
        ];
        let mut b = RobotBuilder::new("decimal-turns");
        let mut parent = b.link("base", vec![]);
        for (k, (r, p, y)) in turns.into_iter().enumerate() {
            let balls = vec![
                PlacedShape::new(Isometry3::translation(0.0, 0.0, 0.05), Shape::sphere(0.03)),
                PlacedShape::new(Isometry3::translation(0.08, 0.02, 0.1), Shape::sphere(0.03)),
            ];
            let link = b.link(format!("l{k}"), balls);
            let origin = Isometry3::from_parts(
                Vector3::new(0.02 * k as f64, 0.1, 0.15).into(),
                UnitQuaternion::from_euler_angles(r, p, y),
            );
            let lim = JointLimits::new(-3.0, 3.0, 1.0, 1.0);
            b.joint(
                format!("j{k}"),
                JointKind::Revolute,
                parent,
                link,
                origin,
                Vector3::z(),
                0.0,
                Isometry3::identity(),
                lim,
            );
            parent = link;
        }
        let robot = b.build().expect("a valid arm");
        let geom = SphereGeom::new(&crate::collision::RobotGeom::new(&robot), false).expect("a sphere robot");
        let kinds: Vec<bool> = geom.lanes.bodies.iter().map(|b| matches!(b.pre, Pre::Perm(..))).collect();
        assert_eq!(kinds, [true, true, true, true, true, false], "permutations but for the last body");
        // Inexact ones (the turn about the joint's own axis joins its angle; the others stay):
        // the nearness is what is tested.
        let near = geom.bodies.iter().skip(1).filter(|b| b.pre_perm.is_none()).count();
        assert!(near >= 4, "{near} inexact turns");
        let bound = geom.lanes.centre_err;
        let dof = robot.dof();
        let mut rng = crate::Rng::new(29);
        let (mut s, mut f) = (LaneScratch::new(), super::super::SphereScratch::new());
        let mut worst: f64 = 0.0;
        for _ in 0..300 {
            let qs: Vec<f64> = (0..LANES).flat_map(|_| robot.random_configuration(&mut rng)).collect();
            let mut w = geom.pose_lanes(Base, RowsIn(&qs), dof, None, &mut s).expect("posed");
            worst = worst.max(centres_within_bound(&geom, &mut w, &qs, 0..LANES, &mut f));
        }
        // The deviations (3.3e-7 a body) are what the batch is off by, not its rounding.
        assert!(worst > 1e-7, "largest centre error {worst:e}");
        eprintln!("largest centre error {worst:e} of a bound {bound:e}");
    }

    /// A prismatic joint's travel is its reach within its limits (3 m here, not
    /// [`PRISMATIC_BOUND`]): a batch with the joint at either limit is posed, within the bound
    /// of double precision; one with a lane past the limit is left to the `f64` query.
    #[test]
    fn prismatic_travel_is_the_joints_reach() {
        let robot = every_body_form();
        let geom = SphereGeom::new(&crate::collision::RobotGeom::new(&robot), false).expect("a sphere robot");
        let travels: Vec<f64> = geom.lanes.bodies.iter().filter(|b| b.prismatic).map(|b| b.travel).collect();
        assert_eq!(travels.len(), 1, "test setup: one prismatic joint");
        assert!(travels[0] >= 3.0 && travels[0] < 3.0 + 1e-6, "travel {}", travels[0]);
        // Joint 4 is the prismatic one (limits ±3).
        let dof = robot.dof();
        let mut rng = crate::Rng::new(5);
        let mut s = LaneScratch::new();
        let mut f = super::super::SphereScratch::new();
        for (at, posed) in [(3.0, true), (-3.0, true), (3.0 + 1e-6, false), (-3.0 - 1e-6, false), (20.0, false)] {
            let mut qs: Vec<f64> = (0..LANES).flat_map(|_| robot.random_configuration(&mut rng)).collect();
            qs[3 * dof + 4] = at;
            let w = geom.pose_lanes(Base, RowsIn(&qs), dof, None, &mut s);
            assert_eq!(w.is_some(), posed, "prismatic joint at {at}");
            let Some(mut w) = w else { continue };
            centres_within_bound(&geom, &mut w, &qs, 3..4, &mut f);
        }
    }

    /// The single-precision sines and cosines stay within [`SIN_COS_ERR`] of `f64`'s (itself
    /// within 2^-52 of the exact values) on dense samples of several turns, around every
    /// multiple of π/4 (where the reduction switches quadrant and the reduced argument is
    /// largest), and far out; the largest error is reported against the bound.
    #[test]
    fn single_precision_sines_and_cosines_are_within_their_bound() {
        let mut xs: Vec<f64> = (0..400_000).map(|k| -13.0 + 26.0 * k as f64 / 400_000.0).collect();
        for m in -40..=40 {
            let c = m as f64 * std::f64::consts::FRAC_PI_4;
            xs.extend((-200..=200).map(|k| c + k as f64 * 1e-9));
            xs.extend((-200..=200).map(|k| c + k as f64 * 3e-5));
        }
        let mut rng = crate::Rng::new(11);
        xs.extend((0..100_000).map(|_| rng.range(-1000.0, 1000.0)));
        xs.extend((0..20_000).map(|_| rng.range(-1_000_000.0, 1_000_000.0)));
        let bound = SIN_COS_ERR - 2f64.powi(-52);
        let mut worst: f64 = 0.0;
        // Fused and not (both forms run in planning).
        for (chunk, fused) in xs.chunks_exact(LANES).flat_map(|c| [(c, false), (c, true)]) {
            let x: [f64; LANES] = std::array::from_fn(|i| chunk[i]);
            let (sn, cs) = sin_cos_f32(&x, fused);
            for i in 0..LANES {
                let (s, c) = x[i].sin_cos();
                let e = (f64::from(sn[i]) - s).abs().max((f64::from(cs[i]) - c).abs());
                assert!(e <= bound, "x = {}: sin {} cos {} against {s} {c}", x[i], sn[i], cs[i]);
                worst = worst.max(e);
            }
        }
        // The bound is not loose by orders of magnitude (it would hide a wrong kernel).
        assert!(worst > 0.25 * SIN_COS_ERR, "largest error {worst:e} of a bound {SIN_COS_ERR:e}");
        eprintln!("largest error {:.2}u of {:.0}u", worst / U, SIN_COS_ERR / U);
    }

    /// A segment's points written into the lanes joint by joint are the same points as rows,
    /// to the bit, and settle exactly what the rows do (free and contact lanes; the baseline
    /// instructions nothing opposite), with the end over lane 0 or not, unused lanes repeating
    /// the last point: on an arm with every body form among boxes, balls and cylinders, on
    /// random segments.
    #[test]
    fn segment_lanes_settle_what_their_rows_do() {
        use crate::collision::{CollisionModel, Environment, Obstacle};
        use crate::{ConfigSpace, Shape};
        let robot = every_body_form();
        let dof = robot.dof();
        let mut env = Environment::new();
        let mut rng = crate::Rng::new(23);
        for k in 0..9 {
            let at = Isometry3::from_parts(
                Vector3::new(rng.range(-0.8, 0.8), rng.range(-0.8, 0.8), rng.range(0.0, 1.0)).into(),
                UnitQuaternion::from_euler_angles(0.0, 0.0, rng.range(-3.0, 3.0)),
            );
            let shape = match k % 3 {
                0 => Shape::cuboid(0.1, 0.15, 0.08),
                1 => Shape::sphere(0.12),
                _ => Shape::cylinder(0.06, 0.2),
            };
            env.add(Obstacle::new(format!("o{k}"), at, shape));
        }
        let model = CollisionModel::new(&robot, env);
        assert!(model.certifies_in_batches());
        let mut s = model.scratch();
        let mut base = model.scratch().with_baseline_vectors();
        let (mut free, mut hit) = (0u32, 0u32);
        for k in 0..400 {
            let a = robot.random_configuration(&mut rng);
            let b = robot.random_configuration(&mut rng);
            let delta: Vec<f64> = a.iter().zip(&b).map(|(a, b)| b - a).collect();
            let n = 2 + k % 23;
            let used = 3 + k % 6;
            let end = (k % 2 == 0).then_some(&b[..]);
            let mut ids = [0u32; LANES];
            for (l, id) in ids.iter_mut().enumerate() {
                let i = (l.min(used - 1) * 7 + k) % n;
                *id = if end.is_some() && l == 0 { 0 } else { i.max(1) as u32 };
            }
            let mut rows = Vec::new();
            for &i in &ids {
                match end {
                    Some(e) if rows.is_empty() => rows.extend_from_slice(e),
                    _ => {
                        let at = rows.len();
                        rows.resize(at + dof, 0.0);
                        ConfigSpace::step_into(&a, &delta, f64::from(i) / n as f64, &mut rows[at..]);
                    }
                }
            }
            // The lanes hold the rows' values to the bit.
            let segment = SegmentIn { a: &a, delta: &delta, n: n as u32, ids, end };
            let (mut by_cols, mut by_rows_cols) = (Vec::new(), Vec::new());
            assert!(segment.columns(dof, &mut by_cols) && RowsIn(&rows).columns(dof, &mut by_rows_cols));
            let bits = |c: &[[f64; LANES]]| c.iter().flat_map(|c| c.map(f64::to_bits)).collect::<Vec<_>>();
            assert_eq!(bits(&by_cols), bits(&by_rows_cols), "segment {k}");
            let input = LaneInput::Segment(segment);
            let by_segment = model.settle_lanes(input, used, 0.0, &mut s).expect("a batch");
            let by_rows = model.settle_lanes(LaneInput::Rows(&rows), used, 0.0, &mut s).expect("a batch");
            assert_eq!(by_segment, by_rows, "segment {k}");
            // The baseline (products rounded before their sums, where AVX2 fuses them) may
            // settle other lanes near a threshold, never the opposite.
            let on_base = model.settle_lanes(input, used, 0.0, &mut base).expect("a batch");
            assert_eq!(on_base.free & by_rows.colliding, 0, "segment {k}");
            assert_eq!(on_base.colliding & by_rows.free, 0, "segment {k}");
            free += by_rows.free.count_ones();
            hit += u32::from(by_rows.colliding != 0);
        }
        // Both kinds of answer were met.
        assert!(free > 400 && hit > 40, "{free} free lanes, {hit} contacts");
    }

    /// A segment's lanes hold its points to the bit for every number of joints (the unrolled
    /// six, seven and eight, and the others four at a time and then one by one), with the end
    /// over lane 0 or not; values of the wrong length give no lanes.
    #[test]
    fn segment_columns_hold_the_points_for_any_number_of_joints() {
        let mut rng = crate::Rng::new(31);
        for dof in 1..=15 {
            for k in 0..20 {
                let a: Vec<f64> = (0..dof).map(|_| rng.range(-4.0, 4.0)).collect();
                let delta: Vec<f64> = (0..dof).map(|_| rng.range(-2.0, 2.0)).collect();
                let b: Vec<f64> = (0..dof).map(|_| rng.range(-4.0, 4.0)).collect();
                let n = 1 + k as u32 % 17;
                let ids: [u32; LANES] = std::array::from_fn(|i| (i as u32 * 3 + k as u32) % (n + 1));
                let end = (k % 2 == 0).then_some(&b[..]);
                let mut cols = vec![[7.0; LANES]; (k % 3) * 4];
                assert!(SegmentIn { a: &a, delta: &delta, n, ids, end }.columns(dof, &mut cols));
                assert_eq!(cols.len(), dof);
                let mut q = vec![0.0; dof];
                for (i, &id) in ids.iter().enumerate() {
                    match end {
                        Some(e) if i == 0 => q.copy_from_slice(e),
                        _ => crate::ConfigSpace::step_into(&a, &delta, f64::from(id) / f64::from(n), &mut q),
                    }
                    for j in 0..dof {
                        assert_eq!(cols[j][i].to_bits(), q[j].to_bits(), "dof {dof}, case {k}, lane {i}, joint {j}");
                    }
                }
                let short = &delta[..dof - 1];
                assert!(!SegmentIn { a: &a, delta: short, n, ids, end }.columns(dof, &mut cols));
                let end = Some(&b[..dof - 1]);
                assert!(!SegmentIn { a: &a, delta: &delta, n, ids, end }.columns(dof, &mut cols));
            }
        }
    }

    /// The thresholds a scratch keeps for a uniform margin follow the robot, the margin and
    /// the obstacles: one scratch passed between two robots of the same shape but other sphere
    /// radii, two sets of obstacles of different extent and three margins answers every batch
    /// as a fresh scratch does.
    #[test]
    fn kept_thresholds_follow_robot_margin_and_obstacles() {
        use crate::Shape;
        use crate::collision::{CollisionModel, Environment, Obstacle};
        let mut rng = crate::Rng::new(41);
        let near = |rng: &mut crate::Rng, far: f64| {
            let mut env = Environment::new();
            for k in 0..3 {
                let at = Vector3::new(rng.range(-0.7, 0.7), rng.range(-0.7, 0.7), rng.range(0.0, 0.9));
                let shape = if k % 2 == 0 { Shape::cuboid(0.06, 0.08, 0.05) } else { Shape::sphere(0.06) };
                env.add(Obstacle::new(format!("o{k}"), Isometry3::translation(at.x, at.y, at.z), shape));
            }
            // One far obstacle sets the scale of the rounding allowance.
            env.add(Obstacle::new("far", Isometry3::translation(far, 0.0, 0.0), Shape::sphere(0.1)));
            env
        };
        let (small, large) = (every_body_form_of(0.04), every_body_form_of(0.07));
        // The same near obstacles in each.
        let env = |far: f64| near(&mut crate::Rng::new(5), far);
        let first = CollisionModel::new(&small, env(3.0));
        // The same robot (the same program) among obstacles whose extent grows the allowance
        // by about 6 mm.
        let mut wide = first.clone();
        wide.set_environment(env(3000.0));
        let models = [first, CollisionModel::new(&large, env(3.0)), wide];
        let mut shared = models[0].scratch();
        let (mut differ_by_robot, mut differ_by_extent, mut settled) = (0, 0, 0);
        for k in 0..600 {
            // Model and margin at random: each kind of change from one batch to the next occurs.
            let margin = [0.0, 0.02, 0.05][rng.below(3)];
            let rows: Vec<f64> = (0..LANES).flat_map(|_| small.random_configuration(&mut rng)).collect();
            let answers: Vec<_> = models
                .iter()
                .map(|m| m.settle_lanes(LaneInput::Rows(&rows), LANES, margin, &mut m.scratch()).expect("a batch"))
                .collect();
            let m = rng.below(models.len());
            let kept = models[m].settle_lanes(LaneInput::Rows(&rows), LANES, margin, &mut shared).expect("a batch");
            assert_eq!(kept, answers[m], "batch {k}, model {m}, margin {margin}");
            differ_by_robot += usize::from(answers[0] != answers[1]);
            differ_by_extent += usize::from(answers[0] != answers[2]);
            settled += answers[m].free.count_ones();
        }
        // The robots and the extents answer differently often enough for a threshold of the
        // wrong one to show.
        assert!(
            differ_by_robot > 30 && differ_by_extent > 10 && settled > 500,
            "{differ_by_robot} / {differ_by_extent} batches differ, {settled} lanes free"
        );
    }

    /// The margin along the motion a batch gives each sphere bounds how far its centre moves
    /// over the piece, sampled densely in double precision, on an arm with every form of body
    /// but a turn after a joint (prismatic, mimic, matrices, permutations), at random
    /// midpoints and directions, short and long. It is not loose either: over all samples it
    /// is within 1.5 times the largest motion (the link margins: about 2-3 times). A robot with a
    /// turn after a joint gets no motion terms.
    #[test]
    fn margins_along_the_motion_bound_the_sampled_motion() {
        use crate::collision::RobotGeom;
        let posted = every_body_form_with(0.04, true);
        let geom = SphereGeom::new(&RobotGeom::new(&posted), false).expect("a sphere robot");
        assert!(!geom.lanes.twist_err.is_finite(), "a turn after a joint: no motion terms");
        let robot = every_body_form_with(0.04, false);
        let geom = SphereGeom::new(&RobotGeom::new(&robot), false).expect("a sphere robot");
        let err = geom.lanes.twist_err;
        assert!(err.is_finite() && err > 0.0 && err < 0.1, "{err:e}");
        let dof = robot.dof();
        let solid = Solid::new(&World::Sphere { c: nalgebra::Point3::new(0.4, 0.1, 0.5), r: 0.1 });
        let obstacles = Solids32::new(&[solid]).expect("a ball has a closed form");
        let mut rng = crate::Rng::new(29);
        let mut s = LaneScratch::new();
        let mut f = super::super::SphereScratch::new();
        let (mut worst, mut tightest): (f64, f64) = (f64::INFINITY, 0.0);
        for trial in 0..300 {
            // A direction of 0.001-0.3 per joint (rad or m), some joints still.
            let scale = [0.001, 0.03, 0.3][trial % 3];
            let dir: Vec<f64> =
                (0..dof).map(|_| if rng.below(5) == 0 { 0.0 } else { rng.range(-scale, scale) }).collect();
            let step: Vec<f64> = dir.iter().map(|d| d.abs()).collect();
            geom.set_lane_motion((&step, &dir), &mut s);
            let grow = geom.allowance(&obstacles, 0.05, 0.1).expect("finite");
            assert_eq!(s.motion.ready, Some(geom.lanes.id), "trial {trial}: terms held");
            let qs: Vec<f64> = (0..LANES).flat_map(|_| robot.random_configuration(&mut rng)).collect();
            let mut w = geom.pose_lanes(Base, RowsIn(&qs), dof, None, &mut s).expect("posed");
            for (l, link) in geom.links.iter().enumerate() {
                geom.pose_lane_link(Base, l, &mut w);
                for k in link.first..link.end {
                    let t = geom.along_thr(Base, l, k, grow, &mut w).store().0;
                    for (i, q) in qs.chunks(dof).enumerate() {
                        // The margin the threshold stands for, without the distance test's
                        // allowance (the threshold is rounded up: a hair more).
                        let m = f64::from(t[i]).sqrt() / f64::from(WIDEN) - f64::from(geom.lanes.radius_up[k]) - grow;
                        let at = |u: f64, f: &mut super::super::SphereScratch| {
                            let qu: Vec<f64> = q.iter().zip(&dir).map(|(a, d)| a + u * d).collect();
                            geom.pose(&qu, f);
                            f.rot[link.body] * geom.centre[k] + f.pos[link.body]
                        };
                        let p0 = at(0.0, &mut f);
                        let moved =
                            (0..=400).map(|j| (at(-1.0 + j as f64 / 200.0, &mut f) - p0).norm()).fold(0.0, f64::max);
                        assert!(
                            moved <= m + 1e-7,
                            "trial {trial}, sphere {k}, lane {i}: moves {moved:e}, margin {m:e}"
                        );
                        if moved > 1e-3 {
                            worst = worst.min(m / moved);
                            tightest = tightest.max(moved / m);
                        }
                    }
                }
            }
        }
        eprintln!("margin over the sampled motion: at least {worst:.3}; tightest {tightest:.3}");
        assert!(tightest > 1.0 / 1.5, "the margins are loose: the motion is at most {tightest} of them");
    }
}
