//! `embodied bench mbm-generate`: make MotionBenchMaker-style UR5 problems of the families we are
//! measured on but do not have (`cage`, `bookshelf_tall`, `bookshelf_thin`, `table_under_pick`),
//! written as MoveIt `sceneNNNN.yaml` / `requestNNNN.yaml` pairs that `bench mbm` reads unchanged.
//!
//! # How a problem is made
//!
//! MotionBenchMaker (Chamzas et al., RA-L 2022) describes each family by a template scene of
//! boxes and cylinders, a random variation of the scene, a base offset, and goal (and sometimes
//! start) queries: the gripper at an offset pose relative to a target object, with tolerances,
//! solved into joint values by inverse kinematics. The numbers below are data from the public
//! repository `KavrakiLab/motion_bench_maker` (`configs/problems/<family>_ur5.yaml`,
//! `configs/scenes/<kind>/scene_*.yaml`, `variation_*.yaml`, `*queries*.yaml`,
//! `configs/robots/ur5.yaml`); the code is ours.
//!
//! For one problem: sample a scene; draw a goal pose within the query's tolerances and solve it
//! with [`Robot::inverse_kinematics`] from random seeds; keep the first solution within the joint
//! limits, clear of the robot's pedestal (and reachable past it from the start) and free of
//! collision in that scene ([`CollisionModel`] built exactly as `bench mbm`
//! builds it: the SRDF's and the scene's allowed pairs, the same always/never-colliding pairs).
//! A scene whose goal (or start) cannot be found in [`IK_CALLS_PER_SCENE`] calls is resampled,
//! up to [`SCENES_PER_PROBLEM`] times; then generation fails with a clear error. Every problem
//! draws from its own generator seeded by the seed, the family and the index: the same seed gives
//! the same files.
//!
//! # Frame conventions
//!
//! Derived by comparing the box template (`configs/scenes/box/scene_box.yaml`,
//! `configs/problems/box_ur5.yaml`, `variation_box.yaml`) and the bookshelf_small one with the
//! 100 public `box_ur5` and `bookshelf_small_ur5` scenes, and the public requests' goal
//! configurations with our forward kinematics of the spherized UR5:
//!
//! - The template's objects are in the robot's `base_link` frame. The spherized URDF's root is
//!   `offset_link` (the scene/world frame), with `base_link` at `(0, 0, 0.9144)` turned by 1.57 rad
//!   about z. A template pose `P` becomes `W * O * B * P` in the world: `B` is the root-to-
//!   `base_link` transform (taken from the URDF), `O` the problem's `base_offset` (a translation in
//!   the world frame), `W` one draw of the `World` variation, applied in the world frame (a global
//!   pre-multiplication; the box's tilted `side_cap` confirms the rotation composes on the left).
//!   Checked: the public box scenes have every yaw at 1.57 +- 1.57, z at 0.44 - 1.1 + 0.9144 +- 0.1,
//!   and the base box at 0.8 +- 0.1 m from the robot's axis; bookshelf_small likewise.
//! - A variation draws each position component uniformly in `[-p, p]` and each roll/pitch/yaw in
//!   `[-r, r]` (the public ranges fill exactly these intervals, so uniform and not the half-width),
//!   as `Translation * Rz(yaw) Ry(pitch) Rx(roll)`.
//! - A per-object variation is applied in the object's own frame (a right multiplication): in the
//!   public box scenes the can sits at local y in [-0.2, 0.2] of the base box, 0.11 above it.
//! - A query's target is `object_pose * offset * ee_offset^-1` for the link `ee_link` (the tip of
//!   the SRDF's `manipulator` chain). Checked: for the public box, bookshelf_small and table_pick
//!   goals, FK of `ee_link` lies within half the query's `position_tol` per world axis (the
//!   tolerance is the full size of a world-aligned box region) and within `orientation_tol` per
//!   axis of the rotation from the target frame.
//! - MotionBenchMaker's UR5 stands on a pedestal (`box_link`, see [`PEDESTAL`]) that the
//!   spherized model and the public scenes leave out. Its validity checks saw it: in the public
//!   goals no upper-arm sphere is below the base, while without it our IK happily returns goals
//!   with the upper arm pointing down through it. Starts and goals are kept clear of it; it is
//!   not written into the scenes (as in the public ones). A goal is also refused when the
//!   shoulder lift would have to swing the upper arm through the pedestal to get there from the
//!   start ([`lift_passes_pedestal`]): such goals were unreachable for every planner we tried, and
//!   the public goals never need it.
//! - The start is MotionBenchMaker's default UR5 state `[1.57, -1.5707, 0, -1.5707, -1.57, 3.14]`
//!   (gripper joints 0) unless the family has a start query (`table_under_pick`: the gripper under
//!   the table), which is solved like the goal.
//!
//! Assumptions (not checkable against the public problems):
//!
//! - `base_offset`'s x and y (non-zero only for `bookshelf_tall`) are in the world frame, as the
//!   offset is applied to the scene after its objects are placed in the world.
//! - `table_under_pick` is placed like the others (base offset, `World` and object variations of
//!   `variation_table.yaml`). The public `table_pick_ur5` scenes, made from the same template, are
//!   instead the template verbatim in the world frame (no offset, no variation; only the IK
//!   solutions differ), but that placement cannot be the one of `table_under_pick`: its start
//!   query (the gripper 0.3 m under the table's top) is then out of the UR5's reach (our IK's
//!   best residual is 1.6 cm against a 0.1 mm tolerance), while the varied placement reaches it.
//! - Within a scene, goal poses are drawn uniformly within 90% of the tolerance region (so that a
//!   solution's small IK residual stays inside it) and each is solved from a random seed.

use std::collections::HashSet;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use embodied_models::formats::moveit::{PlanningScene, parse_request, parse_scene};
use embodied_models::nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use embodied_models::{CollisionModel, IkOptions, ModelError, Rng, Robot, Shape};

use crate::SystemError;
use crate::mbm::{MbmArgs, load_robot};

