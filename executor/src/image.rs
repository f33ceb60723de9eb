//! The images of eq. (7): what the control subsystem reads (`c^i_e, c^i_V, c^i_T`) and what it
//! writes (`c^{i+1}_e, c^{i+1}_V, c^{i+1}_T`).
//!
//! The two halves are separate types. A transition function receives `&InputImages` (it can only
//! read) and `&mut OutputImages`, whose only public methods are setters: nothing it writes can be
//! read back within the step, so `c^{i+1}` depends on `c^i` alone, as eq. (5) demands.

use embodied_models::JointLimits;

/// Number of `f64` words in one [`Message`] and one [`Reading`]; fixed so that images are
/// `Copy` and a control step never allocates.
pub const WORDS: usize = 8;

/// Index of an agent in its [`crate::Runtime`] (the `j` of `a_j`), in order of addition.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize, serde::Deserialize)]
pub struct AgentId(pub usize);

/// One inter-agent message (an element of `c_T`).
///
/// The coordination protocol of a system of agents is typed: a coordinator grants a motion
/// ([`Message::Grant`]), an agent reports it is done ([`Message::Done`]), and the space an agent
/// occupies (its body at rest, or the sweep of its plan) is handed on whole
/// ([`Message::Occupancy`]). User protocols send [`Message::Words`]: a tag and a few numbers.
/// Every kind travels over the same [`crate::Transmitter`], so latency and loss apply to it.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum Message {
    /// A tag saying what it means and [`WORDS`] numbers.
    Words {
        /// What the numbers mean (the protocol's own).
        tag: u32,
        /// The numbers.
        data: [f64; WORDS],
    },
    /// The coordinator grants the receiver its motion. `told` is how many other agents'
    /// [`Message::Occupancy`] the coordinator sent before it: the grant counts only once the
    /// receiver has heard of that many (a grant must not outrun what it depends on when
    /// messages are lost).
    Grant {
        /// Other agents whose occupancy the receiver must know first.
        told: usize,
    },
    /// The receiver of a [`Message::Grant`] acknowledges it (the coordinator sends the grant
    /// again until it hears from the agent).
    GrantAck,
    /// The sender finished its task (`failed`: without reaching its goal).
    Done {
        /// Whether the task failed.
        failed: bool,
    },
    /// Scenario agent `agent` occupies `configurations` (one: its body at rest; several: the
    /// sweep of its plan, waypoint by waypoint).
    Occupancy {
        /// Index of the agent in its system.
        agent: usize,
        /// The configurations, shared (sending does not copy them).
        configurations: std::sync::Arc<[Vec<f64>]>,
    },
    /// The coordinator hands the receiver operator `index` of a task plan, to start now: its
    /// certified motion, from where the receiver's previous operator ended.
    Operator {
        /// Index in the task plan.
        index: usize,
        /// The ground operator, for the log.
        name: std::sync::Arc<str>,
        /// The motion (shared: sending does not copy it).
        trajectory: std::sync::Arc<embodied_planner::trajectory::Trajectory>,
    },
    /// The sender started operator `index` of the task plan.
    OperatorStarted {
        /// Index in the task plan.
        index: usize,
    },
    /// The sender finished operator `index` of the task plan.
    OperatorDone {
        /// Index in the task plan.
        index: usize,
    },
}

impl Message {
    /// A [`Message::Words`] with `tag` and the first `values` (at most [`WORDS`]; extra values
    /// are dropped).
    pub fn new(tag: u32, values: &[f64]) -> Self {
        let mut data = [0.0; WORDS];
        for (d, v) in data.iter_mut().zip(values) {
            *d = *v;
        }
        Message::Words { tag, data }
    }

    /// The tag of a [`Message::Words`].
    pub fn tag(&self) -> Option<u32> {
        match self {
            Message::Words { tag, .. } => Some(*tag),
            _ => None,
        }
    }

