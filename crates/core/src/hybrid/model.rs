//! What a model gives the engine (its modes, dynamics and guards) and what a run
//! returns (events, grazes and the trajectory on the grid).

use crate::linalg::{Mat, Vector};

/// An affine function `h.x + hu u + d` of the state and the held input.
#[derive(Clone, Debug)]
pub struct GuardFn<const S: usize> {
    pub h: Vector<S>,
    /// Coefficient of the input (0 for a function of the state alone). The input is
    /// held over a sample, so such a function may jump at a sample boundary; it then
    /// fires at the start of the sample.
    pub hu: f64,
    pub d: f64,
    /// Positive magnitude by which the function is normalised (e.g. the half-width);
    /// crossing tolerance and grazing margins are relative to it.
    pub scale: f64,
}

/// A guard: fires when every function in `funcs` is positive; the switch then sets the
/// mode of switch `index` to `target`.
#[derive(Clone, Debug)]
pub struct GuardSpec<const S: usize> {
    pub funcs: Vec<GuardFn<S>>,
    pub index: usize,
    pub target: i8,
}

/// A piecewise-affine model whose mode is a vector of `n_switches()` codes in
/// `-2..=2` (`MODE_CODES` values per switch).
pub trait HybridModel<const S: usize>: Sync {
    fn n_switches(&self) -> usize;
    /// `(A, b, c)` of the mode.
    fn dynamics(&self, modes: &[i8]) -> (Mat<S>, Vector<S>, Vector<S>);
    /// Guards that leave the mode.
    fn guards(&self, modes: &[i8]) -> Vec<GuardSpec<S>>;
    /// Mode of a state under input `u` (used for the initial state).
    fn classify(&self, x: &Vector<S>, u: f64) -> Vec<i8>;
    /// The mode switch `index` actually takes when a guard leading from mode `from` to
    /// `target` fires at `x` under input `u` (`modes` holds the other switches'
    /// modes). The model may also reset state components there (e.g. a speed that
    /// sticks at exactly 0). The default keeps the guard's target and the state.
    fn resolve(
        &self,
        index: usize,
        from: i8,
        target: i8,
        modes: &[i8],
        x: &mut Vector<S>,
        u: f64,
    ) -> i8 {
        let _ = (index, from, modes, x, u);
        target
    }
    /// Modes whose dynamics bound the fastest time scale of the model.
    fn extreme_modes(&self) -> Vec<Vec<i8>>;
    /// Number of values of a mode code: 3 (`-1..=1`, the default) or 5 (`-2..=2`).
    fn mode_codes(&self) -> usize {
        3
    }
}

/// A change of mode of one switch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Event {
    pub time: f64,
    pub index: usize,
    pub from: i8,
    pub to: i8,
}

/// A close pass of a guard function to its boundary (see [`GRAZE_RTOL`]): `margin` is
/// the guard's value at its extremum relative to the guard's scale (the half-width for
/// a twist), negative when the boundary was missed, positive when barely crossed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Graze {
    pub time: f64,
    pub index: usize,
    pub margin: f64,
}

/// States on the grid (row-major `n x S`), modes on the grid (`n x n_switches`),
/// events and near-grazing passes.
#[derive(Clone, Debug, Default)]
pub struct Trajectory {
    pub states: Vec<f64>,
    pub modes: Vec<i8>,
    pub events: Vec<Event>,
    pub grazes: Vec<Graze>,
}
