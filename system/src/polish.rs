//! Polishing under a regulated contact force (`[polish]`): a boustrophedon coverage path over
//! the top face of a box workpiece, tool normal to the face, followed while a force regulator
//! holds the contact force at its setpoint; the force-limited reaction stays above it as the
//! stop.
//!
//! **Planning** ([`PolishJob::plan`], before the first step). The face is covered by parallel
//! passes along its longer side, at most 1.8 pad radii apart, 0.8 radii in from the long edges
//! and 0.4 from the short ones, joined at alternate ends (a raster). Every pass and every step between passes is a straight
//! Cartesian line of the tool point at the height where the pad just touches the face, with
//! the tool axis along the face's inward normal: a trapezoidal speed profile along the line,
//! sampled every 10 ms, each sample solved by inverse kinematics from the previous one, its
//! joint velocity from the Jacobian. The approach is a straight joint-space motion (time-scaled
//! within the joint and screw limits) from the start to a point above the first pass. Every
//! part is certified against the robot's joint and actuator limits and collision-free against
//! the scenario's obstacles (the certified verifier, continuous between samples); a line too
//! fast for a limit is slowed and solved again.
//!
//! **Running** ([`PolishArm`], every control step). The commanded configuration is the planned
//! one moved along the face's normal by `depth` (into the face when positive), through the
//! damped pseudo-inverse of the position Jacobian. The regulator is an admittance law on the
//! measured normal force `F`: `d depth/dt = K (F_set - F)`, limited to ±20 mm/s, so that before
//! contact it lowers the tool, in contact it holds `F` near the setpoint (with the world's spring
//! contact of stiffness `k` the force error decays with time constant `1 / (k K)`), and no plan
//! needs to know where exactly the face is. Phases: approach; descend until contact
//! (`Event::ContactMade`) and until the force stays in its band for 0.1 s
//! (`Event::ForceRegulated`); the raster, one `Event::PassFinished` per pass; lift the tool
//! 50 mm; `Event::GoalReached`.

use std::sync::Arc;

use embodied_executor::{
    Event, HaltReason, InputImages, OutputImages, Predicate, Primitive, Reactive, SafeHalt, TransitionFunction,
};
use embodied_models::nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3, Vector6};
use embodied_models::{IkOptions, Robot, Shape};
use embodied_planner::trajectory::{Trajectory, time_parameterize};
use embodied_planner::verify::Verifier;

use crate::SystemError;
use crate::scenario::{PolishSpec, Scenario};

/// Sample step of the planned Cartesian lines, s.
const LINE_DT: f64 = 0.01;
/// Tool acceleration along a line, m/s^2.
const LINE_ACCEL: f64 = 0.5;
/// Hover height of the approach above the contact height, m.
const HOVER: f64 = 0.015;
/// Lift at the end, m.
const LIFT: f64 = 0.05;
/// Admittance gain, m/(N s): with the 2e4 N/m contact, a time constant of 50 ms.
const ADMITTANCE: f64 = 1e-3;
/// Largest rate of the regulated depth, m/s.
const DEPTH_RATE: f64 = 0.02;
/// Normal force above which the tool is in contact, N.
const CONTACT_N: f64 = 2.0;
/// Steps the force must stay in its band before the raster starts.
const SETTLE_STEPS: u32 = 100;
/// Contact stiffness of the simulated force sensor, N/m (as the force-limited reaction's).
pub const CONTACT_STIFFNESS: f64 = 2.0e4;

/// The planned polishing job of one agent.
#[derive(Debug, Clone)]
pub struct PolishJob {
    /// The job as the scenario states it.
    pub spec: PolishSpec,
    /// Height of the face, m.
    pub top_z: f64,
    /// The face: `[x_min, x_max]`, `[y_min, y_max]`, m.
    pub face: [[f64; 2]; 2],
    /// The passes: start and end of the tool point at contact height.
    pub passes: Vec<([f64; 3], [f64; 3])>,
    /// From the start to the hover point above the first pass.
    pub approach: Trajectory,
    /// The raster in contact (passes and the steps between them), from rest to rest.
    pub raster: Trajectory,
    /// Time in [`PolishJob::raster`] at which each pass ends, s.
    pub pass_ends: Vec<f64>,
    /// Tool speed along the passes after certification (the spec's, or slower), m/s.
    pub speed: f64,
    /// Wall-clock planning time, ms.
    pub planning_ms: f64,
}

fn failed(m: String) -> SystemError {
    SystemError::Failed(format!("polish: {m}"))
}

