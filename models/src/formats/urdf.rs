//! URDF loading: a [`Robot`] from a URDF file, optionally with the semantic facts an SRDF gives
//! ([`Semantics`]; the SRDF itself is read by [`super::srdf`] and joined in [`super`]).
//!
//! What is read:
//! - `<link>`: each `<collision>` element (any number per link) with its `<origin xyz rpy>`
//!   and `<geometry>`: `<box size>` (full extents, stored as half extents), `<sphere radius>`,
//!   `<cylinder radius length>` (along z), `<capsule radius length>` (along z) and
//!   `<mesh filename [scale]>`, loaded as the convex hull of its scaled vertices, or several
//!   hulls where the hull is far larger than the mesh (STL, Collada or OBJ; see [`super::mesh`]).
//!   `<visual>` and `<inertial>` are ignored, so a missing visual mesh never stops a load.
//! - `<joint>`: `revolute`, `continuous`, `prismatic` and `fixed`, with `<origin>` (default
//!   identity), `<axis xyz>` (default `1 0 0`, normalised), `<limit lower upper velocity>`
//!   (`effort` ignored) and `<mimic joint multiplier offset>`. The child frame is
//!   `parent * origin * motion(q)`. `floating` and `planar` joints are rejected.
//!
//! Assumptions (also recorded in [`Robot::provenance`]):
//! - URDF has no acceleration limits: every joint gets [`UrdfOptions::default_max_acceleration`]
//!   (10 rad/s^2 or m/s^2 by default).
//! - A joint whose `<limit velocity>` is missing or 0 gets [`UrdfOptions::default_max_velocity`].
//! - End effectors: one per moving chain tip. Leaf links are grouped by the last moving
//!   (non-fixed) joint on their path from the root; a group with one leaf gives that
//!   leaf, a group of several leaves (a gripper with fixed fingers, several tool frames) gives
//!   the child link of that joint. With an SRDF, its `<end_effector parent_link>`s come first and
//!   replace the end effector of their group (UR5: `ee_link`). Tool frames are identity.
//! - Home: the SRDF group state named `home` when an SRDF is given (other joints at zero
//!   clamped into their limits), else zeros clamped into the limits.
//!
//! Mesh file names: a plain path is relative to the URDF's folder; `file://` is an absolute
//! path; `package://NAME/rest` (or `package:///NAME/rest`, as ROS tools accept) is tried in each
//! of [`UrdfOptions::package_dirs`] (a folder that is the package `NAME` itself, or that
//! contains `NAME`), then (with [`UrdfOptions::use_environment`]) in each folder of
//! `ROS_PACKAGE_PATH` (the same way) and as `PREFIX/share/NAME` for each prefix of
//! `AMENT_PREFIX_PATH`, then in the URDF's folder and each of its ancestors (as `NAME/rest`,
//! then `rest`). With [`UrdfOptions::load_meshes`] false, mesh collision elements are skipped
//! (the link keeps its other shapes); otherwise a missing collision mesh is an error
//! ([`ModelError::Mesh`]) naming every path tried, unless [`UrdfOptions::allow_missing_meshes`],
//! which drops that shape with a warning. An unreadable or unsupported mesh is always an error.
//!
//! A `<robot>` without `name` takes the file's stem, with a warning.
//!
//! Every error in the file names `file:line:column` and what was expected there.
//!
//! ```
//! use std::path::Path;
//! use embodied_models::urdf::{parse_urdf, UrdfOptions};
//! let text = r#"<robot name="one">
//!   <link name="base"/>
//!   <link name="arm"><collision><geometry><sphere radius="0.1"/></geometry></collision></link>
//!   <joint name="j" type="revolute"><parent link="base"/><child link="arm"/>
//!     <origin xyz="0 0 0.5"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" velocity="2"/></joint>
//! </robot>"#;
//! let robot = parse_urdf(text, Path::new("one.urdf"), &UrdfOptions::default()).unwrap();
//! assert_eq!(robot.dof(), 1);
//! assert_eq!(robot.end_effectors()[0].link, robot.link_index("arm").unwrap());
//! ```

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use roxmltree::Node;

