//! Task-level deliberation: production-rule operators over symbolic states.
//!
//! In the paper's words (section 4), operators "may result from production rules": here a
//! [`Rule`] is a ground production rule (preconditions, add list, delete list, cost), a search
//! state is the set of facts that hold ([`FactSet`], a bitset over interned facts), and the goal
//! test is "all goal facts hold". [`TaskProblem`] implements [`SearchProblem`], so it is solved
//! by the same [`crate::search::solve`] under the same [`crate::deadline::Deadline`].
//!
//! Every action carries named parameters (arm, object, locations) so that a motion planner can
//! refine it into motion through the [`Refiner`] hook. [`TwoIrp6Cell`] is the ready-made domain
//! of the two-IRp-6 cell.

use std::collections::{BTreeSet, HashMap};
use std::fmt;

use crate::error::PlanError;
use crate::search::{Cost, Plan, SearchProblem, Successor};

/// An interned fact: an index into [`TaskProblem::fact_name`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct FactId(pub u32);

/// A symbolic search state: the set of facts that hold (closed-world), as a bitset.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord, Default)]
pub struct FactSet(Vec<u64>);

impl FactSet {
    fn with_capacity(facts: usize) -> Self {
        FactSet(vec![0; facts.div_ceil(64)])
    }

    fn insert(&mut self, fact: FactId) {
        let i = fact.0 as usize;
        self.0[i / 64] |= 1 << (i % 64);
    }

    /// True when `fact` holds.
    pub fn contains(&self, fact: FactId) -> bool {
        let i = fact.0 as usize;
        self.0.get(i / 64).is_some_and(|w| w & (1 << (i % 64)) != 0)
    }

    /// True when every fact of `self` holds in `other`.
    pub fn is_subset(&self, other: &FactSet) -> bool {
        self.0.iter().zip(&other.0).all(|(a, b)| a & !b == 0)
    }

    /// Number of facts of `self` missing from `other`.
    fn missing_from(&self, other: &FactSet) -> u32 {
        self.0.iter().zip(&other.0).map(|(a, b)| (a & !b).count_ones()).sum()
    }

    /// The facts that hold, in id order.
    pub fn iter(&self) -> impl Iterator<Item = FactId> + '_ {
        self.0.iter().enumerate().flat_map(|(w, &word)| {
            (0..64).filter(move |b| word & (1 << b) != 0).map(move |b| FactId((w * 64 + b) as u32))
        })
    }

    /// STRIPS application: `(self \ delete) ∪ add`.
    fn apply(&self, delete: &FactSet, add: &FactSet) -> FactSet {
        FactSet(self.0.iter().zip(&delete.0).zip(&add.0).map(|((s, d), a)| (s & !d) | a).collect())
    }
}

/// One named parameter of a ground action, e.g. `arm = irp6ot`.
#[derive(Debug, Clone, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct Param {
    /// The parameter's role (`arm`, `object`, `location`, `from`, `to`...).
    pub role: String,
    /// The object bound to it.
    pub value: String,
}

/// A ground action: an operator name with its parameters bound. This is what a motion planner
/// refines into motion.
#[derive(Debug, Clone, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct GroundAction {
    /// The action schema's name (`grasp`, `place`, `handover`, `move`).
    pub name: String,
    /// Parameters in schema order.
    pub params: Vec<Param>,
}

impl GroundAction {
    /// An action from a name and `(role, value)` pairs.
    pub fn new(name: &str, params: &[(&str, &str)]) -> Self {
        let params = params.iter().map(|&(role, value)| Param { role: role.into(), value: value.into() }).collect();
        GroundAction { name: name.into(), params }
    }

    /// The value bound to `role`, if the action has that parameter.
    pub fn param(&self, role: &str) -> Option<&str> {
        self.params.iter().find(|p| p.role == role).map(|p| p.value.as_str())
    }
}

