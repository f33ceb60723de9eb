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
    /// Its vertex graph, for support queries that climb it (see [`ConvexHull::support_index`]).
    climb: Climb,
}

/// A hull's vertex graph (the neighbours of vertex `v` are `adj[first[v]..first[v + 1]]`) and,
/// for each cell of a cube map of directions ([`cube_cell`]), the vertex farthest along its
/// centre (where a climb starts).
#[derive(Debug, Clone)]
struct Climb {
    first: Vec<u32>,
    adj: Vec<u32>,
    /// The point of each entry of `adj` (read in order with it: no second lookup).
    adj_points: Vec<Point3<f64>>,
    starts: Vec<u32>,
}

/// Cells per side of each face of the cube map of directions where climbs start.
const CUBE: usize = 8;

/// The cell of the cube map holding direction `d` (a face by the largest component and its
/// sign, then a cell of that face by the other two components over it); 0 for a zero or NaN
/// direction.
fn cube_cell(d: &Vector3<f64>) -> usize {
    let a = d.abs();
    let (axis, u, v) = if a.x >= a.y && a.x >= a.z {
        (0, d.y, d.z)
    } else if a.y >= a.z {
        (1, d.z, d.x)
    } else {
        (2, d.x, d.y)
    };
    let m = a[axis];
    if m.is_nan() || m <= 0.0 {
        return 0;
    }
    let face = 2 * axis + usize::from(d[axis] < 0.0);
    let at = |t: f64| (((t / m + 1.0) * 0.5 * CUBE as f64) as usize).min(CUBE - 1);
    (face * CUBE + at(u)) * CUBE + at(v)
}

/// The direction at the centre of cube map cell `cell`.
fn cube_dir(cell: usize) -> Vector3<f64> {
    let (face, rest) = (cell / (CUBE * CUBE), cell % (CUBE * CUBE));
    let centre = |i: usize| (i as f64 + 0.5) / CUBE as f64 * 2.0 - 1.0;
    let (u, v) = (centre(rest / CUBE), centre(rest % CUBE));
    let s = if face % 2 == 0 { 1.0 } else { -1.0 };
    match face / 2 {
        0 => Vector3::new(s, u, v),
        1 => Vector3::new(v, s, u),
        _ => Vector3::new(u, v, s),
    }
}

/// Hulls with at most this many vertices answer support queries by a scan (as fast as a climb).
const SCAN_VERTICES: usize = 24;

impl ConvexHull {
    /// The convex hull of a point cloud; `None` if the points are degenerate (flat or too few).
    pub fn from_points(points: &[Point3<f64>]) -> Option<Self> {
        let polyhedron = ConvexPolyhedron::from_convex_hull(points)?;
        let points = polyhedron.points().to_vec();
        let climb = Climb::new(&points, polyhedron.edges().iter().map(|e| (e.vertices.x, e.vertices.y)));
        Some(Self { points, polyhedron, climb })
    }

    /// The index of a vertex farthest along `dir` (a support point of the hull).
    ///
    /// Above [`SCAN_VERTICES`] vertices, by steepest ascent over the vertex graph from the
    /// vertex farthest along the centre of `dir`'s cell of a cube map (384 cells, one looked up
    /// in a few instructions): each step moves to the neighbour farthest along `dir` while one
    /// is strictly farther. On a convex polyhedron a
    /// vertex no neighbour of which is farther along a direction is farthest of all along it
    /// (the simplex method's optimality condition: the edges at a vertex span the cone of the
    /// polyhedron seen from it), so the climb ends on a support vertex; every step gains, so it
    /// ends. parry's own support query scans every vertex: planning on the first two problems of
    /// each public MotionBenchMaker family with the mesh UR5 took 3,235 M instructions with it,
    /// 783 M climbing from the best of 14 fixed directions, 689 M from a cube map of 96 cells,
    /// 668 M from 384 (with the start of [`Climbing`]).
    pub fn support_index(&self, dir: &Vector3<f64>) -> usize {
        self.support_from(dir, None)
    }

