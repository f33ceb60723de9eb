//! Lever arms of the motion certificate on the sphere path: how far a sphere centre can move
//! while the joints move along a sub-interval of a straight joint-space segment.
//!
//! An inflated query poses the robot at the midpoint `q(tm)` of a sub-interval over which
//! every DOF changes by at most `step_i` either side (already scaled, see
//! [`super::Inflation::step`]). A point `p` carried by the robot moves, relative to a body
//! `stop` up its chain, by at most `sum_j sup rho_j * s_j`, over the moving joints `j` between
//! `p` and `stop`, where `s_j` is joint `j`'s change (a mimic joint's is its multiplier times
//! its DOF's) and `rho_j` is the distance of `p` from joint `j`'s axis over the sub-interval
//! (1 for a prismatic joint): the triangle inequality over the joints.
//!
//! Two bounds on `sup rho_j`, both sound; the arm is the smaller:
//!
//! - **Static** ([`Arms::arm`]): valid in every configuration. The sphere's own joint counts its
//!   exact, constant distance from the axis; a joint further up counts the distance to its
//!   origin, bounded by the chain's fixed lengths.
//! - **At the midpoint**: `rho_j` depends only on the joints between `j` and `p` (joint `j` and
//!   those above it move the axis and the point together), and distance from a line is
//!   1-Lipschitz, so over the sub-interval `rho_j <= rho_j(tm) + M_j`, where `M_j` bounds how
//!   far `p` moves in joint `j`'s frame: the margin summed so far over the joints below `j`.
//!   Walking from the sphere up its chain gives both at once. For an arm that is not stretched
//!   out this is far below the static arm (the UR5's base joint sees its wrist at about its
//!   full reach statically), and it costs a cross product per joint, only for the spheres the
//!   query actually tests with margins.
//!
//! **Along the straight motion** (when the query knows its direction, `dir`: the certificate's
//! sub-intervals `q(s) = q(tm) + s dir`, `|s| <= 1`). The sum above adds the joints' lever terms
//! as if they all pushed the centre the same way; they rarely do (the UR5's base joint moves
//! its arm across the plane its shoulder and elbow move it in). So the centre's path is also
//! bounded from its velocity at the midpoint, `v = sum_j dir_j u_j` with `u_j = w_j x (p - o_j)`
//! (`w_j` for a prismatic joint), which the walk gets from the cross product it takes anyway:
//! the path from `s = 0` to any `|s| <= 1` is at most `|v| + sup |p''| / 2`. Differentiating
//! `u_j` along the motion: `w_j` turns and `o_j` moves with the joints above `j`, at angular
//! speed at most `A_j` (the steps of the joints above `j` up to `stop`), and by the Jacobi
//! identity that part of `u_j'` is `Omega x u_j`, at most `A_j rho_j`; the rest is
//! `w_j x (the velocity of p relative to j's parent frame)`, at most the sum of the terms
//! `a_k = d_k rho_k` of the joints at and below `j`. So `|p''| <= sum_j a_j (2 A_j + d_j)` with
//! every `rho` its sub-interval bound above, and the bound is
//! `|v| + sum_j a_j (A_j + d_j / 2)`. The margin is the smaller of the two bounds. For the
//! short sub-intervals of the certificate the second term is small and the bound is within a
//! few percent of the sampled motion (the `tightness` test prints it: median 1.00-1.03 times
//! the path length on the UR5, against 1.3 for the sum and 2.25 for the static arms). It grows
//! at least in proportion to the sub-interval too: `|v|` in proportion, the second term as the
//! product of two terms that do. A query whose motion is any in the box of the steps (the
//! cell tables) has no direction and keeps the sum.
//!
//! **Pairs** ([`SphereGeom::pair_margin`]): what must be bounded for a self-collision pair is
//! how much the distance `|p_i - p_j|` can shrink, not how far each centre moves. A joint `k`
//! that moves `p_i` (and not `p_j`) changes that distance at a rate at most
//! `min(rho_k(p_i), rho_k(p_j)) |dv_k|`: along the unit direction `u` from `p_j` to `p_i`,
//! `u . (w x (p_i - o)) = u . (w x (p_j - o))` since `u x (p_i - p_j) = 0`. The distance of
//! the *other* centre from the axis is bounded the same way at the midpoint, walking down
//! from the common body (the axis moves relative to it only through the joints above `k`).
//! So a joint that carries one link about an axis through the other's sphere (the UR5's base
//! joint, about `base_link`'s sphere) does not count at all for that pair. Along a straight
//! motion, the distance also shrinks by at most the path of `p_i - p_j` in the common body's
//! frame: `|v_i - v_j|` (both velocities relative to that body) plus both second-order terms.
//!
//! The links' and pairs' margins of [`super::Inflation`] (static, from the per-link arms) stay
//! valid pre-filters: every bound here is at most the static per-sphere one, which they bound.

