//! # embodied-models: what a robot *is*
//!
//! Kinematic trees ([`Robot`]) of revolute, continuous, prismatic and fixed joints with
//! position/velocity/acceleration limits; forward kinematics of every link, geometric
//! Jacobians and inverse kinematics; the configuration-space metric in which continuous
//! joints wrap ([`ConfigSpace`]); the seed robots of the source paper ([`builtin`]); URDF and
//! SRDF loading ([`urdf`]); and collision checking ([`collision`]).
//!
//! ```
//! let robot = embodied_models::builtin("irp6-postument").unwrap();
//! let (flange, _tool) = robot.end_effector_poses(robot.home(), 0);
//! assert!((flange.translation.vector.x - 0.6723).abs() < 1e-3);
//! ```
#![forbid(unsafe_code)]

pub mod builtin;
pub mod collision;
pub mod cspace;
pub mod error;
pub mod geometry;
pub mod ik;
pub mod joint;
pub mod rng;
pub mod robot;
pub mod srdf;
pub mod urdf;

pub use builtin::{BUILTIN_NAMES, builtin, builtin_summaries};
pub use collision::{Body, CollisionModel, CollisionScratch, Contact, DistanceReport, Environment, Obstacle};
pub use cspace::{ConfigSpace, wrap_angle};
pub use error::ModelError;
pub use geometry::{ConvexHull, PlacedShape, Shape};
pub use ik::IkOptions;
pub use joint::{Dh, Joint, JointKind, JointLimits};
pub use rng::Rng;
pub use robot::{ClosedForm, EndEffector, Link, Robot, RobotBuilder};

pub use nalgebra;
pub use parry3d_f64 as parry;
