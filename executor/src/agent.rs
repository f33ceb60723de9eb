//! The embodied agent `a_j` with state `s_j = <c_j, e_j, V_j, T_j>` (eq. 1), its control
//! subsystem `c_j` (eq. 7), and the coordinator (an agent without an effector).

use std::sync::Arc;

use embodied_models::{Rng, Robot};

use crate::behaviour::Behaviour;
use crate::effector::{Effector, SafeHalt, SafetyLimiter, ServoModel};
use crate::error::ExecutorError;
use crate::image::{AgentId, Envelope, InputImages, JointCommand, OutputImages, SensorConfig, SensorImage};
use crate::sensor::VirtualSensor;
use crate::world::{ReceptorReadings, ReceptorSpec, Receptors, World};

/// The control subsystem `c_j = <c_c, c^i_e, c^{i+1}_e, c^i_V, c^{i+1}_V, c^i_T, c^{i+1}_T>`
/// (eq. 7): the internal variables `c_c` (a user type, e.g. holding the current plan; one
/// representation) and the double-buffered images, inputs and outputs kept apart.
pub struct ControlSubsystem<C> {
    /// `c_c`.
    pub internal: C,
    inputs: InputImages,
    outputs: OutputImages,
}

impl<C> ControlSubsystem<C> {
    /// The input images of the last step (`c^i`).
    pub fn inputs(&self) -> &InputImages {
        &self.inputs
    }
}

/// An embodied agent: control subsystem `c_j`, optional effector `e_j` (always behind a
/// [`SafetyLimiter`]), virtual sensors `V_j`, receptors `R`, and the behaviour that is its
/// program (eq. 6). Transmissions `T_j` are routed by the [`crate::Runtime`].
pub struct Agent<C> {
    name: String,
    control: ControlSubsystem<C>,
    effector: Option<SafetyLimiter<Box<dyn Effector>>>,
    sensors: Vec<(Box<dyn VirtualSensor>, SensorConfig)>,
    countdown: Vec<u32>,
    receptors: Receptors,
    readings: ReceptorReadings,
    behaviour: Box<dyn Behaviour<C>>,
    halting: bool,
    error: Option<ExecutorError>,
    halt_command: JointCommand,
}

/// A coordinator: an abstract agent (no effector, no body) with virtual sensors of its own that
/// commands other agents through transmissions; coordinators can command coordinators, forming
/// hierarchies.
pub struct Coordinator;

impl Coordinator {
    /// An agent without an effector. Give it a global camera with
    /// `.with_receptors(ReceptorSpec { detector_range: Some(f64::INFINITY), .. })` if it should see.
    #[allow(clippy::new_ret_no_self)]
    pub fn new<C: Send + 'static>(
        name: impl Into<String>,
        internal: C,
        behaviour: impl Behaviour<C> + 'static,
    ) -> Agent<C> {
        Agent::new(name, internal, behaviour)
    }
}

impl<C: Send + 'static> Agent<C> {
    /// An agent without an effector yet (a coordinator unless one is added).
    pub fn new(name: impl Into<String>, internal: C, behaviour: impl Behaviour<C> + 'static) -> Self {
        Self {
            name: name.into(),
            control: ControlSubsystem {
                internal,
                inputs: InputImages::new(AgentId(0), Vec::new(), 0, 0.001),
                outputs: OutputImages::new(AgentId(0), 0, 0),
            },
            effector: None,
            sensors: Vec::new(),
            countdown: Vec::new(),
            receptors: Receptors { spec: ReceptorSpec::default(), robot: None, rng: Rng::new(0), own: None },
            readings: ReceptorReadings::default(),
            behaviour: Box::new(behaviour),
            halting: false,
            error: None,
            halt_command: JointCommand::hold(&[]),
        }
    }

    /// An agent embodied in a simulated `robot`: a [`ServoModel`] starting at `q0` (the robot's
    /// home when `None`), with the robot model placing the force sensor and obstacle detector at
    /// its first end effector.
    pub fn embodied(
        name: impl Into<String>,
        robot: Arc<Robot>,
        q0: Option<&[f64]>,
        internal: C,
        behaviour: impl Behaviour<C> + 'static,
    ) -> Result<Self, ExecutorError> {
        let servo = ServoModel::new(robot.limits(), q0.unwrap_or(robot.home()))?;
        let mut agent = Self::new(name, internal, behaviour).with_effector(servo)?;
        if let Some(e) = agent.effector.take() {
            agent.effector = Some(e.with_actuators(robot.actuators().to_vec()));
        }
        agent.receptors.robot = Some((robot, 0));
        Ok(agent)
    }

    /// Give the agent an effector (wrapped in a [`SafetyLimiter`]).
    pub fn with_effector(mut self, effector: impl Effector + 'static) -> Result<Self, ExecutorError> {
        crate::effector::validate_limits(effector.limits())?;
        let boxed: Box<dyn Effector> = Box::new(effector);
        self.effector = Some(SafetyLimiter::new(boxed));
        Ok(self)
    }

    /// Add virtual sensor `k = number of sensors so far` with its initial configuration.
    pub fn with_sensor(mut self, sensor: impl VirtualSensor + 'static, config: SensorConfig) -> Self {
        self.sensors.push((Box::new(sensor), config));
        self
    }

    /// Set which receptors the agent has.
    pub fn with_receptors(mut self, spec: ReceptorSpec) -> Self {
        self.receptors.spec = spec;
        self
    }

    /// Use `robot`'s end effector `ee` as the sensing point.
    pub fn with_robot_model(mut self, robot: Arc<Robot>, ee: usize) -> Self {
        self.receptors.robot = Some((robot, ee));
        self
    }
}

