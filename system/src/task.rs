//! Task-level deliberation in `c_c` (section 4 of the paper): a coordinator whose internal
//! memory holds an A* search over symbolic states, its operators refined lazily into certified
//! motion, and the resulting plan run by the arms as `Move(f', f'', f_τ)` / `Wait(f_ι)`.
//!
//! * **Search-space states**: which stand and level each part is at, what each hand holds, how
//!   high each stack is (facts of a [`TaskProblem`], a bitset).
//! * **Operators**: ground production rules `pick(arm, part, stand, level)` and
//!   `place(arm, part, stand, level)` (which also say which stand the arm is at) and
//!   `retreat(arm)` (back to its start pose, out of the other arm's way), generated for every stand level an arm reaches (decided
//!   by inverse kinematics and a collision check, not declared), with preconditions, add and
//!   delete lists and a cost: the handling time plus the estimated travel time to the stand.
//! * **Goal test**: every part of a goal stack at its level.
//! * **Heuristic** (admissible): each goal part not yet in place (or resting on one that is
//!   not) must still be picked once (unless held) and placed once at its goal: the cheapest
//!   such pick and place.
//! * **A\*** under a [`Deadline`] with the anytime outcome (`Solved`, `OutOfTime { best }`,
//!   `Infeasible`). Along the best plan each operator is refined into a certified motion (RRT
//!   with shortcuts, time-parameterised, checked by the [`Verifier`]); a refinement that fails
//!   prunes that operator instance (its symbolic state and rule) and the search goes on.
//! * **Execution**: the coordinator hands each operator to its arm when the operators it
//!   depends on have finished: the arm's own previous one, any that touches the same facts
//!   (stand, part), and any of the other arm whose swept volume meets its own. Arms run
//!   concurrently otherwise. Each arm runs `Wait(an operator has been handed over)`, then
//!   `Move(first: take it, next: track its trajectory, terminal: its time is up and the arm
//!   has settled)`, then reports it done.
//!
//! Planning time is counted as the run's clock says: on the wall clock, or simulated from the
//! work (expansions and collision checks), which keeps the log byte-identical for a seed.

use std::collections::{HashMap, HashSet, VecDeque};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, TryRecvError, channel};
use std::time::{Duration, Instant};

use embodied_executor::{
    AgentId, Event, InputImages, Message, Move, OutputImages, Predicate, Primitive, Reactive, Sequence, Wait,
};
use embodied_models::collision::{CollisionModel, Environment, Obstacle};
use embodied_models::nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use embodied_models::{IkOptions, JointKind, Robot, Shape};
use embodied_planner::deadline::Deadline;
use embodied_planner::motion::{Goal, plan_motion};
use embodied_planner::outcome::Outcome;
use embodied_planner::search::{SearchProblem, Successor, solve};
use embodied_planner::task::{FactId, FactSet, GroundAction, Rule, RuleId, TaskProblem};
use embodied_planner::trajectory::{Trajectory, time_parameterize};
use embodied_planner::verify::Verifier;

use crate::SystemError;
use crate::plan::{bodies_as_obstacles, motion_settings};
use crate::scenario::{ClockSpec, Scenario, TaskSpec};

/// Largest joint step between the configurations that stand for a swept volume in the
/// concurrency check.
const SWEEP_STEP: f64 = 0.02;

/// Sampling resolution of the concurrency check along the other arm's path, rad or m.
const CONCURRENCY_RESOLUTION: f64 = 0.02;

/// Time past an operator's motion after which its `Move` ends even if the arm has not settled, s.
const SETTLE_TIMEOUT_S: f64 = 0.5;

/// Index standing for "no part / no stand / no level" in a retreat operator.
const NONE: usize = usize::MAX;

/// Cost of `retreat(arm)`, s: the estimate of an arm's move back to its start pose, out of
/// the other arm's way.
const RETREAT_COST: f64 = 0.3;

/// Margin on the time into another arm's operator after which an operator may start, s: the
/// arm lags its reference a little, and its start is heard a step or more after it happened.
const LAG_MARGIN_S: f64 = 0.2;

/// Distance from the operator's last configuration within which the arm counts as arrived.
const ARRIVED: f64 = 5e-3;

/// One stand level an arm reaches: where its tool goes to pick or place there.
#[derive(Debug, Clone)]
struct Reach {
    q: Vec<f64>,
}

/// The symbolic domain of a stacking task with the geometry behind it.
pub struct TaskDomain {
    /// Scenario agent index of each arm.
    pub arms: Vec<usize>,
    /// The arms' names.
    pub arm_names: Vec<String>,
    /// Parts, in the order of the stands' start stacks.
    pub parts: Vec<String>,
    /// The ground problem.
    pub problem: TaskProblem,
    /// Per rule: (arm position in `arms`, part, stand, level, is a pick); a retreat has
    /// [`NONE`] for part, stand and level.
    ops: Vec<(usize, usize, usize, usize, bool)>,
    /// `reach[arm][stand][level]`.
    reach: Vec<Vec<Vec<Option<Reach>>>>,
    robots: Vec<Robot>,
    starts: Vec<Vec<f64>>,
    static_env: Environment,
    spec: TaskSpec,
    /// `at(part, stand, level)` fact ids.
    at: Vec<Vec<Vec<Option<FactId>>>>,
    /// `holding(arm, part)` fact ids.
    holding: Vec<Vec<Option<FactId>>>,
    /// Goal spot of each part, if it has one: (stand, level).
    goal_of: Vec<Option<(usize, usize)>>,
    /// Cheapest pick of each part, and cheapest place of each part at its goal.
    min_pick: Vec<f64>,
    min_place_goal: Vec<f64>,
}

