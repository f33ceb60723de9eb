//! `embodied model`: a robot's joints, link poses, end effectors and collision state at q.

use std::path::Path;

use embodied_models::collision::{CollisionModel, Environment};
use embodied_models::nalgebra::{self, Isometry3};
use embodied_models::{Robot, builtin};
use serde::Serialize;

use crate::AppError;

/// Load a robot: a built-in name, or a path to a URDF (with an optional SRDF).
pub fn load_robot(spec: &str, srdf: Option<&Path>) -> Result<Robot, AppError> {
    let looks_like_file = spec.ends_with(".urdf") || spec.ends_with(".xml") || spec.contains('/');
    if looks_like_file {
        Ok(embodied_models::urdf::load_urdf(Path::new(spec), srdf)?)
    } else {
        if srdf.is_some() {
            return Err(AppError::Usage(format!("--srdf applies to URDF files, not to the built-in model `{spec}`")));
        }
        Ok(builtin(spec)?)
    }
}

/// Parse `--q v1,v2,...` and check it against the robot (count, finiteness, limits).
pub fn parse_q(robot: &Robot, text: &str) -> Result<Vec<f64>, AppError> {
    let mut q = Vec::new();
    for (i, part) in text.split(',').enumerate() {
        let part = part.trim();
        let v: f64 = part.parse().map_err(|_| {
            AppError::Usage(format!(
                "--q: value {} (`{part}`) is not a number; expected {} comma-separated numbers",
                i + 1,
                robot.dof()
            ))
        })?;
        q.push(v);
    }
    robot.check_configuration(&q)?;
    Ok(q)
}

#[derive(Debug, Serialize)]
/// A pose as JSON: translation and unit quaternion.
pub struct PoseJson {
    /// Translation x, y, z, m.
    pub translation: [f64; 3],
    /// Rotation as the unit quaternion x, y, z, w.
    pub quaternion_xyzw: [f64; 4],
}

impl From<&Isometry3<f64>> for PoseJson {
    fn from(p: &Isometry3<f64>) -> Self {
        let t = p.translation.vector;
        let r = p.rotation;
        Self { translation: [t.x, t.y, t.z], quaternion_xyzw: [r.i, r.j, r.k, r.w] }
    }
}

#[derive(Debug, Serialize)]
/// One degree of freedom of the report.
pub struct JointJson {
    /// The joint's name.
    pub name: String,
    /// `revolute`, `continuous` or `prismatic`.
    pub kind: &'static str,
    /// Lower position limit, rad or m (`None` when unbounded).
    pub lower: Option<f64>,
    /// Upper position limit, rad or m (`None` when unbounded).
    pub upper: Option<f64>,
    /// Velocity limit, rad/s or m/s.
    pub max_velocity: f64,
    /// Acceleration limit, rad/s^2 or m/s^2.
    pub max_acceleration: f64,
}

#[derive(Debug, Serialize)]
/// One link and its world pose at `q`.
pub struct LinkJson {
    /// The link's name.
    pub name: String,
    /// Position of the link frame in the world frame, m.
    pub translation: [f64; 3],
    /// Rotation of the link frame in the world frame, as the unit quaternion x, y, z, w.
    pub quaternion_xyzw: [f64; 4],
}

#[derive(Debug, Serialize)]
/// One end effector and its world poses at `q`.
pub struct EndEffectorJson {
    /// The end effector's name.
    pub name: String,
    /// Pose of the flange (its link frame) in the world frame.
    pub flange: PoseJson,
    /// Pose of the tool frame in the world frame.
    pub tool: PoseJson,
}

#[derive(Debug, Serialize)]
/// Two bodies of the robot, by name.
pub struct CollisionPairJson {
    /// One body ("link `x`").
    pub a: String,
    /// The other body.
    pub b: String,
}

/// The `embodied model --json` object.
#[derive(Debug, Serialize)]
pub struct ModelReport {
    /// The robot's name.
    pub robot: String,
    /// Number of degrees of freedom.
    pub dof: usize,
    /// The configuration reported on (rad or m).
    pub q: Vec<f64>,
    /// The degrees of freedom, in `q` order.
    pub joints: Vec<JointJson>,
    /// Every link with its pose.
    pub links: Vec<LinkJson>,
    /// Every end effector with its poses.
    pub end_effectors: Vec<EndEffectorJson>,
    /// Whether the robot collides with itself at `q`.
    pub self_collision: bool,
    /// The first colliding pair, if any.
    pub colliding_pair: Option<CollisionPairJson>,
    /// Signed distance of the closest pair, m (negative: penetration).
    pub min_distance: f64,
    /// The closest pair of bodies.
    pub closest_pair: CollisionPairJson,
    /// Where the robot's numbers come from, and what is assumed.
    pub provenance: String,
    /// `--ik`: the solutions for a tool pose.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ik: Option<IkReport>,
}