    /// [`Self::support_index`], the climb starting from vertex `from` instead when it is farther
    /// along `dir` than the cube map's vertex.
    fn support_from(&self, dir: &Vector3<f64>, from: Option<usize>) -> usize {
        let pts = &self.points;
        let c = &self.climb;
        if pts.len() <= SCAN_VERTICES || c.first.len() != pts.len() + 1 {
            return scan_support(pts, dir);
        }
        let mut v = c.starts.get(cube_cell(dir)).map_or(0, |&s| s as usize);
        let Some(p) = pts.get(v) else { return scan_support(pts, dir) };
        let mut best = p.coords.dot(dir);
        // The given vertex instead, when it is farther along.
        if let Some((w, d)) = from.and_then(|w| pts.get(w).map(|q| (w, q.coords.dot(dir))))
            && d > best
        {
            v = w;
            best = d;
        }
        loop {
            let mut next = v;
            let (Some(&from), Some(&to)) = (c.first.get(v), c.first.get(v + 1)) else { return v };
            let (from, to) = (from as usize, to as usize);
            let (Some(ids), Some(points)) = (c.adj.get(from..to), c.adj_points.get(from..to)) else { return v };
            for (&n, q) in ids.iter().zip(points) {
                let d = q.x * dir.x + q.y * dir.y + q.z * dir.z;
                if d > best {
                    best = d;
                    next = n as usize;
                }
            }
            if next == v {
                return v;
            }
            v = next;
        }
    }
}

/// The index of a point of `pts` farthest along `dir` (the first of ties; 0 when none compares).
fn scan_support(pts: &[Point3<f64>], dir: &Vector3<f64>) -> usize {
    let mut best = f64::NEG_INFINITY;
    let mut at = 0;
    for (i, p) in pts.iter().enumerate() {
        let d = p.coords.dot(dir);
        if d > best {
            best = d;
            at = i;
        }
    }
    at
}

impl Climb {
    /// The graph of `edges` over `points`, and the climbs' starting vertices.
    fn new(points: &[Point3<f64>], edges: impl Iterator<Item = (u32, u32)>) -> Climb {
        let n = points.len();
        let mut lists: Vec<Vec<u32>> = vec![Vec::new(); n];
        for (a, b) in edges {
            if (a as usize) < n && (b as usize) < n && a != b {
                lists[a as usize].push(b);
                lists[b as usize].push(a);
            }
        }
        let mut first = Vec::with_capacity(n + 1);
        let mut adj = Vec::new();
        for l in &mut lists {
            l.sort_unstable();
            l.dedup();
            first.push(adj.len() as u32);
            adj.extend_from_slice(l);
        }
        first.push(adj.len() as u32);
        let adj_points = adj.iter().map(|&n| points[n as usize]).collect();
        let starts = (0..6 * CUBE * CUBE).map(|cell| scan_support(points, &cube_dir(cell)) as u32).collect();
        Climb { first, adj, adj_points, starts }
    }
}

/// A hull as a parry support map for one query: its support queries climb the vertex graph,
/// each from the farther along of its cube map cell's vertex and the last answer (measured with
/// 14 fixed directions in place of the cube map, on the problems of
/// [`ConvexHull::support_index`]: 776 M instructions, against 783 M from the directions alone
/// and 911 M from the last answer alone).
pub(crate) struct Climbing<'a> {
    hull: &'a ConvexHull,
    last: std::cell::Cell<Option<usize>>,
}

impl<'a> Climbing<'a> {
    pub(crate) fn new(hull: &'a ConvexHull) -> Self {
        Self { hull, last: std::cell::Cell::new(None) }
    }
}

