//! The two-handed carry as an embodied agent: one agent whose effector is both arms.
//!
//! Its `c_c` holds the carry plan (approach, insertion, the closed-chain carry, retreat; made by
//! [`embodied_planner::carry::plan_carry`]) and the closed-chain controller. Each control step a priority
//! list of transition functions picks one:
//! - `safe_halt` once a closed-chain QP has failed (never an unchecked command);
//! - `closed_chain` while the object is held: a QP finds both arms' joint velocities that keep
//!   the grasps rigid (closure with drift correction), track the object's planned motion (with
//!   pose feedback), follow the planned arm posture in the remaining freedom, stay inside the
//!   position, velocity and acceleration limits and slow down near obstacles (a velocity damper
//!   on the nearest pair);
//! - `follow_plan` otherwise: position targets along the plan's free motions.
//!
//! The events `grasp` and `release` mark where the closed chain begins and ends.

use std::sync::{Arc, Mutex};
use std::time::Instant;

use embodied_models::Robot;
use embodied_models::collision::{Body, CollisionModel, Environment};
use embodied_models::nalgebra::{DMatrix, DVector, Isometry3, Vector6};
use embodied_planner::carry::{CarryPlan, pose_difference, tool_pose};
use serde::Serialize;

use super::{
    ChainKinematics, ClosedChainConfig, ClosedChainController, ClosureMode, DamperParams, StepInput, VelocityDamper,
    pose_error, relative_pose_error, step_bounds,
};
use crate::agent::Agent;
use crate::behaviour::{Primitive, Reactive};
use crate::effector::SafeHalt;
use crate::error::ExecutorError;
use crate::event::{Event, HaltReason};
use crate::image::{InputImages, OutputImages};
use crate::transition::{Predicate, TransitionFunction};

/// Gain of the object pose feedback, 1/s.
const OBJECT_GAIN: f64 = 10.0;
/// Gain of the posture feedback (planned joint values), 1/s.
const POSTURE_GAIN: f64 = 5.0;

/// What the closed-chain steps of a run measured.
#[derive(Debug, Clone, Default, Serialize)]
pub struct ClosedChainSummary {
    /// The carrying agent's name.
    pub agent: String,
    /// Wall-clock time the carry plan took, ms.
    pub planning_ms: f64,
    /// Duration of the planned trajectory, s.
    pub plan_duration_s: f64,
    /// Time the object was grasped (both tools holding it), s from the start; `None` if never.
    pub grasp_s: Option<f64>,
    /// Time the object was released, s from the start; `None` if never.
    pub release_s: Option<f64>,
    /// Control steps that solved the closed-chain QP.
    pub qp_steps: usize,
    /// Median controller step time (assembly and solve), µs.
    pub qp_p50_us: f64,
    /// 99th percentile controller step time, µs.
    pub qp_p99_us: f64,
    /// Largest controller step time, µs.
    pub qp_max_us: f64,
    /// Steps whose QP alone took longer than the control step.
    pub qp_late_steps: usize,
    /// Steps where the dense QP solver failed and clarabel answered instead.
    pub qp_fallbacks: usize,
    /// Steps where the closure equality was infeasible and became a cost term ([`ClosureMode::Slacked`]).
    pub slacked_steps: usize,
    /// Largest closure residual `||J_R qd + k_r e_r||` of any step.
    pub max_closure_residual: f64,
    /// Largest drift of the relative pose of the two tools from its value at the grasp.
    pub max_closure_error_m: f64,
    /// Largest drift of the relative tool rotation from its value at the grasp, rad.
    pub max_closure_error_rad: f64,
    /// Largest distance of the object from its planned pose while held.
    pub max_tracking_error_m: f64,
    /// Smallest distance of the held robot to an obstacle or of one arm to the other over the held
    /// steps, m (0 when none was measured).
    pub closest_obstacle_m: f64,
    /// Steps with at least one collision velocity damper row.
    pub damper_steps: usize,
    /// Steps where a damper asked for more deceleration than the limits allow in one step.
    pub damper_relaxed_steps: usize,
    /// Safe halts begun.
    pub halts: usize,
    /// Why the last safe halt began, if one did.
    pub halt_reason: Option<String>,
    /// Where the object was put down, against the scenario's goal, m.
    pub object_goal_error_m: Option<f64>,
    /// Whether the planned trajectory ran to its end.
    pub completed: bool,
}