impl fmt::Display for GroundAction {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}(", self.name)?;
        for (i, p) in self.params.iter().enumerate() {
            if i > 0 {
                write!(f, ", ")?;
            }
            write!(f, "{}={}", p.role, p.value)?;
        }
        write!(f, ")")
    }
}

/// A ground production rule: if all `preconditions` hold, the action may be applied; it
/// removes `delete`, then adds `add`, at path cost `cost`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Rule {
    /// The action this rule performs.
    pub action: GroundAction,
    /// Facts that must hold before.
    pub preconditions: Vec<String>,
    /// Facts made true.
    pub add: Vec<String>,
    /// Facts made false.
    pub delete: Vec<String>,
    /// Path cost of the action (non-negative, not NaN).
    pub cost: f64,
}

/// The operator label of a task plan: the index of a rule of its [`TaskProblem`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct RuleId(pub usize);

/// Which heuristic a [`TaskProblem`] offers to the search.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TaskHeuristic {
    /// `h = 0`: uniform-cost search.
    Zero,
    /// Goal count: `ceil(missing goal facts / most goal facts one rule adds) * cheapest such
    /// rule`. Admissible: every action adds at most that many goal facts, at least that cost.
    #[default]
    GoalCount,
}

#[derive(Debug, Clone)]
struct CompiledRule {
    pre: FactSet,
    add: FactSet,
    delete: FactSet,
    cost: Cost,
}

/// A task-level search problem: initial facts, ground rules, goal facts.
#[derive(Debug, Clone)]
pub struct TaskProblem {
    names: Vec<String>,
    rules: Vec<Rule>,
    compiled: Vec<CompiledRule>,
    initial: FactSet,
    goal: FactSet,
    heuristic: TaskHeuristic,
    max_goal_adds: u32,
    min_goal_cost: f64,
}

impl TaskProblem {
    /// Interns the facts and checks the rules (costs must be non-negative, not NaN).
    pub fn new<I, G, S, T>(initial: I, rules: Vec<Rule>, goal: G) -> Result<Self, PlanError>
    where
        I: IntoIterator<Item = S>,
        G: IntoIterator<Item = T>,
        S: Into<String>,
        T: Into<String>,
    {
        let mut index: HashMap<String, FactId> = HashMap::new();
        let mut names: Vec<String> = Vec::new();
        let mut intern = |name: String| -> Result<FactId, PlanError> {
            if let Some(&id) = index.get(&name) {
                return Ok(id);
            }
            let id = u32::try_from(names.len())
                .map(FactId)
                .map_err(|_| PlanError::InvalidTask { message: "more than 2^32 facts".into() })?;
            index.insert(name.clone(), id);
            names.push(name);
            Ok(id)
        };
        let initial_ids = initial.into_iter().map(|s| intern(s.into())).collect::<Result<Vec<_>, _>>()?;
        let goal_ids = goal.into_iter().map(|s| intern(s.into())).collect::<Result<Vec<_>, _>>()?;
        let mut rule_ids = Vec::with_capacity(rules.len());
        for rule in &rules {
            let cost = Cost::checked(rule.cost, &format!("of rule `{}`", rule.action))?;
            let mut ids = |facts: &[String]| facts.iter().map(|f| intern(f.clone())).collect::<Result<Vec<_>, _>>();
            rule_ids.push((ids(&rule.preconditions)?, ids(&rule.add)?, ids(&rule.delete)?, cost));
        }
        let n = names.len();
        let set = |ids: &[FactId]| {
            let mut s = FactSet::with_capacity(n);
            ids.iter().for_each(|&id| s.insert(id));
            s
        };
        let initial = set(&initial_ids);
        let goal = set(&goal_ids);
        let compiled: Vec<CompiledRule> = rule_ids
            .iter()
            .map(|(pre, add, delete, cost)| CompiledRule {
                pre: set(pre),
                add: set(add),
                delete: set(delete),
                cost: *cost,
            })
            .collect();
        let mut max_goal_adds = 0;
        let mut min_goal_cost = f64::INFINITY;
        for rule in &compiled {
            let adds = goal.0.iter().zip(&rule.add.0).map(|(g, a)| (g & a).count_ones()).sum::<u32>();
            if adds > 0 {
                max_goal_adds = max_goal_adds.max(adds);
                min_goal_cost = min_goal_cost.min(rule.cost.get());
            }
        }
        Ok(TaskProblem {
            names,
            rules,
            compiled,
            initial,
            goal,
            heuristic: TaskHeuristic::default(),
            max_goal_adds,
            min_goal_cost,
        })
    }

