//! The one vocabulary of what a check found wrong: what, where in time, which joint or pair,
//! and by how much.
//!
//! Every check of the [`super::Verifier`] (limits, sampled or certified collisions, the
//! closed-chain constraint) and the streaming [`super::LimitsChecker`] report a [`Finding`].
//! Times are seconds from the trajectory's start; for an untimed path (a list of waypoints) the
//! time is the *path parameter*: waypoint `k` is at `t = k`, and a point at fraction `f` of the
//! segment from waypoint `k` to `k + 1` is at `t = k + f`.

use serde::Serialize;

/// One thing wrong with a plan, and where. Times are seconds from the trajectory's start (the
/// path parameter for an untimed path: waypoint `k` is at `t = k`, a point at fraction `f` of the
/// segment from waypoint `k` on at `t = k + f`).
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Finding {
    /// The trajectory itself is not well formed (lengths, DOF, non-finite values, time order,
    /// unknown end effectors).
    Malformed {
        /// What is malformed.
        message: String,
    },
    /// A joint outside its position limits.
    Position {
        /// When, s (the path parameter for a path).
        t: f64,
        /// The joint's name.
        joint: String,
        /// Its position, rad or m.
        value: f64,
        /// Lower position limit.
        lower: f64,
        /// Upper position limit.
        upper: f64,
        /// How far outside the limits it is.
        excess: f64,
    },
    /// A joint faster than its velocity limit; `source`: `qd` (the stated velocity) or
    /// `finite difference of q`.
    Velocity {
        /// When, s (the path parameter for a path).
        t: f64,
        /// The joint's name.
        joint: String,
        /// Its velocity, rad/s or m/s.
        value: f64,
        /// Its velocity limit.
        limit: f64,
        /// By how much `|value|` exceeds the limit.
        excess: f64,
        /// Where the velocity comes from: `qd` or `finite difference of q`.
        source: String,
    },
    /// A joint accelerating harder than its limit (finite difference of the stated `qd`).
    Acceleration {
        /// When, s.
        t: f64,
        /// The joint's name.
        joint: String,
        /// Its acceleration, rad/s^2 or m/s^2.
        value: f64,
        /// Its acceleration limit.
        limit: f64,
        /// By how much `|value|` exceeds the limit.
        excess: f64,
    },
    /// A linear actuator (a screw driving a joint through a triangle) outside its stroke
    /// (`what` = `length`) or faster than its speed limit (`what` = `speed`).
    Actuator {
        /// When, s (the path parameter for a path).
        t: f64,
        /// The actuator's name.
        actuator: String,
        /// `length` (m) or `speed` (m/s).
        what: String,
        /// Its length (m) or speed (m/s).
        value: f64,
        /// The bound exceeded: the nearer stroke end (m) or the speed limit (m/s).
        limit: f64,
        /// By how much it is exceeded.
        excess: f64,
    },
    /// A configuration on the path in collision: the pair and how deep (m, >= 0).
    Collision {
        /// When, s (the path parameter for a path).
        t: f64,
        /// The configuration in collision.
        q: Vec<f64>,
        /// One body of the pair ("link `x`").
        a: String,
        /// The other body ("obstacle `y`" or another link).
        b: String,
        /// Penetration depth, m (>= 0).
        penetration_m: f64,
    },
    /// A configuration on the path that is free but closer than the clearance the check
    /// requires ([`super::Mode::Certified`]'s `tolerance`): the pair, its distance and the
    /// required clearance (m).
    TooClose {
        /// When, s (the path parameter for a path).
        t: f64,
        /// The configuration that is too close.
        q: Vec<f64>,
        /// One body of the pair ("link `x`").
        a: String,
        /// The other body ("obstacle `y`" or another link).
        b: String,
        /// Their distance, m.
        distance_m: f64,
        /// The clearance required, m.
        required_m: f64,
    },
    /// A piece of the path that the certificate could neither prove free nor show in collision
    /// within the caps: the piece, and the pair closest at its ends.
    NotCertified {
        /// Start of the piece, s (the path parameter for a path).
        t_from: f64,
        /// End of the piece, s (the path parameter for a path).
        t_to: f64,
        /// Configuration at the start of the piece.
        q_from: Vec<f64>,
        /// Configuration at the end of the piece.
        q_to: Vec<f64>,
        /// One body of the closest pair (empty when no pair was evaluated).
        a: String,
        /// The other body of the closest pair (empty when no pair was evaluated).
        b: String,
        /// The smallest clearance bound over the piece, m (NaN when not evaluated).
        clearance_m: f64,
        /// Why the piece could not be certified.
        reason: String,
    },
    /// The verification's budget of distance evaluations
    /// ([`super::CheckSettings::max_evaluations`]) was spent before the motion was certified:
    /// from this segment on nothing is certified (not free, not in collision: unknown).
    BudgetExhausted {
        /// The budget, distance evaluations.
        budget: usize,
        /// The segment (from sample `segment` to `segment + 1`) being checked when it ran out.
        segment: usize,
        /// Start of that segment, s (the path parameter for a path).
        t_from: f64,
        /// End of that segment, s (the path parameter for a path).
        t_to: f64,
        /// The agent whose motion it is (empty where the checker does not know it).
        agent: String,
    },
    /// The pose of the second tool frame relative to the first drifted from its value at the
    /// start of the closed-chain span.
    ClosureDrift {
        /// When, s.
        t: f64,
        /// Index of the closed-chain span.
        span: usize,
        /// Drift of the relative tool position, m.
        position_error_m: f64,
        /// Drift of the relative tool rotation angle, rad.
        angle_error_rad: f64,
        /// Allowed position drift, m.
        tolerance_m: f64,
        /// Allowed angle drift, rad.
        tolerance_rad: f64,
    },
}