/// Scenes sampled at most for one problem before generation gives up.
pub const SCENES_PER_PROBLEM: usize = 200;
/// Inverse-kinematics calls (each from a fresh random seed and goal pose draw) per scene and query.
pub const IK_CALLS_PER_SCENE: usize = 20;
/// Random restarts inside each inverse-kinematics call.
const IK_RESTARTS: usize = 4;

/// MotionBenchMaker's default UR5 start state, the six arm joints (`configs/robots/ur5.yaml`).
#[allow(clippy::approx_constant)] // the literal values of the data file, not rounded constants
pub const UR5_START: [f64; 6] = [1.57, -1.5707, 0.0, -1.5707, -1.57, 3.14];

/// The joints the public problems name, in their order: the arm, then the gripper.
const JOINT_NAMES: [&str; 12] = [
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
    "robotiq_85_left_inner_knuckle_joint",
    "robotiq_85_left_finger_tip_joint",
    "robotiq_85_left_knuckle_joint",
    "robotiq_85_right_inner_knuckle_joint",
    "robotiq_85_right_finger_tip_joint",
    "robotiq_85_right_knuckle_joint",
];

/// The link whose pose a query constrains (the `manipulator` chain's tip).
pub const TIP_LINK: &str = "ee_link";
/// The frame the templates are written in.
pub const TEMPLATE_FRAME: &str = "base_link";

/// Links of the allowed collision matrix of the public UR5 scenes (data from those files).
const ACM_NAMES: [&str; 20] = [
    "base_link",
    "box_link",
    "ee_link",
    "forearm_link",
    "fts_robotside",
    "fts_toolside",
    "robotiq_85_base_link",
    "robotiq_85_left_finger_link",
    "robotiq_85_left_finger_tip_link",
    "robotiq_85_left_inner_knuckle_link",
    "robotiq_85_left_knuckle_link",
    "robotiq_85_right_finger_link",
    "robotiq_85_right_finger_tip_link",
    "robotiq_85_right_inner_knuckle_link",
    "robotiq_85_right_knuckle_link",
    "shoulder_link",
    "upper_arm_link",
    "wrist_1_link",
    "wrist_2_link",
    "wrist_3_link",
];

/// The public UR5 scenes' allowed collision matrix, one row per [`ACM_NAMES`] entry, `1` = allowed.
const ACM_ROWS: [&str; 20] = [
    "01000000000000010000",
    "10000000000000010000",
    "00001111111111100111",
    "00000000000000001100",
    "00100010000000000001",
    "00100010000000000001",
    "00101101111111100111",
    "00100010111111100111",
    "00100011011111100111",
    "00100011101111100111",
    "00100011110111100111",
    "00100011111011100111",
    "00100011111101100111",
    "00100011111110100111",
    "00100011111111000111",
    "11000000000000001000",
    "00010000000000010000",
    "00110011111111100011",
    "00100011111111100101",
    "00101111111111100110",
];

/// A family this generator makes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Family {
    /// A cube inside a cage of bars: the gripper reaches in between two front bars.
    Cage,
    /// A tall four-shelf bookcase with nine cans; grasp a front can.
    BookshelfTall,
    /// A thin bookcase of five shelves split by a middle wall, ten cans; grasp a front can.
    BookshelfThin,
    /// A cluttered table; start with the gripper under the table, grasp the can on top.
    TableUnderPick,
}

impl Family {
    /// Every family, in the order `all` generates them.
    pub const ALL: [Family; 4] = [Family::Cage, Family::BookshelfTall, Family::BookshelfThin, Family::TableUnderPick];

    /// The name `--family` takes.
    pub fn name(self) -> &'static str {
        match self {
            Family::Cage => "cage",
            Family::BookshelfTall => "bookshelf_tall",
            Family::BookshelfThin => "bookshelf_thin",
            Family::TableUnderPick => "table_under_pick",
        }
    }

    /// The folder its problems go in (`<name>_ur5`, as MotionBenchMaker names them).
    pub fn folder(self) -> String {
        format!("{}_ur5", self.name())
    }

    /// The family's template, variation and queries.
    pub fn spec(self) -> &'static FamilySpec {
        match self {
            Family::Cage => &CAGE,
            Family::BookshelfTall => &BOOKSHELF_TALL,
            Family::BookshelfThin => &BOOKSHELF_THIN,
            Family::TableUnderPick => &TABLE_UNDER_PICK,
        }
    }
}

/// The families `--family` names: one of [`Family::ALL`] by name, or `all`.
pub fn parse_families(text: &str) -> Result<Vec<Family>, GenerateError> {
    let text = text.trim();
    if text == "all" {
        return Ok(Family::ALL.to_vec());
    }
    Family::ALL.iter().copied().find(|f| f.name() == text).map(|f| vec![f]).ok_or_else(|| {
        GenerateError::UnknownFamily {
            name: text.to_string(),
            known: Family::ALL.iter().map(|f| f.name()).collect::<Vec<_>>().join(", "),
        }
    })
}

/// A solid of a template object, in the object's frame (`shape_msgs/SolidPrimitive` sizes).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Solid {
    /// Full sizes along x, y, z (m).
    Box([f64; 3]),
    /// Along z: height and radius (m).
    Cylinder {
        /// Height (m).
        height: f64,
        /// Radius (m).
        radius: f64,
    },
}

/// One object of a template scene, posed in [`TEMPLATE_FRAME`] (every MotionBenchMaker template
/// used here has identity orientations).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TemplateObject {
    /// The object's id.
    pub id: &'static str,
    /// Its solid.
    pub solid: Solid,
    /// Its position in the template frame (m).
    pub position: [f64; 3],
}

/// A uniform variation: position components in `[-p, p]` (m), roll, pitch, yaw in `[-r, r]`
/// (rad).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Variation {
    /// Half-ranges of x, y, z.
    pub position: [f64; 3],
    /// Half-ranges of roll, pitch, yaw.
    pub orientation: [f64; 3],
}

/// How a template becomes a scene: MotionBenchMaker's sampler, `W * O * B * P` (see the module
/// documentation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// The problem's `base_offset` translation (m, world frame).
    pub base_offset: [f64; 3],
    /// The `World` variation.
    pub world: Variation,
}

