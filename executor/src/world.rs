//! The simulated world: obstacles that move, appear and vanish, and the receptors `R` of each
//! agent (joint encoders, a wrist force sensor, an obstacle detector) with seeded noise, so that
//! runs need no hardware and replay bit for bit.

use std::sync::Arc;

use embodied_models::{Rng, Robot};

/// A spherical obstacle.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Obstacle {
    /// The obstacle's name.
    pub name: String,
    /// Centre at step 0 (or at `appears_at`), metres.
    pub position: [f64; 3],
    /// Constant velocity, m/s.
    pub velocity: [f64; 3],
    /// Radius, m.
    pub radius: f64,
    /// First step at which the obstacle exists.
    pub appears_at: u64,
    /// First step at which it no longer exists.
    pub vanishes_at: Option<u64>,
}

impl Obstacle {
    /// A static obstacle present from step 0.
    pub fn fixed(name: impl Into<String>, position: [f64; 3], radius: f64) -> Self {
        Self { name: name.into(), position, velocity: [0.0; 3], radius, appears_at: 0, vanishes_at: None }
    }
    /// Whether it exists at `step`.
    pub fn present_at(&self, step: u64) -> bool {
        step >= self.appears_at && self.vanishes_at.is_none_or(|v| step < v)
    }
}

/// An axis-aligned box that the force sensor feels through a compliant skin of thickness
/// `skin` (a polishing pad's, modelled on the surface): within `skin` of the box the sensing
/// point feels `stiffness * (skin - distance)` along the outward normal of the box at the
/// nearest point. A workpiece a tool works on; detectors do not see it.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Solid {
    /// Its name.
    pub name: String,
    /// Centre, m.
    pub centre: [f64; 3],
    /// Half sizes along x, y, z, m.
    pub half: [f64; 3],
    /// Thickness of the compliant skin, m.
    pub skin: f64,
}

impl Solid {
    /// Signed distance from `p` to the box (negative inside) and the outward unit normal there.
    pub fn distance(&self, p: [f64; 3]) -> (f64, [f64; 3]) {
        let d: [f64; 3] = std::array::from_fn(|k| p[k] - self.centre[k]);
        let out: [f64; 3] = std::array::from_fn(|k| d[k].abs() - self.half[k]);
        if out.iter().any(|&o| o > 0.0) {
            let v: [f64; 3] = std::array::from_fn(|k| out[k].max(0.0) * d[k].signum());
            let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            (n, std::array::from_fn(|k| v[k] / n))
        } else {
            // Inside: the nearest face.
            let k = (0..3).max_by(|&a, &b| out[a].total_cmp(&out[b])).unwrap_or(2);
            let mut normal = [0.0; 3];
            normal[k] = if d[k] >= 0.0 { 1.0 } else { -1.0 };
            (out[k], normal)
        }
    }
}

/// An agent's body in the world, as other agents' receptors see it: the bounding spheres of
/// its shapes where its joints stood after the last step.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Body {
    /// Index of the agent in the runtime.
    pub agent: usize,
    /// Its name.
    pub name: String,
    /// Centre (m) and radius (m) of each shape's bounding sphere.
    pub spheres: Vec<([f64; 3], f64)>,
}

/// Everything outside the agents' control subsystems: the obstacles and the agents' bodies.
#[derive(Debug, Clone, Default)]
pub struct World {
    obstacles: Vec<Obstacle>,
    solids: Vec<Solid>,
    bodies: Vec<Body>,
    step: u64,
}

impl World {
    /// An empty world (no obstacles, step 0).
    pub fn new() -> Self {
        Self::default()
    }
    /// Add an obstacle; returns its id (index).
    pub fn add_obstacle(&mut self, obstacle: Obstacle) -> usize {
        self.obstacles.push(obstacle);
        self.obstacles.len() - 1
    }
    /// Add a solid the force sensor feels (see [`Solid`]); returns its index.
    pub fn add_solid(&mut self, solid: Solid) -> usize {
        self.solids.push(solid);
        self.solids.len() - 1
    }
    /// The solids the force sensor feels.
    pub fn solids(&self) -> &[Solid] {
        &self.solids
    }
    /// All obstacles, present or not, at their current positions.
    pub fn obstacles(&self) -> &[Obstacle] {
        &self.obstacles
    }
    /// The agents' bodies (placed by the runtime's [`crate::runtime::StepMonitor`] after every
    /// step; empty without one).
    pub fn bodies(&self) -> &[Body] {
        &self.bodies
    }
    /// Replace the agents' bodies.
    pub fn set_bodies(&mut self, bodies: Vec<Body>) {
        self.bodies = bodies;
    }
    pub(crate) fn bodies_mut(&mut self) -> &mut Vec<Body> {
        &mut self.bodies
    }
    /// The current step.
    pub fn step(&self) -> u64 {
        self.step
    }
    pub(crate) fn advance(&mut self, dt: f64) {
        for o in &mut self.obstacles {
            if o.present_at(self.step) {
                for k in 0..3 {
                    o.position[k] += o.velocity[k] * dt;
                }
            }
        }
        self.step += 1;
    }
}

