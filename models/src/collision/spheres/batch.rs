//! The sphere path over [`LANES`] configurations at once (after VAMP's vectorised checks:
//! Thomason, Kingston and Kavraki, "Motions in Microseconds via Vectorized Sampling-Based
//! Planning", ICRA 2024).
//!
//! Every quantity of a query is a lane vector `[f64; LANES]`, one lane per configuration: the
//! joint values, their sines and cosines, the body frames, the group, link and sphere centres
//! (struct of arrays: `x`, `y`, `z` each a lane vector). The forward kinematics is the
//! robot's program prepared once by [`SphereGeom::new`] (bodies in order, each with its
//! pre-rotation resolved to a signed permutation or a matrix, the joint turning about its
//! frame's z axis): one short branch per *body* chooses the form, the arithmetic then runs over
//! all lanes in loops the compiler turns into vector instructions (no joint is interpreted per
//! configuration). The broad phase is the scalar one (group, link and obstacle-box spheres),
//! taken lane by lane as bit masks: a level is skipped when no lane needs it, and a batch that
//! asks "does any lane collide" stops at the first contact.
//!
//! **Exactly the scalar answer.** Each lane computes the very numbers the scalar query
//! computes, operation for operation, in the same order (the scalar closed forms are written
//! out for that: [`super::dist2`], `mul3v`, `mul3tv`), and its masks are the scalar query's
//! tests. So a lane's answer is [`SphereGeom::check`]'s, bit for bit; the tests compare them on
//! random and near-contact configurations. Double precision throughout: a single-precision
//! lane would need margins for its rounding and would no longer agree exactly.
//!
//! **Lanes as arrays, not a SIMD crate.** Plain `[f64; 8]` loops, which the compiler turns into
//! vector instructions of whatever target the crate is built for (two SSE2 operations per
//! loop on the x86-64 baseline, one AVX-512 or two AVX2 with `-C target-cpu=native`), measured
//! against `wide::f64x4` pairs: see the closing notes of the benchmarks in `benches/collision.rs`.

use super::{
    Check, SIN_COS_RANGE, Solid, SphereGeom, aabb_d2, ball_d2, box_d2, capsule_d2, cuboid_d2, cylinder_d2, local,
    sin_cos, sin_cos_kernel,
};
use crate::collision::ObstacleGeom;

/// Configurations per batch.
pub(crate) const LANES: usize = 8;

/// One number per lane.
type V = [f64; LANES];
/// A point per lane, struct of arrays.
type P = [V; 3];
/// A rotation per lane, row-major (`r[3 * row + col]`).
type R = [V; 9];
/// One bit per lane.
pub(crate) type Mask = u32;

#[inline(always)]
fn splat(x: f64) -> V {
    [x; LANES]
}

#[inline(always)]
fn map2(a: &V, b: &V, f: impl Fn(f64, f64) -> f64) -> V {
    let mut o = [0.0; LANES];
    for i in 0..LANES {
        o[i] = f(a[i], b[i]);
    }
    o
}

/// Lanes where `f` holds, as bits.
#[inline(always)]
fn mask(f: impl Fn(usize) -> bool) -> Mask {
    let mut m = 0;
    for i in 0..LANES {
        m |= (f(i) as Mask) << i;
    }
    m
}

/// `rot * c + pos` per lane (a constant point), as `mul3v(rot, c) + pos`.
#[inline(always)]
fn place(rot: &R, pos: &P, c: &[f64; 3]) -> P {
    let mut o = [[0.0; LANES]; 3];
    for (r, row) in o.iter_mut().enumerate() {
        for i in 0..LANES {
            row[i] = (rot[3 * r][i] * c[0] + rot[3 * r + 1][i] * c[1] + rot[3 * r + 2][i] * c[2]) + pos[r][i];
        }
    }
    o
}

/// `rotᵀ * v` per lane, as `mul3tv`.
#[inline(always)]
fn mul_tv(rot: &R, v: &P) -> P {
    let mut o = [[0.0; LANES]; 3];
    for (c, row) in o.iter_mut().enumerate() {
        for i in 0..LANES {
            row[i] = rot[c][i] * v[0][i] + rot[3 + c][i] * v[1][i] + rot[6 + c][i] * v[2][i];
        }
    }
    o
}