use nalgebra::{Point3, Vector3};

use super::super::{RobotGeom, Value};
use super::{Link, SphereGeom, SphereScratch};

/// Deepest chain (moving joints between a sphere and a pair's common body) that pair margins
/// tighten; deeper ones fall back to the sum of the two spheres' margins. Arms, and arms on a
/// track or a mobile base, have far fewer; the buffer is zeroed on every call (24 cost 0.8% of
/// planning on the MotionBenchMaker UR5 problems).
pub(super) const DEEP: usize = 12;

/// Static lever arms, prepared at construction.
///
/// Every sphere `k` has one *entry* per body on its chain, from its link's body up to, not
/// including, the base (body 0): entry `e` of sphere `k` is at `off[k] + e`.
#[derive(Debug, Clone, Default)]
pub(super) struct Arms {
    /// Each sphere's body.
    body: Vec<u32>,
    /// Each entry's body.
    entry_body: Vec<u32>,
    /// Each sphere's first entry.
    off: Vec<u32>,
    /// Static arm of each sphere entry (0 for joints that do not move).
    arm: Vec<f64>,
    /// Each body's joint axis in its parent's frame (`pre` rotation times axis).
    axis: Vec<Vector3<f64>>,
}

impl Arms {
    /// The joint axes in the parents' frames as the sphere path turns its body frames (see
    /// `turn_to_z`): `pre_r * axis` of each turned body. Call once the bodies are turned.
    pub(super) fn use_turned_axes(&mut self, bodies: &[super::Body]) {
        self.axis = bodies.iter().map(|b| b.pre_r * b.axis).collect();
    }

    pub(super) fn new(g: &RobotGeom, links: &[Link], centre: &[Vector3<f64>]) -> Arms {
        let axis = g.bodies.iter().map(|b| b.pre.rotation * b.axis.into_inner()).collect();
        let mut arms = Arms { axis, ..Arms::default() };
        for link in links {
            for c in &centre[link.first..link.end] {
                arms.body.push(link.body as u32);
                arms.off.push(arms.arm.len() as u32);
                // Walk from the sphere's body to the base; `dist` bounds the distance from the
                // current body's origin to the centre.
                let mut dist = c.norm();
                let mut b = link.body;
                let mut own = true;
                while b != 0 {
                    let body = &g.bodies[b];
                    let post = body.post.map_or(0.0, |p| p.translation.vector.norm());
                    let mut arm = if body.prismatic { 1.0 } else { dist + post };
                    if own && !body.prismatic {
                        // Exact: the centre's distance from this joint's axis never changes.
                        let p = match body.post {
                            Some(post) => (post * Point3::from(*c)).coords,
                            None => *c,
                        };
                        let a = body.axis.into_inner();
                        arm = arm.min((p - a * p.dot(&a)).norm());
                    }
                    own = false;
                    arms.arm.push(if matches!(body.value, Value::Zero) { 0.0 } else { arm });
                    arms.entry_body.push(b as u32);
                    dist += post + body.reach + body.pre.translation.vector.norm();
                    b = body.parent;
                }
            }
        }
        arms
    }
}

