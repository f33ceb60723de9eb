//! Narrow phase: does one pair of posed shapes overlap, and how far apart are they?
//!
//! The robot hot path is spheres and capsules against spheres, boxes, capsules and cylinders, so
//! those pairs are answered here without GJK: in closed form (a capsule against a box by the
//! exact segment-box distance), or, for a capsule against a cylinder's curved side, by a search
//! whose Lipschitz bound decides the answer. Every other pair (box-box, box-cylinder,
//! cylinder-cylinder, meshes...) goes to parry's dispatcher.
//!
//! Distances are *signed*: positive is the gap between the shapes, negative is the penetration
//! depth (the smallest translation that separates them), for the analytic paths and for parry's
//! fallback (`query::contact` when `query::closest_points` says they intersect) alike.

use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};
use parry3d_f64::query::{self, ClosestPoints};
use parry3d_f64::shape::{Ball, Capsule, Cuboid, Cylinder, Segment, Shape as ParryShape, SupportMap};

use crate::geometry::{Climbing, ConvexHull, Shape};

/// The result of a distance query between two shapes, A and B.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Separation {
    /// Gap between the shapes (> 0), or minus the penetration depth (< 0) when they overlap.
    pub distance: f64,
    /// The point of A nearest to B (when overlapping: A's deepest point into B), world frame.
    pub point_a: Point3<f64>,
    /// The point of B nearest to A (when overlapping: B's deepest point into A), world frame.
    pub point_b: Point3<f64>,
}

impl Separation {
    fn flipped(self) -> Self {
        Separation { distance: self.distance, point_a: self.point_b, point_b: self.point_a }
    }
}