/// `rot * v` per lane, as `mul3v`.
#[inline(always)]
fn mul_v(rot: &R, v: &P) -> P {
    let mut o = [[0.0; LANES]; 3];
    for (r, row) in o.iter_mut().enumerate() {
        for i in 0..LANES {
            row[i] = rot[3 * r][i] * v[0][i] + rot[3 * r + 1][i] * v[1][i] + rot[3 * r + 2][i] * v[2][i];
        }
    }
    o
}

/// `|c - p|²` per lane (a constant point), as `(c - p).norm_squared()`.
#[inline(always)]
fn dist2_to(c: &[f64; 3], p: &P) -> V {
    let mut o = [0.0; LANES];
    for i in 0..LANES {
        let (dx, dy, dz) = (c[0] - p[0][i], c[1] - p[1][i], c[2] - p[2][i]);
        o[i] = dx * dx + dy * dy + dz * dz;
    }
    o
}

/// The point of lane `i`.
#[inline(always)]
fn at(p: &P, i: usize) -> [f64; 3] {
    [p[0][i], p[1][i], p[2][i]]
}

/// Lanes where the sphere at `c` of radius `r` may touch the solid: [`super::may_touch`] per lane.
#[inline(always)]
fn may_touch(solid: &Solid, o: &ObstacleGeom, c: &P, r: f64, live: Mask) -> Mask {
    let r2 = r * r;
    live & match solid {
        Solid::Ball { c: cb, r: rb } => mask(|i| ball_d2(cb, *rb, at(c, i)) <= r2),
        Solid::Cuboid { rt, t, half } => mask(|i| cuboid_d2(rt, t, half, at(c, i)) <= r2),
        Solid::Cylinder { rt, t, r: rc, hh } => mask(|i| box_d2(local(rt, t, at(c, i)), [*rc, *rc, *hh]) <= r2),
        _ => mask(|i| aabb_d2(o, at(c, i)) <= r2),
    }
}

/// Squared distance of each lane's point from the solid: [`super::dist2`] per lane (closed
/// forms only).
#[inline(always)]
fn dist2(solid: &Solid, p: &P) -> V {
    let mut o = [f64::INFINITY; LANES];
    match solid {
        Solid::Ball { c, r } => (0..LANES).for_each(|i| o[i] = ball_d2(c, *r, at(p, i))),
        Solid::Cuboid { rt, t, half } => (0..LANES).for_each(|i| o[i] = cuboid_d2(rt, t, half, at(p, i))),
        Solid::Cylinder { rt, t, r, hh } => (0..LANES).for_each(|i| o[i] = cylinder_d2(rt, t, *r, *hh, at(p, i))),
        Solid::Capsule { a, b, r } => (0..LANES).for_each(|i| o[i] = capsule_d2(a, b, *r, at(p, i))),
        Solid::Other => {}
    }
    o
}

/// Working memory of the batched path, kept inside [`super::SphereScratch`].
#[derive(Debug, Clone)]
pub(crate) struct BatchScratch {
    angle: Vec<V>,
    sin: Vec<V>,
    cos: Vec<V>,
    rot: Vec<R>,
    pos: Vec<P>,
    group_c: Vec<P>,
    link_c: Vec<P>,
    link_posed: Vec<bool>,
    centre: Vec<P>,
    posed: Vec<bool>,
    /// Per group, its largest link margin (inflated batches).
    group_e: Vec<f64>,
    /// Per group pair, its largest pair margin (inflated batches).
    pair_e: Vec<f64>,
}

impl BatchScratch {
    pub(crate) const fn new() -> Self {
        Self {
            angle: Vec::new(),
            sin: Vec::new(),
            cos: Vec::new(),
            rot: Vec::new(),
            pos: Vec::new(),
            group_c: Vec::new(),
            link_c: Vec::new(),
            link_posed: Vec::new(),
            centre: Vec::new(),
            posed: Vec::new(),
            group_e: Vec::new(),
            pair_e: Vec::new(),
        }
    }
}

/// Margins of an inflated batch, as [`crate::collision::Inflation`] (the same for every lane:
/// the pieces of one segment's first level are equally long).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Grow<'a> {
    pub link: &'a [f64],
    pub pair: &'a [f64],
    pub step: &'a [f64],
}

/// What a batch found, per lane.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Lanes {
    /// Lanes in contact (exactly, ungrown).
    pub hit: Mask,
    /// Lanes where grown shapes touch (inflated batches; includes the `hit` lanes it found).
    pub near: Mask,
}

