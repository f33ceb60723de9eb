//! A lazy probabilistic roadmap: configurations as vertices of a `petgraph` graph, straight
//! C-space segments as edges whose collision status is found out only when a search needs it.
//!
//! Lazy PRM (Bohlin and Kavraki, 2000): vertices are checked when sampled, edges are not. A
//! query runs A* over every edge not known to be invalid, checks the edges of the path it found
//! (cheapest first), marks what it learns and searches again, until a path survives or the
//! graph is disconnected. Building samples in parallel chunks, each with its own [`Rng`] stream
//! forked in chunk order, so a seed gives the same roadmap on any number of threads.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use embodied_models::{ConfigSpace, Rng, Robot};
use petgraph::graph::{EdgeIndex, NodeIndex, UnGraph};
use petgraph::visit::EdgeRef;
use rayon::prelude::*;

use crate::deadline::{Budget, Deadline};
use crate::error::PlanError;
use crate::outcome::{MotionStats, unwrap_path};
use crate::validity::{CERTIFY_TOLERANCE, DEFAULT_RESOLUTION, EdgeCheck, StateValidity, Validity, check_start};

/// What is known about an edge's straight segment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum EdgeState {
    /// Not checked yet (lazy).
    Unchecked,
    /// Checked collision-free at the checking resolution.
    Valid,
    /// Checked and found in collision.
    Invalid,
}

/// An edge of the roadmap: its C-space length and what is known of it.
#[derive(Debug, Clone, Copy)]
pub struct RoadEdge {
    /// Length of the edge in configuration space (the C-space metric, rad or m).
    pub length: f64,
    /// Whether the edge is known to be free, in collision, or not checked yet.
    pub state: EdgeState,
}

/// A roadmap of collision-free configurations with lazily checked edges.
#[derive(Debug, Clone)]
pub struct Roadmap {
    graph: UnGraph<Vec<f64>, RoadEdge>,
    space: ConfigSpace,
    k: usize,
    rng: Rng,
    samples: usize,
    collision_checks: u64,
}

/// Samples validated per chunk (and per rayon task) when a roadmap grows.
const CHUNK: usize = 32;

/// Counters of one roadmap query.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct QueryCounters {
    pub astar_expansions: usize,
    pub searches: usize,
}

/// How a lazy search ended.
pub(crate) enum LazyOutcome {
    /// A path (vertex indices) whose every edge has been checked valid.
    Found(Vec<NodeIndex>),
    /// No path over the edges not known to be invalid.
    Disconnected,
    /// The deadline passed.
    Interrupted,
}

impl Roadmap {
    /// An empty roadmap for `robot` connecting every new vertex to its `k` nearest neighbours.
    pub fn new(robot: &Robot, k: usize, seed: u64) -> Self {
        Self {
            graph: UnGraph::default(),
            space: robot.config_space(),
            k: k.max(1),
            rng: Rng::new(seed),
            samples: 0,
            collision_checks: 0,
        }
    }

    /// A roadmap of up to `n_samples` random collision-free configurations (samples that collide
    /// are dropped), each connected to its `k` nearest neighbours by unchecked edges. Sampling
    /// and neighbour search run in parallel (rayon); the result depends on the seed only.
    pub fn build<V: StateValidity>(model: &V, n_samples: usize, k: usize, seed: u64) -> Self {
        let mut roadmap = Self::new(model.robot(), k, seed);
        roadmap.grow(model, n_samples, true);
        roadmap
    }

