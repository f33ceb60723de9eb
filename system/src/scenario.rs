//! Scenario files (TOML): robots as agents, their placement, obstacles, start, goals, planner
//! and run settings. Built-in scenarios live in `scenarios/` and are embedded in the binary.
//!
//! Every error names the file, the line and column, and what was expected.

use std::ops::Range;
use std::path::{Path, PathBuf};

use embodied_models::collision::{Environment, Obstacle};
use embodied_models::formats::mesh::read_mesh;
use embodied_models::formats::moveit::{MoveitError, load_scene};
use embodied_models::nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use embodied_models::{ConvexHull, Robot, Shape};
use serde::Deserialize;
use toml::Spanned;

use crate::SystemError;
use crate::faults::{FaultKind, FaultSpec, FaultTrigger};

/// The scenarios embedded in the binary: (name, TOML text).
pub const BUILTIN_SCENARIOS: &[(&str, &str)] = &[
    ("polycrank-transfer", include_str!("../scenarios/polycrank-transfer.toml")),
    ("irp6-pick", include_str!("../scenarios/irp6-pick.toml")),
    ("two-irp6-cell", include_str!("../scenarios/two-irp6-cell.toml")),
    ("rnt-polish", include_str!("../scenarios/rnt-polish.toml")),
    ("rnt-polish-raster", include_str!("../scenarios/rnt-polish-raster.toml")),
    ("polycrank-intruder", include_str!("../scenarios/polycrank-intruder.toml")),
    ("irp6-late-plan", include_str!("../scenarios/irp6-late-plan.toml")),
    ("two-irp6-together", include_str!("../scenarios/two-irp6-together.toml")),
    ("two-irp6-carry", include_str!("../scenarios/two-irp6-carry.toml")),
    ("two-irp6-stack", include_str!("../scenarios/two-irp6-stack.toml")),
    ("polycrank-sort", include_str!("../scenarios/polycrank-sort.toml")),
    ("rnt-faults", include_str!("../scenarios/rnt-faults.toml")),
    ("rnt-motion-faults", include_str!("../scenarios/rnt-motion-faults.toml")),
    ("two-irp6-link-faults", include_str!("../scenarios/two-irp6-link-faults.toml")),
    ("two-irp6-carry-qp-fault", include_str!("../scenarios/two-irp6-carry-qp-fault.toml")),
];

