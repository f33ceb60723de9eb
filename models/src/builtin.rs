//! The seed robots of the source paper, built in.
//!
//! Every number is from `shared/robots/README.md` (which names its public sources); what is
//! not sourced is marked ASSUMPTION here, in the provenance text and in `embodied model --help`.

use std::f64::consts::{FRAC_PI_2, PI};

use nalgebra::{Isometry3, Vector3};

use crate::actuator::{irp6_arm_screws, triangle};
use crate::error::ModelError;
use crate::geometry::{PlacedShape, Shape};
use crate::ik::IRP6_DH;
use crate::joint::{Dh, JointKind, JointLimits};
use crate::robot::{ClosedForm, Robot, RobotBuilder};

/// Names of the built-in robots, in the order `embodied model --help` lists them.
pub const BUILTIN_NAMES: [&str; 5] = ["irp6-postument", "irp6-on-track", "two-irp6", "polycrank", "rnt"];

/// One line per built-in robot: where its numbers come from.
pub fn builtin_summaries() -> Vec<(&'static str, &'static str)> {
    vec![
        ("irp6-postument", IRP6_SOURCE),
        ("irp6-on-track", IRP6_OT_SOURCE),
        ("two-irp6", TWO_IRP6_SOURCE),
        ("polycrank", POLYCRANK_SOURCE),
        ("rnt", RNT_SOURCE),
    ]
}

/// Build a built-in robot by name.
pub fn builtin(name: &str) -> Result<Robot, ModelError> {
    match name {
        "irp6-postument" | "irp6_postument" => irp6_postument(),
        "irp6-on-track" | "irp6_on_track" => irp6_on_track(),
        "two-irp6" | "two_irp6" => two_irp6(),
        "polycrank" => polycrank(),
        "rnt" => rnt(),
        _ => Err(ModelError::UnknownModel {
            name: name.to_string(),
            known: BUILTIN_NAMES.iter().map(|s| s.to_string()).collect(),
        }),
    }
}

const IRP6_SOURCE: &str = "IRp-6 on postument, 6 DOF. DH table: shared/robots/README.md 1.3.1 (derived from MRROC++ \
kinematic_model_irp6p_with_wrist.cc, a2=0.455, a3=0.67, d5=0.19 m); shoulder 0.95 m above base (ROS Irp6pmKinematic.h); \
tool 0.25 m along flange z (MRROC++); joint limits MRROC++ joint space (README 1.5). ASSUMPTION: 1.5 rad/s and 7 rad/s^2 \
per joint (README 1.6: no authoritative spec); collision capsules (README 1.9). Lower and upper arm driven by ball \
screws through triangles, MRROC++ constants (sl123, mi, ni, lead 5 mm, README 1.5); screw speed 0.159 m/s from MRROC++'s \
motor_max_velocity 200 rad/s (a generator default, README 1.6). Strokes from MRROC++'s motor ranges (lower_limit_axis, \
upper_limit_axis): with the joint limits they leave q1 in -125.3..-52.0 degrees and the upper arm's absolute angle \
q1 + q2 + 90 degrees in -25.3..36.5 degrees, as MRROC++ checks both joints and motors.";
const IRP6_OT_SOURCE: &str = "IRp-6 on track, 7 DOF: prismatic track along +y (-0.125..1.21 m, MRROC++ \
kinematic_model_irp6ot_with_wrist.cc) then the IRp-6 arm (flange = Ty(q0) Tz(0.95) DH(q1..q6)). ASSUMPTION: track 0.5 m/s \
(URDF .53), 2 m/s^2; arm 1.5 rad/s, 7 rad/s^2; collision capsules and track bed box (README 1.9).";
const TWO_IRP6_SOURCE: &str = "Two-handed IRp-6 cell, 13 DOF: on-track robot at the world origin (its 7 joints first), \
postument robot based at (0, 2.11, 0) (URDF irp6pboth.urdf.xacro, RCPRG-ros-pkg/irp6_robot@0635618d). Same assumptions \
as irp6-postument and irp6-on-track.";
const POLYCRANK_SOURCE: &str = "Polycrank direct-drive 7R arm without joint limits: GraspIt! DH chain \
(mzbikows/Graspit@3425fbcf Polycrank.xml, README 2.2) in metres/radians, chain base at (0, 0, 0.925); link boxes = the \
link meshes' bounding boxes (README 2.3). Reconstructed from a 2010 simulation model, not manufacturer data. ASSUMPTION: \
all joints continuous, 3 rad/s, 10 rad/s^2.";
const RNT_SOURCE: &str = "RNT serial-parallel milling robot: ASSUMPTION MODEL. No public RNT numbers exist \
(README 3); this is the invented, parameterised RNT-like 6R stand-in of README 3 (reach ~2.5 m, J1-J3 0.5 rad/s, \
J4-J6 1.5 rad/s, ASSUMPTION accelerations 2 and 5 rad/s^2). ASSUMPTION (invented): J2 and J3 driven by screws through \
triangles (L1 0.45, L2 0.55 m, phi 3.0 rad, 0.15 m/s; L1 0.3, L2 0.4 m, phi pi/2, 0.10 m/s). Replace when real data arrive.";