    /// Vertices (collision-free configurations).
    pub fn vertex_count(&self) -> usize {
        self.graph.node_count()
    }
    /// Edges, in any state.
    pub fn edge_count(&self) -> usize {
        self.graph.edge_count()
    }
    /// Samples drawn so far, valid or not.
    pub fn samples(&self) -> usize {
        self.samples
    }
    /// Collision checks spent on sampling.
    pub fn sampling_collision_checks(&self) -> u64 {
        self.collision_checks
    }
    /// The configuration of vertex `i`.
    pub fn configuration(&self, i: usize) -> Option<&[f64]> {
        self.graph.node_weight(NodeIndex::new(i)).map(|q| q.as_slice())
    }
    /// How many edges are in each state: (unchecked, valid, invalid).
    pub fn edge_states(&self) -> (usize, usize, usize) {
        self.graph.edge_weights().fold((0, 0, 0), |(u, v, i), e| match e.state {
            EdgeState::Unchecked => (u + 1, v, i),
            EdgeState::Valid => (u, v + 1, i),
            EdgeState::Invalid => (u, v, i + 1),
        })
    }
    /// The underlying graph (vertex weights are configurations).
    pub fn graph(&self) -> &UnGraph<Vec<f64>, RoadEdge> {
        &self.graph
    }

    /// Draw `n_samples` more samples; add the collision-free ones and connect them. Returns the
    /// number of vertices added.
    pub fn grow<V: StateValidity>(&mut self, model: &V, n_samples: usize, parallel: bool) -> usize {
        let robot = model.robot();
        let chunks = n_samples.div_ceil(CHUNK);
        let streams: Vec<(usize, Rng)> =
            (0..chunks).map(|c| (CHUNK.min(n_samples - c * CHUNK), self.rng.fork(c as u64))).collect();
        let sample_chunk = |(count, mut rng): (usize, Rng)| {
            let mut scratch = model.scratch();
            let mut q = vec![0.0; robot.dof()];
            let mut valid = Vec::new();
            for _ in 0..count {
                robot.random_configuration_into(&mut rng, &mut q);
                if !model.collides(&q, &mut scratch) {
                    valid.push(q.clone());
                }
            }
            valid
        };
        let batches: Vec<Vec<Vec<f64>>> = if parallel && chunks > 1 {
            streams.into_par_iter().map(sample_chunk).collect()
        } else {
            streams.into_iter().map(sample_chunk).collect()
        };
        self.samples += n_samples;
        self.collision_checks += n_samples as u64;
        let first_new = self.graph.node_count();
        for q in batches.into_iter().flatten() {
            self.graph.add_node(q);
        }
        let added = self.graph.node_count() - first_new;
        self.connect_from(first_new, parallel);
        added
    }

    /// Add one configuration (not checked here) and connect it to its nearest neighbours.
    pub fn add_vertex(&mut self, q: Vec<f64>) -> NodeIndex {
        let first = self.graph.node_count();
        let node = self.graph.add_node(q);
        self.connect_from(first, false);
        node
    }

    /// Connect each vertex from `first` on to its `k` nearest among all vertices.
    fn connect_from(&mut self, first: usize, parallel: bool) {
        let n = self.graph.node_count();
        if first >= n {
            return;
        }
        let nodes: Vec<&Vec<f64>> = self.graph.node_weights().collect();
        let nearest = |i: usize| -> Vec<(usize, f64)> { k_nearest(&self.space, &nodes, i, self.k) };
        let neighbours: Vec<Vec<(usize, f64)>> = if parallel && n - first > CHUNK {
            (first..n).into_par_iter().map(nearest).collect()
        } else {
            (first..n).map(nearest).collect()
        };
        for (offset, list) in neighbours.into_iter().enumerate() {
            let a = NodeIndex::new(first + offset);
            for (j, length) in list {
                let b = NodeIndex::new(j);
                if self.graph.find_edge(a, b).is_none() {
                    self.graph.add_edge(a, b, RoadEdge { length, state: EdgeState::Unchecked });
                }
            }
        }
    }

    /// A collision-free path from `start` to `goal` over this roadmap (both are added as
    /// vertices), by lazy A*: search, check the found path's edges shortest first, mark the
    /// invalid one and search again. The path is unwrapped (see [`crate::outcome::MotionPlan`]).
    pub fn query<V: StateValidity>(
        &mut self,
        model: &V,
        start: &[f64],
        goal: &[f64],
        deadline: &Deadline,
    ) -> Result<Vec<Vec<f64>>, PlanError> {
        self.query_any(model, start, &[goal.to_vec()], deadline)
    }