impl TaskDomain {
    /// Build the domain of `scenario`'s `[task]`: decide which stand levels each arm reaches
    /// (inverse kinematics, tool pointing down, collision-free among the static obstacles),
    /// then generate the ground rules.
    // Indices name arms, stands, levels and parts across several tables at once.
    #[allow(clippy::needless_range_loop)]
    pub fn new(scenario: &Scenario) -> Result<Self, SystemError> {
        let spec = scenario
            .task
            .clone()
            .ok_or_else(|| SystemError::Failed(format!("scenario `{}` has no [task]", scenario.name)))?;
        let fail = |m: String| SystemError::Failed(format!("scenario `{}`: task: {m}", scenario.name));
        let parts: Vec<String> = spec.stands.iter().flat_map(|s| s.start.iter().cloned()).collect();
        let levels = parts.len();
        let static_env = scenario.initial_environment();
        let robots: Vec<Robot> = spec.arms.iter().map(|&k| scenario.agents[k].robot.clone()).collect();
        let starts: Vec<Vec<f64>> = spec.arms.iter().map(|&k| scenario.agents[k].start.clone()).collect();
        let arm_names: Vec<String> = spec.arms.iter().map(|&k| scenario.agents[k].name.clone()).collect();
        let mut reach = Vec::new();
        for (a, robot) in robots.iter().enumerate() {
            let model = CollisionModel::new(robot, static_env.clone());
            let mut per_stand = Vec::new();
            for s in 0..spec.stands.len() {
                let mut per_level = Vec::new();
                for l in 0..levels {
                    // The level below's configuration is a good seed for this one.
                    let below = per_level.last().and_then(|r: &Option<Reach>| r.as_ref()).map(|r| r.q.clone());
                    let target = tool_pose(&spec, s, l);
                    per_level.push(grasp_configuration(robot, &model, &starts[a], below.as_deref(), &target));
                }
                per_stand.push(per_level);
            }
            reach.push(per_stand);
        }
        // Facts and rules.
        let stand = |s: usize| spec.stands[s].name.as_str();
        let at = |p: usize, s: usize, l: usize| format!("at({},{},{l})", parts[p], stand(s));
        let height = |s: usize, l: usize| format!("height({},{l})", stand(s));
        let holding = |a: usize, p: usize| format!("holding({},{})", arm_names[a], parts[p]);
        let empty = |a: usize| format!("hand_empty({})", arm_names[a]);
        // Where each arm is, coarsely: at a stand, or at home (its start pose).
        let arm_at = |a: usize, s: usize| format!("arm_at({},{})", arm_names[a], stand(s));
        let home = |a: usize| format!("arm_home({})", arm_names[a]);
        let away = |a: usize| format!("arm_away({})", arm_names[a]);
        let moves_to = |a: usize, s: usize| -> (Vec<String>, Vec<String>) {
            let others = (0..spec.stands.len()).filter(|&o| o != s).map(|o| arm_at(a, o));
            (vec![arm_at(a, s), away(a)], others.chain([home(a)]).collect())
        };
        let mut rules = Vec::new();
        let mut ops = Vec::new();
        for a in 0..robots.len() {
            for s in 0..spec.stands.len() {
                for l in 0..levels {
                    let Some(r) = &reach[a][s][l] else { continue };
                    let cost = spec.handling_s + travel_time(&robots[a], &starts[a], &r.q);
                    for p in 0..parts.len() {
                        let params = [
                            ("arm", arm_names[a].as_str()),
                            ("part", parts[p].as_str()),
                            ("stand", stand(s)),
                            ("level", &l.to_string()),
                        ];
                        let (there, elsewhere) = moves_to(a, s);
                        rules.push(Rule {
                            action: GroundAction::new("pick", &params),
                            preconditions: vec![empty(a), at(p, s, l), height(s, l + 1)],
                            add: [vec![holding(a, p), height(s, l)], there.clone()].concat(),
                            delete: [vec![empty(a), at(p, s, l), height(s, l + 1)], elsewhere.clone()].concat(),
                            cost,
                        });
                        ops.push((a, p, s, l, true));
                        rules.push(Rule {
                            action: GroundAction::new("place", &params),
                            preconditions: vec![holding(a, p), height(s, l)],
                            add: [vec![at(p, s, l), height(s, l + 1), empty(a)], there].concat(),
                            delete: [vec![holding(a, p), height(s, l)], elsewhere].concat(),
                            cost,
                        });
                        ops.push((a, p, s, l, false));
                    }
                }
            }
        }
        for a in 0..robots.len() {
            let mut delete: Vec<String> = (0..spec.stands.len()).map(|s| arm_at(a, s)).collect();
            delete.push(away(a));
            rules.push(Rule {
                action: GroundAction::new("retreat", &[("arm", arm_names[a].as_str())]),
                preconditions: vec![away(a)],
                add: vec![home(a)],
                delete,
                cost: RETREAT_COST,
            });
            ops.push((a, NONE, NONE, NONE, false));
        }
        let mut initial: Vec<String> = (0..robots.len()).flat_map(|a| [empty(a), home(a)]).collect();
        let mut goal = Vec::new();
        let mut goal_of = vec![None; parts.len()];
        let index = |name: &str| parts.iter().position(|p| p == name);
        for (s, st) in spec.stands.iter().enumerate() {
            initial.push(height(s, st.start.len()));
            for (l, name) in st.start.iter().enumerate() {
                let p = index(name).ok_or_else(|| fail(format!("unknown part `{name}`")))?;
                initial.push(at(p, s, l));
            }
            for (l, name) in st.goal.iter().enumerate() {
                let p = index(name).ok_or_else(|| fail(format!("unknown part `{name}` in a goal")))?;
                goal.push(at(p, s, l));
                goal_of[p] = Some((s, l));
            }
        }
        let problem = TaskProblem::new(initial, rules, goal).map_err(|e| fail(e.to_string()))?;
        // Fact ids for the heuristic (a fact no rule or state mentions is never interned: None).
        let mut ids: HashMap<&str, FactId> = HashMap::new();
        let mut f = 0u32;
        while let Some(name) = problem.fact_name(FactId(f)) {
            ids.insert(name, FactId(f));
            f += 1;
        }
        let lookup = |name: &str| ids.get(name).copied();
        let mut at_ids = vec![vec![vec![None; levels]; spec.stands.len()]; parts.len()];
        for (p, per_part) in at_ids.iter_mut().enumerate() {
            for (s, per_stand) in per_part.iter_mut().enumerate() {
                for (l, slot) in per_stand.iter_mut().enumerate() {
                    *slot = lookup(&at(p, s, l));
                }
            }
        }
        let holding_ids: Vec<Vec<Option<FactId>>> =
            (0..robots.len()).map(|a| (0..parts.len()).map(|p| lookup(&holding(a, p))).collect()).collect();
        let mut min_pick = vec![f64::INFINITY; parts.len()];
        let mut min_place_goal = vec![f64::INFINITY; parts.len()];
        for (rule, &(_, p, s, l, pick)) in problem.rules().iter().zip(&ops) {
            if p == NONE {
                continue;
            }
            if pick {
                min_pick[p] = min_pick[p].min(rule.cost);
            } else if goal_of[p] == Some((s, l)) {
                min_place_goal[p] = min_place_goal[p].min(rule.cost);
            }
        }
        Ok(TaskDomain {
            arms: spec.arms.clone(),
            arm_names,
            parts,
            problem,
            ops,
            reach,
            robots,
            starts,
            static_env,
            spec,
            at: at_ids,
            holding: holding_ids,
            goal_of,
            min_pick,
            min_place_goal,
        })
    }