/// A shape posed in the world, borrowed for one query. Spheres and capsules are stored by their
/// world-frame centre/segment, so the hot path never builds an isometry for them.
#[derive(Debug, Clone, Copy)]
pub(crate) enum View<'a> {
    Sphere { c: Point3<f64>, r: f64 },
    Capsule { a: Point3<f64>, b: Point3<f64>, r: f64 },
    Cuboid { iso: &'a Isometry3<f64>, half: Vector3<f64> },
    Cylinder { iso: &'a Isometry3<f64>, r: f64, hh: f64 },
    Mesh { iso: &'a Isometry3<f64>, hull: &'a ConvexHull },
}

// ---------------------------------------------------------------------------------------------
// Closed-form pieces.

/// Closest points between segments `p1-q1` and `p2-q2`: returns the parameters `(s, t)` in
/// [0, 1] of the closest points `p1 + s (q1 - p1)` and `p2 + t (q2 - p2)`.
///
/// Minimises |(p1 + s d1) - (p2 + t d2)|^2 over the unit square: the unconstrained optimum
/// clamped to [0, 1] for `s`, then `t` recomputed for that `s` and clamped, then `s` recomputed
/// when `t` was clamped (the minimum of a convex quadratic over a box lies on this path).
pub fn segment_segment_params(p1: &Point3<f64>, q1: &Point3<f64>, p2: &Point3<f64>, q2: &Point3<f64>) -> (f64, f64) {
    const EPS: f64 = 1e-18;
    let d1 = q1 - p1;
    let d2 = q2 - p2;
    let w = p1 - p2;
    let a = d1.dot(&d1);
    let e = d2.dot(&d2);
    let f = d2.dot(&w);
    if a <= EPS && e <= EPS {
        return (0.0, 0.0);
    }
    if a <= EPS {
        return (0.0, (f / e).clamp(0.0, 1.0));
    }
    let c = d1.dot(&w);
    if e <= EPS {
        return ((-c / a).clamp(0.0, 1.0), 0.0);
    }
    let b = d1.dot(&d2);
    let denom = a * e - b * b;
    // Parallel segments (denom ~ 0): any s works; start from s = 0 and let the clamps fix t.
    let mut s = if denom > 1e-14 * a * e { ((b * f - c * e) / denom).clamp(0.0, 1.0) } else { 0.0 };
    let mut t = (b * s + f) / e;
    if t < 0.0 {
        t = 0.0;
        s = (-c / a).clamp(0.0, 1.0);
    } else if t > 1.0 {
        t = 1.0;
        s = ((b - c) / a).clamp(0.0, 1.0);
    }
    (s, t)
}

/// Nearest point of segment `a-b` to `p`.
#[inline]
pub fn closest_on_segment(p: &Point3<f64>, a: &Point3<f64>, b: &Point3<f64>) -> Point3<f64> {
    let ab = b - a;
    let len2 = ab.norm_squared();
    if len2 <= 1e-18 {
        return *a;
    }
    let t = ((p - a).dot(&ab) / len2).clamp(0.0, 1.0);
    a + ab * t
}

/// Two balls (centre, radius): the sphere-sphere, sphere-capsule and capsule-capsule answers
/// all reduce to this once the nearest core points are known.
fn balls(c1: &Point3<f64>, r1: f64, c2: &Point3<f64>, r2: f64) -> Separation {
    let d = c2 - c1;
    let len = d.norm();
    let n = if len > 1e-12 { d / len } else { Vector3::x() };
    Separation { distance: len - r1 - r2, point_a: c1 + n * r1, point_b: c2 - n * r2 }
}

/// Signed distance between two spheres.
pub fn sphere_sphere(c1: &Point3<f64>, r1: f64, c2: &Point3<f64>, r2: f64) -> Separation {
    balls(c1, r1, c2, r2)
}

/// Signed distance between a sphere and a capsule (segment `a-b`, radius `rc`).
pub fn sphere_capsule(c: &Point3<f64>, r: f64, a: &Point3<f64>, b: &Point3<f64>, rc: f64) -> Separation {
    balls(c, r, &closest_on_segment(c, a, b), rc)
}

/// Signed distance between two capsules (segments `a1-b1`, `a2-b2`).
pub fn capsule_capsule(
    a1: &Point3<f64>,
    b1: &Point3<f64>,
    r1: f64,
    a2: &Point3<f64>,
    b2: &Point3<f64>,
    r2: f64,
) -> Separation {
    let (s, t) = segment_segment_params(a1, b1, a2, b2);
    balls(&(a1 + (b1 - a1) * s), r1, &(a2 + (b2 - a2) * t), r2)
}

/// Signed distance between a sphere and a box (`half` extents, posed by `iso`): the centre is
/// clamped into the box in the box frame; inside, the nearest face gives the depth.
pub fn sphere_box(c: &Point3<f64>, r: f64, iso: &Isometry3<f64>, half: &Vector3<f64>) -> Separation {
    let p = iso.inverse_transform_point(c);
    let q = Point3::new(p.x.clamp(-half.x, half.x), p.y.clamp(-half.y, half.y), p.z.clamp(-half.z, half.z));
    let d = q - p;
    let len = d.norm();
    if len > 1e-12 {
        let n = iso.rotation * (d / len);
        return Separation { distance: len - r, point_a: c + n * r, point_b: iso * q };
    }
    // Centre inside: leave through the face with the least depth.
    let gaps = [p.x.abs() - half.x, p.y.abs() - half.y, p.z.abs() - half.z];
    let mut axis = 0;
    for i in 1..3 {
        if gaps[i] > gaps[axis] {
            axis = i;
        }
    }
    let sign = if p[axis] >= 0.0 { 1.0 } else { -1.0 };
    let mut face = p;
    face[axis] = sign * half[axis];
    let mut out = Vector3::zeros();
    out[axis] = sign;
    let n = iso.rotation * out;
    Separation { distance: gaps[axis] - r, point_a: c - n * r, point_b: iso * face }
}

/// Signed distance between a sphere and a cylinder along its local z (radius `rc`, half height
/// `hh`, posed by `iso`).
pub fn sphere_cylinder(c: &Point3<f64>, r: f64, iso: &Isometry3<f64>, rc: f64, hh: f64) -> Separation {
    let p = iso.inverse_transform_point(c);
    let rho = (p.x * p.x + p.y * p.y).sqrt();
    let (ux, uy) = if rho > 1e-12 { (p.x / rho, p.y / rho) } else { (1.0, 0.0) };
    let dr = rho - rc;
    let dz = p.z.abs() - hh;
    let sz = if p.z >= 0.0 { 1.0 } else { -1.0 };
    if dr <= 0.0 && dz <= 0.0 {
        // Inside: leave through the mantle or the nearer cap, whichever is closer.
        let (face, out) = if dr > dz {
            (Point3::new(ux * rc, uy * rc, p.z), Vector3::new(ux, uy, 0.0))
        } else {
            (Point3::new(p.x, p.y, sz * hh), Vector3::new(0.0, 0.0, sz))
        };
        let n = iso.rotation * out;
        return Separation { distance: dr.max(dz) - r, point_a: c - n * r, point_b: iso * face };
    }
    let k = rho.min(rc);
    let q = Point3::new(ux * k, uy * k, p.z.clamp(-hh, hh));
    let d = q - p;
    let len = d.norm();
    let n = if len > 1e-12 { iso.rotation * (d / len) } else { iso.rotation * Vector3::new(ux, uy, 0.0) };
    Separation { distance: len - r, point_a: c + n * r, point_b: iso * q }
}

/// Squared distance from the segment `p + t d`, t in [0, 1], to the box |x_i| <= `half`_i (all
/// in the box's frame), and the parameter `t` of a nearest segment point.
///
/// Along the segment each axis adds max(0, |x_i(t)| - half_i)^2: a convex piecewise quadratic
/// in t whose pieces change where x_i(t) crosses -half_i or +half_i. The sum is convex and one
/// quadratic between consecutive crossings, so its minimum over [0, 1] is the least of the
/// pieces' minima, each the vertex of its parabola clamped into the piece (at most seven
/// pieces). Each candidate is measured from its point, not from the expanded quadratic, so a
/// small gap keeps its digits. A NaN coordinate reads as inside (distance 0): the safe side.
pub fn segment_box_dist2(p: &Vector3<f64>, d: &Vector3<f64>, half: &Vector3<f64>) -> (f64, f64) {
    let mut ts = [0.0f64; 8];
    let mut n = 1;
    for i in 0..3 {
        if d[i] != 0.0 {
            for edge in [-half[i], half[i]] {
                let t = (edge - p[i]) / d[i];
                if t > 0.0 && t < 1.0 {
                    // Insertion into the sorted crossings.
                    let mut k = n;
                    while k > 1 && ts[k - 1] > t {
                        ts[k] = ts[k - 1];
                        k -= 1;
                    }
                    ts[k] = t;
                    n += 1;
                }
            }
        }
    }
    ts[n] = 1.0;
    let at = |t: f64| {
        let x = p + d * t;
        let e =
            Vector3::new((x.x.abs() - half.x).max(0.0), (x.y.abs() - half.y).max(0.0), (x.z.abs() - half.z).max(0.0));
        e.norm_squared()
    };
    let mut best = (f64::INFINITY, 0.0);
    for k in 0..n {
        let (t0, t1) = (ts[k], ts[k + 1]);
        let tm = 0.5 * (t0 + t1);
        // The piece's quadratic a t^2 + 2 b t + c: the axes outside the slab at its middle.
        let (mut a, mut b) = (0.0, 0.0);
        for i in 0..3 {
            let x = p[i] + d[i] * tm;
            let e = if x > half[i] {
                p[i] - half[i]
            } else if x < -half[i] {
                p[i] + half[i]
            } else {
                continue;
            };
            a += d[i] * d[i];
            b += e * d[i];
        }
        let t = if a > 0.0 { (-b / a).clamp(t0, t1) } else { t0 };
        let f = at(t);
        if f < best.0 {
            best = (f, t);
        }
    }
    best
}

/// Whether a capsule (segment `p`-`q`, radius `r`, world frame) touches a box.
#[inline]
fn capsule_box_hit(p: &Point3<f64>, q: &Point3<f64>, r: f64, iso: &Isometry3<f64>, half: &Vector3<f64>) -> bool {
    let pl = iso.inverse_transform_point(p);
    let ql = iso.inverse_transform_point(q);
    segment_box_dist2(&pl.coords, &(ql - pl), half).0 <= r * r
}

/// Whether a capsule (segment `p`-`q`, radius `r`, world frame) touches a cylinder along its
/// local z. The cylinder's box bounds it from outside, so a capsule clear of the box is clear
/// (the usual answer, exact and cheap). Otherwise the distance from the segment's points to the
/// cylinder, convex along the segment and |q - p|-Lipschitz in its parameter, is searched by
/// golden sections: any point within `r` is a contact; once the best point inside the bracket
/// (which keeps a minimiser of a convex function) less |q - p| times the bracket's width is
/// beyond `r`, nothing on the segment comes within `r`. Undecided after the search (within
/// rounding of touching), it says touching: the safe side.
fn capsule_cylinder_hit(p: &Point3<f64>, q: &Point3<f64>, r: f64, iso: &Isometry3<f64>, rc: f64, hh: f64) -> bool {
    let pl = iso.inverse_transform_point(p);
    let d = iso.inverse_transform_point(q) - pl;
    if segment_box_dist2(&pl.coords, &d, &Vector3::new(rc, rc, hh)).0 > r * r {
        return false;
    }
    let at = cylinder_along(pl, d, rc, hh);
    let lipschitz = d.norm();
    // A NaN (a NaN pose) ends in "touching" too.
    let ends = at(0.0).min(at(1.0));
    if ends.is_nan() || ends <= r {
        return true;
    }
    let mut search = Golden::new(&at);
    for _ in 0..100 {
        let inside = search.inside();
        if inside.is_nan() || inside <= r {
            return true;
        }
        if inside - lipschitz * search.width() > r {
            return false;
        }
        search.step(&at);
    }
    true
}

/// The signed distance from the point `p + t d` to the cylinder along z with radius `rc` and
/// half height `hh` (all in its frame): convex and |d|-Lipschitz in t.
fn cylinder_along(p: Point3<f64>, d: Vector3<f64>, rc: f64, hh: f64) -> impl Fn(f64) -> f64 {
    move |t: f64| {
        let x = p + d * t;
        let dr = (x.x * x.x + x.y * x.y).sqrt() - rc;
        let dz = x.z.abs() - hh;
        let (er, ez) = (dr.max(0.0), dz.max(0.0));
        if dr <= 0.0 && dz <= 0.0 { dr.max(dz) } else { (er * er + ez * ez).sqrt() }
    }
}

/// Golden-section search for the minimum of a convex function on [0, 1]: the bracket
/// [`lo`, `hi`] always holds a minimiser, and `t1` < `t2` inside it carry their values.
struct Golden {
    lo: f64,
    hi: f64,
    t1: f64,
    t2: f64,
    f1: f64,
    f2: f64,
}

impl Golden {
    const G: f64 = 0.618_033_988_749_894_8;

    fn new(f: &impl Fn(f64) -> f64) -> Self {
        let (t1, t2) = (1.0 - Self::G, Self::G);
        Golden { lo: 0.0, hi: 1.0, t1, t2, f1: f(t1), f2: f(t2) }
    }

    fn width(&self) -> f64 {
        self.hi - self.lo
    }

    /// The least value evaluated inside the bracket.
    fn inside(&self) -> f64 {
        self.f1.min(self.f2)
    }

    /// Shrink the bracket by the golden ratio, one new evaluation.
    fn step(&mut self, f: &impl Fn(f64) -> f64) {
        if self.f1 <= self.f2 {
            self.hi = self.t2;
            (self.t2, self.f2) = (self.t1, self.f1);
            self.t1 = self.hi - Self::G * (self.hi - self.lo);
            self.f1 = f(self.t1);
        } else {
            self.lo = self.t1;
            (self.t1, self.f1) = (self.t2, self.f2);
            self.t2 = self.lo + Self::G * (self.hi - self.lo);
            self.f2 = f(self.t2);
        }
    }
}

#[inline]
fn sphere_box_hit(c: &Point3<f64>, r: f64, iso: &Isometry3<f64>, half: &Vector3<f64>) -> bool {
    let p = iso.inverse_transform_point(c);
    let dx = (p.x.abs() - half.x).max(0.0);
    let dy = (p.y.abs() - half.y).max(0.0);
    let dz = (p.z.abs() - half.z).max(0.0);
    dx * dx + dy * dy + dz * dz <= r * r
}

#[inline]
fn sphere_cylinder_hit(c: &Point3<f64>, r: f64, iso: &Isometry3<f64>, rc: f64, hh: f64) -> bool {
    let p = iso.inverse_transform_point(c);
    let rho = (p.x * p.x + p.y * p.y).sqrt();
    let dr = (rho - rc).max(0.0);
    let dz = (p.z.abs() - hh).max(0.0);
    dr * dr + dz * dz <= r * r
}

// ---------------------------------------------------------------------------------------------
// Dispatch.

/// Whether two posed shapes overlap (touching counts).
#[inline]
pub(crate) fn intersects(a: &View, b: &View) -> bool {
    intersects_from(a, b, &mut { Hint::NONE })
}

/// [`intersects`] with a hint: `hint` (world frame; zero for none) is a direction from `a`
/// towards `b` that separated the pair in an earlier query. Where GJK would run (a box, a
/// cylinder or a hull on both sides), the hint is tested first: when the two shapes are apart
/// along it, that is the answer; otherwise GJK starts from it, and a separating direction it
/// finds replaces it. In motion planning a pair is asked about again and again in nearby
/// poses, and the last separating direction most often still separates. Any hint gives the
/// same answer but at GJK's tolerance (a touch within about 1e-7 of the pair's size).
#[inline]
pub(crate) fn intersects_from(a: &View, b: &View, hint: &mut Hint) -> bool {
    use View::*;
    match (a, b) {
        (Sphere { c: c1, r: r1 }, Sphere { c: c2, r: r2 }) => {
            let s = r1 + r2;
            (c2 - c1).norm_squared() <= s * s
        }
        (Sphere { c, r }, Capsule { a, b, r: rc }) | (Capsule { a, b, r: rc }, Sphere { c, r }) => {
            let s = r + rc;
            (closest_on_segment(c, a, b) - c).norm_squared() <= s * s
        }
        (Capsule { a: a1, b: b1, r: r1 }, Capsule { a: a2, b: b2, r: r2 }) => {
            let (s, t) = segment_segment_params(a1, b1, a2, b2);
            let d = (a2 + (b2 - a2) * t) - (a1 + (b1 - a1) * s);
            let rr = r1 + r2;
            d.norm_squared() <= rr * rr
        }
        (Sphere { c, r }, Cuboid { iso, half }) | (Cuboid { iso, half }, Sphere { c, r }) => {
            sphere_box_hit(c, *r, iso, half)
        }
        (Sphere { c, r }, Cylinder { iso, r: rc, hh }) | (Cylinder { iso, r: rc, hh }, Sphere { c, r }) => {
            sphere_cylinder_hit(c, *r, iso, *rc, *hh)
        }
        (Capsule { a, b, r }, Cuboid { iso, half }) | (Cuboid { iso, half }, Capsule { a, b, r }) => {
            capsule_box_hit(a, b, *r, iso, half)
        }
        (Capsule { a, b, r }, Cylinder { iso, r: rc, hh }) | (Cylinder { iso, r: rc, hh }, Capsule { a, b, r }) => {
            capsule_cylinder_hit(a, b, *r, iso, *rc, *hh)
        }
        _ => parry_intersects_from(a, b, hint),
    }
}

/// Signed distance and witness points between two posed shapes.
pub(crate) fn separation(a: &View, b: &View) -> Separation {
    use View::*;
    match (a, b) {
        (Sphere { c: c1, r: r1 }, Sphere { c: c2, r: r2 }) => sphere_sphere(c1, *r1, c2, *r2),
        (Sphere { c, r }, Capsule { a, b, r: rc }) => sphere_capsule(c, *r, a, b, *rc),
        (Capsule { a, b, r: rc }, Sphere { c, r }) => sphere_capsule(c, *r, a, b, *rc).flipped(),
        (Capsule { a: a1, b: b1, r: r1 }, Capsule { a: a2, b: b2, r: r2 }) => capsule_capsule(a1, b1, *r1, a2, b2, *r2),
        (Sphere { c, r }, Cuboid { iso, half }) => sphere_box(c, *r, iso, half),
        (Cuboid { iso, half }, Sphere { c, r }) => sphere_box(c, *r, iso, half).flipped(),
        (Sphere { c, r }, Cylinder { iso, r: rc, hh }) => sphere_cylinder(c, *r, iso, *rc, *hh),
        (Cylinder { iso, r: rc, hh }, Sphere { c, r }) => sphere_cylinder(c, *r, iso, *rc, *hh).flipped(),
        (Capsule { a: p, b: q, r }, other) => rounded_segment(p, q, *r, other),
        (other, Capsule { a: p, b: q, r }) => rounded_segment(p, q, *r, other).flipped(),
        _ => parry_separation(a, b),
    }
}

/// A capsule (segment `p`-`q` grown by `r`) against a box, cylinder or mesh: parry's distance
/// from the *segment*, less `r`, with the capsule's witness `r` along the normal. GJK converges
/// on a polytope pair in finitely many steps, but only to a tolerance on a curved support map
/// such as parry's capsule, whose witness points can sit 1e-5 m inside the capsule (seen against
/// a box). The distance between a Minkowski sum and a convex shape is the distance from its
/// core less the radius, overlaps included, as long as the core stays outside the shape; when
/// the segment itself enters the other shape, its depth in a box in closed form
/// ([`segment_in_box`]), elsewhere parry's contact depth for the segment, less `r`.
fn rounded_segment(p: &Point3<f64>, q: &Point3<f64>, r: f64, other: &View) -> Separation {
    if let View::Cylinder { iso, r: rc, hh } = *other
        && let Some(s) = segment_cylinder(p, q, r, iso, rc, hh)
    {
        return s;
    }
    if let View::Cuboid { iso, half } = *other {
        let pl = iso.inverse_transform_point(p);
        let d = iso.inverse_transform_point(q) - pl;
        let (d2, t) = segment_box_dist2(&pl.coords, &d, &half);
        // Core outside the box (by more than rounding): the nearest core point and its clamp
        // into the box are the witnesses. Touching or inside: parry's depth below.
        if d2 > 1e-24 {
            let s = pl + d * t;
            let c = Point3::new(s.x.clamp(-half.x, half.x), s.y.clamp(-half.y, half.y), s.z.clamp(-half.z, half.z));
            let gap = d2.sqrt();
            let n = iso.rotation * ((c - s) / gap);
            return Separation { distance: gap - r, point_a: iso * s + n * r, point_b: iso * c };
        }
        return segment_in_box(&pl, &d, r, iso, &half);
    }
    let (io, so) = to_parry(other);
    let segment = Segment::new(*p, *q);
    let id = Isometry3::identity();
    match query::closest_points(&id, &segment, &io, so.shape(), f64::MAX) {
        Ok(ClosestPoints::WithinMargin(ps, po)) => {
            let gap = (po - ps).norm();
            // A zero gap means touching: no normal to grow along; the capsule reaches r into it.
            let n = if gap > 0.0 { (po - ps) / gap } else { Vector3::zeros() };
            Separation { distance: gap - r, point_a: ps + n * r, point_b: po }
        }
        Ok(ClosestPoints::Intersecting) => match query::contact(&id, &segment, &io, so.shape(), 0.0) {
            // `normal1` points from the segment into the other shape.
            Ok(Some(c)) => Separation {
                distance: c.dist.min(0.0) - r,
                point_a: c.point1 + c.normal1.into_inner() * r,
                point_b: c.point2,
            },
            _ => parry_separation(&View::Capsule { a: *p, b: *q, r }, other),
        },
        Ok(ClosestPoints::Disjoint) | Err(_) => parry_separation(&View::Capsule { a: *p, b: *q, r }, other),
    }
}

/// A capsule whose core (the segment from `p` by `d`, in the box's frame) touches or enters the
/// box `half` (posed by `iso`): its depth is the segment's least translation out of the box
/// plus `r`. Segment and box are polytopes, so that translation is along a face normal of their
/// Minkowski difference: a box axis or the segment crossed with one (the separating-axis test),
/// and its length is the smallest overlap of their projections on those axes. (Parry's contact
/// query between the segment and the box, an EPA estimate on a flat Minkowski difference, put
/// a thin capsule's core across a thin box 0.019 m deep where the whole capsule's EPA, itself
/// an underestimate, found 0.076 m, seen.)
fn segment_in_box(p: &Point3<f64>, d: &Vector3<f64>, r: f64, iso: &Isometry3<f64>, half: &Vector3<f64>) -> Separation {
    let q = p + d;
    // (depth, push direction, deepest end); the box's own axes always give one.
    let mut best = (f64::INFINITY, Vector3::z(), *p);
    for k in 0..6 {
        let axis = if k < 3 { Vector3::ith(k, 1.0) } else { d.cross(&Vector3::ith(k - 3, 1.0)) };
        let len = axis.norm();
        if len < 1e-12 || !len.is_finite() {
            continue;
        }
        let n = axis / len;
        let h = half.x * n.x.abs() + half.y * n.y.abs() + half.z * n.z.abs();
        let (sp, sq) = (p.coords.dot(&n), q.coords.dot(&n));
        // Out along +n: the segment's lowest end must rise past h; along -n: its highest end
        // must sink below -h. The end that moves last is the deepest point.
        let (up, low) = if sp <= sq { (h - sp, *p) } else { (h - sq, q) };
        let (down, high) = if sp >= sq { (sp + h, *p) } else { (sq + h, q) };
        let candidate = if up <= down { (up, n, low) } else { (down, -n, high) };
        if candidate.0 < best.0 {
            best = candidate;
        }
    }
    // The capsule's deepest point, and where it leaves the box along the push.
    let (depth, n, deepest) = best;
    let reach = depth.max(0.0) + r;
    let point_a = iso * (deepest - n * r);
    Separation { distance: -reach, point_a, point_b: point_a + iso.rotation * n * reach }
}

/// A capsule against a cylinder. The cylinder's side is curved, so GJK, even from the capsule's
/// core segment, stops at a tolerance (1.6e-6 m too far, seen). The signed distance from a point
/// to the (convex) cylinder is convex along the segment, so a golden-section search over the
/// segment with the exact point distance finds the closest point. `None` when the segment
/// enters the cylinder (the capsule's depth is then not a point's).
fn segment_cylinder(
    p: &Point3<f64>,
    q: &Point3<f64>,
    r: f64,
    iso: &Isometry3<f64>,
    rc: f64,
    hh: f64,
) -> Option<Separation> {
    // The search runs in the cylinder's frame on the bare signed distance; the witnesses are
    // built once, for the best point.
    let pl = iso.inverse_transform_point(p);
    let d = iso.inverse_transform_point(q) - pl;
    let signed = cylinder_along(pl, d, rc, hh);
    let at = |t: f64| sphere_cylinder(&(p + (q - p) * t), 0.0, iso, rc, hh);
    // The distance is |q - p|-Lipschitz in t, so once that times the bracket's width is below
    // 1e-13 m the best point is that close to the minimum (at most 0.618^80 of the segment).
    let lipschitz = d.norm();
    let mut search = Golden::new(&signed);
    for _ in 0..80 {
        if lipschitz * search.width() < 1e-13 {
            break;
        }
        search.step(&signed);
    }
    let best = [at(0.0), at(1.0), at(0.5 * (search.lo + search.hi))]
        .into_iter()
        .min_by(|a, b| a.distance.total_cmp(&b.distance))?;
    // Touching, inside, or NaN: not a point's distance.
    if best.distance.is_nan() || best.distance <= 0.0 {
        return None;
    }
    let n = (best.point_b - best.point_a) / best.distance;
    Some(Separation { distance: best.distance - r, point_a: best.point_a + n * r, point_b: best.point_b })
}

/// A parry shape built on the stack from a view (no allocation; meshes are borrowed).
enum Held<'a> {
    Ball(Ball),
    Capsule(Capsule),
    Cuboid(Cuboid),
    Cylinder(Cylinder),
    Poly(&'a ConvexHull),
}

impl Held<'_> {
    fn shape(&self) -> &dyn ParryShape {
        match self {
            Held::Ball(s) => s,
            Held::Capsule(s) => s,
            Held::Cuboid(s) => s,
            Held::Cylinder(s) => s,
            Held::Poly(s) => &s.polyhedron,
        }
    }

    /// The shape as a support map for GJK: a hull climbs its vertex graph (see
    /// [`ConvexHull::support_index`]) instead of parry's scan of every vertex.
    fn with_support_map<T>(&self, f: impl FnOnce(&dyn SupportMap) -> T) -> T {
        match self {
            Held::Ball(s) => f(s),
            Held::Capsule(s) => f(s),
            Held::Cuboid(s) => f(s),
            Held::Cylinder(s) => f(s),
            Held::Poly(h) => f(&Climbing::new(h)),
        }
    }
}