fn tz(z: f64) -> Isometry3<f64> {
    Isometry3::translation(0.0, 0.0, z)
}
fn at(x: f64, y: f64, z: f64) -> Isometry3<f64> {
    Isometry3::translation(x, y, z)
}

/// Append a standard-DH chain below `parent`: link i is DH frame i. Returns the link indices.
#[allow(clippy::too_many_arguments)]
fn dh_chain(
    b: &mut RobotBuilder,
    parent: usize,
    base: Isometry3<f64>,
    prefix: &str,
    joint_names: &[&str],
    dh: &[Dh],
    kinds: &[JointKind],
    limits: &[JointLimits],
    shapes: Vec<Vec<PlacedShape>>,
) -> Vec<usize> {
    let mut links = Vec::new();
    let mut prev = parent;
    let mut shapes = shapes.into_iter();
    for i in 0..dh.len() {
        let link = b.link(format!("{prefix}link{}", i + 1), shapes.next().unwrap_or_default());
        let origin = if i == 0 { base } else { Isometry3::identity() };
        b.joint(
            joint_names[i],
            kinds[i],
            prev,
            link,
            origin,
            Vector3::z(),
            dh[i].theta_offset,
            dh[i].post(),
            limits[i],
        );
        links.push(link);
        prev = link;
    }
    links
}

/// MRROC++ joint-space limits (README 1.5) with the assumed 1.5 rad/s, 7 rad/s^2.
fn irp6_arm_limits() -> [JointLimits; 6] {
    let d = PI / 180.0;
    let (v, a) = (1.5, 7.0);
    [
        JointLimits::new(-170.0 * d, 170.0 * d, v, a),
        JointLimits::new(-130.0 * d, -50.0 * d, v, a),
        JointLimits::new(-25.0 * d, 40.0 * d, v, a),
        JointLimits::new(-90.0 * d, 92.0 * d, v, a),
        JointLimits::new(-10.0, 10.0, v, a),
        JointLimits::new(-2.88, 2.93, v, a),
    ]
}

/// Capsules per DH link (ASSUMPTION derived from the URDF boxes and mesh bounding boxes, README 1.9).
fn irp6_arm_shapes() -> Vec<Vec<PlacedShape>> {
    let id = Isometry3::identity();
    vec![
        vec![],
        // lower arm: shoulder -> elbow along frame-2 x
        vec![PlacedShape::new(id, Shape::capsule([-0.455, 0.0, 0.0], [0.0, 0.0, 0.0], 0.10))],
        // upper arm: 0.2 m behind the elbow to the wrist centre along frame-3 x
        vec![PlacedShape::new(id, Shape::capsule([-0.87, 0.0, 0.0], [0.0, 0.0, 0.0], 0.085))],
        // wrist: wrist centre -> flange along frame-4 z
        vec![PlacedShape::new(id, Shape::capsule([0.0, 0.0, 0.0], [0.0, 0.0, 0.13], 0.06))],
        vec![],
        // flange disc and a gripper body up to the jaws (tool point at z = 0.25)
        vec![
            PlacedShape::new(tz(-0.03), Shape::cylinder(0.08, 0.03)),
            PlacedShape::new(tz(0.11), Shape::cuboid(0.03, 0.06, 0.09)),
        ],
    ]
}

/// The robot base of an IRp-6: base box and column up to the shoulder (ASSUMPTION, README 1.9).
fn irp6_column_shapes(z0: f64) -> Vec<PlacedShape> {
    vec![
        PlacedShape::new(at(0.0, 0.0, z0 + 0.2), Shape::cuboid(0.2, 0.2, 0.2)),
        PlacedShape::new(at(0.0, 0.0, z0 + 0.675), Shape::cylinder(0.2, 0.245)),
    ]
}

const IRP6_FRONT: [f64; 6] = [0.0, -1.57, 0.0, 1.56, 1.57, -1.57];
const IRP6_JOINTS: [&str; 6] = ["column", "lower_arm", "upper_arm", "wrist_t", "wrist_v", "wrist_n"];
fn irp6_joint_names(prefix: &str) -> Vec<String> {
    IRP6_JOINTS.iter().map(|j| format!("{prefix}{j}")).collect()
}