    /// Whether arm `arm` (its position in the task's arm list) reaches stand `stand` (its index)
    /// at some level.
    pub fn reaches(&self, arm: usize, stand: usize) -> bool {
        self.reach.get(arm).and_then(|r| r.get(stand)).is_some_and(|levels| levels.iter().any(Option::is_some))
    }

    /// Per level of stand `stand`: whether arm `arm` reaches it.
    pub fn reach_levels(&self, arm: usize, stand: usize) -> Vec<bool> {
        self.reach
            .get(arm)
            .and_then(|r| r.get(stand))
            .map(|l| l.iter().map(Option::is_some).collect())
            .unwrap_or_default()
    }

    /// Index of the stand named `name`.
    pub fn stand_index(&self, name: &str) -> Option<usize> {
        self.spec.stands.iter().position(|s| s.name == name)
    }

    /// The rule of the domain performing `action`, if there is one.
    pub fn rule_of(&self, action: &GroundAction) -> Option<RuleId> {
        self.problem.rules().iter().position(|r| r.action == *action).map(RuleId)
    }

    /// The admissible heuristic: the cheapest pick and goal placement of every goal part not
    /// yet in place.
    pub fn heuristic(&self, state: &FactSet) -> f64 {
        let holds = |f: Option<FactId>| f.is_some_and(|f| state.contains(f));
        let mut h = 0.0;
        for p in 0..self.parts.len() {
            let Some((s, l)) = self.goal_of[p] else { continue };
            // In place: at its goal level with every goal part below it in place.
            let below_ok = (0..l)
                .all(|m| (0..self.parts.len()).any(|q| self.goal_of[q] == Some((s, m)) && holds(self.at[q][s][m])));
            if holds(self.at[p][s][l]) && below_ok {
                continue;
            }
            let held = (0..self.arms.len()).any(|a| holds(self.holding[a][p]));
            if !held {
                h += self.min_pick[p];
            }
            h += self.min_place_goal[p];
        }
        h
    }
}

/// The tool pose over stand `s` at level `l`: `clearance` above the top of a part resting there,
/// tool z axis pointing down.
fn tool_pose(spec: &TaskSpec, s: usize, l: usize) -> Isometry3<f64> {
    let top = spec.stands[s].top;
    let z = top[2] + spec.part_size * (l as f64 + 1.0) + spec.clearance;
    Isometry3::from_parts(
        Translation3::new(top[0], top[1], z),
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
    )
}

/// A collision-free configuration putting the first end effector at `target`, or `None`.
/// Prismatic joints outside the arm (a track) are seeded towards the target's y.
fn grasp_configuration(
    robot: &Robot,
    model: &CollisionModel,
    start: &[f64],
    near: Option<&[f64]>,
    target: &Isometry3<f64>,
) -> Option<Reach> {
    let limits = robot.limits();
    let mut seeds = vec![start.to_vec()];
    if let Some(d) = (0..robot.dof()).find(|&d| robot.dof_joint(d).kind == JointKind::Prismatic) {
        let base = robot.base().translation.vector;
        for offset in [0.0, -0.3, 0.3, -0.6, 0.6] {
            let mut q = start.to_vec();
            q[d] = (target.translation.vector.y - base.y + offset).clamp(limits[d].lower, limits[d].upper);
            seeds.push(q);
        }
    }
    for seed in &seeds {
        let Ok(solutions) = robot.inverse_kinematics_all(0, target, seed) else { continue };
        if let Some(q) = solutions.into_iter().find(|q| !model.collides(q)) {
            return Some(Reach { q });
        }
    }
    if robot.closed_form(0).is_some() {
        return None;
    }
    // No closed form (Polycrank): damped least squares from the start turned towards the
    // target about the first joint (by the start's own offset and a few others), with restarts.
    let options = IkOptions { restarts: 8, ..IkOptions::default() };
    if let Some(seed) = near
        && let Ok(q) = robot.inverse_kinematics(0, target, seed, &options)
        && !model.collides(&q)
    {
        return Some(Reach { q });
    }
    let t = target.translation.vector - robot.base().translation.vector;
    let start_tool = robot.end_effector_poses(start, 0).1.translation.vector - robot.base().translation.vector;
    let turn = t.y.atan2(t.x) - start_tool.y.atan2(start_tool.x);
    for offset in [0.0, 0.4, -0.4, 0.8, -0.8] {
        let mut seed = start.to_vec();
        if robot.dof() > 0 && robot.dof_joint(0).kind == JointKind::Continuous {
            seed[0] = embodied_models::wrap_angle(start[0] + turn + offset);
        }
        if let Ok(q) = robot.inverse_kinematics(0, target, &seed, &options)
            && !model.collides(&q)
        {
            return Some(Reach { q });
        }
    }
    None
}