/// A query: the tip link at `offset` from one of `objects`, within tolerances.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Query {
    /// Candidate target objects (one is drawn per scene).
    pub objects: &'static [&'static str],
    /// Offset position in the object's frame (m).
    pub position: [f64; 3],
    /// Offset orientation in the object's frame, `[x, y, z, w]`.
    pub orientation: [f64; 4],
    /// Full sizes of the world-aligned box the tip's position may lie in (m).
    pub position_tolerance: [f64; 3],
    /// Largest rotation about each axis of the target frame (rad).
    pub orientation_tolerance: [f64; 3],
}

impl Query {
    /// The tip's target pose for the object at `object_pose`, with the family's `ee_offset`
    /// (`object_pose * offset * ee_offset^-1`).
    pub fn target(&self, object_pose: &Isometry3<f64>, ee_offset: [f64; 3]) -> Isometry3<f64> {
        let [x, y, z, w] = self.orientation;
        let offset = Isometry3::from_parts(
            Translation3::new(self.position[0], self.position[1], self.position[2]),
            UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z)),
        );
        let ee = Isometry3::translation(ee_offset[0], ee_offset[1], ee_offset[2]);
        object_pose * offset * ee.inverse()
    }

    /// Whether `pose` is within the tolerances of `target` (with `slack` added to each bound):
    /// position per world axis within half the region's size, rotation from the target frame
    /// per axis within the orientation tolerance.
    pub fn accepts(&self, target: &Isometry3<f64>, pose: &Isometry3<f64>, slack: f64) -> bool {
        let dp = pose.translation.vector - target.translation.vector;
        let dr = (target.rotation.inverse() * pose.rotation).scaled_axis();
        (0..3).all(|i| {
            dp[i].abs() <= 0.5 * self.position_tolerance[i] + slack
                && dr[i].abs() <= self.orientation_tolerance[i] + slack
        })
    }
}

/// A family's template, variations and queries (data from MotionBenchMaker's configuration files).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FamilySpec {
    /// The template scene.
    pub objects: &'static [TemplateObject],
    /// How the template is placed in the world.
    pub placement: Placement,
    /// Per-object variations (in the object's frame): the objects and the variation each draws.
    pub object_variations: &'static [(&'static [&'static str], Variation)],
    /// The `ee_offset` position (m; its orientation is the identity in every UR5 problem file).
    pub ee_offset: [f64; 3],
    /// The start query, if the start is not [`UR5_START`].
    pub start_query: Option<Query>,
    /// The goal query.
    pub goal_query: Query,
}

const fn cube(id: &'static str, size: [f64; 3], position: [f64; 3]) -> TemplateObject {
    TemplateObject { id, solid: Solid::Box(size), position }
}

const fn can(id: &'static str, height: f64, radius: f64, position: [f64; 3]) -> TemplateObject {
    TemplateObject { id, solid: Solid::Cylinder { height, radius }, position }
}

/// Pitch of 90 degrees: the tip's x axis (the approach) points down.
const TOP_DOWN: [f64; 4] = [0.0, 0.707, 0.0, 0.707];
const IDENTITY: [f64; 4] = [0.0, 0.0, 0.0, 1.0];
/// `ee_offset` of the box and cage UR5 problems (`configs/problems/cage_ur5.yaml`).
const CAGE_EE_OFFSET: [f64; 3] = [0.035, -0.045, 0.0];

/// `configs/scenes/cage/scene_cage.yaml`, `variation_cage.yaml`, `queries_cage.yaml`,
/// `configs/problems/cage_ur5.yaml`.
static CAGE: FamilySpec = FamilySpec {
    objects: &[
        cube("Cube1", [0.07, 0.07, 0.07], [0.8, 0.0, 0.52]),
        cube("base", [0.7, 0.7, 0.04], [0.8, 0.0, 0.44]),
        cube("side_left", [0.7, 0.04, 0.7], [0.8, -0.35, 0.8]),
        cube("side_right", [0.7, 0.04, 0.7], [0.8, 0.35, 0.8]),
        cube("side_frontB", [0.04, 0.7, 0.04], [0.45, 0.0, 0.9]),
        cube("side_frontA", [0.04, 0.7, 0.04], [0.45, 0.0, 0.6]),
        cube("side_cap", [0.65, 0.65, 0.04], [0.85, 0.0, 1.15]),
        cube("side_back", [0.04, 0.7, 0.7], [1.15, 0.0, 0.8]),
    ],
    placement: Placement {
        base_offset: [0.0, 0.0, -0.8],
        world: Variation { position: [0.1, 0.1, 0.1], orientation: [0.0, 0.0, 0.5] },
    },
    object_variations: &[],
    ee_offset: CAGE_EE_OFFSET,
    start_query: None,
    goal_query: Query {
        objects: &["Cube1"],
        position: [0.0, 0.0, 0.21],
        orientation: TOP_DOWN,
        position_tolerance: [0.05, 0.05, 0.01],
        orientation_tolerance: [0.01, 0.01, 0.01],
    },
};

const SHELF_QUERY_POSITION: [f64; 3] = [-0.2, 0.0, 0.05];

