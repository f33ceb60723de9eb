//! Robots among robots and obstacles over a run: the scenario's obstacles as they move and
//! appear step by step ([`ObstacleTimeline`]), the agents' bodies as obstacles for one another,
//! the smallest robot-robot and robot-environment distance of a step ([`ClearanceMeter`], the
//! runtime's per-step [`Clearance`] figure), and the certificate that logged motions are
//! collision-free between consecutive steps ([`certify_environment`], [`certify_pair`]).
//!
//! **Time.** The log line of step `s` holds the joints *after* step `s`; the motion from line
//! `s - 1` to line `s` happens during world step `s`, while every scripted obstacle goes from
//! its position at world step `s` to that at `s + 1`. A motion over several steps is checked
//! against each obstacle present at any of those world steps, placed halfway along its travel
//! and grown by half the travel: every point the obstacle occupies during the motion lies
//! inside the grown shape.
//!
//! **Two robots.** Between two logged steps both robots move. Robot B's shapes, posed at the
//! first of the steps, are grown by a bound on how far any of their points travels until the
//! last one ([`CollisionModel::travel_bounds`], summed step by step); robot A's logged motion
//! is certified against them by the one [`Verifier`]. Where a window of several steps cannot be
//! certified it is checked again step by step (less growth).

use std::sync::Arc;

use embodied_executor::{AgentRecord, Body, Clearance, StepMonitor, World};
use embodied_models::collision::{CollisionModel, Environment, Obstacle};
use embodied_models::nalgebra::{Translation3, Vector3};
use embodied_models::{Robot, Shape};
use embodied_planner::trajectory::Trajectory;
use embodied_planner::verify::{EvaluationBudget, Finding, Verifier};
use serde::Serialize;

use crate::scenario::Scenario;

/// A scenario obstacle as it moves during a run.
#[derive(Debug, Clone)]
struct Timed {
    obstacle: Obstacle,
    appear_step: u64,
    velocity: Vector3<f64>,
}

impl Timed {
    /// Its displacement from its scenario pose at world step `k` (it moves from its appearance).
    fn offset(&self, k: u64, dt: f64) -> Vector3<f64> {
        if self.velocity == Vector3::zeros() {
            // A standing obstacle stays where it is (also for absurd times: 0 * inf is NaN).
            return Vector3::zeros();
        }
        self.velocity * (k.saturating_sub(self.appear_step) as f64 * dt)
    }
}

/// The scenario's obstacles step by step, as the simulated world moves them.
#[derive(Debug, Clone)]
pub struct ObstacleTimeline {
    obstacles: Vec<Timed>,
    dt: f64,
}

impl ObstacleTimeline {
    /// The obstacles of `scenario` in a run with control step `dt` (s).
    pub fn new(scenario: &Scenario, dt: f64) -> Self {
        let obstacles = scenario
            .obstacles
            .iter()
            .map(|o| Timed {
                obstacle: o.obstacle.clone(),
                appear_step: o.appear_at.map_or(0, |t| (t / dt).round().max(0.0) as u64),
                velocity: o.velocity.unwrap_or_else(Vector3::zeros),
            })
            .collect();
        Self { obstacles, dt }
    }

    /// Whether anything changes between world steps `from` and `to` (an obstacle appears or
    /// moves).
    pub fn changes_between(&self, from: u64, to: u64) -> bool {
        self.obstacles.iter().any(|o| o.appear_step <= to && (o.appear_step > from || o.velocity.norm() > 0.0))
    }

    /// What a motion during world steps `from..=to` must avoid: every obstacle present at one
    /// of those steps, halfway along its travel, grown by half the travel.
    pub fn environment(&self, from: u64, to: u64) -> Environment {
        let mut env = Environment::new();
        for o in self.obstacles.iter().filter(|o| o.appear_step <= to) {
            let (a, b) = (o.offset(from.max(o.appear_step), self.dt), o.offset(to, self.dt));
            let mid = (a + b) / 2.0;
            let grow = (b - a).norm() / 2.0;
            let pose = Translation3::from(mid) * o.obstacle.pose;
            env.add(Obstacle { name: o.obstacle.name.clone(), pose, shape: grown(&o.obstacle.shape, grow) });
        }
        env
    }
}

