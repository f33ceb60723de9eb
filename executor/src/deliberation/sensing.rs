//! The virtual sensor of a deliberative agent: the nearest obstacle its map does not hold.

use crate::image::{Reading, SensorConfig};
use crate::sensor::VirtualSensor;
use crate::world::ReceptorReadings;

/// A detected obstacle that is not in the agent's map (`mapped`: world obstacle ids it already
/// plans around), as `[distance, x, y, z, id, radius]`; an empty fresh reading when there is
/// none. The radius is the detector's: centre distance from the sensing point minus the surface
/// distance.
///
/// One reading holds one obstacle: news first. It is the nearest obstacle not reported before
/// or moved by more than [`NEWS_TOLERANCE`] since it was last reported; when there is no news,
/// the nearest. So an obstacle that appears is reported the step it appears even while another
/// is nearer, and several moving obstacles are reported in turn.
///
/// Other agents' bodies (echoes with an `agent`) are skipped unless `bodies` is set: an agent
/// normally knows where the others are from the coordination messages (their bodies or the
/// space they will sweep are on its map).
#[derive(Debug, Clone, Default)]
pub struct UnmappedObstacle {
    /// World obstacle ids the agent already plans around (not reported).
    pub mapped: Vec<usize>,
    /// Report other agents' bodies as unmapped obstacles too.
    pub bodies: bool,
    /// Per obstacle reported: its id and centre when last reported.
    reported: Vec<(usize, [f64; 3])>,
}

/// Movement (m) of an obstacle reported before that makes it news again: half the movement a
/// deliberative agent counts as a change of its world (`move_tolerance`, 0.02 m by default), so
/// that no change it would act on goes unreported.
pub const NEWS_TOLERANCE: f64 = 0.01;

impl UnmappedObstacle {
    /// A sensor that skips the world obstacles `mapped` (and other agents' bodies unless
    /// `bodies`).
    pub fn new(mapped: Vec<usize>, bodies: bool) -> Self {
        Self { mapped, bodies, reported: Vec::new() }
    }
}

impl VirtualSensor for UnmappedObstacle {
    fn aggregate(&mut self, config: &SensorConfig, r: &ReceptorReadings) -> Reading {
        let seen = |o: &&crate::world::ObstacleEcho| {
            (o.agent.is_none() || self.bodies) && !self.mapped.contains(&o.id) && config.region.contains(&o.position)
        };
        let news = |o: &&crate::world::ObstacleEcho| match self.reported.iter().find(|(id, _)| *id == o.id) {
            None => true,
            Some((_, p)) => (0..3).any(|k| (p[k] - o.position[k]).abs() > NEWS_TOLERANCE),
        };
        let nearest =
            |a: &&crate::world::ObstacleEcho, b: &&crate::world::ObstacleEcho| a.distance.total_cmp(&b.distance);
        let best = r
            .obstacles
            .iter()
            .filter(seen)
            .filter(news)
            .min_by(nearest)
            .or_else(|| r.obstacles.iter().filter(seen).min_by(nearest));
        if let Some(o) = best {
            match self.reported.iter_mut().find(|(id, _)| *id == o.id) {
                Some(entry) => entry.1 = o.position,
                None => self.reported.push((o.id, o.position)),
            }
        }
        match best {
            Some(o) => {
                let p = r.sensing_point;
                let d = [p[0] - o.position[0], p[1] - o.position[1], p[2] - o.position[2]];
                let centre = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                let radius = (centre - o.distance).max(0.0);
                Reading::new(&[o.distance, o.position[0], o.position[1], o.position[2], o.id as f64, radius])
            }
            None => Reading { fresh: true, ..Reading::default() },
        }
    }
}