    /// Chooses the heuristic (default: [`TaskHeuristic::GoalCount`]).
    #[must_use]
    pub fn with_heuristic(mut self, heuristic: TaskHeuristic) -> Self {
        self.heuristic = heuristic;
        self
    }

    /// The ground rules, indexed by [`RuleId`].
    pub fn rules(&self) -> &[Rule] {
        &self.rules
    }

    /// The rule behind an operator of a plan.
    pub fn rule(&self, id: RuleId) -> Result<&Rule, PlanError> {
        self.rules.get(id.0).ok_or(PlanError::UnknownOperator { index: id.0, count: self.rules.len() })
    }

    /// The name of an interned fact.
    pub fn fact_name(&self, fact: FactId) -> Option<&str> {
        self.names.get(fact.0 as usize).map(String::as_str)
    }

    /// The facts of a state, by name.
    pub fn fact_names(&self, state: &FactSet) -> BTreeSet<String> {
        state.iter().filter_map(|f| self.fact_name(f)).map(str::to_owned).collect()
    }

    /// The state after applying rule `id` to `state`, or `None` if its preconditions do not hold.
    pub fn apply(&self, state: &FactSet, id: RuleId) -> Result<Option<FactSet>, PlanError> {
        self.rule(id)?;
        let rule = &self.compiled[id.0];
        Ok(rule.pre.is_subset(state).then(|| state.apply(&rule.delete, &rule.add)))
    }

    /// The ground actions of a task plan, in order.
    pub fn actions(&self, plan: &Plan<FactSet, RuleId>) -> Result<Vec<&GroundAction>, PlanError> {
        plan.operators.iter().map(|&id| self.rule(id).map(|r| &r.action)).collect()
    }
}

impl SearchProblem for TaskProblem {
    type State = FactSet;
    type Operator = RuleId;

    fn initial(&self) -> FactSet {
        self.initial.clone()
    }

    fn successors(&self, state: &FactSet, out: &mut Vec<Successor<FactSet, RuleId>>) {
        for (i, rule) in self.compiled.iter().enumerate() {
            if rule.pre.is_subset(state) {
                out.push(Successor {
                    operator: RuleId(i),
                    state: state.apply(&rule.delete, &rule.add),
                    cost: rule.cost,
                });
            }
        }
    }

    fn is_goal(&self, state: &FactSet) -> bool {
        self.goal.is_subset(state)
    }

    fn heuristic(&self, state: &FactSet) -> f64 {
        match self.heuristic {
            TaskHeuristic::Zero => 0.0,
            TaskHeuristic::GoalCount => {
                let missing = self.goal.missing_from(state);
                if missing == 0 {
                    0.0
                } else if self.max_goal_adds == 0 {
                    f64::INFINITY // no rule makes any goal fact true
                } else {
                    f64::from(missing.div_ceil(self.max_goal_adds)) * self.min_goal_cost
                }
            }
        }
    }
}

/// The hook by which a task plan is refined, action by action, into something executable
/// (typically a motion plan for the arm named in the action).
pub trait Refiner {
    /// What one action refines into (a trajectory, a motion request...).
    type Refined;

    /// Refines one ground action.
    fn refine(&mut self, action: &GroundAction) -> Result<Self::Refined, PlanError>;
}