/// One inverse-kinematics solution of `embodied model --ik`.
#[derive(Debug, Serialize)]
pub struct IkSolutionJson {
    /// The solution's joint values (rad or m).
    pub q: Vec<f64>,
    /// Whether the robot collides with itself there.
    pub self_collision: bool,
}

/// The `--ik` part of `embodied model`: solutions nearest the seed first.
#[derive(Debug, Serialize)]
pub struct IkReport {
    /// The end effector whose tool frame was posed.
    pub end_effector: String,
    /// `closed-form` (every solution within the limits) or `numerical` (one, from the seed).
    pub method: &'static str,
    /// The requested tool pose, in the world frame.
    pub target: PoseJson,
    /// The solutions found, nearest the seed first.
    pub solutions: Vec<IkSolutionJson>,
    /// Why there is none, when `solutions` is empty.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub failure: Option<String>,
}

/// Parse `X,Y,Z,ROLL,PITCH,YAW` (metres, radians; roll-pitch-yaw as in scenario files).
pub fn parse_pose(text: &str) -> Result<Isometry3<f64>, AppError> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let expected = "expected 6 comma-separated numbers X,Y,Z,ROLL,PITCH,YAW (m, rad)";
    if parts.len() != 6 {
        return Err(AppError::Usage(format!("--ik: got {} values; {expected}", parts.len())));
    }
    let mut v = [0.0; 6];
    for (i, part) in parts.iter().enumerate() {
        v[i] = part.parse::<f64>().ok().filter(|x| x.is_finite()).ok_or_else(|| {
            AppError::Usage(format!("--ik: value {} (`{part}`) is not a finite number; {expected}", i + 1))
        })?;
    }
    Ok(Isometry3::from_parts(
        nalgebra::Translation3::new(v[0], v[1], v[2]),
        nalgebra::UnitQuaternion::from_euler_angles(v[3], v[4], v[5]),
    ))
}

/// Solve `--ik` for `robot`, seeded at `q`: every closed-form solution, or the numerical one.
pub fn ik_report(robot: &Robot, q: &[f64], pose: &str, ee: Option<&str>) -> Result<IkReport, AppError> {
    let target = parse_pose(pose)?;
    let index = match ee {
        None => 0,
        Some(name) => robot.end_effectors().iter().position(|e| e.name == name).ok_or_else(|| {
            let known: Vec<&str> = robot.end_effectors().iter().map(|e| e.name.as_str()).collect();
            AppError::Usage(format!(
                "--ee: robot `{}` has no end effector `{name}`; it has: {}",
                robot.name(),
                known.join(", ")
            ))
        })?,
    };
    let Some(effector) = robot.end_effectors().get(index) else {
        return Err(AppError::Usage(format!("--ik: robot `{}` has no end effector", robot.name())));
    };
    let (method, solved) = if robot.closed_form(index).is_some() {
        ("closed-form", robot.inverse_kinematics_all(index, &target, q).map_err(|e| e.to_string()))
    } else {
        let options = embodied_models::IkOptions::default();
        ("numerical", robot.inverse_kinematics(index, &target, q, &options).map(|s| vec![s]).map_err(|e| e.to_string()))
    };
    let (solutions, failure) = match solved {
        Ok(s) if s.is_empty() => (s, Some("out of reach, or every solution breaks a joint limit".to_string())),
        Ok(s) => (s, None),
        Err(e) => (Vec::new(), Some(e)),
    };
    let collision = CollisionModel::new(robot, Environment::new());
    Ok(IkReport {
        end_effector: effector.name.clone(),
        method,
        target: (&target).into(),
        solutions: solutions
            .into_iter()
            .map(|s| IkSolutionJson { self_collision: collision.collides(&s), q: s })
            .collect(),
        failure,
    })
}