/// `shape` grown by `margin` (m): a shape that holds every point within `margin` of it.
pub fn grown(shape: &Shape, margin: f64) -> Shape {
    // Not a positive number (NaN included): nothing to grow by.
    if margin.is_nan() || margin <= 0.0 {
        return shape.clone();
    }
    match shape {
        Shape::Sphere { radius } => Shape::Sphere { radius: radius + margin },
        Shape::Capsule { a, b, radius } => Shape::Capsule { a: *a, b: *b, radius: radius + margin },
        Shape::Cuboid { half_extents } => Shape::Cuboid { half_extents: half_extents.add_scalar(margin) },
        Shape::Cylinder { radius, half_height } => {
            Shape::Cylinder { radius: radius + margin, half_height: half_height + margin }
        }
        Shape::ConvexMesh(_) => {
            // The bounding sphere, grown (the hull has no cheap exact offset).
            let (_, r) = shape.bounding_sphere();
            Shape::Sphere { radius: r + margin }
        }
    }
}

/// `robot` with every self-collision pair disabled: its model measures only against the
/// environment.
fn without_self_pairs(robot: &Robot) -> Robot {
    let mut r = robot.clone();
    let n = r.links().len();
    for a in 0..n {
        for b in a + 1..n {
            r.disable_pair(a, b);
        }
    }
    r
}

/// The shapes of `robot` at `q`, named `prefix/link`, each grown by `margins[link]` (m).
pub fn posed_shapes(robot: &Robot, q: &[f64], margins: &[f64], prefix: &str) -> Vec<Obstacle> {
    if q.len() != robot.dof() {
        return Vec::new();
    }
    let poses = robot.forward_kinematics(q);
    let mut out = Vec::new();
    for (l, link) in robot.links().iter().enumerate() {
        let margin = margins.get(l).copied().unwrap_or(0.0);
        for (k, ps) in link.shapes.iter().enumerate() {
            let name = if link.shapes.len() == 1 {
                format!("{prefix}/{}", link.name)
            } else {
                format!("{prefix}/{}#{k}", link.name)
            };
            out.push(Obstacle { name, pose: poses[l] * ps.pose, shape: grown(&ps.shape, margin) });
        }
    }
    out
}

/// Per link of `model`'s robot: a bound on how far any point of its shapes travels along the
/// logged motion `qs` (sum of the step bounds).
fn travel_along(model: &CollisionModel, qs: &[&[f64]]) -> Vec<f64> {
    let mut out = vec![0.0; model.robot().links().len()];
    for w in qs.windows(2) {
        for (l, b) in model.travel_bounds(w[0], w[1]) {
            if let Some(o) = out.get_mut(l) {
                *o += b;
            }
        }
    }
    out
}

/// One collision certificate over a logged motion.
#[derive(Debug, Clone, Serialize)]
pub struct MotionCheck {
    /// What was checked against what (`robot-environment` or `robot-robot A B`).
    pub what: String,
    /// Every step-to-step motion certified free.
    pub ok: bool,
    /// The first step that is not.
    pub violation: Option<Finding>,
    /// Step-to-step motions checked.
    pub segments: usize,
    /// Smallest distance measured at any evaluated configuration, m.
    pub min_clearance_m: f64,
}

impl MotionCheck {
    fn new(what: String) -> Self {
        Self { what, ok: true, violation: None, segments: 0, min_clearance_m: f64::INFINITY }
    }
}

/// Prefix the robot's side of a finding's pair with the agent's name (a spent budget names the
/// agent).
fn name_robot_side(f: Finding, agent: &str) -> Finding {
    let rename = |a: String| format!("{agent}/{a}");
    match f {
        Finding::Collision { t, q, a, b, penetration_m } => Finding::Collision { t, q, a: rename(a), b, penetration_m },
        Finding::TooClose { t, q, a, b, distance_m, required_m } => {
            Finding::TooClose { t, q, a: rename(a), b, distance_m, required_m }
        }
        Finding::NotCertified { t_from, t_to, q_from, q_to, a, b, clearance_m, reason } => {
            Finding::NotCertified { t_from, t_to, q_from, q_to, a: rename(a), b, clearance_m, reason }
        }
        other => other.of_agent(agent),
    }
}

/// A logged motion of one agent: the log's step numbers, times and joints (same length).
pub struct LoggedMotion<'a> {
    /// The agent's name.
    pub agent: &'a str,
    /// Its robot.
    pub robot: &'a Robot,
    /// Step number of each sample.
    pub steps: &'a [u64],
    /// Time of each sample, s.
    pub t: &'a [f64],
    /// Joints of each sample.
    pub q: &'a [Vec<f64>],
}

fn trajectory(robot: &Robot, t: &[f64], q: &[Vec<f64>]) -> Trajectory {
    Trajectory {
        joint_names: robot.joint_names(),
        t: t.to_vec(),
        q: q.to_vec(),
        qd: vec![vec![0.0; robot.dof()]; q.len()],
    }
}