impl<C> Agent<C> {
    /// The agent's name.
    pub fn name(&self) -> &str {
        &self.name
    }
    /// `c_c`.
    pub fn internal(&self) -> &C {
        &self.control.internal
    }
    /// The control subsystem `c_j`: `c_c` and the input and output images.
    pub fn control(&self) -> &ControlSubsystem<C> {
        &self.control
    }
    /// Whether the agent has an effector (a coordinator has none).
    pub fn is_embodied(&self) -> bool {
        self.effector.is_some()
    }
}

/// One agent's line in the per-step log.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AgentRecord {
    /// The agent's name.
    pub agent: String,
    /// Joint positions after the step (empty for a coordinator).
    pub q: Vec<f64>,
    /// Joint velocities after the step (empty for a coordinator).
    pub qd: Vec<f64>,
    /// Path of the active behaviour, e.g. `main/avoid`.
    pub behaviour: String,
    /// What happened in this step.
    pub events: Vec<crate::Event>,
}

/// The object-safe face of an agent that the runtime steps.
pub(crate) trait Steppable: Send {
    fn name(&self) -> &str;
    fn prepare(&mut self, id: AgentId, dt: f64, seed: u64);
    fn inbox(&mut self) -> &mut Vec<Envelope>;
    fn outbox(&mut self) -> &mut Vec<Envelope>;
    /// One iteration of eq. (10); a specification error leaves a safe-halt command executed and
    /// the error stored. Returns whether there is an error or an outgoing message to collect.
    fn step(&mut self, world: &World, step: u64, dt: f64) -> bool;
    fn take_error(&mut self) -> Option<ExecutorError>;
    /// Sense and execute a safe halt without consulting the behaviour.
    fn halt_step(&mut self, world: &World, step: u64, dt: f64);
    fn is_at_rest(&self) -> bool;
    fn record(&self, rec: &mut AgentRecord);
    /// The input images `c^i` of the last step.
    fn images(&self) -> &InputImages;
}

impl<C: Send> Agent<C> {
    /// `e_j ≻ c^i_e; V_j ≻ c^i_V` (the inbox, `c_T ≻ c^i_T`, is filled by the runtime).
    fn read_images(&mut self, world: &World, step: u64) {
        let inputs = &mut self.control.inputs;
        inputs.step = step;
        // One (doubly dynamic) call each for the measured state.
        let (q, qd) = match &self.effector {
            Some(e) => (e.q(), e.qd()),
            None => (&[][..], &[][..]),
        };
        if !q.is_empty() {
            inputs.q.copy_from_slice(q);
            inputs.qd.copy_from_slice(qd);
        }
        if let Some(c) = self.effector.as_ref().and_then(|e| e.commanded_position()) {
            inputs.q_commanded.clear();
            inputs.q_commanded.extend_from_slice(c);
        }
        self.receptors.sample(world, q, qd, &mut self.readings);
        for (k, (sensor, _)) in self.sensors.iter_mut().enumerate() {
            let image = &mut inputs.sensors[k];
            image.reading.fresh = false;
            if image.config.period == 0 {
                continue;
            }
            if self.countdown[k] <= 1 {
                let reading = sensor.aggregate(&image.config, &self.readings);
                if !sensor.dropped_out() {
                    image.reading = reading;
                    image.reading.fresh = true;
                }
                self.countdown[k] = image.config.period;
            } else {
                self.countdown[k] -= 1;
            }
        }
    }