/// Refines every action of `plan` in order; stops at the first failure, naming the step.
pub fn refine_plan<R: Refiner>(
    problem: &TaskProblem,
    plan: &Plan<FactSet, RuleId>,
    refiner: &mut R,
) -> Result<Vec<R::Refined>, PlanError> {
    let actions = problem.actions(plan)?;
    actions
        .into_iter()
        .enumerate()
        .map(|(step, action)| {
            refiner.refine(action).map_err(|source| PlanError::RefinementFailed {
                step,
                action: action.to_string(),
                source: Box::new(source),
            })
        })
        .collect()
}

/// Path costs of the two-IRp-6 cell's actions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CellCosts {
    /// `grasp(arm, object, location)`.
    pub grasp: f64,
    /// `place(arm, object, location)`.
    pub place: f64,
    /// `handover(from, to, object)`.
    pub handover: f64,
    /// `move(arm, from, to)`.
    pub travel: f64,
}

impl Default for CellCosts {
    /// Unit costs: the optimal plan has the fewest actions.
    fn default() -> Self {
        CellCosts { grasp: 1.0, place: 1.0, handover: 1.0, travel: 1.0 }
    }
}

/// The two-IRp-6 cell: `irp6ot` (on a track along +y) reaches `table_a` and `handover`;
/// `irp6p` (on a postument) reaches `table_b` and `handover`. Objects rest only on tables;
/// moving an object from one table to the other therefore needs a hand-to-hand `handover`.
///
/// Facts: `on(obj,loc)`, `holding(arm,obj)`, `hand_empty(arm)`, `arm_at(arm,loc)`.
/// Actions: `grasp(arm, object, location)`, `place(arm, object, location)`,
/// `handover(from, to, object)` (both arms at `handover`), `move(arm, from, to)`.
#[derive(Debug, Clone, PartialEq)]
pub struct TwoIrp6Cell {
    /// Objects and the table each starts on.
    pub objects: Vec<(String, String)>,
    /// Arms and the location each starts at.
    pub arms: Vec<(String, String)>,
    /// Action costs.
    pub costs: CellCosts,
}

impl TwoIrp6Cell {
    /// The arm on the track.
    pub const IRP6OT: &'static str = "irp6ot";
    /// The arm on the postument.
    pub const IRP6P: &'static str = "irp6p";
    /// Table reachable only by `irp6ot`.
    pub const TABLE_A: &'static str = "table_a";
    /// Table reachable only by `irp6p`.
    pub const TABLE_B: &'static str = "table_b";
    /// The hand-to-hand transfer pose, reachable by both.
    pub const HANDOVER: &'static str = "handover";

    /// One object `cube` on `table_a`; `irp6ot` at `table_a`, `irp6p` at `table_b`; unit costs.
    pub fn new() -> Self {
        TwoIrp6Cell {
            objects: vec![("cube".into(), Self::TABLE_A.into())],
            arms: vec![(Self::IRP6OT.into(), Self::TABLE_A.into()), (Self::IRP6P.into(), Self::TABLE_B.into())],
            costs: CellCosts::default(),
        }
    }

