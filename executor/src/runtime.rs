//! The multi-agent runtime: steps every agent through eq. (10)/(14) in lock step, routes the
//! transmissions, advances the simulated world and produces one log record per step.
//!
//! A step of the runtime, for step index `i`:
//! 1. deliver the messages due at `i` into the receivers' `c^i_T`;
//! 2. every agent reads its images, chooses and computes `c^{i+1}`, and transmits `c^{i+1}_e` to
//!    its effector and `c^{i+1}_V` to its virtual sensors (agents are independent here, so this
//!    phase may run on several threads);
//! 3. `c^{i+1}_T` of every agent enters the transmitter, in agent order;
//! 4. the world advances by `dt`.
//!
//! Everything is deterministic for a given seed whatever the thread count: each agent and each
//! channel draws from its own random stream, and cross-agent work happens in agent order.

use rayon::prelude::*;

use crate::agent::{Agent, AgentRecord, Steppable};
use crate::error::ExecutorError;
use crate::image::{AgentId, InputImages};
use crate::transmitter::{ChannelStats, Link, Transmitter};
use crate::world::World;

/// Whether to step agents on several threads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Parallelism {
    /// Step every agent on the calling thread.
    Sequential,
    /// Use rayon when there are at least `min_agents` agents (a fork-join costs tens of
    /// microseconds, so small systems are faster on one thread).
    Rayon {
        /// Fewest agents for which the step runs on several threads.
        min_agents: usize,
    },
}

/// Runtime settings.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RuntimeConfig {
    /// Control period, seconds.
    pub dt: f64,
    /// Seed of all noise and losses.
    pub seed: u64,
    /// Whether to step agents on several threads.
    pub parallelism: Parallelism,
    /// Fill the per-step [`StepRecord`] (off saves a little time in benchmarks).
    pub record: bool,
    /// With [`Parallelism::Rayon`]: tasks per thread in one step (default 1, i.e. one contiguous
    /// chunk of agents per thread and a single fork-join). More tasks let an idle thread take
    /// over work from one the OS has descheduled, at the price of more hand-overs.
    #[serde(default = "one_task")]
    pub tasks_per_thread: usize,
}

fn one_task() -> usize {
    1
}

impl Default for RuntimeConfig {
    fn default() -> Self {
        Self {
            dt: 0.001,
            seed: 0,
            parallelism: Parallelism::Rayon { min_agents: 256 },
            record: true,
            tasks_per_thread: 1,
        }
    }
}

/// The log record of one step (one line of JSON Lines).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StepRecord {
    /// Index of the step, from 0.
    pub step: u64,
    /// Time at the end of the step, seconds.
    pub time: f64,
    /// One record per agent.
    pub agents: Vec<AgentRecord>,
    /// The step's smallest distances between robots and from robots to the environment,
    /// when the runtime has a [`StepMonitor`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clearance: Option<Clearance>,
}

/// The smallest distances of one step (m, signed: negative is penetration), measured after
/// the step: between the shapes of any two robots, and between any robot's shapes and the
/// obstacles present. `None` where there is no such pair.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Clearance {
    /// Smallest distance between two agents' bodies.
    pub robot_robot_m: Option<f64>,
    /// Smallest distance between an agent's body and an obstacle.
    pub robot_environment_m: Option<f64>,
}

/// What the runtime consults after every step about the agents' bodies (it knows their
/// geometry, the runtime does not): where the bodies are, for the other agents' receptors, and
/// the step's [`Clearance`].
pub trait StepMonitor: Send {
    /// The agents' bodies at their joints after the step (`agents`: this step's records).
    fn bodies(&mut self, agents: &[AgentRecord], out: &mut Vec<crate::world::Body>);
    /// The step's clearance; `world` is at the step's end.
    fn clearance(&mut self, world: &World, agents: &[AgentRecord]) -> Clearance;
}

/// Bound on halting steps after a failure in [`Runtime::run`].
pub const MAX_HALT_STEPS: u64 = 100_000;

/// A system of agents in a simulated world.
pub struct Runtime {
    config: RuntimeConfig,
    agents: Vec<Box<dyn Steppable>>,
    world: World,
    transmitter: Transmitter,
    step: u64,
    record: StepRecord,
    failure: Option<ExecutorError>,
    /// Agents whose inbox received messages in the last delivery (cleared at the next one).
    filled_inboxes: Vec<usize>,
    monitor: Option<Box<dyn StepMonitor>>,
}

