//! The crate's one error type.

use thiserror::Error;

/// Everything that can stop a run or reject a specification.
///
/// A run that fails with one of these has already begun a [`crate::SafeHalt`]: the runtime never
/// panics on a faulty agent specification.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum ExecutorError {
    /// The agent's predicates did not select exactly one reaction: either none held and there is
    /// no main reaction (`held` is empty), or the agent declared that exactly one holds and
    /// several did (`held` names them).
    #[error(
        "agent specification error in agent '{agent}' at step {step}, behaviour '{behaviour}': {}",
        describe_held(held)
    )]
    SpecificationError {
        /// The agent's name.
        agent: String,
        /// The step at which it happened.
        step: u64,
        /// The behaviour whose predicates were evaluated.
        behaviour: String,
        /// Names of the predicates that held (empty when none did).
        held: Vec<String>,
    },
    /// A transition function sent a message to an agent with no channel from the sender.
    #[error("agent '{agent}' at step {step} sent a message to agent #{to}, but no channel connects them")]
    NoChannel {
        /// The sending agent's name.
        agent: String,
        /// The step at which it happened.
        step: u64,
        /// Index of the receiving agent.
        to: usize,
    },
    /// A vector's length does not match the number of joints.
    #[error("{what}: expected {expected} values, got {got}")]
    DimensionMismatch {
        /// What the vector is.
        what: String,
        /// The number of joints.
        expected: usize,
        /// The vector's length.
        got: usize,
    },
    /// A limit is not a valid number (negative, NaN, lower > upper).
    #[error("invalid limits for joint {joint}: {reason}")]
    InvalidLimits {
        /// Index of the joint.
        joint: usize,
        /// What is wrong with the limit.
        reason: String,
    },
    /// A name or index that refers to nothing.
    #[error("unknown {what} '{name}'")]
    Unknown {
        /// What kind of thing was referred to.
        what: &'static str,
        /// The name or index given.
        name: String,
    },
    /// The closed-chain QP could not be solved.
    #[error("closed-chain QP failed: {0}")]
    Qp(String),
    /// The closed-chain QP has no solution: its bounds and inequality rows contradict each other.
    #[error("closed-chain QP infeasible: {0}")]
    QpInfeasible(String),
    /// An input holds NaN or an infinity where a finite number is needed.
    #[error("{what} is not finite")]
    NotFinite {
        /// What holds the non-finite value.
        what: String,
    },
    /// A parameter outside its valid range.
    #[error("invalid {what}: {reason}")]
    InvalidParameter {
        /// The parameter.
        what: String,
        /// Why its value is invalid.
        reason: String,
    },
}

fn describe_held(held: &[String]) -> String {
    if held.is_empty() {
        "no predicate holds and there is no main (default) reaction".to_string()
    } else {
        format!("exactly one predicate must hold, but {} held: {}", held.len(), held.join(", "))
    }
}

/// A violation found inside a behaviour; the runtime adds the agent and step.
#[derive(Debug, Clone, PartialEq)]
pub struct Violation {
    /// The behaviour whose predicates failed.
    pub behaviour: String,
    /// The predicates that held (empty: none held and there was no main reaction).
    pub held: Vec<String>,
}

impl Violation {
    pub(crate) fn into_error(self, agent: &str, step: u64) -> ExecutorError {
        ExecutorError::SpecificationError { agent: agent.to_string(), step, behaviour: self.behaviour, held: self.held }
    }
}