impl SphereGeom {
    /// How much joint `value` changes when the DOFs change by `step`.
    #[inline(always)]
    fn joint_step(value: Value, step: &[f64]) -> f64 {
        match value {
            Value::Dof(i) => step[i],
            Value::Mimic(d, m, _) => step[d] * m.abs(),
            Value::Zero => 0.0,
        }
    }

    /// Body `b`'s joint axis (unit) and a point on it, in the world, in the pose of `s`.
    #[inline(always)]
    fn axis_at(&self, b: usize, s: &SphereScratch) -> (Vector3<f64>, Vector3<f64>) {
        let body = &self.bodies[b];
        if body.post.is_none() && !body.prismatic {
            // The body's posed frame is the joint's: origin on the axis, z along it (turned).
            let r = &s.rot[b];
            return (Vector3::new(r[(0, 2)], r[(1, 2)], r[(2, 2)]), s.pos[b]);
        }
        let (r, t) = (&s.rot[body.parent], &s.pos[body.parent]);
        (r * self.arms.axis[b], r * body.pre_t + t)
    }

    /// The velocity of the world point `p` per unit turn of body `b`'s (revolute) joint:
    /// `w x (p - o)`, its norm the distance of `p` from the axis.
    #[inline(always)]
    fn lever(&self, b: usize, p: &Vector3<f64>, s: &SphereScratch) -> Vector3<f64> {
        let (w, o) = self.axis_at(b, s);
        w.cross(&(p - o))
    }

    /// Distance of the world point `p` from body `b`'s joint axis, in the pose of `s`.
    #[inline(always)]
    fn rho(&self, b: usize, p: &Vector3<f64>, s: &SphereScratch) -> f64 {
        self.lever(b, p, s).norm()
    }

    /// How much joint `value` changes, with its sign, when the DOFs change by `dir`.
    #[inline(always)]
    fn joint_dir(value: Value, dir: &[f64]) -> f64 {
        match value {
            Value::Dof(i) => dir[i],
            Value::Mimic(d, m, _) => dir[d] * m,
            Value::Zero => 0.0,
        }
    }

    /// Walks sphere `k`'s chain up to body `stop` (one of its body's ancestors, or 0 for the
    /// world), calling `each(body, arm, joint step)` for every joint that moves. With `at` (the
    /// pose of the sub-interval's midpoint, `k` posed), arms are tightened by the midpoint
    /// distances, and with `dir` too (the signed steps of a straight motion) the centre's
    /// velocity at the midpoint and the second-order term are summed (see the module
    /// documentation).
    #[inline(always)]
    fn walk(
        &self,
        k: usize,
        stop: usize,
        step: &[f64],
        at: Option<&SphereScratch>,
        dir: Option<&[f64]>,
        mut each: impl FnMut(usize, f64, f64),
    ) -> Walked {
        let arms = &self.arms;
        let mut b = arms.body[k] as usize;
        let mut e = arms.off[k] as usize;
        let first = e;
        let mut m = 0.0;
        // The velocity, the joint steps summed from the centre up (`climbed`), and the sums
        // `sum a_j * climbed_j` and `sum a_j * d_j` of the second-order term.
        let (mut v, mut climbed, mut a_climbed, mut a_d) = (Vector3::zeros(), 0.0, 0.0, 0.0);
        let straight = at.zip(dir);
        while b != stop && b != 0 {
            let body = &self.bodies[b];
            let d = Self::joint_step(body.value, step);
            if d > 0.0 {
                let mut arm = arms.arm[e];
                if let Some((s, dir)) = straight {
                    let u = if body.prismatic {
                        self.axis_at(b, s).0
                    } else {
                        let u = self.lever(b, &s.centre[k], s);
                        if e != first {
                            arm = arm.min(u.norm() + m);
                        }
                        u
                    };
                    v += u * Self::joint_dir(body.value, dir);
                    let a = arm * d;
                    climbed += d;
                    a_climbed += a * climbed;
                    a_d += a * d;
                } else if let Some(s) = at
                    && e != first
                    && !body.prismatic
                {
                    arm = arm.min(self.rho(b, &s.centre[k], s) + m);
                }
                each(b, arm, d);
                m += arm * d;
            }
            e += 1;
            b = body.parent;
        }
        // `sum a_j (A_j + d_j / 2)` with `A_j` the steps above joint `j`: `climbed * m` is
        // `sum a_j * (all steps)`.
        let second = if straight.is_some() { climbed * m - a_climbed + 0.5 * a_d } else { f64::INFINITY };
        Walked { sum: m, v, second }
    }