/// parry's cylinders run along y; ours (URDF) along z. Rx(+90 deg) takes y to z.
fn y_to_z() -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::FRAC_PI_2)
}

fn to_parry<'a>(v: &View<'a>) -> (Isometry3<f64>, Held<'a>) {
    match *v {
        View::Sphere { c, r } => (Isometry3::translation(c.x, c.y, c.z), Held::Ball(Ball::new(r))),
        View::Capsule { a, b, r } => (Isometry3::identity(), Held::Capsule(Capsule::new(a, b, r))),
        View::Cuboid { iso, half } => (*iso, Held::Cuboid(Cuboid::new(half))),
        View::Cylinder { iso, r, hh } => {
            (Isometry3::from_parts(iso.translation, iso.rotation * y_to_z()), Held::Cylinder(Cylinder::new(hh, r)))
        }
        View::Mesh { iso, hull } => (*iso, Held::Poly(hull)),
    }
}

pub(crate) fn parry_intersects(a: &View, b: &View) -> bool {
    parry_intersects_from(a, b, &mut { Hint::NONE })
}

/// What an earlier query of a pair of shapes leaves for the next (see [`intersects_from`]):
/// the direction (world frame) from the first shape towards the second that last separated
/// them; zero for none. (Starting each hull's climb from its vertex of the query before as
/// well measured no better than the cube map's start: 617 M planning instructions against
/// 614 M.)
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Hint {
    /// The direction; zero for none.
    pub dir: Vector3<f64>,
}