impl SphereGeom {
    /// Whether the batched path can answer for these obstacles (closed forms only).
    pub(crate) fn batch_supported(&self, solids: &[Solid], dof: usize) -> bool {
        dof > 0 && !solids.iter().any(|s| matches!(s, Solid::Other))
    }

    /// Poses the bodies and group spheres of the configurations `qs` (`LANES` of `dof`
    /// values, one after another, all finite).
    fn pose_batch(&self, qs: &[f64], dof: usize, s: &mut BatchScratch) {
        let (n, m) = (self.bodies.len(), self.angles.len());
        s.rot.resize(n, [[0.0; LANES]; 9]);
        s.pos.resize(n, [[0.0; LANES]; 3]);
        s.angle.resize(m, [0.0; LANES]);
        s.sin.resize(m, [0.0; LANES]);
        s.cos.resize(m, [0.0; LANES]);
        s.group_c.resize(self.groups.len(), [[0.0; LANES]; 3]);
        s.link_c.resize(self.links.len(), [[0.0; LANES]; 3]);
        s.link_posed.clear();
        s.link_posed.resize(self.links.len(), false);
        s.centre.resize(self.centre.len(), [[0.0; LANES]; 3]);
        s.posed.clear();
        s.posed.resize(self.links.len(), false);
        for r in 0..3 {
            for c in 0..3 {
                s.rot[0][3 * r + c] = splat(self.base_r[(r, c)]);
            }
            s.pos[0][r] = splat(self.base_t[r]);
        }
        let mut in_range = true;
        for (a, v) in self.angles.iter().zip(s.angle.iter_mut()) {
            for (i, v) in v.iter_mut().enumerate() {
                *v = (qs[i * dof + a.dof] * a.scale + a.add) + a.offset;
                in_range &= v.abs() < SIN_COS_RANGE;
            }
        }
        for ((v, sn), cs) in s.angle.iter().zip(s.sin.iter_mut()).zip(s.cos.iter_mut()) {
            for i in 0..LANES {
                (sn[i], cs[i]) = if in_range { sin_cos_kernel(v[i]) } else { sin_cos(v[i]) };
            }
        }
        for (k, b) in self.bodies.iter().enumerate().skip(1) {
            let (v, sn, cs) = (&s.angle[k - 1], &s.sin[k - 1], &s.cos[k - 1]);
            let (pr, pp) = (s.rot[b.parent], s.pos[b.parent]);
            let t = [b.pre_t.x, b.pre_t.y, b.pre_t.z];
            // `mul3v(pr, pre_t) + pp`, the origin of every revolute joint's frame.
            let origin = place(&pr, &pp, &t);
            let (mut rot, mut pos): (R, P);
            if let Some((cols, sign)) = &b.turn_perm {
                // As the scalar `pose`: the parent's columns `cols` with signs, the first two
                // mixed by the joint's cosine and sine.
                rot = [[0.0; LANES]; 9];
                for r in 0..3 {
                    let (ca, cb, cc) = (pr[3 * r + cols[0]], pr[3 * r + cols[1]], pr[3 * r + cols[2]]);
                    for i in 0..LANES {
                        let (k0, k1, k2, k3) = (sign[0] * cs[i], sign[1] * sn[i], sign[1] * cs[i], sign[0] * sn[i]);
                        rot[3 * r][i] = ca[i] * k0 + cb[i] * k1;
                        rot[3 * r + 1][i] = cb[i] * k2 - ca[i] * k3;
                        rot[3 * r + 2][i] = cc[i] * sign[2];
                    }
                }
                s.rot[k] = rot;
                s.pos[k] = origin;
                continue;
            }
            // m = pr * pre_r.
            let mut mm: R = [[0.0; LANES]; 9];
            match &b.pre_perm {
                Some((perm, sign)) => {
                    for r in 0..3 {
                        for c in 0..3 {
                            mm[3 * r + c] = pr[3 * r + perm[c]].map(|x| x * sign[c]);
                        }
                    }
                }
                None => {
                    for r in 0..3 {
                        for c in 0..3 {
                            let (b0, b1, b2) = (b.pre_r[(0, c)], b.pre_r[(1, c)], b.pre_r[(2, c)]);
                            for i in 0..LANES {
                                mm[3 * r + c][i] = pr[3 * r][i] * b0 + pr[3 * r + 1][i] * b1 + pr[3 * r + 2][i] * b2;
                            }
                        }
                    }
                }
            }
            if b.prismatic {
                let a: P = [v.map(|x| b.axis.x * x), v.map(|x| b.axis.y * x), v.map(|x| b.axis.z * x)];
                let ma = mul_v(&mm, &a);
                rot = mm;
                pos = [[0.0; LANES]; 3];
                for r in 0..3 {
                    // `mul3v(pr, pre_t) + mul3v(m, a) + pp`.
                    for i in 0..LANES {
                        let pt = pr[3 * r][i] * t[0] + pr[3 * r + 1][i] * t[1] + pr[3 * r + 2][i] * t[2];
                        pos[r][i] = (pt + ma[r][i]) + pp[r][i];
                    }
                }
            } else {
                rot = mm;
                for r in 0..3 {
                    let (c0, c1) = (mm[3 * r], mm[3 * r + 1]);
                    for i in 0..LANES {
                        rot[3 * r][i] = c0[i] * cs[i] + c1[i] * sn[i];
                        rot[3 * r + 1][i] = c1[i] * cs[i] - c0[i] * sn[i];
                    }
                }
                pos = origin;
            }
            if let Some((qr, qt)) = &b.post {
                let add = place(&rot, &[[0.0; LANES]; 3], &[qt.x, qt.y, qt.z]);
                for r in 0..3 {
                    pos[r] = map2(&pos[r], &add[r], |a, b| a + b);
                }
                let old = rot;
                for r in 0..3 {
                    for c in 0..3 {
                        let (b0, b1, b2) = (qr[(0, c)], qr[(1, c)], qr[(2, c)]);
                        for i in 0..LANES {
                            rot[3 * r + c][i] = old[3 * r][i] * b0 + old[3 * r + 1][i] * b1 + old[3 * r + 2][i] * b2;
                        }
                    }
                }
            }
            s.rot[k] = rot;
            s.pos[k] = pos;
        }
        for (g, c) in self.groups.iter().zip(s.group_c.iter_mut()) {
            *c = place(&s.rot[g.body], &s.pos[g.body], &[g.c.x, g.c.y, g.c.z]);
        }
    }