    /// [`Roadmap::query`] to the nearest reachable of several goals.
    pub fn query_any<V: StateValidity>(
        &mut self,
        model: &V,
        start: &[f64],
        goals: &[Vec<f64>],
        deadline: &Deadline,
    ) -> Result<Vec<Vec<f64>>, PlanError> {
        if self.graph.node_count() == 0 {
            return Err(PlanError::EmptyRoadmap);
        }
        let robot = model.robot();
        check_start(model, start)?;
        if goals.is_empty() {
            return Err(PlanError::InvalidInput { message: "the goal set is empty".into() });
        }
        for (index, g) in goals.iter().enumerate() {
            robot.check_configuration(g).map_err(|e| PlanError::GoalUnreachable { reason: e.to_string() })?;
            if let Some(contact) = model.first_collision(g) {
                return Err(PlanError::GoalInCollision { index, contact });
            }
        }
        let mut validity = Validity::new(model, DEFAULT_RESOLUTION)
            .with_edge_check(EdgeCheck::Certified { tolerance: CERTIFY_TOLERANCE });
        let mut budget = Budget::new(deadline);
        let s = self.add_vertex(start.to_vec());
        let gs: Vec<NodeIndex> = goals.iter().map(|g| self.add_vertex(g.clone())).collect();
        let mut counters = QueryCounters::default();
        match self.lazy_search(&mut validity, &mut budget, s, &gs, &mut counters) {
            LazyOutcome::Found(path) => Ok(unwrap_path(&self.space, self.path_configurations(&path))),
            LazyOutcome::Disconnected => Err(PlanError::NoPath { samples: self.samples }),
            LazyOutcome::Interrupted => Err(PlanError::OutOfTime {
                stats: MotionStats {
                    elapsed: budget.started.elapsed(),
                    samples: self.samples,
                    edges_checked: validity.edges_checked,
                    collision_checks: validity.collision_checks,
                    astar_expansions: counters.astar_expansions,
                    searches: counters.searches,
                    planner: "lazy-prm",
                    path_length: 0.0,
                    ..Default::default()
                },
            }),
        }
    }

    pub(crate) fn path_configurations(&self, path: &[NodeIndex]) -> Vec<Vec<f64>> {
        path.iter().map(|&n| self.graph[n].clone()).collect()
    }

    /// Lazy A*: search over edges not known invalid, validate the found path, repeat.
    pub(crate) fn lazy_search<V: StateValidity>(
        &mut self,
        validity: &mut Validity<'_, V>,
        budget: &mut Budget<'_>,
        start: NodeIndex,
        goals: &[NodeIndex],
        counters: &mut QueryCounters,
    ) -> LazyOutcome {
        let mut to_check: Vec<(f64, EdgeIndex)> = Vec::new();
        loop {
            counters.searches += 1;
            let path = match self.astar(start, goals, budget, counters) {
                Search::Found(p) => p,
                Search::Unreachable => return LazyOutcome::Disconnected,
                Search::Interrupted => return LazyOutcome::Interrupted,
            };
            to_check.clear();
            for w in path.windows(2) {
                if let Some(e) = self.graph.find_edge(w[0], w[1])
                    && self.graph[e].state == EdgeState::Unchecked
                {
                    to_check.push((self.graph[e].length, e));
                }
            }
            // Cheapest first: a short edge costs few collision checks.
            to_check.sort_by(|a, b| a.0.total_cmp(&b.0));
            let mut all_valid = true;
            for &(_, e) in &to_check {
                if budget.spend(1, validity.collision_checks) {
                    return LazyOutcome::Interrupted;
                }
                let Some((a, b)) = self.graph.edge_endpoints(e) else { continue };
                let free = validity.segment_free(&self.graph[a], &self.graph[b]);
                self.graph[e].state = if free { EdgeState::Valid } else { EdgeState::Invalid };
                if !free {
                    all_valid = false;
                    break;
                }
            }
            if all_valid {
                return LazyOutcome::Found(path);
            }
        }
    }

