//! Transition functions `^m f_{c_j}` (eq. 8) and the predicates `^q p_{c_j}` that choose them (eq. 9).

use crate::image::{InputImages, OutputImages};

/// One partial transition function `^m f_{c_j}`: from `c^i` (the internal variables `c_c`, which
/// have a single representation, and the read-only input images) compute `c^{i+1}` (the new
/// `c_c` in place and the write-only output images).
///
/// Any `FnMut(&mut C, &InputImages, &mut OutputImages) + Send` is one.
pub trait TransitionFunction<C>: Send {
    /// Compute `c^{i+1}`: update `c_c` in place and write the output images, from `c^i`.
    fn compute(&mut self, cc: &mut C, inputs: &InputImages, outputs: &mut OutputImages);
}

impl<C, F> TransitionFunction<C> for F
where
    F: FnMut(&mut C, &InputImages, &mut OutputImages) + Send,
{
    fn compute(&mut self, cc: &mut C, inputs: &InputImages, outputs: &mut OutputImages) {
        self(cc, inputs, outputs)
    }
}

/// A transition function that does nothing (no effector command: the effector makes a
/// controlled stop and holds).
pub fn idle<C>() -> impl TransitionFunction<C> {
    |_: &mut C, _: &InputImages, _: &mut OutputImages| {}
}

/// The test inside a [`Predicate`].
pub type PredicateFn<C> = Box<dyn Fn(&C, &InputImages) -> bool + Send + Sync>;

/// A named predicate `^q p_{c_j}(c^i)`; it may read `c_c` and the input images only.
pub struct Predicate<C> {
    name: String,
    test: PredicateFn<C>,
}

impl<C> Predicate<C> {
    /// A predicate named `name` that holds when `test` is true on `c^i`.
    pub fn new(name: impl Into<String>, test: impl Fn(&C, &InputImages) -> bool + Send + Sync + 'static) -> Self {
        Self { name: name.into(), test: Box::new(test) }
    }
    /// A predicate that always holds.
    pub fn always(name: impl Into<String>) -> Self {
        Self::new(name, |_, _| true)
    }
    /// The predicate's name.
    pub fn name(&self) -> &str {
        &self.name
    }
    /// Evaluate on `c^i`.
    pub fn holds(&self, cc: &C, inputs: &InputImages) -> bool {
        (self.test)(cc, inputs)
    }
}

impl<C> std::fmt::Debug for Predicate<C> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Predicate").field("name", &self.name).finish()
    }
}