/// `configs/scenes/bookshelf/scene_tall.yaml`, `variation_tall.yaml`, `easy_queries_tall.yaml`,
/// `configs/problems/bookshelf_tall_ur5.yaml`.
static BOOKSHELF_TALL: FamilySpec = FamilySpec {
    objects: &[
        can("Can1", 0.14, 0.03, [0.9, 0.0, 1.38]),
        can("Can2", 0.14, 0.03, [0.7, 0.0, 1.38]),
        can("Can3", 0.14, 0.03, [0.5, 0.0, 1.38]),
        can("Can4", 0.14, 0.03, [0.9, 0.0, 0.78]),
        can("Can5", 0.14, 0.03, [0.7, 0.0, 0.78]),
        can("Can6", 0.14, 0.03, [0.5, 0.0, 0.78]),
        can("Can7", 0.14, 0.03, [0.9, 0.0, 1.08]),
        can("Can8", 0.14, 0.03, [0.7, 0.0, 1.08]),
        can("Can9", 0.14, 0.03, [0.5, 0.0, 1.08]),
        cube("shelf_bottom", [1.2, 1.0, 0.04], [1.0, 0.0, 0.7]),
        cube("shelf_middle_bottom", [1.2, 1.0, 0.04], [1.0, 0.0, 1.0]),
        cube("shelf_middle_top", [1.2, 1.0, 0.04], [1.0, 0.0, 1.3]),
        cube("shelf_top", [1.2, 1.0, 0.04], [1.0, 0.0, 1.6]),
        cube("side_left", [1.3, 0.04, 1.64], [1.0, -0.5, 0.82]),
        cube("side_right", [1.3, 0.04, 1.64], [1.0, 0.5, 0.82]),
    ],
    placement: Placement {
        base_offset: [0.1, 0.1, -0.9144],
        world: Variation { position: [0.1, 0.1, 0.0], orientation: [0.0, 0.0, 1.57] },
    },
    object_variations: &[(
        &["Can1", "Can2", "Can3", "Can4", "Can5", "Can6", "Can7", "Can8", "Can9"],
        Variation { position: [0.0, 0.45, 0.0], orientation: [0.0, 0.0, 0.0] },
    )],
    ee_offset: [0.0, 0.0, 0.0],
    start_query: None,
    goal_query: Query {
        objects: &["Can3", "Can6", "Can9"],
        position: SHELF_QUERY_POSITION,
        orientation: IDENTITY,
        position_tolerance: [0.01, 0.01, 0.01],
        orientation_tolerance: [0.01, 0.01, 0.01],
    },
};

/// `configs/scenes/bookshelf/scene_thin.yaml`, `variation_thin.yaml`, `easy_queries_thin.yaml`,
/// `configs/problems/bookshelf_thin_ur5.yaml`.
static BOOKSHELF_THIN: FamilySpec = FamilySpec {
    objects: &[
        can("Can1", 0.14, 0.03, [1.1, 0.25, 0.44]),
        can("Can2", 0.14, 0.03, [0.8, 0.25, 0.44]),
        can("Can3", 0.14, 0.03, [1.1, -0.25, 0.69]),
        can("Can4", 0.14, 0.03, [0.8, -0.25, 0.69]),
        can("Can5", 0.14, 0.03, [1.1, 0.25, 0.94]),
        can("Can6", 0.14, 0.03, [0.8, 0.25, 0.94]),
        can("Can7", 0.14, 0.03, [1.1, -0.25, 1.19]),
        can("Can8", 0.14, 0.03, [0.8, -0.25, 1.19]),
        can("Can9", 0.14, 0.03, [1.1, 0.25, 1.44]),
        can("Can10", 0.14, 0.03, [0.8, 0.25, 1.44]),
        cube("shelf_bottom", [0.62, 1.0, 0.04], [1.0, 0.0, 0.35]),
        cube("shelf_middle_bottom", [0.62, 1.0, 0.04], [1.0, 0.0, 0.60]),
        cube("shelf_middle", [0.62, 1.0, 0.04], [1.0, 0.0, 0.85]),
        cube("shelf_middle_top", [0.62, 1.0, 0.04], [1.0, 0.0, 1.10]),
        cube("shelf_top", [0.62, 1.0, 0.04], [1.0, 0.0, 1.35]),
        cube("shelf_vert", [0.62, 0.04, 1.4], [1.0, 0.0, 0.9]),
        cube("shelf_top_top", [0.62, 1.0, 0.04], [1.0, 0.0, 1.6]),
        cube("leg_fr", [0.04, 0.04, 1.64], [0.7, 0.5, 0.82]),
        cube("leg_fl", [0.04, 0.04, 1.64], [0.7, -0.5, 0.82]),
        cube("leg_br", [0.04, 0.04, 1.64], [1.3, 0.5, 0.82]),
        cube("leg_bl", [0.04, 0.04, 1.64], [1.3, -0.5, 0.82]),
    ],
    placement: Placement {
        base_offset: [0.0, 0.0, -0.9144],
        world: Variation { position: [0.1, 0.1, 0.0], orientation: [0.0, 0.0, 1.57] },
    },
    object_variations: &[(
        &["Can1", "Can2", "Can3", "Can4", "Can5", "Can6", "Can7", "Can8", "Can9", "Can10"],
        Variation { position: [0.0, 0.2, 0.0], orientation: [0.0, 0.0, 0.0] },
    )],
    ee_offset: [0.0, 0.0, 0.0],
    start_query: None,
    goal_query: Query {
        objects: &["Can2", "Can4", "Can6", "Can8", "Can10"],
        position: SHELF_QUERY_POSITION,
        orientation: IDENTITY,
        position_tolerance: [0.01, 0.01, 0.01],
        orientation_tolerance: [0.01, 0.01, 0.01],
    },
};