/// The tool orientation of the job: tool z along the face's inward normal (world -z), tool x
/// along world x.
fn tool_rotation() -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
}

/// Joint velocities that give the tool `twist` (linear, angular) at `q`.
fn joint_rates(robot: &Robot, q: &[f64], twist: &Vector6<f64>) -> Result<Vec<f64>, SystemError> {
    let e = &robot.end_effectors()[0];
    let jac = robot.jacobian(q, e.link, &e.tool);
    let pinv = jac.pseudo_inverse(1e-10).map_err(|m| failed(format!("Jacobian not invertible: {m}")))?;
    Ok((pinv * twist).iter().copied().collect())
}

/// The configuration that moves the tool of `robot` by `dp` (m, world frame) from `q`, to first
/// order: damped least squares on the position rows of the Jacobian.
pub fn shifted(robot: &Robot, q: &[f64], dp: &Vector3<f64>, out: &mut [f64]) {
    let e = &robot.end_effectors()[0];
    let jac = robot.jacobian(q, e.link, &e.tool);
    let jp = jac.fixed_rows::<3>(0);
    let jjt = jp * jp.transpose() + embodied_models::nalgebra::Matrix3::identity() * 1e-8;
    let y = jjt.try_inverse().map_or(Vector3::zeros(), |m| m * dp);
    let dq = jp.transpose() * y;
    for (i, o) in out.iter_mut().enumerate() {
        *o = q[i] + dq[i];
    }
}

impl PolishJob {
    /// Plan the job of `spec` in `scenario`; see the module documentation.
    pub fn plan(scenario: &Scenario, spec: &PolishSpec) -> Result<PolishJob, SystemError> {
        let started = std::time::Instant::now();
        let agent = &scenario.agents[spec.agent];
        let robot = &agent.robot;
        let o = &scenario.obstacles[spec.workpiece];
        let Shape::Cuboid { half_extents: h } = &o.obstacle.shape else {
            return Err(failed(format!("workpiece `{}` is not a box", o.obstacle.name)));
        };
        let c = o.obstacle.pose.translation.vector;
        let top_z = c.z + h.z;
        let face = [[c.x - h.x, c.x + h.x], [c.y - h.y, c.y + h.y]];
        let r = spec.tool_radius;
        // Passes 0.8 radii in from the long edges (1.8 radii apart at most: the pads' bands
        // overlap) and from 0.4 radii of the short edges (the pad reaching over the edge covers
        // the notches between the ends of two passes not joined there).
        let (inset, inset_ends) = (0.8 * r, 0.4 * r);
        // Passes along the longer side; their number so that neighbours are <= 1.8 r apart.
        let along_x = h.x >= h.y;
        let (long, short) = if along_x { (face[0], face[1]) } else { (face[1], face[0]) };
        let width = (short[1] - short[0] - 2.0 * inset).max(0.0);
        let n = (width / (1.8 * r)).ceil() as usize + 1;
        let spacing = if n > 1 { width / (n - 1) as f64 } else { 0.0 };
        let z = top_z + spec.skin;
        let point = |a: f64, b: f64| if along_x { [a, b, z] } else { [b, a, z] };
        let passes: Vec<([f64; 3], [f64; 3])> = (0..n)
            .map(|k| {
                let b = short[0] + inset + k as f64 * spacing;
                let (a0, a1) = (long[0] + inset_ends, long[1] - inset_ends);
                if k % 2 == 0 { (point(a0, b), point(a1, b)) } else { (point(a1, b), point(a0, b)) }
            })
            .collect();
        let model = crate::plan::agent_problem(scenario, spec.agent, &[]);
        let verifier = Verifier::certified(0.0);
        let rot = tool_rotation();
        let pose = |p: [f64; 3]| Isometry3::from_parts(Translation3::new(p[0], p[1], p[2]), rot);
        // The first contact point, from the start (with restarts: the start may be far).
        let ik = IkOptions { position_tolerance: 1e-7, orientation_tolerance: 1e-7, ..IkOptions::default() };
        let first = robot
            .inverse_kinematics(0, &pose(passes[0].0), &agent.start, &ik)
            .map_err(|e| failed(format!("the first pass's start is out of reach: {e}")))?;
        let mut hover = first.clone();
        shifted(robot, &first, &Vector3::new(0.0, 0.0, HOVER), &mut hover);
        if !robot.within_limits(&hover) {
            return Err(failed("the hover point above the first pass is outside the joint or screw limits".into()));
        }
        let approach = time_parameterize(&[agent.start.clone(), hover], robot, LINE_DT);
        let report = verifier.check_trajectory(&model, &approach, &[]);
        if let Some(f) = report.findings().first() {
            return Err(failed(format!("the approach from the start is not certified: {f}")));
        }
        // The raster: every line at the same speed, slowed until every line is certified.
        let mut speed = spec.speed;
        for _ in 0..6 {
            match raster(robot, &passes, &first, speed) {
                Ok((raster, pass_ends)) => {
                    let report = verifier.check_trajectory(&model, &raster, &[]);
                    if report.collision.violation.is_some() {
                        let f = report.collision.violation.as_ref().map(|f| f.to_string()).unwrap_or_default();
                        return Err(failed(format!("the raster is not collision-free: {f}")));
                    }
                    if report.limits.ok {
                        let planning_ms = started.elapsed().as_secs_f64() * 1e3;
                        return Ok(PolishJob {
                            spec: spec.clone(),
                            top_z,
                            face,
                            passes,
                            approach,
                            raster,
                            pass_ends,
                            speed,
                            planning_ms,
                        });
                    }
                }
                Err(e) => return Err(e),
            }
            speed *= 0.7;
        }
        Err(failed(format!("no tool speed down to {speed:.3} m/s keeps the raster within the limits")))
    }
}