    /// A* from `start` to any of `goals` over edges not known invalid; heuristic: C-space
    /// distance to the nearest goal (admissible: edge costs are C-space lengths).
    fn astar(
        &self,
        start: NodeIndex,
        goals: &[NodeIndex],
        budget: &mut Budget<'_>,
        counters: &mut QueryCounters,
    ) -> Search {
        let n = self.graph.node_count();
        let mut g = vec![f64::INFINITY; n];
        let mut parent = vec![u32::MAX; n];
        let mut closed = vec![false; n];
        let mut is_goal = vec![false; n];
        for &goal in goals {
            is_goal[goal.index()] = true;
        }
        let goal_qs: Vec<&[f64]> = goals.iter().map(|&x| self.graph[x].as_slice()).collect();
        let h = |q: &[f64]| goal_qs.iter().map(|gq| self.space.distance(q, gq)).fold(f64::INFINITY, f64::min);
        let mut open = BinaryHeap::new();
        g[start.index()] = 0.0;
        open.push(Entry { f: h(&self.graph[start]), g: 0.0, node: start.index() as u32 });
        let mut expansions_since = 0u32;
        while let Some(Entry { g: gn, node, .. }) = open.pop() {
            let u = node as usize;
            if closed[u] || gn > g[u] {
                continue;
            }
            if is_goal[u] {
                let mut path = vec![NodeIndex::new(u)];
                let mut v = u;
                while parent[v] != u32::MAX {
                    v = parent[v] as usize;
                    path.push(NodeIndex::new(v));
                }
                path.reverse();
                return Search::Found(path);
            }
            closed[u] = true;
            counters.astar_expansions += 1;
            expansions_since += 1;
            // A* expansions are cheap next to collision checks: count them in bundles.
            if expansions_since == 16 {
                expansions_since = 0;
                if budget.spend(16, budget.checks()) {
                    return Search::Interrupted;
                }
            }
            for e in self.graph.edges(NodeIndex::new(u)) {
                let w = e.weight();
                if w.state == EdgeState::Invalid {
                    continue;
                }
                let v = e.target().index();
                if closed[v] {
                    continue;
                }
                let tentative = gn + w.length;
                if tentative < g[v] {
                    g[v] = tentative;
                    parent[v] = node;
                    open.push(Entry { f: tentative + h(&self.graph[NodeIndex::new(v)]), g: tentative, node: v as u32 });
                }
            }
        }
        Search::Unreachable
    }
}

enum Search {
    Found(Vec<NodeIndex>),
    Unreachable,
    Interrupted,
}

/// An open-list entry, ordered so that the smallest f (then the largest g) pops first.
struct Entry {
    f: f64,
    g: f64,
    node: u32,
}
impl PartialEq for Entry {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Entry {}
impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Entry {
    fn cmp(&self, other: &Self) -> Ordering {
        other.f.total_cmp(&self.f).then(self.g.total_cmp(&other.g)).then(other.node.cmp(&self.node))
    }
}

/// The `k` nearest vertices to vertex `i` (excluding itself), nearest first, ties by index.
fn k_nearest(space: &ConfigSpace, nodes: &[&Vec<f64>], i: usize, k: usize) -> Vec<(usize, f64)> {
    let q = nodes[i];
    let mut best: Vec<(f64, usize)> = Vec::with_capacity(k + 1);
    for (j, other) in nodes.iter().enumerate() {
        if j == i {
            continue;
        }
        let d = space.distance_squared(q, other);
        if best.len() == k && d >= best[k - 1].0 {
            continue;
        }
        let at = best.partition_point(|&(bd, _)| bd <= d);
        best.insert(at, (d, j));
        best.truncate(k);
    }
    best.into_iter().map(|(d, j)| (j, d.sqrt())).collect()
}
