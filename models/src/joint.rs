//! Joints: the degrees of freedom of a kinematic tree and their limits.

use nalgebra::{Isometry3, Translation3, Unit, UnitQuaternion, Vector3};

/// The kind of a joint.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum JointKind {
    /// Rotation about `axis` between `lower` and `upper`.
    Revolute,
    /// Rotation about `axis` with no position limits (an angle: it wraps), as on Polycrank.
    Continuous,
    /// Translation along `axis` between `lower` and `upper`.
    Prismatic,
    /// No motion; not a degree of freedom.
    Fixed,
}

impl JointKind {
    /// The string used in CLI output and JSON.
    pub fn as_str(self) -> &'static str {
        match self {
            JointKind::Revolute => "revolute",
            JointKind::Continuous => "continuous",
            JointKind::Prismatic => "prismatic",
            JointKind::Fixed => "fixed",
        }
    }
}

/// Position, velocity and acceleration limits of one degree of freedom.
///
/// Continuous joints have `lower = -inf`, `upper = +inf`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointLimits {
    /// Lower position bound, rad or m.
    pub lower: f64,
    /// Upper position bound, rad or m.
    pub upper: f64,
    /// |q-dot| bound, rad/s or m/s.
    pub max_velocity: f64,
    /// |q-ddot| bound, rad/s^2 or m/s^2.
    pub max_acceleration: f64,
}

impl JointLimits {
    /// Limits from position bounds (rad or m), velocity bound (rad/s or m/s) and acceleration bound (rad/s^2 or m/s^2).
    pub fn new(lower: f64, upper: f64, max_velocity: f64, max_acceleration: f64) -> Self {
        Self { lower, upper, max_velocity, max_acceleration }
    }
    /// Limits of a joint without position bounds.
    pub fn continuous(max_velocity: f64, max_acceleration: f64) -> Self {
        Self::new(f64::NEG_INFINITY, f64::INFINITY, max_velocity, max_acceleration)
    }
    /// Whether the position bounds are finite.
    pub fn is_bounded(&self) -> bool {
        self.lower.is_finite() && self.upper.is_finite()
    }
    /// Clamp a position into the bounds.
    pub fn clamp(&self, q: f64) -> f64 {
        q.clamp(self.lower, self.upper)
    }
}

/// One joint of the kinematic tree.
///
/// The child link frame is `parent * origin * motion(q + offset) * post`, where `motion` is a
/// rotation about (revolute/continuous) or a translation along (prismatic) `axis`. URDF joints
/// have `post = identity`; standard DH joints have `origin = identity`, `axis = z` and
/// `post = Tz(d) Tx(a) Rx(alpha)`, so that the child link frame is DH frame i.
#[derive(Debug, Clone)]
pub struct Joint {
    /// The joint's name.
    pub name: String,
    /// Revolute, continuous, prismatic or fixed.
    pub kind: JointKind,
    /// Index of the parent link in the robot's links.
    pub parent_link: usize,
    /// Index of the child link in the robot's links.
    pub child_link: usize,
    /// Fixed transform from the parent link frame to the joint frame.
    pub origin: Isometry3<f64>,
    /// Rotation or translation axis, in the joint frame.
    pub axis: Unit<Vector3<f64>>,
    /// Added to the joint variable before the motion (DH theta offsets).
    pub offset: f64,
    /// Fixed transform after the motion (DH `Tz(d) Tx(a) Rx(alpha)`; identity for URDF joints).
    pub post: Isometry3<f64>,
    /// Position, velocity and acceleration limits.
    pub limits: JointLimits,
    /// Index into the robot's configuration vector; `None` for fixed joints.
    pub dof_index: Option<usize>,
    /// `Some((dof, multiplier, offset))`: this joint follows another degree of freedom
    /// (URDF `<mimic>`); it is then not a degree of freedom of its own.
    pub mimic: Option<(usize, f64, f64)>,
}

impl Joint {
    /// The local transform origin * motion(value) * post for a joint variable value.
    #[inline]
    pub fn local_transform(&self, value: f64) -> Isometry3<f64> {
        let v = value + self.offset;
        let motion = match self.kind {
            JointKind::Revolute | JointKind::Continuous => {
                Isometry3::from_parts(Translation3::identity(), UnitQuaternion::from_axis_angle(&self.axis, v))
            }
            JointKind::Prismatic => {
                Isometry3::from_parts(Translation3::from(self.axis.into_inner() * v), UnitQuaternion::identity())
            }
            JointKind::Fixed => Isometry3::identity(),
        };
        self.origin * motion * self.post
    }
}

/// Standard (distal) Denavit-Hartenberg parameters: `A = Rz(theta) Tz(d) Tx(a) Rx(alpha)`,
/// with `theta = q + theta_offset`.
#[derive(Debug, Clone, Copy)]
pub struct Dh {
    /// Added to the joint variable: `theta = q + theta_offset` (rad).
    pub theta_offset: f64,
    /// Offset along the previous z axis (m).
    pub d: f64,
    /// Length along the new x axis (m).
    pub a: f64,
    /// Twist about the new x axis (rad).
    pub alpha: f64,
}

impl Dh {
    /// DH parameters `theta_offset` (rad), `d` (m), `a` (m), `alpha` (rad).
    pub const fn new(theta_offset: f64, d: f64, a: f64, alpha: f64) -> Self {
        Self { theta_offset, d, a, alpha }
    }
    /// The fixed part `Tz(d) Tx(a) Rx(alpha)` that follows the joint rotation.
    pub fn post(&self) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(self.a, 0.0, self.d),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), self.alpha),
        )
    }
}
