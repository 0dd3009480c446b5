//! backlashkit-core: pure-Rust kernels of backlashkit.
//!
//! * [`chain`] -- event-accurate simulation of drive chains with backlash (paper A's
//!   two-mass drive is the two-inertia chain), one run or a parallel batch.
//! * [`hybrid`] -- the piecewise-affine simulation engine underneath.
//! * [`sensitivity`] -- exact forward sensitivities of the two-mass drive.
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
pub mod sensitivity;

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
    /// A contact change at which the shaft grazes a flank (zero relative speed): the
    /// state is not differentiable in the parameters there.
    Grazing { time: f64 },
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::InvalidArgument(m) => write!(f, "{m}"),
            Error::Diverged { time } => write!(
                f,
                "the simulation diverged (non-finite state) at t = {} s; check the parameters' units and magnitudes",
                Seconds(*time)
            ),
            Error::Zeno { time } => write!(
                f,
                "contact chatter at t = {} s: too many contact changes inside one sample; \
                 use a shorter sample time or check the parameters and the input's magnitude",
                Seconds(*time)
            ),
            Error::Grazing { time } => write!(
                f,
                "the shaft grazes a flank at t = {} s (zero relative speed at a contact \
                 change): the sensitivities do not exist there; perturb the input or the \
                 parameters",
                Seconds(*time)
            ),
        }
    }
}

impl std::error::Error for Error {}

/// A time in a message: plain decimals where they are short, else an exponent (the
/// default formatting prints 1e-28 s with 44 decimals).
struct Seconds(f64);

impl fmt::Display for Seconds {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let t = self.0;
        if t == 0.0 || (1e-3..1e7).contains(&t.abs()) {
            write!(f, "{t}")
        } else {
            write!(f, "{t:.6e}")
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn times_in_messages_are_short() {
        let tiny = Error::Zeno {
            time: 1.0339757656912846e-28,
        }
        .to_string();
        assert!(tiny.contains("t = 1.033976e-28 s"), "{tiny}");
        let plain = Error::Zeno { time: 40.008 }.to_string();
        assert!(plain.contains("t = 40.008 s"), "{plain}");
    }
}