/// One obstacle as the detector saw it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObstacleEcho {
    /// Index in [`World::obstacles`]; for a shape of another agent's body (see `agent`), the
    /// number of obstacles plus the index of the shape among all bodies' shapes.
    pub id: usize,
    /// The agent whose body this is, when it is one.
    pub agent: Option<usize>,
    /// Measured centre (with noise).
    pub position: [f64; 3],
    /// Distance from the sensing point to the obstacle surface (negative = penetration).
    pub distance: f64,
}

/// The receptor readings `R` of one agent in one step.
#[derive(Debug, Clone, Default)]
pub struct ReceptorReadings {
    /// Step at which the readings were taken.
    pub step: u64,
    /// Joint encoders: positions and velocities with noise.
    pub joint_positions: Vec<f64>,
    /// Measured joint velocities (rad/s or m/s) with noise; see `joint_positions`.
    pub joint_velocities: Vec<f64>,
    /// The sensing point (tool centre of the agent's end effector; the origin for an agent
    /// without a robot model).
    pub sensing_point: [f64; 3],
    /// Wrist force sensor, N (contact with obstacles modelled as springs), with noise.
    pub force: [f64; 3],
    /// Obstacles within the detector's range, in world order.
    pub obstacles: Vec<ObstacleEcho>,
}

/// Which receptors an agent has and how noisy they are.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ReceptorSpec {
    /// Standard deviation of encoder noise (rad or m); see [`receptor_noise`] for its shape.
    pub encoder_noise: f64,
    /// Force sensor contact stiffness (N/m); `None` = no force sensor.
    pub force_stiffness: Option<f64>,
    /// Standard deviation of force noise (N).
    pub force_noise: f64,
    /// Obstacle detector range from the sensing point (m); `None` = no detector,
    /// infinity = a global camera (e.g. a coordinator's).
    pub detector_range: Option<f64>,
    /// Standard deviation of detected positions (m).
    pub detector_noise: f64,
}

impl Default for ReceptorSpec {
    /// Encoders only, without noise.
    fn default() -> Self {
        Self { encoder_noise: 0.0, force_stiffness: None, force_noise: 0.0, detector_range: None, detector_noise: 0.0 }
    }
}

/// Unit-variance noise for the receptors: the centred Irwin–Hall sum of the four 16-bit words
/// of one draw of the agent's xoshiro256** stream, scaled to standard deviation 1. Close to a
/// normal distribution (bounded at ±2√3 ≈ ±3.46), seeded and bit-for-bit deterministic (integer
/// sum, one multiply), and far cheaper than Box–Muller's `ln`, `sqrt` and `cos` per sample.
pub fn receptor_noise(rng: &mut Rng) -> f64 {
    noise(rng)
}

/// `sqrt(3 / (65536^2 - 1))`: one over the standard deviation of a sum of four independent
/// uniform 16-bit integers.
const NOISE_SCALE: f64 = 2.642_899_792_130_301_8e-5;

#[inline]
fn noise(rng: &mut Rng) -> f64 {
    let x = rng.next_u64();
    let sum = (x & 0xFFFF) + ((x >> 16) & 0xFFFF) + ((x >> 32) & 0xFFFF) + (x >> 48);
    (sum as f64 - 131_070.0) * NOISE_SCALE
}

/// `dst = src`, reusing `dst`'s buffer.
#[inline]
fn copy_into(dst: &mut Vec<f64>, src: &[f64]) {
    if dst.len() == src.len() {
        dst.copy_from_slice(src);
    } else {
        dst.clear();
        dst.extend_from_slice(src);
    }
}

/// The receptors of one agent: a spec, an optional robot model to place the sensing point and
/// the agent's own noise stream.
pub(crate) struct Receptors {
    pub(crate) spec: ReceptorSpec,
    pub(crate) robot: Option<(Arc<Robot>, usize)>,
    pub(crate) rng: Rng,
    /// The agent's own index (its own body is not an obstacle to it).
    pub(crate) own: Option<usize>,
}