impl Hint {
    /// No hint.
    pub const NONE: Hint = Hint { dir: Vector3::new(0.0, 0.0, 0.0) };
}

/// The hint's direction in `a`'s frame (`iso_a` its pose), `None` for none.
fn hint_in(iso_a: &Isometry3<f64>, hint: &Hint) -> Option<nalgebra::Unit<Vector3<f64>>> {
    nalgebra::Unit::try_new(iso_a.rotation.inverse_transform_vector(&hint.dir), f64::EPSILON)
}

fn parry_intersects_from(a: &View, b: &View, hint: &mut Hint) -> bool {
    let (ia, sa) = to_parry(a);
    let (ib, sb) = to_parry(b);
    // Two boxes: parry's separating-axis test, cheaper than trying the hint first.
    if let (Held::Cuboid(ca), Held::Cuboid(cb)) = (&sa, &sb) {
        return query::intersection_test(&ia, ca, &ib, cb).unwrap_or(true);
    }
    let pos12 = ia.inv_mul(&ib);
    let start = hint_in(&ia, hint);
    if let Some(d) = start
        && sa.with_support_map(|ga| sb.with_support_map(|gb| axis_gap(&pos12, ga, gb, &d))) > 0.0
    {
        return false;
    }
    // A hull on either side: GJK on the support maps, the hull's climbing its vertex graph.
    if matches!(sa, Held::Poly(_)) || matches!(sb, Held::Poly(_)) {
        use parry3d_f64::query::gjk::VoronoiSimplex;
        let (hit, dir) = sa.with_support_map(|ga| {
            sb.with_support_map(|gb| {
                query::details::intersection_test_support_map_support_map_with_params(
                    &pos12,
                    ga,
                    gb,
                    &mut VoronoiSimplex::new(),
                    start,
                )
            })
        });
        if !hit {
            hint.dir = ia.rotation * dir.into_inner();
        }
        return hit;
    }
    // Unsupported cannot happen for convex shapes; if it ever does, say "colliding" (safe side).
    query::intersection_test(&ia, sa.shape(), &ib, sb.shape()).unwrap_or(true)
}