/// Measurements shared between the agent and the run.
#[derive(Debug, Default)]
pub struct CarryRecord {
    /// The measurements reported at the end.
    pub summary: ClosedChainSummary,
    /// Per held step: the whole controller step (assembly and solve), ns.
    pub qp_ns: Vec<u64>,
    /// With `compare`: each step's QP solved by the fast dense solver and by clarabel, ns.
    pub fast_ns: Vec<u64>,
    /// With `compare`: each step's QP solve time with clarabel, ns (see `fast_ns`).
    pub reference_ns: Vec<u64>,
    /// With `compare`: largest `||qd_fast - qd_ref||∞ / max(1, ||qd_ref||∞)` over the steps.
    pub max_qd_difference: f64,
    /// With `compare`: largest relative objective difference `|f_fast - f_ref| / max(1, |f_ref|)` over the steps.
    pub max_objective_difference: f64,
}

/// `c_c` of the carrying agent.
pub struct CarryAgent {
    robot: Arc<Robot>,
    /// The arms (with the object) against the environment, self pairs off.
    against_environment: CollisionModel,
    /// One arm (with the object) against the other, no environment.
    arm_against_arm: CollisionModel,
    plan: CarryPlan,
    controller: ClosedChainController,
    limits: Vec<embodied_models::JointLimits>,
    damper: DamperParams,
    /// Relative pose of tool 2 in tool 1 at the grasp.
    reference: Option<Isometry3<f64>>,
    /// The object in tool 1's frame.
    object_in_tool: Isometry3<f64>,
    goal: Isometry3<f64>,
    /// Planning time as the run's clock counts it, ms.
    planning_ms: f64,
    /// Solve every QP with clarabel too (timing and agreement).
    compare: bool,
    released: bool,
    halted: bool,
    done: bool,
    record: Arc<Mutex<CarryRecord>>,
    qp_fault: Option<QpFault>,
}

/// An injected fault of the closed-chain QP: asked at every closed-chain step (its index);
/// `true` makes that step's QP report infeasible, whatever the solver found.
pub type QpFault = Box<dyn FnMut(u64) -> bool + Send>;

impl CarryAgent {
    /// The robot's screws as rows of the QP (serial-parallel actuation): each screw's speed
    /// `|dl/dq · qd| <= max_speed`, and its length kept inside the stroke (`l + dl/dq · qd dt`
    /// within `[min_length, max_length]`). Only rows that the step's velocity box (`lo`, `hi`)
    /// could violate are added, most binding first, up to the controller's row budget; a row the
    /// box cannot satisfy is relaxed to its least violation, like the collision dampers.
    fn screw_rows(&self, q: &[f64], lo: &[f64], hi: &[f64], dt: f64, rows: &mut Vec<VelocityDamper>) {
        let mut found: Vec<(f64, VelocityDamper)> = Vec::new();
        for screw in self.robot.actuators() {
            let l = screw.length(q);
            if !l.is_finite() {
                continue;
            }
            let mut g = DVector::zeros(q.len());
            for (k, d) in screw.gradient(q) {
                if k < q.len() {
                    g[k] += d;
                }
            }
            let extend = screw.max_speed.min(((screw.max_length - l) / dt).max(0.0));
            let retract = screw.max_speed.min(((l - screw.min_length) / dt).max(0.0));
            // The row `sign * g`, made only when the box could violate it.
            for (sign, b) in [(1.0, extend), (-1.0, retract)] {
                let bound = |upper: bool| -> f64 {
                    g.iter()
                        .enumerate()
                        .map(|(j, g)| {
                            let a = sign * g;
                            if (a > 0.0) == upper { a * hi[j] } else { a * lo[j] }
                        })
                        .sum()
                };
                if bound(true) <= b {
                    continue;
                }
                let least = bound(false);
                let b = if least > b { least + 1e-9 * (1.0 + least.abs()) } else { b };
                found.push((b - least, VelocityDamper::new(&g * sign, b)));
            }
        }
        found.sort_by(|x, y| x.0.total_cmp(&y.0));
        let room = self.controller.config().max_dampers.saturating_sub(rows.len());
        rows.extend(found.into_iter().take(room).map(|(_, row)| row));
    }