/// Estimated straight-line motion time: the slowest joint at its speed limit, s.
fn travel_time(robot: &Robot, a: &[f64], b: &[f64]) -> f64 {
    let space = robot.config_space();
    let b = space.unwrap_towards(a, b);
    robot
        .limits()
        .iter()
        .zip(a.iter().zip(&b))
        .map(|(lim, (x, y))| (y - x).abs() / lim.max_velocity)
        .fold(0.0, f64::max)
}

/// The search with pruned operator instances.
struct Pruned<'a> {
    domain: &'a TaskDomain,
    pruned: &'a HashSet<(FactSet, RuleId)>,
}

impl SearchProblem for Pruned<'_> {
    type State = FactSet;
    type Operator = RuleId;

    fn initial(&self) -> FactSet {
        self.domain.problem.initial()
    }

    fn successors(&self, state: &FactSet, out: &mut Vec<Successor<FactSet, RuleId>>) {
        self.domain.problem.successors(state, out);
        if !self.pruned.is_empty() {
            out.retain(|s| !self.pruned.contains(&(state.clone(), s.operator)));
        }
    }

    fn is_goal(&self, state: &FactSet) -> bool {
        self.domain.problem.is_goal(state)
    }

    fn heuristic(&self, state: &FactSet) -> f64 {
        self.domain.heuristic(state)
    }
}

/// One operator of a task plan with its motion.
#[derive(Debug, Clone)]
pub struct RefinedOperator {
    /// The ground operator as text.
    pub name: Arc<str>,
    /// Position of its arm in the task's arm list.
    pub arm: usize,
    /// Its certified trajectory (from where the arm's previous operator ended).
    pub trajectory: Arc<Trajectory>,
    /// The joint-space path the trajectory follows.
    pub path: Vec<Vec<f64>>,
    /// Collision checks its refinement took.
    pub work: u64,
    /// Operators of the other arms it must wait for (earlier in the plan), each with the time
    /// into that operator's motion after which the rest of it is clear of this one's swept
    /// volume (`f64::INFINITY`: wait until it has finished).
    pub after: Vec<(usize, f64)>,
    /// Whether its straight joint-space segment from start to end collides (the motion planner
    /// had to go around).
    pub straight_collides: bool,
}

/// What the task-level deliberation produced, and what it cost.
#[derive(Debug, Clone, Default)]
pub struct TaskPlanReport {
    /// The refined plan (`None`: no plan).
    pub operators: Option<Vec<RefinedOperator>>,
    /// The plan's cost.
    pub cost: f64,
    /// `out_of_time` / `infeasible` with detail, when there is no plan.
    pub failure: Option<String>,
    /// Operators of the best partial plan when out of time.
    pub best_partial: Option<usize>,
    /// A* expansions over all searches.
    pub expansions: u64,
    /// Searches run.
    pub searches: u32,
    /// Refinements tried and failed.
    pub refinements: u32,
    /// Refinements that failed.
    pub refinements_failed: u32,
    /// Collision checks of refinement and concurrency checks.
    pub collision_checks: u64,
    /// Failed refinements: (operator, arm name, reason).
    pub failures: Vec<(String, String, String)>,
    /// Wall-clock time of the search alone and of the motion work.
    pub search_wall: Duration,
    /// Wall-clock time of motion planning, verification and concurrency checks.
    pub motion_wall: Duration,
}

impl TaskPlanReport {
    /// Planning time on `clock`, ms: simulated from the work, or the wall clock. Returns
    /// (total, of which motion).
    pub fn planning_ms(&self, clock: ClockSpec, us_per_expansion: f64) -> (f64, f64) {
        match clock {
            ClockSpec::Wall => {
                let motion = self.motion_wall.as_secs_f64() * 1e3;
                (self.search_wall.as_secs_f64() * 1e3 + motion, motion)
            }
            ClockSpec::Simulated { us_per_check } => {
                let motion = self.collision_checks as f64 * us_per_check * 1e-3;
                (self.expansions as f64 * us_per_expansion * 1e-3 + motion, motion)
            }
        }
    }
}

/// How the deliberation is bounded.
#[derive(Debug, Clone)]
pub struct TaskBudget {
    /// The run's clock.
    pub clock: ClockSpec,
    /// Give up after this much planning time (as the clock counts it), ms.
    pub give_up_ms: f64,
    /// Set to stop the deliberation (its owner has gone).
    pub cancel: Option<Arc<AtomicBool>>,
}

impl TaskBudget {
    /// A budget of `give_up_ms` on `clock`, not cancellable.
    pub fn new(clock: ClockSpec, give_up_ms: f64) -> Self {
        Self { clock, give_up_ms, cancel: None }
    }

    fn cancelled(&self) -> bool {
        self.cancel.as_ref().is_some_and(|c| c.load(Ordering::Relaxed))
    }
}

