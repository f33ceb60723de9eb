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
//! tests (written `d2 <= r2` where the scalar query skips on `d2 > r2`: the same for the finite
//! numbers a batch holds, non-finite configurations being answered one by one). So a lane's answer is [`SphereGeom::check`]'s, bit for bit; the tests compare them on
//! random and near-contact configurations. Double precision throughout: a single-precision
//! lane would need margins for its rounding and would no longer agree exactly.
//!
//! **Lanes as arrays, not a SIMD crate.** Plain `[f64; 8]` loops, which the compiler turns into
//! vector instructions of whatever target the crate is built for (two SSE2 operations per
//! loop on the x86-64 baseline, one AVX-512 or two AVX2 with `-C target-cpu=native`), measured
//! against `wide::f64x4` pairs: see the closing notes of the benchmarks in `benches/collision.rs`.

use super::{
    Check, SIN_COS_RANGE, Solid, SphereGeom, aabb_d2, ball_d2, box_d2, capsule_d2, cuboid_d2, cylinder_d2, local,
    sin_cos,
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

/// `super::sin_cos_kernel` of every lane (`|x|` below `SIN_COS_RANGE`), step by step over the
/// lanes so that each step is one vector loop: the very operations of the scalar kernel, in
/// its order, so the same bits.
#[inline(always)]
pub(super) fn sin_cos_lanes(x: &V) -> (V, V) {
    use super::{COS_C, PIO2_1, PIO2_2, PIO2_2T, SIN_ROUND, SIN_S};
    let (s, c) = (SIN_S, COS_C);
    let mut shifted = [0.0; LANES];
    let mut r = [0.0; LANES];
    for i in 0..LANES {
        shifted[i] = x[i] * std::f64::consts::FRAC_2_PI + SIN_ROUND;
        let k = shifted[i] - SIN_ROUND;
        r[i] = ((x[i] - k * PIO2_1) - k * PIO2_2) - k * PIO2_2T;
    }
    let mut sin = [0.0; LANES];
    let mut cos = [0.0; LANES];
    for i in 0..LANES {
        let r2 = r[i] * r[i];
        let r4 = r2 * r2;
        let ps = (s[0] + r2 * s[1] + r4 * s[2]) + r4 * r2 * (s[3] + r2 * s[4] + r4 * s[5]);
        let pc = (c[0] + r2 * c[1] + r4 * c[2]) + r4 * r2 * (c[3] + r2 * c[4] + r4 * c[5]);
        sin[i] = r[i] + r[i] * r2 * ps;
        let hz = 0.5 * r2;
        let w = 1.0 - hz;
        cos[i] = w + (((1.0 - w) - hz) + r4 * pc);
    }
    let mut out_s = [0.0; LANES];
    let mut out_c = [0.0; LANES];
    for i in 0..LANES {
        let q = shifted[i].to_bits();
        let swap = 0u64.wrapping_sub(q & 1);
        let (sb, cb) = (sin[i].to_bits(), cos[i].to_bits());
        let a = (sb & !swap) | (cb & swap);
        let b = (cb & !swap) | (sb & swap);
        out_s[i] = f64::from_bits(a ^ ((q & 2) << 62));
        out_c[i] = f64::from_bits(b ^ ((q.wrapping_add(1) & 2) << 62));
    }
    (out_s, out_c)
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
        }
    }
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
        // (The branch outside the lane loops: the kernel then runs in vector registers.)
        if in_range {
            for ((v, sn), cs) in s.angle.iter().zip(s.sin.iter_mut()).zip(s.cos.iter_mut()) {
                (*sn, *cs) = sin_cos_lanes(v);
            }
        } else {
            for ((v, sn), cs) in s.angle.iter().zip(s.sin.iter_mut()).zip(s.cos.iter_mut()) {
                for i in 0..LANES {
                    (sn[i], cs[i]) = sin_cos(v[i]);
                }
            }
        }
        for (k, b) in self.bodies.iter().enumerate().skip(1) {
            let (v, sn, cs) = (&s.angle[k - 1], &s.sin[k - 1], &s.cos[k - 1]);
            // (Parents come first: their frames are read in place.)
            let (done_r, todo_r) = s.rot.split_at_mut(k);
            let (done_p, todo_p) = s.pos.split_at_mut(k);
            let (pr, pp) = (&done_r[b.parent], &done_p[b.parent]);
            let (out_r, out_p) = (&mut todo_r[0], &mut todo_p[0]);
            let t = [b.pre_t.x, b.pre_t.y, b.pre_t.z];
            // `mul3v(pr, pre_t) + pp`, the origin of every revolute joint's frame.
            let origin = place(pr, pp, &t);
            let (mut rot, mut pos): (R, P);
            if let Some((cols, sign)) = &b.turn_perm {
                // As the scalar `pose`: the parent's columns `cols` with signs, the first two
                // mixed by the joint's cosine and sine.
                for r in 0..3 {
                    let (ca, cb, cc) = (pr[3 * r + cols[0]], pr[3 * r + cols[1]], pr[3 * r + cols[2]]);
                    for i in 0..LANES {
                        let (k0, k1, k2, k3) = (sign[0] * cs[i], sign[1] * sn[i], sign[1] * cs[i], sign[0] * sn[i]);
                        out_r[3 * r][i] = ca[i] * k0 + cb[i] * k1;
                        out_r[3 * r + 1][i] = cb[i] * k2 - ca[i] * k3;
                        out_r[3 * r + 2][i] = cc[i] * sign[2];
                    }
                }
                *out_p = origin;
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
            *out_r = rot;
            *out_p = pos;
        }
        for (g, c) in self.groups.iter().zip(s.group_c.iter_mut()) {
            *c = place(&s.rot[g.body], &s.pos[g.body], &[g.c.x, g.c.y, g.c.z]);
        }
    }

    /// World centre of link `l`'s bounding sphere per lane (into `s.link_c[l]`), once per batch.
    #[inline(always)]
    fn link_centre_batch(&self, l: usize, s: &mut BatchScratch) {
        if !s.link_posed[l] {
            s.link_posed[l] = true;
            let link = &self.links[l];
            s.link_c[l] = place(&s.rot[link.body], &s.pos[link.body], &[link.c.x, link.c.y, link.c.z]);
        }
    }

    /// World centres of link `l`'s spheres per lane, once per batch.
    #[inline(always)]
    fn pose_link_batch(&self, l: usize, s: &mut BatchScratch) {
        if s.posed[l] {
            return;
        }
        s.posed[l] = true;
        let link = &self.links[l];
        let (rot, pos) = (&s.rot[link.body], &s.pos[link.body]);
        for (w, c) in s.centre[link.first..link.end].iter_mut().zip(&self.centre[link.first..link.end]) {
            *w = place(rot, pos, &[c.x, c.y, c.z]);
        }
    }

    /// The exact query ([`SphereGeom::check`] without inflation) of `LANES` configurations
    /// (`qs`: `dof` values each, one after another, all finite), for the lanes in `active`:
    /// the lanes in contact. With `ANY`, it stops at the first contact found (then the answer
    /// holds at least one lane in contact, not necessarily all of them).
    /// Only for obstacles [`Self::batch_supported`] accepts.
    #[inline(never)]
    pub(crate) fn check_batch<const ANY: bool>(
        &self,
        qs: &[f64],
        dof: usize,
        active: Mask,
        obstacles: &[ObstacleGeom],
        solids: &[Solid],
        s: &mut BatchScratch,
    ) -> Mask {
        if self.fixed == Check::Hit {
            return active;
        }
        self.pose_batch(qs, dof, s);
        // Each lane's box around its group spheres, as the scalar query's.
        let (mut lo, mut hi) = ([[f64::INFINITY; LANES]; 3], [[f64::NEG_INFINITY; LANES]; 3]);
        for (g, c) in self.groups.iter().zip(&s.group_c) {
            for d in 0..3 {
                for i in 0..LANES {
                    let (l, h) = (c[d][i] - g.r, c[d][i] + g.r);
                    if l < lo[d][i] {
                        lo[d][i] = l;
                    }
                    if h > hi[d][i] {
                        hi[d][i] = h;
                    }
                }
            }
        }
        let mut hits = 0;
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
                let mg = may_touch(solid, o, &s.group_c[gi], g.r, in_box & live);
                if mg == 0 {
                    continue;
                }
                for gl in g.first..g.end {
                    let l = self.group_links[gl] as usize;
                    let link = &self.links[l];
                    self.link_centre_batch(l, s);
                    let ml = may_touch(solid, o, &s.link_c[l], link.r, mg & live);
                    if ml == 0 {
                        continue;
                    }
                    self.pose_link_batch(l, s);
                    for k in link.first..link.end {
                        let p = &s.centre[k];
                        let r = self.radius[k];
                        let mk = ml & live & mask(|i| aabb_d2(o, at(p, i)) <= r * r);
                        if mk == 0 {
                            continue;
                        }
                        let d2 = dist2(solid, p);
                        let hit = mk & mask(|i| d2[i] <= r * r);
                        if hit != 0 {
                            hits |= hit;
                            live &= !hit;
                            if ANY || live == 0 {
                                return hits;
                            }
                        }
                    }
                }
            }
        }
        hits | self.self_batch::<ANY>(qs, dof, live, s)
    }

    /// The self-collision part of [`Self::check_batch`], as the scalar `self_pass`: the lanes
    /// of `live` in contact.
    #[inline(always)]
    fn self_batch<const ANY: bool>(&self, qs: &[f64], dof: usize, mut live: Mask, s: &mut BatchScratch) -> Mask {
        let mut hits = 0;
        for (k, gp) in self.group_pairs.iter().enumerate() {
            if live == 0 {
                break;
            }
            let c_inner = s.group_c[gp.inner];
            let rr = gp.rr;
            let co = &s.group_c[gp.outer];
            let mut m = live
                & mask(|i| {
                    let (dx, dy, dz) = (co[0][i] - c_inner[0][i], co[1][i] - c_inner[1][i], co[2][i] - c_inner[2][i]);
                    dx * dx + dy * dy + dz * dz <= rr * rr
                });
            if m == 0 {
                continue;
            }
            if let Some(Some(table)) = self.tables.get(k) {
                for i in 0..LANES {
                    if m & (1 << i) != 0 && table.proves(&qs[i * dof..(i + 1) * dof]) {
                        m &= !(1 << i);
                    }
                }
                if m == 0 {
                    continue;
                }
            }
            let r_inner = gp.r_inner;
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
                let mr = m & live & mask(|i| d2[i] <= reach * reach);
                if mr == 0 {
                    continue;
                }
                for bi in &self.balls[run.first..run.end] {
                    let reach = bi[3] + r_inner;
                    let mb = mr
                        & live
                        & mask(|i| {
                            let (dx, dy, dz) = (bi[0] - g[0][i], bi[1] - g[1][i], bi[2] - g[2][i]);
                            dx * dx + dy * dy + dz * dz <= reach * reach
                        });
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
                        let reach = ri + rp.r;
                        let d2 = dist2_to(&[rp.c.x, rp.c.y, rp.c.z], &u);
                        let mp = mb & live & mask(|i| d2[i] <= reach * reach);
                        if mp == 0 {
                            continue;
                        }
                        for bj in &self.balls[rp.first as usize..rp.end as usize] {
                            let d2 = dist2_to(&[bj[0], bj[1], bj[2]], &u);
                            let r = ri + bj[3];
                            let hit = mp & live & mask(|i| d2[i] <= r * r);
                            if hit != 0 {
                                hits |= hit;
                                live &= !hit;
                                if ANY || live == 0 {
                                    return hits;
                                }
                            }
                        }
                    }
                }
            }
        }
        hits
    }
}