    /// For the batches' straight-motion margins (`lanes`), for the joint steps `step` (already
    /// scaled): per body, the factor `d_j (A_j + d_j / 2)` of its joint in the second-order term
    /// `sum_j a_j (A_j + d_j / 2)` of the module documentation (`A_j` the steps of the joints
    /// above `j`), and the steps of its joint and all above it (`above`). The factors depend on
    /// the joint only, so a sphere's term is its static arms times them ([`Self::static_second`]):
    /// with every `rho_j` its static arm, valid at every pose, so at the midpoint of every piece.
    /// `false` when `step` does not hold a value for every DOF a joint reads.
    pub(super) fn second_factors(&self, step: &[f64], factor: &mut Vec<f64>, above: &mut Vec<f64>) -> bool {
        let n = self.bodies.len();
        factor.clear();
        factor.resize(n, 0.0);
        above.clear();
        above.resize(n, 0.0);
        for b in 1..n {
            let body = &self.bodies[b];
            // Bodies come after their parents (as posing needs).
            if !Self::reads_within(body.value, step) || body.parent >= b {
                return false;
            }
            let d = Self::joint_step(body.value, step);
            let a = above[body.parent];
            factor[b] = d * (a + 0.5 * d);
            above[b] = a + d;
        }
        true
    }

    /// Sphere `k`'s second-order term with its static arms and the joints' `factor`s
    /// ([`Self::second_factors`]), and the steps of its chain (`above` of its body).
    #[inline]
    pub(super) fn static_second(&self, k: usize, factor: &[f64], above: &[f64]) -> (f64, f64) {
        let arms = &self.arms;
        let off = arms.off[k] as usize;
        let end = arms.off.get(k + 1).map_or(arms.arm.len(), |&e| e as usize);
        let second =
            arms.arm[off..end].iter().zip(&arms.entry_body[off..end]).map(|(&arm, &b)| arm * factor[b as usize]).sum();
        (second, above[arms.body[k] as usize])
    }

    /// Body `b`'s joint change, with its sign, when the DOFs change by `dir` (`None` when `dir`
    /// holds no value for its DOF).
    pub(super) fn body_dir(&self, b: usize, dir: &[f64]) -> Option<f64> {
        let value = self.bodies.get(b)?.value;
        Self::reads_within(value, dir).then(|| Self::joint_dir(value, dir))
    }

    /// `values` holds the DOF joint `value` reads (if any).
    fn reads_within(value: Value, values: &[f64]) -> bool {
        match value {
            Value::Dof(i) | Value::Mimic(i, _, _) => i < values.len(),
            Value::Zero => true,
        }
    }