/// Build the report of `robot` at `q` (already checked).
pub fn model_report(robot: &Robot, q: &[f64]) -> ModelReport {
    let joints = (0..robot.dof())
        .map(|i| {
            let j = robot.dof_joint(i);
            let l = j.limits;
            JointJson {
                name: j.name.clone(),
                kind: j.kind.as_str(),
                lower: l.lower.is_finite().then_some(l.lower),
                upper: l.upper.is_finite().then_some(l.upper),
                max_velocity: l.max_velocity,
                max_acceleration: l.max_acceleration,
            }
        })
        .collect();
    let poses = robot.forward_kinematics(q);
    let links = robot
        .links()
        .iter()
        .zip(&poses)
        .map(|(l, p)| {
            let pj = PoseJson::from(p);
            LinkJson { name: l.name.clone(), translation: pj.translation, quaternion_xyzw: pj.quaternion_xyzw }
        })
        .collect();
    let end_effectors = robot
        .end_effectors()
        .iter()
        .map(|e| {
            let flange = poses[e.link];
            EndEffectorJson { name: e.name.clone(), flange: (&flange).into(), tool: (&(flange * e.tool)).into() }
        })
        .collect();
    let collision = CollisionModel::new(robot, Environment::new());
    let contact = collision.first_collision(q);
    let dist = collision.distance(q);
    ModelReport {
        robot: robot.name().to_string(),
        dof: robot.dof(),
        q: q.to_vec(),
        joints,
        links,
        end_effectors,
        self_collision: contact.is_some(),
        colliding_pair: contact.map(|c| CollisionPairJson { a: c.a.to_string(), b: c.b.to_string() }),
        min_distance: dist.distance,
        closest_pair: CollisionPairJson { a: dist.a.to_string(), b: dist.b.to_string() },
        provenance: robot.provenance().to_string(),
        ik: None,
    }
}

/// Human-readable rendering of a [`ModelReport`].
pub fn render_text(r: &ModelReport) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(s, "robot {} ({} DOF)", r.robot, r.dof);
    let _ = writeln!(s, "  source: {}", r.provenance);
    let _ = writeln!(s, "joints:");
    for (j, q) in r.joints.iter().zip(&r.q) {
        let lim = match (j.lower, j.upper) {
            (Some(l), Some(u)) => format!("[{l:+.4}, {u:+.4}]"),
            _ => "unlimited".to_string(),
        };
        let _ = writeln!(
            s,
            "  {:<22} {:<10} q={:+.4}  limits {:<20} vmax {:.3}  amax {:.3}",
            j.name, j.kind, q, lim, j.max_velocity, j.max_acceleration
        );
    }
    let _ = writeln!(s, "links (world frame):");
    for l in &r.links {
        let t = l.translation;
        let _ = writeln!(s, "  {:<28} xyz ({:+.4}, {:+.4}, {:+.4})", l.name, t[0], t[1], t[2]);
    }
    for e in &r.end_effectors {
        let f = e.flange.translation;
        let t = e.tool.translation;
        let _ = writeln!(
            s,
            "end effector {}: flange ({:+.4}, {:+.4}, {:+.4})  tool ({:+.4}, {:+.4}, {:+.4})",
            e.name, f[0], f[1], f[2], t[0], t[1], t[2]
        );
    }
    match &r.colliding_pair {
        Some(p) => {
            let _ = writeln!(s, "self-collision: YES ({} and {})", p.a, p.b);
        }
        None => {
            let _ = writeln!(s, "self-collision: no");
        }
    }
    let _ = writeln!(s, "minimum distance: {:.4} m ({} and {})", r.min_distance, r.closest_pair.a, r.closest_pair.b);
    if let Some(ik) = &r.ik {
        let t = ik.target.translation;
        let _ = writeln!(
            s,
            "inverse kinematics of {} for tool at ({:+.4}, {:+.4}, {:+.4}), {}: {} solution(s), nearest the seed first",
            ik.end_effector,
            t[0],
            t[1],
            t[2],
            ik.method,
            ik.solutions.len()
        );
        for sol in &ik.solutions {
            let q: Vec<String> = sol.q.iter().map(|v| format!("{v:+.4}")).collect();
            let note = if sol.self_collision { "  (self-collision)" } else { "" };
            let _ = writeln!(s, "  q = [{}]{note}", q.join(", "));
        }
        if let Some(why) = &ik.failure {
            let _ = writeln!(s, "  none: {why}");
        }
    }
    s
}
