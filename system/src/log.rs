//! The run log: JSON Lines, one header line ([`LogHeader`]), one line per control step
//! ([`LogStep`], with its typed [`Event`]s and its [`Clearance`]: the smallest robot-robot and
//! robot-environment distance after the step), one summary line.
//!
//! Every line is written and flushed as soon as it exists, so a run that fails or is
//! interrupted leaves a valid log up to its last step. The log holds only what the simulation
//! computed: with a simulated planning clock the same scenario and seed give the same bytes
//! (on the same build and target: forward kinematics uses the platform's libm).

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use embodied_executor::{Clearance, Event, StepRecord};
use serde::{Deserialize, Serialize};

use crate::SystemError;

/// Format tag in every log header.
pub const LOG_FORMAT: &str = "embodied-log/2";

/// A joint's limits as the log header states them (`None`: unbounded).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LoggedLimits {
    /// Lower position limit.
    pub lower: Option<f64>,
    /// Upper position limit.
    pub upper: Option<f64>,
    /// Speed limit.
    pub max_velocity: f64,
    /// Acceleration limit.
    pub max_acceleration: f64,
}

/// An agent as the log header describes it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LoggedAgent {
    /// Joint names in the order of `q`.
    pub joint_names: Vec<String>,
    /// Their limits.
    pub limits: Vec<LoggedLimits>,
}

impl LoggedAgent {
    /// The robot's joints and limits.
    pub fn of(robot: &embodied_models::Robot) -> Self {
        let limits = robot
            .limits()
            .iter()
            .map(|l| LoggedLimits {
                lower: l.lower.is_finite().then_some(l.lower),
                upper: l.upper.is_finite().then_some(l.upper),
                max_velocity: l.max_velocity,
                max_acceleration: l.max_acceleration,
            })
            .collect();
        Self { joint_names: robot.joint_names(), limits }
    }
}

/// The first line of a run log.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LogHeader {
    /// [`LOG_FORMAT`].
    #[serde(default)]
    pub format: String,
    /// Version and commit of the program that wrote the log ([`crate::generator`]).
    #[serde(default)]
    pub generator: String,
    /// Scenario name.
    pub scenario: String,
    /// SHA-256 of the scenario text.
    pub scenario_hash: String,
    /// Seed of the simulated noise.
    pub seed: u64,
    /// Control step, s.
    pub step_s: f64,
    /// Simulated time asked for, s.
    pub duration_s: f64,
    /// How planning time was counted.
    pub planning_clock: String,
    /// Every scenario agent's joints and limits, by name.
    pub agents: BTreeMap<String, LoggedAgent>,
    /// The two-handed carry, when the scenario has one.
    #[serde(default)]
    pub closed_chain: Option<serde_json::Value>,
}

/// One agent in one step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LoggedAgentStep {
    /// Joint positions after the step (empty for a coordinator).
    pub q: Vec<f64>,
    /// Joint velocities after the step.
    pub qd: Vec<f64>,
    /// The active behaviour's path.
    pub behaviour: String,
    /// What happened, typed.
    pub events: Vec<Event>,
}

/// One control step of the log.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LogStep {
    /// Step index.
    pub step: u64,
    /// Time at the end of the step, s.
    pub t: f64,
    /// Every agent (the coordinator too), by name.
    pub agents: BTreeMap<String, LoggedAgentStep>,
    /// Smallest distances after the step, m (signed: negative is penetration): between any two
    /// robots' shapes (`robot_robot_m`, absent with one robot) and between any robot's shapes
    /// and the obstacles present at that time (`robot_environment_m`, absent without
    /// obstacles). Absent in logs written without a clearance monitor.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clearance: Option<Clearance>,
}

impl LogStep {
    /// The log line of a runtime record.
    pub fn of(record: &StepRecord) -> Self {
        let agents = record
            .agents
            .iter()
            .map(|a| {
                let step = LoggedAgentStep {
                    q: a.q.clone(),
                    qd: a.qd.clone(),
                    behaviour: a.behaviour.clone(),
                    events: a.events.clone(),
                };
                (a.agent.clone(), step)
            })
            .collect();
        Self { step: record.step, t: record.time, agents, clearance: record.clearance }
    }
}

/// One line of a run log, as read back.
#[derive(Debug, Clone, PartialEq)]
pub enum LogLine {
    /// The header.
    Header(Box<LogHeader>),
    /// A control step.
    Step(LogStep),
    /// The summary (read as JSON: its fields are the run's, see [`crate::RunSummary`]).
    Summary(serde_json::Value),
}

#[derive(Deserialize)]
#[serde(untagged)]
enum RawLine {
    Header { header: Box<LogHeader> },
    Summary { summary: serde_json::Value },
    Step(LogStep),
}

/// Read one line of a run log; `file` and `line` name it in errors.
pub fn parse_log_line(text: &str, file: &Path, line: usize) -> Result<LogLine, SystemError> {
    let raw: RawLine = serde_json::from_str(text).map_err(|e| SystemError::Parse {
        file: file.to_path_buf(),
        line,
        column: e.column(),
        message: format!("expected a log line (header, step or summary): {e}"),
    })?;
    Ok(match raw {
        RawLine::Header { header } => LogLine::Header(header),
        RawLine::Summary { summary } => LogLine::Summary(summary),
        RawLine::Step(s) => LogLine::Step(s),
    })
}

/// Where log lines go.
pub struct RunLog {
    out: Option<(PathBuf, BufWriter<File>)>,
    lines: usize,
}

impl RunLog {
    /// A log written to `path`, or a log that discards lines when `path` is `None`.
    pub fn create(path: Option<&Path>) -> Result<Self, SystemError> {
        let out = match path {
            Some(p) => Some((p.to_path_buf(), BufWriter::new(File::create(p).map_err(|e| SystemError::write(p, e))?))),
            None => None,
        };
        Ok(Self { out, lines: 0 })
    }

    /// Append one record as a line and flush it to the file.
    pub fn line<T: Serialize>(&mut self, record: &T) -> Result<(), SystemError> {
        self.lines += 1;
        let Some((path, w)) = self.out.as_mut() else { return Ok(()) };
        serde_json::to_writer(&mut *w, record)
            .map_err(|e| SystemError::Failed(format!("log {}: {e}", path.display())))?;
        w.write_all(b"\n").and_then(|_| w.flush()).map_err(|e| SystemError::write(path.clone(), e))
    }

    /// Number of lines written so far.
    pub fn lines(&self) -> usize {
        self.lines
    }
}