/// The arm's six joints below `parent`; `lower_arm` is the degree of freedom of its lower arm
/// (its ball screws drive that joint and the next, MRROC++'s serial-parallel actuation).
fn add_irp6_arm(b: &mut RobotBuilder, parent: usize, base: Isometry3<f64>, prefix: &str, lower_arm: usize) {
    let names = irp6_joint_names(prefix);
    let names: Vec<&str> = names.iter().map(|s| s.as_str()).collect();
    let links = dh_chain(
        b,
        parent,
        base,
        prefix,
        &names,
        &IRP6_DH,
        &[JointKind::Revolute; 6],
        &irp6_arm_limits(),
        irp6_arm_shapes(),
    );
    debug_assert_eq!(links.len(), 6);
    // MRROC++ checks a commanded position twice: its DH joints against the joint limits
    // (`check_joints`) and the motor positions against the motor ranges
    // (`check_motor_position`). The screws carry the second check as their strokes: the
    // lower-arm stroke leaves q1 in [-125.3, -52.0] degrees, the upper-arm stroke the upper
    // arm's absolute angle q1 + q2 + pi/2 in [-25.3, 36.5] degrees (a coupled limit the joint
    // box cannot express).
    for screw in irp6_arm_screws(prefix, lower_arm) {
        b.actuator(screw);
    }
}

/// IRp-6 on postument: base at the world origin, shoulder 0.95 m above it.
pub fn irp6_postument() -> Result<Robot, ModelError> {
    let mut b = RobotBuilder::new("irp6-postument").provenance(IRP6_SOURCE);
    let base = b.link("base", irp6_column_shapes(0.0));
    add_irp6_arm(&mut b, base, tz(0.95), "", 1);
    b.end_effector("irp6p", "link6", tz(0.25));
    b.closed_form_ik("irp6p", ClosedForm::Irp6);
    b.home(IRP6_FRONT.to_vec());
    b.build()
}

fn add_track(b: &mut RobotBuilder, prefix: &str) -> (usize, usize) {
    let bed = b.link(
        format!("{prefix}track"),
        vec![PlacedShape::new(at(0.0, 0.6045, 0.125), Shape::cuboid(0.24, 1.0, 0.125))],
    );
    let carriage = b.link(format!("{prefix}carriage"), irp6_column_shapes(0.25).into_iter().skip(1).collect());
    b.add_shapes(carriage, [PlacedShape::new(at(0.0, 0.0, 0.325), Shape::cuboid(0.2, 0.2, 0.075))]);
    b.joint(
        format!("{prefix}track"),
        JointKind::Prismatic,
        bed,
        carriage,
        Isometry3::identity(),
        Vector3::y(),
        0.0,
        Isometry3::identity(),
        JointLimits::new(-0.125, 1.21, 0.5, 2.0),
    );
    (bed, carriage)
}

/// IRp-6 on a track along +y: flange = Ty(q0) Tz(0.95) DH(q1..q6).
pub fn irp6_on_track() -> Result<Robot, ModelError> {
    let mut b = RobotBuilder::new("irp6-on-track").provenance(IRP6_OT_SOURCE);
    let (_, carriage) = add_track(&mut b, "");
    add_irp6_arm(&mut b, carriage, tz(0.95), "", 2);
    b.end_effector("irp6ot", "link6", tz(0.25));
    b.closed_form_ik("irp6ot", ClosedForm::Irp6);
    let mut home = vec![0.0];
    home.extend(IRP6_FRONT);
    b.home(home);
    b.build()
}

/// The two-handed cell: on-track robot at the origin (joints 0..7), postument at (0, 2.11, 0).
pub fn two_irp6() -> Result<Robot, ModelError> {
    let mut b = RobotBuilder::new("two-irp6").provenance(TWO_IRP6_SOURCE);
    let world = b.link("world", vec![]);
    let (bed, carriage) = add_track(&mut b, "ot_");
    b.joint(
        "ot_base",
        JointKind::Fixed,
        world,
        bed,
        Isometry3::identity(),
        Vector3::z(),
        0.0,
        Isometry3::identity(),
        JointLimits::new(0.0, 0.0, 0.0, 0.0),
    );
    add_irp6_arm(&mut b, carriage, tz(0.95), "ot_", 2);
    let pbase = b.link("p_base", irp6_column_shapes(0.0));
    b.joint(
        "p_base",
        JointKind::Fixed,
        world,
        pbase,
        at(0.0, 2.11, 0.0),
        Vector3::z(),
        0.0,
        Isometry3::identity(),
        JointLimits::new(0.0, 0.0, 0.0, 0.0),
    );
    add_irp6_arm(&mut b, pbase, tz(0.95), "p_", 8);
    b.end_effector("irp6ot", "ot_link6", tz(0.25));
    b.end_effector("irp6p", "p_link6", tz(0.25));
    b.closed_form_ik("irp6ot", ClosedForm::Irp6);
    b.closed_form_ik("irp6p", ClosedForm::Irp6);
    let mut home = vec![0.0];
    home.extend(IRP6_FRONT);
    home.extend(IRP6_FRONT);
    b.home(home);
    b.build()
}

