//! Composition of the partial results `^q c^{i+1}` of several active transition functions into
//! the one `c^{i+1}` that reaches the effector (eq. 14).
//!
//! Competitive composers pick one partial result: [`Composer::Max`] (eq. 15),
//! [`Composer::Select`], [`Composer::Inhibit`], [`Composer::Suppress`] (Brooks' mechanisms, made
//! from selection functions as the paper suggests). The cooperative composer
//! [`Composer::WeightedSum`] superposes them (eq. 16).
//!
//! Only the effector command is composed; the other outputs (sensor configuration, messages,
//! events) of every active function are passed on (for a sensor configured twice, the earlier
//! rule wins).

use crate::image::{CommandMode, JointCommand};

/// A user selection function: given the rule indices that produced a command this step (in rule
/// order), return the one to use.
pub type SelectFn = Box<dyn Fn(&[usize]) -> Option<usize> + Send + Sync>;

/// How the partial effector commands of simultaneously active rules are combined.
pub enum Composer {
    /// Eq. (15): the partial command of greatest magnitude wins, magnitude = Euclidean norm of
    /// the velocity part (the most urgent reaction); ties go to the earlier rule.
    Max,
    /// A user selection function picks one partial command.
    Select(SelectFn),
    /// Inhibition (elimination of some components by others): for each `(inhibitor, inhibited)`
    /// pair, while the inhibitor is active the inhibited rule's command is discarded; the
    /// remaining commands are averaged with equal weights.
    Inhibit(Vec<(usize, usize)>),
    /// Suppression (substitution): the active rule listed first replaces all others.
    Suppress,
    /// Eq. (16): `sum_m (w_m / w) ^m c^{i+1}` over the active rules, `w = sum of their w_m`
    /// (rules without a listed weight weigh 1). Positions are averaged over the rules that
    /// command positions; velocities over all.
    WeightedSum(Vec<f64>),
}

impl std::fmt::Debug for Composer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Composer::Max => write!(f, "Max"),
            Composer::Select(_) => write!(f, "Select(..)"),
            Composer::Inhibit(p) => write!(f, "Inhibit({p:?})"),
            Composer::Suppress => write!(f, "Suppress"),
            Composer::WeightedSum(w) => write!(f, "WeightedSum({w:?})"),
        }
    }
}

impl Composer {
    /// Compose the commands of `candidates` (rule indices in rule order, each with a command
    /// given by `command_of`) into `out`. Returns `false` (and leaves `out` alone) when nothing
    /// is to be commanded.
    pub fn compose<'a>(
        &self,
        candidates: &[usize],
        command_of: impl Fn(usize) -> &'a JointCommand,
        out: &mut JointCommand,
    ) -> bool {
        if candidates.is_empty() {
            return false;
        }
        let pick = |i: usize, out: &mut JointCommand| {
            let c = command_of(i);
            out.mode = c.mode;
            out.q.copy_from_slice(&c.q);
            out.qd.copy_from_slice(&c.qd);
            true
        };
        match self {
            Composer::Max => {
                let mut best = candidates[0];
                let mut best_norm = f64::NEG_INFINITY;
                for &i in candidates {
                    let n: f64 = command_of(i).qd.iter().map(|v| v * v).sum();
                    if n > best_norm {
                        best_norm = n;
                        best = i;
                    }
                }
                pick(best, out)
            }
            Composer::Select(f) => match f(candidates) {
                Some(i) if candidates.contains(&i) => pick(i, out),
                _ => false,
            },
            Composer::Suppress => pick(candidates[0], out),
            Composer::Inhibit(pairs) => {
                let survives =
                    |i: usize| !pairs.iter().any(|&(by, victim)| victim == i && by != i && candidates.contains(&by));
                weighted(candidates, |i| if survives(i) { 1.0 } else { 0.0 }, &command_of, out)
            }
            Composer::WeightedSum(w) => weighted(candidates, |i| w.get(i).copied().unwrap_or(1.0), &command_of, out),
        }
    }
}

fn weighted<'a>(
    candidates: &[usize],
    weight: impl Fn(usize) -> f64,
    command_of: &impl Fn(usize) -> &'a JointCommand,
    out: &mut JointCommand,
) -> bool {
    let (mut w_all, mut w_pos) = (0.0, 0.0);
    let mut mode = None;
    for &i in candidates {
        let w = weight(i);
        if w > 0.0 && w.is_finite() {
            w_all += w;
            let c = command_of(i);
            if c.mode == CommandMode::Position {
                w_pos += w;
            }
            mode.get_or_insert(c.mode);
        }
    }
    let Some(mode) = mode else { return false };
    out.mode = if w_pos > 0.0 { mode } else { CommandMode::Velocity };
    out.q.iter_mut().for_each(|v| *v = 0.0);
    out.qd.iter_mut().for_each(|v| *v = 0.0);
    for &i in candidates {
        let w = weight(i);
        if !(w > 0.0 && w.is_finite()) {
            continue;
        }
        let c = command_of(i);
        for (o, v) in out.qd.iter_mut().zip(&c.qd) {
            *o += w / w_all * v;
        }
        if c.mode == CommandMode::Position {
            for (o, v) in out.q.iter_mut().zip(&c.q) {
                *o += w / w_pos * v;
            }
        }
    }
    if out.mode == CommandMode::Position && w_pos < w_all {
        // Mixed modes: position-less contributions cannot be averaged into positions, so the
        // command becomes a velocity command (the positions still steer through `qd`).
        out.mode = CommandMode::Velocity;
    }
    true
}
