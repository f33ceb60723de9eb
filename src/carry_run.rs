//! The two-handed carry as an embodied agent: one agent whose effector is both IRp-6 arms.
//!
//! Its `c_c` holds the carry plan (made before the first step: approach, insertion, the
//! closed-chain carry, retreat) and the closed-chain controller. Each control step a priority
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

use embodied_executor::closed_chain::{
    ChainKinematics, ClosedChainConfig, ClosedChainController, ClosureMode, DamperParams, StepInput, VelocityDamper,
    pose_error, relative_pose_error,
};
use embodied_executor::{Agent, InputImages, OutputImages, Predicate, Primitive, Reactive, SafeHalt, TransitionFunction};
use embodied_models::collision::{Body, CollisionModel};
use embodied_models::nalgebra::{DVector, Isometry3, Vector6};
use embodied_models::Robot;
use embodied_planner::carry::{CarryPlan, plan_carry, pose_difference};
use serde::Serialize;

use crate::AppError;
use crate::scenario::{ClockSpec, Scenario};

/// Gain of the object pose feedback, 1/s.
const OBJECT_GAIN: f64 = 10.0;
/// Gain of the posture feedback (planned joint values), 1/s.
const POSTURE_GAIN: f64 = 5.0;

/// What the closed-chain steps of a run measured.
#[derive(Debug, Clone, Default, Serialize)]
pub struct ClosedChainSummary {
    pub agent: String,
    pub planning_ms: f64,
    pub plan_duration_s: f64,
    pub grasp_s: Option<f64>,
    pub release_s: Option<f64>,
    pub qp_steps: usize,
    pub qp_p50_us: f64,
    pub qp_p99_us: f64,
    pub qp_max_us: f64,
    /// Steps whose QP alone took longer than the control step.
    pub qp_late_steps: usize,
    pub qp_fallbacks: usize,
    pub slacked_steps: usize,
    pub max_closure_residual: f64,
    /// Largest drift of the relative pose of the two tools from its value at the grasp.
    pub max_closure_error_m: f64,
    pub max_closure_error_rad: f64,
    /// Largest distance of the object from its planned pose while held.
    pub max_tracking_error_m: f64,
    pub closest_obstacle_m: f64,
    pub damper_steps: usize,
    pub halts: usize,
    pub halt_reason: Option<String>,
    /// Where the object was put down, against the scenario's goal, m.
    pub object_goal_error_m: Option<f64>,
    pub completed: bool,
}

/// Measurements shared between the agent and the run.
#[derive(Debug, Default)]
pub struct CarryRecord {
    pub summary: ClosedChainSummary,
    pub qp_ns: Vec<u64>,
}

/// `c_c` of the carrying agent.
pub struct CarryAgent {
    robot: Arc<Robot>,
    held: CollisionModel,
    plan: CarryPlan,
    controller: ClosedChainController,
    damper: DamperParams,
    /// Relative pose of tool 2 in tool 1 at the grasp.
    reference: Option<Isometry3<f64>>,
    /// The object in tool 1's frame.
    object_in_tool: Isometry3<f64>,
    goal: Isometry3<f64>,
    /// Planning time as the run's clock counts it, ms.
    planning_ms: f64,
    released: bool,
    halted: bool,
    done: bool,
    record: Arc<Mutex<CarryRecord>>,
}