    /// Word `k` of a [`Message::Words`] (0 for other messages or beyond [`WORDS`]).
    pub fn word(&self, k: usize) -> f64 {
        match self {
            Message::Words { data, .. } => data.get(k).copied().unwrap_or(0.0),
            _ => 0.0,
        }
    }
}

/// A message with its sender and receiver.
#[derive(Debug, Clone, PartialEq)]
pub struct Envelope {
    /// The sender.
    pub from: AgentId,
    /// The receiver.
    pub to: AgentId,
    /// What it says.
    pub message: Message,
}

/// One virtual sensor reading `v_{j_k}` (eq. 3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reading {
    /// The values; only the first `len` are meaningful.
    pub values: [f64; WORDS],
    /// How many of `values` are meaningful.
    pub len: usize,
    /// Whether the reading was taken in this step (sensors with a period > 1 keep the previous
    /// reading in between, marked stale).
    pub fresh: bool,
}

impl Default for Reading {
    fn default() -> Self {
        Self { values: [0.0; WORDS], len: 0, fresh: false }
    }
}

impl Reading {
    /// A fresh reading holding the first [`WORDS`] of `values`.
    pub fn new(values: &[f64]) -> Self {
        let mut r = Self { fresh: true, ..Self::default() };
        for (d, v) in r.values.iter_mut().zip(values) {
            *d = *v;
        }
        r.len = values.len().min(WORDS);
        r
    }
    /// The meaningful values.
    pub fn as_slice(&self) -> &[f64] {
        &self.values[..self.len]
    }
}

/// A sphere-shaped region of interest in world coordinates.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Region {
    /// Centre, m (world frame).
    pub center: [f64; 3],
    /// Radius, m.
    pub radius: f64,
}

impl Region {
    /// The whole world.
    pub const EVERYWHERE: Region = Region { center: [0.0; 3], radius: f64::INFINITY };
    /// Whether `p` (world frame, m) lies in the region (the boundary included).
    pub fn contains(&self, p: &[f64; 3]) -> bool {
        let d2: f64 = (0..3).map(|k| (p[k] - self.center[k]).powi(2)).sum();
        d2 <= self.radius * self.radius
    }
}

/// The configuration part of a virtual sensor's image (`c_V` holds reading and configuration).
/// Written through [`OutputImages::configure_sensor`] (`c^{i+1}_V ≻ V_j`), in force from the next step.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SensorConfig {
    /// Read every `period` steps (MRROC++'s `base_period`); 0 disables the sensor.
    pub period: u32,
    /// Region of interest.
    pub region: Region,
    /// A sensor-specific threshold (e.g. contact force).
    pub threshold: f64,
}

impl Default for SensorConfig {
    fn default() -> Self {
        Self { period: 1, region: Region::EVERYWHERE, threshold: 0.0 }
    }
}

/// Virtual sensor image: last reading and current configuration.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SensorImage {
    /// The last reading.
    pub reading: Reading,
    /// The configuration in force.
    pub config: SensorConfig,
}

/// How the servo interprets a [`JointCommand`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum CommandMode {
    /// Track position `q` with feed-forward velocity `qd`.
    Position,
    /// Track velocity `qd`; `q` is ignored.
    Velocity,
}

/// The effector command `c^{i+1}_e`: joint position/velocity targets.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct JointCommand {
    /// How the servo interprets `q` and `qd`.
    pub mode: CommandMode,
    /// Joint position targets (rad or m).
    pub q: Vec<f64>,
    /// Joint velocity targets or feed-forward (rad/s or m/s).
    pub qd: Vec<f64>,
}

impl JointCommand {
    /// Hold position `q` at rest.
    pub fn hold(q: &[f64]) -> Self {
        Self { mode: CommandMode::Position, q: q.to_vec(), qd: vec![0.0; q.len()] }
    }
    /// Number of joints.
    pub fn dof(&self) -> usize {
        self.q.len()
    }
}