    /// Locations an arm can reach (empty for an unknown arm).
    pub fn reach(arm: &str) -> &'static [&'static str] {
        match arm {
            Self::IRP6OT => &[Self::TABLE_A, Self::HANDOVER],
            Self::IRP6P => &[Self::TABLE_B, Self::HANDOVER],
            _ => &[],
        }
    }

    fn is_table(location: &str) -> bool {
        location == Self::TABLE_A || location == Self::TABLE_B
    }

    /// The ground rules of the cell.
    pub fn rules(&self) -> Vec<Rule> {
        let c = self.costs;
        let mut rules = Vec::new();
        let rule = |action: GroundAction, pre: Vec<String>, add: Vec<String>, delete: Vec<String>, cost| Rule {
            action,
            preconditions: pre,
            add,
            delete,
            cost,
        };
        for (arm, _) in &self.arms {
            let reach = Self::reach(arm);
            for &from in reach {
                for &to in reach.iter().filter(|&&to| to != from) {
                    rules.push(rule(
                        GroundAction::new("move", &[("arm", arm), ("from", from), ("to", to)]),
                        vec![format!("arm_at({arm},{from})")],
                        vec![format!("arm_at({arm},{to})")],
                        vec![format!("arm_at({arm},{from})")],
                        c.travel,
                    ));
                }
            }
            for (obj, _) in &self.objects {
                for &loc in reach.iter().filter(|l| Self::is_table(l)) {
                    let params = [("arm", arm.as_str()), ("object", obj.as_str()), ("location", loc)];
                    rules.push(rule(
                        GroundAction::new("grasp", &params),
                        vec![format!("arm_at({arm},{loc})"), format!("hand_empty({arm})"), format!("on({obj},{loc})")],
                        vec![format!("holding({arm},{obj})")],
                        vec![format!("hand_empty({arm})"), format!("on({obj},{loc})")],
                        c.grasp,
                    ));
                    rules.push(rule(
                        GroundAction::new("place", &params),
                        vec![format!("arm_at({arm},{loc})"), format!("holding({arm},{obj})")],
                        vec![format!("on({obj},{loc})"), format!("hand_empty({arm})")],
                        vec![format!("holding({arm},{obj})")],
                        c.place,
                    ));
                }
            }
        }
        for (from, _) in &self.arms {
            for (to, _) in self.arms.iter().filter(|(to, _)| to != from) {
                for (obj, _) in &self.objects {
                    let h = Self::HANDOVER;
                    rules.push(rule(
                        GroundAction::new("handover", &[("from", from), ("to", to), ("object", obj), ("location", h)]),
                        vec![
                            format!("holding({from},{obj})"),
                            format!("hand_empty({to})"),
                            format!("arm_at({from},{h})"),
                            format!("arm_at({to},{h})"),
                        ],
                        vec![format!("holding({to},{obj})"), format!("hand_empty({from})")],
                        vec![format!("holding({from},{obj})"), format!("hand_empty({to})")],
                        c.handover,
                    ));
                }
            }
        }
        rules
    }

    /// The initial facts of the cell.
    pub fn initial_facts(&self) -> Vec<String> {
        let arms =
            self.arms.iter().flat_map(|(arm, loc)| [format!("arm_at({arm},{loc})"), format!("hand_empty({arm})")]);
        arms.chain(self.objects.iter().map(|(obj, loc)| format!("on({obj},{loc})"))).collect()
    }

    /// The task "each `(object, location)` of `goal` ends on that location".
    pub fn problem(&self, goal: &[(&str, &str)]) -> Result<TaskProblem, PlanError> {
        for &(obj, loc) in goal {
            if !self.objects.iter().any(|(o, _)| o == obj) {
                return Err(PlanError::InvalidTask { message: format!("unknown object `{obj}` in goal") });
            }
            if !Self::is_table(loc) && loc != Self::HANDOVER {
                return Err(PlanError::InvalidTask { message: format!("unknown location `{loc}` in goal") });
            }
        }
        for (arm, loc) in &self.arms {
            if !Self::reach(arm).contains(&loc.as_str()) {
                return Err(PlanError::InvalidTask { message: format!("arm `{arm}` cannot be at `{loc}`") });
            }
        }
        let goal = goal.iter().map(|(obj, loc)| format!("on({obj},{loc})"));
        TaskProblem::new(self.initial_facts(), self.rules(), goal)
    }

    /// The transfer task: bring `object` from wherever it is to `table_b`.
    pub fn transfer_to_table_b(&self, object: &str) -> Result<TaskProblem, PlanError> {
        self.problem(&[(object, Self::TABLE_B)])
    }
}

impl Default for TwoIrp6Cell {
    fn default() -> Self {
        Self::new()
    }
}