/// Whether two posed shapes that do not overlap may be within `e` of each other: `false` only
/// when they are proven farther apart. Analytic pairs (a sphere or a capsule on either side)
/// compare their closed-form distance; the others (boxes, cylinders, meshes) run GJK as a
/// proximity query that stops as soon as it decides, and answer "farther" only from a
/// separating direction whose support gap, recomputed here, is wider than `e`: a lower bound
/// of the distance, where the converged distance of [`separation`] is an upper one (and GJK's
/// give-up after 100 iterations also comes back as "no intersection").
pub(crate) fn within(a: &View, b: &View, e: f64) -> bool {
    within_from(a, b, e, &mut { Hint::NONE })
}

/// [`within`] with a hint, as [`intersects_from`].
#[inline]
pub(crate) fn within_from(a: &View, b: &View, e: f64, hint: &mut Hint) -> bool {
    use View::*;
    match (a, b) {
        (Sphere { .. } | Capsule { .. }, _) | (_, Sphere { .. } | Capsule { .. }) => separation(a, b).distance <= e,
        _ => parry_within_from(a, b, e, hint),
    }
}

fn parry_within_from(a: &View, b: &View, e: f64, hint: &mut Hint) -> bool {
    parry_proximity(a, b, e, hint).is_err()
}

/// GJK's proximity query of two posed shapes (not analytic) to the margin `e`, after their
/// hint's direction: `Ok(())` when proven farther (the hint then holds the direction that
/// proved it), else `Err(Some(touching))` as GJK concluded, or `Err(None)` when it did not
/// decide (a direction it gave up with after 100 steps, or whose gap is not over `e`).
fn parry_proximity(a: &View, b: &View, e: f64, hint: &mut Hint) -> Result<(), Option<bool>> {
    use parry3d_f64::query::gjk::{self, CSOPoint, GJKResult, VoronoiSimplex};
    let (ia, sa) = to_parry(a);
    let (ib, sb) = to_parry(b);
    let pos12 = ia.inv_mul(&ib);
    let start = hint_in(&ia, hint);
    if let Some(d) = start
        && sa.with_support_map(|ga| sb.with_support_map(|gb| axis_gap(&pos12, ga, gb, &d))) > e
    {
        return Ok(());
    }
    let result = sa.with_support_map(|ga| {
        sb.with_support_map(|gb| {
            let start = start.unwrap_or_else(|| {
                nalgebra::Unit::try_new(-pos12.translation.vector, f64::EPSILON).unwrap_or_else(Vector3::x_axis)
            });
            let mut simplex = VoronoiSimplex::new();
            simplex.reset(CSOPoint::from_shapes(&pos12, ga, gb, &start));
            match gjk::closest_points(&pos12, ga, gb, e, false, &mut simplex) {
                // Farther only when the gap along GJK's direction, recomputed, is over `e` (a
                // NaN gap proves nothing).
                GJKResult::NoIntersection(dir) if axis_gap(&pos12, ga, gb, &dir) > e => Ok(dir),
                GJKResult::NoIntersection(_) => Err(None),
                GJKResult::Intersection => Err(Some(true)),
                _ => Err(Some(false)),
            }
        })
    });
    result.map(|dir| hint.dir = ia.rotation * dir.into_inner())
}

