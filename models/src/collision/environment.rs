//! The static world a robot moves in: named, posed obstacles.

use nalgebra::Isometry3;

use crate::geometry::Shape;

/// One obstacle: a shape posed in the world, with a name for messages ("link `x` and obstacle
/// `table`") and for moving it ([`Environment::set_pose`]).
#[derive(Debug, Clone)]
pub struct Obstacle {
    /// Name used in messages and by the name-based methods of [`Environment`].
    pub name: String,
    /// Pose of the shape's frame in the world frame.
    pub pose: Isometry3<f64>,
    /// The shape, in its own frame.
    pub shape: Shape,
}

impl Obstacle {
    /// An obstacle named `name` with `shape` placed at `pose` in the world frame.
    pub fn new(name: impl Into<String>, pose: Isometry3<f64>, shape: Shape) -> Self {
        Self { name: name.into(), pose, shape }
    }
}

/// A set of obstacles. Names are expected to be unique; the name-based methods act on every
/// obstacle with that name.
#[derive(Debug, Clone, Default)]
pub struct Environment {
    obstacles: Vec<Obstacle>,
}

impl Environment {
    /// An empty environment.
    pub fn new() -> Self {
        Self::default()
    }
    /// Add an obstacle.
    pub fn add(&mut self, o: Obstacle) {
        self.obstacles.push(o);
    }
    /// Builder form of [`Environment::add`].
    pub fn with(mut self, o: Obstacle) -> Self {
        self.add(o);
        self
    }
    /// Every obstacle, in the order added.
    pub fn obstacles(&self) -> &[Obstacle] {
        &self.obstacles
    }
    /// The first obstacle of this name.
    pub fn get(&self, name: &str) -> Option<&Obstacle> {
        self.obstacles.iter().find(|o| o.name == name)
    }
    /// Move the obstacle(s) of this name; `false` if there is none.
    pub fn set_pose(&mut self, name: &str, pose: Isometry3<f64>) -> bool {
        let mut found = false;
        for o in self.obstacles.iter_mut().filter(|o| o.name == name) {
            o.pose = pose;
            found = true;
        }
        found
    }
    /// Remove the obstacle(s) of this name; `false` if there is none.
    pub fn remove(&mut self, name: &str) -> bool {
        let before = self.obstacles.len();
        self.obstacles.retain(|o| o.name != name);
        self.obstacles.len() != before
    }
    /// Number of obstacles.
    pub fn len(&self) -> usize {
        self.obstacles.len()
    }
    /// Whether there are no obstacles.
    pub fn is_empty(&self) -> bool {
        self.obstacles.is_empty()
    }
}

impl FromIterator<Obstacle> for Environment {
    fn from_iter<I: IntoIterator<Item = Obstacle>>(iter: I) -> Self {
        Self { obstacles: iter.into_iter().collect() }
    }
}

impl Extend<Obstacle> for Environment {
    fn extend<I: IntoIterator<Item = Obstacle>>(&mut self, iter: I) {
        self.obstacles.extend(iter);
    }
}