    /// A bound on [`Self::margin`] against the world for every sphere of link `l`, from the
    /// link's bounding sphere at the midpoint pose (`l`'s centre posed in `s`): a sphere's
    /// distance from a joint's axis is at most the bounding centre's plus the bounding radius,
    /// so walking the chain once with that distance bounds each sphere's walk term by term.
    /// A filter: a sphere farther than this from an obstacle needs no walk of its own.
    #[inline]
    pub(super) fn link_margin(&self, l: usize, step: &[f64], s: &SphereScratch) -> f64 {
        let link = &self.links[l];
        let c = s.link_c[l];
        let mut b = link.body;
        let mut m = 0.0;
        while b != 0 {
            let body = &self.bodies[b];
            let d = Self::joint_step(body.value, step);
            if d > 0.0 {
                let arm = if body.prismatic { 1.0 } else { self.rho(b, &c, s) + link.r + m };
                m += arm * d;
            }
            b = body.parent;
        }
        m + 1e-12
    }

    /// How far sphere `k`'s centre can move relative to body `stop` (one of its body's
    /// ancestors, or 0 for the world) when the joints move by at most `step` (already scaled)
    /// either side of the pose in `at` (with `k` posed), or of any pose without `at`; with `dir`
    /// too, along the straight motion `q(tm) + s dir`, `|s| <= 1` (`|dir|` at most `step`).
    #[inline]
    pub(super) fn margin(
        &self,
        k: usize,
        stop: usize,
        step: &[f64],
        at: Option<&SphereScratch>,
        dir: Option<&[f64]>,
    ) -> f64 {
        self.walk(k, stop, step, at, dir, |_, _, _| {}).bound() + 1e-12
    }

    /// How much the distance between the centres of spheres `i` and `j` of a self-collision
    /// pair with common body `stop` can shrink when the joints move by at most `step` (already
    /// scaled) either side of the pose in `s` (both posed); with `dir`, along the straight
    /// motion as in [`Self::margin`]. At most `margin(i, stop) + margin(j, stop)`.
    #[inline]
    pub(super) fn pair_margin(
        &self,
        i: usize,
        j: usize,
        stop: usize,
        step: &[f64],
        dir: Option<&[f64]>,
        s: &SphereScratch,
    ) -> f64 {
        let mut own = [[(0usize, 0.0f64, 0.0f64); DEEP]; 2];
        let mut len = [0usize; 2];
        let mut walk = |side: usize, k: usize| {
            self.walk(k, stop, step, Some(s), dir, |b, arm, d| {
                if len[side] < DEEP {
                    own[side][len[side]] = (b, arm, d);
                }
                len[side] += 1;
            })
        };
        let wi = walk(0, i);
        let wj = walk(1, j);
        // The relative velocity bound (infinite without `dir`).
        let moving = (wi.v - wj.v).norm() + wi.second + wj.second;
        if len[0] > DEEP || len[1] > DEEP {
            return (wi.bound() + wj.bound()).min(moving) + 2e-12;
        }
        // Each side's joints, from the common body down, against the other side's centre:
        // `moved` bounds how far that centre moves in the current joint's parent frame.
        let mut total = 0.0;
        for (side, (other, moved)) in [(s.centre[j], wj.sum), (s.centre[i], wi.sum)].into_iter().enumerate() {
            let mut moved = moved;
            for &(b, arm, d) in own[side][..len[side]].iter().rev() {
                let cross = if self.bodies[b].prismatic { 1.0 } else { self.rho(b, &other, s) + moved };
                total += arm.min(cross) * d;
                moved += cross * d;
            }
        }
        total.min(moving) + 2e-12
    }
}

/// What [`SphereGeom::walk`] sums along a sphere's chain.
#[derive(Debug, Clone, Copy)]
struct Walked {
    /// The margin as the sum of arm times step over the joints.
    sum: f64,
    /// The centre's velocity at the midpoint, `sum_j dir_j u_j` (zero without a direction).
    v: Vector3<f64>,
    /// The second-order term (infinite without a direction).
    second: f64,
}

impl Walked {
    /// The smaller of the two bounds on the centre's motion (without slack).
    #[inline(always)]
    fn bound(&self) -> f64 {
        self.sum.min(self.v.norm() + self.second)
    }
}

#[cfg(test)]
mod tests;