/// The input images `c^i = <c^i_e, c^i_V, c^i_T>` plus the step counter: a read-only view.
#[derive(Debug, Clone)]
pub struct InputImages {
    pub(crate) agent: AgentId,
    pub(crate) step: u64,
    pub(crate) dt: f64,
    pub(crate) q: Vec<f64>,
    pub(crate) qd: Vec<f64>,
    pub(crate) limits: Vec<JointLimits>,
    pub(crate) sensors: Vec<SensorImage>,
    pub(crate) inbox: Vec<Envelope>,
    /// Where the last limited command asked the effector to be now (empty before the first).
    pub(crate) q_commanded: Vec<f64>,
}

impl InputImages {
    pub(crate) fn new(agent: AgentId, limits: Vec<JointLimits>, n_sensors: usize, dt: f64) -> Self {
        let dof = limits.len();
        Self {
            agent,
            step: 0,
            dt,
            q: vec![0.0; dof],
            qd: vec![0.0; dof],
            limits,
            sensors: vec![SensorImage::default(); n_sensors],
            // Grown on the first delivery and kept: an agent that never receives messages keeps
            // no 1.4 kB buffer between its hot data (1,000 agents stay in cache).
            inbox: Vec::new(),
            q_commanded: Vec::new(),
        }
    }
    /// This agent.
    pub fn agent(&self) -> AgentId {
        self.agent
    }
    /// The step index `i`.
    pub fn step(&self) -> u64 {
        self.step
    }
    /// Control period in seconds.
    pub fn dt(&self) -> f64 {
        self.dt
    }
    /// Effector image: the positions the last (limited) command asked the effector to reach by
    /// now (`None` before the first command and for a coordinator). A healthy effector is
    /// there to rounding; see [`crate::effector::tracking_bound`].
    pub fn q_commanded(&self) -> Option<&[f64]> {
        (!self.q_commanded.is_empty()).then_some(&self.q_commanded[..])
    }
    /// Effector image: measured joint positions (`c^i_e`; empty for a coordinator).
    pub fn q(&self) -> &[f64] {
        &self.q
    }
    /// Effector image: measured joint velocities.
    pub fn qd(&self) -> &[f64] {
        &self.qd
    }
    /// The effector's joint limits.
    pub fn limits(&self) -> &[JointLimits] {
        &self.limits
    }
    /// Number of degrees of freedom of the effector (0 for a coordinator).
    pub fn dof(&self) -> usize {
        self.q.len()
    }
    /// Virtual sensor image `k` (`c^i_{V,k}`). Out of range gives an empty, stale reading.
    pub fn sensor(&self, k: usize) -> &Reading {
        static EMPTY: Reading = Reading { values: [0.0; WORDS], len: 0, fresh: false };
        self.sensors.get(k).map_or(&EMPTY, |s| &s.reading)
    }
    /// Configuration in force for virtual sensor `k`.
    pub fn sensor_config(&self, k: usize) -> Option<&SensorConfig> {
        self.sensors.get(k).map(|s| &s.config)
    }
    /// Number of virtual sensors.
    pub fn sensor_count(&self) -> usize {
        self.sensors.len()
    }
    /// Messages delivered in this step (`c^i_T`), in a deterministic order.
    pub fn messages(&self) -> &[Envelope] {
        &self.inbox
    }
}

