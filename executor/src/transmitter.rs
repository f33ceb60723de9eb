//! The inter-agent transmission `T` (`c^{i+1}_T ≻ c^i_T` of eq. 10): one-way channels with a
//! latency in steps and a seeded loss probability, and optionally injected link faults
//! ([`LinkFaults`]: messages lost or delayed for a while). A channel delivers in the order of
//! sending, delayed messages included: a message never overtakes an earlier one.

use std::collections::{HashMap, VecDeque};

use embodied_models::Rng;

use crate::image::{AgentId, Envelope};

/// Properties of one channel.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Link {
    /// Extra steps in transit: a message sent in step `i` is in the receiver's input image at
    /// step `i + 1 + latency`.
    pub latency: u32,
    /// Probability in [0, 1] that a message is lost.
    pub loss: f64,
}

impl Link {
    /// Delivered in the next step, never lost.
    pub const IDEAL: Link = Link { latency: 0, loss: 0.0 };
}

/// Counters of one channel.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct ChannelStats {
    /// Messages sent into the channel.
    pub sent: u64,
    /// Messages lost in transit.
    pub lost: u64,
    /// Messages delivered to the receiver.
    pub delivered: u64,
}

/// What an injected link fault does to one message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transit {
    /// Delivered, `extra` steps later than the link's latency says.
    Deliver {
        /// Extra steps in transit.
        extra: u64,
    },
    /// Lost.
    Lose,
}

/// Injected link faults: asked once for every message sent (after the link's own loss), in
/// the order of sending, so that a seeded implementation replays.
pub trait LinkFaults: Send {
    /// What happens to a message `from -> to` sent in step `step`.
    fn transit(&mut self, from: AgentId, to: AgentId, step: u64) -> Transit;
}

struct Channel {
    from: AgentId,
    to: AgentId,
    link: Link,
    rng: Rng,
    in_flight: VecDeque<(u64, Envelope)>,
    stats: ChannelStats,
}

/// All channels of a system. Delivery order is deterministic: channels in order of creation,
/// messages in order of sending.
#[derive(Default)]
pub struct Transmitter {
    channels: Vec<Channel>,
    by_ends: HashMap<(AgentId, AgentId), usize>,
    faults: Option<Box<dyn LinkFaults>>,
}

impl Transmitter {
    /// No channels.
    pub fn new() -> Self {
        Self::default()
    }
    /// Open (or reconfigure) the channel `from -> to`; `seed` drives its losses.
    pub fn connect(&mut self, from: AgentId, to: AgentId, link: Link, seed: u64) {
        let link =
            Link { latency: link.latency, loss: if link.loss.is_finite() { link.loss.clamp(0.0, 1.0) } else { 1.0 } };
        match self.by_ends.get(&(from, to)) {
            Some(&k) => self.channels[k].link = link,
            None => {
                self.by_ends.insert((from, to), self.channels.len());
                self.channels.push(Channel {
                    from,
                    to,
                    link,
                    rng: Rng::new(seed),
                    in_flight: VecDeque::with_capacity(16),
                    stats: ChannelStats::default(),
                });
            }
        }
    }
    /// Inject link faults into every channel from now on.
    pub fn set_faults(&mut self, faults: Box<dyn LinkFaults>) {
        self.faults = Some(faults);
    }
    /// Whether `from -> to` exists.
    pub fn connected(&self, from: AgentId, to: AgentId) -> bool {
        self.by_ends.contains_key(&(from, to))
    }
    /// Put `envelope`, sent in step `step`, in transit. Returns `false` when there is no channel.
    pub fn send(&mut self, envelope: Envelope, step: u64) -> bool {
        let Some(&k) = self.by_ends.get(&(envelope.from, envelope.to)) else {
            return false;
        };
        let ch = &mut self.channels[k];
        ch.stats.sent += 1;
        if ch.link.loss > 0.0 && ch.rng.uniform() < ch.link.loss {
            ch.stats.lost += 1;
            return true;
        }
        let extra = match self.faults.as_mut().map(|f| f.transit(envelope.from, envelope.to, step)) {
            Some(Transit::Lose) => {
                ch.stats.lost += 1;
                return true;
            }
            Some(Transit::Deliver { extra }) => extra,
            None => 0,
        };
        // In order: a message is never due before the one sent ahead of it.
        let due = (step + 1 + u64::from(ch.link.latency)).saturating_add(extra);
        let due = ch.in_flight.back().map_or(due, |(d, _)| due.max(*d));
        ch.in_flight.push_back((due, envelope));
        true
    }
    /// Hand every message due by `step` to `deliver(receiver, envelope)`.
    pub fn deliver(&mut self, step: u64, mut deliver: impl FnMut(AgentId, Envelope)) {
        for ch in &mut self.channels {
            while ch.in_flight.front().is_some_and(|(due, _)| *due <= step) {
                let Some((_, env)) = ch.in_flight.pop_front() else { break };
                ch.stats.delivered += 1;
                deliver(ch.to, env);
            }
        }
    }
    /// Counters of `from -> to`.
    pub fn stats(&self, from: AgentId, to: AgentId) -> Option<ChannelStats> {
        self.by_ends.get(&(from, to)).map(|&k| self.channels[k].stats)
    }
    /// All channels as `(from, to, link)`.
    pub fn links(&self) -> impl Iterator<Item = (AgentId, AgentId, Link)> + '_ {
        self.channels.iter().map(|c| (c.from, c.to, c.link))
    }
}