/// `configs/scenes/table/scene_table.yaml`, `variation_table.yaml`,
/// `queries_under_pick_table.yaml`, `configs/problems/table_under_pick_ur5.yaml`.
static TABLE_UNDER_PICK: FamilySpec = FamilySpec {
    objects: &[
        can("Can1", 0.12, 0.03, [0.85, 0.0, 0.8]),
        cube("Cube", [0.25, 0.25, 0.25], [0.75, 0.4, 0.85]),
        cube("table_leg_left_back", [0.05, 0.05, 0.7], [1.5, 0.85, 0.35]),
        cube("table_leg_left_front", [0.05, 0.05, 0.7], [0.6, 0.85, 0.35]),
        cube("table_leg_right_back", [0.05, 0.05, 0.7], [1.5, -0.85, 0.35]),
        cube("table_leg_right_front", [0.05, 0.05, 0.7], [0.6, -0.85, 0.35]),
        cube("table_top", [1.2, 2.0, 0.04], [1.05, 0.0, 0.7]),
        can("Object1", 0.35, 0.05, [1.35, 0.0, 0.85]),
        cube("Object2", [0.2, 0.02, 0.4], [1.05, -0.2, 0.9]),
        cube("Object3", [0.02, 0.2, 0.4], [0.65, 0.2, 0.9]),
        cube("Object4", [0.2, 0.05, 0.35], [0.65, -0.2, 0.9]),
        cube("Object5", [0.2, 0.05, 0.35], [1.05, 0.2, 0.9]),
    ],
    placement: Placement {
        base_offset: [0.0, 0.0, -0.45],
        world: Variation { position: [0.1, 0.1, 0.1], orientation: [0.0, 0.0, 1.57] },
    },
    object_variations: &[
        (&["Can1"], Variation { position: [0.05, 0.05, 0.0], orientation: [0.0, 0.0, 0.0] }),
        (
            &["Object1", "Object2", "Object3", "Object4", "Object5", "Cube"],
            Variation { position: [0.1, 0.1, 0.0], orientation: [0.0, 0.0, 1.57] },
        ),
    ],
    ee_offset: [0.0, 0.0, 0.0],
    start_query: Some(Query {
        objects: &["table_top"],
        position: [-0.5, 0.0, -0.3],
        orientation: IDENTITY,
        position_tolerance: [0.0001, 0.0001, 0.0001],
        orientation_tolerance: [0.003, 0.003, 0.003],
    }),
    goal_query: Query {
        objects: &["Can1"],
        position: [-0.2, 0.0, 0.025],
        orientation: IDENTITY,
        position_tolerance: [0.0001, 0.0001, 0.0001],
        orientation_tolerance: [0.003, 0.003, 0.003],
    },
};

/// What can go wrong generating problems.
#[derive(Debug, thiserror::Error)]
pub enum GenerateError {
    /// `--family` names no family.
    #[error("unknown family `{name}`; expected one of {known}, or all")]
    UnknownFamily {
        /// The name given.
        name: String,
        /// The names known.
        known: String,
    },
    /// `--count` is 0.
    #[error("--count must be at least 1")]
    ZeroCount,
    /// `--count` does not fit the four-digit file names.
    #[error("--count must be at most 9999 (files are numbered sceneNNNN.yaml), got {0}")]
    CountTooLarge(usize),
    /// The output folder or a file in it cannot be written.
    #[error("cannot write {}: {source}", path.display())]
    Write {
        /// The folder or file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The robot does not have what the problems need (a link, the group's joints).
    #[error("the robot does not fit the UR5 problems: {0}")]
    Robot(String),
    /// The robot or its SRDF could not be read.
    #[error(transparent)]
    Load(#[from] Box<SystemError>),
    /// A robot-model call failed.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// No valid problem was found within the bounded number of attempts.
    #[error(
        "could not generate {family} problem {index}: no collision-free {what} within the joint limits in {scenes} sampled scenes ({ik_calls} IK calls each)"
    )]
    Exhausted {
        /// The family.
        family: &'static str,
        /// The problem's index (from 1).
        index: usize,
        /// `start` or `goal`.
        what: &'static str,
        /// Scenes sampled.
        scenes: usize,
        /// IK calls per scene.
        ik_calls: usize,
    },
}

impl From<GenerateError> for SystemError {
    fn from(e: GenerateError) -> Self {
        match e {
            GenerateError::Write { path, source } => SystemError::Write { file: path, source },
            GenerateError::Load(e) => *e,
            GenerateError::Model(e) => SystemError::Model(e),
            GenerateError::Exhausted { .. } => SystemError::Failed(e.to_string()),
            other => SystemError::Usage(other.to_string()),
        }
    }
}

/// What `embodied bench mbm-generate` is asked to do.
#[derive(Debug, Clone)]
pub struct GenerateArgs {
    /// The robot (the spherized UR5).
    pub urdf: PathBuf,
    /// Its SRDF.
    pub srdf: PathBuf,
    /// The families to generate.
    pub families: Vec<Family>,
    /// Problems per family.
    pub count: usize,
    /// Base seed.
    pub seed: u64,
    /// Folder to write `<family>_ur5/sceneNNNN.yaml` and `requestNNNN.yaml` into.
    pub out: PathBuf,
}

/// What generating one family took.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct FamilyOutcome {
    /// The family's folder name.
    pub family: String,
    /// Where its files went.
    pub folder: PathBuf,
    /// Problems written.
    pub problems: usize,
    /// Scenes sampled in all (one per problem when every first scene worked).
    pub scenes_sampled: usize,
    /// Inverse-kinematics calls in all.
    pub ik_calls: usize,
}

/// One generated problem, before it is written.
struct Problem {
    objects: Vec<(TemplateObject, Isometry3<f64>)>,
    start: Vec<f64>,
    goal: Vec<f64>,
}

/// The arm and what a problem's checks need, made once.
struct Setup {
    /// The planning arm (group joints only) with the scene's allowed pairs applied.
    arm: Robot,
    /// The same arm with an end effector at [`TIP_LINK`].
    ik_arm: Robot,
    /// The end effector's index in `ik_arm`.
    tip: usize,
    /// World pose of [`TEMPLATE_FRAME`].
    template_frame: Isometry3<f64>,
}

fn setup(args: &GenerateArgs) -> Result<Setup, GenerateError> {
    let loaded = load_robot(&MbmArgs::new(&args.urdf, &args.srdf, &args.out)).map_err(Box::new)?;
    let here = Path::new("<generated>");
    let scene = parse_scene(&scene_yaml(&[]), here).map_err(|e| GenerateError::Robot(e.to_string()))?;
    let request =
        parse_request(&request_yaml(&UR5_START, &UR5_START), here).map_err(|e| GenerateError::Robot(e.to_string()))?;
    let mut robot = loaded.robot.clone();
    scene.apply_allowed_collisions(&mut robot);
    let resolved = request
        .resolve(&robot, &loaded.srdf, scene.robot_state.as_ref())
        .map_err(|e| GenerateError::Robot(e.to_string()))?;
    if resolved.joint_names.iter().map(String::as_str).ne(JOINT_NAMES[..6].iter().copied()) {
        return Err(GenerateError::Robot(format!(
            "the `manipulator` group's joints are {:?}, expected the six UR5 arm joints",
            resolved.joint_names
        )));
    }
    let arm = resolved.planning_robot(&robot)?;
    let (ik_arm, tip) = arm.with_end_effector("mbm_tip", TIP_LINK, Isometry3::identity())?;
    let frame =
        arm.link_index(TEMPLATE_FRAME).ok_or_else(|| GenerateError::Robot(format!("no link `{TEMPLATE_FRAME}`")))?;
    let template_frame = arm.link_pose(&UR5_START, frame);
    Ok(Setup { arm, ik_arm, tip, template_frame })
}

