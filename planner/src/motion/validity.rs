//! The planner's own validity checks: configurations and straight segments in C-space, counted.
//!
//! Segments are certified by default (`CollisionModel::certify`: free for the whole continuum
//! of configurations between their ends). With [`super::EdgeCheck::Sampled`] they are sampled
//! at the resolution instead, in bisection order (midpoint first, then quarter points...) because a
//! colliding segment usually collides somewhere in the middle: the first hit ends the check.
//! The independent checker in [`crate::verify`] walks segments its own way.
//!
//! [`Validity::segment_probed`] is the cheap, incomplete test of lazy RRT-Connect: plain
//! collision checks of sampled configurations, before a segment is certified (or instead of it,
//! for tree edges that never end up on a path).

use std::time::Instant;

use embodied_models::ConfigSpace;
use embodied_models::collision::{CollisionModel, CollisionScratch};

use crate::deadline::Deadline;

/// Counted validity queries against one collision model at one resolution.
pub(crate) struct Validity<'m> {
    pub model: &'m CollisionModel,
    pub space: ConfigSpace,
    pub resolution: f64,
    /// `Some(tolerance)`: segments are certified, not sampled.
    certify: Option<f64>,
    scratch: CollisionScratch,
    buf: Vec<f64>,
    pub collision_checks: u64,
    pub edges_checked: usize,
    /// Collision checks of [`Self::segment_probed`] (also counted in `collision_checks`).
    pub probe_checks: u64,
}

impl<'m> Validity<'m> {
    pub fn new(model: &'m CollisionModel, resolution: f64) -> Self {
        let robot = model.robot();
        Self {
            model,
            space: robot.config_space(),
            resolution,
            certify: None,
            scratch: model.scratch(),
            buf: vec![0.0; robot.dof()],
            collision_checks: 0,
            edges_checked: 0,
            probe_checks: 0,
        }
    }

    /// Check segments as `check` says.
    pub fn with_edge_check(mut self, check: super::EdgeCheck) -> Self {
        self.certify = match check {
            super::EdgeCheck::Certified { tolerance } => Some(tolerance),
            super::EdgeCheck::Sampled => None,
        };
        self
    }

    /// Within the position limits and collision-free.
    pub fn config_free(&mut self, q: &[f64]) -> bool {
        if !self.model.robot().within_limits(q) {
            return false;
        }
        self.collision_checks += 1;
        !self.model.collides_with(q, &mut self.scratch)
    }

    /// The straight C-space segment `a`-`b` (short way on continuous joints) is collision-free
    /// at `resolution` (largest joint step between checked points). The end points are taken as
    /// already checked.
    pub fn segment_free(&mut self, a: &[f64], b: &[f64]) -> bool {
        self.edges_checked += 1;
        if let Some(tolerance) = self.certify {
            let (free, checks) = self.model.certify(a, b, tolerance, false, &mut self.scratch);
            self.collision_checks += u64::from(checks);
            return free;
        }
        self.sampled(a, b, self.resolution)
    }

    /// No sampled configuration of the segment `a`-`b` collides, at `resolution` (largest joint
    /// step), ends excluded. A probe, not a certificate: an obstacle between samples is missed.
    pub fn segment_probed(&mut self, a: &[f64], b: &[f64], resolution: f64) -> bool {
        let before = self.collision_checks;
        let free = self.sampled(a, b, resolution);
        self.probe_checks += self.collision_checks - before;
        free
    }

    /// Sampled check of the segment's inner points, in bisection order.
    fn sampled(&mut self, a: &[f64], b: &[f64], resolution: f64) -> bool {
        let n = steps(&self.space, a, b, resolution);
        if n < 2 {
            return true;
        }
        let mut stride = 1usize;
        while stride * 2 < n {
            stride *= 2;
        }
        let mut first_level = true;
        loop {
            let mut i = stride;
            while i < n {
                if first_level || (i / stride) % 2 == 1 {
                    let t = i as f64 / n as f64;
                    self.space.interpolate_into(a, b, t, &mut self.buf);
                    self.collision_checks += 1;
                    if self.model.collides_with(&self.buf, &mut self.scratch) {
                        return false;
                    }
                }
                i += stride;
            }
            if stride == 1 {
                return true;
            }
            stride /= 2;
            first_level = false;
        }
    }
}

/// Number of equal steps so that no joint moves more than `resolution` per step (at least 1).
pub(crate) fn steps(space: &ConfigSpace, a: &[f64], b: &[f64], resolution: f64) -> usize {
    let max = space.max_joint_step(a, b);
    let n = (max / resolution).ceil();
    if n.is_finite() && n >= 1.0 { n.min(1e7) as usize } else { 1 }
}

/// Units of planning work against a [`Deadline`]: samples drawn, tree extensions, A*
/// expansions. The expansion budget of the deadline bounds this count; the clock and the
/// cancellation flag are read every few units (a unit costs at most a few collision checks).
pub(crate) struct Budget<'d> {
    deadline: &'d Deadline,
    pub work: u64,
    since_clock: u32,
    pub started: Instant,
}

impl<'d> Budget<'d> {
    pub fn new(deadline: &'d Deadline) -> Self {
        Self { deadline, work: 0, since_clock: 0, started: Instant::now() }
    }

    /// Count `units` of work; true when planning must stop now.
    #[inline]
    pub fn spend(&mut self, units: u64) -> bool {
        self.work += units;
        self.since_clock += 1;
        let read_clock = self.since_clock >= 8 && self.deadline.has_clock();
        if read_clock {
            self.since_clock = 0;
        }
        self.deadline.check(self.work, read_clock).is_some()
    }

    /// True when the deadline has passed (reads the clock now).
    pub fn expired(&self) -> bool {
        self.deadline.check(self.work, true).is_some()
    }
}