/// Run the task-level deliberation: A* over the production rules, lazy refinement of the best
/// plan's operators into certified motion, pruning of operators whose refinement fails,
/// concurrency analysis of the refined plan.
pub fn deliberate(domain: &TaskDomain, scenario: &Scenario, budget: &TaskBudget) -> TaskPlanReport {
    let mut report = TaskPlanReport::default();
    let mut pruned: HashSet<(FactSet, RuleId)> = HashSet::new();
    let mut cache: HashMap<(FactSet, RuleId, Vec<u64>), Result<RefinedOperator, String>> = HashMap::new();
    let us_per_expansion = domain.spec.us_per_expansion;
    let spent_ms = |r: &TaskPlanReport| r.planning_ms(budget.clock, us_per_expansion).0;
    loop {
        let left_ms = budget.give_up_ms - spent_ms(&report);
        if left_ms <= 0.0 {
            report.failure = Some(format!("out_of_time: the {} ms budget is spent", budget.give_up_ms));
            return report;
        }
        let mut deadline = match budget.clock {
            ClockSpec::Wall => Deadline::after(Duration::from_secs_f64(left_ms / 1e3)),
            ClockSpec::Simulated { .. } => {
                Deadline::expansions((left_ms * 1e3 / us_per_expansion.max(1e-6)).floor().max(1.0) as u64)
            }
        };
        if let Some(flag) = &budget.cancel {
            deadline = deadline.with_cancel_flag(flag.clone());
        }
        let search_started = Instant::now();
        let searched = solve(&Pruned { domain, pruned: &pruned }, &deadline);
        report.search_wall += search_started.elapsed();
        report.expansions += searched.stats.expansions;
        report.searches += 1;
        let plan = match searched.outcome {
            Outcome::Solved(plan) => plan,
            Outcome::OutOfTime { best, cause } => {
                report.best_partial = best.map(|b| b.plan.len());
                report.failure = Some(format!("out_of_time: the search was stopped ({cause:?})"));
                return report;
            }
            Outcome::Infeasible => {
                report.failure = Some(if pruned.is_empty() {
                    "infeasible: no sequence of operators reaches the goal".into()
                } else {
                    format!("infeasible: no plan once {} operator instance(s) failed to refine", pruned.len())
                });
                return report;
            }
        };
        // Refine along the plan, each arm from where its previous operator left it, among the
        // parts where the plan has them and the other arms where they stand.
        let motion_started = Instant::now();
        let mut arm_q = domain.starts.clone();
        let mut refined = Vec::with_capacity(plan.operators.len());
        let mut failed = false;
        for (i, &rule) in plan.operators.iter().enumerate() {
            // On the wall clock the refinement under way counts too (it is added to the report
            // only when the loop ends).
            let running_ms = match budget.clock {
                ClockSpec::Wall => motion_started.elapsed().as_secs_f64() * 1e3,
                ClockSpec::Simulated { .. } => 0.0,
            };
            if spent_ms(&report) + running_ms > budget.give_up_ms || budget.cancelled() {
                report.motion_wall += motion_started.elapsed();
                report.best_partial = Some(i);
                report.failure = Some(format!("out_of_time: refinement ran past the {} ms budget", budget.give_up_ms));
                return report;
            }
            let state = &plan.states[i];
            let key_q: Vec<u64> = arm_q.iter().flatten().map(|x| x.to_bits()).collect();
            let key = (state.clone(), rule, key_q);
            let result = match cache.get(&key) {
                Some(r) => r.clone(),
                None => {
                    report.refinements += 1;
                    let r = refine(domain, scenario, state, rule, &arm_q);
                    if let Ok(op) = &r {
                        report.collision_checks += op.work;
                    }
                    cache.insert(key, r.clone());
                    r
                }
            };
            match result {
                Ok(op) => {
                    if let Some(last) = op.path.last() {
                        arm_q[op.arm] = last.clone();
                    }
                    refined.push(op);
                }
                Err(reason) => {
                    let (a, ..) = domain.ops[rule.0];
                    let name = domain.problem.rules()[rule.0].action.to_string();
                    report.refinements_failed += 1;
                    report.failures.push((name, domain.arm_names[a].clone(), reason));
                    pruned.insert((state.clone(), rule));
                    failed = true;
                    break;
                }
            }
        }
        report.motion_wall += motion_started.elapsed();
        if failed {
            continue;
        }
        if spent_ms(&report) > budget.give_up_ms {
            report.failure = Some(format!("out_of_time: refinement ran past the {} ms budget", budget.give_up_ms));
            return report;
        }
        let checks_started = Instant::now();
        report.collision_checks += order_constraints(domain, &plan.operators, &mut refined);
        report.motion_wall += checks_started.elapsed();
        report.cost = plan.cost;
        report.operators = Some(refined);
        return report;
    }
}

/// The parts as obstacles where `state` has them (held parts are not modelled).
fn parts_in(domain: &TaskDomain, state: &FactSet) -> Vec<Obstacle> {
    let mut out = Vec::new();
    for (p, per_part) in domain.at.iter().enumerate() {
        for (s, per_stand) in per_part.iter().enumerate() {
            for (l, id) in per_stand.iter().enumerate() {
                if id.is_some_and(|f| state.contains(f)) {
                    out.push(part_obstacle(domain, p, s, l));
                }
            }
        }
    }
    out
}

fn part_obstacle(domain: &TaskDomain, p: usize, s: usize, l: usize) -> Obstacle {
    let top = domain.spec.stands[s].top;
    let h = domain.spec.part_size / 2.0;
    Obstacle {
        name: format!("part/{}", domain.parts[p]),
        pose: Isometry3::translation(top[0], top[1], top[2] + h * (2.0 * l as f64 + 1.0)),
        shape: Shape::cuboid(h, h, h),
    }
}