    /// World centre of link `l`'s bounding sphere per lane, once per batch.
    #[inline(always)]
    fn link_centre_batch(&self, l: usize, s: &mut BatchScratch) -> P {
        if !s.link_posed[l] {
            s.link_posed[l] = true;
            let link = &self.links[l];
            s.link_c[l] = place(&s.rot[link.body], &s.pos[link.body], &[link.c.x, link.c.y, link.c.z]);
        }
        s.link_c[l]
    }

    /// World centres of link `l`'s spheres per lane, once per batch.
    #[inline(always)]
    fn pose_link_batch(&self, l: usize, s: &mut BatchScratch) {
        if s.posed[l] {
            return;
        }
        s.posed[l] = true;
        let link = &self.links[l];
        let (rot, pos) = (s.rot[link.body], s.pos[link.body]);
        for k in link.first..link.end {
            let c = &self.centre[k];
            s.centre[k] = place(&rot, &pos, &[c.x, c.y, c.z]);
        }
    }

    /// The exact query ([`SphereGeom::check`] without inflation) of `LANES` configurations
    /// (`qs`: `dof` values each, one after another, all finite), for the lanes in `active`:
    /// the lanes in contact. With `ANY`, it stops at the first contact found (then the answer
    /// holds at least one lane in contact, not necessarily all of them).
    /// Only for obstacles [`Self::batch_supported`] accepts.
    pub(crate) fn check_batch<const ANY: bool>(
        &self,
        qs: &[f64],
        dof: usize,
        active: Mask,
        obstacles: &[ObstacleGeom],
        solids: &[Solid],
        s: &mut BatchScratch,
    ) -> Mask {
        self.batch_impl::<ANY, false>(qs, dof, active, obstacles, solids, None, s).hit
    }

    /// The inflated query of the motion certificate over `LANES` sub-intervals of one length
    /// (their midpoints in `qs`), for the lanes in `active`: which lanes are in contact
    /// (stopping at the first contact) and which have grown shapes that touch, with the margins
    /// of the links and pairs ([`crate::collision::Inflation`]'s `link` and `pair`), which bound
    /// the tighter per-sphere ones of the scalar query. A lane in neither set is
    /// [`Check::Free`] for the scalar query too (it tests these same margins first).
    pub(crate) fn check_batch_grown(
        &self,
        qs: &[f64],
        dof: usize,
        active: Mask,
        obstacles: &[ObstacleGeom],
        solids: &[Solid],
        grow: Grow<'_>,
        s: &mut BatchScratch,
    ) -> Lanes {
        self.batch_impl::<true, true>(qs, dof, active, obstacles, solids, Some(grow), s)
    }