use super::mesh::{Decomposition, MESH_EXTENSIONS, convex_pieces, read_mesh};
use super::xml::{Xml, child, children};
use crate::error::{ModelError, Warning};
use crate::geometry::{ConvexHull, PlacedShape, Shape};
use crate::joint::{JointKind, JointLimits};
use crate::robot::{Robot, RobotBuilder};

/// Default velocity limit for joints whose URDF `<limit velocity>` is missing or 0 (rad/s, m/s).
pub const DEFAULT_MAX_VELOCITY: f64 = 1.0;
/// Default acceleration limit for every URDF joint (URDF has none), rad/s^2 or m/s^2.
pub const DEFAULT_MAX_ACCELERATION: f64 = 10.0;

/// How to load a URDF.
#[derive(Debug, Clone)]
pub struct UrdfOptions {
    /// Folders to resolve `package://NAME/...` in: each is the package itself (its last
    /// component is `NAME`) or a folder containing `NAME`.
    pub package_dirs: Vec<PathBuf>,
    /// Velocity limit of joints whose `<limit velocity>` is missing or 0.
    pub default_max_velocity: f64,
    /// Acceleration limit of every joint (URDF has no acceleration limits).
    pub default_max_acceleration: f64,
    /// Load `<mesh>` collision geometry; if false, mesh collision elements are skipped.
    pub load_meshes: bool,
    /// A collision mesh found nowhere is dropped with a warning instead of failing the load.
    pub allow_missing_meshes: bool,
    /// Also look for `package://` files in `ROS_PACKAGE_PATH` and `AMENT_PREFIX_PATH`.
    pub use_environment: bool,
    /// When to split a mesh into several convex pieces (`None`: always one hull per mesh).
    pub decomposition: Option<Decomposition>,
}

/// Process-wide defaults of [`UrdfOptions::default`], set once by a program (the CLI's
/// `--package-path` and `--allow-missing-meshes`) so that every URDF it loads honours them.
#[derive(Debug, Clone, Default)]
pub struct UrdfDefaults {
    /// Prepended to [`UrdfOptions::package_dirs`].
    pub package_dirs: Vec<PathBuf>,
    /// [`UrdfOptions::allow_missing_meshes`].
    pub allow_missing_meshes: bool,
}

static DEFAULTS: std::sync::RwLock<Option<UrdfDefaults>> = std::sync::RwLock::new(None);

/// Set the process-wide defaults of [`UrdfOptions::default`].
pub fn set_urdf_defaults(defaults: UrdfDefaults) {
    if let Ok(mut d) = DEFAULTS.write() {
        *d = Some(defaults);
    }
}

impl Default for UrdfOptions {
    fn default() -> Self {
        let defaults = DEFAULTS.read().ok().and_then(|d| d.clone()).unwrap_or_default();
        Self {
            package_dirs: defaults.package_dirs,
            default_max_velocity: DEFAULT_MAX_VELOCITY,
            default_max_acceleration: DEFAULT_MAX_ACCELERATION,
            load_meshes: true,
            allow_missing_meshes: defaults.allow_missing_meshes,
            use_environment: true,
            decomposition: Some(Decomposition::default()),
        }
    }
}

/// What a semantic description (an SRDF) tells the URDF loader: end effectors, the `home`
/// state and self-collision pairs to ignore, with where each fact was written.
#[derive(Debug, Clone, Default)]
pub struct Semantics {
    /// The file the facts come from (named in errors).
    pub file: PathBuf,
    /// `(end effector name, parent link, line, column)`, in file order.
    pub end_effectors: Vec<(String, String, u32, u32)>,
    /// The `home` state.
    pub home: Option<HomeState>,
    /// Link pairs whose collisions are ignored (pairs naming unknown links are skipped).
    pub disabled: Vec<(String, String)>,
}

/// The `home` group state of a semantic description.
#[derive(Debug, Clone, Default)]
pub struct HomeState {
    /// `(joint, value)` pairs.
    pub values: Vec<(String, f64)>,
    /// Line of the state in [`Semantics::file`].
    pub line: u32,
    /// Column of the state.
    pub column: u32,
}