/// Refine one operator: a motion of its arm from `arm_q[arm]` to the stand level's
/// configuration, planned and certified among the static obstacles, the parts where `state`
/// has them and the other arms where they stand.
fn refine(
    domain: &TaskDomain,
    scenario: &Scenario,
    state: &FactSet,
    rule: RuleId,
    arm_q: &[Vec<f64>],
) -> Result<RefinedOperator, String> {
    let (a, _, s, l, _) = domain.ops[rule.0];
    let name: Arc<str> = domain.problem.rules()[rule.0].action.to_string().into();
    let goal = if s == NONE {
        domain.starts[a].clone()
    } else {
        domain.reach[a][s][l].as_ref().ok_or("the arm does not reach that stand level")?.q.clone()
    };
    let mut env = domain.static_env.clone();
    for o in parts_in(domain, state) {
        env.add(o);
    }
    for (m, robot) in domain.robots.iter().enumerate() {
        if m != a {
            for o in bodies_as_obstacles(robot, std::slice::from_ref(&arm_q[m]), f64::INFINITY, &domain.arm_names[m]) {
                env.add(o);
            }
        }
    }
    let robot = &domain.robots[a];
    let model = CollisionModel::new(robot, env);
    let start = &arm_q[a];
    let space = robot.config_space();
    let straight_collides = !model.motion_is_free(start, &goal, scenario.planner.resolution);
    let mut settings = motion_settings(scenario, Deadline::none());
    settings.seed = settings.seed.wrapping_add(rule.0 as u64);
    let (path, work) = if space.distance(start, &goal) < 1e-9 {
        (vec![start.clone(), goal.clone()], 0)
    } else {
        let plan =
            plan_motion(&model, start, &Goal::Configuration(goal.clone()), &settings).map_err(|e| e.to_string())?;
        let w = plan.stats.collision_checks;
        (plan.path, w)
    };
    let trajectory = time_parameterize(&path, robot, 0.0);
    Verifier::default().verify_trajectory(&model, &trajectory).map_err(|f| format!("verifier: {f}"))?;
    Ok(RefinedOperator {
        name,
        arm: a,
        trajectory: Arc::new(trajectory),
        path,
        work,
        after: Vec::new(),
        straight_collides,
    })
}

/// Fill in each operator's `after`: the earlier operators of other arms it must wait for, and
/// for how long (the arm's own previous one is implied). Operators that touch the same facts
/// (a stand, a part) wait for each other to finish; otherwise operator `j` may start once
/// operator `i` has passed the last point of its motion that meets `j`'s swept volume.
/// Returns the collision checks spent.
fn order_constraints(domain: &TaskDomain, rules: &[RuleId], ops: &mut [RefinedOperator]) -> u64 {
    let touched: Vec<HashSet<&str>> = rules
        .iter()
        .map(|r| {
            let rule = &domain.problem.rules()[r.0];
            rule.preconditions.iter().chain(&rule.add).chain(&rule.delete).map(String::as_str).collect()
        })
        .collect();
    let mut checks = 0;
    for j in 0..ops.len() {
        let mut after = Vec::new();
        for i in 0..j {
            if ops[i].arm == ops[j].arm {
                continue;
            }
            let wait = if touched[i].is_disjoint(&touched[j]) {
                let (wait, n) = clear_after(domain, rules, ops, i, j);
                checks += n;
                wait
            } else {
                Some(f64::INFINITY)
            };
            if let Some(t) = wait {
                after.push((i, t));
            }
        }
        ops[j].after = after;
    }
    checks
}

/// How far into operator `i`'s motion its arm is clear of operator `j`'s swept volume (its
/// arm's links along its path, and its part where it picks or places it) for good: the time of
/// the first sample after the last one that meets it, `f64::INFINITY` when `i`'s last
/// configuration meets it, `None` when no sample does. Also the collision checks spent.
fn clear_after(
    domain: &TaskDomain,
    rules: &[RuleId],
    ops: &[RefinedOperator],
    i: usize,
    j: usize,
) -> (Option<f64>, u64) {
    let (_, pj, sj, lj, _) = domain.ops[rules[j].0];
    let mut env = Environment::new();
    for o in bodies_as_obstacles(&domain.robots[ops[j].arm], &ops[j].path, SWEEP_STEP, "sweep") {
        env.add(o);
    }
    if pj != NONE {
        env.add(part_obstacle(domain, pj, sj, lj));
    }
    let (_, pi, si, li, _) = domain.ops[rules[i].0];
    if pi != NONE {
        // Operator i's part where it picks or places it, against j's arm.
        let part = CollisionModel::new(&domain.robots[ops[j].arm], {
            let mut e = Environment::new();
            e.add(part_obstacle(domain, pi, si, li));
            e
        });
        let space = domain.robots[ops[j].arm].config_space();
        for w in ops[j].path.windows(2) {
            if !part.motion_is_free(&w[0], &w[1], CONCURRENCY_RESOLUTION) {
                return (Some(f64::INFINITY), 1);
            }
        }
        let _ = space;
    }
    let model = CollisionModel::new(&domain.robots[ops[i].arm], env);
    let traj = &ops[i].trajectory;
    let robot = &domain.robots[ops[i].arm];
    let vmax = robot.limits().iter().map(|l| l.max_velocity).fold(0.0, f64::max).max(1e-9);
    // Samples no more than CONCURRENCY_RESOLUTION apart in any joint.
    let step = (CONCURRENCY_RESOLUTION / vmax).max(1e-4);
    let duration = traj.duration();
    let mut checks = 0;
    let mut t = duration;
    let mut later = None;
    loop {
        let (q, _, _) = traj.sample(t);
        checks += 1;
        if model.collides(&q) {
            return (Some(later.unwrap_or(f64::INFINITY)), checks);
        }
        if t <= 0.0 {
            return (None, checks);
        }
        later = Some(t);
        t = (t - step).max(0.0);
    }
}