impl std::fmt::Display for Finding {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Finding::Malformed { message } => write!(f, "malformed: {message}"),
            Finding::Position { t, joint, value, lower, upper, excess } => write!(
                f,
                "t = {t:.4} s: joint `{joint}` = {value:.6} is outside [{lower:.6}, {upper:.6}] by {excess:.3e}"
            ),
            Finding::Velocity { t, joint, value, limit, excess, source } => write!(
                f,
                "t = {t:.4} s: joint `{joint}` velocity {value:.6} ({source}) exceeds {limit:.6} by {excess:.3e}"
            ),
            Finding::Acceleration { t, joint, value, limit, excess } => {
                write!(f, "t = {t:.4} s: joint `{joint}` acceleration {value:.6} exceeds {limit:.6} by {excess:.3e}")
            }
            Finding::Actuator { t, actuator, what, value, limit, excess } => write!(
                f,
                "t = {t:.4} s: actuator `{actuator}` {what} {value:.6} is beyond its limit {limit:.6} by {excess:.3e}"
            ),
            Finding::Collision { t, q, a, b, penetration_m } => {
                write!(f, "t = {t:.4} s: {a} and {b} collide (penetration {penetration_m:.3e} m) at q = {}", fmt_q(q))
            }
            Finding::TooClose { t, q, a, b, distance_m, required_m } => write!(
                f,
                "t = {t:.4} s: {a} and {b} are {distance_m:.3e} m apart, closer than the required {required_m:.3e} m, at q = {}",
                fmt_q(q)
            ),
            Finding::NotCertified { t_from, t_to, q_from, a, b, clearance_m, reason, .. } => write!(
                f,
                "t = {t_from:.4}..{t_to:.4} s: not certified ({reason}); closest pair {a} and {b}, \
                 clearance {clearance_m:.3e} m at q = {}",
                fmt_q(q_from)
            ),
            Finding::BudgetExhausted { budget, segment, t_from, t_to, agent } => {
                let of = if agent.is_empty() { String::new() } else { format!(" of agent {agent}") };
                write!(
                    f,
                    "not certified: budget of {budget} distance evaluations exhausted at segment {segment}{of} \
                     (t = {t_from:.4}..{t_to:.4} s)"
                )
            }
            Finding::ClosureDrift { t, span, position_error_m, angle_error_rad, tolerance_m, tolerance_rad } => {
                write!(
                    f,
                    "t = {t:.4} s: closed-chain span {span}: relative tool pose drifted by {position_error_m:.3e} m \
                     (tolerance {tolerance_m:.3e}) and {angle_error_rad:.3e} rad (tolerance {tolerance_rad:.3e})"
                )
            }
        }
    }
}

fn fmt_q(q: &[f64]) -> String {
    let v: Vec<String> = q.iter().map(|x| format!("{x:.4}")).collect();
    format!("[{}]", v.join(", "))
}

impl std::error::Error for Finding {}

impl Finding {
    /// When it happens: seconds from the start (the path parameter for a path); for a piece
    /// that could not be certified, its start; `None` for a malformed input.
    pub fn time(&self) -> Option<f64> {
        match self {
            Finding::Malformed { .. } => None,
            Finding::Position { t, .. }
            | Finding::Velocity { t, .. }
            | Finding::Acceleration { t, .. }
            | Finding::Actuator { t, .. }
            | Finding::Collision { t, .. }
            | Finding::TooClose { t, .. }
            | Finding::ClosureDrift { t, .. } => Some(*t),
            Finding::NotCertified { t_from, .. } | Finding::BudgetExhausted { t_from, .. } => Some(*t_from),
        }
    }

    /// The same finding naming `agent` as the one whose motion it is (a spent budget).
    pub fn of_agent(self, agent: &str) -> Finding {
        match self {
            Finding::BudgetExhausted { budget, segment, t_from, t_to, .. } => {
                Finding::BudgetExhausted { budget, segment, t_from, t_to, agent: agent.to_string() }
            }
            other => other,
        }
    }

    /// The same finding with its segment index moved on by `offset` samples (a check of a
    /// window of a longer motion).
    pub fn shifted(self, offset: usize) -> Finding {
        match self {
            Finding::BudgetExhausted { budget, segment, t_from, t_to, agent } => {
                Finding::BudgetExhausted { budget, segment: segment + offset, t_from, t_to, agent }
            }
            other => other,
        }
    }
}