impl Runtime {
    /// An empty system with `config` (a `dt` that is not a positive finite number becomes 0.001 s).
    pub fn new(config: RuntimeConfig) -> Self {
        let dt = if config.dt.is_finite() && config.dt > 0.0 { config.dt } else { 0.001 };
        Self {
            config: RuntimeConfig { dt, ..config },
            agents: Vec::new(),
            world: World::new(),
            transmitter: Transmitter::new(),
            step: 0,
            record: StepRecord::default(),
            failure: None,
            filled_inboxes: Vec::new(),
            monitor: None,
        }
    }

    /// Let `monitor` place the agents' bodies in the world and measure every step's
    /// [`Clearance`] (needs [`RuntimeConfig::record`]: it reads the step's records).
    pub fn set_monitor(&mut self, monitor: Box<dyn StepMonitor>) {
        self.monitor = Some(monitor);
    }

    /// Add an agent; ids are given in order of addition, starting at 0.
    pub fn add_agent<C: Send + 'static>(&mut self, mut agent: Agent<C>) -> AgentId {
        let id = AgentId(self.agents.len());
        let seed = self.stream_seed(1, id.0 as u64);
        agent.prepare(id, self.config.dt, seed);
        self.agents.push(Box::new(agent));
        self.record.agents.push(AgentRecord::default());
        id
    }

    fn stream_seed(&self, kind: u64, index: u64) -> u64 {
        let mut rng = embodied_models::Rng::new(self.config.seed ^ kind.wrapping_mul(0x9E37_79B9_7F4A_7C15));
        rng.fork(index).next_u64()
    }

    /// The id of the agent called `name`.
    pub fn agent_id(&self, name: &str) -> Option<AgentId> {
        self.agents.iter().position(|a| a.name() == name).map(AgentId)
    }

    /// Number of agents.
    pub fn agent_count(&self) -> usize {
        self.agents.len()
    }

    /// Open the channel `from -> to`.
    pub fn connect(&mut self, from: AgentId, to: AgentId, link: Link) -> Result<(), ExecutorError> {
        for id in [from, to] {
            if id.0 >= self.agents.len() {
                return Err(ExecutorError::Unknown { what: "agent", name: format!("#{}", id.0) });
            }
        }
        let k = self.transmitter.links().count() as u64;
        let seed = self.stream_seed(2, k);
        self.transmitter.connect(from, to, link, seed);
        Ok(())
    }

    /// Open channels both ways.
    pub fn connect_both(&mut self, a: AgentId, b: AgentId, link: Link) -> Result<(), ExecutorError> {
        self.connect(a, b, link)?;
        self.connect(b, a, link)
    }

    /// Inject link faults into every channel ([`crate::transmitter::LinkFaults`]).
    pub fn set_link_faults(&mut self, faults: Box<dyn crate::transmitter::LinkFaults>) {
        self.transmitter.set_faults(faults);
    }

    /// Counters of the channel `from -> to`; `None` if there is none.
    pub fn channel_stats(&self, from: AgentId, to: AgentId) -> Option<ChannelStats> {
        self.transmitter.stats(from, to)
    }

    /// The world outside the agents.
    pub fn world(&self) -> &World {
        &self.world
    }
    /// The world outside the agents, to change it.
    pub fn world_mut(&mut self) -> &mut World {
        &mut self.world
    }
    /// The runtime settings.
    pub fn config(&self) -> &RuntimeConfig {
        &self.config
    }
    /// Index of the next step to run.
    pub fn current_step(&self) -> u64 {
        self.step
    }
    /// The error that stopped the run, if any.
    pub fn failure(&self) -> Option<&ExecutorError> {
        self.failure.as_ref()
    }
    /// The record of the last step run (also after a failing step).
    pub fn last_record(&self) -> &StepRecord {
        &self.record
    }
    /// Agent `id`'s input images `c^i` as of the last step (its measured joints, sensor
    /// readings and delivered messages), or `None` for an unknown id.
    pub fn images(&self, id: AgentId) -> Option<&InputImages> {
        self.agents.get(id.0).map(|a| a.images())
    }
    /// Whether every effector is at rest.
    pub fn is_at_rest(&self) -> bool {
        self.agents.iter().all(|a| a.is_at_rest())
    }

    fn parallel(&self) -> bool {
        match self.config.parallelism {
            Parallelism::Sequential => false,
            Parallelism::Rayon { min_agents } => {
                self.agents.len() >= min_agents.max(2) && rayon::current_num_threads() > 1
            }
        }
    }

    /// `c_T ≻ c^i_T`: empty last step's inboxes (only those that received anything) and deliver
    /// the messages due now.
    fn deliver(&mut self) {
        for &k in &self.filled_inboxes {
            if let Some(a) = self.agents.get_mut(k) {
                a.inbox().clear();
            }
        }
        self.filled_inboxes.clear();
        let (agents, filled) = (&mut self.agents, &mut self.filled_inboxes);
        self.transmitter.deliver(self.step, |to, env| {
            if let Some(a) = agents.get_mut(to.0) {
                a.inbox().push(env);
                filled.push(to.0);
            }
        });
    }

    /// Phase 2 of a step for every agent, each followed by its log record when recording (in
    /// the same pass, while the agent is in cache). Returns whether any agent has an error or
    /// outgoing messages to collect. In parallel the agents are cut into contiguous chunks,
    /// [`RuntimeConfig::tasks_per_thread`] per thread (by default one: a single fork-join).
    fn step_agents(&mut self) -> bool {
        let (world, step, dt, record) = (&self.world, self.step, self.config.dt, self.config.record);
        let one = |a: &mut Box<dyn Steppable>, rec: &mut AgentRecord| {
            let pending = a.step(world, step, dt);
            if record {
                a.record(rec);
            }
            pending
        };
        let chunk = |agents: &mut [Box<dyn Steppable>], recs: &mut [AgentRecord]| {
            agents.iter_mut().zip(recs.iter_mut()).fold(false, |any, (a, r)| one(a, r) | any)
        };
        if self.parallel() {
            let tasks = rayon::current_num_threads().saturating_mul(self.config.tasks_per_thread.max(1));
            let size = self.agents.len().div_ceil(tasks).max(1);
            self.agents
                .par_chunks_mut(size)
                .zip(self.record.agents.par_chunks_mut(size))
                .map(|(agents, recs)| chunk(agents, recs))
                .reduce(|| false, |a, b| a | b)
        } else {
            chunk(&mut self.agents, &mut self.record.agents)
        }
    }

    /// Run one control step. On a specification error the failing agent has already begun a
    /// safe halt, the record of this step is in [`Runtime::last_record`], and the error is
    /// returned; afterwards `step` refuses to run (call [`Runtime::halt_step`]).
    pub fn step(&mut self) -> Result<&StepRecord, ExecutorError> {
        if let Some(f) = &self.failure {
            return Err(f.clone());
        }
        self.deliver();
        let step = self.step;
        let pending = self.step_agents();
        let mut failure = None;
        if pending {
            for a in &mut self.agents {
                if let Some(e) = a.take_error() {
                    failure.get_or_insert(e);
                }
            }
            for agent in &mut self.agents {
                let mut unconnected = None;
                for env in agent.outbox().drain(..) {
                    let to = env.to.0;
                    if !self.transmitter.send(env, step) {
                        unconnected.get_or_insert(to);
                    }
                }
                if let Some(to) = unconnected
                    && failure.is_none()
                {
                    failure = Some(ExecutorError::NoChannel { agent: agent.name().to_string(), step, to });
                }
            }
        }
        self.finish_step(true);
        match failure {
            Some(e) => {
                self.failure = Some(e.clone());
                Err(e)
            }
            None => Ok(&self.record),
        }
    }

    /// Advance the world and close the step's record (`agents_recorded`: the agents' lines are
    /// already written).
    fn finish_step(&mut self, agents_recorded: bool) {
        self.world.advance(self.config.dt);
        if self.config.record {
            self.record.step = self.step;
            self.record.time = (self.step + 1) as f64 * self.config.dt;
            if !agents_recorded {
                for (a, rec) in self.agents.iter().zip(&mut self.record.agents) {
                    a.record(rec);
                }
            }
            if let Some(m) = self.monitor.as_mut() {
                m.bodies(&self.record.agents, self.world.bodies_mut());
                self.record.clearance = Some(m.clearance(&self.world, &self.record.agents));
            }
        }
        self.step += 1;
    }

    /// One step in which every agent makes a controlled stop (the behaviours are not consulted).
    pub fn halt_step(&mut self) -> &StepRecord {
        self.deliver();
        let (world, step, dt) = (&self.world, self.step, self.config.dt);
        for a in &mut self.agents {
            a.halt_step(world, step, dt);
        }
        self.finish_step(false);
        &self.record
    }

    /// Run `steps` steps, handing each record to `on_record`. On failure, keep stepping with a
    /// safe halt until every effector is at rest (handing those records on too), then return the
    /// error.
    pub fn run(&mut self, steps: u64, mut on_record: impl FnMut(&StepRecord)) -> Result<(), ExecutorError> {
        for _ in 0..steps {
            match self.step() {
                Ok(rec) => on_record(rec),
                Err(e) => {
                    if self.current_step() > 0 && self.record.step + 1 == self.current_step() {
                        on_record(&self.record);
                    }
                    let mut n = 0;
                    while !self.is_at_rest() && n < MAX_HALT_STEPS {
                        on_record(self.halt_step());
                        n += 1;
                    }
                    return Err(e);
                }
            }
        }
        Ok(())
    }
}