/// Largest number of steps certified in one piece.
const WINDOW: usize = 400;
/// Steps certified in one piece against a moving obstacle or robot.
const MOVING_WINDOW: usize = 8;

/// Certify `m`'s logged motion free of the scenario's obstacles (at their times) and of
/// self-collision, step to step, with `verifier`, spending distance evaluations from `budget`.
pub fn certify_environment(
    m: &LoggedMotion,
    timeline: &ObstacleTimeline,
    verifier: &Verifier,
    budget: &mut EvaluationBudget,
) -> MotionCheck {
    let mut out = MotionCheck::new("robot-environment".into());
    let n = m.q.len();
    if n == 0 {
        return out;
    }
    let mut model = CollisionModel::new(m.robot, Environment::new());
    let mut i0 = 0;
    loop {
        // Samples i0..=i1: the motion during world steps steps[i0]+1 ..= steps[i1] (+1).
        let first = m.steps[i0] + 1;
        let mut i1 = i0;
        while i1 + 1 < n && i1 - i0 < WINDOW {
            i1 += 1;
            if timeline.changes_between(first, m.steps[i1] + 1) {
                if i1 - i0 > 1 {
                    i1 -= 1;
                }
                break;
            }
        }
        let (from, to) = (if i1 > i0 { m.steps[i0] + 1 } else { m.steps[i0] }, m.steps[i1] + 1);
        model.set_environment(timeline.environment(from, to));
        let report =
            verifier.check_collisions_within(&model, &trajectory(m.robot, &m.t[i0..=i1], &m.q[i0..=i1]), &[], budget);
        out.segments += i1 - i0;
        out.min_clearance_m = out.min_clearance_m.min(report.min_clearance_m);
        if !report.ok {
            out.ok = false;
            out.violation = report.violation.map(|f| name_robot_side(f.shifted(i0), m.agent));
            return out;
        }
        if i1 + 1 >= n {
            return out;
        }
        i0 = i1;
    }
}

/// Certify that robots `a` and `b` never touch while both follow their logged motions (the
/// samples of equal index are at the same step), with `verifier`, spending distance evaluations
/// from `budget`.
pub fn certify_pair(
    a: &LoggedMotion,
    b: &LoggedMotion,
    verifier: &Verifier,
    budget: &mut EvaluationBudget,
) -> MotionCheck {
    let mut out = MotionCheck::new(format!("robot-robot {} {}", a.agent, b.agent));
    let n = a.q.len().min(b.q.len());
    if n == 0 {
        return out;
    }
    let mut model = CollisionModel::new(&without_self_pairs(a.robot), Environment::new());
    let b_model = CollisionModel::new(b.robot, Environment::new());
    let mut check = |model: &mut CollisionModel, i0: usize, i1: usize| {
        let qs: Vec<&[f64]> = b.q[i0..=i1].iter().map(Vec::as_slice).collect();
        let margins = travel_along(&b_model, &qs);
        let env =
            posed_shapes(b.robot, &b.q[i0], &margins, b.agent).into_iter().fold(Environment::new(), Environment::with);
        model.set_environment(env);
        let mut r =
            verifier.check_collisions_within(model, &trajectory(a.robot, &a.t[i0..=i1], &a.q[i0..=i1]), &[], budget);
        r.violation = r.violation.map(|f| f.shifted(i0));
        r
    };
    let mut i0 = 0;
    while i0 + 1 < n || (n == 1 && i0 == 0) {
        let b_moves = b.q[i0..n].windows(2).take(WINDOW).position(|w| w[0] != w[1]);
        // Where B stands still, one piece up to WINDOW steps; where it moves, short pieces.
        let i1 = match b_moves {
            Some(0) => (i0 + MOVING_WINDOW).min(n - 1),
            Some(k) => i0 + k,
            None => (i0 + WINDOW).min(n - 1),
        };
        let report = check(&mut model, i0, i1);
        out.min_clearance_m = out.min_clearance_m.min(report.min_clearance_m);
        if let Some(f @ Finding::BudgetExhausted { .. }) = report.violation {
            // Spent: checking again step by step would certify nothing more.
            out.ok = false;
            out.violation = Some(name_robot_side(f, a.agent));
            return out;
        }
        if !report.ok {
            // Again step by step: less growth of B.
            for j in i0..i1.max(i0 + 1).min(n.max(2) - 1) {
                let r = check(&mut model, j, (j + 1).min(n - 1));
                out.min_clearance_m = out.min_clearance_m.min(r.min_clearance_m);
                if !r.ok {
                    out.ok = false;
                    out.violation = r.violation.map(|f| name_robot_side(f, a.agent));
                    out.segments += j - i0;
                    return out;
                }
            }
        }
        out.segments += i1 - i0;
        if n == 1 {
            break;
        }
        i0 = i1;
    }
    out
}