/// The output images `c^{i+1} = <c^{i+1}_e, c^{i+1}_V, c^{i+1}_T>`: write-only for transition
/// functions (setters only), read by the runtime when it transmits them.
///
/// A transition function cannot read back what it wrote:
/// ```compile_fail
/// fn peek(o: &embodied_executor::OutputImages) -> f64 {
///     o.command.q[0]
/// }
/// ```
/// and cannot write an input image:
/// ```compile_fail
/// fn poke(i: &mut embodied_executor::InputImages) {
///     i.q()[0] = 1.0;
/// }
/// ```
#[derive(Debug, Clone)]
pub struct OutputImages {
    pub(crate) has_command: bool,
    pub(crate) command: JointCommand,
    pub(crate) sensor_configs: Vec<Option<SensorConfig>>,
    pub(crate) outbox: Vec<Envelope>,
    pub(crate) events: Vec<crate::Event>,
    pub(crate) from: AgentId,
    /// First misuse of a setter in this step (what, expected, got).
    pub(crate) misuse: Option<(&'static str, usize, usize)>,
}

impl OutputImages {
    pub(crate) fn new(from: AgentId, dof: usize, n_sensors: usize) -> Self {
        Self {
            has_command: false,
            command: JointCommand { mode: CommandMode::Position, q: vec![0.0; dof], qd: vec![0.0; dof] },
            sensor_configs: vec![None; n_sensors],
            outbox: Vec::new(),
            events: Vec::new(),
            from,
            misuse: None,
        }
    }

    /// `clear(^q c^{i+1})` of eq. (14).
    pub(crate) fn clear(&mut self) {
        self.has_command = false;
        self.sensor_configs.iter_mut().for_each(|c| *c = None);
        self.outbox.clear();
        self.events.clear();
        self.misuse = None;
    }

    fn check_len(&mut self, what: &'static str, got: usize) -> bool {
        let expected = self.command.q.len();
        if got != expected {
            self.misuse.get_or_insert((what, expected, got));
            return false;
        }
        true
    }

    /// Command joint positions `q` with feed-forward velocities `qd`.
    pub fn set_position_target(&mut self, q: &[f64], qd: &[f64]) {
        if self.check_len("position target", q.len()) && self.check_len("feed-forward velocity", qd.len()) {
            self.command.mode = CommandMode::Position;
            self.command.q.copy_from_slice(q);
            self.command.qd.copy_from_slice(qd);
            self.has_command = true;
        }
    }

    /// Command joint velocities.
    pub fn set_velocity_target(&mut self, qd: &[f64]) {
        if self.check_len("velocity target", qd.len()) {
            self.command.mode = CommandMode::Velocity;
            self.command.qd.copy_from_slice(qd);
            self.command.q.iter_mut().for_each(|v| *v = 0.0);
            self.has_command = true;
        }
    }

    /// Command a whole [`JointCommand`].
    pub fn set_command(&mut self, command: &JointCommand) {
        if self.check_len("joint command", command.q.len()) && self.check_len("joint command", command.qd.len()) {
            self.command.mode = command.mode;
            self.command.q.copy_from_slice(&command.q);
            self.command.qd.copy_from_slice(&command.qd);
            self.has_command = true;
        }
    }

    /// Reconfigure virtual sensor `k` from the next step on (`c^{i+1}_V`).
    pub fn configure_sensor(&mut self, k: usize, config: SensorConfig) {
        let n = self.sensor_configs.len();
        match self.sensor_configs.get_mut(k) {
            Some(slot) => *slot = Some(config),
            None => {
                self.misuse.get_or_insert(("sensor index", n, k));
            }
        }
    }

    /// Send `message` to agent `to` (`c^{i+1}_T`).
    pub fn send(&mut self, to: AgentId, message: Message) {
        self.outbox.push(Envelope { from: self.from, to, message });
    }

    /// Note an event in this step's log record (a typed [`crate::Event`], or a user's text
    /// as [`crate::Event::Note`]).
    pub fn event(&mut self, event: impl Into<crate::Event>) {
        self.events.push(event.into());
    }

    /// Copy the non-effector parts (sensor configuration, messages, events) of `other` in; the
    /// first writer of a sensor configuration wins.
    pub(crate) fn merge_side_channels(&mut self, other: &OutputImages) {
        for (mine, theirs) in self.sensor_configs.iter_mut().zip(&other.sensor_configs) {
            if mine.is_none() {
                *mine = *theirs;
            }
        }
        self.outbox.extend_from_slice(&other.outbox);
        self.events.extend(other.events.iter().cloned());
        if self.misuse.is_none() {
            self.misuse = other.misuse;
        }
    }
}
