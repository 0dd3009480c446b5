//! Exact forward sensitivities of the two-mass drive (issue 24): the derivatives of the
//! state `[w_M, w_L, phi]` (`[w_M, w_L, phi, T]` behind a current loop, `T` the motor
//! torque; then the motor's angle where the run tracks it, an encoder's record) with
//! respect to the parameters [`PARAMS`], under paper A's contact law, with
//! Coulomb friction whose breakaway torque is the Coulomb torque (`fs = fc`) or none,
//! from a given state and its sensitivity (zero from rest; a held torque's run or a
//! steady state's where a run continues one).
//!
//! Inside a mode the drive is linear, `dx/dt = A x + b u + c`, and so is each
//! sensitivity `S_j = dx/dp_j`: `dS_j/dt = A S_j + A_j x + b_j u + c_j` (`A_j = dA/dp_j`
//! and so on). The state and one sensitivity together follow a 6-state linear system
//! whose flow over a span of held torque is exact (a matrix exponential, as the
//! simulator's own); see `mode`, `flow` and `coupled`. The contact changes are those the simulator locates:
//! the drive is simulated first (or its run is given, `drive_sensitivities_along`) and
//! its events split the samples they fall in. At a
//! change the sensitivities jump by the saltation `(f_- - f_+) dtau/dp`; see `run`.
//! A stick-slip change is a change of mode like a contact change, with its own guard:
//! the speed's zero crossing, or the breakaway of the torque on a stuck inertia.
//!
//! Where the shaft grazes a flank (`dphi/dt = 0` at the change) the derivative does not
//! exist; near it the jump grows without bound. An exactly grazing change is an
//! [`Error::Grazing`](crate::Error::Grazing).
//!
//! The NumPy twin is `backlashkit._numpy_sensitivity`.

mod coupled;
mod flow;
mod information;
mod jacobian;
mod lanes;
mod mode;
mod run;
#[cfg(test)]
mod tests;

pub use information::{drive_information, DriveInformation};
pub use jacobian::{drive_jacobian_rows_along, RowWeights};
pub use run::{
    drive_sensitivities, drive_sensitivities_along, drive_sensitivities_along_into,
    drive_sensitivities_from, drive_sensitivities_of, drive_sensitivity_at_end_along, Along,
    DriveSensitivities,
};

/// The parameters, in the order of a parameter vector: motor and load inertias, shaft
/// stiffness, motor and load viscous frictions, shaft damping, backlash half-width
/// (paper A's model, the first [`N_LINEAR`]), then the motor's and the load's Coulomb
/// torques (0: no Coulomb friction), then the current loop's time constant (0: none).
pub const PARAMS: [&str; N_PARAMS] = [
    "J_M", "J_L", "k_sh", "f_M", "f_L", "f_sh", "theta", "fc_M", "fc_L", "tau_i",
];
/// Number of parameters.
pub const N_PARAMS: usize = 10;
/// Paper A's model: the parameters before the Coulomb torques.
pub const N_LINEAR: usize = 7;
/// States of the two-mass drive: `[w_M, w_L, phi]`.
pub const N_STATES: usize = 3;
/// States behind a current loop: the drive's, then the motor torque `T`.
pub const N_LOOP_STATES: usize = N_STATES + 1;
/// The most states a run carries: behind a loop, with the motor's angle last (the
/// simulator's `track_angle`, which an encoder's record is fitted with).
pub const N_MAX_STATES: usize = N_LOOP_STATES + 1;

/// The state count of a drive with parameters `p`: [`N_LOOP_STATES`] where its current
/// loop's time constant is positive, else [`N_STATES`] (the motor's angle, where a run
/// tracks it, is one more: [`Along::state_count`]).
pub fn state_count(p: &[f64; N_PARAMS]) -> usize {
    if has_loop(p) {
        N_LOOP_STATES
    } else {
        N_STATES
    }
}

/// Whether the drive with parameters `p` is behind a current loop (`tau_i > 0`), whose
/// torque `T` is then the state after the drive's three.
pub(crate) fn has_loop(p: &[f64; N_PARAMS]) -> bool {
    p[index::TAU] > 0.0
}

/// Indices into a parameter array (order [`PARAMS`]).
pub(crate) mod index {
    pub const J_M: usize = 0;
    pub const J_L: usize = 1;
    pub const K: usize = 2;
    pub const F_M: usize = 3;
    pub const F_L: usize = 4;
    pub const D: usize = 5;
    pub const THETA: usize = 6;
    pub const FC_M: usize = 7;
    pub const FC_L: usize = 8;
    pub const TAU: usize = 9;
}