/// The scenario `embodied run` uses when given none.
pub const DEFAULT_SCENARIO: &str = "two-irp6-carry";

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScenario {
    name: String,
    description: String,
    #[serde(default)]
    seed: Option<u64>,
    #[serde(default)]
    agents: Vec<Spanned<RawAgent>>,
    #[serde(default)]
    obstacles: Vec<Spanned<RawObstacle>>,
    #[serde(default)]
    moveit_scene: Option<Spanned<RawMoveitScene>>,
    #[serde(default)]
    planner: RawPlanner,
    #[serde(default)]
    run: RawRun,
    #[serde(default)]
    carry: Option<Spanned<RawCarry>>,
    #[serde(default)]
    task: Option<Spanned<RawTask>>,
    #[serde(default)]
    polish: Option<Spanned<RawPolish>>,
    #[serde(default)]
    faults: Vec<Spanned<RawFault>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPolish {
    agent: Spanned<String>,
    workpiece: Spanned<String>,
    #[serde(default)]
    force_n: Option<Spanned<f64>>,
    #[serde(default)]
    band_n: Option<Spanned<f64>>,
    #[serde(default)]
    tool_radius: Option<Spanned<f64>>,
    #[serde(default)]
    speed: Option<Spanned<f64>>,
    #[serde(default)]
    skin_mm: Option<Spanned<f64>>,
}

/// One `[[faults]]` table: `kind`, exactly one of `at` (s) and `probability` (per step or
/// request), optional `agent`, `duration` (s) and `seed`; link faults `link`, `loss`, `delay`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFault {
    kind: Spanned<String>,
    #[serde(default)]
    agent: Option<Spanned<String>>,
    #[serde(default)]
    at: Option<f64>,
    #[serde(default)]
    probability: Option<f64>,
    #[serde(default)]
    duration: Option<f64>,
    #[serde(default)]
    seed: Option<u64>,
    #[serde(default)]
    link: Option<Spanned<String>>,
    #[serde(default)]
    loss: Option<f64>,
    #[serde(default)]
    delay: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTask {
    arms: Spanned<Vec<String>>,
    #[serde(default)]
    part_size: Option<Spanned<f64>>,
    #[serde(default)]
    clearance: Option<Spanned<f64>>,
    #[serde(default)]
    handling_s: Option<Spanned<f64>>,
    #[serde(default)]
    deadline_ms: Option<Spanned<f64>>,
    #[serde(default)]
    give_up_ms: Option<Spanned<f64>>,
    #[serde(default)]
    simulated_us_per_expansion: Option<Spanned<f64>>,
    stands: Vec<Spanned<RawStand>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawStand {
    name: String,
    xyz: [f64; 3],
    size: [f64; 3],
    #[serde(default)]
    start: Vec<String>,
    #[serde(default)]
    goal: Vec<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCarry {
    agent: Spanned<String>,
    object: String,
    size: Spanned<[f64; 3]>,
    start_xyz: [f64; 3],
    goal_xyz: [f64; 3],
    #[serde(default)]
    rpy: Option<[f64; 3]>,
    #[serde(default)]
    end_effectors: Option<Spanned<[String; 2]>>,
    #[serde(default)]
    grasp_roll: Option<[f64; 2]>,
    #[serde(default)]
    lattice_step: Option<Spanned<f64>>,
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawRun {
    #[serde(default)]
    duration: Option<Spanned<f64>>,
    #[serde(default)]
    coordination: Option<Spanned<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAgent {
    name: String,
    #[serde(default)]
    robot: Option<Spanned<String>>,
    #[serde(default)]
    urdf: Option<Spanned<String>>,
    #[serde(default)]
    srdf: Option<String>,
    #[serde(default)]
    xyz: Option<[f64; 3]>,
    #[serde(default)]
    rpy: Option<[f64; 3]>,
    #[serde(default)]
    start: Option<Spanned<Vec<f64>>>,
    #[serde(default)]
    goal: Option<Spanned<Vec<f64>>>,
    #[serde(default)]
    goals: Option<Spanned<Vec<Vec<f64>>>>,
    #[serde(default)]
    goal_pose: Option<Spanned<RawPose>>,
    #[serde(default)]
    behaviour: Option<BehaviourSpec>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPose {
    #[serde(default)]
    end_effector: Option<String>,
    xyz: [f64; 3],
    #[serde(default)]
    rpy: Option<[f64; 3]>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawObstacle {
    name: String,
    #[serde(rename = "box", default)]
    cuboid: Option<[f64; 3]>,
    #[serde(default)]
    sphere: Option<f64>,
    #[serde(default)]
    cylinder: Option<RawRadiusLength>,
    #[serde(default)]
    capsule: Option<RawRadiusLength>,
    #[serde(default)]
    mesh: Option<String>,
    #[serde(default)]
    scale: Option<f64>,
    xyz: [f64; 3],
    #[serde(default)]
    rpy: Option<[f64; 3]>,
    /// Time (s) at which the obstacle appears in a run (absent: present from the start).
    #[serde(default, alias = "appears_at")]
    appear_at: Option<Spanned<f64>>,
    /// Velocity (m/s) with which the obstacle moves in a run.
    #[serde(default)]
    velocity: Option<[f64; 3]>,
}

/// `[moveit_scene]`: a MoveIt planning scene whose collision objects are obstacles on the map.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMoveitScene {
    /// The scene file (YAML), relative to the scenario's folder.
    file: String,
    /// Where the scene's frame stands in the world (default: the world origin).
    #[serde(default)]
    xyz: Option<[f64; 3]>,
    #[serde(default)]
    rpy: Option<[f64; 3]>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRadiusLength {
    radius: f64,
    length: f64,
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawPlanner {
    #[serde(default)]
    deadline_ms: Option<f64>,
    #[serde(default)]
    seed: Option<u64>,
    #[serde(default)]
    resolution: Option<f64>,
    #[serde(default)]
    edge_check: Option<Spanned<String>>,
    #[serde(default)]
    expansions: Option<usize>,
    #[serde(default)]
    give_up_ms: Option<Spanned<f64>>,
    #[serde(default)]
    clock: Option<Spanned<String>>,
    #[serde(default)]
    simulated_us_per_check: Option<Spanned<f64>>,
}

/// What an agent should reach.
#[derive(Debug, Clone)]
pub enum GoalSpec {
    /// This configuration.
    Configuration(Vec<f64>),
    /// Any one of these configurations.
    AnyOf(Vec<Vec<f64>>),
    /// End effector `end_effector` at `pose` (world frame).
    ToolPose {
        /// Index of the end effector.
        end_effector: usize,
        /// The tool pose.
        pose: Isometry3<f64>,
    },
}

/// One robot of the scenario, as an agent.
#[derive(Debug, Clone)]
pub struct AgentSpec {
    /// Unique name in the scenario.
    pub name: String,
    /// The robot, placed in the world (its base pose).
    pub robot: Robot,
    /// Start configuration.
    pub start: Vec<f64>,
    /// What it should reach (`None`: it holds where it stands, or the carry drives it).
    pub goal: Option<GoalSpec>,
    /// The agent's behaviour settings.
    pub behaviour: BehaviourSpec,
}

/// An agent's behaviour settings (`[agents.behaviour]`).
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BehaviourSpec {
    /// Contact force (N) above which the force-limited reaction stops the arm and abandons
    /// the task (the reaction has priority over the plan follower).
    #[serde(default)]
    pub force_limit: Option<f64>,
}

/// An obstacle with its run-time script.
#[derive(Debug, Clone)]
pub struct ObstacleSpec {
    /// Its name, shape and pose at time zero.
    pub obstacle: Obstacle,
    /// Time (s) at which the obstacle appears during a run; `None`: there from the start, and
    /// on every agent's map.
    pub appear_at: Option<f64>,
    /// Velocity (m/s) with which it moves during a run.
    pub velocity: Option<Vector3<f64>>,
}

/// How `embodied run` counts planning time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ClockSpec {
    /// Wall clock: real planning time (runs are paced to real time while a plan is computed).
    Wall,
    /// Simulated: `us_per_check` microseconds per collision check the planner makes; runs are
    /// reproducible bit for bit.
    Simulated {
        /// Simulated planning time per collision check, µs.
        us_per_check: f64,
    },
}

/// Simulated planning time per collision check when a scenario does not say, µs.
pub const DEFAULT_US_PER_CHECK: f64 = 2.0;

/// Planner settings of a scenario.
#[derive(Debug, Clone)]
pub struct PlannerSpec {
    /// `embodied plan`: the search's deadline. `embodied run`: when the plan is needed (a plan
    /// not there by then means a safe halt until it lands).
    pub deadline_ms: f64,
    /// `embodied run`: when the search gives up (at least `deadline_ms`).
    pub give_up_ms: f64,
    /// The planner's seed.
    pub seed: u64,
    /// Segments certified free for the whole continuum (default), or sampled at `resolution`.
    pub certify: bool,
    /// Largest joint step between sampled checks (sampled edges; also the gate's sampling).
    pub resolution: f64,
    /// A deadline in expansions instead of time (reproducible plans).
    pub expansions: Option<usize>,
    /// `embodied run`: how planning time is counted.
    pub clock: ClockSpec,
}

/// How the agents of a multi-agent run are coordinated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Coordination {
    /// One after the other: each plans when the one before has finished, around where it stands.
    Sequential,
    /// All at once: each plans around the space the agents before it will sweep (as the
    /// coordinator hands on their plans) and starts as soon as its plan lands.
    Concurrent,
}

/// Run settings of a scenario.
#[derive(Debug, Clone)]
pub struct RunSpec {
    /// Simulated seconds to run (`None`: 6 s).
    pub duration: Option<f64>,
    /// How a coordinator grants the agents' motions.
    pub coordination: Coordination,
}

/// A two-handed carry (`[carry]`): agent `agent` (a robot with two end effectors) grasps a box
/// at both ends of its x axis, carries it from `object_start` to `object_goal` and puts it down.
#[derive(Debug, Clone)]
pub struct CarrySpec {
    /// Index of the carrying agent.
    pub agent: usize,
    /// The object's name.
    pub object: String,
    /// Full box sizes, m.
    pub size: [f64; 3],
    /// Where the object stands at the start.
    pub object_start: Isometry3<f64>,
    /// Where it should be put down.
    pub object_goal: Isometry3<f64>,
    /// `[holder, other]` end-effector indices.
    pub end_effectors: [usize; 2],
    /// Tool frames in the object frame: the tools approach the object's end faces along its x
    /// axis, turned by `grasp_roll` about their approach axes.
    pub grasps: [Isometry3<f64>; 2],
    /// Step of the object-pose lattice the carry's A* searches, m.
    pub lattice_step: f64,
}

/// A polishing job (`[polish]`): agent `agent` covers the top face of the box obstacle
/// `workpiece` with a boustrophedon raster, tool normal to the face, pressing with a regulated
/// force (see `embodied_system::polish`).
#[derive(Debug, Clone, PartialEq)]
pub struct PolishSpec {
    /// Index of the polishing agent.
    pub agent: usize,
    /// Index of the workpiece among the scenario's obstacles (an axis-aligned box).
    pub workpiece: usize,
    /// Contact force setpoint along the face's normal, N.
    pub force_n: f64,
    /// Half-width of the band around the setpoint that counts as regulated, N.
    pub band_n: f64,
    /// Radius of the polishing pad, m (passes are at most 1.8 radii apart).
    pub tool_radius: f64,
    /// Tool speed along the passes, m/s.
    pub speed: f64,
    /// Free thickness of the compliant pad, m (the tool point rides this far above the face at
    /// zero force).
    pub skin: f64,
}

/// A stand of a stacking task (`[[task.stands]]`): a box whose top face is centred at `top`,
/// with a stack of parts on it.
#[derive(Debug, Clone, PartialEq)]
pub struct StandSpec {
    /// Its name (the obstacle is `stand_<name>`).
    pub name: String,
    /// Centre of its top face, m (world frame).
    pub top: [f64; 3],
    /// Box sizes, m.
    pub size: [f64; 3],
    /// Parts stacked on it at the start, bottom first.
    pub start: Vec<String>,
    /// Parts that must end stacked on it, bottom first (empty: no goal here).
    pub goal: Vec<String>,
}

/// A stacking task (`[task]`) for task-level deliberation: parts (cubes) stacked on stands,
/// moved one at a time by the `arms`, to end in the goal stacks. The coordinator plans it with
/// A* over production rules and refines the operators into motion (see `embodied_system::task`).
#[derive(Debug, Clone, PartialEq)]
pub struct TaskSpec {
    /// Scenario agent indices of the arms that run operators (agents without a goal).
    pub arms: Vec<usize>,
    /// The stands.
    pub stands: Vec<StandSpec>,
    /// Edge of the cubic parts, m.
    pub part_size: f64,
    /// Height of the tool above a part's top face where it picks or places it, m.
    pub clearance: f64,
    /// Time to grasp or release, s (part of each operator's cost).
    pub handling_s: f64,
    /// When the task plan is needed, ms (a later plan counts as late).
    pub deadline_ms: f64,
    /// When the task-level deliberation gives up, ms.
    pub give_up_ms: f64,
    /// Simulated clock: planning time per A* expansion, µs.
    pub us_per_expansion: f64,
}

/// A loaded, checked scenario.
#[derive(Debug, Clone)]
pub struct Scenario {
    /// Its name.
    pub name: String,
    /// One line on what it shows.
    pub description: String,
    /// Where it came from (a file, `<built-in>/NAME.toml`, or `<code>`).
    pub source: String,
    /// Hex SHA-256 of the scenario text (of its description, for a scenario built in code).
    pub hash: String,
    /// Seed of all simulated noise.
    pub seed: u64,
    /// The robots as agents.
    pub agents: Vec<AgentSpec>,
    /// The obstacles, with their run-time script.
    pub obstacles: Vec<ObstacleSpec>,
    /// Planner settings.
    pub planner: PlannerSpec,
    /// Run settings.
    pub run: RunSpec,
    /// The two-handed carry, if any.
    pub carry: Option<CarrySpec>,
    /// The stacking task, if any.
    pub task: Option<TaskSpec>,
    /// The polishing job, if any.
    pub polish: Option<PolishSpec>,
    /// Faults to inject in a run ([`crate::faults`]).
    pub faults: Vec<FaultSpec>,
}

impl Scenario {
    /// The carry task of a scenario with a `[carry]` table.
    pub fn carry_task(&self) -> Option<embodied_planner::carry::CarryTask> {
        let c = self.carry.as_ref()?;
        let agent = self.agents.get(c.agent)?;
        Some(embodied_planner::carry::CarryTask {
            robot: agent.robot.clone(),
            environment: self.initial_environment(),
            start: agent.start.clone(),
            object_name: c.object.clone(),
            object_size: c.size,
            object_start: c.object_start,
            object_goal: c.object_goal,
            end_effectors: c.end_effectors,
            grasps: c.grasps,
        })
    }

    /// Carry settings of the scenario (its lattice step, the plan's control step).
    pub fn carry_settings(&self) -> embodied_planner::carry::CarrySettings {
        let mut settings = embodied_planner::carry::CarrySettings::default();
        if let Some(c) = &self.carry {
            settings.lattice_step = c.lattice_step;
        }
        settings.motion.seed = self.planner.seed;
        settings
    }

    /// The obstacles present at time zero.
    pub fn initial_environment(&self) -> Environment {
        let mut env = Environment::new();
        for o in self.obstacles.iter().filter(|o| o.on_map()) {
            env.add(o.obstacle.clone());
        }
        env
    }
}

impl Scenario {
    /// A scenario made in code: start with a name, add agents and obstacles, then
    /// [`ScenarioBuilder::build`] checks it as the TOML reader would.
    pub fn builder(name: impl Into<String>) -> ScenarioBuilder {
        ScenarioBuilder::new(name)
    }

    /// Read a scenario from TOML text; `file` names it in errors, `dir` anchors relative paths
    /// (URDF, meshes). The same as [`parse_scenario`].
    pub fn from_toml(text: &str, file: &Path, dir: &Path) -> Result<Scenario, SystemError> {
        parse_scenario(text, file, dir)
    }
}

impl AgentSpec {
    /// An agent driving `robot` from its home pose, with no goal.
    pub fn new(name: impl Into<String>, robot: Robot) -> Self {
        let start = robot.home().to_vec();
        Self { name: name.into(), robot, start, goal: None, behaviour: BehaviourSpec::default() }
    }

    /// Place the robot's base at `xyz` (m, world frame), before its own base pose.
    pub fn at(self, xyz: [f64; 3]) -> Self {
        self.placed(pose(xyz, None))
    }

    /// Place the robot's base at `placement` (world frame), before its own base pose.
    pub fn placed(mut self, placement: Isometry3<f64>) -> Self {
        let base = placement * self.robot.base();
        self.robot.set_base(base);
        self
    }

    /// Start at `q`.
    pub fn start(mut self, q: Vec<f64>) -> Self {
        self.start = q;
        self
    }

    /// Reach `goal`.
    pub fn goal(mut self, goal: GoalSpec) -> Self {
        self.goal = Some(goal);
        self
    }

    /// Stop and abandon the task on a contact force over `newtons`.
    pub fn force_limit(mut self, newtons: f64) -> Self {
        self.behaviour.force_limit = Some(newtons);
        self
    }
}

/// Builds a [`Scenario`] in code; [`ScenarioBuilder::build`] checks what the TOML reader checks.
#[derive(Debug, Clone)]
pub struct ScenarioBuilder {
    scenario: Scenario,
}

impl ScenarioBuilder {
    fn new(name: impl Into<String>) -> Self {
        let name = name.into();
        Self {
            scenario: Scenario {
                description: String::new(),
                source: "<code>".into(),
                hash: String::new(),
                seed: 1,
                agents: Vec::new(),
                obstacles: Vec::new(),
                planner: PlannerSpec {
                    deadline_ms: 200.0,
                    give_up_ms: 200.0,
                    seed: 1,
                    certify: true,
                    resolution: 0.02,
                    expansions: None,
                    clock: ClockSpec::Wall,
                },
                run: RunSpec { duration: None, coordination: Coordination::Sequential },
                carry: None,
                task: None,
                polish: None,
                faults: Vec::new(),
                name,
            },
        }
    }

    /// One line on what it shows.
    pub fn description(mut self, text: impl Into<String>) -> Self {
        self.scenario.description = text.into();
        self
    }

    /// Seed of the simulated noise and of the planner.
    pub fn seed(mut self, seed: u64) -> Self {
        self.scenario.seed = seed;
        self.scenario.planner.seed = seed;
        self
    }

    /// Add an agent.
    pub fn agent(mut self, agent: AgentSpec) -> Self {
        self.scenario.agents.push(agent);
        self
    }

    /// Add an obstacle, on every agent's map from the start.
    pub fn obstacle(self, obstacle: Obstacle) -> Self {
        self.obstacle_spec(ObstacleSpec { obstacle, appear_at: None, velocity: None })
    }

    /// Add an obstacle with its run-time script (appearing at a time, moving).
    pub fn obstacle_spec(mut self, obstacle: ObstacleSpec) -> Self {
        self.scenario.obstacles.push(obstacle);
        self
    }

    /// Planner settings.
    pub fn planner(mut self, planner: PlannerSpec) -> Self {
        self.scenario.planner = planner;
        self
    }

    /// Count planning time as `us_per_check` µs per collision check: runs replay byte for byte.
    pub fn simulated_clock(mut self, us_per_check: f64) -> Self {
        self.scenario.planner.clock = ClockSpec::Simulated { us_per_check };
        self
    }

    /// How long a run lasts, s.
    pub fn duration(mut self, seconds: f64) -> Self {
        self.scenario.run.duration = Some(seconds);
        self
    }

    /// How the coordinator grants the agents' motions.
    pub fn coordination(mut self, coordination: Coordination) -> Self {
        self.scenario.run.coordination = coordination;
        self
    }

    /// Inject a fault in runs.
    pub fn fault(mut self, fault: FaultSpec) -> Self {
        self.scenario.faults.push(fault);
        self
    }

    /// A two-handed carry by one of the agents.
    pub fn carry(mut self, carry: CarrySpec) -> Self {
        self.scenario.carry = Some(carry);
        self
    }

    /// A polishing job (the `[polish]` table): a raster over the workpiece's top face under a
    /// regulated contact force, see [`PolishSpec::new`].
    pub fn polish(mut self, polish: PolishSpec) -> Self {
        self.scenario.polish = Some(polish);
        self
    }

    /// Check and return the scenario: at least one agent, unique names, start and goals
    /// within the robots' limits, positive sizes and finite numbers.
    pub fn build(self) -> Result<Scenario, SystemError> {
        let mut s = self.scenario;
        let bad = |m: String| SystemError::Usage(format!("scenario `{}`: {m}", s.name));
        if s.agents.is_empty() {
            return Err(bad("a scenario needs at least one agent".into()));
        }
        for (k, a) in s.agents.iter().enumerate() {
            if s.agents[..k].iter().any(|b| b.name == a.name) {
                return Err(bad(format!("two agents are named `{}`", a.name)));
            }
            a.robot.check_configuration(&a.start).map_err(|e| bad(format!("agent `{}`: start: {e}", a.name)))?;
            match &a.goal {
                Some(GoalSpec::Configuration(q)) => {
                    a.robot.check_configuration(q).map_err(|e| bad(format!("agent `{}`: goal: {e}", a.name)))?
                }
                Some(GoalSpec::AnyOf(qs)) => {
                    if qs.is_empty() {
                        return Err(bad(format!("agent `{}`: goals: expected at least one configuration", a.name)));
                    }
                    for q in qs {
                        a.robot.check_configuration(q).map_err(|e| bad(format!("agent `{}`: goals: {e}", a.name)))?;
                    }
                }
                Some(GoalSpec::ToolPose { end_effector, pose }) => {
                    if *end_effector >= a.robot.end_effectors().len() {
                        return Err(bad(format!("agent `{}`: goal: no end effector #{end_effector}", a.name)));
                    }
                    let t = pose.translation.vector;
                    if !(t.iter().all(|v| v.is_finite()) && pose.rotation.coords.iter().all(|v| v.is_finite())) {
                        return Err(bad(format!("agent `{}`: goal pose: expected finite numbers", a.name)));
                    }
                }
                None => {}
            }
            if let Some(f) = a.behaviour.force_limit
                && !(f.is_finite() && f > 0.0)
            {
                return Err(bad(format!("agent `{}`: force_limit: expected a force > 0 N, got {f}", a.name)));
            }
        }
        let p = &s.planner;
        if !(p.deadline_ms.is_finite() && p.deadline_ms >= 0.0) {
            return Err(bad(format!("planner: deadline_ms: expected a time >= 0 ms, got {}", p.deadline_ms)));
        }
        if !(p.give_up_ms.is_finite() && p.give_up_ms >= p.deadline_ms) {
            s.planner.give_up_ms = p.deadline_ms;
        }
        if !(s.planner.resolution.is_finite() && s.planner.resolution > 0.0) {
            return Err(bad("planner: resolution must be positive".into()));
        }
        if let ClockSpec::Simulated { us_per_check } = s.planner.clock
            && !(us_per_check.is_finite() && us_per_check >= 0.0)
        {
            return Err(bad(format!(
                "planner: simulated clock: expected a time >= 0 µs per check, got {us_per_check}"
            )));
        }
        if let Some(d) = s.run.duration
            && !(d.is_finite() && d > 0.0)
        {
            return Err(bad(format!("run: duration: expected a positive time in s, got {d}")));
        }
        for o in &s.obstacles {
            let finite = o.obstacle.pose.translation.vector.iter().all(|v| v.is_finite())
                && o.velocity.is_none_or(|v| v.iter().all(|x| x.is_finite()))
                && o.appear_at.is_none_or(|t| t.is_finite() && t >= 0.0);
            if !finite {
                return Err(bad(format!("obstacle `{}`: expected finite numbers and a time >= 0", o.obstacle.name)));
            }
        }
        for (k, f) in s.faults.iter().enumerate() {
            f.check().map_err(|e| bad(format!("fault #{} ({}): {e}", k + 1, f.kind.as_str())))?;
            if let Some(a) = &f.agent
                && !s.agents.iter().any(|x| x.name == *a)
            {
                return Err(bad(format!("fault #{} ({}): no agent `{a}`", k + 1, f.kind.as_str())));
            }
        }
        if let Some(c) = &s.carry {
            if c.agent >= s.agents.len() {
                return Err(bad(format!("carry: no agent #{}", c.agent)));
            }
            if !c.size.iter().all(|v| v.is_finite() && *v > 0.0) {
                return Err(bad(format!("carry: size: expected three positive lengths in m, got {:?}", c.size)));
            }
        }
        if let Some(p) = &s.polish
            && let Some((_, m)) = p.problem(&s.agents, &s.obstacles)
        {
            return Err(bad(format!("polish: {m}")));
        }
        s.hash = sha256_hex(&format!(
            "{}\n{}\n{:?}",
            s.name,
            s.description,
            s.agents.iter().map(|a| &a.name).collect::<Vec<_>>()
        ));
        Ok(s)
    }
}

impl ObstacleSpec {
    /// Present from the start and still: on the agents' map.
    pub fn on_map(&self) -> bool {
        self.appear_at.is_none_or(|t| t <= 0.0) && self.velocity.is_none_or(|v| v.norm() == 0.0)
    }
}

/// 1-based line and column of a byte offset.
pub fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let offset = offset.min(text.len());
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let col = before.rfind('\n').map_or(offset, |nl| offset - nl - 1) + 1;
    (line, col)
}

struct Ctx<'a> {
    file: &'a Path,
    text: &'a str,
}

impl Ctx<'_> {
    fn err(&self, span: Range<usize>, message: impl Into<String>) -> SystemError {
        let (line, column) = line_col(self.text, span.start);
        SystemError::Parse { file: self.file.to_path_buf(), line, column, message: message.into() }
    }
}

/// The collision objects of a `[moveit_scene]` as obstacles on the map, placed by the table's
/// `xyz`/`rpy`. Objects must be in the scene's frame: an empty `frame_id`, `world`, or the root
/// link of an agent's robot (a scene written for that robot; place the scene where the robot
/// stands). A name already taken by another obstacle is an error.
fn moveit_scene_obstacles(
    ctx: &Ctx,
    spanned: &Spanned<RawMoveitScene>,
    dir: &Path,
    agents: &[AgentSpec],
    obstacles: &mut Vec<ObstacleSpec>,
) -> Result<(), SystemError> {
    let span = spanned.span();
    let raw = spanned.get_ref();
    let numbers = raw.xyz.iter().flatten().chain(raw.rpy.iter().flatten());
    if !numbers.into_iter().all(|v| v.is_finite()) {
        return Err(
            ctx.err(span, format!("[moveit_scene]: expected finite xyz and rpy, got {:?} {:?}", raw.xyz, raw.rpy))
        );
    }
    let path = dir.join(&raw.file);
    let scene = load_scene(&path).map_err(|e| match e {
        MoveitError::Parse { file, line, column, message } => SystemError::Parse { file, line, column, message },
        MoveitError::Io { file, source } => SystemError::io(file, source),
        other => ctx.err(span.clone(), format!("[moveit_scene] {}: {other}", path.display())),
    })?;
    let roots: Vec<String> = agents
        .iter()
        .filter_map(|a| a.robot.links().iter().find(|l| l.parent_joint.is_none()).map(|l| l.name.clone()))
        .collect();
    for o in &scene.objects {
        let f = o.frame_id.trim_start_matches('/');
        if !(f.is_empty() || f == "world" || roots.iter().any(|r| r == f)) {
            return Err(SystemError::Parse {
                file: path.clone(),
                line: o.location.line,
                column: o.location.column,
                message: format!(
                    "object `{}` is in frame `{}`; expected the scene's frame (``, `world` or an agent robot's root link: {})",
                    o.id,
                    o.frame_id,
                    roots.join(", ")
                ),
            });
        }
    }
    let placement = pose(raw.xyz.unwrap_or([0.0; 3]), raw.rpy);
    for o in scene.obstacles() {
        if obstacles.iter().any(|other| other.obstacle.name == o.name) {
            return Err(ctx.err(
                span.clone(),
                format!("[moveit_scene] {}: object `{}` has the name of another obstacle", path.display(), o.name),
            ));
        }
        obstacles.push(ObstacleSpec {
            obstacle: Obstacle { name: o.name, pose: placement * o.pose, shape: o.shape },
            appear_at: None,
            velocity: None,
        });
    }
    Ok(())
}

fn pose(xyz: [f64; 3], rpy: Option<[f64; 3]>) -> Isometry3<f64> {
    let [r, p, y] = rpy.unwrap_or([0.0; 3]);
    Isometry3::from_parts(Translation3::new(xyz[0], xyz[1], xyz[2]), UnitQuaternion::from_euler_angles(r, p, y))
}

/// Resolve a scenario argument: a built-in name or a file path.
pub fn load_scenario(arg: &str) -> Result<Scenario, SystemError> {
    if let Some((_, text)) = BUILTIN_SCENARIOS.iter().find(|(n, _)| *n == arg) {
        return parse_scenario(text, Path::new(&format!("<built-in>/{arg}.toml")), Path::new("."));
    }
    let path = PathBuf::from(arg);
    if arg == "-" {
        let text = crate::error::read_input(&path, embodied_models::formats::limits::InputKind::Text)?;
        return parse_scenario(&text, Path::new("<stdin>"), Path::new("."));
    }
    if !path.exists() {
        let names: Vec<&str> = BUILTIN_SCENARIOS.iter().map(|(n, _)| *n).collect();
        return Err(SystemError::Usage(format!(
            "`{arg}` is neither a scenario file nor a built-in scenario; built-in scenarios are: {}",
            names.join(", ")
        )));
    }
    let text =
        embodied_models::formats::limits::read_text_limited(&path, embodied_models::formats::limits::InputKind::Text)
            .map_err(|e| SystemError::io(&path, e))?;
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_else(|| PathBuf::from("."));
    parse_scenario(&text, &path, &dir)
}

fn sha256_hex(text: &str) -> String {
    use sha2::Digest;
    let digest = sha2::Sha256::digest(text.as_bytes());
    digest.iter().map(|b| format!("{b:02x}")).collect()
}

/// Parse a scenario from TOML text; `file` names it in errors, `dir` anchors relative paths.
pub fn parse_scenario(text: &str, file: &Path, dir: &Path) -> Result<Scenario, SystemError> {
    let ctx = Ctx { file, text };
    embodied_models::formats::limits::check_values(text, embodied_models::formats::limits::Syntax::Data)
        .map_err(|m| ctx.err(0..0, m))?;
    let raw: RawScenario = toml::from_str(text).map_err(|e| {
        let span = e.span().unwrap_or(0..0);
        ctx.err(span, e.message().trim().to_string())
    })?;
    if raw.agents.is_empty() {
        return Err(ctx.err(0..0, "a scenario needs at least one [[agents]] table"));
    }
    let mut agents = Vec::new();
    for spanned in &raw.agents {
        let span = spanned.span();
        let a = spanned.get_ref();
        if agents.iter().any(|x: &AgentSpec| x.name == a.name) {
            return Err(ctx.err(span, format!("two agents are named `{}`", a.name)));
        }
        let mut robot = match (&a.robot, &a.urdf) {
            (Some(name), None) => {
                embodied_models::builtin(name.get_ref()).map_err(|e| ctx.err(name.span(), format!("robot: {e}")))?
            }
            (None, Some(urdf)) => {
                let path = dir.join(urdf.get_ref());
                let srdf = a.srdf.as_ref().map(|s| dir.join(s));
                embodied_models::urdf::load_urdf(&path, srdf.as_deref())
                    .map_err(|e| ctx.err(urdf.span(), format!("urdf: {e}")))?
            }
            _ => {
                return Err(ctx.err(
                    span,
                    format!(
                        "agent `{}`: expected exactly one of `robot = \"<built-in>\"` or `urdf = \"<file>\"`",
                        a.name
                    ),
                ));
            }
        };
        if a.xyz.is_some() || a.rpy.is_some() {
            robot.set_base(pose(a.xyz.unwrap_or([0.0; 3]), a.rpy) * robot.base());
        }
        let check = |q: &Spanned<Vec<f64>>, what: &str| -> Result<Vec<f64>, SystemError> {
            robot.check_configuration(q.get_ref()).map_err(|e| ctx.err(q.span(), format!("{what}: {e}")))?;
            Ok(q.get_ref().clone())
        };
        let start = match &a.start {
            Some(q) => check(q, "start")?,
            None => robot.home().to_vec(),
        };
        let goal = match (&a.goal, &a.goals, &a.goal_pose) {
            (None, None, None) => None,
            (Some(q), None, None) => Some(GoalSpec::Configuration(check(q, "goal")?)),
            (None, Some(qs), None) => {
                let mut list = Vec::new();
                for q in qs.get_ref() {
                    robot
                        .check_configuration(q)
                        .map_err(|e| ctx.err(qs.span(), format!("goals[{}]: {e}", list.len())))?;
                    list.push(q.clone());
                }
                if list.is_empty() {
                    return Err(ctx.err(qs.span(), "goals: expected at least one configuration"));
                }
                Some(GoalSpec::AnyOf(list))
            }
            (None, None, Some(p)) => {
                let raw_pose = p.get_ref();
                let ee = match &raw_pose.end_effector {
                    None => 0,
                    Some(name) => robot.end_effectors().iter().position(|e| &e.name == name).ok_or_else(|| {
                        let names: Vec<&str> = robot.end_effectors().iter().map(|e| e.name.as_str()).collect();
                        ctx.err(p.span(), format!("goal_pose: no end effector `{name}`; expected one of {names:?}"))
                    })?,
                };
                if robot.end_effectors().is_empty() {
                    return Err(ctx.err(p.span(), "goal_pose: this robot has no end effector"));
                }
                let rpy = raw_pose.rpy.unwrap_or([0.0; 3]);
                if !raw_pose.xyz.iter().chain(&rpy).all(|v| v.is_finite()) {
                    return Err(ctx.err(
                        p.span(),
                        format!("goal_pose: expected finite numbers, got xyz {:?}, rpy {rpy:?}", raw_pose.xyz),
                    ));
                }
                Some(GoalSpec::ToolPose { end_effector: ee, pose: pose(raw_pose.xyz, raw_pose.rpy) })
            }
            _ => {
                return Err(ctx.err(span, format!("agent `{}`: give at most one of goal, goals, goal_pose", a.name)));
            }
        };
        let behaviour = a.behaviour.clone().unwrap_or_default();
        if let Some(f) = behaviour.force_limit
            && !(f.is_finite() && f > 0.0)
        {
            return Err(
                ctx.err(span, format!("agent `{}`: behaviour.force_limit: expected a force > 0 N, got {f}", a.name))
            );
        }
        agents.push(AgentSpec { name: a.name.clone(), robot, start, goal, behaviour });
    }
    let mut obstacles = Vec::new();
    for spanned in &raw.obstacles {
        let span = spanned.span();
        let o = spanned.get_ref();
        let positive = |v: f64, what: &str| -> Result<f64, SystemError> {
            if v.is_finite() && v > 0.0 {
                Ok(v)
            } else {
                Err(ctx.err(span.clone(), format!("obstacle `{}`: {what} must be a positive number, got {v}", o.name)))
            }
        };
        let mut shapes = Vec::new();
        if let Some([x, y, z]) = o.cuboid {
            shapes.push(Shape::cuboid(
                positive(x, "box x")? / 2.0,
                positive(y, "box y")? / 2.0,
                positive(z, "box z")? / 2.0,
            ));
        }
        if let Some(r) = o.sphere {
            shapes.push(Shape::sphere(positive(r, "sphere radius")?));
        }
        if let Some(c) = &o.cylinder {
            shapes.push(Shape::cylinder(positive(c.radius, "radius")?, positive(c.length, "length")? / 2.0));
        }
        if let Some(c) = &o.capsule {
            let h = positive(c.length, "length")? / 2.0;
            shapes.push(Shape::capsule([0.0, 0.0, -h], [0.0, 0.0, h], positive(c.radius, "radius")?));
        }
        if let Some(m) = &o.mesh {
            let path = dir.join(m);
            let scale = o.scale.unwrap_or(1.0);
            let mesh = read_mesh(&path, Vector3::repeat(scale))
                .map_err(|e| ctx.err(span.clone(), format!("mesh {}: {e}", path.display())))?;
            let hull = ConvexHull::from_points(&mesh.vertices)
                .ok_or_else(|| ctx.err(span.clone(), format!("mesh {}: degenerate (flat) mesh", path.display())))?;
            shapes.push(Shape::ConvexMesh(std::sync::Arc::new(hull)));
        }
        if shapes.len() != 1 {
            return Err(ctx.err(
                span,
                format!(
                    "obstacle `{}`: expected exactly one shape key: box = [x, y, z], sphere = r, cylinder = {{ radius, length }}, capsule = {{ radius, length }} or mesh = \"file.stl\"",
                    o.name
                ),
            ));
        }
        let Some(shape) = shapes.pop() else { unreachable!("checked above") };
        let (rpy, velocity) = (o.rpy.unwrap_or([0.0; 3]), o.velocity.unwrap_or([0.0; 3]));
        let placement = o.xyz.iter().chain(&rpy).chain(&velocity);
        if !placement.into_iter().all(|v| v.is_finite()) || !o.scale.unwrap_or(1.0).is_finite() {
            return Err(ctx.err(
                span,
                format!(
                    "obstacle `{}`: expected finite numbers, got xyz {:?}, rpy {:?}, velocity {:?}, scale {:?}",
                    o.name, o.xyz, o.rpy, o.velocity, o.scale
                ),
            ));
        }
        let appear_at = match &o.appear_at {
            Some(t) if !(t.get_ref().is_finite() && *t.get_ref() >= 0.0) => {
                return Err(ctx.err(
                    t.span(),
                    format!("obstacle `{}`: appear_at: expected a time >= 0 s, got {}", o.name, t.get_ref()),
                ));
            }
            Some(t) => Some(*t.get_ref()),
            None => None,
        };
        obstacles.push(ObstacleSpec {
            obstacle: Obstacle { name: o.name.clone(), pose: pose(o.xyz, o.rpy), shape },
            appear_at,
            velocity: o.velocity.map(Vector3::from),
        });
    }
    if let Some(scene) = &raw.moveit_scene {
        moveit_scene_obstacles(&ctx, scene, dir, &agents, &mut obstacles)?;
    }
    let seed = raw.seed.unwrap_or(1);
    let deadline_ms = raw.planner.deadline_ms.unwrap_or(200.0);
    if !(deadline_ms.is_finite() && deadline_ms >= 0.0) {
        return Err(ctx.err(0..0, format!("[planner] deadline_ms: expected a time >= 0 ms, got {deadline_ms}")));
    }
    let give_up_ms = match &raw.planner.give_up_ms {
        None => deadline_ms,
        Some(g) if g.get_ref().is_finite() && *g.get_ref() >= deadline_ms => *g.get_ref(),
        Some(g) => {
            return Err(ctx.err(
                g.span(),
                format!("give_up_ms: expected a time >= deadline_ms ({deadline_ms} ms), got {}", g.get_ref()),
            ));
        }
    };
    let us_per_check = match &raw.planner.simulated_us_per_check {
        None => DEFAULT_US_PER_CHECK,
        Some(u) if u.get_ref().is_finite() && *u.get_ref() >= 0.0 => *u.get_ref(),
        Some(u) => {
            return Err(
                ctx.err(u.span(), format!("simulated_us_per_check: expected a time >= 0 µs, got {}", u.get_ref()))
            );
        }
    };
    let clock = match &raw.planner.clock {
        None => ClockSpec::Wall,
        Some(c) => match c.get_ref().as_str() {
            "wall" => ClockSpec::Wall,
            "simulated" => ClockSpec::Simulated { us_per_check },
            other => {
                return Err(ctx.err(c.span(), format!("clock: expected \"wall\" or \"simulated\", got \"{other}\"")));
            }
        },
    };
    let certify = match &raw.planner.edge_check {
        None => true,
        Some(c) => match c.get_ref().as_str() {
            "certified" => true,
            "sampled" => false,
            other => {
                return Err(
                    ctx.err(c.span(), format!("edge_check: expected \"certified\" or \"sampled\", got \"{other}\""))
                );
            }
        },
    };
    let planner = PlannerSpec {
        deadline_ms,
        give_up_ms,
        certify,
        seed: raw.planner.seed.unwrap_or(seed),
        resolution: raw.planner.resolution.unwrap_or(0.02),
        expansions: raw.planner.expansions,
        clock,
    };
    if planner.resolution.is_nan() || planner.resolution <= 0.0 {
        return Err(ctx.err(0..0, "[planner] resolution must be positive"));
    }
    let coordination = match &raw.run.coordination {
        None => Coordination::Sequential,
        Some(c) => match c.get_ref().as_str() {
            "sequential" => Coordination::Sequential,
            "concurrent" => Coordination::Concurrent,
            other => {
                return Err(ctx.err(
                    c.span(),
                    format!("coordination: expected \"sequential\" or \"concurrent\", got \"{other}\""),
                ));
            }
        },
    };
    let duration = match &raw.run.duration {
        None => None,
        Some(d) if d.get_ref().is_finite() && *d.get_ref() > 0.0 => Some(*d.get_ref()),
        Some(d) => {
            return Err(ctx.err(d.span(), format!("duration: expected a positive time in s, got {}", d.get_ref())));
        }
    };
    let carry = match &raw.carry {
        None => None,
        Some(c) => Some(parse_carry(&ctx, c, &agents)?),
    };
    let task = match &raw.task {
        None => None,
        Some(t) => Some(parse_task(&ctx, t, &agents, carry.as_ref())?),
    };
    if let Some(t) = &task {
        for stand in &t.stands {
            let [x, y, z] = stand.size;
            obstacles.push(ObstacleSpec {
                obstacle: Obstacle {
                    name: format!("stand_{}", stand.name),
                    pose: pose([stand.top[0], stand.top[1], stand.top[2] - z / 2.0], None),
                    shape: Shape::cuboid(x / 2.0, y / 2.0, z / 2.0),
                },
                appear_at: None,
                velocity: None,
            });
        }
    }
    let polish = match &raw.polish {
        None => None,
        Some(p) => Some(parse_polish(&ctx, p, &agents, &obstacles)?),
    };
    let mut faults = Vec::new();
    for spanned in &raw.faults {
        faults.push(parse_fault(&ctx, spanned, &agents)?);
    }
    Ok(Scenario {
        faults,
        name: raw.name,
        description: raw.description,
        source: file.display().to_string(),
        hash: sha256_hex(text),
        seed,
        agents,
        obstacles,
        planner,
        run: RunSpec { duration, coordination },
        carry,
        task,
        polish,
    })
}

fn parse_task(
    ctx: &Ctx,
    spanned: &Spanned<RawTask>,
    agents: &[AgentSpec],
    carry: Option<&CarrySpec>,
) -> Result<TaskSpec, SystemError> {
    let t = spanned.get_ref();
    let mut arms = Vec::new();
    for name in t.arms.get_ref() {
        let k = agents.iter().position(|a| a.name == *name).ok_or_else(|| {
            let names: Vec<&str> = agents.iter().map(|a| a.name.as_str()).collect();
            ctx.err(t.arms.span(), format!("task: arms: no agent `{name}`; expected one of {names:?}"))
        })?;
        if agents[k].goal.is_some() || carry.is_some_and(|c| c.agent == k) {
            return Err(ctx.err(
                t.arms.span(),
                format!("task: arms: agent `{name}` has a goal or a carry; the task decides its motion, remove it"),
            ));
        }
        if agents[k].robot.end_effectors().is_empty() {
            return Err(ctx.err(t.arms.span(), format!("task: arms: agent `{name}`'s robot has no end effector")));
        }
        if arms.contains(&k) {
            return Err(ctx.err(t.arms.span(), format!("task: arms: `{name}` listed twice")));
        }
        arms.push(k);
    }
    if arms.is_empty() {
        return Err(ctx.err(t.arms.span(), "task: arms: expected at least one agent name"));
    }
    if let Some(a) = agents.iter().find(|a| a.goal.is_some()) {
        return Err(ctx.err(
            spanned.span(),
            format!(
                "task: agent `{}` has a goal; in a scenario with a [task] the task coordinator drives the agents",
                a.name
            ),
        ));
    }
    let number = |v: &Option<Spanned<f64>>, default: f64, what: &str, ok: &dyn Fn(f64) -> bool, expected: &str| match v
    {
        None => Ok(default),
        Some(x) if ok(*x.get_ref()) => Ok(*x.get_ref()),
        Some(x) => Err(ctx.err(x.span(), format!("task: {what}: expected {expected}, got {}", x.get_ref()))),
    };
    let positive = |x: f64| x.is_finite() && x > 0.0;
    let non_negative = |x: f64| x.is_finite() && x >= 0.0;
    let part_size = number(&t.part_size, 0.05, "part_size", &positive, "a length > 0 m")?;
    let clearance = number(&t.clearance, 0.02, "clearance", &non_negative, "a length >= 0 m")?;
    let handling_s = number(&t.handling_s, 0.5, "handling_s", &non_negative, "a time >= 0 s")?;
    let deadline_ms = number(&t.deadline_ms, 500.0, "deadline_ms", &non_negative, "a time >= 0 ms")?;
    let give_up_ms = number(
        &t.give_up_ms,
        deadline_ms.max(5000.0),
        "give_up_ms",
        &|x| x.is_finite() && x >= deadline_ms,
        &format!("a time >= deadline_ms ({deadline_ms} ms)"),
    )?;
    let us_per_expansion =
        number(&t.simulated_us_per_expansion, 20.0, "simulated_us_per_expansion", &non_negative, "a time >= 0 µs")?;
    let mut stands: Vec<StandSpec> = Vec::new();
    let mut seen_start: Vec<&str> = Vec::new();
    let mut seen_goal: Vec<&str> = Vec::new();
    for st in &t.stands {
        let r = st.get_ref();
        if stands.iter().any(|s| s.name == r.name) {
            return Err(ctx.err(st.span(), format!("task: two stands are named `{}`", r.name)));
        }
        if !r.xyz.iter().all(|v| v.is_finite()) || !r.size.iter().all(|v| v.is_finite() && *v > 0.0) {
            return Err(ctx.err(
                st.span(),
                format!(
                    "task: stand `{}`: expected finite xyz and three positive sizes in m, got xyz {:?}, size {:?}",
                    r.name, r.xyz, r.size
                ),
            ));
        }
        for p in &r.start {
            if seen_start.contains(&p.as_str()) {
                return Err(ctx.err(st.span(), format!("task: part `{p}` starts on two stands (or twice)")));
            }
            seen_start.push(p);
        }
        for p in &r.goal {
            if seen_goal.contains(&p.as_str()) {
                return Err(ctx.err(st.span(), format!("task: part `{p}` is in two goal stacks (or twice)")));
            }
            seen_goal.push(p);
        }
        stands.push(StandSpec {
            name: r.name.clone(),
            top: r.xyz,
            size: r.size,
            start: r.start.clone(),
            goal: r.goal.clone(),
        });
    }
    if stands.is_empty() {
        return Err(ctx.err(spanned.span(), "task: expected at least one [[task.stands]] table"));
    }
    if let Some(p) = seen_goal.iter().find(|p| !seen_start.contains(p)) {
        return Err(ctx.err(
            spanned.span(),
            format!("task: part `{p}` is in a goal stack but starts on no stand; expected one of {seen_start:?}"),
        ));
    }
    Ok(TaskSpec { arms, stands, part_size, clearance, handling_s, deadline_ms, give_up_ms, us_per_expansion })
}

fn parse_fault(ctx: &Ctx, spanned: &Spanned<RawFault>, agents: &[AgentSpec]) -> Result<FaultSpec, SystemError> {
    let f = spanned.get_ref();
    let kind = FaultKind::parse(f.kind.get_ref()).ok_or_else(|| {
        let names: Vec<&str> = FaultKind::ALL.iter().map(|k| k.as_str()).collect();
        ctx.err(f.kind.span(), format!("fault kind: expected one of {names:?}, got \"{}\"", f.kind.get_ref()))
    })?;
    let trigger = match (f.at, f.probability) {
        (Some(t), None) => FaultTrigger::At(t),
        (None, Some(p)) => FaultTrigger::Probability(p),
        _ => {
            return Err(ctx.err(
                spanned.span(),
                "fault: expected exactly one of `at = <time in s>` or `probability = <per step or request>`",
            ));
        }
    };
    if let Some(a) = &f.agent
        && !agents.iter().any(|x| x.name == *a.get_ref())
    {
        let names: Vec<&str> = agents.iter().map(|a| a.name.as_str()).collect();
        return Err(ctx.err(a.span(), format!("fault: no agent `{}`; expected one of {names:?}", a.get_ref())));
    }
    if let Some(l) = &f.link {
        let names: Vec<&str> = agents.iter().map(|a| a.name.as_str()).chain(["coordinator"]).collect();
        let bad_end = l.get_ref().split_once("->").and_then(|(a, b)| {
            [a.trim(), b.trim()].into_iter().find(|e| !e.is_empty() && !names.contains(e)).map(str::to_string)
        });
        if let Some(end) = bad_end {
            return Err(ctx.err(l.span(), format!("fault: link end `{end}`: expected one of {names:?}")));
        }
    }
    let spec = FaultSpec {
        agent: f.agent.as_ref().map(|a| a.get_ref().clone()),
        duration: f.duration.unwrap_or(0.0),
        seed: f.seed,
        link: f.link.as_ref().map(|l| l.get_ref().clone()),
        loss: f.loss.unwrap_or(crate::faults::DEFAULT_LOSS),
        delay: f.delay.unwrap_or(crate::faults::DEFAULT_DELAY),
        ..FaultSpec::new(kind, trigger)
    };
    spec.check().map_err(|e| ctx.err(spanned.span(), format!("fault `{}`: {e}", kind.as_str())))?;
    Ok(spec)
}

fn parse_polish(
    ctx: &Ctx,
    spanned: &Spanned<RawPolish>,
    agents: &[AgentSpec],
    obstacles: &[ObstacleSpec],
) -> Result<PolishSpec, SystemError> {
    let p = spanned.get_ref();
    let agent = agents.iter().position(|a| a.name == *p.agent.get_ref()).ok_or_else(|| {
        let names: Vec<&str> = agents.iter().map(|a| a.name.as_str()).collect();
        ctx.err(p.agent.span(), format!("polish: no agent `{}`; expected one of {names:?}", p.agent.get_ref()))
    })?;
    let workpiece = obstacles.iter().position(|o| o.obstacle.name == *p.workpiece.get_ref()).ok_or_else(|| {
        let names: Vec<&str> = obstacles.iter().map(|o| o.obstacle.name.as_str()).collect();
        ctx.err(
            p.workpiece.span(),
            format!("polish: no obstacle `{}`; expected one of {names:?}", p.workpiece.get_ref()),
        )
    })?;
    let value = |v: &Option<Spanned<f64>>, default: f64| v.as_ref().map_or(default, |x| *x.get_ref());
    let d = PolishSpec::new(agent, workpiece);
    let spec = PolishSpec {
        force_n: value(&p.force_n, d.force_n),
        band_n: value(&p.band_n, d.band_n),
        tool_radius: value(&p.tool_radius, d.tool_radius),
        speed: value(&p.speed, d.speed),
        skin: p.skin_mm.as_ref().map_or(d.skin, |x| *x.get_ref() * 1e-3),
        ..d
    };
    match spec.problem(agents, obstacles) {
        None => Ok(spec),
        Some((field, message)) => {
            let span = match field {
                PolishField::Agent => Some(p.agent.span()),
                PolishField::Workpiece => Some(p.workpiece.span()),
                PolishField::Number("force_n") => p.force_n.as_ref().map(Spanned::span),
                PolishField::Number("band_n") => p.band_n.as_ref().map(Spanned::span),
                PolishField::Number("tool_radius") => p.tool_radius.as_ref().map(Spanned::span),
                PolishField::Number("speed") => p.speed.as_ref().map(Spanned::span),
                PolishField::Number(_) => p.skin_mm.as_ref().map(Spanned::span),
                PolishField::Whole => None,
            };
            Err(ctx.err(span.unwrap_or_else(|| spanned.span()), format!("polish: {message}")))
        }
    }
}

/// The field of a [`PolishSpec`] a problem is about (for the TOML error's place).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum PolishField {
    Agent,
    Workpiece,
    /// A number, by its TOML key.
    Number(&'static str),
    Whole,
}

impl PolishSpec {
    /// Polishing by agent `agent` on obstacle `workpiece` (indices in the scenario) with the
    /// defaults of the `[polish]` table: 20 ± 5 N, a 0.05 m pad, 0.1 m/s, a 5 mm pad skin.
    pub fn new(agent: usize, workpiece: usize) -> Self {
        Self { agent, workpiece, force_n: 20.0, band_n: 5.0, tool_radius: 0.05, speed: 0.1, skin: 0.005 }
    }

    /// What is wrong with this job in a scenario with `agents` and `obstacles`, if anything.
    fn problem(&self, agents: &[AgentSpec], obstacles: &[ObstacleSpec]) -> Option<(PolishField, String)> {
        let Some(a) = agents.get(self.agent) else {
            return Some((PolishField::Agent, format!("no agent #{}", self.agent)));
        };
        if a.goal.is_some() {
            let m = format!("agent `{}` has a goal; the polishing job decides its motion, remove it", a.name);
            return Some((PolishField::Agent, m));
        }
        if a.robot.end_effectors().is_empty() {
            return Some((PolishField::Agent, format!("agent `{}` has no end effector", a.name)));
        }
        let Some(o) = obstacles.get(self.workpiece) else {
            return Some((PolishField::Workpiece, format!("no obstacle #{}", self.workpiece)));
        };
        let axis_aligned = o.obstacle.pose.rotation.angle() < 1e-9;
        if !(axis_aligned && o.on_map() && matches!(o.obstacle.shape, Shape::Cuboid { .. })) {
            let m = format!("workpiece `{}`: expected a still box without rotation (rpy = 0)", o.obstacle.name);
            return Some((PolishField::Workpiece, m));
        }
        let numbers = [
            ("force_n", self.force_n, 0.5, 500.0, "N", 1.0),
            ("band_n", self.band_n, 0.1, 100.0, "N", 1.0),
            ("tool_radius", self.tool_radius, 0.005, 0.5, "m", 1.0),
            ("speed", self.speed, 0.005, 1.0, "m/s", 1.0),
            ("skin_mm", self.skin, 0.5, 50.0, "mm", 1e3),
        ];
        for (what, v, lo, hi, unit, scale) in numbers {
            let v = v * scale;
            if !(v.is_finite() && (lo..=hi).contains(&v)) {
                return Some((PolishField::Number(what), format!("{what}: expected {lo}..{hi} {unit}, got {v}")));
            }
        }
        if let Some(limit) = a.behaviour.force_limit
            && limit <= self.force_n + self.band_n
        {
            let m = format!(
                "force_n + band_n ({} N) must stay below agent `{}`'s force_limit ({limit} N)",
                self.force_n + self.band_n,
                a.name
            );
            return Some((PolishField::Whole, m));
        }
        None
    }
}

fn parse_carry(ctx: &Ctx, spanned: &Spanned<RawCarry>, agents: &[AgentSpec]) -> Result<CarrySpec, SystemError> {
    use std::f64::consts::FRAC_PI_2;
    let c = spanned.get_ref();
    let agent = agents.iter().position(|a| a.name == *c.agent.get_ref()).ok_or_else(|| {
        let names: Vec<&str> = agents.iter().map(|a| a.name.as_str()).collect();
        ctx.err(c.agent.span(), format!("carry: no agent `{}`; expected one of {names:?}", c.agent.get_ref()))
    })?;
    let robot = &agents[agent].robot;
    if agents[agent].goal.is_some() {
        return Err(ctx.err(
            c.agent.span(),
            format!("carry: agent `{}` has a goal; the carry decides its motion, remove the goal", c.agent.get_ref()),
        ));
    }
    let size = *c.size.get_ref();
    if !size.iter().all(|v| v.is_finite() && *v > 0.0) {
        return Err(ctx.err(c.size.span(), format!("carry: size: expected three positive lengths in m, got {size:?}")));
    }
    let names: Vec<&str> = robot.end_effectors().iter().map(|e| e.name.as_str()).collect();
    let end_effectors = match &c.end_effectors {
        None if names.len() >= 2 => [0, 1],
        None => {
            return Err(ctx.err(
                c.agent.span(),
                format!("carry: robot `{}` has {} end effector(s); a carry needs two", robot.name(), names.len()),
            ));
        }
        Some(e) => {
            let find = |name: &String| {
                names.iter().position(|n| n == name).ok_or_else(|| {
                    ctx.err(e.span(), format!("carry: no end effector `{name}`; expected one of {names:?}"))
                })
            };
            let pair = [find(&e.get_ref()[0])?, find(&e.get_ref()[1])?];
            if pair[0] == pair[1] {
                return Err(ctx.err(e.span(), "carry: end_effectors: expected two different end effectors"));
            }
            pair
        }
    };
    let lattice_step = match &c.lattice_step {
        None => 0.05,
        Some(s) if s.get_ref().is_finite() && (0.005..=0.5).contains(s.get_ref()) => *s.get_ref(),
        Some(s) => {
            return Err(ctx.err(s.span(), format!("carry: lattice_step: expected 0.005..0.5 m, got {}", s.get_ref())));
        }
    };
    let finite = |v: &[f64], what: &str| -> Result<(), SystemError> {
        if v.iter().all(|x| x.is_finite()) {
            Ok(())
        } else {
            Err(ctx.err(spanned.span(), format!("carry: {what}: expected finite numbers, got {v:?}")))
        }
    };
    finite(&c.start_xyz, "start_xyz")?;
    finite(&c.goal_xyz, "goal_xyz")?;
    finite(&c.rpy.unwrap_or([0.0; 3]), "rpy")?;
    let roll = c.grasp_roll.unwrap_or([FRAC_PI_2, FRAC_PI_2]);
    finite(&roll, "grasp_roll")?;
    let half = size[0] / 2.0;
    let grasps = [
        Isometry3::from_parts(
            Translation3::new(-half, 0.0, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), FRAC_PI_2)
                * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), roll[0]),
        ),
        Isometry3::from_parts(
            Translation3::new(half, 0.0, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -FRAC_PI_2)
                * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), roll[1]),
        ),
    ];
    Ok(CarrySpec {
        agent,
        object: c.object.clone(),
        size,
        object_start: pose(c.start_xyz, c.rpy),
        object_goal: pose(c.goal_xyz, c.rpy),
        end_effectors,
        grasps,
        lattice_step,
    })
}