    #[allow(clippy::too_many_arguments)]
    #[inline(never)]
    fn batch_impl<const ANY: bool, const GROW: bool>(
        &self,
        qs: &[f64],
        dof: usize,
        active: Mask,
        obstacles: &[ObstacleGeom],
        solids: &[Solid],
        grow: Option<Grow<'_>>,
        s: &mut BatchScratch,
    ) -> Lanes {
        let grow = if GROW { grow } else { None };
        let mut out = Lanes { hit: 0, near: 0 };
        match self.fixed {
            Check::Hit => return Lanes { hit: active, near: active },
            Check::Near if grow.is_some() => out.near = active,
            _ => {}
        }
        self.pose_batch(qs, dof, s);
        s.group_e.clear();
        s.group_e.resize(self.groups.len(), 0.0);
        s.pair_e.clear();
        s.pair_e.resize(self.group_pairs.len(), 0.0);
        if let Some(g) = grow {
            for (gr, e) in self.groups.iter().zip(s.group_e.iter_mut()) {
                *e = self.group_links[gr.first..gr.end].iter().map(|&l| g.link[l as usize]).fold(0.0, f64::max);
            }
            for (gp, e) in self.group_pairs.iter().zip(s.pair_e.iter_mut()) {
                *e = self.run_pairs[gp.pairs.clone()].iter().map(|rp| g.pair[rp.pair as usize]).fold(0.0, f64::max);
            }
        }
        // Each lane's box around its group spheres, as the scalar query's.
        let (mut lo, mut hi) = ([[f64::INFINITY; LANES]; 3], [[f64::NEG_INFINITY; LANES]; 3]);
        for (k, (g, c)) in self.groups.iter().zip(&s.group_c).enumerate() {
            let r = g.r + if grow.is_some() { s.group_e[k] } else { 0.0 };
            for d in 0..3 {
                for i in 0..LANES {
                    let (l, h) = (c[d][i] - r, c[d][i] + r);
                    if l < lo[d][i] {
                        lo[d][i] = l;
                    }
                    if h > hi[d][i] {
                        hi[d][i] = h;
                    }
                }
            }
        }
        let mut live = active;
        for (o, solid) in obstacles.iter().zip(solids) {
            let in_box = live
                & mask(|i| {
                    !(o.lo.x > hi[0][i]
                        || o.hi.x < lo[0][i]
                        || o.lo.y > hi[1][i]
                        || o.hi.y < lo[1][i]
                        || o.lo.z > hi[2][i]
                        || o.hi.z < lo[2][i])
                });
            if in_box == 0 {
                continue;
            }
            for (gi, g) in self.groups.iter().enumerate() {
                let eg = if grow.is_some() { s.group_e[gi] } else { 0.0 };
                let mg = may_touch(solid, o, &s.group_c[gi], g.r + eg, in_box & live);
                if mg == 0 {
                    continue;
                }
                for gl in g.first..g.end {
                    let l = self.group_links[gl] as usize;
                    let link = &self.links[l];
                    let el = grow.map_or(0.0, |g| g.link[l]);
                    let c = self.link_centre_batch(l, s);
                    let ml = may_touch(solid, o, &c, link.r + el, mg & live);
                    if ml == 0 {
                        continue;
                    }
                    self.pose_link_batch(l, s);
                    for k in link.first..link.end {
                        let p = &s.centre[k];
                        let r = self.radius[k];
                        let rel = r + el;
                        let mk = ml & live & mask(|i| aabb_d2(o, at(p, i)) <= rel * rel);
                        if mk == 0 {
                            continue;
                        }
                        let d2 = dist2(solid, p);
                        let hit = mk & mask(|i| d2[i] <= r * r);
                        if GROW {
                            out.near |= mk & mask(|i| d2[i] <= rel * rel);
                        }
                        if hit != 0 {
                            out.hit |= hit;
                            live &= !hit;
                            if ANY || live == 0 {
                                return out;
                            }
                        }
                    }
                }
            }
        }
        self.self_batch::<ANY>(qs, dof, grow, &mut live, &mut out, s);
        out
    }