impl CarryAgent {
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
            o.event(format!("safe_halt_started reason=qp: {reason}"));
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
            o.event(format!(
                "plan_landed planning_ms={:.3} duration_s={:.3} collision_checks={}",
                self.planning_ms,
                self.plan.trajectory.duration(),
                self.plan.stats.collision_checks
            ));
        }
        if !self.released && self.reference.is_some() && t >= self.plan.span.to_s {
            self.released = true;
            o.event("release");
            let object = tool_pose(&self.robot, i.q(), 0) * self.object_in_tool;
            let error = (object.translation.vector - self.goal.translation.vector).norm();
            o.event(format!("object put down {error:.4} m from its goal"));
            self.with_record(|r| {
                r.summary.release_s = Some(t);
                r.summary.object_goal_error_m = Some(error);
            });
        }
        let (q, qd, _) = self.plan.trajectory.sample(t);
        if t >= self.plan.trajectory.duration() && !self.done {
            self.done = true;
            o.event("goal_reached: carry completed");
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
                o.event("grasp");
                self.with_record(|rec| rec.summary.grasp_s = Some(t));
                // The controller's acceleration bound starts from the arms' actual velocity.
                if let Err(e) = self.controller.set_previous_velocity(i.qd()) {
                    return self.halt(e.to_string(), i, o);
                }
                r
            }
        };
        let (q_plan, qd_plan, _) = self.plan.trajectory.sample(t + i.dt());
        let planned = match ChainKinematics::new(&self.robot, &q_plan) {
            Ok(k) => k,
            Err(e) => return self.halt(e.to_string(), i, o),
        };
        let qd_plan_v = DVector::from_column_slice(&qd_plan);
        let feedforward: Vector6<f64> = {
            let v = &planned.j_a * &qd_plan_v;
            Vector6::from_iterator(v.iter().copied())
        };
        let v_a = feedforward + pose_error(&planned.absolute_pose(), &kin.absolute_pose()) * OBJECT_GAIN;
        let e_r = relative_pose_error(&kin.tool1, &kin.tool2, &reference);
        let posture: Vec<f64> =
            qd_plan.iter().zip(q_plan.iter().zip(q)).map(|(v, (p, a))| v + POSTURE_GAIN * (p - a)).collect();
        // The nearest pair (arm-arm, arm-object, arm/object-environment) as a velocity damper.
        let report = self.held.distance(q);
        let mut dampers = Vec::new();
        if report.distance < self.damper.influence && report.distance > 0.0 {
            let normal = (report.point_a - report.point_b) / report.distance;
            let jac = |body: &Body, p: &embodied_models::nalgebra::Point3<f64>| match body {
                Body::Link { link, .. } => {
                    let local = self.robot.link_pose(q, *link).inverse_transform_point(p);
                    Some(self.robot.jacobian(q, *link, &Isometry3::translation(local.x, local.y, local.z)))
                }
                Body::Obstacle { .. } => None,
            };
            let zero = embodied_models::nalgebra::Matrix6xX::zeros(q.len());
            let ja = jac(&report.a, &report.point_a).unwrap_or_else(|| zero.clone());
            let jb = jac(&report.b, &report.point_b).unwrap_or(zero);
            dampers.extend(VelocityDamper::from_witness(&normal, &ja, &jb, report.distance, &self.damper));
        } else if report.distance <= 0.0 {
            return self.halt(format!("contact: {} and {}", report.a.name(), report.b.name()), i, o);
        }
        let input = StepInput { q, j_a: &kin.j_a, j_r: &kin.j_r, v_a, e_r, dampers: &dampers, posture: &posture };
        let started = Instant::now();
        let solution = self.controller.step(&input);
        let ns = started.elapsed().as_nanos() as u64;
        let dt = i.dt();
        match solution {
            Ok(s) => {
                let (closure_m, closure_rad) = pose_difference(&reference, &kin.relative_pose());
                let object = kin.tool1 * self.object_in_tool;
                let planned_object = planned.tool1 * self.object_in_tool;
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
                    m.closest_obstacle_m = m.closest_obstacle_m.min(report.distance);
                    m.damper_steps += usize::from(!dampers.is_empty());
                });
                o.set_velocity_target(&qd);
            }
            Err(e) => self.halt(e.to_string(), i, o),
        }
    }
}