/// What the coordinator's deliberation job sends back.
struct JobResult {
    report: TaskPlanReport,
}

/// `c_c` of the task coordinator: the deliberation job, the plan, and who is doing what.
pub struct TaskCoordinator {
    domain: Option<Arc<TaskDomain>>,
    scenario: Arc<Scenario>,
    budget: TaskBudget,
    deadline_ms: f64,
    dt: f64,
    /// Agent id of each arm.
    arm_ids: Vec<AgentId>,
    job: Option<(Receiver<JobResult>, u64)>,
    held: Option<(TaskPlanReport, u64)>,
    plan: Option<Vec<RefinedOperator>>,
    started: Vec<bool>,
    /// Step at which the coordinator heard that each operator started.
    started_at: Vec<Option<u64>>,
    finished: Vec<bool>,
    done: bool,
}

impl TaskCoordinator {
    /// A coordinator for `scenario`'s task with arms at `arm_ids`.
    pub fn new(
        domain: Arc<TaskDomain>,
        scenario: Arc<Scenario>,
        clock: ClockSpec,
        dt: f64,
        arm_ids: Vec<AgentId>,
    ) -> Self {
        let spec = &domain.spec;
        let budget = TaskBudget { clock, give_up_ms: spec.give_up_ms, cancel: Some(Arc::new(AtomicBool::new(false))) };
        let deadline_ms = spec.deadline_ms;
        Self {
            domain: Some(domain),
            scenario,
            budget,
            deadline_ms,
            dt,
            arm_ids,
            job: None,
            held: None,
            plan: None,
            started: Vec::new(),
            started_at: Vec::new(),
            finished: Vec::new(),
            done: false,
        }
    }

    fn start_job(&mut self, step: u64) {
        let Some(domain) = self.domain.clone() else { return };
        let scenario = self.scenario.clone();
        let budget = self.budget.clone();
        let (tx, rx) = channel();
        std::thread::spawn(move || {
            let report = deliberate(&domain, &scenario, &budget);
            let _ = tx.send(JobResult { report });
        });
        self.job = Some((rx, step));
    }

    /// The delivery, once it has landed by `step` (simulated: after its simulated planning time).
    fn poll(&mut self, step: u64) -> Option<TaskPlanReport> {
        if self.held.is_none() {
            let (rx, requested) = self.job.as_ref()?;
            let report = match self.budget.clock {
                ClockSpec::Wall => match rx.try_recv() {
                    Ok(r) => r.report,
                    Err(TryRecvError::Empty) => return None,
                    Err(TryRecvError::Disconnected) => lost(),
                },
                ClockSpec::Simulated { .. } => rx.recv().map(|r| r.report).unwrap_or_else(|_| lost()),
            };
            let due = match self.budget.clock {
                ClockSpec::Wall => step,
                ClockSpec::Simulated { .. } => {
                    let ms = report.planning_ms(self.budget.clock, self.spec_us()).0;
                    requested + ((ms / 1e3 / self.dt).ceil().max(1.0) as u64)
                }
            };
            self.held = Some((report, due));
            self.job = None;
        }
        match &self.held {
            Some((_, due)) if *due <= step => self.held.take().map(|(r, _)| r),
            _ => None,
        }
    }

    fn spec_us(&self) -> f64 {
        self.domain.as_ref().map_or(1.0, |d| d.spec.us_per_expansion)
    }

    fn land(&mut self, report: TaskPlanReport, o: &mut OutputImages) {
        let Some(domain) = self.domain.clone() else { return };
        let (planning_ms, motion_ms) = report.planning_ms(self.budget.clock, domain.spec.us_per_expansion);
        for (op, arm, reason) in &report.failures {
            o.event(Event::RefinementFailed { operator: op.clone(), agent: arm.clone(), reason: reason.clone() });
        }
        match report.operators {
            Some(ops) => {
                for (index, op) in ops.iter().enumerate() {
                    o.event(Event::OperatorRefined {
                        index,
                        operator: op.name.to_string(),
                        agent: domain.arm_names[op.arm].clone(),
                        duration_s: op.trajectory.duration(),
                        work: op.work,
                        after: op.after.iter().map(|(i, _)| *i).collect(),
                    });
                }
                o.event(Event::TaskPlanFound {
                    operators: ops.len(),
                    cost: report.cost,
                    expansions: report.expansions,
                    searches: report.searches,
                    refinements: report.refinements,
                    refinements_failed: report.refinements_failed,
                    collision_checks: report.collision_checks,
                    planning_ms,
                    motion_ms,
                    in_time: planning_ms <= self.deadline_ms,
                });
                self.started = vec![false; ops.len()];
                self.started_at = vec![None; ops.len()];
                self.finished = vec![false; ops.len()];
                self.plan = Some(ops);
            }
            None => {
                o.event(Event::TaskPlanFailed {
                    reason: report.failure.unwrap_or_else(|| "no plan".into()),
                    expansions: report.expansions,
                    best_partial: report.best_partial,
                    planning_ms,
                });
                self.done = true;
            }
        }
    }

    /// Hand out every operator whose predecessors have finished.
    fn dispatch(&mut self, now: u64, o: &mut OutputImages) {
        let Some(ops) = &self.plan else { return };
        for j in 0..ops.len() {
            if self.started[j] {
                continue;
            }
            let own_previous = (0..j).rev().find(|&i| ops[i].arm == ops[j].arm);
            let passed = |&(i, t): &(usize, f64)| {
                self.finished[i]
                    || (t.is_finite()
                        && self.started_at[i]
                            .is_some_and(|s0| (now.saturating_sub(s0)) as f64 * self.dt >= t + LAG_MARGIN_S))
            };
            let ready = own_previous.is_none_or(|i| self.finished[i]) && ops[j].after.iter().all(passed);
            if ready {
                self.started[j] = true;
                let message =
                    Message::Operator { index: j, name: ops[j].name.clone(), trajectory: ops[j].trajectory.clone() };
                o.send(self.arm_ids[ops[j].arm], message);
            }
        }
    }
}