/// Box from an axis-aligned bounding box given in millimetres.
fn aabb_mm(x: [f64; 2], y: [f64; 2], z: [f64; 2]) -> PlacedShape {
    let c = |r: [f64; 2]| (r[0] + r[1]) / 2000.0;
    let h = |r: [f64; 2]| (r[1] - r[0]) / 2000.0;
    PlacedShape::new(at(c(x), c(y), c(z)), Shape::cuboid(h(x), h(y), h(z)))
}

/// Polycrank: the GraspIt! 7R DH chain, all joints continuous.
pub fn polycrank() -> Result<Robot, ModelError> {
    let mut b = RobotBuilder::new("polycrank").provenance(POLYCRANK_SOURCE);
    // palm/column mesh: 450 x 920 x 450 mm, standing on the floor
    let column = b.link("column", vec![aabb_mm([-225.0, 225.0], [-225.0, 225.0], [0.6, 920.0])]);
    let mm = 1e-3;
    let d = PI / 180.0;
    let table = [
        (220.0, -299.0, 0.0),
        (152.0, 180.0, 0.0),
        (335.0, 0.0, 90.0),
        (120.0, 151.0, 0.0),
        (116.0, 151.0, 0.0),
        (60.0, 0.0, 90.0),
        (43.0, 0.0, 0.0),
    ];
    let dh: Vec<Dh> = table.iter().map(|&(dd, a, al)| Dh::new(0.0, dd * mm, a * mm, al * d)).collect();
    let shapes = vec![
        vec![aabb_mm([-172.0, 469.0], [-172.0, 172.0], [-224.0, -1.0])],
        vec![aabb_mm([-353.0, 121.0], [-171.0, 175.0], [-154.0, 0.0])],
        // z trimmed from 121 to 89 mm: the full box reaches into link 5's layer along the parallel
        // axes 4-6 (z 90..235 mm in frame 3), which the real arm passes over; untrimmed, link 3 and
        // link 5 overlapped at home and in ~90% of configurations.
        vec![aabb_mm([-118.0, 118.0], [-345.0, 108.0], [-165.0, 89.0])],
        vec![aabb_mm([-243.0, 92.0], [-91.0, 91.0], [-146.0, -1.0])],
        vec![aabb_mm([-243.0, 92.0], [-91.0, 91.0], [-146.0, -1.0])],
        vec![PlacedShape::new(Isometry3::identity(), Shape::cuboid(0.055, 0.0515, 0.0575))],
        vec![PlacedShape::new(tz(-0.005), Shape::cylinder(0.0315, 0.005))],
    ];
    let names: Vec<String> = (1..=7).map(|i| format!("joint{i}")).collect();
    let names: Vec<&str> = names.iter().map(|s| s.as_str()).collect();
    dh_chain(
        &mut b,
        column,
        tz(0.925),
        "",
        &names,
        &dh,
        &[JointKind::Continuous; 7],
        &[JointLimits::continuous(3.0, 10.0); 7],
        shapes,
    );
    // GraspIt! PolycrankGripper.xml attaches the gripper 48 mm along the last z.
    b.end_effector("polycrank", "link7", tz(0.048));
    b.home(vec![0.0; 7]);
    b.build()
}

