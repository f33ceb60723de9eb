//! Collision shapes attached to links and obstacles.
//!
//! A closed enum of the shapes the toolkit knows (as parry's `TypedShape`), so that hot paths can
//! `match` and use analytic tests, while general pairs fall back to parry's GJK.

use std::sync::Arc;

use nalgebra::{Isometry3, Point3, Vector3};
use parry3d_f64::shape::ConvexPolyhedron;

/// A collision shape in its own frame.
#[derive(Debug, Clone)]
pub enum Shape {
    /// A ball centred at the origin.
    Sphere {
        /// Radius (m).
        radius: f64,
    },
    /// The set of points within `radius` of the segment `a`-`b`.
    Capsule {
        /// One end of the segment, in the shape's frame.
        a: Point3<f64>,
        /// The other end of the segment, in the shape's frame.
        b: Point3<f64>,
        /// Radius (m).
        radius: f64,
    },
    /// A box centred at the origin with these half extents.
    Cuboid {
        /// Half the box's size along x, y and z (m).
        half_extents: Vector3<f64>,
    },
    /// A cylinder along z, centred at the origin (URDF convention).
    Cylinder {
        /// Radius (m).
        radius: f64,
        /// Half the length along z (m).
        half_height: f64,
    },
    /// The convex hull of a mesh (URDF `<mesh>` collision elements are taken as convex hulls).
    ConvexMesh(Arc<ConvexHull>),
}

/// A convex polyhedron with its vertices kept for bounding-volume computation.
#[derive(Debug)]
pub struct ConvexHull {
    /// The hull's vertices, in the shape's frame.
    pub points: Vec<Point3<f64>>,
    /// The hull as a parry polyhedron, for the narrow phase.
    pub polyhedron: ConvexPolyhedron,
}

impl ConvexHull {
    /// The convex hull of a point cloud; `None` if the points are degenerate (flat or too few).
    pub fn from_points(points: &[Point3<f64>]) -> Option<Self> {
        let polyhedron = ConvexPolyhedron::from_convex_hull(points)?;
        let points = polyhedron.points().to_vec();
        Some(Self { points, polyhedron })
    }
}

impl Shape {
    /// A ball of `radius` (m) centred at the origin.
    pub fn sphere(radius: f64) -> Self {
        Shape::Sphere { radius }
    }
    /// A capsule around the segment `a`-`b` (m) with `radius` (m).
    pub fn capsule(a: [f64; 3], b: [f64; 3], radius: f64) -> Self {
        Shape::Capsule { a: Point3::from(a), b: Point3::from(b), radius }
    }
    /// A box centred at the origin with half extents `hx`, `hy`, `hz` (m).
    pub fn cuboid(hx: f64, hy: f64, hz: f64) -> Self {
        Shape::Cuboid { half_extents: Vector3::new(hx, hy, hz) }
    }
    /// A cylinder along z centred at the origin, `radius` and `half_height` in m.
    pub fn cylinder(radius: f64, half_height: f64) -> Self {
        Shape::Cylinder { radius, half_height }
    }

    /// Centre and radius of a sphere (in the shape's frame) enclosing the shape.
    pub fn bounding_sphere(&self) -> (Point3<f64>, f64) {
        match self {
            Shape::Sphere { radius } => (Point3::origin(), *radius),
            Shape::Capsule { a, b, radius } => (nalgebra::center(a, b), (b - a).norm() / 2.0 + radius),
            Shape::Cuboid { half_extents } => (Point3::origin(), half_extents.norm()),
            Shape::Cylinder { radius, half_height } => {
                (Point3::origin(), (radius * radius + half_height * half_height).sqrt())
            }
            Shape::ConvexMesh(hull) => {
                let n = hull.points.len().max(1) as f64;
                let c = Point3::from(hull.points.iter().fold(Vector3::zeros(), |s, p| s + p.coords) / n);
                let r = hull.points.iter().map(|p| (p - c).norm()).fold(0.0, f64::max);
                (c, r)
            }
        }
    }

    /// A short human name of the shape kind.
    pub fn kind(&self) -> &'static str {
        match self {
            Shape::Sphere { .. } => "sphere",
            Shape::Capsule { .. } => "capsule",
            Shape::Cuboid { .. } => "box",
            Shape::Cylinder { .. } => "cylinder",
            Shape::ConvexMesh(_) => "mesh",
        }
    }
}

/// A shape placed in a frame (a link frame or the world).
#[derive(Debug, Clone)]
pub struct PlacedShape {
    /// Pose of the shape's frame in the enclosing frame.
    pub pose: Isometry3<f64>,
    /// The shape.
    pub shape: Shape,
}

impl PlacedShape {
    /// `shape` placed at `pose`.
    pub fn new(pose: Isometry3<f64>, shape: Shape) -> Self {
        Self { pose, shape }
    }
}