fn sample_variation(v: &Variation, rng: &mut Rng) -> Isometry3<f64> {
    let mut draw = |half: f64| if half > 0.0 { rng.range(-half, half) } else { 0.0 };
    let (x, y, z) = (draw(v.position[0]), draw(v.position[1]), draw(v.position[2]));
    let (roll, pitch, yaw) = (draw(v.orientation[0]), draw(v.orientation[1]), draw(v.orientation[2]));
    Isometry3::from_parts(Translation3::new(x, y, z), UnitQuaternion::from_euler_angles(roll, pitch, yaw))
}

/// One scene of `spec`: every template object with its world pose.
fn sample_scene(
    spec: &FamilySpec,
    template_frame: &Isometry3<f64>,
    rng: &mut Rng,
) -> Vec<(TemplateObject, Isometry3<f64>)> {
    let Placement { base_offset, world } = spec.placement;
    let w = sample_variation(&world, rng);
    let o = Isometry3::translation(base_offset[0], base_offset[1], base_offset[2]);
    let whole = w * o * template_frame;
    let mut objects: Vec<(TemplateObject, Isometry3<f64>)> = spec
        .objects
        .iter()
        .map(|t| (*t, whole * Isometry3::translation(t.position[0], t.position[1], t.position[2])))
        .collect();
    for (names, variation) in spec.object_variations {
        for name in names.iter() {
            if let Some((_, pose)) = objects.iter_mut().find(|(t, _)| t.id == *name) {
                *pose *= sample_variation(variation, rng);
            }
        }
    }
    objects
}

/// A pose drawn within 90% of `query`'s tolerances about `target`.
fn sample_within(query: &Query, target: &Isometry3<f64>, rng: &mut Rng) -> Isometry3<f64> {
    let mut d = [0.0; 3];
    let mut r = [0.0; 3];
    for i in 0..3 {
        let half = 0.45 * query.position_tolerance[i];
        d[i] = if half > 0.0 { rng.range(-half, half) } else { 0.0 };
        let tol = 0.9 * query.orientation_tolerance[i];
        r[i] = if tol > 0.0 { rng.range(-tol, tol) } else { 0.0 };
    }
    let rotation = target.rotation * UnitQuaternion::from_scaled_axis(Vector3::new(r[0], r[1], r[2]));
    let translation = target.translation.vector + Vector3::new(d[0], d[1], d[2]);
    Isometry3::from_parts(Translation3::from(translation), rotation)
}

/// The pedestal MotionBenchMaker's UR5 stands on: `box_link` of robowflex_resources'
/// `ur/robots/ur5_robotiq_robot_limited_small_table.urdf.xacro`, a 0.4 x 0.4 x 0.9144 m box
/// centred 0.4572 m above the world origin, under `base_link` (at 0.9144 m, turned by 1.57 rad:
/// the same mounting as the spherized URDF's `offset_joint`). The spherized model and the public
/// scenes leave it out, but MotionBenchMaker's validity checks had it: problems whose start or goal
/// puts the arm into it are not MotionBenchMaker problems. Its lower and upper corners (m).
pub const PEDESTAL: ([f64; 3], [f64; 3]) = ([-0.2, -0.2, 0.0], [0.2, 0.2, 0.9144]);
/// The pedestal's link name in the allowed collision matrix.
const PEDESTAL_LINK: &str = "box_link";

/// The links the allowed collision matrix lets touch the pedestal (`base_link`, `shoulder_link`).
fn pedestal_allowed() -> Vec<&'static str> {
    let Some(row) = ACM_NAMES.iter().position(|n| *n == PEDESTAL_LINK) else { return Vec::new() };
    ACM_ROWS[row].bytes().zip(ACM_NAMES).filter(|(b, _)| *b == b'1').map(|(_, n)| n).collect()
}

/// Whether a sphere of the arm (other than the links allowed to touch it) overlaps the pedestal.
/// Only spheres are checked (the spherized UR5 has no other collision shapes).
pub fn touches_pedestal(model: &CollisionModel, q: &[f64]) -> bool {
    pedestal_contact(model, q, None)
}

/// [`touches_pedestal`], for the link `only` alone when given.
fn pedestal_contact(model: &CollisionModel, q: &[f64], only: Option<&str>) -> bool {
    let allowed = pedestal_allowed();
    let (lo, hi) = PEDESTAL;
    model.link_shapes_world(q).iter().any(|o| {
        let link = o.name.split('#').next().unwrap_or_default();
        let Shape::Sphere { radius } = o.shape else { return false };
        if allowed.contains(&link) || only.is_some_and(|l| l != link) {
            return false;
        }
        let c = o.pose.translation.vector;
        let d2: f64 = (0..3).map(|i| (lo[i] - c[i]).max(0.0).max(c[i] - hi[i]).powi(2)).sum();
        d2 < radius * radius
    })
}

/// Within the limits, free of collision in the scene (as `bench mbm` checks) and clear of the
/// pedestal.
fn valid(model: &CollisionModel, q: &[f64]) -> bool {
    model.robot().within_limits(q) && model.first_collision(q).is_none() && !touches_pedestal(model, q)
}

/// Index of `shoulder_lift_joint` in the arm's configuration, and the link it swings.
const LIFT: usize = 1;
const UPPER_ARM: &str = "upper_arm_link";
/// Steps of the shoulder lift checked between a start and a goal.
const LIFT_STEPS: usize = 64;