/// Measures every step's [`Clearance`] and places the agents' bodies in the world for the
/// others' receptors (the runtime's [`StepMonitor`]).
pub struct ClearanceMeter {
    timeline: ObstacleTimeline,
    /// Per runtime agent: its robot (scenario agents only; the coordinator has none).
    robots: Vec<Option<(String, Arc<Robot>)>>,
    /// Per scenario agent: its robot without self pairs against the obstacles.
    env_models: Vec<Option<CollisionModel>>,
    /// Per pair of agents `(i, j)`, `i < j`: robot `i` without self pairs against robot `j`.
    pair_models: Vec<((usize, usize), CollisionModel)>,
    /// The world step whose obstacles the environment models hold.
    last_world_step: Option<u64>,
}

impl ClearanceMeter {
    /// A meter for `scenario`'s agents (runtime agent `k` is scenario agent `k`).
    pub fn new(scenario: &Scenario, dt: f64) -> Self {
        let robots: Vec<Option<(String, Arc<Robot>)>> =
            scenario.agents.iter().map(|a| Some((a.name.clone(), Arc::new(a.robot.clone())))).collect();
        let env_models = robots
            .iter()
            .map(|r| r.as_ref().map(|(_, robot)| CollisionModel::new(&without_self_pairs(robot), Environment::new())))
            .collect();
        let mut pair_models = Vec::new();
        for i in 0..robots.len() {
            for j in i + 1..robots.len() {
                if let Some((_, robot)) = &robots[i] {
                    pair_models.push(((i, j), CollisionModel::new(&without_self_pairs(robot), Environment::new())));
                }
            }
        }
        Self { timeline: ObstacleTimeline::new(scenario, dt), robots, env_models, pair_models, last_world_step: None }
    }
}

/// Bounding spheres of `robot`'s shapes at `q`: its body as the receptors see it.
fn body_spheres(robot: &Robot, q: &[f64]) -> Vec<([f64; 3], f64)> {
    if q.len() != robot.dof() {
        return Vec::new();
    }
    let poses = robot.forward_kinematics(q);
    let mut out = Vec::new();
    for (l, link) in robot.links().iter().enumerate() {
        for ps in &link.shapes {
            let (c, r) = ps.shape.bounding_sphere();
            let p = poses[l] * ps.pose * c;
            out.push(([p.x, p.y, p.z], r));
        }
    }
    out
}

impl StepMonitor for ClearanceMeter {
    fn bodies(&mut self, agents: &[AgentRecord], out: &mut Vec<Body>) {
        out.clear();
        for (k, (r, a)) in self.robots.iter().zip(agents).enumerate() {
            if let Some((name, robot)) = r {
                out.push(Body { agent: k, name: name.clone(), spheres: body_spheres(robot, &a.q) });
            }
        }
    }

    fn clearance(&mut self, world: &World, agents: &[AgentRecord]) -> Clearance {
        let k = world.step();
        if self.last_world_step.is_none() || self.timeline.changes_between(self.last_world_step.unwrap_or(0), k) {
            let env = self.timeline.environment(k, k);
            for m in self.env_models.iter_mut().flatten() {
                m.set_environment(env.clone());
            }
        }
        self.last_world_step = Some(k);
        let mut env_min: Option<f64> = None;
        for (m, a) in self.env_models.iter().zip(agents) {
            if let Some(m) = m
                && !m.environment().is_empty()
                && a.q.len() == m.robot().dof()
            {
                let d = m.distance(&a.q).distance;
                env_min = Some(env_min.map_or(d, |x| x.min(d)));
            }
        }
        let mut robot_min: Option<f64> = None;
        for ((i, j), m) in &mut self.pair_models {
            let (Some(Some((_, rb))), Some(a), Some(b)) = (self.robots.get(*j), agents.get(*i), agents.get(*j)) else {
                continue;
            };
            if a.q.len() != m.robot().dof() || b.q.len() != rb.dof() {
                continue;
            }
            let env = posed_shapes(rb, &b.q, &[], "other").into_iter().fold(Environment::new(), Environment::with);
            m.set_environment(env);
            let d = m.distance(&a.q).distance;
            robot_min = Some(robot_min.map_or(d, |x| x.min(d)));
        }
        Clearance { robot_robot_m: robot_min, robot_environment_m: env_min }
    }
}