    fn time(i: &InputImages) -> f64 {
        i.step() as f64 * i.dt()
    }

    fn holding(&self, t: f64) -> bool {
        !self.halted && t >= self.plan.span.from_s && t < self.plan.span.to_s
    }

    fn with_record(&self, f: impl FnOnce(&mut CarryRecord)) {
        if let Ok(mut r) = self.record.lock() {
            f(&mut r);
        }
    }

    /// Halt: the controlled stop of [`SafeHalt`], and the reason in the log.
    fn halt(&mut self, reason: String, i: &InputImages, o: &mut OutputImages) {
        if !self.halted {
            self.halted = true;
            let speed = i.qd().iter().fold(0.0_f64, |m, v| m.max(v.abs()));
            o.event(Event::HaltStarted { reason: HaltReason::ClosedChain, speed, detail: Some(reason.clone()) });
            self.with_record(|r| {
                r.summary.halts += 1;
                r.summary.halt_reason = Some(reason);
            });
        }
        TransitionFunction::compute(&mut SafeHalt, &mut (), i, o);
    }

    /// The free motions: position targets along the plan.
    fn follow(&mut self, i: &InputImages, o: &mut OutputImages) {
        let t = Self::time(i);
        if i.step() == 0 {
            o.event(Event::PlanLanded {
                id: 0,
                world: 0,
                in_time: true,
                work: self.plan.stats.collision_checks,
                planning_ms: self.planning_ms,
                duration_s: self.plan.trajectory.duration(),
                wall: None,
            });
        }
        if !self.released && self.reference.is_some() && t >= self.plan.span.to_s {
            self.released = true;
            o.event(Event::Release);
            let object = tool_pose(&self.robot, i.q(), 0) * self.object_in_tool;
            let error = (object.translation.vector - self.goal.translation.vector).norm();
            o.event(Event::ObjectPlaced { error_m: error });
            self.with_record(|r| {
                r.summary.release_s = Some(t);
                r.summary.object_goal_error_m = Some(error);
            });
        }
        let (q, qd, _) = self.plan.trajectory.sample(t);
        if t >= self.plan.trajectory.duration() && !self.done {
            self.done = true;
            o.event(Event::GoalReached { id: None });
            self.with_record(|r| r.summary.completed = true);
        }
        o.set_position_target(&q, &qd);
    }