impl Drop for TaskCoordinator {
    fn drop(&mut self) {
        // A deliberation still running has no one to deliver to: stop it.
        if let Some(flag) = &self.budget.cancel {
            flag.store(true, Ordering::Relaxed);
        }
    }
}

fn lost() -> TaskPlanReport {
    TaskPlanReport { failure: Some("the deliberation job was lost".into()), ..TaskPlanReport::default() }
}

/// The coordinator's program: start the deliberation, wait for it, hand out operators, collect
/// their completion.
pub fn coordinator_program() -> Primitive<TaskCoordinator> {
    Primitive::new("task_coordinator", 1, |c: &mut TaskCoordinator, i: &InputImages, o: &mut OutputImages| {
        if c.job.is_none() && c.held.is_none() && c.plan.is_none() && !c.done {
            c.start_job(i.step());
        }
        if let Some(report) = c.poll(i.step()) {
            c.land(report, o);
        }
        for env in i.messages() {
            match env.message {
                Message::OperatorDone { index } if index < c.finished.len() => c.finished[index] = true,
                Message::OperatorStarted { index } if index < c.started_at.len() => {
                    c.started_at[index].get_or_insert(i.step());
                }
                _ => {}
            }
        }
        c.dispatch(i.step(), o);
        if !c.done && !c.finished.is_empty() && c.finished.iter().all(|f| *f) {
            c.done = true;
            o.event(Event::AllDone);
        }
    })
}

/// `c_c` of an arm that runs task operators.
pub struct TaskArm {
    coordinator: AgentId,
    inbox: VecDeque<(usize, Arc<str>, Arc<Trajectory>)>,
    current: Option<(usize, Arc<str>, Arc<Trajectory>, u64)>,
}

impl TaskArm {
    /// An arm taking its operators from `coordinator`.
    pub fn new(coordinator: AgentId) -> Self {
        Self { coordinator, inbox: VecDeque::new(), current: None }
    }

    fn read(&mut self, i: &InputImages) {
        for env in i.messages() {
            if let Message::Operator { index, name, trajectory } = &env.message {
                self.inbox.push_back((*index, name.clone(), trajectory.clone()));
            }
        }
    }

    fn track(&self, i: &InputImages, o: &mut OutputImages) {
        match &self.current {
            Some((_, _, traj, t0)) => {
                let t = i.step().saturating_sub(*t0) as f64 * i.dt();
                let (q, qd, _) = traj.sample(t);
                if q.len() == i.dof() {
                    o.set_position_target(&q, &qd);
                    return;
                }
                hold(i, o);
            }
            None => hold(i, o),
        }
    }

    fn arrived(&self, i: &InputImages) -> bool {
        let Some((_, _, traj, t0)) = &self.current else { return true };
        let t = i.step().saturating_sub(*t0) as f64 * i.dt();
        let Some(end) = traj.q.last() else { return true };
        let error = end.iter().zip(i.q()).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        t >= traj.duration() && (error <= ARRIVED || t >= traj.duration() + SETTLE_TIMEOUT_S)
    }
}

fn hold(i: &InputImages, o: &mut OutputImages) {
    let q = i.q().to_vec();
    o.set_position_target(&q, &vec![0.0; q.len()]);
}

/// An arm's program: `Wait(an operator was handed over)`, `Move(first: take it, next: track
/// it, terminal: its time is up and the arm has arrived)`, then report it done; again.
pub fn arm_program() -> Reactive<TaskArm> {
    let await_operator =
        Wait::new("await_operator", Predicate::new("operator_handed_over", |c: &TaskArm, _| !c.inbox.is_empty()))
            .during(|c: &mut TaskArm, i: &InputImages, o: &mut OutputImages| {
                c.read(i);
                hold(i, o);
            });
    let operator = Move::new(
        "operator",
        |c: &mut TaskArm, i: &InputImages, o: &mut OutputImages| {
            c.read(i);
            if let Some((index, name, traj)) = c.inbox.pop_front() {
                o.event(Event::OperatorStarted { index, operator: name.to_string() });
                o.send(c.coordinator, Message::OperatorStarted { index });
                c.current = Some((index, name, traj, i.step()));
            }
            c.track(i, o);
        },
        |c: &mut TaskArm, i: &InputImages, o: &mut OutputImages| {
            c.read(i);
            c.track(i, o);
        },
        Predicate::new("operator_done", |c: &TaskArm, i: &InputImages| c.arrived(i)),
    );
    let report = Primitive::new("report_done", 1, |c: &mut TaskArm, i: &InputImages, o: &mut OutputImages| {
        c.read(i);
        if let Some((index, name, traj, _)) = c.current.take() {
            let error =
                traj.q.last().map_or(0.0, |end| end.iter().zip(i.q()).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max));
            o.event(Event::OperatorFinished { index, operator: name.to_string(), error });
            o.send(c.coordinator, Message::OperatorDone { index });
            if let Some(end) = traj.q.last().filter(|e| e.len() == i.dof()) {
                o.set_position_target(end, &vec![0.0; end.len()]);
                return;
            }
        }
        hold(i, o);
    });
    let sequence: Sequence<TaskArm> = Sequence::new("operators").then(await_operator).then(operator).then(report);
    Reactive::priority("task_arm").main_reaction(sequence)
}