/// Where two posed shapes stand against a margin (see [`proximity_from`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Proximity {
    /// Proven farther apart than the margin.
    Farther,
    /// Not proven farther, and not touching.
    Near,
    /// Touching or overlapping (as [`intersects`] answers).
    Touching,
}

/// [`within_from`] and then, when not proven farther, [`intersects_from`], in one GJK run
/// where GJK decides: its proximity query to the margin ends in "farther" (with a separating
/// direction whose gap, recomputed, is over the margin), "separated, within the margin" (a
/// positive gap or its convergence to a positive distance: not touching, as parry's own
/// overlap test concludes from the same steps) or "intersecting". A pair found near is then
/// asked about once, not twice. Analytic pairs answer as the two tests do.
#[inline]
pub(crate) fn proximity_from(a: &View, b: &View, e: f64, hint: &mut Hint) -> Proximity {
    use View::*;
    let answer = |touching: bool| if touching { Proximity::Touching } else { Proximity::Near };
    match (a, b) {
        (Sphere { .. } | Capsule { .. }, _) | (_, Sphere { .. } | Capsule { .. }) => {
            if separation(a, b).distance <= e {
                answer(intersects(a, b))
            } else {
                Proximity::Farther
            }
        }
        _ => match parry_proximity(a, b, e, hint) {
            Ok(()) => Proximity::Farther,
            Err(Some(touching)) => answer(touching),
            // Undecided: near, and the overlap test of its own decides.
            Err(None) => answer(parry_intersects_from(a, b, hint)),
        },
    }
}

