//! The virtual sensor of a deliberative agent: the nearest obstacle its map does not hold.

use crate::image::{Reading, SensorConfig};
use crate::sensor::VirtualSensor;
use crate::world::ReceptorReadings;

/// The nearest detected obstacle that is not in the agent's map (`mapped`: world obstacle ids
/// it already plans around), as `[distance, x, y, z, id, radius]`; an empty fresh reading when
/// there is none. The radius is the detector's: centre distance from the sensing point minus
/// the surface distance.
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
}

impl VirtualSensor for UnmappedObstacle {
    fn aggregate(&mut self, config: &SensorConfig, r: &ReceptorReadings) -> Reading {
        let best = r
            .obstacles
            .iter()
            .filter(|o| (o.agent.is_none() || self.bodies) && !self.mapped.contains(&o.id))
            .filter(|o| config.region.contains(&o.position))
            .min_by(|a, b| a.distance.total_cmp(&b.distance));
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
