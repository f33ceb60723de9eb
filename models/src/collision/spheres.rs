//! The fast path for robots whose collision geometry is spheres only (the "spherized" URDFs of
//! MotionBenchMaker, VAMP and cuRobo).
//!
//! Everything a query touches is flat and prepared at construction: body transforms as rotation
//! matrices (no quaternions: a revolute joint costs one `sin_cos` and Rodrigues' formula),
//! sphere centres in their body frames, link bounding spheres, and obstacles in closed forms
//! that answer "how far is this point from the solid" (squared, no square root for boxes).
//! A query poses the bodies, then the link bounding spheres, and poses a link's spheres only
//! when its bounding sphere survives the broad phase.
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

/// The answer of one (possibly inflated) query.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Check {
    Free,
    /// Free, but some inflated shapes touch.
    Near,
    Hit,
}

#[derive(Debug, Clone)]
struct Body {
    parent: usize,
    pre_r: Matrix3<f64>,
    pre_t: Vector3<f64>,
    axis: Vector3<f64>,
    prismatic: bool,
    offset: f64,
    post: Option<(Matrix3<f64>, Vector3<f64>)>,
    value: Value,
}

#[derive(Debug, Clone)]
struct Link {
    body: usize,
    first: usize,
    end: usize,
    c: Vector3<f64>,
    r: f64,
}