/// Whether the shoulder lift can turn from `from` to `to` without swinging the upper arm through
/// the pedestal (checked every 1/[`LIFT_STEPS`] of the way, at `to`'s other joint values; the
/// upper arm's place depends only on the pan and the lift). The lift's limits are +-pi, not a
/// continuous joint: a goal at lift +3.1 is not reached from the start's -1.57 the short way
/// round, and the long way (lift through 0 to +pi) points the upper arm down through the
/// pedestal. The public goals never have such a lift (all 300 at most 0.17); ours did, and no
/// planner found a path to them.
pub fn lift_passes_pedestal(model: &CollisionModel, from: &[f64], to: &[f64]) -> bool {
    let mut q = to.to_vec();
    (0..=LIFT_STEPS).any(|k| {
        q[LIFT] = from[LIFT] + (to[LIFT] - from[LIFT]) * k as f64 / LIFT_STEPS as f64;
        pedestal_contact(model, &q, Some(UPPER_ARM))
    })
}

/// The target pose of `query` on one of its objects (drawn) in the sampled scene.
fn query_target(
    spec: &FamilySpec,
    query: &Query,
    objects: &[(TemplateObject, Isometry3<f64>)],
    rng: &mut Rng,
) -> Result<Isometry3<f64>, GenerateError> {
    let name = query.objects[rng.below(query.objects.len())];
    let Some((_, object_pose)) = objects.iter().find(|(t, _)| t.id == name) else {
        return Err(GenerateError::Robot(format!("the template has no object `{name}`")));
    };
    Ok(query.target(object_pose, spec.ee_offset))
}

/// A configuration placing the tip within `query`'s tolerances of `target`, within the limits,
/// free of collision and (from `reach_from`) not behind the pedestal, from at most
/// [`IK_CALLS_PER_SCENE`] calls; `None` when none is found. Counts the calls in `calls`.
fn solve_query(
    setup: &Setup,
    query: &Query,
    target: &Isometry3<f64>,
    model: &CollisionModel,
    reach_from: Option<&[f64]>,
    rng: &mut Rng,
    calls: &mut usize,
) -> Result<Option<Vec<f64>>, GenerateError> {
    for _ in 0..IK_CALLS_PER_SCENE {
        *calls += 1;
        let pose = sample_within(query, target, rng);
        let seed = setup.ik_arm.random_configuration(rng);
        let options =
            IkOptions { restarts: IK_RESTARTS, seed: rng.next_u64(), closed_form: false, ..IkOptions::default() };
        match setup.ik_arm.inverse_kinematics(setup.tip, &pose, &seed, &options) {
            Ok(q) if valid(model, &q) && reach_from.is_none_or(|from| !lift_passes_pedestal(model, from, &q)) => {
                return Ok(Some(q));
            }
            Ok(_) | Err(ModelError::IkFailed { .. }) => {}
            Err(e) => return Err(e.into()),
        }
    }
    Ok(None)
}

/// The generator of problem `index` of `family`: the same for a seed whatever else is generated.
fn problem_rng(seed: u64, family: Family, index: usize) -> Rng {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in family.name().bytes() {
        h = (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
    }
    Rng::new(seed ^ h ^ (index as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15))
}

fn environment_of(objects: &[(TemplateObject, Isometry3<f64>)]) -> Result<PlanningScene, GenerateError> {
    parse_scene(&scene_yaml(objects), Path::new("<generated>")).map_err(|e| GenerateError::Robot(e.to_string()))
}

fn generate_problem(
    setup: &Setup,
    family: Family,
    index: usize,
    seed: u64,
    outcome: &mut FamilyOutcome,
) -> Result<Problem, GenerateError> {
    let spec = family.spec();
    let mut rng = problem_rng(seed, family, index);
    let mut failed_on = "goal";
    for _ in 0..SCENES_PER_PROBLEM {
        outcome.scenes_sampled += 1;
        let objects = sample_scene(spec, &setup.template_frame, &mut rng);
        // The collision environment as `bench mbm` reads it: through the scene file's parser.
        let model = CollisionModel::new(&setup.arm, environment_of(&objects)?.environment());
        let start = match &spec.start_query {
            None if valid(&model, &UR5_START) => UR5_START.to_vec(),
            None => {
                failed_on = "start";
                continue;
            }
            Some(query) => {
                let target = query_target(spec, query, &objects, &mut rng)?;
                match solve_query(setup, query, &target, &model, None, &mut rng, &mut outcome.ik_calls)? {
                    Some(q) => q,
                    None => {
                        failed_on = "start";
                        continue;
                    }
                }
            }
        };
        let goal_query = &spec.goal_query;
        let target = query_target(spec, goal_query, &objects, &mut rng)?;
        let from = Some(start.as_slice());
        if let Some(goal) = solve_query(setup, goal_query, &target, &model, from, &mut rng, &mut outcome.ik_calls)? {
            return Ok(Problem { objects, start, goal });
        }
        failed_on = "goal";
    }
    Err(GenerateError::Exhausted {
        family: family.name(),
        index,
        what: failed_on,
        scenes: SCENES_PER_PROBLEM,
        ik_calls: IK_CALLS_PER_SCENE,
    })
}

/// Generate `args.count` problems of each of `args.families` into `args.out/<family>_ur5/`.
/// `on_progress(family, done, total)` is called before the first problem of a family and after
/// each. Files of an earlier run with an index above `count` are removed from the family folder,
/// so that the folder holds exactly this run's problems.
pub fn generate_mbm(
    args: &GenerateArgs,
    on_progress: &mut dyn FnMut(Family, usize, usize),
) -> Result<Vec<FamilyOutcome>, GenerateError> {
    if args.count == 0 {
        return Err(GenerateError::ZeroCount);
    }
    if args.count > 9999 {
        return Err(GenerateError::CountTooLarge(args.count));
    }
    if args.families.is_empty() {
        return Err(GenerateError::UnknownFamily {
            name: String::new(),
            known: Family::ALL.iter().map(|f| f.name()).collect::<Vec<_>>().join(", "),
        });
    }
    // Refuse an unwritable output before the (slow) robot set-up.
    std::fs::create_dir_all(&args.out).map_err(|source| GenerateError::Write { path: args.out.clone(), source })?;
    let setup = setup(args)?;
    let mut seen = HashSet::new();
    let mut outcomes = Vec::new();
    for &family in args.families.iter().filter(|f| seen.insert(**f)) {
        let folder = args.out.join(family.folder());
        std::fs::create_dir_all(&folder).map_err(|source| GenerateError::Write { path: folder.clone(), source })?;
        remove_stale(&folder, args.count)?;
        let mut outcome = FamilyOutcome {
            family: family.folder(),
            folder: folder.clone(),
            problems: 0,
            scenes_sampled: 0,
            ik_calls: 0,
        };
        on_progress(family, 0, args.count);
        for index in 1..=args.count {
            let problem = generate_problem(&setup, family, index, args.seed, &mut outcome)?;
            write_file(&folder.join(format!("scene{index:04}.yaml")), &scene_yaml(&problem.objects))?;
            write_file(&folder.join(format!("request{index:04}.yaml")), &request_yaml(&problem.start, &problem.goal))?;
            outcome.problems += 1;
            on_progress(family, index, args.count);
        }
        outcomes.push(outcome);
    }
    Ok(outcomes)
}

fn write_file(path: &Path, text: &str) -> Result<(), GenerateError> {
    std::fs::write(path, text).map_err(|source| GenerateError::Write { path: path.to_path_buf(), source })
}

/// Remove `sceneNNNN.yaml` / `requestNNNN.yaml` with NNNN above `count` (an earlier, larger run).
fn remove_stale(folder: &Path, count: usize) -> Result<(), GenerateError> {
    let entries =
        std::fs::read_dir(folder).map_err(|source| GenerateError::Write { path: folder.to_path_buf(), source })?;
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        let digits =
            name.strip_suffix(".yaml").and_then(|n| n.strip_prefix("scene").or_else(|| n.strip_prefix("request")));
        let stale = digits
            .filter(|d| !d.is_empty() && d.bytes().all(|b| b.is_ascii_digit()))
            .and_then(|d| d.parse::<usize>().ok())
            .is_some_and(|i| i > count);
        if stale {
            let path = entry.path();
            std::fs::remove_file(&path).map_err(|source| GenerateError::Write { path, source })?;
        }
    }
    Ok(())
}