/// The raster through `passes` at tool `speed`, starting at configuration `q0` (the first
/// pass's start); the time each pass ends.
fn raster(
    robot: &Robot,
    passes: &[([f64; 3], [f64; 3])],
    q0: &[f64],
    speed: f64,
) -> Result<(Trajectory, Vec<f64>), SystemError> {
    let mut traj = Trajectory {
        joint_names: robot.joint_names(),
        t: vec![0.0],
        q: vec![q0.to_vec()],
        qd: vec![vec![0.0; q0.len()]],
    };
    let mut ends = Vec::new();
    let mut from = passes[0].0;
    for (k, &(a, b)) in passes.iter().enumerate() {
        if k > 0 {
            line(robot, &mut traj, from, a, speed)?;
        }
        line(robot, &mut traj, a, b, speed)?;
        ends.push(traj.duration());
        from = b;
    }
    Ok((traj, ends))
}

/// Append the straight tool line `a -> b` (rest to rest, trapezoidal speed) to `traj`, whose
/// last sample is at `a`.
fn line(robot: &Robot, traj: &mut Trajectory, a: [f64; 3], b: [f64; 3], speed: f64) -> Result<(), SystemError> {
    let d = Vector3::new(b[0] - a[0], b[1] - a[1], b[2] - a[2]);
    let length = d.norm();
    if length < 1e-9 {
        return Ok(());
    }
    let u = d / length;
    // Trapezoid (or triangle) in the arc length.
    let (v, acc) = (speed.min((LINE_ACCEL * length).sqrt()), LINE_ACCEL);
    let t_acc = v / acc;
    let t_end = length / v + t_acc;
    let arc = |t: f64| -> (f64, f64) {
        if t <= t_acc {
            (0.5 * acc * t * t, acc * t)
        } else if t <= t_end - t_acc {
            (0.5 * acc * t_acc * t_acc + v * (t - t_acc), v)
        } else {
            let r = (t_end - t).max(0.0);
            (length - 0.5 * acc * r * r, acc * r)
        }
    };
    let rot = tool_rotation();
    let ik = IkOptions { position_tolerance: 1e-8, orientation_tolerance: 1e-8, restarts: 0, ..IkOptions::default() };
    let t0 = traj.duration();
    let steps = (t_end / LINE_DT).ceil() as usize;
    let mut times: Vec<f64> = (1..steps).map(|k| k as f64 * LINE_DT).collect();
    times.extend([t_acc, t_end - t_acc, t_end]);
    times.sort_by(f64::total_cmp);
    times.dedup_by(|x, y| (*x - *y).abs() < 1e-6);
    for t in times {
        let (s, sd) = arc(t);
        let p = Vector3::new(a[0], a[1], a[2]) + u * s;
        let target = Isometry3::from_parts(Translation3::from(p), rot);
        let seed = traj.q.last().cloned().unwrap_or_default();
        let q = robot.inverse_kinematics(0, &target, &seed, &ik).map_err(|e| {
            failed(format!("the raster point ({:.3}, {:.3}, {:.3}) m is out of reach: {e}", p.x, p.y, p.z))
        })?;
        if !robot.within_limits(&q) {
            return Err(failed(format!(
                "the raster point ({:.3}, {:.3}, {:.3}) m is outside the joint or screw limits",
                p.x, p.y, p.z
            )));
        }
        let end = (t - t_end).abs() < 1e-9;
        let twist = Vector6::new(u.x * sd, u.y * sd, u.z * sd, 0.0, 0.0, 0.0);
        let qd = if end { vec![0.0; q.len()] } else { joint_rates(robot, &q, &twist)? };
        traj.t.push(t0 + t);
        traj.q.push(q);
        traj.qd.push(qd);
    }
    Ok(())
}