    /// One closed-chain step.
    fn closed_chain(&mut self, i: &InputImages, o: &mut OutputImages) {
        let t = Self::time(i);
        let q = i.q();
        let kin = match ChainKinematics::new(&self.robot, q) {
            Ok(k) => k,
            Err(e) => return self.halt(e.to_string(), i, o),
        };
        let reference = match self.reference {
            Some(r) => r,
            None => {
                let r = kin.relative_pose();
                self.reference = Some(r);
                o.event(Event::Grasp);
                self.with_record(|rec| rec.summary.grasp_s = Some(t));
                // The controller's acceleration bound starts from the arms' actual velocity.
                if let Err(e) = self.controller.set_previous_velocity(i.qd()) {
                    return self.halt(e.to_string(), i, o);
                }
                r
            }
        };
        let (q_plan, qd_plan, _) = self.plan.trajectory.sample(t + i.dt());
        // The object's task: its frame rigidly attached to tool 1 (the symmetric "absolute" frame
        // of the two tools is ill-defined when they face each other, as here). One forward
        // kinematics pass per configuration serves every Jacobian of this step.
        let holder = &self.robot.end_effectors()[0];
        let frame = holder.tool * self.object_in_tool;
        let poses = self.robot.forward_kinematics(q);
        let planned_poses = self.robot.forward_kinematics(&q_plan);
        let j_object = self.robot.jacobian_with_poses(&poses, holder.link, &frame);
        let j_object = DMatrix::from_column_slice(6, q.len(), j_object.as_slice());
        let j_planned = self.robot.jacobian_with_poses(&planned_poses, holder.link, &frame);
        let feedforward: Vector6<f64> = j_planned * DVector::from_column_slice(&qd_plan);
        let object = kin.tool1 * self.object_in_tool;
        let planned_object = planned_poses[holder.link] * frame;
        let v_a = feedforward + pose_error(&planned_object, &object) * OBJECT_GAIN;
        let e_r = relative_pose_error(&kin.tool1, &kin.tool2, &reference);
        let posture: Vec<f64> =
            qd_plan.iter().zip(q_plan.iter().zip(q)).map(|(v, (p, a))| v + POSTURE_GAIN * (p - a)).collect();
        // Velocity dampers: the nearest pair between the arms (the object with the holder) and
        // the nearest pair between the arms (with the object) and the environment.
        let mut dampers = Vec::new();
        let mut nearest = f64::INFINITY;
        let mut relaxed = false;
        // Within one step the joints can only decelerate so much: a row asking for more than
        // the acceleration limits allow becomes "approach as slowly as possible".
        let (mut lo, mut hi) = (vec![0.0; q.len()], vec![0.0; q.len()]);
        step_bounds(q, self.controller.previous_velocity().as_slice(), &self.limits, i.dt(), &mut lo, &mut hi);
        let reports = [self.arm_against_arm.distance(q), self.against_environment.distance(q)];
        if let Some(r) = reports.iter().find(|r| r.distance <= 0.0) {
            let reason = format!("contact: {} and {}", r.a.name(), r.b.name());
            return self.halt(reason, i, o);
        }
        for report in &reports {
            nearest = nearest.min(report.distance);
            if report.distance >= self.damper.influence {
                continue;
            }
            let normal = (report.point_a - report.point_b) / report.distance;
            let jac = |body: &Body, p: &embodied_models::nalgebra::Point3<f64>| match body {
                Body::Link { link, .. } => {
                    let local = poses[*link].inverse_transform_point(p);
                    self.robot.jacobian_with_poses(&poses, *link, &Isometry3::translation(local.x, local.y, local.z))
                }
                Body::Obstacle { .. } => embodied_models::nalgebra::Matrix6xX::zeros(q.len()),
            };
            let (ja, jb) = (jac(&report.a, &report.point_a), jac(&report.b, &report.point_b));
            if let Some(mut row) = VelocityDamper::from_witness(&normal, &ja, &jb, report.distance, &self.damper) {
                let best: f64 =
                    row.a.iter().enumerate().map(|(j, a)| if *a > 0.0 { a * lo[j] } else { a * hi[j] }).sum();
                if best > row.b {
                    row.b = best + 1e-9 * (1.0 + best.abs());
                    relaxed = true;
                }
                dampers.push(row);
            }
        }
        self.screw_rows(q, &lo, &hi, i.dt(), &mut dampers);
        let input =
            StepInput { q, j_a: &j_object, j_r: &kin.j_r, v_a, e_r, dampers: &dampers, reference: Some(&posture) };
        let started = Instant::now();
        let solution = if self.compare {
            // Both solvers on this step's QP: the fast one drives, clarabel is timed and compared.
            self.controller.compare(&input).map(|c| {
                self.with_record(|r| {
                    r.reference_ns.push(c.reference.solve_ns);
                    r.fast_ns.push(c.fast.solve_ns);
                    r.max_qd_difference = r.max_qd_difference.max(c.qd_difference);
                    r.max_objective_difference = r.max_objective_difference.max(c.objective_difference);
                });
                c.fast
            })
        } else {
            self.controller.step(&input)
        };
        let ns = started.elapsed().as_nanos() as u64;
        let dt = i.dt();
        let injected = self.qp_fault.as_mut().is_some_and(|f| f(i.step()));
        let solution = if injected {
            Err(ExecutorError::QpInfeasible("injected fault: the QP reports infeasible".into()))
        } else {
            solution
        };
        match solution {
            Ok(s) => {
                let (closure_m, closure_rad) = pose_difference(&reference, &kin.relative_pose());
                let tracking = (object.translation.vector - planned_object.translation.vector).norm();
                let qd: Vec<f64> = s.qd.iter().copied().collect();
                self.with_record(|r| {
                    let m = &mut r.summary;
                    r.qp_ns.push(ns);
                    m.qp_steps += 1;
                    m.qp_late_steps += usize::from(ns as f64 * 1e-9 > dt);
                    m.qp_fallbacks += usize::from(s.fell_back);
                    m.slacked_steps += usize::from(s.closure == ClosureMode::Slacked);
                    m.max_closure_residual = m.max_closure_residual.max(s.closure_residual);
                    m.max_closure_error_m = m.max_closure_error_m.max(closure_m);
                    m.max_closure_error_rad = m.max_closure_error_rad.max(closure_rad);
                    m.max_tracking_error_m = m.max_tracking_error_m.max(tracking);
                    m.closest_obstacle_m = m.closest_obstacle_m.min(nearest);
                    m.damper_steps += usize::from(!dampers.is_empty());
                    m.damper_relaxed_steps += usize::from(relaxed);
                });
                o.set_velocity_target(&qd);
            }
            Err(e) => self.halt(e.to_string(), i, o),
        }
    }
}