/// A number as YAML (shortest text that reads back to the same `f64`).
fn num(v: f64) -> String {
    if v == 0.0 { "0".to_string() } else { format!("{v}") }
}

fn list(values: impl IntoIterator<Item = f64>) -> String {
    let items: Vec<String> = values.into_iter().map(num).collect();
    format!("[{}]", items.join(", "))
}

/// A planning scene in the layout of the public MotionBenchMaker UR5 scenes.
fn scene_yaml(objects: &[(TemplateObject, Isometry3<f64>)]) -> String {
    let mut s = String::new();
    s.push_str("fixed_frame_transforms:\n  - transform:\n      rotation: [0, 0, 0, 1]\n      translation: [0, 0, 0]\n    child_frame_id: world\n");
    s.push_str("robot_model_name: ur5_robotiq85\nrobot_state:\n  joint_state:\n");
    let _ = writeln!(s, "    position: {}", list([0.0; 12]));
    let _ = writeln!(s, "    name: [{}]", JOINT_NAMES.join(", "));
    s.push_str("name: \"\"\nallowed_collision_matrix:\n");
    let _ = writeln!(s, "  entry_names: [{}]", ACM_NAMES.join(", "));
    s.push_str("  entry_values:\n");
    for row in ACM_ROWS {
        let cells: Vec<&str> = row.bytes().map(|b| if b == b'1' { "true" } else { "false" }).collect();
        let _ = writeln!(s, "    - [{}]", cells.join(", "));
    }
    s.push_str("world:\n  collision_objects:");
    if objects.is_empty() {
        s.push_str(" []\n");
        return s;
    }
    s.push('\n');
    for (t, pose) in objects {
        let _ = writeln!(s, "    - id: {}\n      primitives:", t.id);
        match t.solid {
            Solid::Box(size) => {
                let _ = writeln!(s, "        - type: box\n          dimensions: {}", list(size));
            }
            Solid::Cylinder { height, radius } => {
                let _ = writeln!(s, "        - type: cylinder\n          dimensions: {}", list([height, radius]));
            }
        }
        let p = pose.translation.vector;
        let q = pose.rotation.quaternion();
        let _ = writeln!(
            s,
            "      primitive_poses:\n        - position: {}\n          orientation: {}",
            list([p.x, p.y, p.z]),
            list([q.i, q.j, q.k, q.w])
        );
    }
    s
}

/// A motion plan request in the layout of the public MotionBenchMaker UR5 requests: the
/// `manipulator` group from `start` (arm joints; gripper joints 0) to the joint goal `goal`.
fn request_yaml(start: &[f64], goal: &[f64]) -> String {
    let mut s = String::from("goal_constraints:\n  - joint_constraints:\n");
    for (name, v) in JOINT_NAMES.iter().zip(goal) {
        let _ = writeln!(s, "      - joint_name: {name}\n        position: {}", num(*v));
    }
    s.push_str("group_name: manipulator\nmax_acceleration_scaling_factor: 0\nallowed_planning_time: 60\n");
    let full: Vec<f64> = start.iter().copied().chain(std::iter::repeat(0.0)).take(JOINT_NAMES.len()).collect();
    let _ = writeln!(s, "start_state:\n  joint_state:\n    position: {}", list(full));
    let _ = writeln!(s, "    name: [{}]", JOINT_NAMES.join(", "));
    s.push_str("num_planning_attempts: 2\nplanner_id: BKPIECEGood\nmax_velocity_scaling_factor: 0\n");
    s.push_str(
        "workspace_parameters:\n  header:\n    frame_id: \"\"\n  max_corner: [1, 1, 1]\n  min_corner: [-1, -1, -1]\n",
    );
    s
}