impl Receptors {
    /// Sample all receptors at the true joint state `(q, qd)` into `out`.
    pub(crate) fn sample(&mut self, world: &World, q: &[f64], qd: &[f64], out: &mut ReceptorReadings) {
        let spec = &self.spec;
        out.step = world.step;
        copy_into(&mut out.joint_positions, q);
        copy_into(&mut out.joint_velocities, qd);
        if spec.encoder_noise > 0.0 {
            for v in out.joint_positions.iter_mut() {
                *v += spec.encoder_noise * noise(&mut self.rng);
            }
        }
        out.obstacles.clear();
        out.force = [0.0; 3];
        if spec.force_stiffness.is_none() && spec.detector_range.is_none() {
            return;
        }
        out.sensing_point = match &self.robot {
            Some((robot, ee)) if q.len() == robot.dof() && *ee < robot.end_effectors().len() => {
                let t = robot.end_effector_poses(q, *ee).1.translation.vector;
                [t.x, t.y, t.z]
            }
            _ => [0.0; 3],
        };
        let p = out.sensing_point;
        let rng = &mut self.rng;
        let mut sense = |id: usize, agent: Option<usize>, position: [f64; 3], radius: f64| {
            let d = [p[0] - position[0], p[1] - position[1], p[2] - position[2]];
            let centre_dist = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            let distance = centre_dist - radius;
            // The force sensor feels obstacles; another robot's body is seen, not felt.
            if let Some(k) = spec.force_stiffness
                && agent.is_none()
                && distance < 0.0
                && centre_dist > 0.0
            {
                for (f, da) in out.force.iter_mut().zip(d) {
                    *f += k * (-distance) * da / centre_dist;
                }
            }
            if let Some(range) = spec.detector_range
                && distance <= range
            {
                let mut position = position;
                if spec.detector_noise > 0.0 {
                    for c in position.iter_mut() {
                        *c += spec.detector_noise * noise(rng);
                    }
                }
                out.obstacles.push(ObstacleEcho { id, agent, position, distance });
            }
        };
        for (id, o) in world.obstacles().iter().enumerate() {
            if o.present_at(world.step) {
                sense(id, None, o.position, o.radius);
            }
        }
        let mut id = world.obstacles().len();
        for b in &world.bodies {
            for &(position, radius) in &b.spheres {
                if Some(b.agent) != self.own {
                    sense(id, Some(b.agent), position, radius);
                }
                id += 1;
            }
        }
        if let Some(k) = spec.force_stiffness {
            for solid in &world.solids {
                let (distance, normal) = solid.distance(p);
                if distance < solid.skin {
                    for (f, n) in out.force.iter_mut().zip(normal) {
                        *f += k * (solid.skin - distance) * n;
                    }
                }
            }
        }
        if spec.force_stiffness.is_some() && spec.force_noise > 0.0 {
            for f in out.force.iter_mut() {
                *f += spec.force_noise * noise(&mut self.rng);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_detector_sees_other_agents_bodies_but_not_its_own_and_feels_only_obstacles() {
        let mut world = World::new();
        world.add_obstacle(Obstacle::fixed("ball", [0.5, 0.0, 0.0], 0.1));
        world.set_bodies(vec![
            Body { agent: 0, name: "me".into(), spheres: vec![([0.0, 0.0, 0.0], 0.2)] },
            Body { agent: 1, name: "other".into(), spheres: vec![([0.0, 0.05, 0.0], 0.3), ([0.0, 2.0, 0.0], 0.1)] },
        ]);
        let spec = ReceptorSpec { detector_range: Some(1.0), force_stiffness: Some(100.0), ..ReceptorSpec::default() };
        let mut r = Receptors { spec, robot: None, rng: Rng::new(1), own: Some(0) };
        let mut out = ReceptorReadings::default();
        r.sample(&world, &[], &[], &mut out);
        // The sensing point is the origin (no robot): the ball, and the other agent's near
        // shape (id: one obstacle, then the bodies' shapes in order: own 1, other 2 and 3).
        let seen: Vec<(usize, Option<usize>)> = out.obstacles.iter().map(|e| (e.id, e.agent)).collect();
        assert_eq!(seen, vec![(0, None), (2, Some(1))]);
        assert!((out.obstacles[1].distance - (0.05 - 0.3)).abs() < 1e-12);
        // Inside the other's body sphere, but a body is seen, not felt.
        assert_eq!(out.force, [0.0; 3]);
    }

    #[test]
    fn noise_scale_gives_unit_variance() {
        // Variance of one uniform 16-bit word is (65536^2 - 1) / 12; four of them sum to a third.
        let variance = (65536.0_f64 * 65536.0 - 1.0) / 3.0;
        assert!((NOISE_SCALE * NOISE_SCALE * variance - 1.0).abs() < 1e-12);
    }

    #[test]
    fn receptor_noise_is_centred_unit_bounded_and_seeded() {
        let n = 200_000;
        let draw = |seed| {
            let mut rng = Rng::new(seed);
            (0..n).map(|_| receptor_noise(&mut rng)).collect::<Vec<f64>>()
        };
        let a = draw(5);
        assert_eq!(a, draw(5), "same seed, same noise");
        assert_ne!(a, draw(6), "another seed, other noise");
        let mean = a.iter().sum::<f64>() / n as f64;
        let var = a.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
        assert!(mean.abs() < 0.01, "mean {mean}");
        assert!((var - 1.0).abs() < 0.02, "variance {var}");
        assert!(a.iter().all(|x| x.abs() <= 2.0 * 3.0_f64.sqrt() + 1e-9));
        // Shaped like a normal: about 68% within one standard deviation, 95% within two.
        let within = |k: f64| a.iter().filter(|x| x.abs() <= k).count() as f64 / n as f64;
        assert!((within(1.0) - 0.683).abs() < 0.02, "{}", within(1.0));
        assert!((within(2.0) - 0.954).abs() < 0.02, "{}", within(2.0));
    }
}