/// A robot loaded from a URDF, with what was noticed but did not stop the load.
#[derive(Debug, Clone)]
pub struct UrdfLoad {
    /// The robot.
    pub robot: Robot,
    /// Warnings (missing name, dropped meshes, ...), in the order they arose.
    pub warnings: Vec<Warning>,
}

/// Parse URDF text; `file` names the file in errors and anchors relative mesh paths.
pub fn parse_urdf(text: &str, file: &Path, options: &UrdfOptions) -> Result<Robot, ModelError> {
    Ok(build(text, file, options, None)?.robot)
}

/// [`parse_urdf`] with semantic facts, returning the warnings too.
pub fn parse_urdf_with(
    text: &str,
    file: &Path,
    options: &UrdfOptions,
    semantics: Option<&Semantics>,
) -> Result<UrdfLoad, ModelError> {
    build(text, file, options, semantics)
}

/// Read a URDF file's text; a `.xacro` file is expanded by the `xacro` program if it is on
/// `PATH`, else refused with an error that says so.
pub fn read_urdf_text(path: &Path) -> Result<String, ModelError> {
    let is_xacro = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("xacro"));
    if !is_xacro {
        return read_text(path);
    }
    let output = std::process::Command::new("xacro").arg(path).output();
    match output {
        Ok(out) if out.status.success() => String::from_utf8(out.stdout).map_err(|_| ModelError::Parse {
            file: path.to_path_buf(),
            line: 1,
            column: 1,
            message: "xacro printed text that is not UTF-8 (expected URDF XML)".into(),
        }),
        Ok(out) => Err(ModelError::Parse {
            file: path.to_path_buf(),
            line: 1,
            column: 1,
            message: format!("`xacro` failed ({}): {}", out.status, String::from_utf8_lossy(&out.stderr).trim()),
        }),
        Err(e) => Err(ModelError::Parse {
            file: path.to_path_buf(),
            line: 1,
            column: 1,
            message: format!(
                "a .xacro file needs the `xacro` program to expand it, and it could not be run ({e}); install xacro (ROS) or pass the expanded URDF (`xacro FILE > robot.urdf`)"
            ),
        }),
    }
}

fn read_text(path: &Path) -> Result<String, ModelError> {
    super::limits::read_text_limited(path, super::limits::InputKind::Text)
        .map_err(|source| ModelError::Io { file: path.to_path_buf(), source })
}

/// `<origin xyz rpy>` of `parent` (identity if absent). URDF rpy: R = Rz(yaw) Ry(pitch) Rx(roll).
fn origin(x: &Xml, parent: Node) -> Result<Isometry3<f64>, ModelError> {
    let Some(o) = child(parent, "origin") else { return Ok(Isometry3::identity()) };
    let xyz = x.vec3_or(o, "xyz", [0.0; 3])?;
    let rpy = x.vec3_or(o, "rpy", [0.0; 3])?;
    Ok(Isometry3::from_parts(Translation3::from(xyz), UnitQuaternion::from_euler_angles(rpy.x, rpy.y, rpy.z)))
}

/// Per-load state: options, the URDF's folder, and loaded meshes (by resolved path and scale).
struct Loader<'o> {
    options: &'o UrdfOptions,
    dir: PathBuf,
    meshes: HashMap<(PathBuf, [u64; 3]), Vec<Arc<ConvexHull>>>,
    warnings: Vec<Warning>,
}