/// How far apart two support maps are along the unit direction `d` (the first's frame, from the
/// first towards the second; `pos12` the second's pose in the first's frame): the least `d.x`
/// over the second less the greatest over the first, a lower bound of their distance (NaN
/// when a support point is not finite, which proves nothing). The same sum GJK's own test of a
/// direction makes.
fn axis_gap(pos12: &Isometry3<f64>, ga: &dyn SupportMap, gb: &dyn SupportMap, d: &nalgebra::Unit<Vector3<f64>>) -> f64 {
    use parry3d_f64::query::gjk::CSOPoint;
    -d.dot(&CSOPoint::from_shapes(pos12, ga, gb, d).point.coords)
}

pub(crate) fn parry_separation(a: &View, b: &View) -> Separation {
    let (ia, sa) = to_parry(a);
    let (ib, sb) = to_parry(b);
    let centre_a = Point3::from(ia.translation.vector);
    let centre_b = Point3::from(ib.translation.vector);
    let touching = Separation { distance: 0.0, point_a: centre_a, point_b: centre_b };
    match query::closest_points(&ia, sa.shape(), &ib, sb.shape(), f64::MAX) {
        Ok(ClosestPoints::WithinMargin(pa, pb)) => Separation { distance: (pb - pa).norm(), point_a: pa, point_b: pb },
        Ok(ClosestPoints::Intersecting) => match query::contact(&ia, sa.shape(), &ib, sb.shape(), 0.0) {
            Ok(Some(c)) => Separation { distance: c.dist.min(0.0), point_a: c.point1, point_b: c.point2 },
            _ => touching,
        },
        Ok(ClosestPoints::Disjoint) | Err(_) => touching,
    }
}