/// The RNT's shoulder (J2) and elbow (J3) screws, README 3's "actuator-space option"
/// `l^2 = L1^2 + L2^2 - 2 L1 L2 cos(q + phi)`. INVENTED (ASSUMPTION): no RNT numbers exist.
/// Chosen so that the triangle angle `q + phi` stays inside (0, pi) where the arm works: the
/// elbow's whole joint range fits (its stroke is the lengths at the joint limits, 1 mm wider),
/// the shoulder's half-turn range cannot (no triangle covers pi), so its stroke ends where the
/// angle is 0.25 and 2.95 rad (q2 in [-2.75, -0.05]), as the IRp-6 screws' strokes cut their
/// joints' ranges. Speeds 0.15 and 0.10 m/s: below what 0.5 rad/s asks mid-stroke (0.17 and
/// 0.12 m/s), so the screws, not the joints, bound the shoulder and elbow there.
fn rnt_screws(limits: &[JointLimits; 6]) -> [crate::actuator::ScrewTriangle; 2] {
    let (l1, l2, phi) = (0.45, 0.55, 3.0);
    let len = |a: f64, l1: f64, l2: f64| (l1 * l1 + l2 * l2 - 2.0 * l1 * l2 * a.cos()).sqrt();
    let shoulder = triangle("shoulder_screw", 1, l1, l2, phi, (len(0.25, l1, l2), len(2.95, l1, l2)), 0.15);
    let (e1, e2, ephi) = (0.3, 0.4, FRAC_PI_2);
    let stroke = (len(limits[2].lower + ephi, e1, e2) - 1e-3, len(limits[2].upper + ephi, e1, e2) + 1e-3);
    let elbow = triangle("elbow_screw", 2, e1, e2, ephi, stroke, 0.10);
    [shoulder, elbow]
}

/// RNT-like serial-parallel milling robot: ASSUMPTION MODEL (README 3).
pub fn rnt() -> Result<Robot, ModelError> {
    let mut b = RobotBuilder::new("rnt").provenance(RNT_SOURCE);
    // Column up to 0.8 m (0.2 m below the shoulder at d1 = 1.0), so that the link-2 capsule
    // (r 0.15) clears it at every q1; a column up to 0.9 m touched it in every configuration.
    let base = b.link("base", vec![PlacedShape::new(tz(0.4), Shape::cylinder(0.35, 0.4))]);
    let dh = [
        Dh::new(0.0, 1.00, 0.35, -FRAC_PI_2),
        Dh::new(0.0, 0.0, 1.20, 0.0),
        Dh::new(FRAC_PI_2, 0.0, 0.20, -FRAC_PI_2),
        Dh::new(0.0, 1.10, 0.0, FRAC_PI_2),
        Dh::new(0.0, 0.0, 0.0, -FRAC_PI_2),
        Dh::new(0.0, 0.25, 0.0, 0.0),
    ];
    let limits = [
        JointLimits::new(-PI, PI, 0.5, 2.0),
        JointLimits::new(-PI, 0.0, 0.5, 2.0),
        JointLimits::new(-1.2, 1.2, 0.5, 2.0),
        JointLimits::new(-PI, PI, 1.5, 5.0),
        JointLimits::new(-2.0, 2.0, 1.5, 5.0),
        JointLimits::new(-PI, PI, 1.5, 5.0),
    ];
    let id = Isometry3::identity();
    let shapes = vec![
        vec![PlacedShape::new(id, Shape::capsule([-0.35, 0.0, 0.0], [0.0, 0.0, 0.0], 0.15))],
        vec![PlacedShape::new(id, Shape::capsule([-1.2, 0.0, 0.0], [0.0, 0.0, 0.0], 0.15))],
        vec![PlacedShape::new(id, Shape::capsule([-0.2, 0.0, 0.0], [0.0, 0.0, 0.0], 0.15))],
        // starts 0.2 m along the forearm (was 0): link 3 covers the elbow, and from 0 the capsule
        // overlapped link 2's at the elbow in every configuration
        vec![PlacedShape::new(id, Shape::capsule([0.0, -0.9, 0.0], [0.0, -0.15, 0.0], 0.12))],
        vec![PlacedShape::new(id, Shape::capsule([0.0, 0.0, 0.0], [0.0, 0.0, 0.0], 0.1))],
        vec![
            PlacedShape::new(tz(-0.12), Shape::cylinder(0.08, 0.12)),
            PlacedShape::new(tz(0.05), Shape::cylinder(0.04, 0.05)),
        ],
    ];
    let names = ["j1", "j2", "j3", "j4", "j5", "j6"];
    dh_chain(&mut b, base, Isometry3::identity(), "", &names, &dh, &[JointKind::Revolute; 6], &limits, shapes);
    for screw in rnt_screws(&limits) {
        b.actuator(screw);
    }
    // ASSUMPTION: a 0.10 m milling/polishing spindle along the flange z.
    b.end_effector("rnt", "link6", tz(0.10));
    // With README 3's theta3 offset (+pi/2) the forearm folds back along the upper arm at q3 = 0
    // (the old home put the wrist against the column); q3 = -1.2 opens the elbow as far as the
    // limits allow, reaching forward at shoulder height.
    b.home(vec![0.0, -1.2, -1.2, 0.0, 0.5, 0.0]);
    b.build()
}