impl Loader<'_> {
    /// The collision shapes of a `<link>`.
    fn link_shapes(&mut self, x: &Xml, link: Node) -> Result<Vec<PlacedShape>, ModelError> {
        let mut shapes = Vec::new();
        for collision in children(link, "collision") {
            let pose = origin(x, collision)?;
            let Some(geometry) = child(collision, "geometry") else {
                return Err(x.err(collision, "<collision> has no <geometry> (expected one)".into()));
            };
            let mut elements = geometry.children().filter(|n| n.is_element());
            let Some(g) = elements.next() else {
                return Err(x.err(
                    geometry,
                    "<geometry> is empty (expected one of <box>, <sphere>, <cylinder>, <capsule>, <mesh>)".into(),
                ));
            };
            if let Some(extra) = elements.next() {
                return Err(x.err(extra, "<geometry> has more than one shape (expected exactly one)".into()));
            }
            let shape = match g.tag_name().name() {
                "box" => {
                    let expected = "three non-negative lengths \"x y z\" (full extents)";
                    let s = x.numbers(g, "size", x.attr(g, "size", expected)?, 3, expected)?;
                    if s.iter().any(|&v| v < 0.0) {
                        return Err(x.err(g, format!("<box> has a negative size {s:?} (expected {expected})")));
                    }
                    Shape::cuboid(s[0] / 2.0, s[1] / 2.0, s[2] / 2.0)
                }
                "sphere" => Shape::sphere(x.length(g, "radius", "a non-negative radius")?),
                "cylinder" => Shape::cylinder(
                    x.length(g, "radius", "a non-negative radius")?,
                    x.length(g, "length", "a non-negative length (along z)")? / 2.0,
                ),
                "capsule" => {
                    let r = x.length(g, "radius", "a non-negative radius")?;
                    let h = x.length(g, "length", "a non-negative length (along z)")? / 2.0;
                    Shape::capsule([0.0, 0.0, -h], [0.0, 0.0, h], r)
                }
                "mesh" => {
                    let pieces = self.mesh(x, g)?.unwrap_or_default();
                    shapes.extend(pieces.into_iter().map(|h| PlacedShape::new(pose, Shape::ConvexMesh(h))));
                    continue;
                }
                other => {
                    return Err(x.err(
                        g,
                        format!(
                            "unknown geometry <{other}> (expected one of <box>, <sphere>, <cylinder>, <capsule>, <mesh>)"
                        ),
                    ));
                }
            };
            shapes.push(PlacedShape::new(pose, shape));
        }
        Ok(shapes)
    }

    /// The convex pieces of a `<mesh>`; `None` when meshes are not loaded or a missing mesh is
    /// dropped ([`UrdfOptions::allow_missing_meshes`]).
    fn mesh(&mut self, x: &Xml, mesh: Node) -> Result<Option<Vec<Arc<ConvexHull>>>, ModelError> {
        let uri = x.attr(mesh, "filename", "a mesh file name or package:// URI")?;
        let scale = x.vec3_or(mesh, "scale", [1.0; 3])?;
        if !self.options.load_meshes {
            return Ok(None);
        }
        let line = x.line(mesh);
        let mesh_err = |resolved: PathBuf, reason: String| ModelError::Mesh {
            urdf: x.file.clone(),
            line,
            uri: uri.to_string(),
            resolved,
            reason,
        };
        let candidates = self.candidates(uri).map_err(|reason| mesh_err(PathBuf::from(uri), reason))?;
        let ext = Path::new(uri).extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
        if !MESH_EXTENSIONS.contains(&ext.as_str()) {
            return Err(mesh_err(
                PathBuf::from(uri),
                format!(
                    "`.{ext}` meshes are not supported (expected STL, Collada .dae or Wavefront .obj); load with `load_meshes: false` to skip mesh collision geometry"
                ),
            ));
        }
        let Some(path) = candidates.iter().find(|p| p.is_file()).cloned() else {
            let first = candidates.first().cloned().unwrap_or_else(|| PathBuf::from(uri));
            let tried: Vec<String> = candidates.iter().map(|p| p.display().to_string()).collect();
            let reason = format!("collision mesh file not found (tried: {})", tried.join(", "));
            if self.options.allow_missing_meshes {
                let (line, column) = x.position(mesh);
                self.warnings.push(Warning {
                    file: x.file.clone(),
                    line,
                    column,
                    message: format!("mesh `{uri}`: {reason}; shape dropped (missing meshes allowed)"),
                });
                return Ok(None);
            }
            return Err(mesh_err(first, format!("{reason}; pass --allow-missing-meshes to drop it")));
        };
        let key = (path.clone(), [scale.x.to_bits(), scale.y.to_bits(), scale.z.to_bits()]);
        if let Some(pieces) = self.meshes.get(&key) {
            return Ok(Some(pieces.clone()));
        }
        let tri = read_mesh(&path, scale).map_err(|reason| mesh_err(path.clone(), reason))?;
        let pieces = convex_pieces(&tri, self.options.decomposition.as_ref()).ok_or_else(|| {
            mesh_err(
                path.clone(),
                format!("the {} vertices are degenerate (flat or too few for a convex hull)", tri.vertices.len()),
            )
        })?;
        self.meshes.insert(key, pieces.clone());
        Ok(Some(pieces))
    }

    /// Candidate file paths of a mesh URI, in the order they are tried.
    fn candidates(&self, uri: &str) -> Result<Vec<PathBuf>, String> {
        if let Some(rest) = uri.strip_prefix("package://") {
            let rest = rest.strip_prefix('/').unwrap_or(rest);
            let Some((name, rest)) = rest.split_once('/').filter(|(n, r)| !n.is_empty() && !r.is_empty()) else {
                return Err("malformed package URI (expected package://NAME/path)".into());
            };
            let mut out = Vec::new();
            let mut package_dirs = self.options.package_dirs.clone();
            let mut prefixes = Vec::new();
            if self.options.use_environment {
                if let Some(p) = std::env::var_os("ROS_PACKAGE_PATH") {
                    package_dirs.extend(std::env::split_paths(&p).filter(|d| !d.as_os_str().is_empty()));
                }
                if let Some(p) = std::env::var_os("AMENT_PREFIX_PATH") {
                    prefixes.extend(std::env::split_paths(&p).filter(|d| !d.as_os_str().is_empty()));
                }
            }
            for d in &package_dirs {
                if d.file_name().is_some_and(|f| f == name) {
                    out.push(d.join(rest));
                }
                out.push(d.join(name).join(rest));
            }
            for prefix in &prefixes {
                out.push(prefix.join("share").join(name).join(rest));
            }
            for a in self.dir.ancestors() {
                out.push(a.join(name).join(rest));
                out.push(a.join(rest));
            }
            Ok(out)
        } else if let Some(path) = uri.strip_prefix("file://") {
            Ok(vec![PathBuf::from(path)])
        } else if uri.contains("://") {
            Err("unsupported URI scheme (expected a path, package:// or file://)".into())
        } else {
            Ok(vec![self.dir.join(uri)])
        }
    }
}

