//! backlashkit-core: pure-Rust kernels of backlashkit.
//!
//! * [`chain`] -- event-accurate simulation of drive chains with backlash (paper A's
//!   two-mass drive is the two-inertia chain), one run or a parallel batch.
//! * [`hybrid`] -- the piecewise-affine simulation engine underneath.
//! * [`linalg`] -- small fixed-size linear algebra (matrix exponential and integral).
//!
//! Units are SI; every backlash `theta` is the half-width of the dead zone.

// Numeric kernels index several arrays with one loop variable; iterator chains would
// obscure the maths without making it faster.
#![allow(clippy::needless_range_loop)]

pub mod bare;
pub mod chain;
pub mod control;
pub mod hybrid;
pub mod linalg;
pub mod play;

use std::fmt;

/// Errors of the kernels; the Python binding turns them into `ValueError`.
#[derive(Clone, Debug, PartialEq)]
pub enum Error {
    /// An argument violates its constraint; the message says which and how.
    InvalidArgument(String),
    /// The state became non-finite (parameters far outside a physical range).
    Diverged { time: f64 },
    /// More contact changes inside one step than the engine accepts.
    Zeno { time: f64 },
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::InvalidArgument(m) => write!(f, "{m}"),
            Error::Diverged { time } => write!(
                f,
                "the simulation diverged (non-finite state) at t = {time} s; check the parameters' units and magnitudes"
            ),
            Error::Zeno { time } => write!(
                f,
                "contact chatter at t = {time} s: too many contact changes inside one sample; \
                 use a shorter sample time or check the parameters"
            ),
        }
    }
}

impl std::error::Error for Error {}
