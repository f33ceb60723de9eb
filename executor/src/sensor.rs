//! Virtual sensors `v_{j_k} = f_{v_{j_k}}(c_j, R_{j_k})` (eq. 3): each aggregates receptor
//! readings `R` into one reading useful for control, under a configuration written by the
//! control subsystem (`c^{i+1}_V`: rate, region of interest, threshold).

use crate::image::{Reading, SensorConfig};
use crate::world::ReceptorReadings;

/// A virtual sensor. The runtime calls it every `config.period` steps (never when the period is
/// 0) and puts the result into the input image `c^i_V`.
///
/// Any `FnMut(&SensorConfig, &ReceptorReadings) -> Reading + Send` is one.
pub trait VirtualSensor: Send {
    /// One reading `v_j` from the receptor readings `R`, under the sensor's configuration.
    fn aggregate(&mut self, config: &SensorConfig, receptors: &ReceptorReadings) -> Reading;
    /// Whether the last [`VirtualSensor::aggregate`] gave no reading at all (a dropout): the
    /// input image then keeps its previous reading, marked stale, as between two readings of a
    /// slower sensor.
    fn dropped_out(&self) -> bool {
        false
    }
}

impl<F> VirtualSensor for F
where
    F: FnMut(&SensorConfig, &ReceptorReadings) -> Reading + Send,
{
    fn aggregate(&mut self, config: &SensorConfig, receptors: &ReceptorReadings) -> Reading {
        self(config, receptors)
    }
}

/// Joint positions from the encoders (first [`crate::image::WORDS`] joints).
#[derive(Debug, Clone, Copy, Default)]
pub struct JointState;

impl VirtualSensor for JointState {
    fn aggregate(&mut self, _config: &SensorConfig, r: &ReceptorReadings) -> Reading {
        Reading::new(&r.joint_positions)
    }
}

/// The nearest detected obstacle whose centre lies in the region of interest:
/// `[distance to surface, centre x, y, z, obstacle index]`; an empty reading when none.
#[derive(Debug, Clone, Copy, Default)]
pub struct NearestObstacle;

impl VirtualSensor for NearestObstacle {
    fn aggregate(&mut self, config: &SensorConfig, r: &ReceptorReadings) -> Reading {
        let best = r
            .obstacles
            .iter()
            .filter(|o| config.region.contains(&o.position))
            .min_by(|a, b| a.distance.total_cmp(&b.distance));
        match best {
            Some(o) => Reading::new(&[o.distance, o.position[0], o.position[1], o.position[2], o.id as f64]),
            None => Reading { fresh: true, ..Reading::default() },
        }
    }
}

/// Contact from the force sensor: `[|F|, 1 if |F| > threshold else 0, Fx, Fy, Fz]`.
#[derive(Debug, Clone, Copy, Default)]
pub struct Contact;

impl VirtualSensor for Contact {
    fn aggregate(&mut self, config: &SensorConfig, r: &ReceptorReadings) -> Reading {
        let f = r.force;
        let n = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
        let touching = if n > config.threshold { 1.0 } else { 0.0 };
        Reading::new(&[n, touching, f[0], f[1], f[2]])
    }
}