// ---------------------------------------------------------------------------------------------
// Public entry points on [`Shape`]s (used by tests, tools and the planner's clearance queries).

/// A shape and its pose, as a query view; the pose is folded into the view for spheres/capsules.
pub(crate) fn view_of<'a>(shape: &'a Shape, pose: &'a Isometry3<f64>) -> View<'a> {
    match shape {
        Shape::Sphere { radius } => View::Sphere { c: Point3::from(pose.translation.vector), r: *radius },
        Shape::Capsule { a, b, radius } => View::Capsule { a: pose * a, b: pose * b, r: *radius },
        Shape::Cuboid { half_extents } => View::Cuboid { iso: pose, half: *half_extents },
        Shape::Cylinder { radius, half_height } => View::Cylinder { iso: pose, r: *radius, hh: *half_height },
        Shape::ConvexMesh(hull) => View::Mesh { iso: pose, hull },
    }
}

/// Whether two posed shapes overlap (touching counts), with the analytic fast paths.
pub fn shapes_intersect(a: &Shape, pose_a: &Isometry3<f64>, b: &Shape, pose_b: &Isometry3<f64>) -> bool {
    intersects(&view_of(a, pose_a), &view_of(b, pose_b))
}

/// Whether two posed shapes that do not overlap may be within `e` of each other (`false` only
/// when proven farther apart): the test a certificate's inflated check makes.
pub fn shapes_within(a: &Shape, pose_a: &Isometry3<f64>, b: &Shape, pose_b: &Isometry3<f64>, e: f64) -> bool {
    within(&view_of(a, pose_a), &view_of(b, pose_b), e)
}

/// Signed distance between two posed shapes, with the analytic fast paths.
pub fn shape_separation(a: &Shape, pose_a: &Isometry3<f64>, b: &Shape, pose_b: &Isometry3<f64>) -> Separation {
    separation(&view_of(a, pose_a), &view_of(b, pose_b))
}

/// Signed distance between two posed shapes computed by parry only (the reference the analytic
/// paths are tested against).
pub fn parry_shape_separation(a: &Shape, pose_a: &Isometry3<f64>, b: &Shape, pose_b: &Isometry3<f64>) -> Separation {
    parry_separation(&view_of(a, pose_a), &view_of(b, pose_b))
}

/// Whether two posed shapes overlap, by parry only.
pub fn parry_shapes_intersect(a: &Shape, pose_a: &Isometry3<f64>, b: &Shape, pose_b: &Isometry3<f64>) -> bool {
    parry_intersects(&view_of(a, pose_a), &view_of(b, pose_b))
}

/// World-frame axis-aligned bounding box of a posed shape.
pub(crate) fn aabb(v: &View) -> (Point3<f64>, Point3<f64>) {
    let (iso, held) = to_parry(v);
    let bb = held.shape().compute_aabb(&iso);
    (bb.mins, bb.maxs)
}