/// Fraction of the rectangle `face` within `radius` of at least one of `points` (x, y), on a
/// grid of `cell`-sized cells (a cell counts when its centre does).
pub fn coverage(face: [[f64; 2]; 2], points: &[[f64; 2]], radius: f64, cell: f64) -> f64 {
    let nx = ((face[0][1] - face[0][0]) / cell).ceil().max(1.0) as usize;
    let ny = ((face[1][1] - face[1][0]) / cell).ceil().max(1.0) as usize;
    let mut covered = vec![false; nx * ny];
    let reach = (radius / cell).ceil() as i64 + 1;
    for p in points {
        let ix = ((p[0] - face[0][0]) / cell).floor() as i64;
        let iy = ((p[1] - face[1][0]) / cell).floor() as i64;
        for i in (ix - reach).max(0)..=(ix + reach).min(nx as i64 - 1) {
            for j in (iy - reach).max(0)..=(iy + reach).min(ny as i64 - 1) {
                let cx = face[0][0] + (i as f64 + 0.5) * cell;
                let cy = face[1][0] + (j as f64 + 0.5) * cell;
                if (cx - p[0]).hypot(cy - p[1]) <= radius {
                    covered[i as usize * ny + j as usize] = true;
                }
            }
        }
    }
    covered.iter().filter(|&&c| c).count() as f64 / covered.len() as f64
}

/// Where the polishing agent is in its job.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    Approach,
    Descend,
    Raster,
    Lift,
    Done,
    Stopped,
}

/// `c_c` of the polishing agent: the job, the regulator's state and the per-pass tallies.
pub struct PolishArm {
    job: Arc<PolishJob>,
    robot: Arc<Robot>,
    /// Index of its contact sensor.
    force_sensor: usize,
    phase: Phase,
    /// Time in the current phase's trajectory, s.
    tau: f64,
    /// Regulated depth below the planned path, m (negative: above it).
    depth: f64,
    contact: bool,
    settled: u32,
    pass: usize,
    pass_force: f64,
    pass_steps: u32,
    reference: Vec<f64>,
    command: Vec<f64>,
    rates: Vec<f64>,
}

impl PolishArm {
    /// The agent's `c_c` for `job`; its contact sensor is sensor `force_sensor`.
    pub fn new(job: Arc<PolishJob>, robot: Arc<Robot>, force_sensor: usize) -> Self {
        let n = robot.dof();
        Self {
            job,
            robot,
            force_sensor,
            phase: Phase::Approach,
            tau: 0.0,
            depth: -HOVER,
            contact: false,
            settled: 0,
            pass: 0,
            pass_force: 0.0,
            pass_steps: 0,
            reference: vec![0.0; n],
            command: vec![0.0; n],
            rates: vec![0.0; n],
        }
    }

    fn normal_force(&self, i: &InputImages) -> f64 {
        if i.sensor_count() > self.force_sensor { i.sensor(self.force_sensor).values[4] } else { 0.0 }
    }

    /// Command the planned `(q, qd)` shifted by the regulated depth along the face's normal:
    /// one Jacobian per step, `dq/d depth` for a unit depth, applied to the depth and its rate.
    fn command_shifted(&mut self, q: &[f64], qd: &[f64], depth_rate: f64, o: &mut OutputImages) {
        shifted(&self.robot, q, &Vector3::new(0.0, 0.0, -1.0), &mut self.command);
        for k in 0..q.len() {
            let per_depth = self.command[k] - q[k];
            self.command[k] = q[k] + per_depth * self.depth;
            self.rates[k] = qd[k] + per_depth * depth_rate;
        }
        o.set_position_target(&self.command, &self.rates);
    }