/// A sphere robot prepared for the fast path (built from [`RobotGeom`] when every shape is a sphere).
#[derive(Debug, Clone)]
pub(crate) struct SphereGeom {
    base_r: Matrix3<f64>,
    base_t: Vector3<f64>,
    bodies: Vec<Body>,
    links: Vec<Link>,
    /// Sphere centres in their body frames and radii, grouped by link.
    centre: Vec<Vector3<f64>>,
    radius: Vec<f64>,
    self_pairs: Vec<(u32, u32)>,
    /// The deepest body carrying both links of each self pair.
    pair_common: Vec<u32>,
    /// Per-sphere lever arms of the motion certificate, and how the pose at a sub-interval's
    /// midpoint tightens them: see [`arms`].
    arms: arms::Arms,
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
#[inline(always)]
fn dist2(solid: &Solid, p: &Vector3<f64>) -> Option<f64> {
    Some(match solid {
        Solid::Ball { c, r } => {
            let d = ((p - c).norm() - r).max(0.0);
            d * d
        }
        Solid::Cuboid { rt, t, half } => {
            let l = rt * (p - t);
            let dx = (l.x.abs() - half.x).max(0.0);
            let dy = (l.y.abs() - half.y).max(0.0);
            let dz = (l.z.abs() - half.z).max(0.0);
            dx * dx + dy * dy + dz * dz
        }
        Solid::Cylinder { rt, t, r, hh } => {
            let l = rt * (p - t);
            let dr = ((l.x * l.x + l.y * l.y).sqrt() - r).max(0.0);
            let dz = (l.z.abs() - hh).max(0.0);
            dr * dr + dz * dz
        }
        Solid::Capsule { a, b, r } => {
            let ab = b - a;
            let len2 = ab.norm_squared();
            let s = if len2 > 1e-18 { ((p - a).dot(&ab) / len2).clamp(0.0, 1.0) } else { 0.0 };
            let d = ((a + ab * s - p).norm() - r).max(0.0);
            d * d
        }
        Solid::Other => return None,
    })
}

/// Rotation by `angle` about the unit `axis` (Rodrigues).
#[inline(always)]
fn axis_angle(axis: &Vector3<f64>, angle: f64) -> Matrix3<f64> {
    let (s, c) = angle.sin_cos();
    let k = 1.0 - c;
    let (x, y, z) = (axis.x, axis.y, axis.z);
    Matrix3::new(
        c + x * x * k,
        x * y * k - z * s,
        x * z * k + y * s,
        y * x * k + z * s,
        c + y * y * k,
        y * z * k - x * s,
        z * x * k - y * s,
        z * y * k + x * s,
        c + z * z * k,
    )
}

/// Working memory of the fast path, kept inside [`super::CollisionScratch`].
#[derive(Debug, Clone)]
pub(crate) struct SphereScratch {
    rot: Vec<Matrix3<f64>>,
    pos: Vec<Vector3<f64>>,
    link_c: Vec<Vector3<f64>>,
    centre: Vec<Vector3<f64>>,
    posed: Vec<u32>,
    stamp: u32,
}

impl SphereScratch {
    pub(crate) const fn new() -> Self {
        Self { rot: Vec::new(), pos: Vec::new(), link_c: Vec::new(), centre: Vec::new(), posed: Vec::new(), stamp: 0 }
    }
}

impl SphereGeom {
    /// The fast form of `g`, or `None` when some shape is not a sphere.
    pub(crate) fn new(g: &RobotGeom) -> Option<SphereGeom> {
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
                pre_t: b.pre.translation.vector,
                axis: b.axis.into_inner(),
                prismatic: b.prismatic,
                offset: b.offset,
                post: b.post.map(|p| (mat(&p.rotation), p.translation.vector)),
                value: b.value,
            })
            .collect();
        let arms = arms::Arms::new(g, &links, &centre);
        let pair_common = g
            .self_pairs
            .iter()
            .map(|&(a, b)| super::common_body(&g.bodies, links[a as usize].body, links[b as usize].body) as u32)
            .collect();
        Some(SphereGeom {
            base_r: mat(&g.base.rotation),
            base_t: g.base.translation.vector,
            bodies,
            links,
            centre,
            radius,
            self_pairs: g.self_pairs.clone(),
            pair_common,
            arms,
        })
    }

    fn begin(&self, s: &mut SphereScratch) {
        if s.rot.len() != self.bodies.len() {
            s.rot.resize(self.bodies.len(), Matrix3::identity());
            s.pos.resize(self.bodies.len(), Vector3::zeros());
        }
        if s.link_c.len() != self.links.len() {
            s.link_c.resize(self.links.len(), Vector3::zeros());
            s.posed.resize(self.links.len(), 0);
        }
        if s.centre.len() != self.centre.len() {
            s.centre.resize(self.centre.len(), Vector3::zeros());
        }
        s.stamp = s.stamp.wrapping_add(1);
        if s.stamp == 0 {
            s.posed.iter_mut().for_each(|p| *p = 0);
            s.stamp = 1;
        }
    }

    /// Body transforms and link bounding-sphere centres at `q` (of the right length).
    #[inline]
    fn pose(&self, q: &[f64], s: &mut SphereScratch) {
        self.begin(s);
        s.rot[0] = self.base_r;
        s.pos[0] = self.base_t;
        for (i, b) in self.bodies.iter().enumerate().skip(1) {
            let v = match b.value {
                Value::Dof(d) => q[d],
                Value::Mimic(d, m, o) => q[d] * m + o,
                Value::Zero => 0.0,
            } + b.offset;
            let (mut r, mut t) = if b.prismatic {
                (b.pre_r, b.pre_t + b.pre_r * (b.axis * v))
            } else {
                (b.pre_r * axis_angle(&b.axis, v), b.pre_t)
            };
            if let Some((pr, pt)) = &b.post {
                t += r * pt;
                r *= pr;
            }
            let (pr, pp) = (s.rot[b.parent], s.pos[b.parent]);
            s.rot[i] = pr * r;
            s.pos[i] = pr * t + pp;
        }
        for (l, link) in self.links.iter().enumerate() {
            s.link_c[l] = s.rot[link.body] * link.c + s.pos[link.body];
        }
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
        for k in link.first..link.end {
            s.centre[k] = r * self.centre[k] + t;
        }
    }

    /// Self-collision pair `p` alone, each sphere grown by its motion relative to the pair's
    /// common body when the joints move by at most `step`.
    pub(crate) fn pair_check(&self, q: &[f64], p: usize, step: &[f64], s: &mut SphereScratch) -> Check {
        self.pose(q, s);
        let (a, b) = self.self_pairs[p];
        let (a, b) = (a as usize, b as usize);
        self.pose_link(a, s);
        self.pose_link(b, s);
        let stop = self.pair_common[p] as usize;
        let (la, lb) = (&self.links[a], &self.links[b]);
        let mut near = false;
        for i in la.first..la.end {
            let ei = self.margin(i, stop, step, None);
            for j in lb.first..lb.end {
                let d2 = (s.centre[i] - s.centre[j]).norm_squared();
                let r = self.radius[i] + self.radius[j];
                if d2 <= r * r {
                    return Check::Hit;
                }
                let re = r + ei + self.margin(j, stop, step, None);
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
            Some(_) => self.check_impl::<true>(q, obstacles, solids, inflation, s),
            None => self.check_impl::<false>(q, obstacles, solids, None, s),
        }
    }

    /// [`Self::check`], compiled separately for exact queries (`GROW` = false).
    #[inline]
    fn check_impl<const GROW: bool>(
        &self,
        q: &[f64],
        obstacles: &[ObstacleGeom],
        solids: &[Solid],
        inflation: Option<Inflation<'_>>,
        s: &mut SphereScratch,
    ) -> Check {
        self.pose(q, s);
        // Once some grown shapes touch, the answer is at least `Near`: from then on only an
        // exact contact matters, so the rest of the query runs without margins.
        let mut inf = if GROW { inflation } else { None };
        let mut near = false;
        // The box around every (grown) link sphere: obstacles outside it are skipped whole.
        let mut lo = Vector3::repeat(f64::INFINITY);
        let mut hi = Vector3::repeat(f64::NEG_INFINITY);
        for (l, link) in self.links.iter().enumerate() {
            let r = Vector3::repeat(link.r + inf.map_or(0.0, |i| i.link[l]));
            lo = lo.inf(&(s.link_c[l] - r));
            hi = hi.sup(&(s.link_c[l] + r));
        }
        for (o, solid) in obstacles.iter().zip(solids) {
            if o.lo.x > hi.x || o.hi.x < lo.x || o.lo.y > hi.y || o.hi.y < lo.y || o.lo.z > hi.z || o.hi.z < lo.z {
                continue;
            }
            for (l, link) in self.links.iter().enumerate() {
                let el = inf.map_or(0.0, |i| i.link[l]);
                let rl = link.r + el;
                let c = &s.link_c[l];
                // Link sphere against the obstacle's box.
                let dx = (o.lo.x - c.x).max(0.0).max(c.x - o.hi.x);
                let dy = (o.lo.y - c.y).max(0.0).max(c.y - o.hi.y);
                let dz = (o.lo.z - c.z).max(0.0).max(c.z - o.hi.z);
                if dx * dx + dy * dy + dz * dz > rl * rl {
                    continue;
                }
                self.pose_link(l, s);
                for k in link.first..link.end {
                    let p = &s.centre[k];
                    let r = self.radius[k];
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
                                    let re = r + self.margin(k, 0, i.step, Some(s));
                                    if d2 <= re * re {
                                        near = true;
                                        inf = None;
                                    }
                                }
                            }
                        }
                        None => {
                            let sep = narrow::separation(&View::Sphere { c: Point3::from(*p), r }, &o.world.view());
                            if sep.distance <= 0.0 {
                                return Check::Hit;
                            }
                            if let Some(i) = inf
                                && sep.distance <= self.margin(k, 0, i.step, Some(s))
                            {
                                near = true;
                                inf = None;
                            }
                        }
                    }
                }
            }
        }
        for (p, &(a, b)) in self.self_pairs.iter().enumerate() {
            let (a, b) = (a as usize, b as usize);
            let (la, lb) = (&self.links[a], &self.links[b]);
            let ep = inf.map_or(0.0, |i| i.pair[p]);
            let rr = la.r + lb.r + ep;
            if (s.link_c[a] - s.link_c[b]).norm_squared() > rr * rr {
                continue;
            }
            self.pose_link(a, s);
            self.pose_link(b, s);
            let stop = self.pair_common[p] as usize;
            let cb = s.link_c[b];
            for i in la.first..la.end {
                let (ci, ri) = (s.centre[i], self.radius[i]);
                // Sphere `i` against link b's bounding sphere first: b's bounding sphere holds
                // every sphere of b, and `ep` bounds the growth of any two spheres of the pair.
                let reach = ri + lb.r + ep;
                if (ci - cb).norm_squared() > reach * reach {
                    continue;
                }
                for j in lb.first..lb.end {
                    let d2 = (ci - s.centre[j]).norm_squared();
                    let r = ri + self.radius[j];
                    if d2 <= r * r {
                        return Check::Hit;
                    }
                    if let Some(inf_now) = inf {
                        let rp = r + ep;
                        if d2 <= rp * rp {
                            let re = r + self.pair_margin(i, j, stop, inf_now.step, s);
                            if d2 <= re * re {
                                near = true;
                                inf = None;
                            }
                        }
                    }
                }
            }
        }
        if near { Check::Near } else { Check::Free }
    }
}