    /// The self-collision part of [`Self::batch_impl`], as the scalar `self_pass`.
    #[inline(always)]
    fn self_batch<const ANY: bool>(
        &self,
        qs: &[f64],
        dof: usize,
        grow: Option<Grow<'_>>,
        live: &mut Mask,
        out: &mut Lanes,
        s: &mut BatchScratch,
    ) {
        for (k, gp) in self.group_pairs.iter().enumerate() {
            if *live == 0 {
                return;
            }
            let eg = s.pair_e[k];
            let c_inner = s.group_c[gp.inner];
            let rr = if grow.is_some() { gp.rr + eg } else { gp.rr };
            let co = &s.group_c[gp.outer];
            let mut m = *live
                & mask(|i| {
                    let (dx, dy, dz) = (co[0][i] - c_inner[0][i], co[1][i] - c_inner[1][i], co[2][i] - c_inner[2][i]);
                    !(dx * dx + dy * dy + dz * dz > rr * rr)
                });
            if m == 0 {
                continue;
            }
            if let Some(Some(table)) = self.tables.get(k) {
                for i in 0..LANES {
                    if m & (1 << i) == 0 {
                        continue;
                    }
                    let q = &qs[i * dof..(i + 1) * dof];
                    let proven = match grow {
                        Some(g) => table.proves_box(q, g.step),
                        None => table.proves(q),
                    };
                    if proven {
                        m &= !(1 << i);
                    }
                }
                if m == 0 {
                    continue;
                }
            }
            let r_inner = if grow.is_some() { gp.r_inner + eg } else { gp.r_inner };
            let (rot_o, pos_o) = (&s.rot[gp.body_o], &s.pos[gp.body_o]);
            let (rot_i, pos_i) = (&s.rot[gp.body_i], &s.pos[gp.body_i]);
            let rel: P = [
                map2(&c_inner[0], &pos_o[0], |a, b| a - b),
                map2(&c_inner[1], &pos_o[1], |a, b| a - b),
                map2(&c_inner[2], &pos_o[2], |a, b| a - b),
            ];
            let g = mul_tv(rot_o, &rel);
            for run in &self.runs[gp.runs.clone()] {
                let reach = run.r + r_inner;
                let d2 = dist2_to(&[run.c.x, run.c.y, run.c.z], &g);
                let mr = m & *live & mask(|i| !(d2[i] > reach * reach));
                if mr == 0 {
                    continue;
                }
                for bi in &self.balls[run.first..run.end] {
                    let reach = bi[3] + r_inner;
                    let mut mb = mr
                        & mask(|i| {
                            let (dx, dy, dz) = (bi[0] - g[0][i], bi[1] - g[1][i], bi[2] - g[2][i]);
                            !(dx * dx + dy * dy + dz * dz > reach * reach)
                        });
                    mb &= *live;
                    if mb == 0 {
                        continue;
                    }
                    let ri = bi[3];
                    // Sphere `i` in the inner body's frame: `mul3tv(rot_i, mul3v(rot_o, ci) + pos_o - pos_i)`.
                    let w = place(rot_o, pos_o, &[bi[0], bi[1], bi[2]]);
                    let d: P = [
                        map2(&w[0], &pos_i[0], |a, b| a - b),
                        map2(&w[1], &pos_i[1], |a, b| a - b),
                        map2(&w[2], &pos_i[2], |a, b| a - b),
                    ];
                    let u = mul_tv(rot_i, &d);
                    for rp in &self.run_pairs[run.pairs.clone()] {
                        let ep = grow.map_or(0.0, |g| g.pair[rp.pair as usize]);
                        let reach = if grow.is_some() { ri + rp.r + ep } else { ri + rp.r };
                        let d2 = dist2_to(&[rp.c.x, rp.c.y, rp.c.z], &u);
                        let mp = mb & *live & mask(|i| !(d2[i] > reach * reach));
                        if mp == 0 {
                            continue;
                        }
                        for bj in &self.balls[rp.first as usize..rp.end as usize] {
                            let d2 = dist2_to(&[bj[0], bj[1], bj[2]], &u);
                            let r = ri + bj[3];
                            let hit = mp & *live & mask(|i| d2[i] <= r * r);
                            if grow.is_some() {
                                let grown = r + ep;
                                out.near |= mp & mask(|i| d2[i] <= grown * grown);
                            }
                            if hit != 0 {
                                out.hit |= hit;
                                *live &= !hit;
                                if ANY || *live == 0 {
                                    return;
                                }
                            }
                        }
                    }
                }
            }
        }
    }
}