/// The carrying agent's program: halt > closed chain > follow the plan.
fn program() -> Reactive<CarryAgent> {
    Reactive::priority("carry")
        .rule(
            Predicate::new("qp_failed", |c: &CarryAgent, _| c.halted),
            Primitive::new("safe_halt", 1, |_: &mut CarryAgent, i: &InputImages, o: &mut OutputImages| {
                TransitionFunction::compute(&mut SafeHalt, &mut (), i, o);
            }),
        )
        .rule(
            Predicate::new("holding", |c: &CarryAgent, i| c.holding(CarryAgent::time(i))),
            Primitive::new("closed_chain", 1, |c: &mut CarryAgent, i: &InputImages, o: &mut OutputImages| {
                c.closed_chain(i, o);
            }),
        )
        .main_reaction(Primitive::new("follow_plan", 1, |c: &mut CarryAgent, i: &InputImages, o: &mut OutputImages| {
            c.follow(i, o);
        }))
}

/// The carrying agent and its shared measurements.
pub type CarryParts = (Agent<CarryAgent>, Arc<Mutex<CarryRecord>>);

/// What the carrying agent is made of.
#[derive(Debug, Clone)]
pub struct CarrySetup {
    /// The agent's name.
    pub name: String,
    /// The robot whose end effectors 0 and 1 are the two hands.
    pub robot: Robot,
    /// The carry plan ([`embodied_planner::carry::plan_carry`]).
    pub plan: CarryPlan,
    /// The obstacles the dampers keep the arms and the object away from.
    pub environment: Environment,
    /// Where the object should be put down.
    pub object_goal: Isometry3<f64>,
    /// The closed-chain controller's settings (its `dt` is the control step).
    pub config: ClosedChainConfig,
    /// Planning time as the run's clock counts it, ms (logged with the plan).
    pub planning_ms: f64,
    /// Solve every QP with clarabel as well (timing and agreement).
    pub compare: bool,
}

/// [`carry_agent`] whose closed-chain QP has an injected fault: the pair halts (reason
/// `closed_chain`) the step the QP reports infeasible, as for a real infeasible QP.
pub fn carry_agent_with_fault(setup: CarrySetup, fault: QpFault) -> Result<CarryParts, ExecutorError> {
    carry_agent_inner(setup, Some(fault))
}

/// The carrying agent: its `c_c` ([`CarryAgent`]) and program (halt > closed chain > follow).
pub fn carry_agent(setup: CarrySetup) -> Result<CarryParts, ExecutorError> {
    carry_agent_inner(setup, None)
}