/// A joint as read from the file, before the tree is checked.
struct RawJoint<'a, 'i> {
    node: Node<'a, 'i>,
    name: String,
    kind: JointKind,
    parent: usize,
    child: usize,
    origin: Isometry3<f64>,
    axis: Vector3<f64>,
    limits: JointLimits,
    mimic: Option<(Node<'a, 'i>, String, f64, f64)>,
}

fn read_joint<'a, 'i>(
    x: &Xml<'i>,
    node: Node<'a, 'i>,
    link_names: &[(String, Node<'a, 'i>)],
    options: &UrdfOptions,
) -> Result<RawJoint<'a, 'i>, ModelError> {
    let name = x.attr(node, "name", "the joint's name")?.to_string();
    let type_name = x.attr(node, "type", "one of revolute, continuous, prismatic, fixed")?;
    let kind = match type_name {
        "revolute" => JointKind::Revolute,
        "continuous" => JointKind::Continuous,
        "prismatic" => JointKind::Prismatic,
        "fixed" => JointKind::Fixed,
        "floating" | "planar" => {
            return Err(x.err(
                node,
                format!(
                    "joint `{name}`: `{type_name}` joints are not supported (expected revolute, continuous, prismatic or fixed)"
                ),
            ));
        }
        other => {
            return Err(x.err(
                node,
                format!(
                    "joint `{name}` has unknown type `{other}` (expected revolute, continuous, prismatic or fixed)"
                ),
            ));
        }
    };
    let link_ref = |tag: &str| -> Result<usize, ModelError> {
        let Some(e) = child(node, tag) else {
            return Err(x.err(node, format!("joint `{name}` has no <{tag} link=\"...\"/> (expected one)")));
        };
        let link = x.attr(e, "link", "a link name")?;
        link_names.iter().position(|(n, _)| n == link).ok_or_else(|| {
            x.err(
                e,
                format!("joint `{name}` refers to unknown link `{link}` (expected the name of a <link> of the file)"),
            )
        })
    };
    let parent = link_ref("parent")?;
    let child_link = link_ref("child")?;
    if parent == child_link {
        return Err(x.err(node, format!("joint `{name}` connects link `{}` to itself", link_names[parent].0)));
    }
    let origin = origin(x, node)?;
    let axis = match child(node, "axis") {
        Some(a) => {
            let v = x.vec3_or(a, "xyz", [1.0, 0.0, 0.0])?;
            if kind != JointKind::Fixed && v.norm() < 1e-12 {
                return Err(x.err(a, format!("joint `{name}` has a zero axis (expected a non-zero vector)")));
            }
            v.try_normalize(1e-12).unwrap_or(Vector3::x())
        }
        None => Vector3::x(),
    };
    let limit = child(node, "limit");
    let velocity = match limit {
        Some(l) => {
            let v = x.number_or(l, "velocity", 0.0, "a non-negative velocity limit")?;
            if v < 0.0 {
                return Err(x.err(l, format!("joint `{name}` has a negative velocity limit {v} (expected >= 0)")));
            }
            if v > 0.0 { v } else { options.default_max_velocity }
        }
        None => options.default_max_velocity,
    };
    let acceleration = options.default_max_acceleration;
    let limits = match kind {
        JointKind::Revolute | JointKind::Prismatic => {
            let Some(l) = limit else {
                return Err(x.err(
                    node,
                    format!("{type_name} joint `{name}` has no <limit> (expected <limit lower upper velocity>)"),
                ));
            };
            let lower = x.number_or(l, "lower", 0.0, "a number")?;
            let upper = x.number_or(l, "upper", 0.0, "a number")?;
            if lower > upper {
                return Err(x.err(l, format!("joint `{name}` has lower limit {lower} > upper limit {upper}")));
            }
            JointLimits::new(lower, upper, velocity, acceleration)
        }
        JointKind::Continuous => JointLimits::continuous(velocity, acceleration),
        JointKind::Fixed => JointLimits::new(0.0, 0.0, velocity, acceleration),
    };
    let mimic = match child(node, "mimic") {
        Some(m) if kind != JointKind::Fixed => Some((
            m,
            x.attr(m, "joint", "the name of the joint to follow")?.to_string(),
            x.number_or(m, "multiplier", 1.0, "a number")?,
            x.number_or(m, "offset", 0.0, "a number")?,
        )),
        _ => None,
    };
    Ok(RawJoint { node, name, kind, parent, child: child_link, origin, axis, limits, mimic })
}