    fn step(&mut self, i: &InputImages, o: &mut OutputImages) {
        let dt = i.dt();
        let f = self.normal_force(i);
        let setpoint = self.job.spec.force_n;
        let regulate = |depth: &mut f64| -> f64 {
            let rate = (ADMITTANCE * (setpoint - f)).clamp(-DEPTH_RATE, DEPTH_RATE);
            *depth += rate * dt;
            rate
        };
        match self.phase {
            Phase::Approach => {
                self.tau += dt;
                let (q, qd, _) = self.job.approach.sample(self.tau);
                o.set_position_target(&q, &qd);
                if self.tau >= self.job.approach.duration() {
                    self.phase = Phase::Descend;
                    self.tau = 0.0;
                }
            }
            Phase::Descend => {
                let rate = regulate(&mut self.depth);
                if !self.contact && f > CONTACT_N {
                    self.contact = true;
                    o.event(Event::ContactMade { force_n: f });
                }
                let in_band = (f - setpoint).abs() <= self.job.spec.band_n;
                self.settled = if self.contact && in_band { self.settled + 1 } else { 0 };
                if self.settled >= SETTLE_STEPS {
                    o.event(Event::ForceRegulated { force_n: f, setpoint_n: setpoint, depth_mm: self.depth * 1e3 });
                    self.phase = Phase::Raster;
                    self.tau = 0.0;
                }
                self.reference.clone_from(&self.job.raster.q[0]);
                let (q, zero) = (self.reference.clone(), vec![0.0; self.reference.len()]);
                self.command_shifted(&q, &zero, rate, o);
            }
            Phase::Raster => {
                let rate = regulate(&mut self.depth);
                self.tau += dt;
                self.pass_force += f;
                self.pass_steps += 1;
                let (q, qd, _) = self.job.raster.sample(self.tau);
                self.command_shifted(&q, &qd, rate, o);
                if let Some(&end) = self.job.pass_ends.get(self.pass)
                    && self.tau >= end
                {
                    let mean = self.pass_force / f64::from(self.pass_steps.max(1));
                    o.event(Event::PassFinished { pass: self.pass, passes: self.job.passes.len(), mean_force_n: mean });
                    self.pass += 1;
                    self.pass_force = 0.0;
                    self.pass_steps = 0;
                }
                if self.tau >= self.job.raster.duration() {
                    self.phase = Phase::Lift;
                }
            }
            Phase::Lift => {
                let rate = -DEPTH_RATE;
                self.depth += rate * dt;
                let end = self.job.raster.q.last().cloned().unwrap_or_default();
                let zero = vec![0.0; end.len()];
                if self.depth <= -LIFT {
                    self.depth = -LIFT;
                    self.command_shifted(&end, &zero, 0.0, o);
                    self.phase = Phase::Done;
                    o.event(Event::GoalReached { id: None });
                } else {
                    self.command_shifted(&end, &zero, rate, o);
                }
            }
            Phase::Done | Phase::Stopped => {
                let q = i.q().to_vec();
                o.set_position_target(&q, &vec![0.0; q.len()]);
            }
        }
    }
}

/// The polishing agent's program: the force-limited reaction (contact force over the limit:
/// a controlled stop, job abandoned) above the job.
pub fn polish_program(force_limit: Option<f64>) -> Reactive<PolishArm> {
    let mut program = Reactive::priority("polish");
    if force_limit.is_some() {
        program = program.rule(
            Predicate::new("force_over_limit", |c: &PolishArm, i| {
                c.phase == Phase::Stopped
                    || (i.sensor_count() > c.force_sensor && i.sensor(c.force_sensor).values[1] > 0.5)
            }),
            Primitive::new("force_stop", 1, move |c: &mut PolishArm, i: &InputImages, o: &mut OutputImages| {
                TransitionFunction::compute(&mut SafeHalt, c, i, o);
                if c.phase != Phase::Stopped {
                    let speed = i.qd().iter().fold(0.0_f64, |m, v| m.max(v.abs()));
                    o.event(Event::ForceLimit { force_n: i.sensor(c.force_sensor).values[0] });
                    o.event(Event::HaltStarted { reason: HaltReason::ForceLimit, speed, detail: None });
                    c.phase = Phase::Stopped;
                }
            }),
        );
    }
    program.main_reaction(Primitive::new("polish", 1, |c: &mut PolishArm, i: &InputImages, o: &mut OutputImages| {
        c.step(i, o)
    }))
}

/// The tool points (x, y) of `q`s whose tool is within `skin` of the face (in contact), and
/// the spring force there, from forward kinematics alone: what a log shows was polished.
pub fn contact_of(robot: &Robot, job: &PolishJob, q: &[f64]) -> Option<([f64; 2], f64)> {
    let p = robot.end_effector_poses(q, 0).1.translation.vector;
    let [[x0, x1], [y0, y1]] = job.face;
    let inside = p.x >= x0 && p.x <= x1 && p.y >= y0 && p.y <= y1;
    let gap = p.z - job.top_z;
    (inside && gap < job.spec.skin).then(|| ([p.x, p.y], CONTACT_STIFFNESS * (job.spec.skin - gap)))
}