fn carry_agent_inner(setup: CarrySetup, qp_fault: Option<QpFault>) -> Result<CarryParts, ExecutorError> {
    let CarrySetup { name, robot, plan, environment, object_goal, config, planning_ms, compare } = setup;
    let invalid = |reason: &str| ExecutorError::InvalidParameter {
        what: format!("carry of agent '{name}'"),
        reason: reason.into(),
    };
    let object = plan.span.object.clone().ok_or_else(|| invalid("the plan holds no object"))?;
    let object_in_tool = object.pose_in_tool().ok_or_else(|| invalid("the object's pose in the tool is not finite"))?;
    let ee = [0, 1];
    let hands: Vec<&str> = robot.end_effectors().iter().take(2).map(|e| e.name.as_str()).collect();
    if hands != [plan.span.end_effectors[0].as_str(), plan.span.end_effectors[1].as_str()] {
        return Err(invalid("the two hands must be the robot's end effectors 0 and 1"));
    }
    let other_link = robot.end_effectors()[ee[1]].link;
    let held_robot = object.attach(&robot, ee[0], &[other_link]).ok_or_else(|| invalid("cannot attach the object"))?;
    let (against_environment, arm_against_arm) = damper_models(&held_robot, ee, environment);
    let controller = ClosedChainController::new(robot.limits(), config)?;
    let record = Arc::new(Mutex::new(CarryRecord {
        summary: ClosedChainSummary {
            agent: name.clone(),
            planning_ms,
            plan_duration_s: plan.trajectory.duration(),
            closest_obstacle_m: f64::INFINITY,
            ..ClosedChainSummary::default()
        },
        ..CarryRecord::default()
    }));
    let start = plan.trajectory.q.first().cloned();
    let robot = Arc::new(robot);
    let state = CarryAgent {
        robot: robot.clone(),
        against_environment,
        arm_against_arm,
        plan,
        controller,
        limits: robot.limits(),
        damper: DamperParams { xi: 1.0, safety: 0.003, influence: 0.03 },
        reference: None,
        object_in_tool,
        goal: object_goal,
        planning_ms,
        compare,
        released: false,
        halted: false,
        done: false,
        record: record.clone(),
        qp_fault,
    };
    let a = Agent::embodied(name, robot, start.as_deref(), state, program())?;
    Ok((a, record))
}

/// The two collision models of the dampers: the robot without self pairs among the
/// environment, and each arm's links (the chain to its end effector) against the other arm's,
/// with no environment.
fn damper_models(robot: &Robot, ee: [usize; 2], environment: Environment) -> (CollisionModel, CollisionModel) {
    let n = robot.links().len();
    let alone = robot.without_self_collisions();
    let arm = |k: usize| -> Vec<usize> {
        let link = robot.end_effectors()[ee[k]].link;
        let mut links: Vec<usize> = robot.chain_to(link).iter().map(|&j| robot.joints()[j].child_link).collect();
        links.retain(|&l| l != 0);
        links
    };
    let (first, second) = (arm(0), arm(1));
    let mut arms = robot.clone();
    for a in 0..n {
        for b in a + 1..n {
            let across = (first.contains(&a) && second.contains(&b)) || (first.contains(&b) && second.contains(&a));
            if !across {
                arms.disable_pair(a, b);
            }
        }
    }
    (CollisionModel::new(&alone, environment), CollisionModel::new(&arms, Environment::new()))
}

/// p50, p99 and max of times in ns, as µs.
pub fn percentiles_us(ns: &[u64]) -> (f64, f64, f64) {
    let mut ns = ns.to_vec();
    ns.sort_unstable();
    let pct = |p: f64| ns.get(((ns.len() as f64 - 1.0) * p).round() as usize).map_or(0.0, |v| *v as f64 / 1e3);
    (pct(0.5), pct(0.99), ns.last().map_or(0.0, |v| *v as f64 / 1e3))
}

/// Percentiles of the QP times into the summary.
pub fn finish(record: &Mutex<CarryRecord>) -> Option<ClosedChainSummary> {
    let r = record.lock().ok()?;
    let mut s = r.summary.clone();
    (s.qp_p50_us, s.qp_p99_us, s.qp_max_us) = percentiles_us(&r.qp_ns);
    if !s.closest_obstacle_m.is_finite() {
        s.closest_obstacle_m = 0.0;
    }
    Some(s)
}