fn build(text: &str, file: &Path, options: &UrdfOptions, srdf: Option<&Semantics>) -> Result<UrdfLoad, ModelError> {
    let x = Xml::parse(text, file)?;
    let root = x.doc.root_element();
    if root.tag_name().name() != "robot" {
        return Err(x.err(root, format!("expected a <robot> root element, found <{}>", root.tag_name().name())));
    }
    let max_links = super::limits::input_limits().max_links;
    if let Some(extra) = children(root, "link").nth(max_links) {
        let n = children(root, "link").count();
        return Err(x.err(
            extra,
            format!("the robot has {n} links, more than the limit of {max_links} (raise it with --max-links)"),
        ));
    }
    let mut warnings = Vec::new();
    let robot_name = match root.attribute("name").filter(|n| !n.trim().is_empty()) {
        Some(n) => n.to_string(),
        None => {
            let stem = file.file_stem().and_then(|s| s.to_str()).unwrap_or("robot");
            let stem = stem.strip_suffix(".urdf").unwrap_or(stem).to_string();
            let (line, column) = x.position(root);
            warnings.push(Warning {
                file: file.to_path_buf(),
                line,
                column,
                message: format!("<robot> has no `name`; using the file's stem `{stem}`"),
            });
            stem
        }
    };
    let dir = match file.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let dir = dir.canonicalize().unwrap_or(dir);
    let mut loader = Loader { options, dir, meshes: HashMap::new(), warnings: Vec::new() };

    // Links, in file order.
    let mut links: Vec<(String, Node)> = Vec::new();
    let mut shapes = Vec::new();
    for node in children(root, "link") {
        let name = x.attr(node, "name", "the link's name")?.to_string();
        if let Some((_, first)) = links.iter().find(|(n, _)| *n == name) {
            return Err(x.err(
                node,
                format!("a second link named `{name}` (first at line {}; expected unique link names)", x.line(*first)),
            ));
        }
        shapes.push(loader.link_shapes(&x, node)?);
        links.push((name, node));
    }
    if links.is_empty() {
        return Err(x.err(root, format!("robot `{robot_name}` has no <link> (expected at least one)")));
    }

    // Joints, in file order.
    let mut joints: Vec<RawJoint> = Vec::new();
    let mut parent_joint: Vec<Option<usize>> = vec![None; links.len()];
    for node in children(root, "joint") {
        let j = read_joint(&x, node, &links, options)?;
        if let Some(first) = joints.iter().find(|o| o.name == j.name) {
            return Err(x.err(
                node,
                format!(
                    "a second joint named `{}` (first at line {}; expected unique joint names)",
                    j.name,
                    x.line(first.node)
                ),
            ));
        }
        if let Some(other) = parent_joint[j.child] {
            return Err(x.err(
                node,
                format!(
                    "link `{}` is the child of joint `{}` (line {}) and of joint `{}` (expected one parent joint per link: a tree)",
                    links[j.child].0,
                    joints[other].name,
                    x.line(joints[other].node),
                    j.name
                ),
            ));
        }
        parent_joint[j.child] = Some(joints.len());
        joints.push(j);
    }

    // Exactly one root, every link reachable from it.
    let roots: Vec<usize> = (0..links.len()).filter(|&l| parent_joint[l].is_none()).collect();
    let Some(&root_link) = roots.first() else {
        return Err(x.err(
            root,
            "every link is the child of a joint, so the joints form a cycle (expected one root link)".into(),
        ));
    };
    if let Some(&second) = roots.get(1) {
        return Err(x.err(
            links[second].1,
            format!(
                "link `{}` is not the child of any joint, but neither is `{}` (line {}): two roots (expected exactly one root link; connect them with a joint)",
                links[second].0,
                links[root_link].0,
                x.line(links[root_link].1)
            ),
        ));
    }
    let mut reached = vec![false; links.len()];
    let mut stack = vec![root_link];
    while let Some(l) = stack.pop() {
        reached[l] = true;
        stack.extend(joints.iter().filter(|j| j.parent == l && !reached[j.child]).map(|j| j.child));
    }
    if let Some(l) = (0..links.len()).find(|&l| !reached[l]) {
        let ji = parent_joint[l].unwrap_or(0);
        return Err(x.err(
            joints[ji].node,
            format!(
                "joint `{}` closes a cycle: link `{}` is not connected to the root link `{}` (expected a tree)",
                joints[ji].name, links[l].0, links[root_link].0
            ),
        ));
    }

    // Mimic joints must follow an existing, actuated, non-mimic joint.
    for j in &joints {
        if let Some((m, leader, ..)) = &j.mimic {
            let ok = joints.iter().any(|o| o.name == *leader && o.kind != JointKind::Fixed && o.mimic.is_none());
            if !ok {
                return Err(x.err(
                    *m,
                    format!(
                        "joint `{}` mimics `{leader}` (expected the name of a non-fixed joint that is not itself a mimic joint)",
                        j.name
                    ),
                ));
            }
        }
    }

    let mut builder = RobotBuilder::new(robot_name.clone());
    for ((name, _), s) in links.iter().zip(shapes) {
        builder.link(name.clone(), s);
    }
    for j in &joints {
        let ji = builder.joint(
            j.name.clone(),
            j.kind,
            j.parent,
            j.child,
            j.origin,
            j.axis,
            0.0,
            Isometry3::identity(),
            j.limits,
        );
        if let Some((_, leader, mult, off)) = &j.mimic {
            builder.mimic(ji, leader.clone(), *mult, *off);
        }
    }
    let mut provenance = format!(
        "URDF {}{}; assumed: acceleration limit {} for every joint (URDF has none), velocity limit {} where the URDF gives none",
        file.display(),
        srdf.map(|s| format!(" with SRDF {}", s.file.display())).unwrap_or_default(),
        options.default_max_acceleration,
        options.default_max_velocity
    );
    if !options.load_meshes {
        provenance.push_str("; mesh collision geometry skipped");
    }
    builder = builder.provenance(provenance);

    // A first build gives the ordered tree, from which end effectors and home are chosen.
    let probe = builder.clone().build()?;
    let srdf_doc = || srdf.map(|s| s.file.clone()).unwrap_or_default();
    let srdf_err =
        |(line, column): (u32, u32), message: String| ModelError::Parse { file: srdf_doc(), line, column, message };
    let mut ee_links: Vec<usize> = Vec::new();
    let mut taken_groups: Vec<Option<usize>> = Vec::new();
    let last_actuated = |link: usize| {
        let moving = |j: usize| probe.joints()[j].dof_index.is_some() || probe.joints()[j].mimic.is_some();
        probe.chain_to(link).into_iter().rev().find(|&j| moving(j))
    };
    if let Some(s) = srdf {
        for (ee_name, parent_link, line, column) in &s.end_effectors {
            let Some(l) = probe.link_index(parent_link) else {
                // MoveIt ignores such an end effector too.
                warnings.push(Warning {
                    file: srdf_doc(),
                    line: *line,
                    column: *column,
                    message: format!(
                        "end effector `{ee_name}` has parent link `{parent_link}`, which robot `{robot_name}` does not have; ignored"
                    ),
                });
                continue;
            };
            if !ee_links.contains(&l) {
                ee_links.push(l);
                taken_groups.push(last_actuated(l));
            }
        }
    }
    let is_leaf = |l: usize| !probe.joints().iter().any(|j| j.parent_link == l);
    let leaves: Vec<usize> = (0..probe.links().len()).filter(|&l| is_leaf(l)).collect();
    let mut groups: Vec<(usize, Vec<usize>)> = Vec::new();
    for &leaf in &leaves {
        let Some(j) = last_actuated(leaf) else { continue };
        match groups.iter_mut().find(|(g, _)| *g == j) {
            Some((_, members)) => members.push(leaf),
            None => groups.push((j, vec![leaf])),
        }
    }
    for (j, members) in groups {
        if taken_groups.contains(&Some(j)) {
            continue;
        }
        let l = if members.len() == 1 { members[0] } else { probe.joints()[j].child_link };
        if !ee_links.contains(&l) {
            ee_links.push(l);
        }
    }
    if ee_links.is_empty()
        && let Some(&leaf) = leaves.first()
    {
        ee_links.push(leaf);
    }
    for &l in &ee_links {
        let name = probe.links()[l].name.clone();
        builder.end_effector(name.clone(), name, Isometry3::identity());
    }

    if let Some(HomeState { values, line, column }) = srdf.and_then(|s| s.home.as_ref()) {
        let at = (*line, *column);
        let mut home = probe.home().to_vec();
        for (joint, value) in values {
            let Some(ji) = probe.joint_index(joint) else {
                warnings.push(Warning {
                    file: srdf_doc(),
                    line: at.0,
                    column: at.1,
                    message: format!(
                        "group state `home` sets joint `{joint}`, which robot `{robot_name}` does not have; ignored"
                    ),
                });
                continue;
            };
            let j = &probe.joints()[ji];
            if let Some(d) = j.dof_index {
                if *value < j.limits.lower - 1e-9 || *value > j.limits.upper + 1e-9 {
                    return Err(srdf_err(
                        at,
                        format!(
                            "group state `home` sets joint `{joint}` to {value}, outside its limits [{}, {}]",
                            j.limits.lower, j.limits.upper
                        ),
                    ));
                }
                home[d] = *value;
            }
        }
        builder.home(home);
    }

    let mut robot = builder.build()?;
    if let Some(s) = srdf {
        for (a, b) in &s.disabled {
            if let (Some(a), Some(b)) = (robot.link_index(a), robot.link_index(b)) {
                robot.disable_pair(a, b);
            }
        }
    }
    warnings.extend(loader.warnings);
    Ok(UrdfLoad { robot, warnings })
}
