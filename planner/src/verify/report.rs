//! The checker's settings and the reports of its checks (serialised as they are by
//! `embodied verify --json`).

use serde::Serialize;

use super::finding::Finding;

/// Tolerances and caps of the checker.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CheckSettings {
    /// Relative tolerance on velocity and acceleration limits (rounding in the profiles).
    pub limit_tolerance: f64,
    /// Absolute tolerance on joint position limits, rad or m.
    pub position_tolerance: f64,
    /// Pairs whose bounding spheres are closer than this (m) are measured exactly.
    pub exact_within: f64,
    /// Largest bisection depth of one sample-to-sample segment.
    pub max_depth: u32,
    /// Largest number of distance evaluations spent bisecting one segment.
    pub max_evaluations_per_segment: usize,
    /// Largest number of distance evaluations of one verification, every collision check of it
    /// together (`None`: no limit). Once they are spent, the rest of the motion is not
    /// certified ([`Finding::BudgetExhausted`]): a spent budget never counts as free.
    pub max_evaluations: Option<usize>,
}

impl Default for CheckSettings {
    fn default() -> Self {
        CheckSettings {
            limit_tolerance: 1e-6,
            position_tolerance: 1e-9,
            exact_within: 0.2,
            max_depth: 30,
            max_evaluations_per_segment: 20_000,
            max_evaluations: None,
        }
    }
}

/// Position, velocity and acceleration limits along the timed trajectory.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LimitsReport {
    /// No limit is exceeded.
    pub ok: bool,
    /// The earliest violation.
    pub violation: Option<Finding>,
    /// Samples (and joints) over a limit, counted once per sample and joint and kind.
    pub violations: usize,
    /// Samples checked.
    pub samples: usize,
    /// Largest |velocity| / limit over the trajectory.
    pub max_velocity_ratio: f64,
    /// Largest |acceleration| / limit over the trajectory.
    pub max_acceleration_ratio: f64,
    /// Wall-clock time of the check, s.
    pub time_s: f64,
}

/// Collision freedom of the path through the samples (certified, or sampled at a resolution).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CollisionReport {
    /// The whole path is free (certified, or free at every sample, by the mode).
    pub ok: bool,
    /// The first problem along the path.
    pub violation: Option<Finding>,
    /// Sample-to-sample segments.
    pub segments: usize,
    /// Segments shown free (certified, or free at every sample, by the mode).
    pub certified_segments: usize,
    /// Configurations at which every pair was measured (anchors, segment ends, midpoints).
    pub distance_evaluations: usize,
    /// Bisection midpoints evaluated.
    pub subdivisions: usize,
    /// The deepest bisection.
    pub max_depth: u32,
    /// Pairs checked (link-obstacle plus self-collision pairs), in the plain model.
    pub pairs: usize,
    /// Smallest distance measured at any evaluated configuration (exact when below
    /// `exact_within`, m).
    pub min_clearance_m: f64,
    /// The smallest certified lower bound on the distance over the whole path, m (`NaN` when
    /// the path is only sampled).
    pub certified_clearance_m: f64,
    /// The pair at the smallest measured distance.
    pub closest_pair: Option<[String; 2]>,
    /// Wall-clock time of the check, s.
    pub time_s: f64,
}

/// The closed-chain constraint over the plan's spans.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ClosureReport {
    /// Every span keeps its relative tool pose.
    pub ok: bool,
    /// The earliest drift.
    pub violation: Option<Finding>,
    /// Spans checked.
    pub spans: usize,
    /// Samples inside spans.
    pub samples: usize,
    /// Largest position error of the relative tool pose, m.
    pub max_position_error_m: f64,
    /// Largest angle error of the relative tool pose, rad.
    pub max_angle_error_rad: f64,
    /// Wall-clock time of the check, s.
    pub time_s: f64,
}

/// Everything checked for one agent's trajectory.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TrajectoryReport {
    /// Limits, collisions and closure all passed.
    pub certified: bool,
    /// Duration of the trajectory, s.
    pub duration_s: f64,
    /// Samples of the trajectory.
    pub samples: usize,
    /// Position, velocity and acceleration limits.
    pub limits: LimitsReport,
    /// Collision freedom.
    pub collision: CollisionReport,
    /// The closed-chain constraint.
    pub closure: ClosureReport,
}

impl TrajectoryReport {
    /// The first finding of each check, in the order limits, collision, closure.
    pub fn findings(&self) -> Vec<&Finding> {
        [&self.limits.violation, &self.collision.violation, &self.closure.violation].into_iter().flatten().collect()
    }
}
