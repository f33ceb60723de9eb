//! Triangle meshes for collision geometry: STL (binary or ASCII), Collada (`.dae`) and
//! Wavefront (`.obj`), read with the `mesh-loader` crate, and turned into convex shapes.
//!
//! A mesh becomes the convex hull of its (scaled) vertices. When that hull is far larger than the
//! mesh itself, the hull would block space the robot does not occupy (a C-shaped gripper, a
//! hollow base), so the mesh is decomposed into several convex pieces instead
//! ([`Decomposition`]): the rule is "closed mesh whose hull volume exceeds
//! [`Decomposition::volume_ratio`] times its enclosed volume". Only closed (watertight) meshes
//! have an enclosed volume; open meshes always get their single hull.
//!
//! Collada files are read with their node transforms and `<unit meter>` applied; `<up_axis>` is
//! not applied. One difference from the assimp-based ROS tools: mesh-loader scales vertices by
//! `<unit>` but not the translations of scene nodes, so a file with a unit other than metres
//! *and* translated nodes is placed differently (none of the corpus files is such a file).

use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

use nalgebra::{Point3, Vector3};
use parry3d_f64::transformation::vhacd::{VHACD, VHACDParameters};

use super::limits::{InputKind, input_limits, read_bytes_limited};
use crate::geometry::ConvexHull;

/// A triangle mesh in its file's frame, scaled.
#[derive(Debug, Clone, Default)]
pub struct TriMesh {
    /// Vertex positions.
    pub vertices: Vec<Point3<f64>>,
    /// Triangles as indices into `vertices`.
    pub triangles: Vec<[u32; 3]>,
}

/// The mesh file formats that can be read, by file extension.
pub const MESH_EXTENSIONS: [&str; 3] = ["stl", "dae", "obj"];

/// Read a mesh file (STL, Collada or OBJ, by extension, case-insensitive) and scale it.
///
/// A file larger than [`InputLimits::max_mesh_bytes`](super::limits::InputLimits) is refused
/// before it is read. The error is a sentence saying what is wrong with the file (the caller
/// names the file).
pub fn read_mesh(path: &Path, scale: Vector3<f64>) -> Result<TriMesh, String> {
    let ext = mesh_extension(path)?;
    if ext == "stl" {
        // A binary STL's triangles follow from its size: refuse too many before reading them.
        let head = std::fs::File::open(path).and_then(|f| {
            let len = f.metadata()?.len();
            let mut head = Vec::with_capacity(512);
            std::io::Read::read_to_end(&mut std::io::Read::take(f, 512), &mut head)?;
            Ok((len, head))
        });
        if let Ok((len, head)) = head
            && binary_stl_triangles(&head).is_some()
        {
            let n = usize::try_from(len.saturating_sub(84) / 50).unwrap_or(usize::MAX);
            let max = input_limits().max_mesh_triangles;
            if n > max {
                return Err(format!(
                    "the mesh has {n} triangles, more than the limit of {max} (simplify it, or raise --max-mesh-triangles)"
                ));
            }
        }
    }
    let bytes = read_bytes_limited(path, InputKind::Mesh).map_err(|e| e.to_string())?;
    parse_mesh(&bytes, &ext, scale)
}

fn mesh_extension(path: &Path) -> Result<String, String> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    if !MESH_EXTENSIONS.contains(&ext.as_str()) {
        return Err(format!(
            "`.{ext}` meshes are not supported (expected one of: {})",
            MESH_EXTENSIONS.iter().map(|e| format!(".{e}")).collect::<Vec<_>>().join(", ")
        ));
    }
    Ok(ext)
}

/// Triangles a binary STL holds (50 bytes each after an 84-byte header), from its first bytes
/// (`None` for an ASCII STL, which starts with `solid`, or a file too short to be binary).
fn binary_stl_triangles(bytes: &[u8]) -> Option<usize> {
    let ascii = bytes.iter().take(512).skip_while(|b| b.is_ascii_whitespace()).take(5).eq(b"solid".iter());
    (!ascii && bytes.len() >= 84).then(|| (bytes.len() - 84) / 50)
}