    /// One iteration of eq. (10): read the images, choose and compute `c^{i+1}`, hand
    /// `c^{i+1}_V` to the virtual sensors and `c^{i+1}_e` to the effector.
    fn step_once(&mut self, world: &World, step: u64, dt: f64) {
        self.read_images(world, step);
        let ctl = &mut self.control;
        ctl.outputs.clear();
        let result = self.behaviour.step(&mut ctl.internal, &ctl.inputs, &mut ctl.outputs);
        let error = match result {
            Err(v) => Some(v.into_error(&self.name, step)),
            Ok(_) => ctl.outputs.misuse.map(|(what, expected, got)| ExecutorError::DimensionMismatch {
                what: format!("agent '{}' at step {step}: {what}", self.name),
                expected,
                got,
            }),
        };
        if let Some(e) = error {
            ctl.outputs.outbox.clear();
            ctl.outputs.event(crate::Event::SpecificationError { message: e.to_string() });
            self.error = Some(e);
            self.halting = true;
            self.execute_halt(dt);
            return;
        }
        // c^{i+1}_V ≻ V_j: new configurations take effect from the next step.
        for (k, new) in ctl.outputs.sensor_configs.iter().enumerate() {
            if let Some(config) = new {
                ctl.inputs.sensors[k].config = *config;
                self.countdown[k] = 1;
            }
        }
        // c^{i+1}_e ≻ e_j; no command means a controlled stop.
        if ctl.outputs.has_command {
            if let Some(e) = &mut self.effector {
                e.execute(&ctl.outputs.command, dt);
            }
        } else {
            self.execute_halt(dt);
        }
    }
    fn execute_halt(&mut self, dt: f64) {
        if let Some(e) = &mut self.effector {
            SafeHalt::command_into(e.q(), e.qd(), e.limits(), dt, &mut self.halt_command);
            e.execute(&self.halt_command, dt);
        }
    }
}

impl<C: Send> Steppable for Agent<C> {
    fn name(&self) -> &str {
        &self.name
    }
    fn prepare(&mut self, id: AgentId, dt: f64, seed: u64) {
        let limits = self.effector.as_ref().map(|e| e.limits().to_vec()).unwrap_or_default();
        let dof = limits.len();
        let n = self.sensors.len();
        self.control.inputs = InputImages::new(id, limits, n, dt);
        for (k, (_, config)) in self.sensors.iter().enumerate() {
            self.control.inputs.sensors[k] = SensorImage { reading: Default::default(), config: *config };
        }
        self.countdown = vec![1; n];
        self.control.outputs = OutputImages::new(id, dof, n);
        self.receptors.rng = Rng::new(seed);
        self.receptors.own = Some(id.0);
        self.halt_command = JointCommand::hold(&vec![0.0; dof]);
        if let Some(e) = &self.effector {
            self.control.inputs.q.copy_from_slice(e.q());
        }
    }
    fn inbox(&mut self) -> &mut Vec<Envelope> {
        &mut self.control.inputs.inbox
    }
    fn outbox(&mut self) -> &mut Vec<Envelope> {
        &mut self.control.outputs.outbox
    }
    fn step(&mut self, world: &World, step: u64, dt: f64) -> bool {
        self.step_once(world, step, dt);
        self.error.is_some() || !self.control.outputs.outbox.is_empty()
    }
    fn take_error(&mut self) -> Option<ExecutorError> {
        self.error.take()
    }
    fn halt_step(&mut self, world: &World, step: u64, dt: f64) {
        self.read_images(world, step);
        self.control.outputs.clear();
        self.halting = true;
        self.execute_halt(dt);
    }
    fn is_at_rest(&self) -> bool {
        self.effector.as_ref().is_none_or(|e| e.qd().iter().all(|v| *v == 0.0))
    }
    fn images(&self) -> &InputImages {
        &self.control.inputs
    }
    fn record(&self, rec: &mut AgentRecord) {
        // A record slot belongs to one agent for the runtime's life: name it once.
        if rec.agent.is_empty() {
            rec.agent.clone_from(&self.name);
        }
        rec.q.clear();
        rec.qd.clear();
        if let Some(e) = &self.effector {
            rec.q.extend_from_slice(e.q());
            rec.qd.extend_from_slice(e.qd());
        }
        rec.behaviour.clear();
        if self.halting {
            rec.behaviour.push_str("safe-halt");
        } else {
            self.behaviour.describe(&mut rec.behaviour);
        }
        rec.events.clear();
        rec.events.extend(self.control.outputs.events.iter().cloned());
    }
}