fn tool_pose(robot: &Robot, q: &[f64], ee: usize) -> Isometry3<f64> {
    robot.end_effector_poses(q, ee).1
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

/// The carrying agent of `scenario` (which has a `[carry]` table): the plan is made here.
pub fn carry_agent(
    scenario: &Scenario,
    dt: f64,
    clock: ClockSpec,
) -> Result<(Agent<CarryAgent>, Arc<Mutex<CarryRecord>>, serde_json::Value), AppError> {
    let (Some(task), Some(spec)) = (scenario.carry_task(), &scenario.carry) else {
        return Err(AppError::Failed(format!("scenario `{}` has no [carry] table", scenario.name)));
    };
    let agent = &scenario.agents[spec.agent];
    let mut settings = scenario.carry_settings();
    settings.dt = dt;
    let plan = plan_carry(&task, &settings)
        .map_err(|e| AppError::Failed(format!("scenario `{}`: agent `{}`: carry: {e}", scenario.name, agent.name)))?;
    let object = plan.span.object.clone().ok_or_else(|| AppError::Failed("carry plan without its object".into()))?;
    let object_in_tool = object.pose_in_tool().ok_or_else(|| AppError::Failed("carry: bad object pose".into()))?;
    let ee = task.end_effectors;
    if ee != [0, 1] {
        return Err(AppError::Failed(format!(
            "scenario `{}`: carry: `embodied run` drives end effectors 0 and 1 of the robot as the two hands",
            scenario.name
        )));
    }
    let other_link = agent.robot.end_effectors()[ee[1]].link;
    let held_robot = object
        .attach(&agent.robot, ee[0], &[other_link])
        .ok_or_else(|| AppError::Failed("carry: cannot attach the object".into()))?;
    let held = CollisionModel::new(&held_robot, scenario.initial_environment());
    let controller = ClosedChainController::new(agent.robot.limits(), ClosedChainConfig { dt, ..Default::default() })
        .map_err(|e| AppError::Failed(format!("carry: closed-chain controller: {e}")))?;
    let record = Arc::new(Mutex::new(CarryRecord {
        summary: ClosedChainSummary {
            agent: agent.name.clone(),
            planning_ms: plan.stats.planning_ms,
            plan_duration_s: plan.trajectory.duration(),
            closest_obstacle_m: f64::INFINITY,
            ..ClosedChainSummary::default()
        },
        qp_ns: Vec::new(),
    }));
    // Planning time as the run counts it: simulated from the collision checks (the log stays
    // byte-identical for a seed) or the wall clock.
    let planning_ms = match clock {
        ClockSpec::Wall => plan.stats.planning_ms,
        ClockSpec::Simulated { us_per_check } => plan.stats.collision_checks as f64 * us_per_check * 1e-3,
    };
    let header = serde_json::json!({
        "agent": agent.name,
        "end_effectors": plan.span.end_effectors,
        "tolerance_m": plan.span.tolerance_m,
        "tolerance_rad": plan.span.tolerance_rad,
        "object": object,
    });
    let start = plan.trajectory.q.first().cloned().unwrap_or_else(|| agent.start.clone());
    let state = CarryAgent {
        robot: Arc::new(agent.robot.clone()),
        held,
        plan,
        controller,
        damper: DamperParams::default(),
        reference: None,
        object_in_tool,
        goal: spec.object_goal,
        planning_ms,
        released: false,
        halted: false,
        done: false,
        record: record.clone(),
    };
    let a = Agent::embodied(agent.name.clone(), Arc::new(agent.robot.clone()), Some(&start), state, program())
        .map_err(|e| AppError::Failed(format!("agent `{}`: {e}", agent.name)))?;
    Ok((a, record, header))
}

/// Percentiles of the QP times into the summary.
pub fn finish(record: &Mutex<CarryRecord>) -> Option<ClosedChainSummary> {
    let r = record.lock().ok()?;
    let mut s = r.summary.clone();
    let mut ns = r.qp_ns.clone();
    ns.sort_unstable();
    let pct = |p: f64| ns.get(((ns.len() as f64 - 1.0) * p).round() as usize).map_or(0.0, |v| *v as f64 / 1e3);
    s.qp_p50_us = pct(0.5);
    s.qp_p99_us = pct(0.99);
    s.qp_max_us = ns.last().map_or(0.0, |v| *v as f64 / 1e3);
    if !s.closest_obstacle_m.is_finite() {
        s.closest_obstacle_m = 0.0;
    }
    Some(s)
}