/// Parse a mesh from its bytes; `ext` (`stl`, `dae` or `obj`) says which format. An OBJ file's
/// material library is not read. More triangles than
/// [`InputLimits::max_mesh_triangles`](super::limits::InputLimits) are refused, counted before
/// parsing where the format allows (binary STL, OBJ).
pub fn parse_mesh(bytes: &[u8], ext: &str, scale: Vector3<f64>) -> Result<TriMesh, String> {
    let ext = ext.to_ascii_lowercase();
    let max = input_limits().max_mesh_triangles;
    let refuse = |n: usize| {
        format!("the mesh has {n} triangles, more than the limit of {max} (simplify it, or raise --max-mesh-triangles)")
    };
    let claimed = match ext.as_str() {
        "stl" => binary_stl_triangles(bytes),
        // Every face is a line starting with `f`; a polygon of k corners is k - 2 triangles, so
        // this is a lower bound of what the reader would build.
        "obj" => Some(bytes.windows(2).filter(|w| w[0] == b'\n' && w[1] == b'f').count()),
        _ => None,
    };
    if let Some(n) = claimed.filter(|&n| n > max) {
        return Err(refuse(n));
    }
    let load = || {
        let loader = mesh_loader::Loader::default();
        let path = Path::new("mesh");
        match ext.as_str() {
            "stl" => loader.load_stl_from_slice(bytes, path),
            "dae" => loader.load_collada_from_slice(bytes, path),
            "obj" => loader.load_obj_from_slice_with_reader(bytes, path, |p: &Path| {
                Err(std::io::Error::other(format!("{}: material libraries are not read", p.display())))
            }),
            other => Err(std::io::Error::other(format!("`.{other}` meshes are not supported"))),
        }
    };
    // mesh-loader 0.1.13 panics on some malformed Collada files (a reference to a source the
    // file does not define); such a file is refused like any other malformed one.
    let scene = match std::panic::catch_unwind(std::panic::AssertUnwindSafe(load)) {
        Ok(result) => result.map_err(|e| format!("not a valid {} file: {e}", ext.to_ascii_uppercase()))?,
        Err(_) => {
            return Err(format!(
                "not a valid {} file: the reader failed on it (a reference to something the file does not define?)",
                ext.to_ascii_uppercase()
            ));
        }
    };
    let triangles: usize = scene.meshes.iter().map(|m| m.faces.len()).sum();
    if triangles > max {
        return Err(refuse(triangles));
    }
    let mut out = TriMesh::default();
    for mesh in &scene.meshes {
        let base = u32::try_from(out.vertices.len()).map_err(|_| "the mesh has too many vertices".to_string())?;
        for v in &mesh.vertices {
            let p = Point3::new(f64::from(v[0]) * scale.x, f64::from(v[1]) * scale.y, f64::from(v[2]) * scale.z);
            if !p.coords.iter().all(|c| c.is_finite()) {
                return Err("the mesh has non-finite vertex coordinates".into());
            }
            out.vertices.push(p);
        }
        let n = mesh.vertices.len();
        for f in &mesh.faces {
            if f.iter().any(|&i| i as usize >= n) {
                return Err(format!("a face refers to vertex {f:?}, but the mesh part has {n} vertices"));
            }
            out.triangles.push([base + f[0], base + f[1], base + f[2]]);
        }
    }
    if out.vertices.is_empty() {
        return Err("the file has no vertices (expected a triangle mesh)".into());
    }
    Ok(out)
}

/// When and how a mesh is split into several convex pieces.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decomposition {
    /// Decompose a closed mesh whose convex hull's volume is more than this many times the
    /// volume the mesh encloses.
    pub volume_ratio: f64,
    /// At most this many pieces per mesh.
    pub max_hulls: u32,
    /// Voxel resolution of the decomposition (parry's VHACD `resolution`).
    pub resolution: u32,
}

impl Default for Decomposition {
    fn default() -> Self {
        Self { volume_ratio: 2.0, max_hulls: 8, resolution: 32 }
    }
}

/// Volume enclosed by a closed mesh (absolute value of the signed tetrahedron sum), or `None` if
/// the mesh is not closed (some edge is not shared by exactly two triangles once coincident
/// vertices are merged).
pub fn enclosed_volume(mesh: &TriMesh) -> Option<f64> {
    // Merge coincident vertices (files often repeat them per face).
    let mut ids: HashMap<[u64; 3], u32> = HashMap::new();
    let mut welded = Vec::with_capacity(mesh.vertices.len());
    for p in &mesh.vertices {
        let key = [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
        let next = ids.len() as u32;
        welded.push(*ids.entry(key).or_insert(next));
    }
    let mut edges: HashMap<(u32, u32), i32> = HashMap::new();
    let mut volume = 0.0;
    for t in &mesh.triangles {
        let w = [welded[t[0] as usize], welded[t[1] as usize], welded[t[2] as usize]];
        if w[0] == w[1] || w[1] == w[2] || w[0] == w[2] {
            continue;
        }
        for k in 0..3 {
            let (a, b) = (w[k], w[(k + 1) % 3]);
            *edges.entry((a.min(b), a.max(b))).or_default() += 1;
        }
        let [a, b, c] = t.map(|i| mesh.vertices[i as usize].coords);
        volume += a.dot(&b.cross(&c)) / 6.0;
    }
    if edges.is_empty() || edges.values().any(|&n| n != 2) {
        return None;
    }
    Some(volume.abs())
}

/// The convex shapes standing for a mesh: its convex hull, or (per `decomposition`) several
/// convex pieces. `None` if the vertices are degenerate (flat or too few for a hull).
pub fn convex_pieces(mesh: &TriMesh, decomposition: Option<&Decomposition>) -> Option<Vec<Arc<ConvexHull>>> {
    let hull = ConvexHull::from_points(&mesh.vertices)?;
    if let Some(rule) = decomposition
        && let Some(inside) = enclosed_volume(mesh).filter(|v| *v > 0.0)
    {
        let hull_volume = hull_volume(&hull);
        if hull_volume > rule.volume_ratio * inside {
            let params = VHACDParameters {
                resolution: rule.resolution,
                max_convex_hulls: rule.max_hulls,
                ..VHACDParameters::default()
            };
            let parts = VHACD::decompose(&params, &mesh.vertices, &mesh.triangles, false).compute_convex_hulls(4);
            let pieces: Vec<Arc<ConvexHull>> =
                parts.iter().filter_map(|(points, _)| ConvexHull::from_points(points)).map(Arc::new).collect();
            if pieces.len() > 1 {
                return Some(pieces);
            }
        }
    }
    Some(vec![Arc::new(hull)])
}

/// Volume of a convex hull.
pub fn hull_volume(hull: &ConvexHull) -> f64 {
    use parry3d_f64::shape::Shape as _;
    hull.polyhedron.mass_properties(1.0).mass()
}
