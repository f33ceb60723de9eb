//! MRROC++'s motion instructions as behaviours (fig. 3, eq. 17-18).
//!
//! `Move(f', f'', f_τ)`: the first step is computed by `f'`, every later one by `f''`, until the
//! terminal condition `f_τ` holds. `Wait(f_ι)`: do nothing (the effector holds) until the
//! initial condition `f_ι` holds. Both turn the synchronous step loop into an event-driven one.
//! Several `Move`s run in parallel inside a [`crate::Reactive::composed`] behaviour, which hands
//! their partial results to a [`crate::Composer`] before anything reaches the effector.

use crate::behaviour::{Behaviour, Status};
use crate::error::Violation;
use crate::image::{InputImages, OutputImages};
use crate::transition::{Predicate, TransitionFunction, idle};

/// `Move(^m f'_{c_j}, ^m f''_{c_j}, ^m f_{τ_j})`.
///
/// Step 1 runs `first_step`. In every later step the terminal condition is tested on `c^i`
/// first: if it holds, the Move ends without output (and its parent chooses the next behaviour
/// in the same step); otherwise `next_step` runs.
pub struct Move<C> {
    name: String,
    first_step: Box<dyn TransitionFunction<C>>,
    next_step: Box<dyn TransitionFunction<C>>,
    terminal: Predicate<C>,
    started: bool,
}

impl<C> Move<C> {
    /// A motion named `name`: `first_step` in its first step, then `next_step` until `terminal_condition` holds.
    pub fn new(
        name: impl Into<String>,
        first_step: impl TransitionFunction<C> + 'static,
        next_step: impl TransitionFunction<C> + 'static,
        terminal_condition: Predicate<C>,
    ) -> Self {
        Self {
            name: name.into(),
            first_step: Box::new(first_step),
            next_step: Box::new(next_step),
            terminal: terminal_condition,
            started: false,
        }
    }
}

impl<C> Behaviour<C> for Move<C> {
    fn name(&self) -> &str {
        &self.name
    }
    fn step(&mut self, cc: &mut C, inputs: &InputImages, outputs: &mut OutputImages) -> Result<Status, Violation> {
        if !self.started {
            self.started = true;
            self.first_step.compute(cc, inputs, outputs);
            return Ok(Status::Running);
        }
        if self.terminal.holds(cc, inputs) {
            self.started = false;
            return Ok(Status::Skipped);
        }
        self.next_step.compute(cc, inputs, outputs);
        Ok(Status::Running)
    }
    fn reset(&mut self) {
        self.started = false;
    }
}

/// `Wait(^m f_{ι_j})`: until the initial condition holds, run `during` (by default nothing: no
/// effector command, so the effector stops in a controlled way and holds); then end without
/// output, so the next behaviour starts in the same step.
pub struct Wait<C> {
    name: String,
    initial: Predicate<C>,
    during: Box<dyn TransitionFunction<C>>,
}

impl<C: 'static> Wait<C> {
    /// Wait named `name` until `initial_condition` holds, doing nothing meanwhile.
    pub fn new(name: impl Into<String>, initial_condition: Predicate<C>) -> Self {
        Self { name: name.into(), initial: initial_condition, during: Box::new(idle::<C>()) }
    }
}

impl<C> Wait<C> {
    /// What to do while waiting (e.g. keep reporting state to a coordinator).
    pub fn during(mut self, f: impl TransitionFunction<C> + 'static) -> Self {
        self.during = Box::new(f);
        self
    }
}

impl<C> Behaviour<C> for Wait<C> {
    fn name(&self) -> &str {
        &self.name
    }
    fn step(&mut self, cc: &mut C, inputs: &InputImages, outputs: &mut OutputImages) -> Result<Status, Violation> {
        if self.initial.holds(cc, inputs) {
            return Ok(Status::Skipped);
        }
        self.during.compute(cc, inputs, outputs);
        Ok(Status::Running)
    }
    fn reset(&mut self) {}
}
