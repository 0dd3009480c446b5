//! Event-accurate simulation of piecewise-affine systems with zero-order-hold input.
//!
//! A [`HybridModel`] has discrete modes; in each mode the state obeys
//! `dx/dt = A x + b u + c` and the mode is left when a *guard* fires. A guard is a set
//! of affine functions `g(x) = h.x + d` and fires when all of them become positive.
//!
//! The engine advances the state sample by sample with the exact flow of the current
//! mode, `x <- E x + F (b u + c)`, `E = exp(A h)`, `F = int_0^h exp(A s) ds`, and checks
//! every sample cheaply: the sign of each guard function at the sample's end, and
//! whether one reached an extremum towards its boundary inside the sample (slopes of
//! opposite signs at the two ends, peak bounded by the tangent lines). To keep those
//! checks off the state's dependency chain it runs the flow over a block of samples
//! first, then proves whole blocks clear with interval bounds, testing sample by
//! sample only where a bound fails, and rolls back to the first suspect sample.
//!
//! Only there does it look closely: it expands the flow as a Taylor polynomial in
//! time (valid because the internal step `h` keeps `rho(A) h <= 1/2`), scans it for the
//! earliest crossing, locates it by regula falsi (Illinois) to a few ulps of the step,
//! switches mode there and finishes the step in the new mode. The switching instants
//! are therefore located inside the sample, not rounded to the grid.
//!
//! The pieces: `model`, what a model gives the engine and what a run returns; `mode`, a
//! mode built for the engine; `engine`, the run and its per-sample check; `blocks`, the
//! block-wise fast path; `locate`, the close look inside one internal step; `settle`,
//! the proof that a run stays in its mode through the rest of a held input, after
//! which it runs the flow alone.

mod blocks;
mod engine;
mod locate;
mod mode;
mod model;
mod settle;
#[cfg(test)]
mod tests;

pub use engine::{flow, Engine};
pub use model::{Event, Graze, GuardFn, GuardSpec, HybridModel, Trajectory};

/// Relative distance to a boundary under which an extremum is reported as near-grazing.
pub const GRAZE_RTOL: f64 = 1e-6;
