//! # embodied-models: what a robot *is*
//!
//! Kinematic trees ([`Robot`]) of revolute, continuous, prismatic and fixed joints with
//! position/velocity/acceleration limits; forward kinematics of every link, geometric
//! Jacobians and inverse kinematics; the configuration-space metric in which continuous
//! joints wrap ([`ConfigSpace`]); the seed robots of the source paper ([`builtin`]); the file
//! formats robots and MoveIt problems come in ([`formats`]: URDF, SRDF, meshes, MoveIt YAML,
//! joint limits, joint trajectories); and collision checking ([`collision`]).
//!
//! ```
//! let robot = embodied_models::builtin("irp6-postument").unwrap();
//! let (flange, _tool) = robot.end_effector_poses(robot.home(), 0);
//! assert!((flange.translation.vector.x - 0.6723).abs() < 1e-3);
//! ```
#![forbid(unsafe_code)]

pub mod actuator;
pub mod builtin;
pub mod collision;
pub mod cspace;
pub mod error;
pub mod formats;
pub mod geometry;
pub mod ik;
pub mod joint;
pub mod rng;
pub mod robot;

/// URDF loading (the code lives in [`formats::urdf`]; this path is kept for existing users).
pub mod urdf {
    pub use crate::formats::urdf::*;
    pub use crate::formats::{Description, load_description, load_urdf, load_urdf_with, parse_urdf_with_srdf};
}

/// SRDF reading (the code lives in [`formats::srdf`]; this path is kept for existing users).
pub mod srdf {
    pub use crate::formats::srdf::*;
}

pub use actuator::ScrewTriangle;
pub use builtin::{BUILTIN_NAMES, builtin, builtin_summaries};
pub use collision::{Body, CollisionModel, CollisionScratch, Contact, DistanceReport, Environment, Obstacle};
pub use cspace::{ConfigSpace, wrap_angle};
pub use error::{ModelError, Warning};
pub use geometry::{ConvexHull, PlacedShape, Shape};
pub use ik::IkOptions;
pub use joint::{Dh, Joint, JointKind, JointLimits};
pub use rng::Rng;
pub use robot::{ClosedForm, EndEffector, Link, Robot, RobotBuilder};

pub use nalgebra;
pub use parry3d_f64 as parry;
