//! Two end effectors holding one rigid object: the closed-chain part of a plan.

use embodied_models::Robot;
use embodied_models::geometry::{PlacedShape, Shape};
use embodied_models::nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use serde::{Deserialize, Serialize};

/// A rigid box carried by two end effectors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CarriedObject {
    pub name: String,
    /// Full box sizes along the object's x, y, z, m.
    pub size: [f64; 3],
    /// Pose of the object in the first end effector's tool frame: x, y, z, then the unit
    /// quaternion w, x, y, z.
    pub in_tool: [f64; 7],
}

impl CarriedObject {
    /// `in_tool` as an isometry (the quaternion normalised; `None` if it is zero or not finite).
    pub fn pose_in_tool(&self) -> Option<Isometry3<f64>> {
        let [x, y, z, qw, qx, qy, qz] = self.in_tool;
        let q = Quaternion::new(qw, qx, qy, qz);
        if !self.in_tool.iter().all(|v| v.is_finite()) || q.norm() < 1e-9 {
            return None;
        }
        Some(Isometry3::from_parts(Translation3::new(x, y, z), UnitQuaternion::from_quaternion(q)))
    }

    /// `pose` (object in tool frame) in the `in_tool` layout.
    pub fn encode_pose(pose: &Isometry3<f64>) -> [f64; 7] {
        let t = pose.translation.vector;
        let q = pose.rotation.into_inner();
        [t.x, t.y, t.z, q.w, q.i, q.j, q.k]
    }

    /// A copy of `robot` with the object rigidly attached to the flange link of end effector
    /// `holder`; collisions between that link and the links in `touching` (the other
    /// gripper) are no longer checked, since the object's shape is part of the holder's link.
    pub fn attach(&self, robot: &Robot, holder: usize, touching: &[usize]) -> Option<Robot> {
        let ee = robot.end_effectors().get(holder)?;
        if !self.size.iter().all(|s| s.is_finite() && *s > 0.0) {
            return None;
        }
        let pose = ee.tool * self.pose_in_tool()?;
        let shape = Shape::cuboid(self.size[0] / 2.0, self.size[1] / 2.0, self.size[2] / 2.0);
        let link = ee.link;
        let mut out = robot.clone();
        out.attach_shapes(link, [PlacedShape::new(pose, shape)]);
        for &other in touching {
            if other != link && other < robot.links().len() {
                out.disable_pair(link, other);
            }
        }
        Some(out)
    }
}

/// A span of a plan during which two end effectors hold one rigid object (a closed chain):
/// the pose of the second tool frame relative to the first must stay what it is at `from_s`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ClosedChainSpan {
    pub from_s: f64,
    pub to_s: f64,
    /// End-effector names of the robot (see [`Robot::end_effectors`]).
    pub end_effectors: [String; 2],
    /// Largest allowed change of the relative position, m, and rotation angle, rad.
    pub tolerance_m: f64,
    pub tolerance_rad: f64,
    /// The object, attached to the first end effector (its collisions count too).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub object: Option<CarriedObject>,
}