impl parry3d_f64::shape::SupportMap for Climbing<'_> {
    fn local_support_point(&self, dir: &Vector3<f64>) -> Point3<f64> {
        let v = self.hull.support_from(dir, self.last.get());
        self.last.set(Some(v));
        self.hull.points.get(v).copied().unwrap_or_else(Point3::origin)
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

#[cfg(test)]
mod climb_tests {
    use super::*;
    use crate::rng::Rng;

    /// A climb's support vertex is as far along the direction as the farthest vertex (to the
    /// last bit of the dot product), on hulls of random clouds (rounded, flat, elongated,
    /// with many points on a few faces) and random directions, axis directions included.
    #[test]
    fn climbing_support_matches_the_scan() {
        let mut rng = Rng::new(17);
        let mut climbed = 0;
        for case in 0..60 {
            let n = 30 + (case * 37) % 400;
            let scale = Vector3::new(rng.range(0.01, 1.0), rng.range(0.01, 1.0), rng.range(0.01, 1.0));
            let cloud: Vec<Point3<f64>> = (0..n)
                .map(|_| {
                    let d = Vector3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
                    let d = if case % 3 == 0 { d } else { d.normalize() };
                    // Every fourth cloud: snapped to a coarse grid, so many points share faces.
                    let d = if case % 4 == 1 { d.map(|x| (x * 3.0).round() / 3.0) } else { d };
                    Point3::from(d.component_mul(&scale))
                })
                .collect();
            let Some(hull) = ConvexHull::from_points(&cloud) else { continue };
            climbed += usize::from(hull.points.len() > SCAN_VERTICES);
            // Axes, cube map cell centres and edges (where the cell choice flips), random ones.
            let mut dirs: Vec<Vector3<f64>> = (0..6 * CUBE * CUBE).map(cube_dir).collect();
            dirs.extend([
                Vector3::x(),
                -Vector3::y(),
                Vector3::z(),
                Vector3::new(1.0, 1.0, 0.0),
                Vector3::new(1.0, -1.0, 1.0),
            ]);
            dirs.extend(
                (0..300).map(|_| Vector3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0))),
            );
            let climbing = Climbing::new(&hull);
            for (i, dir) in dirs.iter().enumerate() {
                let best = hull.points.iter().map(|p| p.coords.dot(dir)).fold(f64::NEG_INFINITY, f64::max);
                let got = hull.points[hull.support_index(dir)].coords.dot(dir);
                assert_eq!(got, best, "case {case}, {} vertices, dir {dir:?}", hull.points.len());
                // From any vertex (here: the last answer, or vertex i), the same.
                let from = hull.points[hull.support_from(dir, Some(i % hull.points.len()))].coords.dot(dir);
                assert_eq!(from, best, "case {case}, from vertex {i}");
                use parry3d_f64::shape::SupportMap;
                assert_eq!(climbing.local_support_point(dir).coords.dot(dir), best, "case {case}, warm");
            }
        }
        assert!(climbed > 30, "only {climbed} hulls were large enough to climb");
    }

    /// Overlap tests and proximity tests with a hull climbing its graph answer as parry's own
    /// (which scans every vertex) on random hulls against hulls and boxes at random poses.
    #[test]
    fn climbing_hull_queries_answer_as_parry() {
        use crate::collision::narrow::{parry_shapes_intersect, shapes_within};
        use parry3d_f64::query;
        let mut rng = Rng::new(29);
        let hull = |rng: &mut Rng| {
            let cloud: Vec<Point3<f64>> = (0..200)
                .map(|_| {
                    let d = Vector3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)).normalize();
                    Point3::new(0.3 * d.x, 0.1 * d.y, 0.08 * d.z)
                })
                .collect();
            Shape::ConvexMesh(Arc::new(ConvexHull::from_points(&cloud).expect("a hull")))
        };
        let (a, b) = (hull(&mut rng), hull(&mut rng));
        let cuboid = Shape::cuboid(0.2, 0.05, 0.3);
        let parry_of = |s: &Shape| -> Box<dyn parry3d_f64::shape::Shape> {
            match s {
                Shape::ConvexMesh(h) => Box::new(h.polyhedron.clone()),
                Shape::Cuboid { half_extents } => Box::new(parry3d_f64::shape::Cuboid::new(*half_extents)),
                _ => unreachable!("hulls and boxes only"),
            }
        };
        let (mut hits, mut near) = (0, 0);
        for i in 0..3000 {
            let other = if i % 2 == 0 { &b } else { &cuboid };
            let pose = |rng: &mut Rng| {
                Isometry3::new(
                    Vector3::new(rng.range(-0.5, 0.5), rng.range(-0.3, 0.3), rng.range(-0.3, 0.3)),
                    Vector3::new(rng.range(-3.0, 3.0), rng.range(-3.0, 3.0), rng.range(-3.0, 3.0)),
                )
            };
            let (pa, pb) = (pose(&mut rng), pose(&mut rng));
            let reference = query::intersection_test(&pa, &*parry_of(&a), &pb, &*parry_of(other)).expect("convex");
            assert_eq!(parry_shapes_intersect(&a, &pa, other, &pb), reference, "pose {i}");
            hits += usize::from(reference);
            if !reference {
                let d = query::distance(&pa, &*parry_of(&a), &pb, &*parry_of(other)).expect("convex");
                // Proven farther only when farther; never "farther" within the distance.
                assert!(shapes_within(&a, &pa, other, &pb, d * 1.001 + 1e-9), "pose {i}: {d}");
                if d > 0.02 {
                    near += usize::from(shapes_within(&a, &pa, other, &pb, 0.5 * d));
                }
            }
        }
        assert!(hits > 300 && hits < 2700, "{hits} overlaps of 3000");
        assert_eq!(near, 0, "proximity tests called shapes near at half their distance");
    }

    /// Queries that start from the direction that separated the pair in the query before (see
    /// `narrow::intersects_from`), as a planner asks about a pair in nearby poses one after
    /// another, answer as parry's own from nothing: the same overlaps, never "farther" within
    /// the distance, "farther" at half of it. Hull against hull, hull against box, box against
    /// cylinder, each pose a small step from the one before; the kept direction alone decides
    /// most of the answers "apart". The one-run proximity test (`narrow::proximity_from`)
    /// answers as the proximity test and then the overlap test do.
    #[test]
    fn hinted_queries_answer_as_parry_along_walks() {
        use crate::collision::narrow::{Hint, Proximity, intersects_from, proximity_from, view_of, within_from};
        use nalgebra::UnitQuaternion;
        use parry3d_f64::query;
        let mut rng = Rng::new(31);
        let cloud: Vec<Point3<f64>> = (0..200)
            .map(|_| {
                let d = Vector3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)).normalize();
                Point3::new(0.3 * d.x, 0.1 * d.y, 0.08 * d.z)
            })
            .collect();
        let hull = Arc::new(ConvexHull::from_points(&cloud).expect("a hull"));
        let mesh = Shape::ConvexMesh(hull.clone());
        let cuboid = Shape::cuboid(0.2, 0.05, 0.3);
        let cylinder = Shape::cylinder(0.1, 0.25);
        let parry_of = |s: &Shape| -> Box<dyn parry3d_f64::shape::Shape> {
            match s {
                Shape::ConvexMesh(h) => Box::new(h.polyhedron.clone()),
                Shape::Cuboid { half_extents } => Box::new(parry3d_f64::shape::Cuboid::new(*half_extents)),
                // parry's cylinders run along y, ours along z.
                Shape::Cylinder { radius, half_height } => {
                    Box::new(parry3d_f64::shape::Cylinder::new(*half_height, *radius))
                }
                _ => unreachable!("hulls, boxes and cylinders only"),
            }
        };
        let to_y = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::FRAC_PI_2);
        let parry_pose = |s: &Shape, p: &Isometry3<f64>| match s {
            Shape::Cylinder { .. } => Isometry3::from_parts(p.translation, p.rotation * to_y),
            _ => *p,
        };
        let (mut apart, mut decided, mut hits) = (0, 0, 0);
        for (a, b) in [(&mesh, &mesh), (&mesh, &cuboid), (&cuboid, &cylinder)] {
            let mut hint = Hint::NONE;
            let mut pa = Isometry3::identity();
            let mut pb = Isometry3::translation(0.3, 0.0, 0.0);
            for i in 0..2000 {
                // A small step of each, pulled back towards the region where they meet.
                let step = |rng: &mut Rng, p: &Isometry3<f64>, home: Vector3<f64>| {
                    let t = home
                        + (p.translation.vector - home) * 0.98
                        + Vector3::new(rng.range(-0.03, 0.03), rng.range(-0.03, 0.03), rng.range(-0.03, 0.03));
                    let r = UnitQuaternion::new(Vector3::new(
                        rng.range(-0.05, 0.05),
                        rng.range(-0.05, 0.05),
                        rng.range(-0.05, 0.05),
                    )) * p.rotation;
                    Isometry3::from_parts(t.into(), r)
                };
                pa = step(&mut rng, &pa, Vector3::zeros());
                pb = step(&mut rng, &pb, Vector3::new(0.4, 0.0, 0.0));
                let (ra, rb) = (parry_pose(a, &pa), parry_pose(b, &pb));
                let reference = query::intersection_test(&ra, &*parry_of(a), &rb, &*parry_of(b)).expect("convex");
                let (va, vb) = (view_of(a, &pa), view_of(b, &pb));
                let before = hint;
                assert_eq!(intersects_from(&va, &vb, &mut hint), reference, "pose {i}");
                hits += usize::from(reference);
                // The one-run proximity test answers as the two tests (at a margin of 1 cm).
                let mut other = hint;
                let expected = if reference {
                    Proximity::Touching
                } else if within_from(&va, &vb, 0.01, &mut { hint }) {
                    Proximity::Near
                } else {
                    Proximity::Farther
                };
                assert_eq!(proximity_from(&va, &vb, 0.01, &mut other), expected, "pose {i}");
                if reference {
                    continue;
                }
                apart += 1;
                decided += usize::from(before.dir != Vector3::zeros() && hint == before);
                let d = query::distance(&ra, &*parry_of(a), &rb, &*parry_of(b)).expect("convex");
                assert!(within_from(&va, &vb, d * 1.001 + 1e-9, &mut hint), "pose {i}: {d}");
                if d > 0.02 {
                    assert!(!within_from(&va, &vb, 0.5 * d, &mut hint), "pose {i}: near at half of {d}");
                }
            }
        }
        assert!(hits > 300 && apart > 1000, "{hits} overlaps, {apart} apart");
        assert!(decided * 5 > apart * 4, "the kept direction decided {decided} of {apart} answers apart");
    }
}
